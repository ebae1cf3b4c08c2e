/* The paper's closed loop as one co-simulation FMU: the controller's and the plant's model code
 * (parts.h), stepped as our master's Gauss-Seidel loop steps their two FMUs
 * (impedance_cosim/cosim/master/master.py, native/master/loop.c): per step from t, the controller takes
 * the plant's outputs at t (its sample at t), then the plant integrates over the step with the
 * controller's torque held (the paper's sample-and-hold). Initialization follows the master's:
 * the plant first (its outputs depend on no input), the controller from the plant's outputs, the
 * plant again with the controller's torque.
 *
 * A communication step longer than the controller's sample period is cut at the sample instants
 * start + k * sample_period (the loop runs at the sample rate whatever the host's step); a step
 * of one sample period on the grid is one such step, given to the parts as the host gave it.
 * Co-simulation only (ME_OFFERED 0): the closed loop has no Model Exchange form.
 */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "glue.h"
#include "model_me.h"
#include "parts.h"

#define TIME_TOL 1e-9 /* sample-time comparisons, relative to the sample period (as the controller) */

static const Part *part_api(int part)
{
    return part == PART_PLANT ? &plant_part : &controller_part;
}

static PartData *part_of(ModelState *m, int part)
{
    return part == PART_PLANT ? &m->plant : &m->controller;
}

/* The closed loop's parameter values into its parts: every parameter, or the tunable ones. */
static void copy_parameters(const Data *d, ModelState *m, int tunable_only)
{
    for (int vr = 0; vr < N_VARS; vr++) {
        const VarInfo *v = &VARS[vr];
        const Part *part = part_api(LINKS[vr].part);
        PartData *p = part_of(m, LINKS[vr].part);
        const int pvr = LINKS[vr].vr;
        if (v->causality != C_PARAMETER || (tunable_only && !v->tunable)) {
            continue;
        }
        if (v->type == T_REAL) {
            part->set_real(p, pvr, d->r[vr]);
        } else if (v->type == T_STRING) {
            part->set_string(p, pvr, d->s[vr]);
        } else {
            part->set_int(p, pvr, d->i[vr]);
        }
    }
}

static void copy_outputs(Data *d)
{
    for (int vr = 0; vr < N_VARS; vr++) {
        if (VARS[vr].causality == C_OUTPUT) {
            d->r[vr] = part_api(LINKS[vr].part)->get_real(part_of(&d->m, LINKS[vr].part),
                                                          LINKS[vr].vr);
        }
    }
}

/* The connections of the SSD: the plant's sensors into the controller, the torque back. */
static void feed_controller(ModelState *m)
{
    for (int k = 0; k < N_FEED; k++) {
        controller_part.set_real(&m->controller, FEED[k][1],
                                 plant_part.get_real(&m->plant, FEED[k][0]));
    }
}

static void feed_plant(ModelState *m)
{
    for (int k = 0; k < N_TORQUE; k++) {
        plant_part.set_real(&m->plant, TORQUE[k][1],
                            controller_part.get_real(&m->controller, TORQUE[k][0]));
    }
}

/* A part's message, named after the part. */
static int part_failed(char *msg, const char *part, const char *inner)
{
    return fail(msg, "%s: %s", part, inner);
}

int model_initialize(Data *d, char *msg)
{
    char inner[MSG_MAX];
    ModelState *m = &d->m;
    plant_part.start(&m->plant, d->start_time);
    controller_part.start(&m->controller, d->start_time);
    copy_parameters(d, m, 0);
    inner[0] = '\0';
    if (plant_part.initialize(&m->plant, inner)) {
        return part_failed(msg, "plant", inner);
    }
    feed_controller(m);
    inner[0] = '\0';
    if (controller_part.initialize(&m->controller, inner)) {
        return part_failed(msg, "controller", inner);
    }
    if (inner[0] != '\0') { /* a warning (e.g. a singular start): the glue logs it */
        part_failed(msg, "controller", inner);
    }
    feed_plant(m);
    inner[0] = '\0';
    if (plant_part.initialize(&m->plant, inner)) {
        return part_failed(msg, "plant", inner);
    }
    copy_outputs(d);
    return 0;
}

