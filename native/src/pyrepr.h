/* Python's repr() in C, for messages that read exactly like the Python models' (the plant, the
 * controller and the integrator quote numbers and names in their errors). */
#ifndef PYREPR_H
#define PYREPR_H

#include <stddef.h>

#define PY_REPR_STR_MAX 256 /* the longest str py_str_repr quotes whole */

/* repr(x): the shortest digits that round-trip, fixed notation for 1e-4 <= |x| < 1e16 (with a
 * ".0" when integral), else d.ddde+XX; "inf", "-inf", "nan" */
void py_float_repr(double x, char *buf, size_t size);
/* repr(s) of a str of at most max_len characters (ASCII escapes; other bytes as they are) */
void py_str_repr(const char *s, size_t max_len, char *buf, size_t size);

#endif
