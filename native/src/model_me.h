/* What a native model implements to offer FMI 2.0 Model Exchange (instance_me.c calls it): models
 * whose generated config.h defines MODEL_EXCHANGE (with N_STATES, N_EVENT_INDICATORS and
 * DERIVATIVE_VRS[]). Their continuous states live in the model's own state (d->m). */
#ifndef MODEL_ME_H
#define MODEL_ME_H

#include "glue.h"

/* ME_OFFERED 0 in config.h: the model has the Model Exchange side the FMI 3 layer compiles
 * against, but does not offer it (the closed loop: co-simulation only). */
#ifndef ME_OFFERED
#define ME_OFFERED 1
#endif

#ifdef MODEL_EXCHANGE
#define ME_SUPPORTED ME_OFFERED

/* What an event update tells the host (fmi2EventInfo, in model terms). */
typedef struct {
    int changed;       /* the discrete state changed (outputs and derivatives may have) */
    int again;         /* another update is needed at the same time instant */
    int next_defined;  /* a time event is due at next */
    double next;
} MeEvent;

int model_me_check(const Data *d, char *msg); /* settings that ME cannot honour */
void model_me_get_states(const Data *d, double x[]);   /* N_STATES values */
void model_me_set_states(Data *d, const double x[]);   /* N_STATES values */
/* Outputs and the derivative variables (DERIVATIVE_VRS) at the current state, inputs and
 * discrete state, from the same equations the co-simulation step uses. */
int model_me_evaluate(Data *d, char *msg);
int model_me_event_indicators(const Data *d, double z[], char *msg); /* N_EVENT_INDICATORS */
/* At an event at time t: update the discrete state, say what changed and the next time event. */
int model_me_event_update(Data *d, double t, MeEvent *ev, char *msg);
/* model_step_to_tick of a clocked model (FMI 3.0 Co-Simulation with event mode): stop at the
 * first tick inside the step for early return, or for the intermediate update (the whole step
 * then bounded as model_step bounds it); the tick at the step's start sampled inside it */
#define TICK_EARLY 1
#define TICK_UPDATE 2
#define TICK_RESUME 4
#else
#define ME_SUPPORTED 0
#endif

#endif
