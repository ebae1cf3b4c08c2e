/* Exact partial derivatives and output derivatives of a native model (FMI 2.0
 * fmi2GetDirectionalDerivative / fmi2GetRealOutputDerivatives, FMI 3.0
 * fmi3GetDirectionalDerivative / fmi3GetOutputDerivatives: partials.c checks the call, the model
 * computes). A model offers them when its generated config.h defines MODEL_PARTIALS (with
 * N_KNOWNS, KNOWN_VRS[]: the states, then the inputs; MAX_OUTPUT_DERIVATIVE_ORDER) and its
 * model.c implements the two model_* functions of model_partials.h. */
#ifndef PARTIALS_H
#define PARTIALS_H

#include <stddef.h>

#include "instance.h"
#include "model_partials.h" /* what the model computes */

/* The checked call (function: the FMI function's name, for the log): sensitivity[u] =
 * sum_k d unknowns[u] / d knowns[k] * seed[k]. Under Model Exchange the knowns are states and
 * inputs, in co-simulation the inputs (the standard's knowns of the mode). */
fmi2Status partials_directional(Instance *inst, const char *function,
                                const unsigned int unknowns[], size_t n_unknowns,
                                const unsigned int knowns[], size_t n_knowns, const double seed[],
                                double sensitivity[]);
/* values[i] = the orders[i]-th time derivative of output vrs[i] (co-simulation, after
 * initialization). */
fmi2Status partials_output_derivatives(Instance *inst, const char *function,
                                       const unsigned int vrs[], size_t n, const int orders[],
                                       double values[]);

#endif
