/* See ode.h: a transcription of impedance_cosim/physics/ode.py. Sums and products keep Python's
 * left-to-right evaluation order; min/max keep Python's tie and NaN behaviour. */
#include <math.h>
#include <stdio.h>

#include "ode.h"
#include "pyrepr.h" /* py_float_repr, for messages like the Python ones */

/* Dormand & Prince (1980) RK5(4)7M tableau. */
static const double A2 = 1.0 / 5.0;
static const double A3[2] = {3.0 / 40.0, 9.0 / 40.0};
static const double A4[3] = {44.0 / 45.0, -56.0 / 15.0, 32.0 / 9.0};
static const double A5[4] = {19372.0 / 6561.0, -25360.0 / 2187.0, 64448.0 / 6561.0,
                             -212.0 / 729.0};
static const double A6[5] = {9017.0 / 3168.0, -355.0 / 33.0, 46732.0 / 5247.0, 49.0 / 176.0,
                             -5103.0 / 18656.0};
/* weights of k1, k3, k4, k5, k6 */
static const double B[5] = {35.0 / 384.0, 500.0 / 1113.0, 125.0 / 192.0, -2187.0 / 6784.0,
                            11.0 / 84.0};
/* error weights (5th minus 4th order) for k1, k3, k4, k5, k6, k7 */
static const double E[6] = {71.0 / 57600.0, -71.0 / 16695.0, 71.0 / 1920.0, -17253.0 / 339200.0,
                            22.0 / 525.0, -1.0 / 40.0};

int ode_dopri5_step(OdeRhs f, void *ctx, const double y[ODE_N], double h, const double k1[ODE_N],
                    double y_new[ODE_N], double err[ODE_N], double k7[ODE_N], char *msg)
{
    double k2[ODE_N], k3[ODE_N], k4[ODE_N], k5[ODE_N], k6[ODE_N], ys[ODE_N];
    int i;
    for (i = 0; i < ODE_N; i++) {
        ys[i] = y[i] + h * A2 * k1[i];
    }
    if (f(ctx, ys, k2, msg)) {
        return ODE_FAILED;
    }
    for (i = 0; i < ODE_N; i++) {
        ys[i] = y[i] + h * (A3[0] * k1[i] + A3[1] * k2[i]);
    }
    if (f(ctx, ys, k3, msg)) {
        return ODE_FAILED;
    }
    for (i = 0; i < ODE_N; i++) {
        ys[i] = y[i] + h * (A4[0] * k1[i] + A4[1] * k2[i] + A4[2] * k3[i]);
    }
    if (f(ctx, ys, k4, msg)) {
        return ODE_FAILED;
    }
    for (i = 0; i < ODE_N; i++) {
        ys[i] = y[i] + h * (A5[0] * k1[i] + A5[1] * k2[i] + A5[2] * k3[i] + A5[3] * k4[i]);
    }
    if (f(ctx, ys, k5, msg)) {
        return ODE_FAILED;
    }
    for (i = 0; i < ODE_N; i++) {
        ys[i] = y[i] + h * (A6[0] * k1[i] + A6[1] * k2[i] + A6[2] * k3[i] + A6[3] * k4[i]
                            + A6[4] * k5[i]);
    }
    if (f(ctx, ys, k6, msg)) {
        return ODE_FAILED;
    }
    for (i = 0; i < ODE_N; i++) {
        y_new[i] = y[i] + h * (B[0] * k1[i] + B[1] * k3[i] + B[2] * k4[i] + B[3] * k5[i]
                               + B[4] * k6[i]);
    }
    if (f(ctx, y_new, k7, msg)) {
        return ODE_FAILED;
    }
    for (i = 0; i < ODE_N; i++) {
        err[i] = h * (E[0] * k1[i] + E[1] * k3[i] + E[2] * k4[i] + E[3] * k5[i] + E[4] * k6[i]
                      + E[5] * k7[i]);
    }
    return ODE_OK;
}

