/* The master's stepping loop in C: the same Gauss-Seidel / Jacobi steps as the Python loop in
 * impedance_cosim/cosim/master.py, called through ctypes with the FMUs' own fmi2SetReal/fmi2DoStep/
 * fmi2GetReal function pointers, so a step costs the FMUs' time plus well under a microsecond.
 *
 * Rows: data is (n_steps + 1) x n_cols, column 0 the time, then every component's outputs in
 * order (component k's outputs at columns out_col .. out_col + n_out - 1). Row `first` must be
 * filled by the caller; the loop fills rows first+1 .. first+n_steps.
 */
#include <math.h>
#include <stddef.h>
#include <string.h>

typedef int (*set_real_t)(void *, const unsigned *, size_t, const double *);
typedef int (*get_real_t)(void *, const unsigned *, size_t, double *);
typedef int (*do_step_t)(void *, double, double, int);

#define MAX_IO 256

typedef struct {
    void *component;
    set_real_t set_real;
    get_real_t get_real;
    do_step_t do_step;
    int n_in;
    const unsigned *in_vr;
    const int *in_col; /* column of the row each input is fed from */
    int n_out;
    const unsigned *out_vr;
    int out_col;
} Comp;

typedef struct {
    int comp;   /* component that failed, or -1 */
    int status; /* its FMI status */
    int call;   /* 0 set, 1 step, 2 get */
    int column; /* diverged column, or -1 */
} LoopError;

static int feed(const Comp *c, const double *row)
{
    double in[MAX_IO];
    if (c->n_in == 0) {
        return 0;
    }
    for (int k = 0; k < c->n_in; k++) {
        in[k] = row[c->in_col[k]];
    }
    return c->set_real(c->component, c->in_vr, (size_t)c->n_in, in);
}

/* Returns the number of rows filled after `first` (n_steps when all went well). */
long run_loop(const Comp *comps, int n_comps, int jacobi, double t0, double h, long first,
              long n_steps, double limit, double *data, int n_cols, LoopError *err)
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
            int s = feed(c, jacobi ? prev : cur);
            if (s > 1) {
                err->comp = k, err->status = s, err->call = 0;
                return i - first;
            }
            if (!jacobi) {
                s = c->do_step(c->component, t, h, 1);
                if (s > 1) {
                    err->comp = k, err->status = s, err->call = 1;
                    return i - first;
                }
                s = c->get_real(c->component, c->out_vr, (size_t)c->n_out, cur + c->out_col);
                if (s > 1) {
                    err->comp = k, err->status = s, err->call = 2;
                    return i - first;
                }
            }
        }
        if (jacobi) {
            for (int k = 0; k < n_comps; k++) {
                const Comp *c = &comps[k];
                int s = c->do_step(c->component, t, h, 1);
                if (s > 1) {
                    err->comp = k, err->status = s, err->call = 1;
                    return i - first;
                }
            }
            for (int k = 0; k < n_comps; k++) {
                const Comp *c = &comps[k];
                int s = c->get_real(c->component, c->out_vr, (size_t)c->n_out, cur + c->out_col);
                if (s > 1) {
                    err->comp = k, err->status = s, err->call = 2;
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
