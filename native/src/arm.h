/* The hand-written part of the arm model shared by the native models, mirroring Arm in
 * impedance_cosim/physics/arm.py operation for operation (the generated terms are in arm_terms.h). */
#ifndef ARM_H
#define ARM_H

#include <math.h>

#include "arm_terms.h"
#include "linalg3.h"

/* Arm.forward_dynamics: qdd = H^-1 (tau - C qd - F qd - g), eq. (5); tau is the net joint torque.
 * Returns 1 (Python's ZeroDivisionError) when H is singular. */
static inline int arm_forward_dynamics(const ArmParams *p, const double q[3], const double qd[3],
                                       const double tau[3], double qdd[3])
{
    double c[9], cqd[3], grav[3], h[9], rhs[3];
    arm_coriolis(p, q, qd, c);
    matvec(c, qd, cqd);
    arm_gravity(p, q, grav);
    rhs[0] = tau[0] - cqd[0] - p->f1 * qd[0] - grav[0];
    rhs[1] = tau[1] - cqd[1] - p->f2 * qd[1] - grav[1];
    rhs[2] = tau[2] - cqd[2] - p->f3 * qd[2] - grav[2];
    arm_inertia(p, q, h);
    return solve3(h, rhs, qdd);
}

/* Arm.jacobian_det: det J = a1 a2 sin(q2). */
static inline double arm_jacobian_det(const ArmParams *p, const double q[3])
{
    return p->a1 * p->a2 * sin(q[1]);
}

#endif