double ode_error_norm(const double y[ODE_N], const double y_new[ODE_N], const double err[ODE_N],
                      double rtol, double atol)
{
    double worst = 0.0;
    for (int i = 0; i < ODE_N; i++) {
        const double ay = fabs(y[i]), an = fabs(y_new[i]);
        const double big = an > ay ? an : ay; /* Python max(ay, an) */
        const double scaled = fabs(err[i]) / (atol + rtol * big);
        if (!(scaled <= worst)) { /* also catches NaN */
            worst = scaled == scaled ? scaled : (double)INFINITY;
        }
    }
    return worst;
}

int ode_euler_step(OdeRhs f, void *ctx, const double y[ODE_N], double h, double y_new[ODE_N],
                   char *msg)
{
    double k[ODE_N];
    if (f(ctx, y, k, msg)) {
        return ODE_FAILED;
    }
    for (int i = 0; i < ODE_N; i++) {
        y_new[i] = y[i] + h * k[i];
    }
    return ODE_OK;
}

static int all_finite(const double y[ODE_N])
{
    for (int i = 0; i < ODE_N; i++) {
        if (!isfinite(y[i])) {
            return 0;
        }
    }
    return 1;
}

/* ode._locate: the event time inside the step [t, t + h] by the Illinois method on the step
 * size, re-stepping from y; (offset into the step, state) just past the crossing (event > 0). */
static int locate(OdeRhs f, OdeEvent event, void *ctx, const double y[ODE_N],
                  const double k1[ODE_N], double h, double g0, double time_tol, double *t_ev,
                  double y_ev[ODE_N], char *msg)
{
    double lo = 0.0, g_lo = g0, hi = h, g_hi, g_s, s;
    double y_hi[ODE_N], y_s[ODE_N], e[ODE_N], k7[ODE_N];
    int side = 0, i;
    if (ode_dopri5_step(f, ctx, y, hi, k1, y_hi, e, k7, msg) || event(ctx, y_hi, &g_hi, msg)) {
        return ODE_FAILED;
    }
    for (int it = 0; it < 100; it++) {
        if (hi - lo <= time_tol) {
            break;
        }
        {
            const double den = g_hi - g_lo;
            if (den == 0.0) {
                snprintf(msg, ODE_MSG_MAX, "float division by zero");
                return ODE_FAILED;
            }
            s = hi - g_hi * (hi - lo) / den;
        }
        if (!(lo < s && s < hi)) {
            s = 0.5 * (lo + hi);
        }
        if (ode_dopri5_step(f, ctx, y, s, k1, y_s, e, k7, msg) || event(ctx, y_s, &g_s, msg)) {
            return ODE_FAILED;
        }
        if (g_s > 0.0) {
            hi = s;
            g_hi = g_s;
            for (i = 0; i < ODE_N; i++) {
                y_hi[i] = y_s[i];
            }
            if (side == 1) {
                g_lo *= 0.5;
            }
            side = 1;
        } else {
            lo = s;
            g_lo = g_s;
            if (side == -1) {
                g_hi *= 0.5;
            }
            side = -1;
        }
    }
    *t_ev = hi;
    for (i = 0; i < ODE_N; i++) {
        y_ev[i] = y_hi[i];
    }
    return ODE_OK;
}

/* One ode_integrate run: the problem and where the integration stands. */
typedef struct {
    OdeRhs f;
    OdeEvent event;
    void *ctx;
    double t1, rtol, atol, time_tol;
    double t, h, g_prev, y[ODE_N], k1[ODE_N];
} Run;

/* A rejected step of h_try: the smaller next step size into r->h, or ODE_FAILED with msg when
 * the state went non-finite or the step size underflowed. */
static int rejected(Run *r, double norm, double h_try, char *msg)
{
    char a[40];
    if (!isfinite(norm) && !all_finite(r->y)) {
        py_float_repr(r->t, a, sizeof a);
        snprintf(msg, ODE_MSG_MAX, "non-finite state at t=%s", a);
        return ODE_FAILED;
    }
    if (isfinite(norm)) {
        const double m = 0.9 * pow(norm, -0.2);
        r->h = h_try * (m > 0.2 ? m : 0.2); /* Python max(0.2, m) */
    } else {
        r->h = 0.1 * h_try;
    }
    if (r->h < ODE_MIN_STEP) {
        py_float_repr(r->t, a, sizeof a);
        snprintf(msg, ODE_MSG_MAX, "step size underflow at t=%s (h=%.3g s)", a, r->h);
        return ODE_FAILED;
    }
    return ODE_OK;
}

