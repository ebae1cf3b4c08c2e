/* The FMI 2.0 Model Exchange entry points of the models that offer it (config.h defines
 * MODEL_EXCHANGE): each calls the instance core's Model Exchange side (instance_me.c). */
#include "fmi2Functions.h"
#include "glue.h"
#include "instance.h"
#include "fmi2_states.h" /* MASK_<function>, LEGAL */

#ifdef MODEL_EXCHANGE

TRANSITION(fmi2EnterEventMode, instance_enter_event_mode)

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *eventInfo)
{
    LEGAL(c, fmi2NewDiscreteStates);
    return instance_new_discrete_states(c, eventInfo);
}

TRANSITION(fmi2EnterContinuousTimeMode, instance_enter_continuous_time_mode)

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c,
                                       fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode,
                                       fmi2Boolean *terminateSimulation)
{
    LEGAL(c, fmi2CompletedIntegratorStep);
    return instance_completed_integrator_step(c, noSetFMUStatePriorToCurrentPoint, enterEventMode,
                                              terminateSimulation);
}

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time)
{
    LEGAL(c, fmi2SetTime);
    return instance_set_time(c, time);
}

/* The functions over the continuous states and event indicators: legal in the instance's
 * state, then the core's. */
#define VECTOR(function, core, ctype)                                                              \
    fmi2Status function(fmi2Component c, ctype values[], size_t n)                              \
    {                                                                                           \
        LEGAL(c, function);                                                                     \
        return core(c, values, n);                                                              \
    }

VECTOR(fmi2SetContinuousStates, instance_set_continuous_states, const fmi2Real)
VECTOR(fmi2GetContinuousStates, instance_get_continuous_states, fmi2Real)
VECTOR(fmi2GetNominalsOfContinuousStates, instance_get_nominals, fmi2Real)
VECTOR(fmi2GetDerivatives, instance_get_derivatives, fmi2Real)
VECTOR(fmi2GetEventIndicators, instance_get_event_indicators, fmi2Real)

#endif
