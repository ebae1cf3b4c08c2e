/* Included by fmi3_glue.c before it includes the FMI 2 layer (fmi2_glue.c, fmi2_me.c) into the
 * same translation unit: the FMI 2 functions get internal names (impc_fmi2...), which
 * -fvisibility=hidden keeps out of the library's exports, so the FMI 3 binary exports only
 * fmi3* functions and never clashes with an FMI 2 binary of the same model in one process. */
#ifndef FMI2_HIDDEN_H
#define FMI2_HIDDEN_H

#include "fmi2Functions.h" /* declares the public fmi2* names, which this binary never defines */

#undef fmi2GetTypesPlatform
#define fmi2GetTypesPlatform impc_fmi2GetTypesPlatform
#undef fmi2GetVersion
#define fmi2GetVersion impc_fmi2GetVersion
#undef fmi2SetDebugLogging
#define fmi2SetDebugLogging impc_fmi2SetDebugLogging
#undef fmi2Instantiate
#define fmi2Instantiate impc_fmi2Instantiate
#undef fmi2FreeInstance
#define fmi2FreeInstance impc_fmi2FreeInstance
#undef fmi2SetupExperiment
#define fmi2SetupExperiment impc_fmi2SetupExperiment
#undef fmi2EnterInitializationMode
#define fmi2EnterInitializationMode impc_fmi2EnterInitializationMode
#undef fmi2ExitInitializationMode
#define fmi2ExitInitializationMode impc_fmi2ExitInitializationMode
#undef fmi2Terminate
#define fmi2Terminate impc_fmi2Terminate
#undef fmi2Reset
#define fmi2Reset impc_fmi2Reset
#undef fmi2GetReal
#define fmi2GetReal impc_fmi2GetReal
#undef fmi2GetInteger
#define fmi2GetInteger impc_fmi2GetInteger
#undef fmi2GetBoolean
#define fmi2GetBoolean impc_fmi2GetBoolean
#undef fmi2GetString
#define fmi2GetString impc_fmi2GetString
#undef fmi2SetReal
#define fmi2SetReal impc_fmi2SetReal
#undef fmi2SetInteger
#define fmi2SetInteger impc_fmi2SetInteger
#undef fmi2SetBoolean
#define fmi2SetBoolean impc_fmi2SetBoolean
#undef fmi2SetString
#define fmi2SetString impc_fmi2SetString
#undef fmi2GetFMUstate
#define fmi2GetFMUstate impc_fmi2GetFMUstate
#undef fmi2SetFMUstate
#define fmi2SetFMUstate impc_fmi2SetFMUstate
#undef fmi2FreeFMUstate
#define fmi2FreeFMUstate impc_fmi2FreeFMUstate
#undef fmi2SerializedFMUstateSize
#define fmi2SerializedFMUstateSize impc_fmi2SerializedFMUstateSize
#undef fmi2SerializeFMUstate
#define fmi2SerializeFMUstate impc_fmi2SerializeFMUstate
#undef fmi2DeSerializeFMUstate
#define fmi2DeSerializeFMUstate impc_fmi2DeSerializeFMUstate
#undef fmi2GetDirectionalDerivative
#define fmi2GetDirectionalDerivative impc_fmi2GetDirectionalDerivative
#undef fmi2EnterEventMode
#define fmi2EnterEventMode impc_fmi2EnterEventMode
#undef fmi2NewDiscreteStates
#define fmi2NewDiscreteStates impc_fmi2NewDiscreteStates
#undef fmi2EnterContinuousTimeMode
#define fmi2EnterContinuousTimeMode impc_fmi2EnterContinuousTimeMode
#undef fmi2CompletedIntegratorStep
#define fmi2CompletedIntegratorStep impc_fmi2CompletedIntegratorStep
#undef fmi2SetTime
#define fmi2SetTime impc_fmi2SetTime
#undef fmi2SetContinuousStates
#define fmi2SetContinuousStates impc_fmi2SetContinuousStates
#undef fmi2GetDerivatives
#define fmi2GetDerivatives impc_fmi2GetDerivatives
#undef fmi2GetEventIndicators
#define fmi2GetEventIndicators impc_fmi2GetEventIndicators
#undef fmi2GetContinuousStates
#define fmi2GetContinuousStates impc_fmi2GetContinuousStates
#undef fmi2GetNominalsOfContinuousStates
#define fmi2GetNominalsOfContinuousStates impc_fmi2GetNominalsOfContinuousStates
#undef fmi2SetRealInputDerivatives
#define fmi2SetRealInputDerivatives impc_fmi2SetRealInputDerivatives
#undef fmi2GetRealOutputDerivatives
#define fmi2GetRealOutputDerivatives impc_fmi2GetRealOutputDerivatives
#undef fmi2DoStep
#define fmi2DoStep impc_fmi2DoStep
#undef fmi2CancelStep
#define fmi2CancelStep impc_fmi2CancelStep
#undef fmi2GetStatus
#define fmi2GetStatus impc_fmi2GetStatus
#undef fmi2GetRealStatus
#define fmi2GetRealStatus impc_fmi2GetRealStatus
#undef fmi2GetIntegerStatus
#define fmi2GetIntegerStatus impc_fmi2GetIntegerStatus
#undef fmi2GetBooleanStatus
#define fmi2GetBooleanStatus impc_fmi2GetBooleanStatus
#undef fmi2GetStringStatus
#define fmi2GetStringStatus impc_fmi2GetStringStatus

#endif
