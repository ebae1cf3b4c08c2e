/* The native ImpedanceController: reduced-order velocity observer (eq. 9) + impedance law
 * (eq. 10), sampled at sample_period with its outputs held between samples.
 *
 * A transcription of controller_model/model.py (and of Arm.forward_dynamics, jacobian_det and
 * friction in physics/arm.py), operation for operation: the same temporaries, the same
 * order of terms and the same parenthesisation as Python's left-to-right evaluation, the same libm
 * calls, so that with -ffp-contract=off (no fused multiply-add) and without -ffast-math it computes
 * the same numbers as the Python FMU, bit for bit. Error messages are the Python ones, floats
 * formatted like Python's repr. Read the Python first; the comments here only note departures.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "arm.h"
#include "arm_terms.h"
#include "glue.h"
#include "controller.h" /* Params, the functions model_me.c shares */
#include "pyrepr.h"
#include "linalg3.h"

#define PI 3.141592653589793 /* math.pi */
#define TWO_PI (2.0 * PI)
#define SINGULAR_TOL 1e-6 /* |det J| below SINGULAR_TOL * a1 * a2 is singular */
#define N_OUTPUTS 24      /* VR_tau1 .. VR_e_phi, contiguous and in ControllerModel's order */
#define SINGULAR_POSE 2   /* impedance_terms' return when J is singular (eq. 10 undefined) */

static const char *const VELOCITY_SOURCES[3] = {"observer", "difference", "measured"};
/* observer_discretization (OBSERVER_DISCRETIZATIONS) */
static const char *const DISCRETIZATIONS[3] = {"euler", "implicit", "exponential"};
void controller_read_params(const Data *d, Params *p)
{
    const double *r = d->r;
    p->discretization = -1;
    for (int k = 0; k < 3; k++) {
        if (strncmp(d->s[VR_observer_discretization], DISCRETIZATIONS[k], STRING_MAX) == 0) {
            p->discretization = k;
        }
    }
    p->arm.a1 = r[VR_a1];
    p->arm.a2 = r[VR_a2];
    p->arm.a3 = r[VR_a3];
    p->arm.m1 = r[VR_m1];
    p->arm.m2 = r[VR_m2];
    p->arm.m3 = r[VR_m3];
    p->arm.rx1 = r[VR_rx1];
    p->arm.ry1 = r[VR_ry1];
    p->arm.rx2 = r[VR_rx2];
    p->arm.rx3 = r[VR_rx3];
    p->arm.Iu1 = r[VR_Iu1];
    p->arm.Iu2 = r[VR_Iu2];
    p->arm.Iu3 = r[VR_Iu3];
    p->arm.Im1 = r[VR_Im1];
    p->arm.Im2 = r[VR_Im2];
    p->arm.Im3 = r[VR_Im3];
    p->arm.f1 = r[VR_f1];
    p->arm.f2 = r[VR_f2];
    p->arm.f3 = r[VR_f3];
    p->arm.g = r[VR_g];
    p->traj_cx = r[VR_traj_cx];
    p->traj_cy = r[VR_traj_cy];
    p->traj_ax = r[VR_traj_ax];
    p->traj_ay = r[VR_traj_ay];
    p->traj_f = r[VR_traj_f];
    p->traj_phi = r[VR_traj_phi];
    p->wall_x = r[VR_wall_x];
    p->wall_depth = r[VR_wall_depth];
    p->K[0] = r[VR_K1];
    p->K[1] = r[VR_K2];
    p->K[2] = r[VR_K3];
    p->G[0] = r[VR_G1];
    p->G[1] = r[VR_G2];
    p->G[2] = r[VR_G3];
    p->B[0] = r[VR_B1];
    p->B[1] = r[VR_B2];
    p->B[2] = r[VR_B3];
    p->yhat0[0] = r[VR_yhat0_1];
    p->yhat0[1] = r[VR_yhat0_2];
    p->yhat0[2] = r[VR_yhat0_3];
    p->tau_max[0] = r[VR_tau_max1];
    p->tau_max[1] = r[VR_tau_max2];
    p->tau_max[2] = r[VR_tau_max3];
    p->ts = r[VR_sample_period];
    p->limit_torque = d->i[VR_limit_torque] != 0;
}

/* --- virtual trajectory, observer, impedance law --------------------------------------------- */

