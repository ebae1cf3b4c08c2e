/* The instance core's Model Exchange side, for the native models that offer it (config.h defines
 * MODEL_EXCHANGE): called by the FMI 2.0 entry points (fmi2_me.c) and the FMI 3.0 glue
 * (fmi3_events.c).
 *
 * State machine (FMI 2.0, section 3.2.3): instantiated -> initialization mode -> event mode
 * <-> continuous-time mode -> terminated; the glue refuses a call out of order (fmi2_states.h,
 * fmi3_states.h), the core makes the transitions. The host owns time and the continuous states: fmi2SetTime,
 * fmi2SetContinuousStates and fmi2Set<Type> mark the outputs and derivatives stale, and the next
 * getter recomputes them once (model_me_evaluate). The model's discrete state (the plant's
 * contact mode, the controller's samples) changes only in event mode, in fmi2NewDiscreteStates,
 * which also announces the model's next time event (the controller's next sample instant);
 * continuous states never jump.
 */
#include <math.h>
#include <stddef.h>

#include "fmi2Functions.h"
#include "glue.h"
#include "instance.h"

#define MAX_EVENT_SWITCHES 10 /* discrete-state updates at one event instant */

#ifdef MODEL_EXCHANGE

/* The instance's time: the last fmi2SetTime, else the start time. */
static double now(const Instance *inst)
{
    return inst->s.me_time_set ? inst->s.me_time : inst->s.d.start_time;
}

int me_initialize(Data *d, char *msg)
{
    if (model_me_check(d, msg)) {
        return 1;
    }
    return model_me_evaluate(d, msg);
}

fmi2Status me_update(Instance *inst)
{
    if (!inst->s.dirty) {
        return fmi2OK;
    }
    if (model_me_evaluate(&inst->s.d, inst->msg)) {
        return ERROR(inst, "at t=%.17g: %s", now(inst), inst->msg);
    }
    inst->s.dirty = 0;
    return fmi2OK;
}

/* The instance, if it is a Model Exchange instance (the glue has checked that the call is legal
 * in its phase); otherwise log why not and return NULL. */
static Instance *me_instance(fmi2Component c)
{
    Instance *inst = (Instance *)c;
    if (inst->type != fmi2ModelExchange) {
        log_message(inst, fmi2Error, "logStatusError",
                    "%s is a Model Exchange function, but this instance is for co-simulation",
                    inst->fn);
        return NULL;
    }
    return inst;
}


/* The Model Exchange instance (me_instance) whose array argument of n values, where the FMU has
 * expected, is usable; NULL (logged) if the instance or the array is not. */
static Instance *me_array(fmi2Component c, const void *array, size_t n, size_t expected,
                          const char *what)
{
    Instance *inst = me_instance(c);
    if (!inst) {
        return NULL;
    }
    if (n > 0 && !array) {
        log_message(inst, fmi2Error, "logStatusError", "%s: the %s array is NULL", inst->fn,
                    what);
        return NULL;
    }
    if (n != expected) {
        log_message(inst, fmi2Error, "logStatusError", "%s: %lu %s given, this FMU has %lu",
                    inst->fn, (unsigned long)n, what, (unsigned long)expected);
        return NULL;
    }
    return inst;
}

/* In initialization mode the outputs come from (re)initialization, as for the getters. */
static fmi2Status refresh(Instance *inst)
{
    if (inst->s.phase == S_INITIALIZATION) {
        const fmi2ValueReference none[1] = {0};
        return instance_get_real(inst, none, 0, NULL);
    }
    return me_update(inst);
}

/* --- mode changes --------------------------------------------------------------------------- */

fmi2Status instance_enter_event_mode(fmi2Component c)
{
    Instance *inst = me_instance(c);
    if (!inst) {
        return fmi2Error;
    }
    inst->s.phase = S_EVENT_MODE;
    inst->s.event_switches = 0;
    return fmi2OK;
}

fmi2Status instance_new_discrete_states(fmi2Component c, fmi2EventInfo *eventInfo)
{
    Instance *inst = me_instance(c);
    MeEvent ev = {0, 0, 0, 0.0};
    if (!inst) {
        return fmi2Error;
    }
    if (!eventInfo) {
        return ERROR_FN(inst, "eventInfo is NULL");
    }
    if (model_me_event_update(&inst->s.d, now(inst), &ev, inst->msg)) {
        return ERROR(inst, "at t=%.17g: %s", now(inst), inst->msg);
    }
    if (ev.changed) {
        inst->s.dirty = 1;
        inst->s.event_switches += 1;
        if (inst->s.event_switches > MAX_EVENT_SWITCHES) {
            return ERROR(inst, "at t=%.17g: more than %d discrete-state changes at one event",
                         now(inst), MAX_EVENT_SWITCHES);
        }
    }
    eventInfo->newDiscreteStatesNeeded = ev.again ? fmi2True : fmi2False;
    eventInfo->terminateSimulation = fmi2False;
    eventInfo->nominalsOfContinuousStatesChanged = fmi2False;
    eventInfo->valuesOfContinuousStatesChanged = fmi2False; /* no state jumps */
    eventInfo->nextEventTimeDefined = ev.next_defined ? fmi2True : fmi2False;
    eventInfo->nextEventTime = ev.next_defined ? ev.next : 0.0;
    return fmi2OK;
}

