/* The FMI 3.0 entry points of every pogofmu FMU, of both backends, model exchange and
 * co-simulation (event mode, early return): every function of the standard exists once here,
 * checks the instance's call state against the one table of call_states.h and its arguments,
 * filters the log (pg_logging.h), and hands the work to the backend the binary is linked with
 * (pg_backend.h): the one adapter (adapter/pg_backend.c), whose model is generated C (native FMUs)
 * or the FMU's Python code (python/pg_source_py.c: the Python-hosted FMUs). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"
#include "pg_backend.h"
#include "pg_logging.h"

#include "call_states.h"

#define ST_OK fmi3OK
#define ST_WARNING fmi3Warning
#define ST_ERROR fmi3Error

/* A live instance starts with this word; fmi3FreeInstance clears it before the memory goes back,
 * and every entry point checks it: a call on a freed instance (or on no instance) is refused, a
 * second free does nothing, where they would have used freed memory (as far as the word, the
 * first bytes of the instance, is still mapped and not yet given to another instance). */
#define INST_MAGIC 0x706f6733u /* 'pog3' */

typedef struct {
    unsigned magic;
    char *name;
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log;
    PgLogFilter filter; /* fmi3SetDebugLogging */
    unsigned mode;
    int me;              /* a model-exchange instance */
    int event_mode_used; /* co-simulation: fixed at instantiation */
    int event_pending;   /* co-simulation: the last fmi3DoStep returned eventHandlingNeeded (Event Mode next) */
    size_t nx, nz;       /* continuous states, event indicators */
    const unsigned *arrays; /* the backend's array table (pgb_arrays): n_arrays pairs (vr, elements) */
    size_t n_arrays;
    PgBackend *b;
} Inst;

static void emit(Inst *in, int status, const char *category, const char *message)
{
    if (in->log) in->log(in->env, (fmi3Status)status, category, message);
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
    return (in->mode & (in->me ? CALL_RULES[rule].me : CALL_RULES[rule].cs)) ? 1 : refused(in, rule, function);
}

static PG_NOINLINE int refused(Inst *in, int rule, const char *function)
{
    const CallRule *r = &CALL_RULES[rule];
    unsigned mask = in->me ? r->me : r->cs;
    char text[700], where[400];
    if (!mask) {
        snprintf(text, sizeof text, "%s refused: it is a %s function, and this instance is a %s instance", function,
                 in->me ? "co-simulation" : "model-exchange", in->me ? "model-exchange" : "co-simulation");
    } else if (!(in->mode & mask)) {
        mode_list(mask, 1, where, sizeof where);
        snprintf(text, sizeof text, "%s refused: not allowed in %s (the standard allows it in %s)", function,
                 mode_name(in->mode, 1), where);
    } else {
        return 1;
    }
    emit(in, ST_ERROR, "logStatusError", text);
    return 0;
}

/* A NULL where the standard wants an argument: Error naming it (as the Reference-FMUs'
 * ASSERT_NOT_NULL does) */
static PG_NOINLINE fmi3Status null_argument(Inst *in, const char *function, const char *argument)
{
    char msg[300];
    snprintf(msg, sizeof msg, "%s refused: the argument %s must not be NULL", function, argument);
    emit(in, ST_ERROR, "logStatusError", msg);
    return fmi3Error;
}

/* Every variable of this FMU is a scalar: one value per value reference. */
static int counts_match(Inst *in, const char *function, size_t nvr, size_t n_values)
{
    if (nvr == n_values) return 1;
    char msg[300];
    snprintf(msg, sizeof msg, "%s refused: nValues = %zu for nValueReferences = %zu (every variable of this FMU is "
             "a scalar: nValues must equal nValueReferences)", function, n_values, nvr);
    emit(in, ST_ERROR, "logStatusError", msg);
    return 0;
}

/* The number of values of value reference vr: an array's elements, 1 for a scalar, 0 for an
 * element of an array after its first (no FMI 3.0 variable: *array is then the array's vr). */
static size_t values_of(const Inst *in, unsigned vr, unsigned *array)
{
    for (size_t k = 0; k < in->n_arrays; ++k) {
        unsigned head = in->arrays[2 * k], n = in->arrays[2 * k + 1];
        if (vr == head) return n;
        if (vr > head && vr < head + n) {
            *array = head;
            return 0;
        }
    }
    return 1;
}

/* The value references of a get, set or directional derivative as the backends take them: each
 * array's expanded into its elements' (row-major, the order of the values). nValues must count
 * every element: else Error naming the call, the counts and the first array. Returns vr itself
 * when the FMU has no arrays, else a list in *tmp (freed by the caller); NULL after an Error. */
