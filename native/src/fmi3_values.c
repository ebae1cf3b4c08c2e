/* The FMI 3.0 getters and setters of every native model (see fmi3_glue.c), over the instance
 * core's (instance_values.c): every variable is a scalar, so nValues must equal the number of
 * value references; Int64 (the enumerations) and fmi3Boolean arrays are converted; the value
 * references past the variable table are FMI 3.0's own: time (VR_TIME, read-only) and the event
 * indicators (read-only locals). Types without variables here: fmi3_stubs.c. In the array
 * edition (FMI3_ARRAYS, fmi3_arrays.c) a Float64 array's value reference stands for its elements.
 */
#include <stdlib.h>

#include "fmi3_wrapper.h" /* Wrapper, WRAP, FAIL */
#ifdef FMI3_ARRAYS
#include "fmi3_arrays.h" /* fmi3_array_slots */
#endif

/* --- getters and setters ---------------------------------------------------------------------- */

/* Every variable is a scalar: nValues must equal nValueReferences; arrays may be NULL only when
 * empty. 1 if the call is well formed, else 0 after logging why. */
static int well_formed(Wrapper *w, const fmi3ValueReference vr[], size_t nvr, const void *values,
                       size_t nValues, const char *function)
{
    if (nValues != nvr) {
        log_message(w->inner, fmi2Error, "logStatusError",
                    "%s: %lu values for %lu value references (every variable is a scalar)",
                    function, (unsigned long)nValues, (unsigned long)nvr);
        return 0;
    }
    if (nvr > 0 && (!vr || !values)) {
        log_message(w->inner, fmi2Error, "logStatusError", "%s: NULL array", function);
        return 0;
    }
    return 1;
}

/* Value references past the FMI 2 table: time (VR_TIME), then the event indicators (Float64
 * locals from VR_INDICATOR on) or the clock (VR_CLOCK). */
static int mentions_extra(const fmi3ValueReference vr[], size_t nvr)
{
    for (size_t k = 0; k < nvr; k++) {
        if (vr[k] >= N_VARS) {
            return 1;
        }
    }
    return 0;
}

/* An FMI 3 Float64 past the FMI 2 table (1 with the value, or 0 if vr is none of them). */
static fmi3Status get_extra(Wrapper *w, fmi3ValueReference vr, double *value)
{
    if (vr == VR_TIME) {
        *value = w->inner->s.last_time; /* start time, the last step's end, or fmi3SetTime */
        return fmi3OK;
    }
#if N_EVENT_INDICATORS > 0
    if (vr >= VR_INDICATOR && vr < VR_INDICATOR + N_EVENT_INDICATORS) {
        double z[N_EVENT_INDICATORS];
        if (model_me_event_indicators(&w->inner->s.d, z, w->inner->msg)) {
            return FAIL(w, "%s", w->inner->msg);
        }
        *value = z[vr - VR_INDICATOR];
        return fmi3OK;
    }
#endif
    return FAIL(w, "value reference %u is not a Float64 variable of this FMU", (unsigned)vr);
}

/* fmi3GetFloat64 of nvr scalar variables, the call checked. */
static fmi3Status get_float64(Wrapper *w, const fmi3ValueReference vr[], size_t nvr,
                              fmi3Float64 values[])
{
    if (!mentions_extra(vr, nvr)) {
        return status3(instance_get_real(w->inner, (const fmi2ValueReference *)vr, nvr, values));
    }
    for (size_t k = 0; k < nvr; k++) {
        fmi3Status s;
        if (vr[k] >= N_VARS) {
            s = get_extra(w, vr[k], &values[k]);
        } else {
            s = status3(instance_get_real(w->inner, (const fmi2ValueReference *)&vr[k], 1,
                                          &values[k]));
        }
        if (s != fmi3OK) {
            return s;
        }
    }
    return fmi3OK;
}

/* fmi3SetFloat64 of nvr scalar variables, the call checked. */
static fmi3Status set_float64(Wrapper *w, const fmi3ValueReference vr[], size_t nvr,
                              const fmi3Float64 values[])
{
    for (size_t k = 0; k < nvr; k++) {
        if (vr[k] == VR_TIME) {
            return FAIL(w, "time is the independent variable: it cannot be set (fmi3SetTime "
                           "does that under Model Exchange)");
        }
        if (vr[k] >= N_VARS) {
            return FAIL(w, "variable %u is computed by the model: it cannot be set",
                        (unsigned)vr[k]);
        }
    }
    return status3(instance_set_real(w->inner, (const fmi2ValueReference *)vr, nvr, values));
}

/* fmi3Get/SetFloat64 (set: values are the setter's, read only) over the scalar variables; in the
 * array edition the arrays' value references become their elements' first (checked whole). */
