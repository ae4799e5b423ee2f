/* The FMI 2.0 co-simulation entry points of every pogofmu FMU, of both backends: every function of
 * the standard exists once here, checks the instance's call state against the one table of
 * call_states.h and its arguments, filters the log (pg_logging.h), and hands the work to the
 * backend (pg_backend.h): the one adapter (adapter/pg_backend.c), whose model is generated C
 * (native FMUs) or the FMU's Python code (python/pg_source_py.c: the Python-hosted FMUs). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "pg_backend.h"
#include "pg_logging.h"

#include "call_states.h"

#define ST_OK fmi2OK
#define ST_WARNING fmi2Warning
#define ST_ERROR fmi2Error

/* A live instance starts with this word; fmi2FreeInstance clears it before the memory goes back,
 * and every entry point checks it: a call on a freed instance (or on no instance) is refused, a
 * second free does nothing, where they would have used freed memory (as far as the word, the
 * first bytes of the instance, is still mapped and not yet given to another instance). */
#define INST_MAGIC 0x706f6732u /* 'pog2' */

typedef struct {
    unsigned magic;
    char *name;
    fmi2CallbackFunctions cb;
    PgLogFilter filter; /* fmi2SetDebugLogging */
    unsigned mode;
    PgBackend *b;
} Inst;

static void emit(Inst *in, int status, const char *category, const char *message)
{
    if (!in->cb.logger) return;
    /* the FMI 2 logger takes a printf format: double every '%' */
    size_t n = strlen(message), extra = 0;
    for (size_t i = 0; i < n; ++i) extra += message[i] == '%';
    char *text = malloc(n + extra + 1);
    if (!text) return;
    for (size_t i = 0, j = 0; i <= n; ++i) {
        text[j++] = message[i];
        if (message[i] == '%') text[j++] = '%';
    }
    in->cb.logger(in->cb.componentEnvironment, in->name, (fmi2Status)status, category, text);
    free(text);
}

static void log_from_backend(void *env, int status, const char *category, const char *message)
{
    Inst *in = env;
    if (pg_log_wanted(&in->filter, status, category)) emit(in, status, category, message);
}

static PG_NOINLINE int refused(Inst *in, int rule, const char *function);

/* the call's rule holds in the instance's call state: the check of every call, kept to a test and
 * a branch; the message is written only for a refusal */
static inline int allowed(Inst *in, int rule, const char *function)
{
    return (in->mode & CALL_RULES[rule].cs) ? 1 : refused(in, rule, function);
}

static PG_NOINLINE int refused(Inst *in, int rule, const char *function)
{
    const CallRule *r = &CALL_RULES[rule];
    unsigned mask = r->cs;
    char text[700], where[400];
    if (!mask) {
        snprintf(text, sizeof text, "%s refused: it is not a co-simulation function", function);
    } else if (!(in->mode & mask)) {
        mode_list(mask, 0, where, sizeof where);
        snprintf(text, sizeof text, "%s refused: not allowed in %s (the standard allows it in %s)", function,
                 mode_name(in->mode, 0), where);
    } else {
        return 1;
    }
    emit(in, ST_ERROR, "logStatusError", text);
    return 0;
}

/* A NULL where the standard wants an argument: Error naming it (as the Reference-FMUs'
 * ASSERT_NOT_NULL does) */
static PG_NOINLINE fmi2Status null_argument(Inst *in, const char *function, const char *argument)
{
    char msg[300];
    snprintf(msg, sizeof msg, "%s refused: the argument %s must not be NULL", function, argument);
    emit(in, ST_ERROR, "logStatusError", msg);
    return fmi2Error;
}

static PG_NOINLINE fmi2Status unsupported(Inst *in, const char *what)
{
    char msg[300];
    snprintf(msg, sizeof msg, "%s is not supported by this FMU", what);
    emit(in, ST_ERROR, "logStatusError", msg);
    return fmi2Error;
}