/* The step size proposed after an accepted step of h_try with the guess h; a step clipped to
 * reach t1 keeps the larger guess. */
static double next_step_size(double norm, double h_try, double h)
{
    double h_next;
    if (norm > 0.0) {
        const double m = 0.9 * pow(norm, -0.2);
        h_next = h_try * (m < 5.0 ? m : 5.0); /* Python min(5.0, m) */
    } else {
        h_next = 5.0 * h_try;
    }
    if (h_try < h) {
        return h_next > h ? h_next : h; /* Python max(h, h_next) */
    }
    return h_next;
}

/* One attempted step of h_try from (r->t, r->y): rejected (r->h shrunk), accepted (r moved to
 * its end) or, when the event crosses zero inside it, res set at the crossing and *hit = 1. */
static int attempt(Run *r, double h_try, OdeResult *res, int *hit, char *msg)
{
    double y_new[ODE_N], err[ODE_N], k7[ODE_N], g_new, norm;
    int i;
    if (ode_dopri5_step(r->f, r->ctx, r->y, h_try, r->k1, y_new, err, k7, msg)) {
        return ODE_FAILED;
    }
    norm = ode_error_norm(r->y, y_new, err, r->rtol, r->atol);
    if (norm > 1.0) {
        return rejected(r, norm, h_try, msg);
    }
    r->h = next_step_size(norm, h_try, r->h);
    if (r->event != NULL && r->g_prev <= 0.0) {
        if (r->event(r->ctx, y_new, &g_new, msg)) {
            return ODE_FAILED;
        }
        if (g_new > 0.0) {
            double t_ev;
            if (locate(r->f, r->event, r->ctx, r->y, r->k1, h_try, r->g_prev, r->time_tol, &t_ev,
                       res->y, msg)) {
                return ODE_FAILED;
            }
            res->t = r->t + t_ev;
            res->h = r->h;
            res->hit = 1;
            *hit = 1;
            return ODE_OK;
        }
    }
    r->t = h_try == r->t1 - r->t ? r->t1 : r->t + h_try;
    for (i = 0; i < ODE_N; i++) {
        r->y[i] = y_new[i];
        r->k1[i] = k7[i];
    }
    if (r->event != NULL) {
        return r->event(r->ctx, r->y, &r->g_prev, msg) ? ODE_FAILED : ODE_OK;
    }
    r->g_prev = -1.0;
    return ODE_OK;
}

int ode_integrate(OdeRhs f, OdeEvent event, void *ctx, double t0, const double y0[ODE_N],
                  double t1, double h, double rtol, double atol, double time_tol, OdeResult *res,
                  char *msg)
{
    Run r = {f, event, ctx, t1, rtol, atol, time_tol, t0, h, -1.0, {0.0}, {0.0}};
    double h_try;
    char a[40], b[40];
    long steps = 0;
    int i, hit = 0;
    for (i = 0; i < ODE_N; i++) {
        r.y[i] = y0[i];
    }
    if (f(ctx, r.y, r.k1, msg)) {
        return ODE_FAILED;
    }
    if (event != NULL && event(ctx, r.y, &r.g_prev, msg)) {
        return ODE_FAILED;
    }
    while (t1 - r.t > time_tol) {
        steps += 1;
        if (steps > ODE_MAX_STEPS) {
            py_float_repr(t0, a, sizeof a);
            py_float_repr(t1, b, sizeof b);
            snprintf(msg, ODE_MSG_MAX, "more than %d steps between t=%s and t=%s", ODE_MAX_STEPS,
                     a, b);
            return ODE_FAILED;
        }
        h_try = (t1 - r.t) < r.h ? (t1 - r.t) : r.h; /* Python min(h, t1 - t) */
        if (attempt(&r, h_try, res, &hit, msg)) {
            return ODE_FAILED;
        }
        if (hit) {
            return ODE_OK;
        }
    }
    res->t = t1;
    for (i = 0; i < ODE_N; i++) {
        res->y[i] = r.y[i];
    }
    res->h = r.h;
    res->hit = 0;
    return ODE_OK;
}
