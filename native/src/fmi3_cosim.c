/* FMI 3.0 Co-Simulation stepping (see fmi3_glue.c): fmi3DoStep with early return, the
 * intermediate update callback and event mode at the model's discrete-state switches (the plant's
 * wall contact, model_step_early), and the Step Mode / Event Mode state machine of
 * Co-Simulation. A model without such switches (HAS_EARLY_RETURN 0) steps as under FMI 2.0.
 *
 * At a switch the model step has stopped with the mode switched, its outputs computed at the
 * switch time: the intermediate update there offers them (intermediateStepFinished, get allowed,
 * no input set requested). The step ends there (earlyReturn) only where the importer allowed early
 * return: with eventModeUsed (then with eventHandlingNeeded), without an intermediate update
 * callback, or when the callback requests it; else it goes on to the communication point.
 *
 * The controller (HAS_CLOCK) with eventModeUsed: its sample clock's ticks are the events. The
 * step stops at a tick inside it where early return is allowed (else it samples inside as
 * without event mode: the standard leaves events inside a step without early return to the FMU),
 * a tick at its end signals eventHandlingNeeded; fmi3UpdateDiscreteStates takes the sample. With
 * an intermediate update callback the step stops at each tick inside it for the callback (the
 * outputs held up to the tick readable) and ends there only on its request; a tick it lets pass
 * is sampled inside the step (TICK_RESUME), as without early return. */
#include <string.h>

#include "fmi3_wrapper.h"

static const char *state_name(State3 state)
{
    switch (state) {
    case ST_INSTANTIATED: return "Instantiated";
    case ST_INITIALIZATION: return "Initialization Mode";
    case ST_EVENT: return "Event Mode";
    case ST_CONTINUOUS_TIME: return "Continuous-Time Mode";
    case ST_STEP: return "Step Mode";
    case ST_CLOCK_ACTIVATION: return "Clock Activation Mode";
    case ST_INTERMEDIATE_UPDATE:
        return "Intermediate Update Mode (inside the intermediate update callback)";
    case ST_TERMINATED: return "Terminated";
    }
    return "an unknown state";
}

int state_allows(Wrapper *w, unsigned mask, const char *function)
{
    w->inner->fn = function; /* the core's messages name it */
    if (mask & (unsigned)w->state) {
        return 1;
    }
    log_message(w->inner, fmi2Error, "logStatusError", "%s called in %s: not allowed there",
                function, state_name(w->state));
    return 0;
}

/* The core's phase, restored with its Snapshot, in FMI 3 terms; Co-Simulation's Event Mode is
 * not part of the Snapshot (it lies between steps, at the same core phase as Step Mode). */
State3 state_of_core(const Wrapper *w)
{
    switch (w->inner->s.phase) {
    case S_INSTANTIATED: return ST_INSTANTIATED;
    case S_INITIALIZATION: return ST_INITIALIZATION;
    case S_STEP_COMPLETE: return w->state == ST_EVENT ? ST_EVENT : ST_STEP;
    case S_EVENT_MODE: return w->kind == K_SE ? ST_CLOCK_ACTIVATION : ST_EVENT;
    case S_CONTINUOUS_TIME: return ST_CONTINUOUS_TIME;
    case S_TERMINATED: break;
    }
    return ST_TERMINATED;
}

#if HAS_CLOCK
int tick_due(const Wrapper *w)
{
    const Data *d = &w->inner->s.d;
    return model_next_tick(d) <= w->inner->s.last_time + 1e-9 * d->r[CLOCK_PERIOD_VR];
}

/* Where a restored FMU state is in Event Mode: a sample due, or tick 0 (sampled in
 * Initialization Mode, active in the Event Mode after it) still at the start time. */
int tick_pending(const Wrapper *w)
{
    const Data *d = &w->inner->s.d;
    return tick_due(w) || (d->m.k_next == 1 && w->inner->s.last_time <=
                                                   d->m.start_time + 1e-9 * d->r[CLOCK_PERIOD_VR]);
}

/* The sample due at the current time (model_me_event_update, as under Model Exchange). */
static fmi3Status take_due_sample(Wrapper *w, fmi3Boolean *defined, fmi3Float64 *next)
{
    MeEvent ev = {0, 0, 0, 0.0};
    if (model_me_event_update(&w->inner->s.d, w->inner->s.last_time, &ev, w->inner->msg)) {
        return FAIL(w, "fmi3UpdateDiscreteStates: %s", w->inner->msg);
    }
    *defined = ev.next_defined ? fmi3True : fmi3False;
    *next = ev.next;
    return fmi3OK;
}
#endif

/* Co-Simulation fmi3EnterEventMode: from Step Mode, where the importer used event mode. */
fmi3Status cs_enter_event_mode(Wrapper *w)
{
    if (!w->event_mode_used) {
        return FAIL(w, "fmi3EnterEventMode: the instance was created with eventModeUsed=false");
    }
    w->state = ST_EVENT;
#if HAS_CLOCK
    w->tick_active = w->clock_events && tick_due(w);
#endif
    return fmi3OK;
}

/* Co-Simulation fmi3UpdateDiscreteStates, in Event Mode: the plant's model step has already
 * switched the contact mode at the event, so nothing changes there; the controller takes the
 * sample due and tells the next tick. */
