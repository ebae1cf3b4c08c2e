/* Adaptive Dormand-Prince 5(4) integration with event location, for a state of dimension
 * ODE_N = 6, mirroring impedance_cosim/physics/ode.py operation for operation (same tableau constants,
 * evaluation order, step-size control and event location) so the native plant computes the
 * same numbers as the Python one.
 *
 * The right-hand side and the event function take a context pointer. Either may fail (the
 * Python code raises, e.g. ZeroDivisionError on a singular inertia matrix, ValueError from
 * math.sin of an infinite angle): it then writes the exception's text into err (ODE_MSG_MAX
 * bytes) and returns nonzero, and the integration stops with ODE_FAILED and that text. */
#ifndef ODE_H
#define ODE_H

#define ODE_N 6
#define ODE_MSG_MAX 256

#define ODE_MIN_STEP 1e-13   /* s; a step this small means the solution is blowing up */
#define ODE_MAX_STEPS 200000 /* accepted + rejected steps per ode_integrate() call */
#define ODE_TIME_TOL 1e-12   /* integrate()'s default time_tol */

/* y' = f(y): write f(y) into out; return 0, or nonzero after writing the error text into err */
typedef int (*OdeRhs)(void *ctx, const double y[ODE_N], double out[ODE_N], char *err);
/* switching function g(y) into *g; return 0, or nonzero after writing the error into err */
typedef int (*OdeEvent)(void *ctx, const double y[ODE_N], double *g, char *err);

enum { ODE_OK = 0, ODE_FAILED = 1 };

typedef struct {
    double t;         /* where the run stopped (t1, or just past the event) */
    double y[ODE_N];  /* the state there */
    double h;         /* the next step-size guess */
    int hit;          /* 1 when stopped at an event (event(y) > 0), 0 at t1 */
} OdeResult;

/* ode.dopri5_step: one step of size h from y with k1 = f(y); y_new, err and k7 = f(y_new). */
int ode_dopri5_step(OdeRhs f, void *ctx, const double y[ODE_N], double h, const double k1[ODE_N],
                    double y_new[ODE_N], double err[ODE_N], double k7[ODE_N], char *msg);

/* ode.euler_step: y_new = y + h f(y), one explicit Euler step (the plant's integrator = euler). */
int ode_euler_step(OdeRhs f, void *ctx, const double y[ODE_N], double h, double y_new[ODE_N],
                   char *msg);

/* ode.error_norm: max-norm of err scaled by atol + rtol * max(|y|, |y_new|); NaN -> inf. */
double ode_error_norm(const double y[ODE_N], const double y_new[ODE_N], const double err[ODE_N],
                      double rtol, double atol);

/* ode.integrate(f, t0, y0, t1, h, rtol, atol, event, time_tol): event may be NULL. Returns
 * ODE_OK with *res filled, or ODE_FAILED with the IntegrationError (or the failing function's)
 * text in msg (ODE_MSG_MAX bytes), e.g. "step size underflow at t=0.0 (h=4e-14 s)". */
int ode_integrate(OdeRhs f, OdeEvent event, void *ctx, double t0, const double y0[ODE_N],
                  double t1, double h, double rtol, double atol, double time_tol, OdeResult *res,
                  char *msg);

#endif
