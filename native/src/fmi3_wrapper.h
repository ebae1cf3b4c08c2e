/* The FMI 3.0 instance of the native FMUs, shared by fmi3_glue.c (lifecycle,
 * values, FMU state, co-simulation), fmi3_events.c (Model Exchange, the clock of Scheduled
 * Execution) and fmi3_stubs.c (what these FMUs do not provide). A Wrapper holds the instance of
 * the instance core (instance.h), which has the model's state, and what FMI 3.0 adds to it: its
 * state in the FMI 3.0 state machine (fmi3_states.h), the importer's choices and callbacks. */
#ifndef FMI3_WRAPPER_H
#define FMI3_WRAPPER_H

#include "fmi3Functions.h"
#include "glue.h"
#include "instance.h"
#include "fmi3_states.h" /* State3, MASK_<function> */
#include "fmi3_config.h" /* VR_TIME, VR_INDICATOR; HAS_CLOCK, VR_CLOCK, CLOCK_PERIOD_VR;
                            HAS_EARLY_RETURN: written by the build */

#define WRAPPER_MAGIC 0x494d5033u /* "IMP3" */

typedef enum { K_ME, K_CS, K_SE } Kind;

typedef struct {
    unsigned magic; /* WRAPPER_MAGIC while alive; fmi3FreeInstance clears it */
    Instance *inner; /* the instance core's instance (instance.c): the model's state */
    Kind kind;
    State3 state; /* where the instance is in the FMI 3.0 state machine */
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log;
    int early_return; /* co-simulation: the model step stops at each switch (model_step_early) */
    double reached;   /* where the last model step stopped */
    StepWork work;    /* the current fmi3DoStep's work so far, across its model steps */
    int early_allowed;  /* the importer's earlyReturnAllowed */
    int event_mode_used; /* the importer's eventModeUsed */
    fmi3IntermediateUpdateCallback update; /* the importer's, or NULL */
    int clock_events; /* a model with the sample clock, in Model Exchange or in co-simulation
                         with eventModeUsed: its ticks are events */
    int tick_active;  /* clock_events: the sample clock is active (Event Mode at a tick, until
                         fmi3UpdateDiscreteStates) */
    int tick_passed;  /* fmi3DoStep goes on from a tick the intermediate update let pass: the
                         next model step samples it */
} Wrapper;

/* An fmi2Status as fmi3Status (the same numbers; fmi2Pending, never returned, as fmi3Error). */
fmi3Status status3(fmi2Status s);
/* The core's transition's status s; where it succeeded, the wrapper in state, its clock inactive. */
fmi3Status entered(Wrapper *w, fmi2Status s, State3 state);
/* The wrapper, if instance is a live FMI 3 instance of this FMU (else NULL, said on stderr:
 * the host's logger lives in the instance and cannot be trusted then). */
Wrapper *wrapper_of(fmi3Instance instance, const char *function);

/* First line of every entry point: w, or return fmi3Error where instance is not live or the
 * function is not legal in its state (MASK_<function>, fmi3_states.h). */
#define WRAP(function)                                                                         \
    Wrapper *w = wrapper_of(instance, #function);                                              \
    if (!w || !state_allows(w, MASK_##function, #function)) {                                  \
        return fmi3Error;                                                                      \
    }

/* fmi3_cosim.c: 1 if w's state is in mask, else 0 after logging the function and the state. */
int state_allows(Wrapper *w, unsigned mask, const char *function);
/* fmi3_cosim.c: the state after the instance core's Snapshot was restored (fmi3SetFMUState). */
State3 state_of_core(const Wrapper *w);
/* fmi3_glue.c: the model step of fmi3DoStep (model_step, or with early return on, one that stops
 * at the next discrete-state switch) */
int model_step_fmi3(Data *d, double t, double h, char *msg);
/* Co-Simulation Event Mode (fmi3_cosim.c): fmi3EnterEventMode, fmi3UpdateDiscreteStates. */
fmi3Status cs_enter_event_mode(Wrapper *w);
fmi3Status cs_update_discrete_states(Wrapper *w, fmi3Boolean *discreteStatesNeedUpdate,
                                     fmi3Boolean *terminateSimulation,
                                     fmi3Boolean *nominalsOfContinuousStatesChanged,
                                     fmi3Boolean *valuesOfContinuousStatesChanged,
                                     fmi3Boolean *nextEventTimeDefined,
                                     fmi3Float64 *nextEventTime);

#if HAS_CLOCK
/* the controller's model_me.c: the next sample's time; the step stopping at a tick if early */
double model_next_tick(const Data *d);
int model_step_to_tick(Data *d, double t, double h, int early, double *reached, char *msg);
/* fmi3_cosim.c: 1 if a sample is due at the instance's current time (not taken yet) */
int tick_due(const Wrapper *w);
/* fmi3_cosim.c: the clock's activation in a restored Event Mode (fmi3SetFMUState) */
int tick_pending(const Wrapper *w);
#endif

#define FAIL(w, ...) (log_message((w)->inner, fmi2Error, "logStatusError", __VA_ARGS__), fmi3Error)

#endif
