/* The FMI 3.0 interface of every native model (Co-Simulation, Model Exchange and, for a model
 * with a sample clock, Scheduled Execution), over the instance core (instance.c, instance_me.c)
 * that the FMI 2.0 glue calls too (so do fmi3_events.c: Model Exchange and the clock, and
 * fmi3_stubs.c: what is not provided): one set of checks (parameters, non-finite inputs,
 * FMU-state validation) and one FMU-state format for both standards. The call order is checked
 * here, against the FMI 3.0 state machine (fmi3_states.h, WRAP). What FMI 3 adds is here: the `independent` time variable (value reference VR_TIME, read-only), the nValues
 * argument, fmi3Boolean (bool) arrays, the log callback without instance name, fmi3DoStep's extra
 * results, and the sample clock of Scheduled Execution (fmi3ActivateModelPartition at a tick = an
 * event of the model's Model Exchange side at that time: the samples due are taken, outputs
 * updated). Co-Simulation (fmi3_cosim.c) samples inside doStep as under FMI 2.0, so a host
 * without clock support runs it unchanged; with eventModeUsed the clock's ticks are events (early
 * return, the sample in Event Mode); a model with discrete-state switches (the plant) offers
 * early return, the intermediate update and event mode at each switch.
 */
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>

#include "fmi3Functions.h"
#include "glue.h"
#include "instance.h"
#include "fmi3_wrapper.h" /* Wrapper, WRAP, FAIL */
#if HAS_EARLY_RETURN
/* model.c: model_step that stops at the first discrete-state switch inside the step, its work
 * added to *work (the fmi3DoStep's so far: the bounds hold for that whole) */
int model_step_early(Data *d, double t, double h, double *reached, StepWork *work, char *msg);
#endif

#ifndef MODEL_EXCHANGE
#error "the FMI 3 layer needs the model's Model Exchange side (config.h: MODEL_EXCHANGE)"
#endif

/* The model step fmi3DoStep takes (through instance_do_step): the model's own, or, where early
 * return is on, one that stops at an event. instance_do_step steps the instance's own Data
 * (inst->s.d, never a copy: the early-return test would fail otherwise), so d leads to the
 * instance and its logger environment, the Wrapper. */
int model_step_fmi3(Data *d, double t, double h, char *msg)
{
    const Instance *inst =
        (const Instance *)((const char *)d - offsetof(Instance, s) - offsetof(Snapshot, d));
    Wrapper *w = (Wrapper *)inst->cb.componentEnvironment;
#if HAS_EARLY_RETURN
    if (w->early_return && w->inner == inst) {
        return model_step_early(d, t, h, &w->reached, &w->work, msg);
    }
#endif
#if HAS_CLOCK
    if (w->clock_events && w->inner == inst) {
        const int stop = w->update ? TICK_UPDATE : w->early_allowed ? TICK_EARLY : 0;
        return model_step_to_tick(d, t, h, stop | (w->tick_passed ? TICK_RESUME : 0), &w->reached,
                                  msg);
    }
#endif
    w->reached = t + h;
    return model_step(d, t, h, msg);
}

/* The inner layer's logger: passes the message on to the FMI 3 callback (which is not
 * printf-style, so the inner layer's doubled '%' is undone). */
static void relay(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status,
                  fmi2String category, fmi2String message, ...)
{
    const Wrapper *w = (const Wrapper *)env;
    char text[2 * (MSG_MAX + 64)];
    size_t k = 0;
    (void)name;
    if (!w || !w->log || !message) {
        return;
    }
    for (const char *p = message; *p && k + 1 < sizeof text;) {
        if (p[0] == '%' && p[1] == '%') {
            p++;
        }
        text[k++] = *p++;
    }
    text[k] = '\0';
    w->log(w->env, status <= fmi2Fatal ? (fmi3Status)status : fmi3Error,
           category ? category : "logAll", text);
}

fmi3Status status3(fmi2Status s)
{
    return s <= fmi2Fatal ? (fmi3Status)s : fmi3Error;
}

/* The core's transition's status as fmi3Status; where it succeeded, the wrapper is in state and
 * the sample clock not active (it is only at a tick in Event Mode, which the caller then sets). */
fmi3Status entered(Wrapper *w, fmi2Status s, State3 state)
{
    if (s <= fmi2Warning) {
        w->state = state;
        w->tick_active = 0;
    }
    return status3(s);
}

/* The wrapper, if instance is a live FMI 3 instance of this FMU (else NULL, said on stderr:
 * the host's logger lives in the instance and cannot be trusted then). */
Wrapper *wrapper_of(fmi3Instance instance, const char *function)
{
    Wrapper *w = (Wrapper *)instance;
    if (!w) {
        return NULL;
    }
    if (w->magic != WRAPPER_MAGIC) {
        fprintf(stderr, "%s: %s called on an instance that is not a live %s instance\n",
                MODEL_IDENTIFIER_STR, function, MODEL_IDENTIFIER_STR);
        return NULL;
    }
    return w;
}


