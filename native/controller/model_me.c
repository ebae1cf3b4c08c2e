/* The native ImpedanceController's Model Exchange side (model_me.h): no continuous states, a
 * sample at each time event (its next sample instant), over model.c's sampling (controller.h). */
#include <math.h>
#include <stdio.h>

#include "controller.h"
#include "glue.h"
#include "model_me.h"
#include "pyrepr.h"

/* --- Model Exchange (model_me.h) --------------------------------------------------------------
 * A sampled-data model: no continuous states and no event indicators. Each sample instant
 * t_k = start_time + k * sample_period is a time event; at it the sample is taken from the
 * inputs the host has set (take_sample, as in model_step), and the outputs hold until the next. */

int model_me_check(const Data *d, char *msg)
{
    (void)d;
    (void)msg;
    return 0;
}

void model_me_get_states(const Data *d, double x[])
{
    (void)d;
    (void)x;
}

void model_me_set_states(Data *d, const double x[])
{
    (void)d;
    (void)x;
}

int model_me_evaluate(Data *d, char *msg)
{
    (void)d; /* the outputs are the held sample, written by take_sample */
    (void)msg;
    return 0;
}

int model_me_event_indicators(const Data *d, double z[], char *msg)
{
    (void)d;
    (void)z;
    (void)msg;
    return 0;
}

int model_me_event_update(Data *d, double t, MeEvent *ev, char *msg)
{
    ModelState *m = &d->m;
    Params p;
    double q[3], f[3], qd_meas[3], tol;
    int64_t k;
    controller_read_params(d, &p);
    tol = TIME_TOL * p.ts;
    if (m->start_time + (double)m->k_next * p.ts <= t + tol) {
        const int n_max = d->i[VR_max_samples_per_step];
        if (m->start_time + (double)(m->k_next + n_max) * p.ts <= t + tol) {
            char buf[2][32]; /* sample k_next + n_max is due: the host skipped that many */
            py_float_repr(t, buf[0], sizeof buf[0]);
            py_float_repr(m->t, buf[1], sizeof buf[1]);
            return fail(msg,
                        "an event at t=%s from t=%s would take more than %d samples (parameter"
                        " max_samples_per_step): the host skipped the time events between",
                        buf[0], buf[1], n_max);
        }
        if (controller_split_inputs(d, q, f, qd_meas, msg)) {
            return 1;
        }
        /* every sample due by t (more than one only if the host skipped a time event: those
         * use the inputs at t, as model_step does inside a step) */
        for (k = m->k_next; m->start_time + (double)k * p.ts <= t + tol; k++) {
            if (m->start_time + (double)k * p.ts < t - tol) {
                m->held_input_samples += 1;
            }
            if (controller_take_sample(d, &p, k, q, f, qd_meas, 1, msg)) {
                return 1;
            }
        }
        m->k_next = k;
        ev->changed = 1;
    }
    m->t = t;
    ev->next_defined = 1;
    ev->next = m->start_time + (double)m->k_next * p.ts;
    return 0;
}

/* --- Co-Simulation with event mode (FMI 3.0: the sample clock's ticks are events) ------------ */

static double tick_time(const Data *d, int64_t k)
{
    return d->m.start_time + (double)k * d->r[VR_sample_period];
}

double model_next_tick(const Data *d)
{
    return tick_time(d, d->m.k_next);
}

/* The step from t (stop: TICK_*, model_me.h): up to the first tick inside it where stop asks
 * (*reached: where it stopped), else to t + h sampling inside as model_step does; a tick at the
 * step's end is left for Event Mode. TICK_RESUME: the tick at t was offered to the intermediate
 * update and not taken as an event, so it is sampled here, inside the step (on the inputs of its
 * start, counted as held, as model_step counts it); else a sample due at t was left to Event
 * Mode and not taken there: refused. TICK_UPDATE bounds the whole step by max_samples_per_step
 * as model_step does (the callback may let every tick pass). */
int model_step_to_tick(Data *d, double t, double h, int stop, double *reached, char *msg)
{
    const double tol = TIME_TOL * d->r[VR_sample_period];
    const int n_max = d->i[VR_max_samples_per_step];
    const int resume = (stop & TICK_RESUME) && model_next_tick(d) <= t + tol;
    const double tick = tick_time(d, d->m.k_next + resume);
    char buf[32];
    if (!resume && model_next_tick(d) <= t + tol) {
        py_float_repr(model_next_tick(d), buf, sizeof buf);
        return fail(msg, "the sample due at t=%s was not taken: fmi3EnterEventMode and "
                         "fmi3UpdateDiscreteStates first (eventHandlingNeeded)", buf);
    }
    if ((stop & TICK_UPDATE) && tick_time(d, d->m.k_next + n_max) < t + h - tol) {
        py_float_repr(h, buf, sizeof buf);
        return fail(msg, "a communication step of %s s would take more than %d samples "
                         "(parameter max_samples_per_step): take a smaller step", buf, n_max);
    }
    if (!(stop & (TICK_EARLY | TICK_UPDATE)) || !(tick < t + h - tol)) {
        *reached = t + h;
    } else {
        *reached = tick; /* no sample at the tick: it is this model step's end */
    }
    if (model_step(d, t, *reached - t, msg)) {
        return 1;
    }
    d->m.held_input_samples += resume;
    d->m.t = *reached;
    return 0;
}