static const unsigned *expand(Inst *in, const char *function, const char *count, const fmi3ValueReference vr[],
                              size_t nvr, size_t n_values, unsigned **tmp)
{
    char msg[400];
    *tmp = NULL;
    if (in->n_arrays == 0) {
        if (nvr == n_values) return vr;
        snprintf(msg, sizeof msg, "%s refused: %s = %zu for nValueReferences = %zu (every variable of this FMU is a "
                 "scalar: %s must equal nValueReferences)", function, count, n_values, nvr, count);
        emit(in, ST_ERROR, "logStatusError", msg);
        return NULL;
    }
    size_t total = 0, first_array = (size_t)-1;
    for (size_t i = 0; i < nvr; ++i) {
        unsigned array = 0;
        size_t n = values_of(in, vr[i], &array);
        if (n == 0) {
            snprintf(msg, sizeof msg, "%s refused: value reference %u is not a variable of this FMU (it is element %u "
                     "of the array at value reference %u: address the array, with nValues counting its elements)",
                     function, (unsigned)vr[i], (unsigned)vr[i] - array + 1, array);
            emit(in, ST_ERROR, "logStatusError", msg);
            return NULL;
        }
        if (n > 1 && first_array == (size_t)-1) first_array = i;
        total += n;
    }
    if (total != n_values) {
        if (first_array != (size_t)-1) {
            snprintf(msg, sizeof msg, "%s refused: %s = %zu, but the %zu value reference(s) hold %zu values (value "
                     "reference %u is an array of %zu elements): %s must count every array element", function, count,
                     n_values, nvr, total, (unsigned)vr[first_array], values_of(in, vr[first_array], &(unsigned){0}),
                     count);
        } else {
            snprintf(msg, sizeof msg, "%s refused: %s = %zu for nValueReferences = %zu (these variables are scalars: "
                     "%s must equal nValueReferences)", function, count, n_values, nvr, count);
        }
        emit(in, ST_ERROR, "logStatusError", msg);
        return NULL;
    }
    if (total == nvr) return vr; /* scalars only */
    unsigned *out = malloc(total * sizeof *out);
    if (!out) {
        emit(in, ST_ERROR, "logStatusError", "out of memory");
        return NULL;
    }
    size_t j = 0;
    for (size_t i = 0; i < nvr; ++i) {
        unsigned array = 0;
        size_t n = values_of(in, vr[i], &array);
        for (size_t e = 0; e < n; ++e) out[j++] = (unsigned)vr[i] + (unsigned)e;
    }
    *tmp = out;
    return out;
}

static PG_NOINLINE fmi3Status unsupported(Inst *in, const char *what)
{
    char msg[300];
    snprintf(msg, sizeof msg, "%s is not supported by this FMU", what);
    if (in) emit(in, ST_ERROR, "logStatusError", msg);
    return fmi3Error;
}


static char *copy_text(const char *text)
{
    char *out = malloc(strlen(text) + 1);
    if (out) strcpy(out, text);
    return out;
}

#define INST ((Inst *)c)
#define LIVE(c) ((c) && ((const Inst *)(c))->magic == INST_MAGIC)
/* a live instance (nothing to log to otherwise) */
#define CHECK(c) do { if (!LIVE(c)) return fmi3Error; } while (0)
#define NOT_NULL(p, function, argument) do { if (!(p)) return null_argument(INST, function, argument); } while (0)
/* Float64 and Int32 values: the arrays given, nValues counting every array element; `call`
 * the backend's function with the value references expanded (expand) */
#define VALUES(nvr, n_values, vr, values, function, call)                                           \
    do {                                                                                            \
        if (nvr) {                                                                                  \
            NOT_NULL(vr, function, "valueReferences");                                              \
            if (n_values) NOT_NULL(values, function, "values");                                     \
        }                                                                                           \
        unsigned *tmp_;                                                                             \
        const unsigned *vrs_ = expand(INST, function, "nValues", vr, nvr, n_values, &tmp_);         \
        if (!vrs_) return fmi3Error;                                                                \
        fmi3Status st_ = (fmi3Status)call(INST->b, vrs_, n_values, values);                         \
        free(tmp_);                                                                                 \
        return st_;                                                                                 \
    } while (0)
#define REQUIRE(rule, function) do { if (!allowed(INST, RULE_##rule, function)) return fmi3Error; } while (0)
#define LEADS_TO(st, m) do { if ((st) <= ST_WARNING) INST->mode = (m); } while (0)
#define UNUSED(x) (void)(x)

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance c, fmi3Boolean loggingOn, size_t nCategories, const fmi3String categories[])
{
    CHECK(c);
    REQUIRE(fmi3SetDebugLogging, "fmi3SetDebugLogging");
    if (nCategories) NOT_NULL(categories, "fmi3SetDebugLogging", "categories");
    char text[1200];
    size_t n_known = 0;
    const char *const *known = pgb_log_categories(INST->b, &n_known);
    int rc = pg_log_set(&INST->filter, known, n_known, loggingOn, nCategories, categories, "fmi3SetDebugLogging",
                        text, sizeof text);
    if (rc > 0) emit(INST, ST_ERROR, "logStatusError", text);
    return rc ? fmi3Error : fmi3OK;
}