static void virtual_trajectory(const Params *p, double t, double xv[3], double xv_dot[3],
                               double xv_ddot[3])
{
    const double w = TWO_PI * p->traj_f;
    const double theta = w * t - 0.5 * PI;
    const double s = sin(theta), c = cos(theta);
    const double x = p->traj_cx + p->traj_ax * s;
    const double y = p->traj_cy + p->traj_ay * c;
    const double yd = -p->traj_ay * w * s;
    const double ydd = -p->traj_ay * w * w * c;
    xv[1] = y;
    xv[2] = p->traj_phi;
    xv_dot[1] = yd;
    xv_dot[2] = 0.0;
    xv_ddot[1] = ydd;
    xv_ddot[2] = 0.0;
    if (x >= p->wall_x) { /* in contact: the target lies wall_depth inside the wall */
        xv[0] = p->wall_x + p->wall_depth;
        xv_dot[0] = 0.0;
        xv_ddot[0] = 0.0;
        return;
    }
    xv[0] = x;
    xv_dot[0] = p->traj_ax * w * c;
    xv_ddot[0] = -p->traj_ax * w * w * s;
}

static int observer_update(const Params *p, const double yhat_prev[3], const double q_prev[3],
                           const double q_now[3], const double tau_prev[3], const double f_prev[3],
                           double dt, double yhat[3], char *msg)
{
    const double *K = p->K;
    double j[9], jtf[3], net[3], acc[3];
    int i;
    arm_jacobian(&p->arm, q_prev, j);
    matTvec(j, f_prev, jtf);
    net[0] = tau_prev[0] - jtf[0];
    net[1] = tau_prev[1] - jtf[1];
    net[2] = tau_prev[2] - jtf[2];
    if (arm_forward_dynamics(&p->arm, q_prev, yhat_prev, net, acc)) {
        /* Python: ZeroDivisionError in linalg3.solve */
        return fail(msg, "the inertia matrix of the controller's arm model is singular");
    }
    for (i = 0; i < 3; i++) {
        const double dq = q_now[i] - q_prev[i];
        if (p->discretization == OBS_IMPLICIT) {
            yhat[i] = (yhat_prev[i] + K[i] * dq + dt * acc[i]) / (1.0 + dt * K[i]);
        } else if (p->discretization == OBS_EXPONENTIAL) {
            const double a = exp(-K[i] * dt);
            yhat[i] = a * yhat_prev[i] + (1.0 - a) * (dq / dt + acc[i] / K[i]);
        } else {
            yhat[i] = yhat_prev[i] + K[i] * (q_now[i] - q_prev[i]) + dt * acc[i] -
                      dt * K[i] * yhat_prev[i];
        }
    }
    return 0;
}

static double wrap_angle(double a)
{
    const double w = remainder(a, TWO_PI); /* exact, like math.remainder */
    return w <= -PI ? w + TWO_PI : w;
}

static int impedance_terms(const Params *p, const double q[3], const double yhat[3],
                           const double f_au[3], const double xv[3], const double xv_dot[3],
                           const double xv_ddot[3], double tau[3], double e[3],
                           double xd_hat[3], char *msg)
{
    const ArmParams *arm = &p->arm;
    const double *G = p->G, *B = p->B;
    const double det = arm_jacobian_det(arm, q);
    double j[9], qd_v[3], jdot[9], jdot_qd[3], rhs[3], qdd_v[3], pose[3], f_c[3], jtf[3];
    double h[9], hq[3], c[9], cq[3], fq[3], g[3];
    if (!(fabs(det) >= SINGULAR_TOL * arm->a1 * arm->a2)) { /* Python: SingularPoseError */
        fail(msg,
             "the Jacobian is singular at q = (%.6g, %.6g, %.6g) rad"
             " (det J = a1 a2 sin q2 = %.3g): the impedance law needs J^-1",
             q[0], q[1], q[2], det);
        return SINGULAR_POSE;
    }
    arm_jacobian(arm, q, j);
    if (solve3(j, xv_dot, qd_v)) { /* Python: ZeroDivisionError in linalg3.solve */
        return fail(msg, "the Jacobian is singular (det = 0) at q = (%.6g, %.6g, %.6g) rad", q[0],
                    q[1], q[2]);
    }
    arm_jacobian_dot(arm, q, yhat, jdot);
    matvec(jdot, qd_v, jdot_qd);
    rhs[0] = xv_ddot[0] - jdot_qd[0];
    rhs[1] = xv_ddot[1] - jdot_qd[1];
    rhs[2] = xv_ddot[2] - jdot_qd[2];
    if (solve3(j, rhs, qdd_v)) { /* same matrix as above: cannot happen */
        return fail(msg, "the Jacobian is singular (det = 0)");
    }
    arm_kinematics(arm, q, pose);
    e[0] = pose[0] - xv[0];
    e[1] = pose[1] - xv[1];
    e[2] = wrap_angle(pose[2] - xv[2]);
    matvec(j, yhat, xd_hat);
    f_c[0] = f_au[0] - B[0] * (xd_hat[0] - xv_dot[0]) - G[0] * e[0];
    f_c[1] = f_au[1] - B[1] * (xd_hat[1] - xv_dot[1]) - G[1] * e[1];
    f_c[2] = f_au[2] - B[2] * (xd_hat[2] - xv_dot[2]) - G[2] * e[2];
    matTvec(j, f_c, jtf);
    arm_inertia(arm, q, h);
    matvec(h, qdd_v, hq);
    arm_coriolis(arm, q, yhat, c);
    matvec(c, qd_v, cq);
    fq[0] = arm->f1 * qd_v[0]; /* Arm.friction */
    fq[1] = arm->f2 * qd_v[1];
    fq[2] = arm->f3 * qd_v[2];
    arm_gravity(arm, q, g);
    tau[0] = hq[0] + cq[0] + fq[0] + g[0] + jtf[0];
    tau[1] = hq[1] + cq[1] + fq[1] + g[1] + jtf[1];
    tau[2] = hq[2] + cq[2] + fq[2] + g[2] + jtf[2];
    return 0;
}

