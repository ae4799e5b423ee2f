/* The standard's call states: which FMI function may be called in which state of an instance, for
 * FMI 2.0 co-simulation and FMI 3.0 model exchange and co-simulation, in one table — checked at
 * every entry point (as the Modelica Reference-FMUs check theirs with ASSERT_STATE masks), with
 * the state each successful call leads to.
 *
 * An instance's state is one bit of `CallState`. A rule gives, per interface, the states a
 * function is allowed in; 0 for an interface means the function is not one of that interface's.
 * A call in another state is refused with Error and a message naming the function, the state and
 * where the standard allows it; nothing else happens, so the instance stays usable.
 *
 * Included by the FMI entry files fmi2/pg_fmi2.c and fmi3/pg_fmi3.c (one table for both backends
 * of the FMUs: the adapter with generated C, and with the FMU's Python code). */
#ifndef POGOFMU_CALL_STATES_H
#define POGOFMU_CALL_STATES_H

typedef enum {
    MODE_INSTANTIATED = 1u << 0,   /* after instantiate, fmi2Reset / fmi3Reset */
    MODE_INITIALIZATION = 1u << 1, /* Initialization Mode */
    MODE_STEP = 1u << 2,           /* FMI 2.0: slave initialized, step complete; FMI 3.0: Step Mode */
    MODE_EVENT = 1u << 3,          /* FMI 3.0 Event Mode */
    MODE_CONTINUOUS = 1u << 4,     /* FMI 3.0 Continuous-Time Mode (model exchange) */
    MODE_TERMINATED = 1u << 5,     /* after terminate */
    MODE_STEP_FAILED = 1u << 6,    /* FMI 2.0 after a step returned Discard (FMI 3.0: Step Discarded) */
    /* FMI 3.0 Configuration Mode and Reconfiguration Mode: entered only by an FMU with structural
     * parameters, so never by these; in the table so that every rule reads as the standard's text
     * (bit 8 is MODE_EVENT_PENDING, below) */
    MODE_CONFIGURATION = 1u << 7,
    MODE_RECONFIGURATION = 1u << 9
} CallState;

#define MODE_ANY (MODE_INSTANTIATED | MODE_INITIALIZATION | MODE_STEP | MODE_EVENT | MODE_CONTINUOUS | \
                  MODE_TERMINATED | MODE_STEP_FAILED | MODE_CONFIGURATION | MODE_RECONFIGURATION)
#define MODE_RUNNING (MODE_INITIALIZATION | MODE_STEP | MODE_EVENT | MODE_CONTINUOUS | MODE_STEP_FAILED | \
                      MODE_TERMINATED)

typedef struct {
    const char *name;
    unsigned cs; /* allowed states of a co-simulation instance (0: not a co-simulation function) */
    unsigned me; /* ... of a model-exchange instance (0: not a model-exchange function) */
} CallRule;

/* FMI 2.0 co-simulation (the FMUs offer no FMI 2.0 model exchange) */
#define FMI2_RULES(X)                                                                                      \
    X(fmi2SetDebugLogging, MODE_ANY, 0)                                                                   \
    X(fmi2SetupExperiment, MODE_INSTANTIATED, 0)                                                          \
    X(fmi2EnterInitializationMode, MODE_INSTANTIATED, 0)                                                  \
    X(fmi2ExitInitializationMode, MODE_INITIALIZATION, 0)                                                 \
    X(fmi2Terminate, MODE_STEP | MODE_STEP_FAILED, 0)                                                     \
    X(fmi2Reset, MODE_ANY, 0)                                                                             \
    X(fmi2GetValues, MODE_INITIALIZATION | MODE_STEP | MODE_STEP_FAILED | MODE_TERMINATED, 0)             \
    X(fmi2SetValues, MODE_INSTANTIATED | MODE_INITIALIZATION | MODE_STEP, 0)                              \
    X(fmi2FMUstate, MODE_ANY, 0)                                                                          \
    X(fmi2GetDirectionalDerivative, MODE_INITIALIZATION | MODE_STEP | MODE_STEP_FAILED | MODE_TERMINATED, 0) \
    X(fmi2SetRealInputDerivatives, MODE_INSTANTIATED | MODE_INITIALIZATION | MODE_STEP, 0)                \
    X(fmi2GetRealOutputDerivatives, MODE_STEP | MODE_STEP_FAILED | MODE_TERMINATED, 0)                    \
    X(fmi2DoStep, MODE_STEP, 0)                                                                           \
    X(fmi2CancelStep, MODE_STEP, 0)                                                                       \
    X(fmi2GetStatus, MODE_STEP | MODE_STEP_FAILED | MODE_TERMINATED, 0)