static Inst *instantiate(const char *function, fmi3String instanceName, fmi3String token, fmi3String resources,
                         int visible, fmi3Boolean loggingOn, fmi3InstanceEnvironment env, fmi3LogMessageCallback log,
                         int me, int event_mode_used, int early_return_allowed, size_t n_required)
{
    if (!instanceName) {
        char msg[200];
        snprintf(msg, sizeof msg, "%s refused: the argument instanceName must not be NULL", function);
        if (log) log(env, fmi3Error, "logStatusError", msg);
        return NULL;
    }
    Inst *in = calloc(1, sizeof *in);
    if (!in) return NULL;
    in->name = copy_text(instanceName);
    if (!in->name) {
        free(in);
        return NULL;
    }
    in->env = env, in->log = log, in->filter.on = loggingOn, in->me = me, in->event_mode_used = event_mode_used != 0;
    if (n_required > 0) {
        emit(in, fmi3Error, "logStatusError", "fmi3InstantiateCoSimulation: intermediate variable access is not "
             "supported (nRequiredIntermediateVariables must be 0)");
    } else {
        PgSetup setup = {in->name, token, resources, visible, 3, me ? 'm' : 'c', event_mode_used != 0,
                         early_return_allowed != 0, log_from_backend, in};
        in->b = pgb_new(&setup);
        if (in->b) {
            pgb_counts(in->b, &in->nx, &in->nz);
            in->arrays = pgb_arrays(in->b, &in->n_arrays);
            in->mode = MODE_INSTANTIATED;
            in->magic = INST_MAGIC;
            return in;
        }
    }
    free(in->name);
    free(in);
    return NULL;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage)
{
    return instantiate("fmi3InstantiateModelExchange", instanceName, instantiationToken, resourcePath, visible,
                       loggingOn, instanceEnvironment, logMessage, 1, 0, 0, 0);
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate)
{
    UNUSED(requiredIntermediateVariables), UNUSED(intermediateUpdate);
    return instantiate("fmi3InstantiateCoSimulation", instanceName, instantiationToken, resourcePath, visible,
                       loggingOn, instanceEnvironment, logMessage, 0, eventModeUsed, earlyReturnAllowed,
                       nRequiredIntermediateVariables);
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                               fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption)
{
    UNUSED(instanceName), UNUSED(instantiationToken), UNUSED(resourcePath), UNUSED(visible), UNUSED(loggingOn);
    UNUSED(clockUpdate), UNUSED(lockPreemption), UNUSED(unlockPreemption);
    if (logMessage)
        logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                   "fmi3InstantiateScheduledExecution is not supported by this FMU (model exchange and "
                   "co-simulation only)");
    return NULL;
}

void fmi3FreeInstance(fmi3Instance c)
{
    if (!LIVE(c)) return; /* none, or freed already */
    INST->magic = 0;
    pgb_free(INST->b);
    pg_log_free(&INST->filter);
    free(INST->name);
    free(INST);
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance c, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime)
{
    CHECK(c);
    REQUIRE(fmi3EnterInitializationMode, "fmi3EnterInitializationMode");
    if (toleranceDefined && !(tolerance > 0 && tolerance < HUGE_VAL)) {
        char text[300];
        snprintf(text, sizeof text, "fmi3EnterInitializationMode refused: tolerance = %g violates the rule: with "
                 "toleranceDefined the tolerance is a number > 0 and finite", tolerance);
        emit(INST, ST_ERROR, "logStatusError", text);
        return fmi3Error;
    }
    int st = pgb_setup_experiment(INST->b, toleranceDefined, tolerance, startTime, stopTimeDefined, stopTime);
    if (st <= ST_WARNING) {
        int st2 = pgb_enter_initialization(INST->b);
        st = st2 > st ? st2 : st;
    }
    LEADS_TO(st, MODE_INITIALIZATION);
    return (fmi3Status)st;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance c)
{
    CHECK(c);
    REQUIRE(fmi3ExitInitializationMode, "fmi3ExitInitializationMode");
    int st = pgb_exit_initialization(INST->b);
    /* model exchange, and co-simulation with eventModeUsed, go on in Event Mode */
    LEADS_TO(st, (INST->me || INST->event_mode_used) ? MODE_EVENT : MODE_STEP);
    return (fmi3Status)st;
}

fmi3Status fmi3EnterEventMode(fmi3Instance c)
{
    CHECK(c);
    REQUIRE(fmi3EnterEventMode, "fmi3EnterEventMode");
    if (!INST->me && !INST->event_mode_used) {
        emit(INST, ST_ERROR, "logStatusError", "fmi3EnterEventMode refused: this co-simulation instance was "
             "instantiated with eventModeUsed = false (it handles its events inside fmi3DoStep)");
        return fmi3Error;
    }
    int st = pgb_enter_event_mode(INST->b);
    LEADS_TO(st, MODE_EVENT);
    if (st <= ST_WARNING) INST->event_pending = 0;
    return (fmi3Status)st;
}

fmi3Status fmi3Terminate(fmi3Instance c)
{
    CHECK(c);
    REQUIRE(fmi3Terminate, "fmi3Terminate");
    int st = pgb_terminate(INST->b);
    LEADS_TO(st, MODE_TERMINATED);
    if (st <= ST_WARNING) INST->event_pending = 0;
    return (fmi3Status)st;
}

fmi3Status fmi3Reset(fmi3Instance c)
{
    CHECK(c);
    REQUIRE(fmi3Reset, "fmi3Reset");
    int st = pgb_reset(INST->b);
    LEADS_TO(st, MODE_INSTANTIATED);
    if (st <= ST_WARNING) INST->event_pending = 0;
    return (fmi3Status)st;
}

/* ---- variables ------------------------------------------------------------------------------ */
static int no_type(Inst *in, const char *function, const char *type, size_t nvr, const fmi3ValueReference vr[])
{
    if (nvr == 0) return fmi3OK;
    if (!vr) return null_argument(in, function, "valueReferences");
    char msg[256];
    snprintf(msg, sizeof msg, "%s: value reference %u is not a variable of type %s (this FMU has Float64 and "
             "Int32 variables only)", function, vr ? (unsigned)vr[0] : 0u, type);
    if (in) emit(in, ST_ERROR, "logStatusError", msg);
    return fmi3Error;
}

