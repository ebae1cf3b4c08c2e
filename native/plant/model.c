/* The native PumaPlant: plant_model/model.py (PlantModel) transcribed operation for operation,
 * with impedance_cosim/physics/arm.py (inverse_kinematics, forward_dynamics) and impedance_cosim/physics/wall.py,
 * so that it computes the same numbers as the Python FMU, bit for bit.
 *
 * Each doStep integrates eq. (1) with the torque held, using adaptive Dormand-Prince 5(4)
 * (ode.c) and stopping exactly where the contact closes or opens; the contact mode switches there
 * and the integration continues. Joint angles are measured with CPython's random.gauss noise
 * (pyrandom.c) and quantized like Python's round(). */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "arm.h"
#include "arm_partials.h"
#include "arm_terms.h"
#include "glue.h"
#include "linalg3.h"
#include "model_me.h"
#include "ode.h"
#include "model_partials.h"
#include "pyrandom.h"

#define H0 1e-3            /* s, the integrator's first step guess */
#define MAX_SWITCHES 1000  /* contact mode switches per communication step */
#define REPR 40            /* buffer size for py_float_repr */
#define MAX_EULER_SUBSTEPS 1000000 /* per communication step (PlantModel's MAX_EULER_SUBSTEPS) */

/* What the right-hand side and the event function need (PlantModel._rhs / _event closures). */
typedef struct {
    ArmParams arm;
    double wall_x, wall_k, wall_d;
    double tau[3];
    int in_contact;
    int64_t *budget; /* evaluations of eq. (1) left in this step (max_rhs_evaluations), or NULL
                        outside a co-simulation step (Model Exchange: one evaluation per call) */
    int max_evaluations;
} PlantCtx;

static void read_arm(const Data *d, ArmParams *p)
{
    p->a1 = d->r[VR_a1];
    p->a2 = d->r[VR_a2];
    p->a3 = d->r[VR_a3];
    p->m1 = d->r[VR_m1];
    p->m2 = d->r[VR_m2];
    p->m3 = d->r[VR_m3];
    p->rx1 = d->r[VR_rx1];
    p->ry1 = d->r[VR_ry1];
    p->rx2 = d->r[VR_rx2];
    p->rx3 = d->r[VR_rx3];
    p->Iu1 = d->r[VR_Iu1];
    p->Iu2 = d->r[VR_Iu2];
    p->Iu3 = d->r[VR_Iu3];
    p->Im1 = d->r[VR_Im1];
    p->Im2 = d->r[VR_Im2];
    p->Im3 = d->r[VR_Im3];
    p->f1 = d->r[VR_f1];
    p->f2 = d->r[VR_f2];
    p->f3 = d->r[VR_f3];
    p->g = d->r[VR_g];
}