static Wrapper *instantiate(Kind kind, fmi3String name, fmi3String token, fmi3Boolean visible,
                            fmi3Boolean logging_on, fmi3InstanceEnvironment env,
                            fmi3LogMessageCallback log)
{
    fmi2CallbackFunctions cb;
    Wrapper *w = (Wrapper *)calloc(1, sizeof(Wrapper));
    if (!w) {
        if (log) {
            log(env, fmi3Error, "logStatusError", "out of memory");
        }
        return NULL;
    }
    w->magic = WRAPPER_MAGIC;
    w->kind = kind;
    w->state = ST_INSTANTIATED;
    w->env = env;
    w->log = log;
    cb.logger = relay;
    cb.allocateMemory = calloc;
    cb.freeMemory = free;
    cb.stepFinished = NULL;
    cb.componentEnvironment = w;
    w->inner = (Instance *)instance_new(name, kind == K_CS ? fmi2CoSimulation : fmi2ModelExchange,
                                           token, NULL, &cb, visible ? fmi2True : fmi2False,
                                           logging_on ? fmi2True : fmi2False);
    if (!w->inner) {
        free(w);
        return NULL;
    }
    w->inner->type_names = FMI3_TYPE_NAMES;
    return w;
}

/* --- common functions ----------------------------------------------------------------------- */

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[])
{
    WRAP(fmi3SetDebugLogging);
    return status3(instance_set_logging(w->inner, loggingOn ? fmi2True : fmi2False, nCategories,
                                  categories));
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible,
                                          fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage)
{
    Wrapper *w;
    (void)resourcePath;
    w = instantiate(K_ME, instanceName, instantiationToken, visible, loggingOn,
                    instanceEnvironment, logMessage);
    if (w) {
        w->clock_events = HAS_CLOCK; /* clocked Model Exchange: the ticks are time events */
    }
    return w;
}

/* NULL if the importer's requiredIntermediateVariables are all outputs of a model with
 * intermediate update (the only variables with intermediateUpdate="true"), else why not. */
static const char *required_outputs(const fmi3ValueReference vr[], size_t n)
{
    if (n > 0 && !HAS_EARLY_RETURN && !HAS_CLOCK) {
        return MODEL_IDENTIFIER_STR " provides no intermediate update";
    }
    if (n > 0 && !vr) {
        return "fmi3InstantiateCoSimulation: requiredIntermediateVariables is NULL";
    }
    for (size_t k = 0; k < n; k++) {
        if (vr[k] >= N_VARS || VARS[vr[k]].causality != C_OUTPUT) {
            return "fmi3InstantiateCoSimulation: a required intermediate variable is not an "
                   "output (only outputs have intermediateUpdate=\"true\")";
        }
    }
    return NULL;
}

fmi3Instance fmi3InstantiateCoSimulation(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
    fmi3Boolean visible, fmi3Boolean loggingOn, fmi3Boolean eventModeUsed,
    fmi3Boolean earlyReturnAllowed, const fmi3ValueReference requiredIntermediateVariables[],
    size_t nRequiredIntermediateVariables, fmi3InstanceEnvironment instanceEnvironment,
    fmi3LogMessageCallback logMessage, fmi3IntermediateUpdateCallback intermediateUpdate)
{
    Wrapper *w;
    const char *refused = required_outputs(requiredIntermediateVariables,
                                           nRequiredIntermediateVariables);
    (void)resourcePath;
    if (!HAS_EARLY_RETURN && !HAS_CLOCK && eventModeUsed) {
        refused = MODEL_IDENTIFIER_STR " has no event mode in co-simulation (hasEventMode=false)";
    }
    if (refused) {
        if (logMessage) {
            logMessage(instanceEnvironment, fmi3Error, "logStatusError", refused);
        }
        return NULL;
    }
    w = instantiate(K_CS, instanceName, instantiationToken, visible, loggingOn,
                    instanceEnvironment, logMessage);
    if (w) { /* the plant stops its step at each switch for early return or the callback, the
              * controller (with event mode) at each tick */
        w->early_allowed = (HAS_EARLY_RETURN || HAS_CLOCK) && earlyReturnAllowed;
        w->event_mode_used = eventModeUsed != fmi3False;
        w->clock_events = HAS_CLOCK && w->event_mode_used; /* the controller: ticks are events */
        w->update = HAS_EARLY_RETURN || HAS_CLOCK ? intermediateUpdate : NULL;
        w->early_return = w->early_allowed || w->update != NULL;
    }
    return w;
}