fmi3Status fmi3GetFloat64(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 values[], size_t nValues)
{
    CHECK(c);
    REQUIRE(fmi3GetValues, "fmi3GetFloat64");
    VALUES(nvr, nValues, vr, values, "fmi3GetFloat64", pgb_get_real);
}

fmi3Status fmi3GetInt32(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Int32 values[], size_t nValues)
{
    CHECK(c);
    REQUIRE(fmi3GetValues, "fmi3GetInt32");
    VALUES(nvr, nValues, vr, values, "fmi3GetInt32", pgb_get_integer);
}

fmi3Status fmi3GetBoolean(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Boolean values[], size_t nValues)
{
    UNUSED(values);
    CHECK(c);
    REQUIRE(fmi3GetValues, "fmi3GetBoolean");
    if (!counts_match(INST, "fmi3GetBoolean", nvr, nValues)) return fmi3Error;
    if (nvr) NOT_NULL(vr, "fmi3GetBoolean", "valueReferences");
    return (fmi3Status)pgb_no_such_type(INST->b, vr, nvr, "Boolean");
}

fmi3Status fmi3GetString(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3String values[], size_t nValues)
{
    UNUSED(values);
    CHECK(c);
    REQUIRE(fmi3GetValues, "fmi3GetString");
    if (!counts_match(INST, "fmi3GetString", nvr, nValues)) return fmi3Error;
    if (nvr) NOT_NULL(vr, "fmi3GetString", "valueReferences");
    return (fmi3Status)pgb_no_such_type(INST->b, vr, nvr, "String");
}

fmi3Status fmi3SetFloat64(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3Float64 values[],
                          size_t nValues)
{
    CHECK(c);
    REQUIRE(fmi3SetFloat, "fmi3SetFloat64");
    VALUES(nvr, nValues, vr, values, "fmi3SetFloat64", pgb_set_real);
}

fmi3Status fmi3SetInt32(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3Int32 values[], size_t nValues)
{
    CHECK(c);
    REQUIRE(fmi3SetDiscrete, "fmi3SetInt32");
    VALUES(nvr, nValues, vr, values, "fmi3SetInt32", pgb_set_integer);
}

fmi3Status fmi3SetBoolean(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3Boolean values[],
                          size_t nValues)
{
    UNUSED(values);
    CHECK(c);
    REQUIRE(fmi3SetDiscrete, "fmi3SetBoolean");
    if (!counts_match(INST, "fmi3SetBoolean", nvr, nValues)) return fmi3Error;
    if (nvr) NOT_NULL(vr, "fmi3SetBoolean", "valueReferences");
    return (fmi3Status)pgb_no_such_type(INST->b, vr, nvr, "Boolean");
}

fmi3Status fmi3SetString(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3String values[],
                         size_t nValues)
{
    UNUSED(values);
    CHECK(c);
    REQUIRE(fmi3SetDiscrete, "fmi3SetString");
    if (!counts_match(INST, "fmi3SetString", nvr, nValues)) return fmi3Error;
    if (nvr) NOT_NULL(vr, "fmi3SetString", "valueReferences");
    return (fmi3Status)pgb_no_such_type(INST->b, vr, nvr, "String");
}

/* types this FMU has no variables of: checked against the call-state table like the others
 * (`SET_RULE`: fmi3SetFloat for Float32, fmi3SetDiscrete for the rest), then an error naming the
 * function and the value reference */
