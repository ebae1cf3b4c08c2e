/* FMI 3.0 Co-Simulation stepping (see fmi3_glue.c): fmi3DoStep with early return, the
 * intermediate update callback and event mode at the model's discrete-state switches (the plant's
 * wall contact, model_step_early), and the Step Mode / Event Mode state machine of
 * Co-Simulation. A model without such switches (HAS_EARLY_RETURN 0) steps as under FMI 2.0.
 *
 * At a switch the model step has stopped with the mode switched, its outputs computed at the
 * switch time: the intermediate update there offers them (intermediateStepFinished, get allowed,
 * no input set requested). The step ends there (earlyReturn) only where the importer allowed early
 * return: with eventModeUsed (then with eventHandlingNeeded), without an intermediate update
 * callback, or when the callback requests it; else it goes on to the communication point. */
#include <string.h>

#include "fmi3_wrapper.h"

static const char *const UPDATE_GETTERS[] = {"fmi3GetFloat64", "fmi3GetInt32", "fmi3GetInt64",
                                             "fmi3GetBoolean", "fmi3GetString"};

int allowed_in_update(Wrapper *w, const char *function)
{
    if (!w->in_update) {
        return 1;
    }
    for (size_t k = 0; k < sizeof UPDATE_GETTERS / sizeof UPDATE_GETTERS[0]; k++) {
        if (strcmp(function, UPDATE_GETTERS[k]) == 0) {
            return 1;
        }
    }
    log_message(w->inner, fmi2Error, "logStatusError",
                "%s called inside the intermediate update callback: only fmi3Get{VariableType} "
                "of the outputs is allowed there (no input is requested)", function);
    return 0;
}

/* Co-Simulation fmi3EnterEventMode: from Step Mode, where the importer used event mode. */
fmi3Status cs_enter_event_mode(Wrapper *w)
{
    if (!w->event_mode_used) {
        return FAIL(w, "fmi3EnterEventMode: the instance was created with eventModeUsed=false");
    }
    if (w->inner->s.phase != S_STEP_COMPLETE || w->cs_event_mode) {
        return FAIL(w, "fmi3EnterEventMode: allowed in Step Mode only (after "
                       "fmi3ExitInitializationMode and fmi3EnterStepMode)");
    }
    w->cs_event_mode = 1;
    return fmi3OK;
}

/* Co-Simulation fmi3UpdateDiscreteStates, in Event Mode: the model step has already switched
 * the contact mode at the event and nothing else is discrete, so nothing changes here. */
fmi3Status cs_update_discrete_states(Wrapper *w, fmi3Boolean *discreteStatesNeedUpdate,
                                     fmi3Boolean *terminateSimulation,
                                     fmi3Boolean *nominalsOfContinuousStatesChanged,
                                     fmi3Boolean *valuesOfContinuousStatesChanged,
                                     fmi3Boolean *nextEventTimeDefined,
                                     fmi3Float64 *nextEventTime)
{
    if (!w->cs_event_mode) {
        return FAIL(w, "fmi3UpdateDiscreteStates: allowed in Event Mode only (call "
                       "fmi3EnterEventMode first)");
    }
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
    return fmi3OK;
}

fmi3Status fmi3EnterStepMode(fmi3Instance instance)
{
    WRAP("fmi3EnterStepMode");
    if (w->kind != K_CS || !w->event_mode_used) {
        return FAIL(w, "fmi3EnterStepMode: only for co-simulation with eventModeUsed=true");
    }
    if (!w->cs_event_mode) {
        return FAIL(w, "fmi3EnterStepMode: allowed in Event Mode only (already in Step Mode)");
    }
    w->cs_event_mode = 0;
    return fmi3OK;
}

/* At a switch at time t inside the step: the importer's intermediate update. 1 if it requests
 * the early return (honoured only where the importer allowed early return). */
static int intermediate_update(Wrapper *w, double t)
{
    fmi3Boolean requested = fmi3False;
    fmi3Float64 when = t;
    if (!w->update) {
        return 0;
    }
    w->in_update = 1;
    w->update(w->env, t, fmi3False, fmi3True, fmi3True, w->early_allowed ? fmi3True : fmi3False,
              &requested, &when);
    w->in_update = 0;
    return w->early_allowed && requested;
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
    WRAP("fmi3DoStep");
    if (w->kind != K_CS) {
        return FAIL(w, "fmi3DoStep: this instance is not for co-simulation");
    }
    if (!eventHandlingNeeded || !terminateSimulation || !earlyReturn || !lastSuccessfulTime) {
        return FAIL(w, "fmi3DoStep: NULL output argument");
    }
    if (w->cs_event_mode) {
        return FAIL(w, "fmi3DoStep called in Event Mode: call fmi3EnterStepMode first");
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
        if (s != fmi2OK && t > currentCommunicationPoint) {
            w->inner->s.d.m = backup_m;
            memcpy(w->inner->s.d.r, backup_r, sizeof backup_r);
            w->inner->s.last_time = currentCommunicationPoint;
        }
        if (s != fmi2OK || !(w->reached < t_end)) {
            break;
        }
        /* stopped at a discrete-state switch (the plant's wall contact) */
        t = w->reached;
        w->inner->s.last_time = t;
        if (intermediate_update(w, t) || (w->early_allowed && (!w->update ||
                                                                w->event_mode_used))) {
            *earlyReturn = fmi3True;
            *eventHandlingNeeded = w->event_mode_used ? fmi3True : fmi3False;
            log_message(w->inner, fmi2OK, "logAll", "fmi3DoStep returns early at t=%.17g%s", t,
                        w->event_mode_used ? " (event: the contact switched)" : "");
            break;
        }
    }
    *lastSuccessfulTime = w->inner->s.last_time;
    return status3(s);
}
