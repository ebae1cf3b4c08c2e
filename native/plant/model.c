/* The native PumaPlant: plant_model/model.py (PlantModel) transcribed operation for operation, with
 * physics/arm.py (inverse_kinematics, forward_dynamics) and physics/wall.py, so that it computes
 * the same numbers as the Python FMU, bit for bit (Model Exchange and partials: model_me.c).
 *
 * Each doStep integrates eq. (1) with the torque held, using adaptive Dormand-Prince 5(4)
 * (ode.c) and stopping exactly where the contact closes or opens; the contact mode switches there
 * and the integration continues. Joint angles are measured with CPython's random.gauss noise
 * (pyrandom.c) and quantized like Python's round(). */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "arm.h"
#include "arm_terms.h"
#include "glue.h"
#include "plant.h" /* PlantCtx, the functions model_me.c shares */
#include "linalg3.h"
#include "ode.h"
#include "pyrandom.h"
#include "pyrepr.h"

#define H0 1e-3            /* s, the integrator's first step guess */
#define MAX_SWITCHES 1000  /* contact mode switches per communication step */
#define REPR 40            /* buffer size for py_float_repr */
#define MAX_EULER_SUBSTEPS 1000000 /* per communication step (PlantModel's MAX_EULER_SUBSTEPS) */

static void read_arm(const Data *d, ArmParams *p)
{
#define ARM(name) p->name = d->r[VR_##name]
    ARM(a1); ARM(a2); ARM(a3); ARM(m1); ARM(m2); ARM(m3); ARM(rx1);
    ARM(ry1); ARM(rx2); ARM(rx3); ARM(Iu1); ARM(Iu2); ARM(Iu3); ARM(Im1);
    ARM(Im2); ARM(Im3); ARM(f1); ARM(f2); ARM(f3); ARM(g);
#undef ARM
}

void plant_read_ctx(const Data *d, PlantCtx *c)
{
    read_arm(d, &c->arm);
    c->wall.x = d->r[VR_wall_x];
    c->wall.k = d->r[VR_wall_k];
    c->wall.d = d->r[VR_wall_d];
    c->tau[0] = d->r[VR_tau1];
    c->tau[1] = d->r[VR_tau2];
    c->tau[2] = d->r[VR_tau3];
    c->in_contact = d->m.in_contact;
    c->budget = NULL; /* set by model_step */
    c->max_evaluations = 0;
}

/* Python's math.sin / math.cos raise ValueError("math domain error") for an infinite argument,
 * where C returns NaN: report it the same way (it ends the step, as in Python). */
static int domain_error(char *err)
{
    snprintf(err, ODE_MSG_MAX, "math domain error");
    return 1;
}

/* Every sin/cos argument of arm_terms' coriolis, gravity, inertia and jacobian and of ee_x. */
static int angles_infinite(const double q[3])
{
    const double q12 = q[0] + q[1];
    return isinf(q[0]) || isinf(q[1]) || isinf(q[2]) || isinf(q12) || isinf(q12 + q[2])
           || isinf(q[1] + q[2]);
}

/* --- PlantModel equations -------------------------------------------------------------------- */

/* PlantModel._ee_x: end-effector x and x-velocity (all the wall needs). */
int plant_ee_x(const ArmParams *a, const double q[3], const double qd[3], double *x, double *xd,
                char *err)
{
    const double q12 = q[0] + q[1];
    const double q123 = q12 + q[2];
    double s1, s12, s123;
    if (isinf(q[0]) || isinf(q12) || isinf(q123)) {
        return domain_error(err);
    }
    s1 = a->a1 * sin(q[0]);
    s12 = a->a2 * sin(q12);
    s123 = a->a3 * sin(q123);
    *x = a->a1 * cos(q[0]) + a->a2 * cos(q12) + a->a3 * cos(q123);
    *xd = -(s1 + s12 + s123) * qd[0] - (s12 + s123) * qd[1] - s123 * qd[2];
    return 0;
}

/* Arm.forward_dynamics (arm.h); a singular H is Python's ZeroDivisionError. */
static int forward_dynamics(const ArmParams *p, const double q[3], const double qd[3],
                            const double tau[3], double qdd[3], char *err)
{
    if (arm_forward_dynamics(p, q, qd, tau, qdd)) {
        snprintf(err, ODE_MSG_MAX, "float division by zero");
        return 1;
    }
    return 0;
}

