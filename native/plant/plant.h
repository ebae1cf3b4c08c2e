/* What the native PumaPlant's two files share: model.c (the co-simulation model: wall, dynamics,
 * the step) and model_me.c (Model Exchange and the exact partial derivatives). Prefixed plant_,
 * so that the closed-loop FMU, which links the plant's and the controller's model.c into one
 * library, has no two functions of one name. */
#ifndef PLANT_H
#define PLANT_H

#include <stdint.h>

#include "arm.h"
#include "glue.h"
#include "ode.h"
#include "wall.h"

/* What the right-hand side and the event function need (PlantModel._rhs / _event closures). */
typedef struct {
    ArmParams arm;
    Wall wall;
    double tau[3];
    int in_contact;
    int64_t *budget; /* evaluations of eq. (1) left in this step (max_rhs_evaluations), or NULL
                        outside a co-simulation step (Model Exchange: one evaluation per call) */
    int max_evaluations;
} PlantCtx;

void plant_read_ctx(const Data *d, PlantCtx *c);
/* eq. (1) with the wall: the derivative of y = (q, qd) (ode.h's right-hand side) */
int plant_rhs(void *ctx, const double y[ODE_N], double out[ODE_N], char *err);
/* the switching function of the current contact mode (ode.h's event function) */
int plant_event(void *ctx, const double y[ODE_N], double *g, char *err);
int plant_ee_x(const ArmParams *a, const double q[3], const double qd[3], double *x, double *xd,
               char *err);
/* the outputs in d->r from the model state d->m */
void plant_write_outputs(Data *d);

#endif