#define INST ((Inst *)c)
#define LIVE(c) ((c) && ((const Inst *)(c))->magic == INST_MAGIC)
/* a live instance (nothing to log to otherwise) */
#define CHECK(c) do { if (!LIVE(c)) return fmi2Error; } while (0)
#define NOT_NULL(p, function, argument) do { if (!(p)) return null_argument(INST, function, argument); } while (0)
/* nvr values: the arrays vr and value given */
#define VALUES(n, vr, value, function) do { if (n) { NOT_NULL(vr, function, "vr"); NOT_NULL(value, function, "value"); } } while (0)
#define REQUIRE(rule, function) do { if (!allowed(INST, RULE_##rule, function)) return fmi2Error; } while (0)
#define LEADS_TO(st, m) do { if ((st) <= ST_WARNING) INST->mode = (m); } while (0)

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn)
{
    /* the standard's callbacks: without a logger nothing could be said, about this or anything else */
    if (!functions || !functions->logger) return NULL;
    if (!instanceName) {
        functions->logger(functions->componentEnvironment, "", fmi2Error, "logStatusError",
                          "fmi2Instantiate refused: the argument instanceName must not be NULL");
        return NULL;
    }
    Inst *in = calloc(1, sizeof *in);
    if (!in) return NULL;
    in->name = malloc(strlen(instanceName) + 1);
    if (!in->name) {
        free(in);
        return NULL;
    }
    strcpy(in->name, instanceName);
    in->cb = *functions;
    in->filter.on = loggingOn;
    if (fmuType != fmi2CoSimulation) {
        emit(in, fmi2Error, "logStatusError",
             "this FMU implements FMI 2.0 co-simulation only (fmuType must be fmi2CoSimulation)");
    } else {
        PgSetup setup = {in->name, fmuGUID, fmuResourceLocation, visible, 2, 'c', 0, 0, log_from_backend, in};
        in->b = pgb_new(&setup);
        if (in->b) {
            in->mode = MODE_INSTANTIATED;
            in->magic = INST_MAGIC;
            return in;
        }
    }
    free(in->name);
    free(in);
    return NULL;
}

void fmi2FreeInstance(fmi2Component c)
{
    if (!LIVE(c)) return; /* none, or freed already */
    INST->magic = 0;
    pgb_free(INST->b);
    pg_log_free(&INST->filter);
    free(INST->name);
    free(INST);
}

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories, const fmi2String categories[])
{
    CHECK(c);
    REQUIRE(fmi2SetDebugLogging, "fmi2SetDebugLogging");
    if (nCategories) NOT_NULL(categories, "fmi2SetDebugLogging", "categories");
    char text[1200];
    size_t n_known = 0;
    const char *const *known = pgb_log_categories(INST->b, &n_known);
    int rc = pg_log_set(&INST->filter, known, n_known, loggingOn, nCategories, categories, "fmi2SetDebugLogging",
                        text, sizeof text);
    if (rc > 0) emit(INST, ST_ERROR, "logStatusError", text);
    return rc ? fmi2Error : fmi2OK;
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    CHECK(c);
    REQUIRE(fmi2SetupExperiment, "fmi2SetupExperiment");
    if (toleranceDefined && !(tolerance > 0 && tolerance < HUGE_VAL)) {
        char text[300];
        snprintf(text, sizeof text, "fmi2SetupExperiment refused: tolerance = %g violates the rule: with "
                 "toleranceDefined the tolerance is a number > 0 and finite", tolerance);
        emit(INST, ST_ERROR, "logStatusError", text);
        return fmi2Error;
    }
    return (fmi2Status)pgb_setup_experiment(INST->b, toleranceDefined, tolerance, startTime, stopTimeDefined, stopTime);
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    CHECK(c);
    REQUIRE(fmi2EnterInitializationMode, "fmi2EnterInitializationMode");
    fmi2Status st = (fmi2Status)pgb_enter_initialization(INST->b);
    LEADS_TO(st, MODE_INITIALIZATION);
    return st;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    CHECK(c);
    REQUIRE(fmi2ExitInitializationMode, "fmi2ExitInitializationMode");
    fmi2Status st = (fmi2Status)pgb_exit_initialization(INST->b);
    LEADS_TO(st, MODE_STEP);
    return st;
}

fmi2Status fmi2Terminate(fmi2Component c)
{
    CHECK(c);
    REQUIRE(fmi2Terminate, "fmi2Terminate");
    fmi2Status st = (fmi2Status)pgb_terminate(INST->b);
    LEADS_TO(st, MODE_TERMINATED);
    return st;
}

fmi2Status fmi2Reset(fmi2Component c)
{
    CHECK(c);
    REQUIRE(fmi2Reset, "fmi2Reset");
    fmi2Status st = (fmi2Status)pgb_reset(INST->b);
    LEADS_TO(st, MODE_INSTANTIATED);
    return st;
}