/* gravity_hold_terms: gravity compensation alone, with e and J yhat (sample 0 at a singular
 * pose, where eq. 10 is undefined) */
static void gravity_hold_terms(const Params *p, const double q[3], const double yhat[3],
                               const double xv[3], double tau[3], double e[3], double xd_hat[3])
{
    double j[9], pose[3];
    arm_jacobian(&p->arm, q, j);
    arm_kinematics(&p->arm, q, pose);
    e[0] = pose[0] - xv[0];
    e[1] = pose[1] - xv[1];
    e[2] = wrap_angle(pose[2] - xv[2]);
    arm_gravity(&p->arm, q, tau);
    matvec(j, yhat, xd_hat);
}

/* --- the model ------------------------------------------------------------------------------- */

/* ControllerModel._split: the inputs, after checking they are finite (qd_meas only when used). */
int controller_split_inputs(const Data *d, double q[3], double f[3], double qd_meas[3], char *msg)
{
    const int n = d->m.velocity_source == SOURCE_MEASURED ? 9 : 6;
    int k;
    for (k = 0; k < n; k++) {
        const double v = d->r[VR_q1 + k];
        if (!(v - v == 0.0)) { /* false for NaN and +-inf */
            char buf[32];
            py_float_repr(v, buf, sizeof buf);
            return fail(msg, "input %s is not finite (%s)", VARS[VR_q1 + k].name, buf);
        }
    }
    for (k = 0; k < 3; k++) {
        q[k] = d->r[VR_q1 + k];
        f[k] = d->r[VR_fx + k];
        qd_meas[k] = d->r[VR_qd_meas1 + k];
    }
    return 0;
}

/* ControllerModel._sample: sample k from the state in d->m (the previous sample's) and this
 * sample's inputs; on success, updates d->m and writes the outputs to d->r. law 0: gravity
 * compensation instead of eq. (10). Returns SINGULAR_POSE when eq. (10) is undefined. */
int controller_take_sample(Data *d, const Params *p, int64_t k, const double q[3],
                           const double f[3], const double qd_meas[3], int law, char *msg)
{
    ModelState *m = &d->m;
    const double ts = p->ts;
    double yhat[3], qd_diff[3], xv[3], xv_dot[3], xv_ddot[3], tau[3], e[3], xd_hat[3];
    const double *qd_hat;
    double *out = &d->r[VR_tau1];
    int i;
    if (k == 0) {
        for (i = 0; i < 3; i++) {
            yhat[i] = qd_diff[i] = p->yhat0[i];
        }
    } else {
        if (observer_update(p, m->yhat, m->q_prev, q, m->tau_prev, m->f_prev, ts, yhat, msg)) {
            return 1;
        }
        for (i = 0; i < 3; i++) {
            qd_diff[i] = (q[i] - m->q_prev[i]) / ts;
        }
    }
    qd_hat = m->velocity_source == SOURCE_OBSERVER     ? yhat
             : m->velocity_source == SOURCE_DIFFERENCE ? qd_diff
                                                       : qd_meas;
    virtual_trajectory(p, m->start_time + (double)k * ts, xv, xv_dot, xv_ddot);
    if (!law) {
        gravity_hold_terms(p, q, qd_hat, xv, tau, e, xd_hat);
    } else {
        const int r = impedance_terms(p, q, qd_hat, f, xv, xv_dot, xv_ddot, tau, e, xd_hat, msg);
        if (r) {
            return r;
        }
    }
    if (p->limit_torque) {
        for (i = 0; i < 3; i++) { /* min(m, max(-m, tau)), with Python's min/max on ties/NaN */
            const double hi = p->tau_max[i], lo = -p->tau_max[i];
            const double clipped = tau[i] > lo ? tau[i] : lo;
            tau[i] = clipped < hi ? clipped : hi;
        }
    }
    for (i = 0; i < 3; i++) {
        out[0 + i] = tau[i];
        out[3 + i] = qd_hat[i];
        out[6 + i] = yhat[i];
        out[9 + i] = qd_diff[i];
        out[12 + i] = xd_hat[i];
        out[15 + i] = xv[i];
        out[18 + i] = xv_dot[i];
        out[21 + i] = e[i];
        m->yhat[i] = yhat[i];
        m->q_prev[i] = q[i];
        m->tau_prev[i] = tau[i];
        m->f_prev[i] = f[i];
    }
    return 0;
}