fmi3Instance fmi3InstantiateScheduledExecution(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
    fmi3Boolean visible, fmi3Boolean loggingOn, fmi3InstanceEnvironment instanceEnvironment,
    fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
    fmi3LockPreemptionCallback lockPreemption, fmi3UnlockPreemptionCallback unlockPreemption)
{
    (void)resourcePath, (void)clockUpdate, (void)lockPreemption, (void)unlockPreemption;
#if HAS_CLOCK && defined(MODEL_EXCHANGE)
    return instantiate(K_SE, instanceName, instantiationToken, visible, loggingOn,
                       instanceEnvironment, logMessage);
#else
    (void)instanceName, (void)instantiationToken, (void)visible, (void)loggingOn;
    if (logMessage) {
        logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                   MODEL_IDENTIFIER_STR " (this FMU) has no Scheduled Execution interface");
    }
    return NULL;
#endif
}

void fmi3FreeInstance(fmi3Instance instance)
{
    Wrapper *w = wrapper_of(instance, "fmi3FreeInstance");
    if (!w || !state_allows(w, MASK_fmi3FreeInstance, "fmi3FreeInstance")) {
        return; /* refused inside the intermediate update: fmi3DoStep goes on with w */
    }
    instance_free(w->inner);
    *(volatile unsigned *)&w->magic = 0; /* volatile: the store must survive free() */
    free(w);
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined,
                                       fmi3Float64 tolerance, fmi3Float64 startTime,
                                       fmi3Boolean stopTimeDefined, fmi3Float64 stopTime)
{
    fmi2Status s;
    WRAP(fmi3EnterInitializationMode);
    s = instance_setup(w->inner, toleranceDefined ? fmi2True : fmi2False, tolerance,
                            startTime, stopTimeDefined ? fmi2True : fmi2False, stopTime);
    if (s == fmi2OK) {
        s = instance_enter_initialization(w->inner);
    }
    if (s == fmi2OK) {
        w->state = ST_INITIALIZATION;
    }
    return status3(s);
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance)
{
    fmi3Status s;
    WRAP(fmi3ExitInitializationMode);
    s = status3(instance_exit_initialization(w->inner));
    if (s <= fmi3Warning) { /* co-simulation with eventModeUsed goes into Event Mode */
        w->state = w->kind == K_ME   ? ST_EVENT
                   : w->kind == K_SE ? ST_CLOCK_ACTIVATION
                   : w->event_mode_used ? ST_EVENT
                                        : ST_STEP;
        w->tick_active = w->clock_events; /* tick 0, sampled in Initialization Mode */
    }
    return s;
}

fmi3Status fmi3EnterEventMode(fmi3Instance instance)
{
    fmi3Status s;
    WRAP(fmi3EnterEventMode);
    if (w->kind == K_CS) {
        return cs_enter_event_mode(w);
    }
    s = status3(instance_enter_event_mode(w->inner));
    if (s <= fmi3Warning) {
        w->state = ST_EVENT;
#if HAS_CLOCK
        w->tick_active = w->clock_events && tick_due(w); /* a time event at a tick */
#endif
    }
    return s;
}

fmi3Status fmi3Terminate(fmi3Instance instance)
{
    WRAP(fmi3Terminate);
    return entered(w, instance_terminate(w->inner), ST_TERMINATED);
}

fmi3Status fmi3Reset(fmi3Instance instance)
{
    WRAP(fmi3Reset);
    w->state = ST_INSTANTIATED;
    return status3(instance_reset(w->inner));
}

/* --- FMU state: the instance core's (validated on set and deserialization) ------------------- */

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState)
{
    WRAP(fmi3GetFMUState);
    return status3(instance_get_state(w->inner, FMUState));
}

fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState)
{
    fmi3Status s;
    WRAP(fmi3SetFMUState);
    s = status3(instance_set_state(w->inner, FMUState));
    if (s <= fmi3Warning) {
        w->state = state_of_core(w);
#if HAS_CLOCK
        w->tick_active = w->clock_events && w->state == ST_EVENT && tick_pending(w);
#endif
    }
    return s;
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState)
{
    WRAP(fmi3FreeFMUState);
    return status3(instance_free_state(w->inner, FMUState));
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState, size_t *size)
{
    WRAP(fmi3SerializedFMUStateSize);
    return status3(instance_serialized_size(w->inner, FMUState, size));
}

fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState,
                                 fmi3Byte serializedState[], size_t size)
{
    WRAP(fmi3SerializeFMUState);
    return status3(instance_serialize(w->inner, FMUState, (fmi2Byte *)serializedState, size));
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[],
                                   size_t size, fmi3FMUState *FMUState)
{
    WRAP(fmi3DeserializeFMUState);
    return status3(instance_deserialize(w->inner, (const fmi2Byte *)serializedState, size,
                                      FMUState));
}
/* --- Co-Simulation: fmi3DoStep, fmi3EnterStepMode in fmi3_cosim.c ---------------------------- */