fmi2Status instance_enter_continuous_time_mode(fmi2Component c)
{
    Instance *inst = me_instance(c);
    if (!inst) {
        return fmi2Error;
    }
    inst->s.phase = S_CONTINUOUS_TIME;
    return fmi2OK;
}

fmi2Status instance_completed_integrator_step(fmi2Component c,
                                       fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode,
                                       fmi2Boolean *terminateSimulation)
{
    Instance *inst = me_instance(c);
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!inst) {
        return fmi2Error;
    }
    if (!enterEventMode || !terminateSimulation) {
        return ERROR_FN(inst, "NULL output argument");
    }
    *enterEventMode = fmi2False; /* no step events: the contact is found by event indicators */
    *terminateSimulation = fmi2False;
    return fmi2OK;
}

/* --- time and states ------------------------------------------------------------------------ */

fmi2Status instance_set_time(fmi2Component c, fmi2Real time)
{
    Instance *inst = me_instance(c);
    if (!inst) {
        return fmi2Error;
    }
    if (!isfinite(time)) {
        return ERROR_FN(inst, "time is not finite (%g)", time);
    }
    inst->s.me_time = time;
    inst->s.me_time_set = 1;
    inst->s.last_time = time;
    inst->s.dirty = 1;
    return fmi2OK;
}

fmi2Status instance_set_continuous_states(fmi2Component c, const fmi2Real x[], size_t nx)
{
    Instance *inst = me_array(c, x, nx, N_STATES, "states");
    if (!inst) {
        return fmi2Error;
    }
    for (size_t k = 0; k < nx; k++) { /* check all before changing anything */
        if (!isfinite(x[k])) {
            return ERROR_FN(inst, "state %lu is not finite (%g)",
                         (unsigned long)k + 1, x[k]);
        }
    }
    model_me_set_states(&inst->s.d, x);
    inst->s.dirty = 1;
    return fmi2OK;
}

fmi2Status instance_get_nominals(fmi2Component c, fmi2Real x_nominal[], size_t nx)
{
    Instance *inst = me_array(c, x_nominal, nx, N_STATES, "states");
    if (!inst) {
        return fmi2Error;
    }
    for (size_t k = 0; k < nx; k++) {
        x_nominal[k] = 1.0; /* rad and rad/s: the angles and velocities are of order one */
    }
    return fmi2OK;
}

/* --- model equations ------------------------------------------------------------------------ */

typedef enum { ME_STATES, ME_DERIVATIVES, ME_INDICATORS } MeValues;

/* The continuous states, their derivatives or the event indicators at the current time, states
 * and inputs (brought up to date first), into out[0..n). */
static fmi2Status me_read(fmi2Component c, fmi2Real out[], size_t n, MeValues which)
{
    static const char *const what[] = {"states", "derivatives", "event indicators"};
    const size_t expected = which == ME_INDICATORS ? N_EVENT_INDICATORS : N_STATES;
    Instance *inst = me_array(c, out, n, expected, what[which]);
    fmi2Status status = inst ? refresh(inst) : fmi2Error;
    if (status != fmi2OK) {
        return status;
    }
    if (which == ME_STATES) {
        model_me_get_states(&inst->s.d, out);
    } else if (which == ME_INDICATORS) {
        if (model_me_event_indicators(&inst->s.d, out, inst->msg)) {
            return ERROR(inst, "at t=%.17g: %s", now(inst), inst->msg);
        }
    } else {
#if N_STATES > 0
        for (size_t k = 0; k < n; k++) {
            out[k] = inst->s.d.r[DERIVATIVE_VRS[k]];
        }
#endif
    }
    return fmi2OK;
}

#define ME_READ(function, which)                                                                   \
    fmi2Status function(fmi2Component c, fmi2Real out[], size_t n)                             \
    {                                                                                          \
        return me_read(c, out, n, which);                                                      \
    }

ME_READ(instance_get_continuous_states, ME_STATES)
ME_READ(instance_get_derivatives, ME_DERIVATIVES)
ME_READ(instance_get_event_indicators, ME_INDICATORS)

#else /* co-simulation only: fmi2Instantiate refuses fmi2ModelExchange, these are never reached */

int me_initialize(Data *d, char *msg)
{
    (void)d;
    return fail(msg, "%s supports co-simulation only", MODEL_IDENTIFIER_STR);
}

fmi2Status me_update(Instance *inst)
{
    (void)inst;
    return fmi2OK;
}

#endif
