/* The FMI 3.0 array edition (fmus/fmi3/arrays/): the joint vectors as fixed-size Float64 arrays.
 * fmi3_config.h (written by the build, impedance_cosim/fmi/fmi3_arrays.py) defines FMI3_ARRAYS:
 * {value reference, size} of each array variable, whose elements are the consecutive slots of the
 * variable table from that value reference on. */
#ifndef FMI3_ARRAYS_H
#define FMI3_ARRAYS_H

#include <stddef.h>

#include "fmi3_wrapper.h" /* Wrapper */

/* The slots of the variables vr[0..nvr) in order, nValues of them (malloc'd: the caller frees),
 * or NULL after logging why the call is not well formed: a NULL array, a value reference that is
 * an array's second or later element, nValues other than the sum of the variables' sizes. */
fmi3ValueReference *fmi3_array_slots(Wrapper *w, const fmi3ValueReference vr[], size_t nvr,
                                     const void *values, size_t nValues, const char *function);

#endif