static void read_ctx(const Data *d, PlantCtx *c)
{
    read_arm(d, &c->arm);
    c->wall_x = d->r[VR_wall_x];
    c->wall_k = d->r[VR_wall_k];
    c->wall_d = d->r[VR_wall_d];
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

/* --- wall.py --------------------------------------------------------------------------------- */

static double wall_force(const PlantCtx *c, double x, double xd)
{
    const double pen = x - c->wall_x;
    double force;
    if (pen <= 0.0) {
        return 0.0;
    }
    force = c->wall_k * pen + c->wall_d * xd;
    return force > 0.0 ? force : 0.0;
}

static double contact_force_law(const PlantCtx *c, double x, double xd)
{
    return c->wall_k * (x - c->wall_x) + c->wall_d * xd;
}

static double contact_event(const PlantCtx *c, double x, double xd, int in_contact)
{
    const double force = contact_force_law(c, x, xd);
    const double closing = c->wall_k * (x - c->wall_x);
    if (in_contact) {
        return -force;
    }
    return force < closing ? force : closing; /* Python min(closing, force) */
}

/* --- PlantModel equations -------------------------------------------------------------------- */

/* PlantModel._ee_x: end-effector x and x-velocity (all the wall needs). */
static int ee_x(const ArmParams *a, const double q[3], const double qd[3], double *x, double *xd,
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
static int plant_rhs(void *ctx, const double y[ODE_N], double out[ODE_N], char *err)
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
        if (ee_x(&c->arm, q, qd, &x, &xd, err)) {
            return 1;
        }
        fx = contact_force_law(c, x, xd);
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
static int plant_event(void *ctx, const double y[ODE_N], double *g, char *err)
{
    const PlantCtx *c = (const PlantCtx *)ctx;
    double x, xd;
    if (ee_x(&c->arm, y, y + 3, &x, &xd, err)) {
        return 1;
    }
    *g = contact_event(c, x, xd, c->in_contact);
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
static void write_outputs(Data *d)
{
    const ModelState *m = &d->m;
    PlantCtx c;
    double pose[3], j[9], xdot[3], fx, pen;
    read_ctx(d, &c);
    arm_kinematics(&c.arm, m->q, pose);
    arm_jacobian(&c.arm, m->q, j);
    for (int r = 0; r < 3; r++) {
        xdot[r] = j[3 * r] * m->qd[0] + j[3 * r + 1] * m->qd[1] + j[3 * r + 2] * m->qd[2];
    }
    fx = wall_force(&c, pose[0], xdot[0]);
    pen = pose[0] - c.wall_x;
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
    read_ctx(d, &c);
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
    if (ee_x(&c.arm, m->q, m->qd, &x, &xd, err)) {
        return fail(msg, "%s", err); /* not reached: inverse kinematics gives finite angles */
    }
    m->in_contact = contact_event(&c, x, xd, 0) > 0.0;
    m->h = H0;
    pyrandom_seed(&m->rng, (int64_t)d->i[VR_noise_seed]);
    if (measure(d, m->q, m->q_meas, msg)) {
        return 1;
    }
    write_outputs(d);
    return 0;
}

/* model_step; with reached (FMI 3 early return) it stops at the first contact switch inside the
 * step, the switch then done, and says where it stopped (t + h when there was none). With work,
 * the evaluations and switches of the fmi3DoStep so far count against its bounds, and this
 * step's are added to them. */
static int plant_step(Data *d, double t, double h, double *reached, StepWork *work,
                      char *msg)
{
    static const char *const inputs[3] = {"tau1", "tau2", "tau3"};
    ModelState *m = &d->m;
    PlantCtx c;
    OdeResult res;
    double y[ODE_N], t_end, t_cur, hh, scale;
    char err[ODE_MSG_MAX], a[REPR], b[REPR];
    int mode, switches = work ? work->switches : 0;
    const int euler = (int)d->i[VR_euler_substeps];
    int64_t budget = d->i[VR_max_rhs_evaluations] - (work ? work->rhs_evaluations : 0);
    read_ctx(d, &c);
    c.budget = &budget;
    c.max_evaluations = d->i[VR_max_rhs_evaluations];
    for (int i = 0; i < 3; i++) {
        const double v = c.tau[i];
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
    if (fabs(t - m->t) > 1e-9 * scale) {
        py_float_repr(t, a, sizeof a);
        py_float_repr(m->t, b, sizeof b);
        return fail(msg, "doStep at t=%s, but the plant is at t=%s", a, b);
    }
    t_end = t + h;
    for (int i = 0; i < 3; i++) {
        y[i] = m->q[i];
        y[3 + i] = m->qd[i];
    }
    t_cur = t;
    mode = m->in_contact;
    hh = m->h;
    if (euler > 0 && euler_steps(&c, y, h, euler, &mode, err)) {
        return fail(msg, "plant integration failed: %s", err);
    }
    while (euler == 0) {
        c.in_contact = mode;
        if (ode_integrate(plant_rhs, plant_event, &c, t_cur, y, t_end, hh, d->r[VR_rtol],
                          d->r[VR_atol], ODE_TIME_TOL, &res, err)) {
            return fail(msg, "plant integration failed: %s", err);
        }
        t_cur = res.t;
        memcpy(y, res.y, sizeof y);
        hh = res.h;
        if (!res.hit) {
            break;
        }
        mode = !mode;
        switches += 1;
        if (switches > MAX_SWITCHES) {
            return fail(msg, "plant integration failed: contact chattering: more than %d switches"
                             " in a step", MAX_SWITCHES);
        }
        if (reached) { /* return early, at the switch (FMI 3 co-simulation only) */
            t_end = t_cur;
            break;
        }
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
    write_outputs(d);
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
const StateReals MODEL_STATE_REALS[] = {
    {"plant t", offsetof(ModelState, t), 1},
    {"plant q", offsetof(ModelState, q), 3},
    {"plant qd", offsetof(ModelState, qd), 3},
    {"plant h", offsetof(ModelState, h), 1},
    {"plant q_meas", offsetof(ModelState, q_meas), 3},
    {"plant noise generator's gauss_next", offsetof(ModelState, rng.gauss_next), 1},
};
const int N_MODEL_STATE_REALS = (int)(sizeof MODEL_STATE_REALS / sizeof MODEL_STATE_REALS[0]);

/* --- Model Exchange (instance.h) ------------------------------------------------------------
 * The continuous states are (q1..q3, qd1..qd3), the order of the state vector y of plant_rhs and
 * of PlantModel.MODEL_EXCHANGE.states; the derivatives come from plant_rhs itself, the right-hand
 * side the co-simulation integrator uses. The contact mode is the discrete state: the event
 * indicator is plant_event's switching function for the current mode (it turns positive where
 * the contact closes, resp. opens), and the mode switches at that event, as in model_step. */

int model_me_check(const Data *d, char *msg)
{
    if (d->r[VR_q_noise] != 0.0 || d->r[VR_q_quant] != 0.0) {
        return fail(msg,
                    "q_noise = %g and q_quant = %g: under Model Exchange the encoders are ideal"
                    " (q1..q3 are the true angles); encoder noise and quantization are"
                    " sampled-data effects of the co-simulation interface: set both to 0 or"
                    " use co-simulation",
                    d->r[VR_q_noise], d->r[VR_q_quant]);
    }
    if (d->i[VR_euler_substeps] != 0) {
        return fail(msg, "euler_substeps = %d: under Model Exchange the host integrates the plant;"
                         " set it to 0 or use co-simulation", (int)d->i[VR_euler_substeps]);
    }
    return 0;
}

void model_me_get_states(const Data *d, double x[])
{
    for (int i = 0; i < 3; i++) {
        x[i] = d->m.q[i];
        x[3 + i] = d->m.qd[i];
    }
}

void model_me_set_states(Data *d, const double x[])
{
    for (int i = 0; i < 3; i++) {
        d->m.q[i] = x[i];
        d->m.qd[i] = x[3 + i];
    }
}

int model_me_evaluate(Data *d, char *msg)
{
    ModelState *m = &d->m;
    PlantCtx c;
    double y[ODE_N], dy[ODE_N];
    char err[ODE_MSG_MAX];
    read_ctx(d, &c);
    model_me_get_states(d, y);
    if (plant_rhs(&c, y, dy, err)) {
        return fail(msg, "plant derivatives failed: %s", err);
    }
    for (int k = 0; k < N_STATES; k++) {
        d->r[DERIVATIVE_VRS[k]] = dy[k];
    }
    memcpy(m->q_meas, m->q, sizeof m->q_meas); /* ideal encoders (model_me_check) */
    write_outputs(d);
    return 0;
}

int model_me_event_indicators(const Data *d, double z[], char *msg)
{
    PlantCtx c;
    double y[ODE_N];
    char err[ODE_MSG_MAX];
    read_ctx(d, &c);
    model_me_get_states(d, y);
    if (plant_event(&c, y, &z[0], err)) {
        return fail(msg, "contact event indicator failed: %s", err);
    }
    return 0;
}

/* The current mode's switching function an instant (LOOKAHEAD) later along the trajectory:
 * decides the switch where the host's root finder stopped exactly on the root (g == 0), where
 * model_step would have stopped just past it (g > 0). */
#define LOOKAHEAD 1e-9 /* s */

static int switching_function_ahead(const Data *d, double *g, char *msg)
{
    PlantCtx c;
    double y[ODE_N], dy[ODE_N];
    char err[ODE_MSG_MAX];
    read_ctx(d, &c);
    model_me_get_states(d, y);
    if (plant_rhs(&c, y, dy, err)) {
        return fail(msg, "plant derivatives failed: %s", err);
    }
    for (int k = 0; k < ODE_N; k++) {
        y[k] += LOOKAHEAD * dy[k];
    }
    if (plant_event(&c, y, g, err)) {
        return fail(msg, "contact event indicator failed: %s", err);
    }
    return 0;
}

int model_me_event_update(Data *d, double t, MeEvent *ev, char *msg)
{
    double g;
    (void)t; /* no time events: the contact is a state event */
    if (model_me_event_indicators(d, &g, msg)) {
        return 1;
    }
    if (g == 0.0 && switching_function_ahead(d, &g, msg)) {
        return 1;
    }
    if (g > 0.0) { /* the current mode's switching function crossed: switch, as model_step */
        d->m.in_contact = !d->m.in_contact;
        ev->changed = 1;
        if (model_me_event_indicators(d, &g, msg)) {
            return 1;
        }
        ev->again = g > 0.0;
    }
    return 0;
}

/* --- exact partial derivatives (partials.h) -------------------------------------------------
 * Eq. (1) differentiated: with the generalized force n = tau - fx J0^T - C qd - F qd - g (fx the
 * contact law in contact mode, J0 the first row of J, 0 out of contact), H qdd = n gives
 * d qdd / dz = H^-1 (dn/dz - (dH/dz) qdd) for z = q, qd, tau; dH/dq, d(C qd)/dq, d(C qd)/dqd,
 * dg/dq and dJ/dq are generated from the same symbolic derivation (arm_partials.c). */

/* qdd at y (plant_rhs) and dqdd[k][m] = d qdd_k / d known m (q, qd, tau). */
static int qdd_partials(const PlantCtx *c, const double y[ODE_N], double qdd[3],
                        double dqdd[3][9], char *err)
{
    const double *q = y, *qd = y + 3;
    const double f[3] = {c->arm.f1, c->arm.f2, c->arm.f3};
    double dy[ODE_N], j[9], dj[27], h[9], dh[27], dcq[9], dcqd[9], dg[9], dn[3][9];
    if (plant_rhs((void *)c, y, dy, err)) {
        return 1;
    }
    memcpy(qdd, dy + 3, 3 * sizeof(double));
    arm_jacobian(&c->arm, q, j);
    arm_jacobian_dq(&c->arm, q, dj);
    arm_inertia(&c->arm, q, h);
    arm_inertia_dq(&c->arm, q, dh);
    arm_coriolis_qd_dq(&c->arm, q, qd, dcq);
    arm_coriolis_qd_dqd(&c->arm, q, qd, dcqd);
    arm_gravity_dq(&c->arm, q, dg);
    for (int k = 0; k < 3; k++) {
        for (int i = 0; i < 3; i++) {
            dn[k][i] = -dcq[3 * k + i] - dg[3 * k + i];
            dn[k][3 + i] = -dcqd[3 * k + i] - (i == k ? f[k] : 0.0);
            dn[k][6 + i] = i == k ? 1.0 : 0.0;
        }
    }
    if (c->in_contact) { /* fx = k (x - wall_x) + d xd, x = kin_x(q), xd = J0 qd */
        double x, xd, fx;
        if (ee_x(&c->arm, q, qd, &x, &xd, err)) {
            return 1;
        }
        fx = contact_force_law(c, x, xd);
        for (int i = 0; i < 3; i++) {
            const double dxd = dj[9 * i] * qd[0] + dj[9 * i + 1] * qd[1] + dj[9 * i + 2] * qd[2];
            const double dfx_dq = c->wall_k * j[i] + c->wall_d * dxd;
            const double dfx_dqd = c->wall_d * j[i];
            for (int k = 0; k < 3; k++) {
                dn[k][i] -= dfx_dq * j[k] + fx * dj[9 * i + k];
                dn[k][3 + i] -= dfx_dqd * j[k];
            }
        }
    }
    for (int m = 0; m < 9; m++) {
        double rhs[3], col[3];
        for (int k = 0; k < 3; k++) {
            rhs[k] = dn[k][m];
            if (m < 3) {
                rhs[k] -= dh[9 * m + 3 * k] * qdd[0] + dh[9 * m + 3 * k + 1] * qdd[1]
                          + dh[9 * m + 3 * k + 2] * qdd[2];
            }
        }
        if (solve3(h, rhs, col)) {
            snprintf(err, ODE_MSG_MAX, "float division by zero");
            return 1;
        }
        for (int k = 0; k < 3; k++) {
            dqdd[k][m] = col[k];
        }
    }
    return 0;
}

int model_partials(const Data *d, double jac[N_VARS][N_KNOWNS], char *msg)
{
    static const int meas[3] = {VR_q1, VR_q2, VR_q3}, truth[3] = {VR_q1_true, VR_q2_true,
                                                                    VR_q3_true};
    static const int vel[3] = {VR_qd1, VR_qd2, VR_qd3}, pose[3] = {VR_x, VR_y, VR_phi};
    static const int twist[3] = {VR_xd, VR_yd, VR_phid};
    const ModelState *m = &d->m;
    PlantCtx c;
    double y[ODE_N], qdd[3], dqdd[3][9], j[9], dj[27], x, xd, pen, force;
    char err[ODE_MSG_MAX];
    read_ctx(d, &c);
    model_me_get_states(d, y);
    memset(jac, 0, sizeof(double) * N_VARS * N_KNOWNS);
    if (qdd_partials(&c, y, qdd, dqdd, err)) {
        return fail(msg, "plant partial derivatives failed: %s", err);
    }
    arm_jacobian(&c.arm, m->q, j);
    arm_jacobian_dq(&c.arm, m->q, dj);
    for (int k = 0; k < 3; k++) {
        jac[DERIVATIVE_VRS[k]][3 + k] = 1.0;
        memcpy(jac[DERIVATIVE_VRS[3 + k]], dqdd[k], sizeof dqdd[k]);
        jac[meas[k]][k] = 1.0; /* the encoders are ideal where the states are knowns (ME) */
        jac[truth[k]][k] = 1.0;
        jac[vel[k]][3 + k] = 1.0;
        for (int i = 0; i < 3; i++) {
            jac[pose[k]][i] = j[3 * k + i];
            jac[twist[k]][i] = dj[9 * i + 3 * k] * m->qd[0] + dj[9 * i + 3 * k + 1] * m->qd[1]
                               + dj[9 * i + 3 * k + 2] * m->qd[2];
            jac[twist[k]][3 + i] = j[3 * k + i];
        }
    }
    if (ee_x(&c.arm, m->q, m->qd, &x, &xd, err)) {
        return fail(msg, "plant partial derivatives failed: %s", err);
    }
    pen = x - c.wall_x;
    force = c.wall_k * pen + c.wall_d * xd;
    for (int i = 0; i < 6 && pen > 0.0; i++) { /* the branches wall_force and write_outputs take */
        jac[VR_penetration][i] = jac[VR_x][i];
        if (force > 0.0) {
            jac[VR_fx][i] = c.wall_k * jac[VR_x][i] + c.wall_d * jac[VR_xd][i];
            jac[VR_contact_force][i] = jac[VR_fx][i];
        }
    }
    return 0;
}

int model_output_derivative(const Data *d, int vr, int order, double *value, char *msg)
{
    const ModelState *m = &d->m;
    PlantCtx c;
    double y[ODE_N], dy[ODE_N], j[9], jdot[9], xdot[3], xddot[3], pose[3], pen, force;
    char err[ODE_MSG_MAX];
    (void)order; /* 1: MAX_OUTPUT_DERIVATIVE_ORDER */
    read_ctx(d, &c);
    model_me_get_states(d, y);
    if (plant_rhs(&c, y, dy, err)) {
        return fail(msg, "output derivative of %s failed: %s", VARS[vr].name, err);
    }
    arm_kinematics(&c.arm, m->q, pose);
    arm_jacobian(&c.arm, m->q, j);
    arm_jacobian_dot(&c.arm, m->q, m->qd, jdot);
    matvec(j, m->qd, xdot);
    matvec(j, dy + 3, xddot);
    for (int r = 0; r < 3; r++) {
        xddot[r] += jdot[3 * r] * m->qd[0] + jdot[3 * r + 1] * m->qd[1]
                    + jdot[3 * r + 2] * m->qd[2];
    }
    pen = pose[0] - c.wall_x;
    force = c.wall_k * pen + c.wall_d * xdot[0];
    switch (vr) {
    case VR_q1: case VR_q2: case VR_q3:
        if (d->r[VR_q_noise] != 0.0 || d->r[VR_q_quant] != 0.0) {
            return fail(msg, "%s has no time derivative: the encoder adds noise (q_noise = %g)"
                             " and quantizes (q_quant = %g); qd%d is the true velocity",
                        VARS[vr].name, d->r[VR_q_noise], d->r[VR_q_quant], vr - VR_q1 + 1);
        }
        *value = m->qd[vr - VR_q1];
        return 0;
    case VR_q1_true: case VR_q2_true: case VR_q3_true:
        *value = m->qd[vr - VR_q1_true];
        return 0;
    case VR_qd1: case VR_qd2: case VR_qd3:
        *value = dy[3 + vr - VR_qd1];
        return 0;
    case VR_x: case VR_y: case VR_phi:
        *value = xdot[vr - VR_x];
        return 0;
    case VR_xd: case VR_yd: case VR_phid:
        *value = xddot[vr - VR_xd];
        return 0;
    case VR_fx: case VR_contact_force: /* wall_force's branch at this pose */
        *value = pen > 0.0 && force > 0.0 ? c.wall_k * xdot[0] + c.wall_d * xddot[0] : 0.0;
        return 0;
    case VR_penetration:
        *value = pen > 0.0 ? xdot[0] : 0.0;
        return 0;
    default: /* fy, n: always zero */
        *value = 0.0;
        return 0;
    }
}