/* FMI 3.0: the states follow the "Allowed Function Calls" of each state of the standard (§2.3,
 * §3.2, §4.2). Getters: Instantiated lists fmi3Set{VariableType} and no getter (as FMI 2.0 has none
 * there); the Reference-FMUs allow getters in Instantiated since v0.0.21, these FMUs do not
 * (docs/fmi3.md). Setters: Instantiated, Configuration and Reconfiguration Mode (structural
 * parameters), Initialization Mode, Event Mode, Step Mode, Continuous-Time Mode (continuous inputs
 * and states only) — not Terminated, whose allowed calls are getters only (the Reference-FMUs
 * accept setters there, these FMUs do not, as FMI 2.0 does not). Every fmi3Get<T> / fmi3Set<T>, of
 * a type the FMU has or not, is checked here. The FMU state functions, fmi3Reset and
 * fmi3SetDebugLogging belong to the super state FMU State Settable: every state. The counts
 * (fmi3GetNumberOf...) and dependencies are constants of the FMU: allowed in every state, as by
 * the Reference-FMUs (the standard lists the counts in Instantiated and Event Mode only; importers
 * ask in Continuous-Time Mode). */
#define FMI3_GET (MODE_INITIALIZATION | MODE_EVENT | MODE_CONTINUOUS | MODE_STEP | MODE_STEP_FAILED | \
                  MODE_TERMINATED)
#define FMI3_SET_DISCRETE (MODE_INSTANTIATED | MODE_CONFIGURATION | MODE_RECONFIGURATION | MODE_INITIALIZATION | \
                           MODE_EVENT | MODE_STEP)
#define FMI3_SET_CONTINUOUS (FMI3_SET_DISCRETE | MODE_CONTINUOUS)
#define FMI3_RULES(X)                                                                                      \
    X(fmi3SetDebugLogging, MODE_ANY, MODE_ANY)                                                            \
    X(fmi3EnterInitializationMode, MODE_INSTANTIATED, MODE_INSTANTIATED)                                  \
    X(fmi3ExitInitializationMode, MODE_INITIALIZATION, MODE_INITIALIZATION)                               \
    X(fmi3EnterEventMode, MODE_STEP, MODE_CONTINUOUS)                                                     \
    X(fmi3Terminate, MODE_STEP | MODE_EVENT | MODE_STEP_FAILED, MODE_CONTINUOUS | MODE_EVENT)             \
    X(fmi3Reset, MODE_ANY, MODE_ANY)                                                                      \
    X(fmi3GetValues, FMI3_GET, FMI3_GET)                                                                  \
    X(fmi3SetFloat, FMI3_SET_CONTINUOUS, FMI3_SET_CONTINUOUS)                                             \
    X(fmi3SetDiscrete, FMI3_SET_DISCRETE, FMI3_SET_DISCRETE)                                              \
    X(fmi3FMUState, MODE_ANY, MODE_ANY)                                                                   \
    X(fmi3GetDirectionalDerivative, MODE_INITIALIZATION | MODE_EVENT | MODE_STEP | MODE_TERMINATED,       \
      MODE_INITIALIZATION | MODE_EVENT | MODE_CONTINUOUS | MODE_TERMINATED)                              \
    X(fmi3EnterConfigurationMode, MODE_INSTANTIATED | MODE_STEP, MODE_INSTANTIATED | MODE_EVENT)           \
    X(fmi3ExitConfigurationMode, MODE_CONFIGURATION | MODE_RECONFIGURATION,                               \
      MODE_CONFIGURATION | MODE_RECONFIGURATION)                                                          \
    X(fmi3Clocks, MODE_ANY, MODE_ANY)                                                                     \
    X(fmi3Dependencies, MODE_ANY, MODE_ANY)                                                               \
    X(fmi3UpdateDiscreteStates, MODE_EVENT, MODE_EVENT)                                                   \
    X(fmi3EnterContinuousTimeMode, 0, MODE_EVENT)                                                         \
    X(fmi3CompletedIntegratorStep, 0, MODE_CONTINUOUS)                                                    \
    X(fmi3SetTime, 0, MODE_EVENT | MODE_CONTINUOUS)                                                       \
    X(fmi3SetContinuousStates, 0, MODE_CONTINUOUS)                                                        \
    X(fmi3GetContinuous, 0, MODE_INITIALIZATION | MODE_EVENT | MODE_CONTINUOUS | MODE_TERMINATED)         \
    X(fmi3GetNumbers, MODE_ANY, MODE_ANY)                                                                 \
    X(fmi3EnterStepMode, MODE_EVENT, 0) /* (the standard: from Event Mode only) */                       \
    X(fmi3GetOutputDerivatives, MODE_STEP | MODE_TERMINATED, 0)                                           \
    X(fmi3DoStep, MODE_STEP, 0)

