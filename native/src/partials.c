/* The FMI side of the exact partial derivatives (partials.h): which calls are legal, in which
 * mode, for which variables; the numbers come from the model (model_partials,
 * model_output_derivative). Models without MODEL_PARTIALS refuse both, naming the capability. */
#include <stdio.h>
#include <string.h>

#include "partials.h"

#define ERR(inst, ...) (log_message((inst), fmi2Error, "logStatusError", __VA_ARGS__), fmi2Error)

#ifdef MODEL_PARTIALS

static int is_derivative(unsigned int vr)
{
    for (int k = 0; k < N_STATES; k++) {
        if ((unsigned int)DERIVATIVE_VRS[k] == vr) {
            return 1;
        }
    }
    return 0;
}

static int known_index(unsigned int vr)
{
    for (int k = 0; k < N_KNOWNS; k++) {
        if ((unsigned int)KNOWN_VRS[k] == vr) {
            return k;
        }
    }
    return -1;
}

fmi2Status partials_directional(Instance *inst, const char *function,
                                const unsigned int unknowns[], size_t n_unknowns,
                                const unsigned int knowns[], size_t n_knowns, const double seed[],
                                double sensitivity[])
{
    double jac[N_VARS][N_KNOWNS];
    int col[N_VARS];
    const int cs = inst->type == fmi2CoSimulation;
    if ((n_unknowns && (!unknowns || !sensitivity)) || (n_knowns && (!knowns || !seed))) {
        return ERR(inst, "%s: NULL array with a non-zero count", function);
    }
    if (n_knowns > N_VARS) {
        return ERR(inst, "%s: %zu knowns, more than the %d variables", function, n_knowns,
                   N_VARS);
    }
    for (size_t u = 0; u < n_unknowns; u++) {
        const unsigned int vr = unknowns[u];
        if (vr >= N_VARS || !(VARS[vr].causality == C_OUTPUT || is_derivative(vr))) {
            return ERR(inst, "%s: unknown %u is not an output or a state derivative", function,
                       vr);
        }
    }
    for (size_t k = 0; k < n_knowns; k++) {
        const unsigned int vr = knowns[k];
        const int i = known_index(vr);
        if (i < 0 || (cs && VARS[vr].causality != C_INPUT)) {
            return ERR(inst, "%s: known %u (%s) is not %s", function, vr,
                       vr < N_VARS ? VARS[vr].name : "no variable",
                       cs ? "an input (in co-simulation the knowns are the inputs)"
                          : "a continuous state or an input");
        }
        if (!(seed[k] - seed[k] == 0.0)) {
            return ERR(inst, "%s: seed %zu (for %s) is not finite", function, k, VARS[vr].name);
        }
        col[k] = i;
    }
    if (model_partials(&inst->s.d, jac, inst->msg)) {
        return ERR(inst, "%s: %s", function, inst->msg);
    }
    for (size_t u = 0; u < n_unknowns; u++) {
        double sum = 0.0;
        for (size_t k = 0; k < n_knowns; k++) {
            sum += jac[unknowns[u]][col[k]] * seed[k];
        }
        sensitivity[u] = sum;
    }
    return fmi2OK;
}

fmi2Status partials_output_derivatives(Instance *inst, const char *function,
                                       const unsigned int vrs[], size_t n, const int orders[],
                                       double values[])
{
    if (inst->type != fmi2CoSimulation) {
        return ERR(inst, "%s: output derivatives are a co-simulation function", function);
    }
    if (n && (!vrs || !orders || !values)) {
        return ERR(inst, "%s: NULL array with a non-zero count", function);
    }
    for (size_t i = 0; i < n; i++) {
        if (vrs[i] >= N_VARS || VARS[vrs[i]].causality != C_OUTPUT) {
            return ERR(inst, "%s: variable %u is not an output", function, vrs[i]);
        }
        if (orders[i] < 1 || orders[i] > MAX_OUTPUT_DERIVATIVE_ORDER) {
            return ERR(inst, "%s: order %d of %s refused: this FMU gives output derivatives of"
                             " order 1 to %d (maxOutputDerivativeOrder)", function, orders[i],
                       VARS[vrs[i]].name, MAX_OUTPUT_DERIVATIVE_ORDER);
        }
    }
    for (size_t i = 0; i < n; i++) {
        if (model_output_derivative(&inst->s.d, (int)vrs[i], orders[i], &values[i],
                                    inst->msg)) {
            return ERR(inst, "%s: %s", function, inst->msg);
        }
    }
    return fmi2OK;
}

#else /* the model provides neither */

fmi2Status partials_directional(Instance *inst, const char *function,
                                const unsigned int unknowns[], size_t n_unknowns,
                                const unsigned int knowns[], size_t n_knowns, const double seed[],
                                double sensitivity[])
{
    (void)unknowns, (void)n_unknowns, (void)knowns, (void)n_knowns, (void)seed,
        (void)sensitivity;
    return ERR(inst, "%s: directional derivatives are not provided", function);
}

fmi2Status partials_output_derivatives(Instance *inst, const char *function,
                                       const unsigned int vrs[], size_t n, const int orders[],
                                       double values[])
{
    (void)vrs, (void)n, (void)orders, (void)values;
    return ERR(inst, "%s: output derivatives are not provided (maxOutputDerivativeOrder=0)",
               function);
}

#endif