/* ControllerParams.validate: the gains, period and limits that must be > 0 */
static int check_positive(const Data *d, char *msg)
{
    static const int positive[] = {VR_K1, VR_K2, VR_K3, VR_G1, VR_G2, VR_G3, VR_B1, VR_B2, VR_B3,
                                   VR_sample_period, VR_tau_max1, VR_tau_max2, VR_tau_max3};
    char buf[32];
    for (size_t k = 0; k < sizeof positive / sizeof positive[0]; k++) {
        const double value = d->r[positive[k]];
        if (isfinite(value) && !(value > 0.0)) {
            py_float_repr(value, buf, sizeof buf);
            return fail(msg, "parameter %s must be > 0 (got %s)", VARS[positive[k]].name, buf);
        }
    }
    return 0;
}

/* The gains (K, G, B), force setpoint and trajectory may change between steps: model_step reads
 * them at every step; their ranges are those of initialization (the glue checked the minimums). */
int model_check_tunable(const Data *d, char *msg) { return check_positive(d, msg); }

int model_initialize(Data *d, char *msg)
{
    ModelState *m = &d->m;
    Params p;
    double q[3], f[3], qd_meas[3];
    char buf[2][32];
    const int source = d->i[VR_velocity_source];
    controller_read_params(d, &p);
    /* ArmParams.validate (the glue has checked finiteness and minimums) */
    if (p.arm.a1 <= 0.0 || p.arm.a2 <= 0.0) {
        py_float_repr(p.arm.a1, buf[0], sizeof buf[0]);
        py_float_repr(p.arm.a2, buf[1], sizeof buf[1]);
        return fail(msg, "link lengths a1, a2 must be > 0 (got a1=%s, a2=%s)", buf[0], buf[1]);
    }
    /* ControllerParams.validate */
    if (check_positive(d, msg)) {
        return 1;
    }
    if (source < 1 || source > 3) { /* the VelocitySource enumeration's items, valued 1..3 */
        return fail(msg,
                    "parameter velocity_source must be one of 1 (%s), 2 (%s), 3 (%s) (got %d)",
                    VELOCITY_SOURCES[0], VELOCITY_SOURCES[1], VELOCITY_SOURCES[2], source);
    }
    if (p.discretization < 0) {
        char text[4 * STRING_MAX + 3];
        py_str_repr(d->s[VR_observer_discretization], STRING_MAX, text, sizeof text);
        return fail(msg,
                    "parameter observer_discretization must be one of %s, %s, %s (got %s)",
                    DISCRETIZATIONS[0], DISCRETIZATIONS[1], DISCRETIZATIONS[2], text);
    }
    memset(m, 0, sizeof *m);
    m->velocity_source = source - 1;
    m->start_time = d->start_time;
    if (controller_split_inputs(d, q, f, qd_meas, msg)) {
        return 1;
    }
    /* Sample 0, from the inputs at initialization (previous sample: zeros, unused at k = 0).
     * Any finite inputs initialize: at a singular pose, gravity compensation only, and the
     * message (a warning: the glue logs a message left by a successful model_initialize). */
    {
        const int r = controller_take_sample(d, &p, 0, q, f, qd_meas, 1, msg);
        if (r == SINGULAR_POSE) {
            char reason[MSG_MAX];
            snprintf(reason, sizeof reason, "%s", msg);
            py_float_repr(d->start_time, buf[0], sizeof buf[0]);
            if (controller_take_sample(d, &p, 0, q, f, qd_meas, 0, msg)) {
                return 1;
            }
            snprintf(msg, MSG_MAX,
                     "%.300s: at initialization (t=%s) the torque is gravity compensation only,"
                     " tau = g(q); a step that samples at a singular pose is refused",
                     reason, buf[0]);
        } else if (r) {
            return 1;
        }
    }
    m->t = m->start_time;
    m->k_next = 1;
    m->held_input_samples = 0;
    return 0;
}

