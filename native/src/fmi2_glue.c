/* The FMI 2.0 interface of every native model: the exported fmi2* functions (Co-Simulation and
 * those common to both interfaces; Model Exchange: fmi2_me.c). Each first checks that the call
 * is legal in the instance's state (fmi2_states.h), then calls the instance core (instance.c: the
 * transitions, the checks of values, the FMU-state format; see instance.h), which the FMI 3.0
 * glue (fmi3_glue.c) calls too; fmi2DoStep steps with the model's own model_step. What
 * only FMI 2.0 has (the status queries, the entry points of the partial derivatives) is here.
 */
#include "fmi2Functions.h"
#include "glue.h"
#include "instance.h"
#include "fmi2_states.h" /* MASK_<function>, LEGAL */
#include "partials.h" /* directional and output derivatives (partials.c) */

int legal2(Instance *inst, unsigned mask, const char *function)
{
    static const char *const names[] = {"instantiated",         "initialization mode",
                                        "step complete",        "event mode",
                                        "continuous-time mode", "terminated"};
    if (!instance_ok(inst, function)) {
        return 0;
    }
    inst->fn = function; /* the core's messages name it */
    if (mask & IN2(inst->s.phase)) {
        return 1;
    }
    log_message(inst, fmi2Error, "logStatusError", "%s cannot be called in %s", function,
                names[inst->s.phase]);
    return 0;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                              fmi2Boolean loggingOn)
{
    return instance_new(instanceName, fmuType, fmuGUID, fmuResourceLocation, functions, visible,
                        loggingOn);
}

void fmi2FreeInstance(fmi2Component c)
{
    instance_free(c);
}

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[])
{
    LEGAL(c, fmi2SetDebugLogging);
    return instance_set_logging(c, loggingOn, nCategories, categories);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    LEGAL(c, fmi2SetupExperiment);
    return instance_setup(c, toleranceDefined, tolerance, startTime, stopTimeDefined, stopTime);
}

TRANSITION(fmi2EnterInitializationMode, instance_enter_initialization)
TRANSITION(fmi2ExitInitializationMode, instance_exit_initialization)
TRANSITION(fmi2Terminate, instance_terminate)
TRANSITION(fmi2Reset, instance_reset)

/* The getters and setters: legal in the instance's state, then the core's of the same type. */
#define VALUES(function, core, ctype)                                                              \
    fmi2Status function(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,             \
                        ctype value[])                                                          \
    {                                                                                           \
        LEGAL(c, function);                                                                     \
        return core(c, vr, nvr, value);                                                         \
    }

VALUES(fmi2GetReal, instance_get_real, fmi2Real)
VALUES(fmi2GetInteger, instance_get_integer, fmi2Integer)
VALUES(fmi2GetBoolean, instance_get_boolean, fmi2Boolean)
VALUES(fmi2GetString, instance_get_string, fmi2String)
VALUES(fmi2SetReal, instance_set_real, const fmi2Real)
VALUES(fmi2SetInteger, instance_set_integer, const fmi2Integer)
VALUES(fmi2SetBoolean, instance_set_boolean, const fmi2Boolean)
VALUES(fmi2SetString, instance_set_string, const fmi2String)

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint,
                      fmi2Real communicationStepSize, fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    LEGAL(c, fmi2DoStep);
    return instance_do_step(c, currentCommunicationPoint, communicationStepSize,
                            noSetFMUStatePriorToCurrentPoint, model_step);
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    LEGAL(c, fmi2GetFMUstate);
    return instance_get_state(c, state);
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state)
{
    LEGAL(c, fmi2SetFMUstate);
    return instance_set_state(c, state);
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    LEGAL(c, fmi2FreeFMUstate);
    return instance_free_state(c, state);
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t *size)
{
    LEGAL(c, fmi2SerializedFMUstateSize);
    return instance_serialized_size(c, state, size);
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte serializedState[],
                                 size_t size)
{
    LEGAL(c, fmi2SerializeFMUstate);
    return instance_serialize(c, state, serializedState, size);
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *state)
{
    LEGAL(c, fmi2DeSerializeFMUstate);
    return instance_deserialize(c, serializedState, size, state);
}

