/* The wall: see wall.h. */
#include "wall.h"

double wall_force(const Wall *w, double x, double xd)
{
    const double pen = x - w->x;
    double force;
    if (pen <= 0.0) {
        return 0.0;
    }
    force = w->k * pen + w->d * xd;
    return force > 0.0 ? force : 0.0;
}

double wall_contact_force_law(const Wall *w, double x, double xd)
{
    return w->k * (x - w->x) + w->d * xd;
}

double wall_contact_event(const Wall *w, double x, double xd, int in_contact)
{
    const double force = wall_contact_force_law(w, x, xd);
    const double closing = w->k * (x - w->x);
    if (in_contact) {
        return -force;
    }
    return force < closing ? force : closing; /* Python min(closing, force) */
}
