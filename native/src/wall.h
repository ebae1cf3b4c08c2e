/* The wall (impedance_cosim/physics/wall.py, operation for operation): a spring-damper at x that
 * only pushes, its contact force law, and the switching function of the contact mode. */
#ifndef WALL_H
#define WALL_H

typedef struct {
    double x, k, d; /* position [m], stiffness [N/m], damping [N s/m] */
} Wall;

/* the force on the end effector at x moving at xd: k pen + d xd while pushing, else 0 */
double wall_force(const Wall *w, double x, double xd);
/* k (x - wall x) + d xd, the law in contact whatever its sign */
double wall_contact_force_law(const Wall *w, double x, double xd);
/* positive where the contact mode must switch: closing while free, releasing in contact */
double wall_contact_event(const Wall *w, double x, double xd, int in_contact);

#endif