fmi3Status cs_update_discrete_states(Wrapper *w, fmi3Boolean *discreteStatesNeedUpdate,
                                     fmi3Boolean *terminateSimulation,
                                     fmi3Boolean *nominalsOfContinuousStatesChanged,
                                     fmi3Boolean *valuesOfContinuousStatesChanged,
                                     fmi3Boolean *nextEventTimeDefined,
                                     fmi3Float64 *nextEventTime)
{
    if (!discreteStatesNeedUpdate || !terminateSimulation || !nominalsOfContinuousStatesChanged ||
        !valuesOfContinuousStatesChanged || !nextEventTimeDefined || !nextEventTime) {
        return FAIL(w, "fmi3UpdateDiscreteStates: NULL output argument");
    }
    *discreteStatesNeedUpdate = fmi3False;
    *terminateSimulation = fmi3False;
    *nominalsOfContinuousStatesChanged = fmi3False;
    *valuesOfContinuousStatesChanged = fmi3False;
    *nextEventTimeDefined = fmi3False;
    *nextEventTime = 0.0;
#if HAS_CLOCK
    if (w->clock_events) {
        return take_due_sample(w, nextEventTimeDefined, nextEventTime);
    }
#endif
    return fmi3OK;
}

fmi3Status fmi3EnterStepMode(fmi3Instance instance)
{
    WRAP(fmi3EnterStepMode);
    if (w->kind != K_CS) {
        return FAIL(w, "fmi3EnterStepMode: only for co-simulation with eventModeUsed=true");
    }
    w->state = ST_STEP;
    w->tick_active = 0;
    return fmi3OK;
}

/* At a switch or tick at time t inside the step: the importer's intermediate update. 1 if it
 * requests the early return (honoured only where the importer allowed early return). */
static int intermediate_update(Wrapper *w, double t)
{
    fmi3Boolean requested = fmi3False;
    fmi3Float64 when = t;
    if (!w->update) {
        return 0;
    }
    w->state = ST_INTERMEDIATE_UPDATE;
    w->update(w->env, t, fmi3False, fmi3True, fmi3True, w->early_allowed ? fmi3True : fmi3False,
              &requested, &when);
    w->state = ST_STEP;
    return w->early_allowed && requested;
}

/* 1 if the step ends at the switch or tick at t (early return): where the importer allowed
 * early return, the plant ends it without a callback, with event mode, or on request; the
 * controller without a callback or on request (else the tick is sampled inside the step, on
 * the inputs of its start, as without early return). */
static int ends_step(Wrapper *w, double t)
{
    if (intermediate_update(w, t)) {
        return 1;
    }
    return w->early_allowed && (!w->update || (w->event_mode_used && !w->clock_events));
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation,
                      fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime)
{
    fmi2Status s;
    double t = currentCommunicationPoint;
    const double t_end = currentCommunicationPoint + communicationStepSize;
    ModelState backup_m; /* a step that fails past a switch is undone whole (fmi3Discard) */
    double backup_r[N_VARS];
    WRAP(fmi3DoStep);
    if (!eventHandlingNeeded || !terminateSimulation || !earlyReturn || !lastSuccessfulTime) {
        return FAIL(w, "fmi3DoStep: NULL output argument");
    }
    *eventHandlingNeeded = fmi3False;
    *terminateSimulation = fmi3False;
    *earlyReturn = fmi3False;
    memset(&w->work, 0, sizeof w->work); /* one work bound for the whole call */
    backup_m = w->inner->s.d.m;
    memcpy(backup_r, w->inner->s.d.r, sizeof backup_r);
    for (;;) {
        w->reached = t_end;
        s = instance_do_step(w->inner, t, t_end - t,
                             noSetFMUStatePriorToCurrentPoint ? fmi2True : fmi2False,
                             model_step_fmi3);
        w->tick_passed = 0;
        if (s != fmi2OK && t > currentCommunicationPoint) {
            w->inner->s.d.m = backup_m;
            memcpy(w->inner->s.d.r, backup_r, sizeof backup_r);
            w->inner->s.last_time = currentCommunicationPoint;
        }
        if (s != fmi2OK || !(w->reached < t_end)) {
            break;
        }
        /* stopped at a discrete-state switch (the plant's wall contact) or a tick */
        t = w->reached;
        w->inner->s.last_time = t;
        if (ends_step(w, t)) {
            *earlyReturn = fmi3True;
            *eventHandlingNeeded = w->event_mode_used ? fmi3True : fmi3False;
            log_message(w->inner, fmi2OK, "logAll", "fmi3DoStep returns early at t=%.17g%s", t,
                        !w->event_mode_used ? ""
                        : w->clock_events   ? " (event: a clock tick)"
                                            : " (event: the contact switched)");
            break;
        }
        w->tick_passed = w->clock_events;
    }
#if HAS_CLOCK
    if (s == fmi2OK && w->clock_events && !*earlyReturn) { /* the step's end as one model step */
        w->inner->s.last_time = t_end;                    /* computes it, past passed ticks too */
        w->inner->s.d.m.t = t_end;
    }
    if (s == fmi2OK && w->clock_events) { /* at a tick: inside the step (early) or at its end */
        w->tick_active = tick_due(w);
        *eventHandlingNeeded = w->tick_active ? fmi3True : fmi3False;
    }
#endif
    *lastSuccessfulTime = w->inner->s.last_time;
    return status3(s);
}