/* PlantModel._rhs(tau, in_contact): y' = f(y) for y = (q, qd), eq. (1). */
int plant_rhs(void *ctx, const double y[ODE_N], double out[ODE_N], char *err)
{
    const PlantCtx *c = (const PlantCtx *)ctx;
    const double q[3] = {y[0], y[1], y[2]};
    const double qd[3] = {y[3], y[4], y[5]};
    double net[3], qdd[3];
    if (c->budget && --*c->budget < 0) {
        snprintf(err, ODE_MSG_MAX,
                 "more than %d evaluations of the dynamics in one communication step (parameter"
                 " max_rhs_evaluations): take a smaller step",
                 c->max_evaluations);
        return 1;
    }
    if (angles_infinite(q)) {
        return domain_error(err);
    }
    if (c->in_contact) {
        double x, xd, fx, j[9];
        if (plant_ee_x(&c->arm, q, qd, &x, &xd, err)) {
            return 1;
        }
        fx = wall_contact_force_law(&c->wall, x, xd);
        arm_jacobian(&c->arm, q, j); /* J^T (fx, 0, 0) = fx * first row of J */
        net[0] = c->tau[0] - fx * j[0];
        net[1] = c->tau[1] - fx * j[1];
        net[2] = c->tau[2] - fx * j[2];
    } else {
        net[0] = c->tau[0];
        net[1] = c->tau[1];
        net[2] = c->tau[2];
    }
    if (forward_dynamics(&c->arm, q, qd, net, qdd, err)) {
        return 1;
    }
    out[0] = qd[0];
    out[1] = qd[1];
    out[2] = qd[2];
    out[3] = qdd[0];
    out[4] = qdd[1];
    out[5] = qdd[2];
    return 0;
}

/* PlantModel._event(in_contact) */
int plant_event(void *ctx, const double y[ODE_N], double *g, char *err)
{
    const PlantCtx *c = (const PlantCtx *)ctx;
    double x, xd;
    if (plant_ee_x(&c->arm, y, y + 3, &x, &xd, err)) {
        return 1;
    }
    *g = wall_contact_event(&c->wall, x, xd, c->in_contact);
    return 0;
}

/* Python's round(v) (half to even, via C round as in float.__round__), returning an int: that
 * fails for NaN and infinity, and has no negative zero. */
static int py_round(double v, double *out, char *msg)
{
    double rounded;
    if (isnan(v)) {
        return fail(msg, "joint angle measurement failed: cannot convert float NaN to integer");
    }
    if (isinf(v)) {
        return fail(msg, "joint angle measurement failed: cannot convert float infinity to"
                         " integer");
    }
    rounded = round(v);
    if (fabs(v - rounded) == 0.5) {
        rounded = 2.0 * round(v / 2.0);
    }
    *out = rounded == 0.0 ? 0.0 : rounded;
    return 0;
}

/* PlantModel._measure: joint encoders, truth + Gaussian noise, then quantized. */
static int measure(Data *d, const double q[3], double out[3], char *msg)
{
    const double q_noise = d->r[VR_q_noise], q_quant = d->r[VR_q_quant];
    for (int i = 0; i < 3; i++) {
        double qi = q[i];
        if (q_noise > 0.0) {
            qi += pyrandom_gauss(&d->m.rng, 0.0, q_noise);
        }
        if (q_quant > 0.0) {
            double k = 0.0;
            if (py_round(qi / q_quant, &k, msg)) {
                return 1;
            }
            qi = k * q_quant;
        }
        out[i] = qi;
    }
    return 0;
}

