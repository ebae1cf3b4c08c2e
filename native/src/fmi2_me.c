/* The FMI 2.0 Model Exchange entry points of the models that offer it (config.h defines
 * MODEL_EXCHANGE): each calls the instance core's Model Exchange side (instance_me.c). */
#include "fmi2Functions.h"
#include "glue.h"
#include "instance.h"
#include "fmi2_states.h" /* MASK_<function>, LEGAL */

#ifdef MODEL_EXCHANGE

fmi2Status fmi2EnterEventMode(fmi2Component c)
{
    LEGAL(c, fmi2EnterEventMode);
    return instance_enter_event_mode(c);
}

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *eventInfo)
{
    LEGAL(c, fmi2NewDiscreteStates);
    return instance_new_discrete_states(c, eventInfo);
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c)
{
    LEGAL(c, fmi2EnterContinuousTimeMode);
    return instance_enter_continuous_time_mode(c);
}

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

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx)
{
    LEGAL(c, fmi2SetContinuousStates);
    return instance_set_continuous_states(c, x, nx);
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx)
{
    LEGAL(c, fmi2GetContinuousStates);
    return instance_get_continuous_states(c, x, nx);
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx)
{
    LEGAL(c, fmi2GetNominalsOfContinuousStates);
    return instance_get_nominals(c, x_nominal, nx);
}

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx)
{
    LEGAL(c, fmi2GetDerivatives);
    return instance_get_derivatives(c, derivatives, nx);
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni)
{
    LEGAL(c, fmi2GetEventIndicators);
    return instance_get_event_indicators(c, eventIndicators, ni);
}

#endif