static fmi3Status float64_call(Wrapper *w, const fmi3ValueReference vr[], size_t nvr,
                               fmi3Float64 values[], size_t nValues, int set,
                               const char *function)
{
#ifdef FMI3_ARRAYS
    fmi3ValueReference *slots = fmi3_array_slots(w, vr, nvr, values, nValues, function);
    fmi3Status s = !slots ? fmi3Error
                   : set  ? set_float64(w, slots, nValues, values)
                          : get_float64(w, slots, nValues, values);
    free(slots);
    return s;
#else
    if (!well_formed(w, vr, nvr, values, nValues, function)) {
        return fmi3Error;
    }
    return set ? set_float64(w, vr, nvr, values) : get_float64(w, vr, nvr, values);
#endif
}

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, fmi3Float64 values[], size_t nValues)
{
    WRAP(fmi3GetFloat64);
    return float64_call(w, valueReferences, nValueReferences, values, nValues, 0,
                        "fmi3GetFloat64");
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, const fmi3Float64 values[], size_t nValues)
{
    WRAP(fmi3SetFloat64);
    return float64_call(w, valueReferences, nValueReferences, (fmi3Float64 *)values, nValues, 1,
                        "fmi3SetFloat64");
}

/* The FMI 3 types the core stores as int (Int32, Int64: the enumerations, Boolean) or as text. */
typedef enum { F_INT32, F_INT64, F_BOOLEAN, F_STRING } Form;

/* The getters but Float64: the core's values of the form, converted element by element. */
static fmi3Status get_values(Wrapper *w, const fmi3ValueReference vr[], size_t nvr, void *values,
                             Form form)
{
    const fmi2ValueReference *vr2 = (const fmi2ValueReference *)vr;
    fmi2Integer *buf;
    fmi2Status s;
    if (form == F_STRING) {
        return status3(instance_get_string(w->inner, vr2, nvr, (fmi2String *)values));
    }
    buf = (fmi2Integer *)malloc((nvr ? nvr : 1) * sizeof *buf);
    if (!buf) {
        return FAIL(w, "out of memory");
    }
    s = form == F_BOOLEAN ? instance_get_boolean(w->inner, vr2, nvr, buf)
                          : instance_get_integer(w->inner, vr2, nvr, buf);
    for (size_t k = 0; s == fmi2OK && k < nvr; k++) {
        if (form == F_INT32) {
            ((fmi3Int32 *)values)[k] = buf[k];
        } else if (form == F_INT64) {
            ((fmi3Int64 *)values)[k] = buf[k];
        } else {
            ((fmi3Boolean *)values)[k] = buf[k] != fmi2False;
        }
    }
    free(buf);
    return status3(s);
}

/* The setters but Float64: the values converted to the core's form (an Int64 beyond the model's
 * 32 bits refused), then set together. */
static fmi3Status set_values(Wrapper *w, const fmi3ValueReference vr[], size_t nvr,
                             const void *values, Form form)
{
    const fmi2ValueReference *vr2 = (const fmi2ValueReference *)vr;
    fmi2Integer *buf;
    fmi2Status s;
    if (form == F_STRING) {
        return status3(instance_set_string(w->inner, vr2, nvr, (const fmi2String *)values));
    }
    for (size_t k = 0; form == F_INT64 && k < nvr; k++) {
        const fmi3Int64 v = ((const fmi3Int64 *)values)[k];
        if (v < -2147483647 - 1 || v > 2147483647) {
            return FAIL(w, "fmi3SetInt64: value %lld is beyond the 32-bit range of this FMU",
                        (long long)v);
        }
    }
    buf = (fmi2Integer *)malloc((nvr ? nvr : 1) * sizeof *buf);
    if (!buf) {
        return FAIL(w, "out of memory");
    }
    for (size_t k = 0; k < nvr; k++) {
        buf[k] = form == F_INT32   ? ((const fmi3Int32 *)values)[k]
                 : form == F_INT64 ? (fmi2Integer)((const fmi3Int64 *)values)[k]
                                   : (((const fmi3Boolean *)values)[k] ? fmi2True : fmi2False);
    }
    s = form == F_BOOLEAN ? instance_set_boolean(w->inner, vr2, nvr, buf)
                          : instance_set_integer(w->inner, vr2, nvr, buf);
    free(buf);
    return status3(s);
}

/* The getters and setters but Float64, one line each: legal, well formed, then the core's. */
#define VALUES3(function, ctype, access, form)                                                     \
    fmi3Status function(fmi3Instance instance, const fmi3ValueReference valueReferences[],     \
                        size_t nValueReferences, ctype values[], size_t nValues)               \
    {                                                                                          \
        WRAP(function);                                                                        \
        if (!well_formed(w, valueReferences, nValueReferences, values, nValues, #function)) {  \
            return fmi3Error;                                                                  \
        }                                                                                      \
        return access(w, valueReferences, nValueReferences, values, form);                     \
    }

VALUES3(fmi3GetInt32, fmi3Int32, get_values, F_INT32)
VALUES3(fmi3SetInt32, const fmi3Int32, set_values, F_INT32)
VALUES3(fmi3GetInt64, fmi3Int64, get_values, F_INT64) /* the enumerations */
VALUES3(fmi3SetInt64, const fmi3Int64, set_values, F_INT64)
VALUES3(fmi3GetBoolean, fmi3Boolean, get_values, F_BOOLEAN)
VALUES3(fmi3SetBoolean, const fmi3Boolean, set_values, F_BOOLEAN)
VALUES3(fmi3GetString, fmi3String, get_values, F_STRING)
VALUES3(fmi3SetString, const fmi3String, set_values, F_STRING)
