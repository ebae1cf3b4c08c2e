/* The FMI 3.0 Model Exchange functions and the sample clock of Scheduled Execution, of Model
 * Exchange and of Co-Simulation with event mode (see fmi3_glue.c, fmi3_cosim.c): calls of the
 * instance core's Model Exchange side (instance_me.c). A clock tick is an event of the model's
 * Model Exchange side at the tick's time: the samples due are taken. */
#include <math.h>
#include <stddef.h>

#include "fmi3_wrapper.h"

/* --- clocks (Scheduled Execution; Co-Simulation with event mode) ------------------------------ */

/* The clock's value reference is VR_CLOCK: 1 if every reference is it, else 0 after logging. */
static int clocks_only(Wrapper *w, const fmi3ValueReference vr[], size_t nvr, const void *out,
                       const char *function)
{
    if (nvr > 0 && (!vr || !out)) {
        log_message(w->inner, fmi2Error, "logStatusError", "%s: NULL array", function);
        return 0;
    }
    for (size_t k = 0; k < nvr; k++) {
#if HAS_CLOCK
        if (vr[k] == VR_CLOCK) {
            continue;
        }
#endif
        log_message(w->inner, fmi2Error, "logStatusError", "%s: %u is not a clock of this FMU",
                    function, (unsigned)vr[k]);
        return 0;
    }
    return 1;
}

/* The sample clock in Model Exchange and in Co-Simulation with event mode (Wrapper.tick_active):
 * active in Event Mode at a tick until fmi3UpdateDiscreteStates, which takes its sample and
 * deactivates it (FMI 3.0: the FMU deactivates every clock active during that call).
 * fmi3GetClock tells it (the standard's getter is for output clocks; this input clock answers
 * too); fmi3SetClock, the importer's activation, may confirm it, never move it (its ticks are
 * fixed). */
fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, fmi3Clock values[])
{
    WRAP(fmi3GetClock);
    if (!clocks_only(w, valueReferences, nValueReferences, values, "fmi3GetClock")) {
        return fmi3Error;
    }
    for (size_t k = 0; k < nValueReferences; k++) {
        values[k] = w->state == ST_EVENT && w->tick_active;
    }
    return fmi3OK;
}

fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, const fmi3Clock values[])
{
    WRAP(fmi3SetClock);
    if (!clocks_only(w, valueReferences, nValueReferences, values, "fmi3SetClock")) {
        return fmi3Error;
    }
    for (size_t k = 0; k < nValueReferences; k++) {
        if (values[k] && !(w->state == ST_EVENT && w->tick_active)) {
            return FAIL(w, "fmi3SetClock: the sample clock ticks every sample_period from the "
                           "start time only: in Event Mode at a tick (Model Exchange, "
                           "co-simulation with event mode), before fmi3UpdateDiscreteStates");
        }
    }
    return fmi3OK;
}

fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance,
                                  const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, fmi3Float64 intervals[],
                                  fmi3IntervalQualifier qualifiers[])
{
    WRAP(fmi3GetIntervalDecimal);
    if (!clocks_only(w, valueReferences, nValueReferences, intervals, "fmi3GetIntervalDecimal") ||
        (nValueReferences > 0 && !qualifiers)) {
        return fmi3Error;
    }
    for (size_t k = 0; k < nValueReferences; k++) {
#if HAS_CLOCK
        intervals[k] = w->inner->s.d.r[CLOCK_PERIOD_VR];
#endif
        qualifiers[k] = fmi3IntervalChanged;
    }
    return fmi3OK;
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, fmi3Float64 shifts[])
{
    WRAP(fmi3GetShiftDecimal);
    if (!clocks_only(w, valueReferences, nValueReferences, shifts, "fmi3GetShiftDecimal")) {
        return fmi3Error;
    }
    for (size_t k = 0; k < nValueReferences; k++) {
        shifts[k] = 0.0; /* the first tick is at the start time */
    }
    return fmi3OK;
}

fmi3Status fmi3GetIntervalFraction(fmi3Instance instance,
                                   const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, fmi3UInt64 counters[],
                                   fmi3UInt64 resolutions[], fmi3IntervalQualifier qualifiers[])
{
    WRAP(fmi3GetIntervalFraction);
    (void)valueReferences, (void)nValueReferences, (void)counters, (void)resolutions,
        (void)qualifiers;
    return FAIL(w, "the clock interval is given as a decimal only (supportsFraction=false)");
}

fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, fmi3UInt64 counters[],
                                fmi3UInt64 resolutions[])
{
    WRAP(fmi3GetShiftFraction);
    (void)valueReferences, (void)nValueReferences, (void)counters, (void)resolutions;
    return FAIL(w, "the clock shift is given as a decimal only (supportsFraction=false)");
}

fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, const fmi3Float64 intervals[])
{
    WRAP(fmi3SetIntervalDecimal);
    (void)valueReferences, (void)nValueReferences, (void)intervals;
    return FAIL(w, "the clock interval is fixed by the parameter sample_period");
}

fmi3Status fmi3SetIntervalFraction(fmi3Instance instance,
                                   const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, const fmi3UInt64 counters[],
                                   const fmi3UInt64 resolutions[])
{
    WRAP(fmi3SetIntervalFraction);
    (void)valueReferences, (void)nValueReferences, (void)counters, (void)resolutions;
    return FAIL(w, "the clock interval is fixed by the parameter sample_period");
}

fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, const fmi3Float64 shifts[])
{
    WRAP(fmi3SetShiftDecimal);
    (void)valueReferences, (void)nValueReferences, (void)shifts;
    return FAIL(w, "the clock has no shift to set");
}

fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, const fmi3UInt64 counters[],
                                const fmi3UInt64 resolutions[])
{
    WRAP(fmi3SetShiftFraction);
    (void)valueReferences, (void)nValueReferences, (void)counters, (void)resolutions;
    return FAIL(w, "the clock has no shift to set");
}

fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime)
{
    fmi2EventInfo ev;
    fmi2Status s;
    WRAP(fmi3ActivateModelPartition);
    if (!clocks_only(w, &clockReference, 1, &clockReference, "fmi3ActivateModelPartition")) {
        return fmi3Error;
    }
    if (!isfinite(activationTime) || activationTime < w->inner->s.last_time) {
        return FAIL(w, "fmi3ActivateModelPartition: activation time %.17g is not finite or "
                       "before the previous one (%.17g)", activationTime, w->inner->s.last_time);
    }
    /* a tick is an event of the Model Exchange side at that time: the samples due are taken */
    s = instance_enter_event_mode(w->inner);
    if (s == fmi2OK) {
        s = instance_set_time(w->inner, activationTime);
    }
    if (s == fmi2OK) {
        s = instance_new_discrete_states(w->inner, &ev);
    }
    return status3(s);
}
/* --- Model Exchange --------------------------------------------------------------------------- */

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation,
                                    fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged,
                                    fmi3Boolean *nextEventTimeDefined, fmi3Float64 *nextEventTime)
{
    fmi2EventInfo ev;
    fmi2Status s;
    WRAP(fmi3UpdateDiscreteStates);
    w->tick_active = 0; /* the sample due is taken below */
    if (w->kind == K_CS) {
        return cs_update_discrete_states(w, discreteStatesNeedUpdate, terminateSimulation,
                                         nominalsOfContinuousStatesChanged,
                                         valuesOfContinuousStatesChanged, nextEventTimeDefined,
                                         nextEventTime);
    }
    s = instance_new_discrete_states(w->inner, &ev);
    if (s != fmi2OK) {
        return status3(s);
    }
    /* every output argument may be NULL (FMI 3.0, section 3.2.2: then it is not needed) */
    if (discreteStatesNeedUpdate) {
        *discreteStatesNeedUpdate = ev.newDiscreteStatesNeeded != fmi2False;
    }
    if (terminateSimulation) {
        *terminateSimulation = ev.terminateSimulation != fmi2False;
    }
    if (nominalsOfContinuousStatesChanged) {
        *nominalsOfContinuousStatesChanged = ev.nominalsOfContinuousStatesChanged != fmi2False;
    }
    if (valuesOfContinuousStatesChanged) {
        *valuesOfContinuousStatesChanged = ev.valuesOfContinuousStatesChanged != fmi2False;
    }
    if (nextEventTimeDefined) {
        *nextEventTimeDefined = ev.nextEventTimeDefined != fmi2False;
    }
    if (nextEventTime) {
        *nextEventTime = ev.nextEventTime;
    }
    return fmi3OK;
}

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance)
{
    WRAP(fmi3EnterContinuousTimeMode);
    return entered(w, instance_enter_continuous_time_mode(w->inner), ST_CONTINUOUS_TIME);
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance,
                                       fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode,
                                       fmi3Boolean *terminateSimulation)
{
    fmi2Boolean enter = fmi2False, stop = fmi2False;
    fmi2Status s;
    WRAP(fmi3CompletedIntegratorStep);
    if (!enterEventMode || !terminateSimulation) {
        return FAIL(w, "fmi3CompletedIntegratorStep: NULL output argument");
    }
    s = instance_completed_integrator_step(w->inner, noSetFMUStatePriorToCurrentPoint, &enter, &stop);
    *enterEventMode = enter != fmi2False;
    *terminateSimulation = stop != fmi2False;
    return status3(s);
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time)
{
    WRAP(fmi3SetTime);
    return status3(instance_set_time(w->inner, time));
}

/* The functions over the continuous states and event indicators: the core's, on the wrapper's
 * instance. */
#define VECTOR3(function, core, ctype)                                                             \
    fmi3Status function(fmi3Instance instance, ctype values[], size_t n)                       \
    {                                                                                          \
        WRAP(function);                                                                        \
        return status3(core(w->inner, values, n));                                             \
    }

VECTOR3(fmi3SetContinuousStates, instance_set_continuous_states, const fmi3Float64)
VECTOR3(fmi3GetContinuousStateDerivatives, instance_get_derivatives, fmi3Float64)
VECTOR3(fmi3GetEventIndicators, instance_get_event_indicators, fmi3Float64)
VECTOR3(fmi3GetContinuousStates, instance_get_continuous_states, fmi3Float64)
VECTOR3(fmi3GetNominalsOfContinuousStates, instance_get_nominals, fmi3Float64)

/* The numbers of continuous states and event indicators (none without Model Exchange). */
#ifdef MODEL_EXCHANGE
#define N_STATES3 N_STATES
#define N_EVENT_INDICATORS3 N_EVENT_INDICATORS
#else
#define N_STATES3 0
#define N_EVENT_INDICATORS3 0
#endif
#define COUNT3(function, count)                                                                    \
    fmi3Status function(fmi3Instance instance, size_t *n)                                      \
    {                                                                                          \
        WRAP(function);                                                                        \
        if (!n) {                                                                              \
            return FAIL(w, #function ": NULL output argument");                                \
        }                                                                                      \
        *n = count;                                                                            \
        return fmi3OK;                                                                         \
    }

COUNT3(fmi3GetNumberOfEventIndicators, N_EVENT_INDICATORS3)
COUNT3(fmi3GetNumberOfContinuousStates, N_STATES3)