#define NO_TYPE_GET(T, CT)                                                                                      \
    fmi3Status fmi3Get##T(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, CT values[], size_t nValues) \
    {                                                                                                           \
        UNUSED(values);                                                                                         \
        CHECK(c);                                                                                               \
        REQUIRE(fmi3GetValues, "fmi3Get" #T);                                                                   \
        if (!counts_match(INST, "fmi3Get" #T, nvr, nValues)) return fmi3Error;                                 \
        return (fmi3Status)no_type(INST, "fmi3Get" #T, #T, nvr, vr);                                           \
    }
#define NO_TYPE_SET(T, CT, SET_RULE)                                                                            \
    fmi3Status fmi3Set##T(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const CT values[],          \
                          size_t nValues)                                                                       \
    {                                                                                                           \
        UNUSED(values);                                                                                         \
        CHECK(c);                                                                                               \
        REQUIRE(SET_RULE, "fmi3Set" #T);                                                                        \
        if (!counts_match(INST, "fmi3Set" #T, nvr, nValues)) return fmi3Error;                                 \
        return (fmi3Status)no_type(INST, "fmi3Set" #T, #T, nvr, vr);                                           \
    }
#define NO_TYPE(T, CT, SET_RULE) NO_TYPE_GET(T, CT) NO_TYPE_SET(T, CT, SET_RULE)
NO_TYPE(Float32, fmi3Float32, fmi3SetFloat)
NO_TYPE(Int8, fmi3Int8, fmi3SetDiscrete)
NO_TYPE(UInt8, fmi3UInt8, fmi3SetDiscrete)
NO_TYPE(Int16, fmi3Int16, fmi3SetDiscrete)
NO_TYPE(UInt16, fmi3UInt16, fmi3SetDiscrete)
NO_TYPE(UInt32, fmi3UInt32, fmi3SetDiscrete)
NO_TYPE(Int64, fmi3Int64, fmi3SetDiscrete)
NO_TYPE(UInt64, fmi3UInt64, fmi3SetDiscrete)

fmi3Status fmi3GetBinary(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, size_t valueSizes[],
                         fmi3Binary values[], size_t nValues)
{
    UNUSED(valueSizes), UNUSED(values);
    CHECK(c);
    REQUIRE(fmi3GetValues, "fmi3GetBinary");
    if (!counts_match(INST, "fmi3GetBinary", nvr, nValues)) return fmi3Error;
    return (fmi3Status)no_type(INST, "fmi3GetBinary", "Binary", nvr, vr);
}

fmi3Status fmi3SetBinary(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const size_t valueSizes[],
                         const fmi3Binary values[], size_t nValues)
{
    UNUSED(valueSizes), UNUSED(values);
    CHECK(c);
    REQUIRE(fmi3SetDiscrete, "fmi3SetBinary");
    if (!counts_match(INST, "fmi3SetBinary", nvr, nValues)) return fmi3Error;
    return (fmi3Status)no_type(INST, "fmi3SetBinary", "Binary", nvr, vr);
}

fmi3Status fmi3GetClock(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Clock values[])
{
    UNUSED(values);
    CHECK(c);
    REQUIRE(fmi3Clocks, "fmi3GetClock");
    return (fmi3Status)no_type(INST, "fmi3GetClock", "Clock", nvr, vr);
}

fmi3Status fmi3SetClock(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3Clock values[])
{
    UNUSED(values);
    CHECK(c);
    REQUIRE(fmi3Clocks, "fmi3SetClock");
    return (fmi3Status)no_type(INST, "fmi3SetClock", "Clock", nvr, vr);
}

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance c, fmi3ValueReference valueReference, size_t *nDependencies)
{
    UNUSED(valueReference), UNUSED(nDependencies);
    CHECK(c);
    return unsupported(INST, "fmi3GetNumberOfVariableDependencies (the model description lists the dependencies)");
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance c, fmi3ValueReference dependent, size_t elementIndicesOfDependent[],
                                       fmi3ValueReference independents[], size_t elementIndicesOfIndependents[],
                                       fmi3DependencyKind dependencyKinds[], size_t nDependencies)
{
    UNUSED(dependent), UNUSED(elementIndicesOfDependent), UNUSED(independents);
    UNUSED(elementIndicesOfIndependents), UNUSED(dependencyKinds), UNUSED(nDependencies);
    CHECK(c);
    return unsupported(INST, "fmi3GetVariableDependencies (the model description lists the dependencies)");
}

/* ---- FMU states (the backend's handles) ------------------------------------------------------ */
fmi3Status fmi3GetFMUState(fmi3Instance c, fmi3FMUState *FMUState)
{
    CHECK(c);
    REQUIRE(fmi3FMUState, "fmi3GetFMUState");
    NOT_NULL(FMUState, "fmi3GetFMUState", "FMUState");
    return (fmi3Status)pgb_state_get(INST->b, INST->mode | (INST->event_pending ? MODE_EVENT_PENDING : 0u), FMUState);
}

/* The call state an FMU state was taken in (kept and serialized with it) is one this instance can
 * be in (an instance of the same FMU may be of the other interface, or without Event Mode): 1;
 * else 0 with the reason logged. */
static int state_fits(Inst *in, void *state, const char *function, unsigned *mode)
{
    if (pgb_state_mode(in->b, state, mode) > ST_WARNING) return 0;
    unsigned modes = in->me ? FMI3_ME_STATE_MODES : FMI3_CS_STATE_MODES | (in->event_mode_used ? MODE_EVENT : 0u);
    unsigned flags = !in->me && in->event_mode_used ? MODE_EVENT_PENDING : 0u;
    const char *kind = in->me ? "model-exchange" : in->event_mode_used ? "co-simulation"
                                                                       : "co-simulation (eventModeUsed = false)";
    char text[700];
    if (state_call_state_fits(*mode, modes, flags, 1, function, kind, text, sizeof text)) return 1;
    emit(in, ST_ERROR, "logStatusError", text);
    return 0;
}

fmi3Status fmi3SetFMUState(fmi3Instance c, fmi3FMUState FMUState)
{
    CHECK(c);
    REQUIRE(fmi3FMUState, "fmi3SetFMUState");
    unsigned mode = 0;
    if (!state_fits(INST, FMUState, "fmi3SetFMUState", &mode)) return fmi3Error;
    int st = pgb_state_set(INST->b, FMUState, &mode);
    if (st <= ST_WARNING) { /* back in the call state it was taken in */
        INST->mode = mode & ~MODE_FLAGS;
        INST->event_pending = (mode & MODE_EVENT_PENDING) != 0;
    }
    return (fmi3Status)st;
}

fmi3Status fmi3FreeFMUState(fmi3Instance c, fmi3FMUState *FMUState)
{
    CHECK(c);
    REQUIRE(fmi3FMUState, "fmi3FreeFMUState");
    return (fmi3Status)pgb_state_free(INST->b, FMUState);
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance c, fmi3FMUState FMUState, size_t *size)
{
    CHECK(c);
    REQUIRE(fmi3FMUState, "fmi3SerializedFMUStateSize");
    NOT_NULL(size, "fmi3SerializedFMUStateSize", "size");
    return (fmi3Status)pgb_state_size(INST->b, FMUState, size);
}

fmi3Status fmi3SerializeFMUState(fmi3Instance c, fmi3FMUState FMUState, fmi3Byte serializedState[], size_t size)
{
    CHECK(c);
    REQUIRE(fmi3FMUState, "fmi3SerializeFMUState");
    NOT_NULL(serializedState, "fmi3SerializeFMUState", "serializedState");
    return (fmi3Status)pgb_state_serialize(INST->b, FMUState, (unsigned char *)serializedState, size);
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance c, const fmi3Byte serializedState[], size_t size, fmi3FMUState *FMUState)
{
    CHECK(c);
    REQUIRE(fmi3FMUState, "fmi3DeserializeFMUState");
    NOT_NULL(serializedState, "fmi3DeserializeFMUState", "serializedState");
    NOT_NULL(FMUState, "fmi3DeserializeFMUState", "FMUState");
    int st = pgb_state_deserialize(INST->b, (const unsigned char *)serializedState, size, FMUState);
    unsigned mode = 0;
    if (st <= ST_WARNING && !state_fits(INST, *FMUState, "fmi3DeserializeFMUState", &mode)) {
        pgb_state_free(INST->b, FMUState);
        return fmi3Error;
    }
    return (fmi3Status)st;
}

/* ---- not provided --------------------------------------------------------------------------- */
fmi3Status fmi3GetDirectionalDerivative(fmi3Instance c, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                        const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                        size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity)
{
    CHECK(c);
    REQUIRE(fmi3GetDirectionalDerivative, "fmi3GetDirectionalDerivative");
    if (nUnknowns) {
        NOT_NULL(unknowns, "fmi3GetDirectionalDerivative", "unknowns");
        NOT_NULL(sensitivity, "fmi3GetDirectionalDerivative", "sensitivity");
    }
    if (nKnowns) {
        NOT_NULL(knowns, "fmi3GetDirectionalDerivative", "knowns");
        NOT_NULL(seed, "fmi3GetDirectionalDerivative", "seed");
    }
    /* one seed per element of a known, one sensitivity per element of an unknown (the standard's
     * rule for array variables) */
    unsigned *tmp_u, *tmp_k = NULL;
    const unsigned *u = expand(INST, "fmi3GetDirectionalDerivative", "nSensitivity", unknowns, nUnknowns,
                               nSensitivity, &tmp_u);
    const unsigned *k = u ? expand(INST, "fmi3GetDirectionalDerivative", "nSeed", knowns, nKnowns, nSeed, &tmp_k)
                          : NULL;
    fmi3Status st = fmi3Error;
    if (u && k)
        st = (fmi3Status)pgb_directional(INST->b, u, nSensitivity, k, nSeed, seed, sensitivity,
                                         "fmi3GetDirectionalDerivative");
    free(tmp_u);
    free(tmp_k);
    return st;
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance c, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                    const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                    size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity)
{
    UNUSED(unknowns), UNUSED(nUnknowns), UNUSED(knowns), UNUSED(nKnowns), UNUSED(seed), UNUSED(nSeed);
    UNUSED(sensitivity), UNUSED(nSensitivity);
    CHECK(c);
    REQUIRE(fmi3GetDirectionalDerivative, "fmi3GetAdjointDerivative");
    return unsupported(INST, "fmi3GetAdjointDerivative (providesAdjointDerivatives = false)");
}

/* The standard: fmi3EnterConfigurationMode "must not be called if the FMU contains no structural
 * parameter" — these FMUs have none: refused in the states that allow it, naming that rule, and by
 * the call state elsewhere; fmi3ExitConfigurationMode only in (Re)Configuration Mode, never here. */
fmi3Status fmi3EnterConfigurationMode(fmi3Instance c)
{
    CHECK(c);
    REQUIRE(fmi3EnterConfigurationMode, "fmi3EnterConfigurationMode");
    emit(INST, ST_ERROR, "logStatusError", "fmi3EnterConfigurationMode refused: this FMU has no structural "
         "parameters (the standard: it must not be called then)");
    return fmi3Error;
}

fmi3Status fmi3ExitConfigurationMode(fmi3Instance c)
{
    CHECK(c);
    REQUIRE(fmi3ExitConfigurationMode, "fmi3ExitConfigurationMode");
    return fmi3Error; /* (not reached: no state of these FMUs allows it) */
}

#define NO_CLOCKS(call_) do { CHECK(c); return unsupported(INST, call_ " (this FMU has no clocks)"); } while (0)
fmi3Status fmi3GetIntervalDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Float64 intervals[],
                                  fmi3IntervalQualifier qualifiers[])
{
    UNUSED(vr), UNUSED(n), UNUSED(intervals), UNUSED(qualifiers);
    NO_CLOCKS("fmi3GetIntervalDecimal");
}
fmi3Status fmi3GetIntervalFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3UInt64 counters[],
                                   fmi3UInt64 resolutions[], fmi3IntervalQualifier qualifiers[])
{
    UNUSED(vr), UNUSED(n), UNUSED(counters), UNUSED(resolutions), UNUSED(qualifiers);
    NO_CLOCKS("fmi3GetIntervalFraction");
}
fmi3Status fmi3GetShiftDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Float64 shifts[])
{
    UNUSED(vr), UNUSED(n), UNUSED(shifts);
    NO_CLOCKS("fmi3GetShiftDecimal");
}
fmi3Status fmi3GetShiftFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3UInt64 counters[],
                                fmi3UInt64 resolutions[])
{
    UNUSED(vr), UNUSED(n), UNUSED(counters), UNUSED(resolutions);
    NO_CLOCKS("fmi3GetShiftFraction");
}
fmi3Status fmi3SetIntervalDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3Float64 intervals[])
{
    UNUSED(vr), UNUSED(n), UNUSED(intervals);
    NO_CLOCKS("fmi3SetIntervalDecimal");
}
fmi3Status fmi3SetIntervalFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3UInt64 counters[],
                                   const fmi3UInt64 resolutions[])
{
    UNUSED(vr), UNUSED(n), UNUSED(counters), UNUSED(resolutions);
    NO_CLOCKS("fmi3SetIntervalFraction");
}
fmi3Status fmi3SetShiftDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3Float64 shifts[])
{
    UNUSED(vr), UNUSED(n), UNUSED(shifts);
    NO_CLOCKS("fmi3SetShiftDecimal");
}
fmi3Status fmi3SetShiftFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3UInt64 counters[],
                                const fmi3UInt64 resolutions[])
{
    UNUSED(vr), UNUSED(n), UNUSED(counters), UNUSED(resolutions);
    NO_CLOCKS("fmi3SetShiftFraction");
}
fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance c) { NO_CLOCKS("fmi3EvaluateDiscreteStates"); }
fmi3Status fmi3ActivateModelPartition(fmi3Instance c, fmi3ValueReference clockReference, fmi3Float64 activationTime)
{
    UNUSED(clockReference), UNUSED(activationTime);
    CHECK(c);
    return unsupported(INST, "fmi3ActivateModelPartition (scheduled execution is not supported)");
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3Int32 orders[],
                                    fmi3Float64 values[], size_t nValues)
{
    UNUSED(vr), UNUSED(nvr), UNUSED(orders), UNUSED(values), UNUSED(nValues);
    CHECK(c);
    REQUIRE(fmi3GetOutputDerivatives, "fmi3GetOutputDerivatives");
    return unsupported(INST, "fmi3GetOutputDerivatives (maxOutputDerivativeOrder = 0)");
}

