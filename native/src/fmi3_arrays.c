/* The array edition's value references (fmi3_arrays.h): an array's value reference is its first
 * element's slot in the variable table, its elements the next slots. fmi3_values.c checks each
 * fmi3GetFloat64 / fmi3SetFloat64 call whole here (FMI 3.0: nValues counts the values of all the
 * variables, each array serialized in row-major order), then the scalar code does one call on
 * the slots, with its own checks. */
#include <stdlib.h>

#include "fmi3_arrays.h"

typedef struct {
    fmi3ValueReference vr; /* the array's value reference = its first element's slot */
    size_t size;
} Fmi3Array;

static const Fmi3Array ARRAYS[] = FMI3_ARRAYS;
#define N_ARRAYS (sizeof ARRAYS / sizeof ARRAYS[0])

/* The number of values of the variable vr: its array's size, 1 for a scalar, 0 for the second or
 * later element of an array (no variable of this edition); *array: the array's value reference. */
static size_t fmi3_values_of(fmi3ValueReference vr, fmi3ValueReference *array)
{
    for (size_t k = 0; k < N_ARRAYS; k++) {
        if (vr >= ARRAYS[k].vr && vr - ARRAYS[k].vr < ARRAYS[k].size) {
            *array = ARRAYS[k].vr;
            return vr == ARRAYS[k].vr ? ARRAYS[k].size : 0;
        }
    }
    *array = vr;
    return 1;
}

/* The number of values of vr[0..nvr), or 0 after logging an element's value reference. */
static size_t fmi3_count_values(Wrapper *w, const fmi3ValueReference vr[], size_t nvr,
                                const char *function)
{
    size_t total = 0;
    for (size_t k = 0; k < nvr; k++) {
        fmi3ValueReference array;
        size_t n = fmi3_values_of(vr[k], &array);
        if (n == 0) {
            log_message(w->inner, fmi2Error, "logStatusError",
                        "%s: value reference %u is an element of the array variable %u, not a "
                        "variable of this FMU", function, (unsigned)vr[k], (unsigned)array);
            return 0;
        }
        total += n;
    }
    return total;
}

fmi3ValueReference *fmi3_array_slots(Wrapper *w, const fmi3ValueReference vr[], size_t nvr,
                                     const void *values, size_t nValues, const char *function)
{
    fmi3ValueReference *slots;
    size_t total;
    if (nvr > 0 && (!vr || !values)) {
        log_message(w->inner, fmi2Error, "logStatusError", "%s: NULL array", function);
        return NULL;
    }
    total = fmi3_count_values(w, vr, nvr, function);
    if (total == 0 && nvr > 0) {
        return NULL;
    }
    if (total != nValues) {
        log_message(w->inner, fmi2Error, "logStatusError",
                    "%s: %lu values for %lu value references whose variables hold %lu values "
                    "(an array counts its elements)", function, (unsigned long)nValues,
                    (unsigned long)nvr, (unsigned long)total);
        return NULL;
    }
    slots = (fmi3ValueReference *)malloc((total + 1) * sizeof *slots);
    if (!slots) {
        log_message(w->inner, fmi2Error, "logStatusError", "%s: out of memory", function);
        return NULL;
    }
    total = 0;
    for (size_t k = 0; k < nvr; k++) {
        fmi3ValueReference array;
        size_t n = fmi3_values_of(vr[k], &array);
        for (size_t j = 0; j < n; j++) {
            slots[total++] = vr[k] + (fmi3ValueReference)j;
        }
    }
    return slots;
}