/* PlantModel.outputs(), into d->r. */
void plant_write_outputs(Data *d)
{
    const ModelState *m = &d->m;
    PlantCtx c;
    double pose[3], j[9], xdot[3], fx, pen;
    plant_read_ctx(d, &c);
    arm_kinematics(&c.arm, m->q, pose);
    arm_jacobian(&c.arm, m->q, j);
    for (int r = 0; r < 3; r++) {
        xdot[r] = j[3 * r] * m->qd[0] + j[3 * r + 1] * m->qd[1] + j[3 * r + 2] * m->qd[2];
    }
    fx = wall_force(&c.wall, pose[0], xdot[0]);
    pen = pose[0] - c.wall.x;
    pen = pen > 0.0 ? pen : 0.0; /* Python max(0.0, pen) */
    d->r[VR_q1] = m->q_meas[0];
    d->r[VR_q2] = m->q_meas[1];
    d->r[VR_q3] = m->q_meas[2];
    d->r[VR_fx] = fx;
    d->r[VR_fy] = 0.0;
    d->r[VR_n] = 0.0;
    d->r[VR_q1_true] = m->q[0];
    d->r[VR_q2_true] = m->q[1];
    d->r[VR_q3_true] = m->q[2];
    d->r[VR_qd1] = m->qd[0];
    d->r[VR_qd2] = m->qd[1];
    d->r[VR_qd3] = m->qd[2];
    d->r[VR_x] = pose[0];
    d->r[VR_y] = pose[1];
    d->r[VR_phi] = pose[2];
    d->r[VR_xd] = xdot[0];
    d->r[VR_yd] = xdot[1];
    d->r[VR_phid] = xdot[2];
    d->r[VR_contact_force] = fx;
    d->r[VR_penetration] = pen;
}

/* Arm.inverse_kinematics; the message is UnreachablePoseError's, prefixed like PlantModel's. */
static int inverse_kinematics(const ArmParams *p, double x, double y, double phi, int elbow_up,
                              double q[3], char *msg)
{
    char sx[REPR], sy[REPR], sphi[REPR];
    double wx, wy, c2, s2, q1, q2;
    py_float_repr(x, sx, sizeof sx);
    py_float_repr(y, sy, sizeof sy);
    py_float_repr(phi, sphi, sizeof sphi);
    if (!(isfinite(x) && isfinite(y) && isfinite(phi))) {
        return fail(msg, "initial pose: pose (%s, %s, %s) is not finite", sx, sy, sphi);
    }
    wx = x - p->a3 * cos(phi);
    wy = y - p->a3 * sin(phi);
    c2 = (wx * wx + wy * wy - pow(p->a1, 2.0) - pow(p->a2, 2.0)) / (2.0 * p->a1 * p->a2);
    if (c2 > 1.0 || c2 < -1.0) {
        const double r = hypot(wx, wy);
        return fail(msg,
                    "initial pose: pose (x=%s, y=%s, phi=%s) is unreachable: the wrist is %.4f m"
                    " from the shoulder, the arm reaches from %.4f m to %.4f m",
                    sx, sy, sphi, r, fabs(p->a1 - p->a2), p->a1 + p->a2);
    }
    s2 = elbow_up ? -sqrt(1.0 - c2 * c2) : sqrt(1.0 - c2 * c2);
    q2 = atan2(s2, c2);
    q1 = atan2(wy, wx) - atan2(p->a2 * s2, p->a1 + p->a2 * c2);
    q[0] = q1;
    q[1] = q2;
    q[2] = phi - q1 - q2;
    return 0;
}

/* PlantModel._euler_steps (euler_substeps = n > 0): n explicit Euler steps of h / n, each in the
 * mode at its start; the mode switches after a step if its switching function turned positive.
 * A reproduction aid for Fig. 4, not a default. */
static int euler_steps(PlantCtx *c, double y[ODE_N], double h, int n, int *mode, char *err)
{
    const double dt = h / (double)n;
    for (int k = 0; k < n; k++) {
        double y_new[ODE_N], g;
        c->in_contact = *mode;
        if (ode_euler_step(plant_rhs, c, y, dt, y_new, err)) {
            return 1;
        }
        memcpy(y, y_new, sizeof y_new);
        if (plant_event(c, y, &g, err)) {
            return 1;
        }
        if (g > 0.0) {
            *mode = !*mode;
        }
    }
    return 0;
}

/* --- the model (glue.h) ---------------------------------------------------------------------- */

/* The plant has no tunable parameters (the glue refuses every parameter set after
 * initialization): nothing beyond the glue's checks. */
int model_check_tunable(const Data *d, char *msg)
{
    (void)d;
    (void)msg;
    return 0;
}

