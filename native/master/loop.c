/* The master's stepping loop in C: the same Gauss-Seidel / Jacobi steps as the Python loop in
 * impedance_cosim/cosim/master/master.py, called through ctypes with the FMUs' own fmi2SetReal/fmi2DoStep/
 * fmi2GetReal function pointers (FMI 3.0 co-simulation: fmi3SetFloat64/fmi3DoStep/
 * fmi3GetFloat64), so a step costs the FMUs' time plus well under a microsecond.
 *
 * Rows: data is (n_steps + 1) x n_cols, column 0 the time, then every component's outputs in
 * order (component k's outputs at columns out_col .. out_col + n_out - 1). Row `first` must be
 * filled by the caller; the loop fills rows first+1 .. first+n_steps.
 *
 * Input extrapolation (Jacobi only; impedance_cosim/cosim/master/extrapolation.py): with `rates` not
 * NULL (one per column, the time derivatives of the outputs at the row before the step), each
 * input is row[col] + h * rates[col]; after each step the components with n_rate > 0 refresh
 * their columns of `rates` (fmi2GetRealOutputDerivatives / fmi3GetOutputDerivatives, order 1).
 */
#include <math.h>
#include <stdbool.h>
#include <stddef.h>
#include <string.h>

typedef int (*set_real_t)(void *, const unsigned *, size_t, const double *);
typedef int (*get_real_t)(void *, const unsigned *, size_t, double *);
typedef int (*do_step_t)(void *, double, double, int);
/* FMI 3.0: fmi3SetFloat64/fmi3GetFloat64 take the number of values too; fmi3DoStep reports
 * events, termination, an early return and the time reached (no early return is allowed at
 * instantiation, so the step always reaches t + h, as in the Python loop). */
typedef int (*set_float64_t)(void *, const unsigned *, size_t, const double *, size_t);
typedef int (*get_float64_t)(void *, const unsigned *, size_t, double *, size_t);
typedef int (*do_step3_t)(void *, double, double, bool, bool *, bool *, bool *, double *);
typedef int (*get_deriv_t)(void *, const unsigned *, size_t, const int *, double *);
typedef int (*get_deriv3_t)(void *, const unsigned *, size_t, const int *, double *, size_t);

#define MAX_IO 256

/* One FMU function of either standard (the `fmi3` flag of the component says which). */
typedef union {
    set_real_t fmi2;
    set_float64_t fmi3;
} SetFn;
typedef union {
    get_real_t fmi2;
    get_float64_t fmi3;
} GetFn;
typedef union {
    do_step_t fmi2;
    do_step3_t fmi3;
} StepFn;
typedef union {
    get_deriv_t fmi2;
    get_deriv3_t fmi3;
} DerivFn;

typedef struct {
    void *component;
    SetFn set_real;
    GetFn get_real;
    StepFn do_step;
    int fmi3;
    int n_in;
    const unsigned *in_vr;
    const int *in_col; /* column of the row each input is fed from */
    int n_out;
    const unsigned *out_vr;
    int out_col;
    DerivFn get_deriv;    /* with n_rate > 0: the outputs' time derivatives */
    int n_rate;
    const unsigned *rate_vr;
    const int *rate_col; /* column of each derivative in rates */
} Comp;

typedef struct {
    int comp;   /* component that failed, or -1 */
    int status; /* its FMI status */
    int call;   /* 0 set, 1 step, 2 get, 3 get derivatives */
    int column; /* diverged column, or -1 */
} LoopError;

static int feed(const Comp *c, const double *row, const double *rates, double h)
{
    double in[MAX_IO];
    const size_t n = (size_t)c->n_in;
    if (n == 0) {
        return 0;
    }
    for (size_t k = 0; k < n; k++) {
        const int col = c->in_col[k];
        in[k] = rates ? row[col] + h * rates[col] : row[col];
    }
    if (c->fmi3) {
        return c->set_real.fmi3(c->component, c->in_vr, n, in, n);
    }
    return c->set_real.fmi2(c->component, c->in_vr, n, in);
}

static int step(const Comp *c, double t, double h)
{
    if (c->fmi3) {
        bool event = false, terminate = false, early = false;
        double reached = t + h;
        return c->do_step.fmi3(c->component, t, h, true, &event, &terminate, &early, &reached);
    }
    return c->do_step.fmi2(c->component, t, h, 1);
}

static int collect(const Comp *c, double *row)
{
    const size_t n = (size_t)c->n_out;
    if (c->fmi3) {
        return c->get_real.fmi3(c->component, c->out_vr, n, row + c->out_col, n);
    }
    return c->get_real.fmi2(c->component, c->out_vr, n, row + c->out_col);
}

static int derivatives(const Comp *c, double *rates)
{
    int ones[MAX_IO];
    double d[MAX_IO];
    const size_t n = (size_t)c->n_rate;
    if (n > MAX_IO) {
        return 3; /* fmi2Error: more than the loop takes (fastloop.unsupported refuses it first) */
    }
    for (size_t k = 0; k < n; k++) {
        ones[k] = 1; /* first derivatives */
    }
    int s = c->fmi3 ? c->get_deriv.fmi3(c->component, c->rate_vr, n, ones, d, n)
                    : c->get_deriv.fmi2(c->component, c->rate_vr, n, ones, d);
    for (size_t k = 0; k < n && s <= 1; k++) {
        rates[c->rate_col[k]] = d[k];
    }
    return s;
}

/* Returns the number of rows filled after `first` (n_steps when all went well). */
long run_loop(const Comp *comps, int n_comps, int jacobi, double t0, double h, long first,
              long n_steps, double limit, double *data, int n_cols, double *rates,
              LoopError *err)
{
    err->comp = -1;
    err->column = -1;
    for (long i = first; i < first + n_steps; i++) {
        const double t = t0 + (double)i * h;
        double *prev = data + (size_t)i * (size_t)n_cols;
        double *cur = prev + n_cols;
        memcpy(cur, prev, sizeof(double) * (size_t)n_cols);
        cur[0] = t0 + (double)(i + 1) * h;
        for (int k = 0; k < n_comps; k++) {
            const Comp *c = &comps[k];
            int s = feed(c, jacobi ? prev : cur, jacobi ? rates : NULL, h);
            if (s > 1) {
                err->comp = k, err->status = s, err->call = 0;
                return i - first;
            }
            if (!jacobi) {
                s = step(c, t, h);
                if (s > 1) {
                    err->comp = k, err->status = s, err->call = 1;
                    return i - first;
                }
                s = collect(c, cur);
                if (s > 1) {
                    err->comp = k, err->status = s, err->call = 2;
                    return i - first;
                }
            }
        }
        if (jacobi) {
            for (int k = 0; k < n_comps; k++) {
                const Comp *c = &comps[k];
                int s = step(c, t, h);
                if (s > 1) {
                    err->comp = k, err->status = s, err->call = 1;
                    return i - first;
                }
            }
            for (int k = 0; k < n_comps; k++) {
                const Comp *c = &comps[k];
                int s = collect(c, cur);
                if (s > 1) {
                    err->comp = k, err->status = s, err->call = 2;
                    return i - first;
                }
                s = rates && c->n_rate > 0 ? derivatives(c, rates) : 0;
                if (s > 1) {
                    err->comp = k, err->status = s, err->call = 3;
                    return i - first;
                }
            }
        }
        for (int j = 0; j < n_cols; j++) {
            if (!isfinite(cur[j]) || fabs(cur[j]) > limit) {
                err->column = j;
                return i - first + 1; /* the offending row is kept */
            }
        }
    }
    return n_steps;
}
