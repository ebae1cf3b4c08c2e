/* The native PumaPlant's Model Exchange side (model_me.h) and its exact partial derivatives
 * (model_partials.h), over the equations of model.c (plant.h). */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "arm.h"
#include "arm_partials.h"
#include "arm_terms.h"
#include "glue.h"
#include "linalg3.h"
#include "model_me.h"
#include "model_partials.h"
#include "ode.h"
#include "plant.h"

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

/* The states y and their derivatives dy at d's states and torques (c: the plant's context). */
static int derivatives(const Data *d, PlantCtx *c, double y[ODE_N], double dy[ODE_N], char *msg)
{
    char err[ODE_MSG_MAX];
    plant_read_ctx(d, c);
    model_me_get_states(d, y);
    if (plant_rhs(c, y, dy, err)) {
        return fail(msg, "plant derivatives failed: %s", err);
    }
    return 0;
}

int model_me_evaluate(Data *d, char *msg)
{
    ModelState *m = &d->m;
    PlantCtx c;
    double y[ODE_N], dy[ODE_N];
    if (derivatives(d, &c, y, dy, msg)) {
        return 1;
    }
    for (int k = 0; k < N_STATES; k++) {
        d->r[DERIVATIVE_VRS[k]] = dy[k];
    }
    memcpy(m->q_meas, m->q, sizeof m->q_meas); /* ideal encoders (model_me_check) */
    plant_write_outputs(d);
    return 0;
}

int model_me_event_indicators(const Data *d, double z[], char *msg)
{
    PlantCtx c;
    double y[ODE_N];
    char err[ODE_MSG_MAX];
    plant_read_ctx(d, &c);
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
    if (derivatives(d, &c, y, dy, msg)) {
        return 1;
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
        if (plant_ee_x(&c->arm, q, qd, &x, &xd, err)) {
            return 1;
        }
        fx = wall_contact_force_law(&c->wall, x, xd);
        for (int i = 0; i < 3; i++) {
            const double dxd = dj[9 * i] * qd[0] + dj[9 * i + 1] * qd[1] + dj[9 * i + 2] * qd[2];
            const double dfx_dq = c->wall.k * j[i] + c->wall.d * dxd;
            const double dfx_dqd = c->wall.d * j[i];
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
    plant_read_ctx(d, &c);
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
    if (plant_ee_x(&c.arm, m->q, m->qd, &x, &xd, err)) {
        return fail(msg, "plant partial derivatives failed: %s", err);
    }
    pen = x - c.wall.x;
    force = c.wall.k * pen + c.wall.d * xd;
    for (int i = 0; i < 6 && pen > 0.0; i++) { /* the branches wall_force and write_outputs take */
        jac[VR_penetration][i] = jac[VR_x][i];
        if (force > 0.0) {
            jac[VR_fx][i] = c.wall.k * jac[VR_x][i] + c.wall.d * jac[VR_xd][i];
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
    plant_read_ctx(d, &c);
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
    pen = pose[0] - c.wall.x;
    force = c.wall.k * pen + c.wall.d * xdot[0];
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
        *value = pen > 0.0 && force > 0.0 ? c.wall.k * xdot[0] + c.wall.d * xddot[0] : 0.0;
        return 0;
    case VR_penetration:
        *value = pen > 0.0 ? xdot[0] : 0.0;
        return 0;
    default: /* fy, n: always zero */
        *value = 0.0;
        return 0;
    }
}