int model_initialize(Data *d, char *msg)
{
    ModelState *m = &d->m;
    PlantCtx c;
    double q[3] = {0.0, 0.0, 0.0}, x, xd;
    char err[ODE_MSG_MAX];
    plant_read_ctx(d, &c);
    if (c.arm.a1 <= 0.0 || c.arm.a2 <= 0.0) {
        char s1[REPR], s2[REPR];
        py_float_repr(c.arm.a1, s1, sizeof s1);
        py_float_repr(c.arm.a2, s2, sizeof s2);
        return fail(msg, "link lengths a1, a2 must be > 0 (got a1=%s, a2=%s)", s1, s2);
    }
    if (inverse_kinematics(&c.arm, d->r[VR_x0], d->r[VR_y0], d->r[VR_phi0], d->i[VR_elbow_up] != 0,
                           q, msg)) {
        return 1;
    }
    if (d->i[VR_euler_substeps] > MAX_EULER_SUBSTEPS) { /* PlantSetup.validate */
        return fail(msg, "parameter euler_substeps must be <= %d (got %d)", MAX_EULER_SUBSTEPS,
                    (int)d->i[VR_euler_substeps]);
    }
    memset(m, 0, sizeof *m);
    m->t = d->start_time;
    m->q[0] = q[0];
    m->q[1] = q[1];
    m->q[2] = q[2];
    m->qd[0] = m->qd[1] = m->qd[2] = 0.0;
    if (plant_ee_x(&c.arm, m->q, m->qd, &x, &xd, err)) {
        return fail(msg, "%s", err); /* not reached: inverse kinematics gives finite angles */
    }
    m->in_contact = wall_contact_event(&c.wall, x, xd, 0) > 0.0;
    m->h = H0;
    pyrandom_seed(&m->rng, (int64_t)d->i[VR_noise_seed]);
    if (measure(d, m->q, m->q_meas, msg)) {
        return 1;
    }
    plant_write_outputs(d);
    return 0;
}

/* plant_step's refusals: an input not finite, a bad step size, a step not from the plant's t. */
static int check_step(const Data *d, const PlantCtx *c, double t, double h, char *msg)
{
    static const char *const inputs[3] = {"tau1", "tau2", "tau3"};
    double scale;
    char a[REPR], b[REPR];
    for (int i = 0; i < 3; i++) {
        const double v = c->tau[i];
        if (!(v - v == 0.0)) { /* false for NaN and +-inf */
            py_float_repr(v, a, sizeof a);
            return fail(msg, "input %s is not finite (%s)", inputs[i], a);
        }
    }
    if (!(h > 0.0)) {
        py_float_repr(h, a, sizeof a);
        return fail(msg, "communication step must be > 0 (got %s)", a);
    }
    if (isinf(h)) {
        return fail(msg, "communication step must be finite (got inf)");
    }
    scale = fabs(t) > 1.0 ? fabs(t) : 1.0; /* Python max(1.0, abs(t)) */
    if (fabs(t - d->m.t) > 1e-9 * scale) {
        py_float_repr(t, a, sizeof a);
        py_float_repr(d->m.t, b, sizeof b);
        return fail(msg, "doStep at t=%s, but the plant is at t=%s", a, b);
    }
    return 0;
}

/* The adaptive integration of y from t to *t_end, the contact mode (*mode) switched at each
 * crossing and counted in *switches; *hh the step-size guess. With early it stops at the first
 * switch, *t_end then the time of the switch. */
static int integrate(const Data *d, PlantCtx *c, double y[ODE_N], double t, double *t_end,
                     double *hh, int *mode, int *switches, int early, char *msg)
{
    OdeResult res;
    char err[ODE_MSG_MAX];
    double t_cur = t;
    for (;;) {
        c->in_contact = *mode;
        if (ode_integrate(plant_rhs, plant_event, c, t_cur, y, *t_end, *hh, d->r[VR_rtol],
                          d->r[VR_atol], ODE_TIME_TOL, &res, err)) {
            return fail(msg, "plant integration failed: %s", err);
        }
        t_cur = res.t;
        memcpy(y, res.y, sizeof res.y);
        *hh = res.h;
        if (!res.hit) {
            return 0;
        }
        *mode = !*mode;
        *switches += 1;
        if (*switches > MAX_SWITCHES) {
            return fail(msg, "plant integration failed: contact chattering: more than %d switches"
                             " in a step", MAX_SWITCHES);
        }
        if (early) { /* return early, at the switch (FMI 3 co-simulation only) */
            *t_end = t_cur;
            return 0;
        }
    }
}