/* An FMU state carries the call state it was taken in (its number, with the flag below), in
 * memory and serialized; a set puts the instance back in it. It is restored only into an instance
 * that can be in that call state: these are the states an instance of each kind can be in (the
 * standard allows getting an FMU state in every one of them). */
#define MODE_EVENT_PENDING (1u << 8) /* FMI 3.0 CS flag: the last fmi3DoStep returned eventHandlingNeeded */
#define MODE_FLAGS MODE_EVENT_PENDING
#define FMI2_STATE_MODES (MODE_INSTANTIATED | MODE_INITIALIZATION | MODE_STEP | MODE_STEP_FAILED | MODE_TERMINATED)
#define FMI3_CS_STATE_MODES (MODE_INSTANTIATED | MODE_INITIALIZATION | MODE_STEP | MODE_TERMINATED) /* + Event Mode if used */
#define FMI3_ME_STATE_MODES (MODE_INSTANTIATED | MODE_INITIALIZATION | MODE_EVENT | MODE_CONTINUOUS | MODE_TERMINATED)

#define RULE_ENUM(name, cs, me) RULE_##name,
#define RULE_ENTRY(name, cs, me) {#name, cs, me},
enum { FMI2_RULES(RULE_ENUM) FMI3_RULES(RULE_ENUM) N_RULES };
static const CallRule CALL_RULES[N_RULES] = {FMI2_RULES(RULE_ENTRY) FMI3_RULES(RULE_ENTRY)};
#undef RULE_ENUM
#undef RULE_ENTRY

static const char *mode_name(unsigned mode, int fmi3)
{
    switch (mode) {
    case MODE_INSTANTIATED: return "Instantiated";
    case MODE_INITIALIZATION: return "Initialization Mode";
    case MODE_STEP: return fmi3 ? "Step Mode" : "Step Complete (initialized)";
    case MODE_EVENT: return "Event Mode";
    case MODE_CONTINUOUS: return "Continuous-Time Mode";
    case MODE_TERMINATED: return "Terminated";
    case MODE_STEP_FAILED: return fmi3 ? "Step Discarded" : "Step Failed";
    case MODE_CONFIGURATION: return "Configuration Mode";
    case MODE_RECONFIGURATION: return "Reconfiguration Mode";
    default: return "an unknown state";
    }
}

/* "Instantiated, Initialization Mode or Terminated" for a mask, into `out`. */
static void mode_list(unsigned mask, int fmi3, char *out, size_t size)
{
    const unsigned all[] = {MODE_INSTANTIATED, MODE_CONFIGURATION, MODE_RECONFIGURATION, MODE_INITIALIZATION,
                            MODE_EVENT, MODE_CONTINUOUS, MODE_STEP, MODE_STEP_FAILED, MODE_TERMINATED};
    size_t n = 0, count = 0, total = 0;
    for (size_t i = 0; i < sizeof all / sizeof *all; ++i) total += (mask & all[i]) != 0;
    out[0] = '\0';
    for (size_t i = 0; i < sizeof all / sizeof *all && n < size; ++i) {
        if (!(mask & all[i])) continue;
        ++count;
        n += (size_t)snprintf(out + n, size - n, "%s%s", count == 1 ? "" : count == total ? " or " : ", ",
                              mode_name(all[i], fmi3));
    }
}

/* A state's call state `saved` fits an instance that can be in the states `modes` (and carry the
 * flags `flags`, set in Step Mode only): 1. Else 0, and "<function> refused: ..." in `out`,
 * naming the call state and the kind of instance (`kind`). */
static int state_call_state_fits(unsigned saved, unsigned modes, unsigned flags, int fmi3, const char *function,
                                 const char *kind, char *out, size_t size)
{
    unsigned base = saved & ~MODE_FLAGS, extra = saved & MODE_FLAGS;
    int one = base && !(base & (base - 1));
    if (one && (base & modes) && !(extra & ~flags) && (!extra || base == MODE_STEP)) return 1;
    char where[400];
    mode_list(modes, fmi3, where, sizeof where);
    if (!one || (extra && base != MODE_STEP))
        snprintf(out, size, "%s refused: the FMU state carries no call state this FMU knows (%u)", function, saved);
    else if (!(base & modes))
        snprintf(out, size, "%s refused: the FMU state was taken in %s, and this %s instance cannot be in it (it can "
                 "be in %s)", function, mode_name(base, fmi3), kind, where);
    else
        snprintf(out, size, "%s refused: the FMU state was taken after fmi3DoStep returned eventHandlingNeeded, and "
                 "this %s instance has no Event Mode to handle it", function, kind);
    return 0;
}

#endif