/* ---- variables ------------------------------------------------------------------------------ */
fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    CHECK(c);
    REQUIRE(fmi2GetValues, "fmi2GetReal");
    VALUES(nvr, vr, value, "fmi2GetReal");
    return (fmi2Status)pgb_get_real(INST->b, vr, nvr, value);
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[])
{
    CHECK(c);
    REQUIRE(fmi2GetValues, "fmi2GetInteger");
    VALUES(nvr, vr, value, "fmi2GetInteger");
    return (fmi2Status)pgb_get_integer(INST->b, vr, nvr, value);
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[])
{
    CHECK(c);
    REQUIRE(fmi2GetValues, "fmi2GetBoolean");
    (void)value;
    if (nvr) NOT_NULL(vr, "fmi2GetBoolean", "vr");
    return (fmi2Status)pgb_no_such_type(INST->b, vr, nvr, "Boolean");
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[])
{
    CHECK(c);
    REQUIRE(fmi2GetValues, "fmi2GetString");
    (void)value;
    if (nvr) NOT_NULL(vr, "fmi2GetString", "vr");
    return (fmi2Status)pgb_no_such_type(INST->b, vr, nvr, "String");
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[])
{
    CHECK(c);
    REQUIRE(fmi2SetValues, "fmi2SetReal");
    VALUES(nvr, vr, value, "fmi2SetReal");
    return (fmi2Status)pgb_set_real(INST->b, vr, nvr, value);
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[])
{
    CHECK(c);
    REQUIRE(fmi2SetValues, "fmi2SetInteger");
    VALUES(nvr, vr, value, "fmi2SetInteger");
    return (fmi2Status)pgb_set_integer(INST->b, vr, nvr, value);
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[])
{
    CHECK(c);
    REQUIRE(fmi2SetValues, "fmi2SetBoolean");
    (void)value;
    if (nvr) NOT_NULL(vr, "fmi2SetBoolean", "vr");
    return (fmi2Status)pgb_no_such_type(INST->b, vr, nvr, "Boolean");
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[])
{
    CHECK(c);
    REQUIRE(fmi2SetValues, "fmi2SetString");
    (void)value;
    if (nvr) NOT_NULL(vr, "fmi2SetString", "vr");
    return (fmi2Status)pgb_no_such_type(INST->b, vr, nvr, "String");
}

/* ---- FMU states (the backend's handles) ------------------------------------------------------ */
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    CHECK(c);
    REQUIRE(fmi2FMUstate, "fmi2GetFMUstate");
    NOT_NULL(FMUstate, "fmi2GetFMUstate", "FMUstate");
    return (fmi2Status)pgb_state_get(INST->b, INST->mode, FMUstate);
}

/* The call state an FMU state was taken in (kept and serialized with it) is one this instance can
 * be in: 1; else 0 with the reason logged. */
static int state_fits(Inst *in, void *state, const char *function, unsigned *mode)
{
    if (pgb_state_mode(in->b, state, mode) > ST_WARNING) return 0;
    char text[700];
    if (state_call_state_fits(*mode, FMI2_STATE_MODES, 0, 0, function, "co-simulation", text, sizeof text)) return 1;
    emit(in, ST_ERROR, "logStatusError", text);
    return 0;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate)
{
    CHECK(c);
    REQUIRE(fmi2FMUstate, "fmi2SetFMUstate");
    unsigned mode = 0;
    if (!state_fits(INST, FMUstate, "fmi2SetFMUstate", &mode)) return fmi2Error;
    int st = pgb_state_set(INST->b, FMUstate, &mode);
    if (st <= fmi2Warning) INST->mode = mode; /* back in the call state it was taken in */
    return (fmi2Status)st;
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    CHECK(c);
    REQUIRE(fmi2FMUstate, "fmi2FreeFMUstate");
    return (fmi2Status)pgb_state_free(INST->b, FMUstate);
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size)
{
    CHECK(c);
    REQUIRE(fmi2FMUstate, "fmi2SerializedFMUstateSize");
    NOT_NULL(size, "fmi2SerializedFMUstateSize", "size");
    return (fmi2Status)pgb_state_size(INST->b, FMUstate, size);
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate, fmi2Byte serializedState[], size_t size)
{
    CHECK(c);
    REQUIRE(fmi2FMUstate, "fmi2SerializeFMUstate");
    NOT_NULL(serializedState, "fmi2SerializeFMUstate", "serializedState");
    return (fmi2Status)pgb_state_serialize(INST->b, FMUstate, (unsigned char *)serializedState, size);
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size, fmi2FMUstate *FMUstate)
{
    CHECK(c);
    REQUIRE(fmi2FMUstate, "fmi2DeSerializeFMUstate");
    NOT_NULL(serializedState, "fmi2DeSerializeFMUstate", "serializedState");
    NOT_NULL(FMUstate, "fmi2DeSerializeFMUstate", "FMUstate");
    int st = pgb_state_deserialize(INST->b, (const unsigned char *)serializedState, size, FMUstate);
    unsigned mode = 0;
    if (st <= fmi2Warning && !state_fits(INST, *FMUstate, "fmi2DeSerializeFMUstate", &mode)) {
        pgb_state_free(INST->b, FMUstate);
        return fmi2Error;
    }
    return (fmi2Status)st;
}

