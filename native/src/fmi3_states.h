/* The FMI 3.0 state machine of the glue (FMI 3.0, sections 3.2 Model Exchange, 4.2
 * Co-Simulation, 5.2 Scheduled Execution) and, for every fmi3 function, the states in which it is
 * legal (MASK_<function>; the check is WRAP's, fmi3_wrapper.h). The glue makes the transitions.
 * Configuration and Reconfiguration Mode are never entered (no structural parameters). */
#ifndef FMI3_STATES_H
#define FMI3_STATES_H

typedef enum {
    ST_INSTANTIATED = 1 << 0,
    ST_INITIALIZATION = 1 << 1,
    ST_EVENT = 1 << 2,              /* Model Exchange; Co-Simulation with eventModeUsed */
    ST_CONTINUOUS_TIME = 1 << 3,    /* Model Exchange */
    ST_STEP = 1 << 4,               /* Co-Simulation */
    ST_CLOCK_ACTIVATION = 1 << 5,   /* Scheduled Execution */
    ST_INTERMEDIATE_UPDATE = 1 << 6, /* Co-Simulation: inside the intermediate update callback */
    ST_TERMINATED = 1 << 7
} State3;

/* every state but inside the intermediate update callback (where only getters are legal) */
#define ST_ANY (ST_INSTANTIATED | ST_INITIALIZATION | ST_EVENT | ST_CONTINUOUS_TIME | ST_STEP | \
                ST_CLOCK_ACTIVATION | ST_TERMINATED)
#define ST_RUNNING (ST_EVENT | ST_CONTINUOUS_TIME | ST_STEP | ST_CLOCK_ACTIVATION)
/* values are read from Initialization Mode on; inputs set until Terminated */
#define ST_READ (ST_ANY & ~ST_INSTANTIATED)
#define ST_WRITE (ST_ANY & ~ST_TERMINATED)
/* the Model Exchange side's equations are evaluated from Initialization Mode on */
#define ST_EVALUATED (ST_INITIALIZATION | ST_EVENT | ST_CONTINUOUS_TIME | ST_TERMINATED)

#define MASK_fmi3SetDebugLogging ST_ANY
#define MASK_fmi3FreeInstance ST_ANY
#define MASK_fmi3Reset ST_ANY
#define MASK_fmi3EnterInitializationMode ST_INSTANTIATED
#define MASK_fmi3ExitInitializationMode ST_INITIALIZATION
#define MASK_fmi3EnterEventMode (ST_CONTINUOUS_TIME | ST_STEP)
#define MASK_fmi3Terminate ST_RUNNING
#define MASK_fmi3EnterConfigurationMode (ST_INSTANTIATED | ST_STEP | ST_EVENT | ST_CLOCK_ACTIVATION)
#define MASK_fmi3ExitConfigurationMode ST_ANY /* refused always: never in Configuration Mode */

#define MASK_fmi3GetFMUState ST_ANY
#define MASK_fmi3SetFMUState ST_ANY
#define MASK_fmi3FreeFMUState ST_ANY
#define MASK_fmi3SerializedFMUStateSize ST_ANY
#define MASK_fmi3SerializeFMUState ST_ANY
#define MASK_fmi3DeserializeFMUState ST_ANY

/* the getters of this FMU's variable types are legal inside the intermediate update too */
#define MASK_fmi3GetFloat64 (ST_READ | ST_INTERMEDIATE_UPDATE)
#define MASK_fmi3GetInt32 (ST_READ | ST_INTERMEDIATE_UPDATE)
#define MASK_fmi3GetInt64 (ST_READ | ST_INTERMEDIATE_UPDATE)
#define MASK_fmi3GetBoolean (ST_READ | ST_INTERMEDIATE_UPDATE)
#define MASK_fmi3GetString (ST_READ | ST_INTERMEDIATE_UPDATE)
#define MASK_fmi3SetFloat64 ST_WRITE
#define MASK_fmi3SetInt32 ST_WRITE
#define MASK_fmi3SetInt64 ST_WRITE
#define MASK_fmi3SetBoolean ST_WRITE
#define MASK_fmi3SetString ST_WRITE
/* the types this FMU has no variables of (fmi3_stubs.c) */
#define MASK_fmi3GetFloat32 ST_READ
#define MASK_fmi3GetInt8 ST_READ
#define MASK_fmi3GetUInt8 ST_READ
#define MASK_fmi3GetInt16 ST_READ
#define MASK_fmi3GetUInt16 ST_READ
#define MASK_fmi3GetUInt32 ST_READ
#define MASK_fmi3GetUInt64 ST_READ
#define MASK_fmi3GetBinary ST_READ
#define MASK_fmi3GetClock ST_READ
#define MASK_fmi3SetFloat32 ST_WRITE
#define MASK_fmi3SetInt8 ST_WRITE
#define MASK_fmi3SetUInt8 ST_WRITE
#define MASK_fmi3SetInt16 ST_WRITE
#define MASK_fmi3SetUInt16 ST_WRITE
#define MASK_fmi3SetUInt32 ST_WRITE
#define MASK_fmi3SetUInt64 ST_WRITE
#define MASK_fmi3SetBinary ST_WRITE
#define MASK_fmi3SetClock ST_WRITE

#define MASK_fmi3GetNumberOfVariableDependencies ST_ANY
#define MASK_fmi3GetVariableDependencies ST_ANY
#define MASK_fmi3GetDirectionalDerivative (ST_EVENT | ST_CONTINUOUS_TIME | ST_STEP)
#define MASK_fmi3GetAdjointDerivative ST_ANY
#define MASK_fmi3GetOutputDerivatives (ST_STEP | ST_EVENT)
#define MASK_fmi3EvaluateDiscreteStates ST_ANY

/* Co-Simulation */
#define MASK_fmi3EnterStepMode ST_EVENT
#define MASK_fmi3DoStep ST_STEP

/* Model Exchange (fmi3UpdateDiscreteStates also in Co-Simulation's Event Mode) */
#define MASK_fmi3UpdateDiscreteStates ST_EVENT
#define MASK_fmi3EnterContinuousTimeMode ST_EVENT
#define MASK_fmi3CompletedIntegratorStep ST_CONTINUOUS_TIME
#define MASK_fmi3SetTime (ST_EVENT | ST_CONTINUOUS_TIME)
#define MASK_fmi3SetContinuousStates ST_CONTINUOUS_TIME
#define MASK_fmi3GetContinuousStateDerivatives ST_EVALUATED
#define MASK_fmi3GetEventIndicators ST_EVALUATED
#define MASK_fmi3GetContinuousStates ST_EVALUATED
#define MASK_fmi3GetNominalsOfContinuousStates (ST_INSTANTIATED | ST_EVALUATED)
#define MASK_fmi3GetNumberOfEventIndicators ST_ANY
#define MASK_fmi3GetNumberOfContinuousStates ST_ANY

/* clocks (Scheduled Execution; Get/SetClock also in Co-Simulation with event mode) */
#define MASK_fmi3GetIntervalDecimal ST_READ
#define MASK_fmi3GetShiftDecimal ST_ANY
#define MASK_fmi3GetIntervalFraction ST_ANY
#define MASK_fmi3GetShiftFraction ST_ANY
#define MASK_fmi3SetIntervalDecimal ST_ANY
#define MASK_fmi3SetIntervalFraction ST_ANY
#define MASK_fmi3SetShiftDecimal ST_ANY
#define MASK_fmi3SetShiftFraction ST_ANY
#define MASK_fmi3ActivateModelPartition ST_CLOCK_ACTIVATION

#endif