/* One step of the loop from t over h, the master's Gauss-Seidel step. */
static int loop_step(ModelState *m, double t, double h, char *msg)
{
    char inner[MSG_MAX];
    feed_controller(m);
    if (controller_part.step(&m->controller, t, h, inner)) {
        return part_failed(msg, "controller", inner);
    }
    feed_plant(m);
    if (plant_part.step(&m->plant, t, h, inner)) {
        return part_failed(msg, "plant", inner);
    }
    return 0;
}

int model_step(Data *d, double t, double h, char *msg)
{
    const double ts = d->r[VR_controller_sample_period];
    const double tol = TIME_TOL * ts;
    const double end = t + h;
    const int n_max = d->i[VR_controller_max_samples_per_step];
    double tc = t;
    int64_t k;
    int n = 0;
    if (!(h > 0.0) || !isfinite(end)) {
        return fail(msg, "the communication step size must be positive and finite (got %g)", h);
    }
    copy_parameters(d, &d->m, 1); /* tunable parameters set since the last step */
    k = (int64_t)floor((t - d->start_time) / ts + TIME_TOL) + 1; /* next sample after t */
    /* refused before any work where it surely spans too many (the loop's count, within 1) */
    if (floor((end - tol - d->start_time) / ts) - (double)k + 2.0 > (double)n_max + 2.0) {
        return fail(msg, "a step of %g s spans more than %d sample periods (parameter "
                         "controller.max_samples_per_step): take a smaller step", h, n_max);
    }
    for (;;) {
        const double next = d->start_time + (double)k * ts;
        const int last = !(next < end - tol);
        const double hc = last ? (tc == t ? h : end - tc) : next - tc;
        if ((int64_t)++n > (int64_t)n_max + 1) {
            return fail(msg, "a step of %g s spans more than %d sample periods (parameter "
                             "controller.max_samples_per_step): take a smaller step", h, n_max);
        }
        if (loop_step(&d->m, tc, hc, msg)) {
            return 1;
        }
        if (last) {
            break;
        }
        tc = next;
        k++;
    }
    copy_outputs(d);
    return 0;
}

int model_check_tunable(const Data *d, char *msg)
{
    ModelState *tmp = (ModelState *)malloc(sizeof *tmp); /* large: not on a host's stack */
    char inner[MSG_MAX];
    if (!tmp) {
        return fail(msg, "out of memory checking the tunable parameters");
    }
    *tmp = d->m;
    copy_parameters(d, tmp, 1);
    if (plant_part.check_tunable(&tmp->plant, inner)) {
        free(tmp);
        return part_failed(msg, "plant", inner);
    }
    if (controller_part.check_tunable(&tmp->controller, inner)) {
        free(tmp);
        return part_failed(msg, "controller", inner);
    }
    free(tmp);
    return 0;
}

int model_check_state(const Data *d, char *msg)
{
    char inner[MSG_MAX];
    if (plant_part.check_state(&d->m.plant, inner)) {
        return part_failed(msg, "plant", inner);
    }
    if (controller_part.check_state(&d->m.controller, inner)) {
        return part_failed(msg, "controller", inner);
    }
    return 0;
}

/* The parts' reals are checked by model_check_state (part by part), not listed here. */
const StateReals MODEL_STATE_REALS[] = {{"none", 0, 0}};
const int N_MODEL_STATE_REALS = 0;

/* --- the Model Exchange side the FMI 3 layer compiles against; never offered (ME_OFFERED 0) -- */

int model_me_check(const Data *d, char *msg)
{
    (void)d;
    return fail(msg, "the closed loop offers co-simulation only");
}
void model_me_get_states(const Data *d, double x[]) { (void)d, (void)x; }
void model_me_set_states(Data *d, const double x[]) { (void)d, (void)x; }
int model_me_evaluate(Data *d, char *msg)
{
    (void)d;
    return fail(msg, "the closed loop offers co-simulation only");
}
int model_me_event_indicators(const Data *d, double z[], char *msg)
{
    (void)d, (void)z;
    return fail(msg, "the closed loop offers co-simulation only");
}
int model_me_event_update(Data *d, double t, MeEvent *ev, char *msg)
{
    (void)d, (void)t, (void)ev;
    return fail(msg, "the closed loop offers co-simulation only");
}
