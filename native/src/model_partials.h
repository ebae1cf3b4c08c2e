/* What a native model implements to provide exact partial derivatives and output derivatives
 * (partials.c calls it, see partials.h): models whose generated config.h defines MODEL_PARTIALS
 * (with N_KNOWNS, KNOWN_VRS[]: the states, then the inputs; MAX_OUTPUT_DERIVATIVE_ORDER). Plain
 * model code: no FMI types. */
#ifndef MODEL_PARTIALS_H
#define MODEL_PARTIALS_H

#include "glue.h"

#ifdef MODEL_PARTIALS
/* jac[r][k] = d (variable r) / d (known KNOWN_VRS[k]) at the current state, inputs and discrete
 * state, for every output and der() variable r (other rows zero). 0, or 1 with msg set. */
int model_partials(const Data *d, double jac[N_VARS][N_KNOWNS], char *msg);
/* The order-th time derivative of output vr at the current state and inputs (1 <= order <=
 * MAX_OUTPUT_DERIVATIVE_ORDER). 0, or 1 with msg set. */
int model_output_derivative(const Data *d, int vr, int order, double *value, char *msg);
#endif

#endif