/* A function this FMU does not provide: fmi2Error, logged when the instance is alive. */
#define REFUSE(c, function, ...)                                                                   \
    (instance_ok((Instance *)(c), function) ? ERROR((Instance *)(c), __VA_ARGS__) : fmi2Error)

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2CancelStep(fmi2Component c)
{
    return REFUSE(c, "fmi2CancelStep", "fmi2CancelStep: doStep never runs asynchronously");
}

/* --- what only FMI 2.0 has: status queries, derivatives' entry points ------------------------ */

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[],
                                        size_t nUnknown, const fmi2ValueReference vKnown_ref[],
                                        size_t nKnown, const fmi2Real dvKnown[],
                                        fmi2Real dvUnknown[])
{
    LEGAL(c, fmi2GetDirectionalDerivative);
    return partials_directional((Instance *)c, "fmi2GetDirectionalDerivative", vUnknown_ref,
                                nUnknown, vKnown_ref, nKnown, dvKnown, dvUnknown);
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[])
{
    (void)vr, (void)nvr, (void)order, (void)value;
    return REFUSE(c, "fmi2SetRealInputDerivatives",
                  "input derivatives are not supported (canInterpolateInputs=false)");
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[])
{
    LEGAL(c, fmi2GetRealOutputDerivatives);
    return partials_output_derivatives((Instance *)c, "fmi2GetRealOutputDerivatives", vr, nvr,
                                       order, value);
}

/* A status query's arguments: value not NULL and s the one kind the query answers here. */
static int status_query_ok(Instance *inst, const char *function, const void *value,
                           fmi2StatusKind s, fmi2StatusKind answered, const char *answered_name)
{
    if (!value) {
        log_message(inst, fmi2Error, "logStatusError", "%s: value is NULL", function);
        return 0;
    }
    if (s != answered) {
        log_message(inst, fmi2Error, "logStatusError", "%s supports %s only", function,
                    answered_name);
        return 0;
    }
    return 1;
}

/* A status query that answers one kind, with the value of answer. */
#define STATUS_ANSWERED(function, ctype, kind, answer)                                             \
    fmi2Status function(fmi2Component c, const fmi2StatusKind s, ctype *value)                  \
    {                                                                                           \
        LEGAL(c, function);                                                                     \
        if (!status_query_ok((Instance *)c, #function, value, s, kind, #kind)) {               \
            return fmi2Error;                                                                   \
        }                                                                                       \
        *value = answer;                                                                        \
        return fmi2OK;                                                                          \
    }

/* A status query with nothing to answer. */
#define STATUS_NONE(function, ctype, why)                                                          \
    fmi2Status function(fmi2Component c, const fmi2StatusKind s, ctype *value)                  \
    {                                                                                           \
        (void)s, (void)value;                                                                   \
        return REFUSE(c, #function, #function ": " why);                                        \
    }

STATUS_NONE(fmi2GetStatus, fmi2Status, "no asynchronous step to report on")
STATUS_ANSWERED(fmi2GetRealStatus, fmi2Real, fmi2LastSuccessfulTime, ((Instance *)c)->s.last_time)
STATUS_NONE(fmi2GetIntegerStatus, fmi2Integer, "no integer status")
/* fmi2Terminated is true after a refused step: the same step would be refused again (the model
 * is deterministic), so the master must stop (or go on from another FMU state or with a smaller
 * step). */
STATUS_ANSWERED(fmi2GetBooleanStatus, fmi2Boolean, fmi2Terminated,
                ((Instance *)c)->step_refused ? fmi2True : fmi2False)
STATUS_NONE(fmi2GetStringStatus, fmi2String, "no string status")