/* ---- event mode (both interfaces) ----------------------------------------------------------- */
static void put(fmi3Boolean *flag, int value)
{
    if (flag) *flag = value ? fmi3True : fmi3False;
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance c, fmi3Boolean *discreteStatesNeedUpdate, fmi3Boolean *terminateSimulation,
                                    fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged, fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime)
{
    CHECK(c);
    REQUIRE(fmi3UpdateDiscreteStates, "fmi3UpdateDiscreteStates");
    PgEventFlags f;
    memset(&f, 0, sizeof f);
    int st = pgb_update_discrete_states(INST->b, &f);
    if (st > ST_WARNING) return (fmi3Status)st;
    put(discreteStatesNeedUpdate, f.discrete_states_need_update), put(terminateSimulation, f.terminate_simulation);
    put(nominalsOfContinuousStatesChanged, f.nominals_changed), put(valuesOfContinuousStatesChanged, f.values_changed);
    put(nextEventTimeDefined, f.next_event_time_defined);
    if (nextEventTime) *nextEventTime = f.next_event_time;
    return (fmi3Status)st;
}

/* ---- model exchange ------------------------------------------------------------------------- */
fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance c)
{
    CHECK(c);
    REQUIRE(fmi3EnterContinuousTimeMode, "fmi3EnterContinuousTimeMode");
    int st = pgb_enter_continuous_time_mode(INST->b);
    LEADS_TO(st, MODE_CONTINUOUS);
    return (fmi3Status)st;
}