/* model_step; with reached (FMI 3 early return) it stops at the first contact switch inside the
 * step, the switch then done, and says where it stopped (t + h when there was none). With work,
 * the evaluations and switches of the fmi3DoStep so far count against its bounds, and this
 * step's are added to them. */
static int plant_step(Data *d, double t, double h, double *reached, StepWork *work,
                      char *msg)
{
    ModelState *m = &d->m;
    PlantCtx c;
    double y[ODE_N], t_end, hh;
    char err[ODE_MSG_MAX];
    int mode, switches = work ? work->switches : 0;
    const int euler = (int)d->i[VR_euler_substeps];
    int64_t budget = d->i[VR_max_rhs_evaluations] - (work ? work->rhs_evaluations : 0);
    plant_read_ctx(d, &c);
    c.budget = &budget;
    c.max_evaluations = d->i[VR_max_rhs_evaluations];
    if (check_step(d, &c, t, h, msg)) {
        return 1;
    }
    t_end = t + h;
    for (int i = 0; i < 3; i++) {
        y[i] = m->q[i];
        y[3 + i] = m->qd[i];
    }
    mode = m->in_contact;
    hh = m->h;
    if (euler > 0 && euler_steps(&c, y, h, euler, &mode, err)) {
        return fail(msg, "plant integration failed: %s", err);
    }
    if (euler == 0 &&
        integrate(d, &c, y, t, &t_end, &hh, &mode, &switches, reached != NULL, msg)) {
        return 1;
    }
    if (work) {
        work->rhs_evaluations = d->i[VR_max_rhs_evaluations] - budget;
        work->switches = switches;
    }
    m->t = t_end;
    for (int i = 0; i < 3; i++) {
        m->q[i] = y[i];
        m->qd[i] = y[3 + i];
    }
    m->in_contact = mode;
    m->h = hh;
    if (measure(d, m->q, m->q_meas, msg)) {
        return 1;
    }
    plant_write_outputs(d);
    if (reached) {
        *reached = t_end;
    }
    return 0;
}

int model_step(Data *d, double t, double h, char *msg)
{
    return plant_step(d, t, h, NULL, NULL, msg);
}

int model_step_early(Data *d, double t, double h, double *reached, StepWork *work, char *msg)
{
    return plant_step(d, t, h, reached, work, msg);
}

int model_check_state(const Data *d, char *msg)
{
    const ModelState *m = &d->m;
    const PyRandom *r = &m->rng;
    if (!isfinite(m->t) || !(isfinite(m->h) && m->h > 0.0)) {
        return fail(msg, "plant time or step-size guess not finite (or h <= 0)");
    }
    for (int i = 0; i < 3; i++) {
        if (!isfinite(m->q[i]) || !isfinite(m->qd[i]) || !isfinite(m->q_meas[i])) {
            return fail(msg, "plant joint %d angle, velocity or measurement not finite", i + 1);
        }
    }
    if (m->in_contact != 0 && m->in_contact != 1) {
        return fail(msg, "plant contact mode %d is not 0 or 1", (int)m->in_contact);
    }
    if (r->index < 0 || r->index > PYRANDOM_N) {
        return fail(msg, "noise generator index %d is outside 0..%d", (int)r->index, PYRANDOM_N);
    }
    if (r->has_gauss_next != 0 && r->has_gauss_next != 1) {
        return fail(msg, "noise generator flag %d is not 0 or 1", (int)r->has_gauss_next);
    }
    if (r->has_gauss_next && !isfinite(r->gauss_next)) {
        return fail(msg, "noise generator's cached deviate is not finite");
    }
    return 0;
}

/* Every double of ModelState (glue.h), the generator's cached deviate included (0.0 when none). */
MODEL_LINKAGE const StateReals MODEL_STATE_REALS[] = {
    {"plant t", offsetof(ModelState, t), 1},
    {"plant q", offsetof(ModelState, q), 3},
    {"plant qd", offsetof(ModelState, qd), 3},
    {"plant h", offsetof(ModelState, h), 1},
    {"plant q_meas", offsetof(ModelState, q_meas), 3},
    {"plant noise generator's gauss_next", offsetof(ModelState, rng.gauss_next), 1},
};
MODEL_LINKAGE const int N_MODEL_STATE_REALS = sizeof MODEL_STATE_REALS / sizeof *MODEL_STATE_REALS;
