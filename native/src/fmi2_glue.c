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

fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    LEGAL(c, fmi2EnterInitializationMode);
    return instance_enter_initialization(c);
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    LEGAL(c, fmi2ExitInitializationMode);
    return instance_exit_initialization(c);
}

fmi2Status fmi2Terminate(fmi2Component c)
{
    LEGAL(c, fmi2Terminate);
    return instance_terminate(c);
}

fmi2Status fmi2Reset(fmi2Component c)
{
    LEGAL(c, fmi2Reset);
    return instance_reset(c);
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    LEGAL(c, fmi2GetReal);
    return instance_get_real(c, vr, nvr, value);
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Integer value[])
{
    LEGAL(c, fmi2GetInteger);
    return instance_get_integer(c, vr, nvr, value);
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Boolean value[])
{
    LEGAL(c, fmi2GetBoolean);
    return instance_get_boolean(c, vr, nvr, value);
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         fmi2String value[])
{
    LEGAL(c, fmi2GetString);
    return instance_get_string(c, vr, nvr, value);
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                       const fmi2Real value[])
{
    LEGAL(c, fmi2SetReal);
    return instance_set_real(c, vr, nvr, value);
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Integer value[])
{
    LEGAL(c, fmi2SetInteger);
    return instance_set_integer(c, vr, nvr, value);
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Boolean value[])
{
    LEGAL(c, fmi2SetBoolean);
    return instance_set_boolean(c, vr, nvr, value);
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         const fmi2String value[])
{
    LEGAL(c, fmi2SetString);
    return instance_set_string(c, vr, nvr, value);
}

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

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value)
{
    (void)s, (void)value;
    return REFUSE(c, "fmi2GetStatus", "fmi2GetStatus: no asynchronous step to report on");
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value)
{
    Instance *inst = (Instance *)c;
    LEGAL(c, fmi2GetRealStatus);
    if (!value) {
        return ERROR(inst, "fmi2GetRealStatus: value is NULL");
    }
    if (s != fmi2LastSuccessfulTime) {
        return ERROR(inst, "fmi2GetRealStatus supports fmi2LastSuccessfulTime only");
    }
    *value = inst->s.last_time;
    return fmi2OK;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value)
{
    (void)s, (void)value;
    return REFUSE(c, "fmi2GetIntegerStatus", "fmi2GetIntegerStatus: no integer status");
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value)
{
    Instance *inst = (Instance *)c;
    LEGAL(c, fmi2GetBooleanStatus);
    if (!value) {
        return ERROR(inst, "fmi2GetBooleanStatus: value is NULL");
    }
    if (s != fmi2Terminated) {
        return ERROR(inst, "fmi2GetBooleanStatus supports fmi2Terminated only");
    }
    /* after a refused step: the same step would be refused again (the model is deterministic),
     * so the master must stop (or go on from another FMU state or with a smaller step) */
    *value = inst->step_refused ? fmi2True : fmi2False;
    return fmi2OK;
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value)
{
    (void)s, (void)value;
    return REFUSE(c, "fmi2GetStringStatus", "fmi2GetStringStatus: no string status");
}