/* A count an importer passes must be the FMU's: the message names both. */
static int right_count(Inst *in, const char *function, const char *arg, size_t given, size_t have, const char *what)
{
    if (given == have) return 1;
    char text[300];
    snprintf(text, sizeof text, "%s refused: %s = %zu, and this FMU has %s = %zu", function, arg, given, what, have);
    emit(in, ST_ERROR, "logStatusError", text);
    return 0;
}

#define NX (INST->nx)
#define NZ (INST->nz)

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance c, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation)
{
    UNUSED(noSetFMUStatePriorToCurrentPoint);
    CHECK(c);
    REQUIRE(fmi3CompletedIntegratorStep, "fmi3CompletedIntegratorStep");
    int enter = 0, terminate = 0;
    int st = pgb_completed_integrator_step(INST->b, &enter, &terminate);
    if (st > ST_WARNING) return (fmi3Status)st;
    put(enterEventMode, enter), put(terminateSimulation, terminate);
    return (fmi3Status)st;
}

fmi3Status fmi3SetTime(fmi3Instance c, fmi3Float64 time)
{
    CHECK(c);
    REQUIRE(fmi3SetTime, "fmi3SetTime");
    return (fmi3Status)pgb_set_time(INST->b, time);
}

fmi3Status fmi3SetContinuousStates(fmi3Instance c, const fmi3Float64 continuousStates[], size_t nContinuousStates)
{
    CHECK(c);
    REQUIRE(fmi3SetContinuousStates, "fmi3SetContinuousStates");
    if (!right_count(INST, "fmi3SetContinuousStates", "nContinuousStates", nContinuousStates, NX, "nx")) return fmi3Error;
    if (nContinuousStates) NOT_NULL(continuousStates, "fmi3SetContinuousStates", "continuousStates");
    return (fmi3Status)pgb_set_continuous_states(INST->b, continuousStates, nContinuousStates);
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance c, fmi3Float64 derivatives[], size_t nContinuousStates)
{
    CHECK(c);
    REQUIRE(fmi3GetContinuous, "fmi3GetContinuousStateDerivatives");
    if (!right_count(INST, "fmi3GetContinuousStateDerivatives", "nContinuousStates", nContinuousStates, NX, "nx"))
        return fmi3Error;
    if (nContinuousStates) NOT_NULL(derivatives, "fmi3GetContinuousStateDerivatives", "derivatives");
    return (fmi3Status)pgb_get_derivatives(INST->b, derivatives, nContinuousStates);
}

