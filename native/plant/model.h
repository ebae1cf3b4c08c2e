/* State of the native PumaPlant: what plant_model/model.py's PlantModel keeps on self between
 * doStep calls, as plain data (the glue copies it with the rest of Data for FMU states).
 * The outputs (PlantModel.outputs()) live in Data.r[VR_q1 .. VR_penetration]; the parameters are
 * read from Data.r / Data.i, which cannot change after initialization. */
#ifndef MODEL_H
#define MODEL_H

#include <stdint.h>

#include "pyrandom.h"

typedef struct {
    double t;           /* communication time reached (self.t) */
    double q[3];        /* joint angles (self.q) */
    double qd[3];       /* joint velocities (self.qd) */
    double h;           /* the integrator's next step-size guess (self.h) */
    double q_meas[3];   /* encoder readings at t (self.q_meas) */
    int32_t in_contact; /* contact mode (self.in_contact) */
    int32_t pad;
    PyRandom rng;       /* the sensor-noise generator (self.rng), seeded with noise_seed */
} ModelState;

#endif
