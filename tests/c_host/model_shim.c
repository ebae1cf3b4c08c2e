/* Test shim of the native model tests (tests/test_native_plant_model.py,
 * tests/test_native_controller_model.py): a model's model.c driven through ctypes without the FMI
 * layer (linked with native/src/fail.c): ctypes access to Data, and steps as the glue does (on
 * a copy, kept only on success). Compiled with one model's config.h. */
#include <string.h>

#include "glue.h"

size_t data_size(void) { return sizeof(Data); }
size_t state_size(void) { return sizeof(ModelState); }
int n_vars(void) { return N_VARS; }
const char *var_name(int vr) { return VARS[vr].name; }
double var_start(int vr) { return VARS[vr].start; }
double *data_r(Data *d) { return d->r; }
int *data_i(Data *d) { return d->i; }

void data_init(Data *d, double start_time) { data_start(d, start_time); }

void data_set_string(Data *d, int vr, const char *s)
{
    memset(d->s[vr], 0, STRING_MAX);
    strncpy(d->s[vr], s, STRING_MAX - 1);
}

int data_initialize(Data *d, char *msg)
{
    Data tmp = *d;
    if (model_initialize(&tmp, msg)) {
        return 1;
    }
    *d = tmp;
    return 0;
}

int data_step(Data *d, double t, double h, char *msg)
{
    Data tmp = *d;
    if (model_step(&tmp, t, h, msg)) {
        return 1;
    }
    *d = tmp;
    return 0;
}
