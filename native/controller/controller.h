/* What the native ImpedanceController's two files share: model.c (the controller: observer,
 * impedance law, sampling) and model_me.c (its Model Exchange side, a sample at each time
 * event). Prefixed controller_, so that the closed-loop FMU, which links the plant's and the
 * controller's model.c into one library, has no two functions of one name. */
#ifndef CONTROLLER_H
#define CONTROLLER_H

#include <stdint.h>

#include "arm.h"
#include "glue.h"

#define TIME_TOL 1e-9 /* sample-time comparisons, relative to the sample period */

enum { OBS_EULER = 0, OBS_IMPLICIT = 1, OBS_EXPONENTIAL = 2 };

typedef struct {
    ArmParams arm; /* the controller's own model of the arm */
    double traj_cx, traj_cy, traj_ax, traj_ay, traj_f, traj_phi, wall_x, wall_depth;
    double K[3], G[3], B[3], yhat0[3], tau_max[3];
    double ts;
    int limit_torque;
    int discretization; /* OBS_*, -1 if unknown (refused by model_initialize) */
} Params;

void controller_read_params(const Data *d, Params *p);
/* the inputs q, f (and the measured velocities, source "measured") out of d, checked finite */
int controller_split_inputs(const Data *d, double q[3], double f[3], double qd_meas[3], char *msg);
/* sample k: observer, impedance law (law: which), outputs written into d */
int controller_take_sample(Data *d, const Params *p, int64_t k, const double q[3],
                           const double f[3], const double qd_meas[3], int law, char *msg);
/* model_me.c, for FMI 3.0 Co-Simulation with event mode: the next sample's time, and the step
 * that stops at a tick (fmi3_wrapper.h declares both for the glue; model_me.h the TICK_* flags) */
double model_next_tick(const Data *d);
int model_step_to_tick(Data *d, double t, double h, int stop, double *reached, char *msg);

#endif
