/* State of the native ImpedanceController: what controller_model/model.py keeps on self between
 * doStep calls, as plain data (the glue copies it with the rest of Data for FMU states).
 * The outputs (ControllerModel.out) live in Data.r[VR_tau1 .. VR_e_phi]; the parameters are read
 * from Data.r / Data.i / Data.s, which cannot change after initialization. */
#ifndef MODEL_H
#define MODEL_H

#include <stdint.h>

/* velocity_source, parsed once by model_initialize (ControllerModel's VELOCITY_SOURCES) */
enum { SOURCE_OBSERVER = 0, SOURCE_DIFFERENCE = 1, SOURCE_MEASURED = 2 };

typedef struct {
    double t;                   /* communication time reached (self.t) */
    double start_time;          /* t_k = start_time + k * sample_period */
    int64_t k_next;             /* next sample to process */
    int64_t held_input_samples; /* samples taken strictly inside a step, on held inputs */
    double yhat[3];             /* observer state of the latest sample */
    double q_prev[3];           /* angles, applied (clipped) torque and wrist force of the */
    double tau_prev[3];         /* latest sample, for the next observer update */
    double f_prev[3];
    int32_t velocity_source;    /* SOURCE_* */
    int32_t pad;
} ModelState;

#endif
