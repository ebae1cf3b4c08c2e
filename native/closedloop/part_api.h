/* The body of a part's translation unit (plant_part.c, controller_part.c): defines PART_PREFIX
 * and the part's headers, then includes this file. It renames the part's model functions (so the
 * two parts and the closed loop link into one library), compiles the part's model.c unchanged
 * and implements the parts.h functions on the part's own Data. */
#include <math.h>
#include <string.h>

#include "parts.h"

#define PART_CAT2(a, b) a##_##b
#define PART_CAT(a, b) PART_CAT2(a, b)
#define PART(name) PART_CAT(PART_PREFIX, name)

#define model_initialize PART(model_initialize)
#define model_step PART(model_step)
#define model_step_early PART(model_step_early)
#define model_check_tunable PART(model_check_tunable)
#define model_check_state PART(model_check_state)
#define MODEL_STATE_REALS PART(MODEL_STATE_REALS)
#define N_MODEL_STATE_REALS PART(N_MODEL_STATE_REALS)

#include PART_MODEL_SOURCE /* the part's model.c, as shipped in its own FMU */

typedef char part_data_fits[sizeof(Data) <= sizeof(PartData) ? 1 : -1];

#define AS_DATA(d) ((Data *)(void *)(d)->bytes)
#define AS_CDATA(d) ((const Data *)(const void *)(d)->bytes)

/* The part's start values, as its own FMU's fmi2Instantiate sets them. */
void PART(part_start)(PartData *p, double start_time)
{
    memset(p, 0, sizeof *p);
    data_start(AS_DATA(p), start_time);
}

void PART(part_set_real)(PartData *p, int vr, double value) { AS_DATA(p)->r[vr] = value; }
void PART(part_set_int)(PartData *p, int vr, int value) { AS_DATA(p)->i[vr] = value; }
double PART(part_get_real)(const PartData *p, int vr) { return AS_CDATA(p)->r[vr]; }

void PART(part_set_string)(PartData *p, int vr, const char *value)
{
    memset(AS_DATA(p)->s[vr], 0, STRING_MAX);
    strncpy(AS_DATA(p)->s[vr], value, STRING_MAX - 1);
}

int PART(part_initialize)(PartData *p, char *msg) { return model_initialize(AS_DATA(p), msg); }

int PART(part_step)(PartData *p, double t, double h, char *msg)
{
    return model_step(AS_DATA(p), t, h, msg);
}

int PART(part_check_tunable)(const PartData *p, char *msg)
{
    return model_check_tunable(AS_CDATA(p), msg);
}

/* A part's state from outside (a deserialized closed-loop state): its reals finite, then its
 * model's own checks, as the part's glue does for its own FMU's states. */
int PART(part_check_state)(const PartData *p, char *msg)
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