/* ---- the rest of co-simulation --------------------------------------------------------------- */
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
                                        const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[])
{
    CHECK(c);
    REQUIRE(fmi2GetDirectionalDerivative, "fmi2GetDirectionalDerivative");
    if (nUnknown) {
        NOT_NULL(vUnknown_ref, "fmi2GetDirectionalDerivative", "vUnknown_ref");
        NOT_NULL(dvUnknown, "fmi2GetDirectionalDerivative", "dvUnknown");
    }
    if (nKnown) {
        NOT_NULL(vKnown_ref, "fmi2GetDirectionalDerivative", "vKnown_ref");
        NOT_NULL(dvKnown, "fmi2GetDirectionalDerivative", "dvKnown");
    }
    return (fmi2Status)pgb_directional(INST->b, vUnknown_ref, nUnknown, vKnown_ref, nKnown, dvKnown, dvUnknown,
                                           "fmi2GetDirectionalDerivative");
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[])
{
    CHECK(c);
    REQUIRE(fmi2SetRealInputDerivatives, "fmi2SetRealInputDerivatives");
    if (nvr) {
        NOT_NULL(vr, "fmi2SetRealInputDerivatives", "vr");
        NOT_NULL(order, "fmi2SetRealInputDerivatives", "order");
        NOT_NULL(value, "fmi2SetRealInputDerivatives", "value");
    }
    return (fmi2Status)pgb_set_input_derivatives(INST->b, vr, nvr, order, value);
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[])
{
    (void)vr, (void)nvr, (void)order, (void)value;
    CHECK(c);
    REQUIRE(fmi2GetRealOutputDerivatives, "fmi2GetRealOutputDerivatives");
    return unsupported(INST, "fmi2GetRealOutputDerivatives (maxOutputDerivativeOrder = 0)");
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    (void)noSetFMUStatePriorToCurrentPoint;
    CHECK(c);
    REQUIRE(fmi2DoStep, "fmi2DoStep");
    fmi2Status st = (fmi2Status)pgb_do_step(INST->b, currentCommunicationPoint, communicationStepSize);
    if (st == fmi2Discard) INST->mode = MODE_STEP_FAILED; /* the standard's stepFailed */
    return st;
}

fmi2Status fmi2CancelStep(fmi2Component c)
{
    CHECK(c);
    REQUIRE(fmi2CancelStep, "fmi2CancelStep");
    /* FMI 2.0 §4.2.2: fmi2CancelStep stops an asynchronous step, one whose fmi2DoStep returned
     * fmi2Pending; these FMUs declare canRunAsynchronuously = false and every fmi2DoStep returns
     * when its work is done, so no call of it is in the standard's sequence. */
    emit(INST, ST_ERROR, "logStatusError",
         "fmi2CancelStep refused: it applies only while an asynchronous fmi2DoStep is pending (after fmi2DoStep "
         "returned fmi2Pending, FMI 2.0 section 4.2.2); this FMU's fmi2DoStep is synchronous "
         "(canRunAsynchronuously = false) and never returns fmi2Pending. One call's work is bounded by the "
         "parameter max_steps_per_call instead");
    return fmi2Error;
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value)
{
    (void)s, (void)value;
    CHECK(c);
    REQUIRE(fmi2GetStatus, "fmi2GetStatus");
    return unsupported(INST, "fmi2GetStatus (fmi2DoStep never returns fmi2Pending)");
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value)
{
    CHECK(c);
    REQUIRE(fmi2GetStatus, "fmi2GetRealStatus");
    NOT_NULL(value, "fmi2GetRealStatus", "value");
    if (s != fmi2LastSuccessfulTime) return unsupported(INST, "fmi2GetRealStatus for this status kind");
    return (fmi2Status)pgb_last_successful_time(INST->b, value);
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value)
{
    (void)s, (void)value;
    CHECK(c);
    REQUIRE(fmi2GetStatus, "fmi2GetIntegerStatus");
    return unsupported(INST, "fmi2GetIntegerStatus");
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value)
{
    CHECK(c);
    REQUIRE(fmi2GetStatus, "fmi2GetBooleanStatus");
    NOT_NULL(value, "fmi2GetBooleanStatus", "value");
    if (s != fmi2Terminated) return unsupported(INST, "fmi2GetBooleanStatus for this status kind");
    int terminated = 0;
    fmi2Status st = (fmi2Status)pgb_terminated(INST->b, &terminated);
    if (st <= fmi2Warning) *value = terminated ? fmi2True : fmi2False;
    return st;
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value)
{
    (void)s, (void)value;
    CHECK(c);
    REQUIRE(fmi2GetStatus, "fmi2GetStringStatus");
    return unsupported(INST, "fmi2GetStringStatus");
}

