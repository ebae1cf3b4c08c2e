/* The FMI 2.0 state machine as the FMI 2.0 glue checks it (FMI 2.0, sections 3.2.3 Model
 * Exchange, 4.2.4 Co-Simulation): for every fmi2 function, the states (the instance core's
 * Phase, instance.h) in which it is legal. fmi2_glue.c refuses a call in any other. */
#ifndef FMI2_STATES_H
#define FMI2_STATES_H

#include "instance.h" /* Phase */

#define IN2(phase) (1u << (phase))
#define ST2_ANY                                                                                \
    (IN2(S_INSTANTIATED) | IN2(S_INITIALIZATION) | IN2(S_STEP_COMPLETE) | IN2(S_EVENT_MODE) |  \
     IN2(S_CONTINUOUS_TIME) | IN2(S_TERMINATED))
#define ST2_RUNNING (IN2(S_STEP_COMPLETE) | IN2(S_EVENT_MODE) | IN2(S_CONTINUOUS_TIME))
/* values are read from initialization mode on, set until fmi2Terminate */
#define ST2_READ (ST2_ANY & ~IN2(S_INSTANTIATED))
#define ST2_WRITE (ST2_ANY & ~IN2(S_TERMINATED))
/* the Model Exchange side's equations are evaluated from initialization mode on */
#define ST2_EVALUATED                                                                          \
    (IN2(S_INITIALIZATION) | IN2(S_EVENT_MODE) | IN2(S_CONTINUOUS_TIME) | IN2(S_TERMINATED))

#define MASK_fmi2SetDebugLogging ST2_ANY
#define MASK_fmi2SetupExperiment IN2(S_INSTANTIATED)
#define MASK_fmi2EnterInitializationMode IN2(S_INSTANTIATED)
#define MASK_fmi2ExitInitializationMode IN2(S_INITIALIZATION)
#define MASK_fmi2Terminate ST2_RUNNING
#define MASK_fmi2Reset ST2_ANY

#define MASK_fmi2GetReal ST2_READ
#define MASK_fmi2GetInteger ST2_READ
#define MASK_fmi2GetBoolean ST2_READ
#define MASK_fmi2GetString ST2_READ
#define MASK_fmi2SetReal ST2_WRITE
#define MASK_fmi2SetInteger ST2_WRITE
#define MASK_fmi2SetBoolean ST2_WRITE
#define MASK_fmi2SetString ST2_WRITE

#define MASK_fmi2GetFMUstate ST2_ANY
#define MASK_fmi2SetFMUstate ST2_ANY
#define MASK_fmi2FreeFMUstate ST2_ANY
#define MASK_fmi2SerializedFMUstateSize ST2_ANY
#define MASK_fmi2SerializeFMUstate ST2_ANY
#define MASK_fmi2DeSerializeFMUstate ST2_ANY
#define MASK_fmi2GetDirectionalDerivative ST2_RUNNING

/* Co-Simulation */
#define MASK_fmi2DoStep IN2(S_STEP_COMPLETE)
#define MASK_fmi2GetRealStatus ST2_ANY
#define MASK_fmi2GetBooleanStatus ST2_ANY
#define MASK_fmi2GetRealOutputDerivatives IN2(S_STEP_COMPLETE)

/* Model Exchange (fmi2_me.c) */
#define MASK_fmi2EnterEventMode (IN2(S_EVENT_MODE) | IN2(S_CONTINUOUS_TIME))
#define MASK_fmi2NewDiscreteStates IN2(S_EVENT_MODE)
#define MASK_fmi2EnterContinuousTimeMode IN2(S_EVENT_MODE)
#define MASK_fmi2CompletedIntegratorStep IN2(S_CONTINUOUS_TIME)
#define MASK_fmi2SetTime (IN2(S_EVENT_MODE) | IN2(S_CONTINUOUS_TIME))
#define MASK_fmi2SetContinuousStates IN2(S_CONTINUOUS_TIME)
#define MASK_fmi2GetContinuousStates ST2_EVALUATED
#define MASK_fmi2GetNominalsOfContinuousStates (IN2(S_INSTANTIATED) | ST2_EVALUATED)
#define MASK_fmi2GetDerivatives ST2_EVALUATED
#define MASK_fmi2GetEventIndicators ST2_EVALUATED

/* The first line of an fmi2 function: return fmi2Error unless c is a live instance in a state
 * where the function is legal (the refusal logged, fmi2_glue.c). */
#define LEGAL(c, function)                                                                     \
    if (!legal2((Instance *)(c), MASK_##function, #function)) {                                \
        return fmi2Error;                                                                      \
    }
int legal2(Instance *inst, unsigned mask, const char *function);

/* An fmi2 function that changes the state and takes no argument but the instance: legal, then
 * the core's transition. */
#define TRANSITION(function, core)                                                             \
    fmi2Status function(fmi2Component c)                                                       \
    {                                                                                          \
        LEGAL(c, function);                                                                    \
        return core(c);                                                                        \
    }

#endif