fmi3Status fmi3GetEventIndicators(fmi3Instance c, fmi3Float64 eventIndicators[], size_t nEventIndicators)
{
    CHECK(c);
    REQUIRE(fmi3GetContinuous, "fmi3GetEventIndicators");
    if (!right_count(INST, "fmi3GetEventIndicators", "nEventIndicators", nEventIndicators, NZ, "nz")) return fmi3Error;
    if (nEventIndicators) NOT_NULL(eventIndicators, "fmi3GetEventIndicators", "eventIndicators");
    return (fmi3Status)pgb_get_event_indicators(INST->b, eventIndicators, nEventIndicators);
}

fmi3Status fmi3GetContinuousStates(fmi3Instance c, fmi3Float64 continuousStates[], size_t nContinuousStates)
{
    CHECK(c);
    REQUIRE(fmi3GetContinuous, "fmi3GetContinuousStates");
    if (!right_count(INST, "fmi3GetContinuousStates", "nContinuousStates", nContinuousStates, NX, "nx")) return fmi3Error;
    if (nContinuousStates) NOT_NULL(continuousStates, "fmi3SetContinuousStates", "continuousStates");
    return (fmi3Status)pgb_get_continuous_states(INST->b, continuousStates, nContinuousStates);
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance c, fmi3Float64 nominals[], size_t nContinuousStates)
{
    CHECK(c);
    REQUIRE(fmi3GetContinuous, "fmi3GetNominalsOfContinuousStates");
    if (!right_count(INST, "fmi3GetNominalsOfContinuousStates", "nContinuousStates", nContinuousStates, NX, "nx"))
        return fmi3Error;
    if (nContinuousStates) NOT_NULL(nominals, "fmi3GetNominalsOfContinuousStates", "nominals");
    return (fmi3Status)pgb_get_nominals(INST->b, nominals, nContinuousStates);
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance c, size_t *nEventIndicators)
{
    CHECK(c);
    REQUIRE(fmi3GetNumbers, "fmi3GetNumberOfEventIndicators");
    NOT_NULL(nEventIndicators, "fmi3GetNumberOfEventIndicators", "nEventIndicators");
    *nEventIndicators = NZ;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance c, size_t *nContinuousStates)
{
    CHECK(c);
    REQUIRE(fmi3GetNumbers, "fmi3GetNumberOfContinuousStates");
    NOT_NULL(nContinuousStates, "fmi3GetNumberOfContinuousStates", "nContinuousStates");
    *nContinuousStates = NX;
    return fmi3OK;
}

/* ---- co-simulation -------------------------------------------------------------------------- */
fmi3Status fmi3EnterStepMode(fmi3Instance c)
{
    CHECK(c);
    REQUIRE(fmi3EnterStepMode, "fmi3EnterStepMode");
    int st = pgb_enter_step_mode(INST->b);
    LEADS_TO(st, MODE_STEP);
    return (fmi3Status)st;
}

fmi3Status fmi3DoStep(fmi3Instance c, fmi3Float64 currentCommunicationPoint, fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint, fmi3Boolean *eventHandlingNeeded,
                      fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime)
{
    UNUSED(noSetFMUStatePriorToCurrentPoint);
    CHECK(c);
    REQUIRE(fmi3DoStep, "fmi3DoStep");
    /* the FMU stopped before the event's jump: a step on would skip it */
    if (INST->event_pending) {
        emit(INST, ST_ERROR, "logStatusError", "fmi3DoStep refused: the last fmi3DoStep returned eventHandlingNeeded "
             "= true, and the importer has to enter Event Mode (fmi3EnterEventMode) to handle the event before the "
             "next step (FMI 3.0 section 4.2.1, Step Mode: fmi3DoStep, fmi3EnterEventMode)");
        return fmi3Error;
    }
    int event = 0, terminate = 0, early = 0;
    double last = 0.0;
    int st = pgb_do_step3(INST->b, currentCommunicationPoint, communicationStepSize, &event, &terminate, &early, &last);
    if (st > ST_WARNING) return (fmi3Status)st;
    INST->event_pending = event && INST->event_mode_used;
    put(eventHandlingNeeded, event), put(terminateSimulation, terminate), put(earlyReturn, early);
    if (lastSuccessfulTime) *lastSuccessfulTime = last;
    return (fmi3Status)st;
}
