/* What a native model implements to offer FMI 2.0 Model Exchange (fmi2_me.c calls it): models
 * whose generated config.h defines MODEL_EXCHANGE (with N_STATES, N_EVENT_INDICATORS and
 * DERIVATIVE_VRS[]). Their continuous states live in the model's own state (d->m). */
#ifndef MODEL_ME_H
#define MODEL_ME_H

#include "glue.h"

#ifdef MODEL_EXCHANGE
#define ME_SUPPORTED 1
int model_me_check(const Data *d, char *msg); /* settings that ME cannot honour */
void model_me_get_states(const Data *d, double x[N_STATES]);
void model_me_set_states(Data *d, const double x[N_STATES]);
/* Outputs and the derivative variables (DERIVATIVE_VRS) at the current state, inputs and
 * discrete mode, from the same right-hand side the co-simulation integrator uses. */
int model_me_evaluate(Data *d, char *msg);
int model_me_event_indicators(const Data *d, double z[N_EVENT_INDICATORS], char *msg);
/* At an event: update the discrete state; *changed = 1 if it changed, *again = 1 if another
 * update is needed at the same time instant. */
int model_me_event_update(Data *d, int *changed, int *again, char *msg);
#else
#define ME_SUPPORTED 0
#endif

#endif