int model_step(Data *d, double t, double h, char *msg)
{
    ModelState *m = &d->m;
    Params p;
    double q[3], f[3], qd_meas[3], tol, t_end;
    int64_t k, held = 0;
    char buf[2][32];
    controller_read_params(d, &p);
    if (controller_split_inputs(d, q, f, qd_meas, msg)) {
        return 1;
    }
    if (!(h > 0.0)) {
        py_float_repr(h, buf[0], sizeof buf[0]);
        return fail(msg, "communication step must be > 0 (got %s)", buf[0]);
    }
    if (isinf(h)) {
        return fail(msg, "communication step must be finite (got inf)");
    }
    {
        const double at = fabs(t);
        const double scale = at > 1.0 ? at : 1.0; /* max(1.0, abs(t)) */
        if (fabs(t - m->t) > 1e-9 * scale) {
            py_float_repr(t, buf[0], sizeof buf[0]);
            py_float_repr(m->t, buf[1], sizeof buf[1]);
            return fail(msg, "doStep at t=%s, but the controller is at t=%s", buf[0], buf[1]);
        }
    }
    tol = TIME_TOL * p.ts;
    t_end = t + h;
    {
        const int n_max = d->i[VR_max_samples_per_step];
        if (m->start_time + (double)(m->k_next + n_max) * p.ts < t_end - tol) {
            py_float_repr(h, buf[0], sizeof buf[0]); /* sample k_next + n_max would be taken */
            py_float_repr(t, buf[1], sizeof buf[1]);
            return fail(msg,
                        "a communication step of %s s from t=%s would take more than %d samples"
                        " (parameter max_samples_per_step): take a smaller step",
                        buf[0], buf[1], n_max);
        }
    }
    /* every unprocessed sample t_k < t + h, all on the inputs given at t (the glue discards d
     * when this fails, so the state may be updated sample by sample) */
    for (k = m->k_next; m->start_time + (double)k * p.ts < t_end - tol; k++) {
        if (m->start_time + (double)k * p.ts > t + tol) {
            held += 1; /* strictly inside the step: the inputs at t are reused */
        }
        if (controller_take_sample(d, &p, k, q, f, qd_meas, 1, msg)) {
            return 1;
        }
    }
    m->k_next = k;
    m->held_input_samples += held;
    m->t = t_end;
    return 0;
}

int model_check_state(const Data *d, char *msg)
{
    const ModelState *m = &d->m;
    if (!isfinite(m->t) || !isfinite(m->start_time)) {
        return fail(msg, "controller time not finite");
    }
    /* k_next counts samples: 1 after initialization, and below 2^53 so k * Ts stays exact */
    if (m->k_next < 1 || m->k_next > ((int64_t)1 << 53)) {
        return fail(msg, "controller sample counter %lld out of range",
                    (long long)m->k_next);
    }
    if (m->held_input_samples < 0 || m->held_input_samples >= m->k_next) {
        return fail(msg, "controller held-sample counter %lld out of range",
                    (long long)m->held_input_samples);
    }
    if (m->velocity_source < SOURCE_OBSERVER || m->velocity_source > SOURCE_MEASURED ||
        m->velocity_source != d->i[VR_velocity_source] - 1) {
        return fail(msg, "controller velocity source %d does not match velocity_source",
                    (int)m->velocity_source);
    }
    for (int i = 0; i < 3; i++) {
        if (!isfinite(m->q_prev[i]) || !isfinite(m->f_prev[i])) {
            return fail(msg, "controller's previous sample (angles, force) not finite");
        }
    }
    return 0;
}

/* Every double of ModelState (glue.h). In memory, yhat and tau_prev may overflow to inf or NaN
 * under extreme gains (as in the Python model); a serialized state must hold finite ones. */
MODEL_LINKAGE const StateReals MODEL_STATE_REALS[] = {
    {"controller t", offsetof(ModelState, t), 1},
    {"controller start_time", offsetof(ModelState, start_time), 1},
    {"controller yhat", offsetof(ModelState, yhat), 3},
    {"controller q_prev", offsetof(ModelState, q_prev), 3},
    {"controller tau_prev", offsetof(ModelState, tau_prev), 3},
    {"controller f_prev", offsetof(ModelState, f_prev), 3},
};
MODEL_LINKAGE const int N_MODEL_STATE_REALS = sizeof MODEL_STATE_REALS / sizeof *MODEL_STATE_REALS;
