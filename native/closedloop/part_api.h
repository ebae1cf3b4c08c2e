/* The body of a part's translation unit (plant_part.c, controller_part.c): defines PART_TABLE
 * (the part's name in parts.h) and the part's headers, then includes this file. It compiles the
 * part's model.c unchanged with its model API static (MODEL_LINKAGE), so the two parts and the
 * closed loop link into one library, and gives the closed loop the part's Part table: the same
 * functions for both parts, on each part's own Data. */
#include <math.h>
#include <string.h>

#include "parts.h"

#define MODEL_LINKAGE static
#include PART_MODEL_SOURCE /* the part's model.c, as shipped in its own FMU */

typedef char part_data_fits[sizeof(Data) <= sizeof(PartData) ? 1 : -1];

#define AS_DATA(d) ((Data *)(void *)(d)->bytes)
#define AS_CDATA(d) ((const Data *)(const void *)(d)->bytes)

/* The part's start values, as its own FMU's fmi2Instantiate sets them. */
static void part_start(PartData *p, double start_time)
{
    memset(p, 0, sizeof *p);
    data_start(AS_DATA(p), start_time);
}

static void part_set_real(PartData *p, int vr, double value) { AS_DATA(p)->r[vr] = value; }
static void part_set_int(PartData *p, int vr, int value) { AS_DATA(p)->i[vr] = value; }
static double part_get_real(const PartData *p, int vr) { return AS_CDATA(p)->r[vr]; }

static void part_set_string(PartData *p, int vr, const char *value)
{
    memset(AS_DATA(p)->s[vr], 0, STRING_MAX);
    strncpy(AS_DATA(p)->s[vr], value, STRING_MAX - 1);
}

static int part_initialize(PartData *p, char *msg) { return model_initialize(AS_DATA(p), msg); }

static int part_step(PartData *p, double t, double h, char *msg)
{
    return model_step(AS_DATA(p), t, h, msg);
}

static int part_check_tunable(const PartData *p, char *msg)
{
    return model_check_tunable(AS_CDATA(p), msg);
}

/* A part's state from outside (a deserialized closed-loop state): its reals finite, then its
 * model's own checks, as the part's glue does for its own FMU's states. */
static int part_check_state(const PartData *p, char *msg)
{
    const Data *d = AS_CDATA(p);
    if (!isfinite(d->start_time)) {
        return fail(msg, "the start time is not finite");
    }
    for (int vr = 0; vr < N_VARS; vr++) {
        if (VARS[vr].type == T_REAL && !isfinite(d->r[vr])) {
            return fail(msg, "the value of %s is not finite", VARS[vr].name);
        }
        if (VARS[vr].type == T_STRING && !memchr(d->s[vr], '\0', STRING_MAX)) {
            return fail(msg, "string %s is not NUL-terminated", VARS[vr].name);
        }
    }
    for (int k = 0; k < N_MODEL_STATE_REALS; k++) {
        const StateReals *f = &MODEL_STATE_REALS[k];
        for (int j = 0; j < f->count; j++) {
            double x;
            memcpy(&x, (const char *)&d->m + f->offset + j * sizeof x, sizeof x);
            if (!isfinite(x)) {
                return fail(msg, "%s[%d] is not finite", f->name, j);
            }
        }
    }
    return model_check_state(d, msg);
}

const Part PART_TABLE = {part_start,      part_set_real, part_set_int,       part_set_string,
                         part_get_real,   part_initialize, part_step, part_check_tunable,
                         part_check_state};
