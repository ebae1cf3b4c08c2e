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

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, fmi3Float64 values[], size_t nValues)
{
    WRAP(fmi3GetFloat64);
#ifdef FMI3_ARRAYS /* the arrays' value references become their elements' (checked whole) */
    fmi3ValueReference *slots = fmi3_array_slots(w, valueReferences, nValueReferences, values,
                                                 nValues, "fmi3GetFloat64");
    fmi3Status s = slots ? get_float64(w, slots, nValues, values) : fmi3Error;
    free(slots);
    return s;
#else
    if (!well_formed(w, valueReferences, nValueReferences, values, nValues, "fmi3GetFloat64")) {
        return fmi3Error;
    }
    return get_float64(w, valueReferences, nValueReferences, values);
#endif
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, const fmi3Float64 values[], size_t nValues)
{
    WRAP(fmi3SetFloat64);
#ifdef FMI3_ARRAYS /* the arrays' value references become their elements' (checked whole) */
    fmi3ValueReference *slots = fmi3_array_slots(w, valueReferences, nValueReferences, values,
                                                 nValues, "fmi3SetFloat64");
    fmi3Status s = slots ? set_float64(w, slots, nValues, values) : fmi3Error;
    free(slots);
    return s;
#else
    if (!well_formed(w, valueReferences, nValueReferences, values, nValues, "fmi3SetFloat64")) {
        return fmi3Error;
    }
    return set_float64(w, valueReferences, nValueReferences, values);
#endif
}

fmi3Status fmi3GetInt32(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, fmi3Int32 values[], size_t nValues)
{
    WRAP(fmi3GetInt32);
    if (!well_formed(w, valueReferences, nValueReferences, values, nValues, "fmi3GetInt32")) {
        return fmi3Error;
    }
    return status3(instance_get_integer(w->inner, (const fmi2ValueReference *)valueReferences,
                             nValueReferences, (fmi2Integer *)values));
}

fmi3Status fmi3SetInt32(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, const fmi3Int32 values[], size_t nValues)
{
    WRAP(fmi3SetInt32);
    if (!well_formed(w, valueReferences, nValueReferences, values, nValues, "fmi3SetInt32")) {
        return fmi3Error;
    }
    return status3(instance_set_integer(w->inner, (const fmi2ValueReference *)valueReferences,
                             nValueReferences, (const fmi2Integer *)values));
}

/* Enumerations are read and written as Int64 in FMI 3.0; the model stores them as integers. */
fmi3Status fmi3GetInt64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, fmi3Int64 values[], size_t nValues)
{
    fmi2Integer buf[64];
    WRAP(fmi3GetInt64);
    if (!well_formed(w, valueReferences, nValueReferences, values, nValues, "fmi3GetInt64")) {
        return fmi3Error;
    }
    for (size_t k = 0; k < nValueReferences; k += 64) {
        size_t n = nValueReferences - k < 64 ? nValueReferences - k : 64;
        fmi2Status s = instance_get_integer(w->inner, (const fmi2ValueReference *)valueReferences + k,
                                      n, buf);
        if (s != fmi2OK) {
            return status3(s);
        }
        for (size_t j = 0; j < n; j++) {
            values[k + j] = buf[j];
        }
    }
    return fmi3OK;
}

fmi3Status fmi3SetInt64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, const fmi3Int64 values[], size_t nValues)
{
    fmi2Integer *buf;
    fmi2Status s;
    WRAP(fmi3SetInt64);
    if (!well_formed(w, valueReferences, nValueReferences, values, nValues, "fmi3SetInt64")) {
        return fmi3Error;
    }
    if (nValueReferences == 0) {
        return fmi3OK;
    }
    for (size_t k = 0; k < nValueReferences; k++) {
        if (values[k] < -2147483647 - 1 || values[k] > 2147483647) {
            return FAIL(w, "fmi3SetInt64: value %lld is beyond the 32-bit range of this FMU",
                        (long long)values[k]);
        }
    }
    buf = (fmi2Integer *)malloc(nValueReferences * sizeof *buf);
    if (!buf) {
        return FAIL(w, "out of memory");
    }
    for (size_t k = 0; k < nValueReferences; k++) {
        buf[k] = (fmi2Integer)values[k];
    }
    s = instance_set_integer(w->inner, (const fmi2ValueReference *)valueReferences, nValueReferences,
                       buf);
    free(buf);
    return status3(s);
}

fmi3Status fmi3GetBoolean(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, fmi3Boolean values[], size_t nValues)
{
    fmi2Boolean buf[64];
    WRAP(fmi3GetBoolean);
    if (!well_formed(w, valueReferences, nValueReferences, values, nValues, "fmi3GetBoolean")) {
        return fmi3Error;
    }
    for (size_t k = 0; k < nValueReferences; k += 64) {
        size_t n = nValueReferences - k < 64 ? nValueReferences - k : 64;
        fmi2Status s = instance_get_boolean(w->inner, (const fmi2ValueReference *)valueReferences + k,
                                      n, buf);
        if (s != fmi2OK) {
            return status3(s);
        }
        for (size_t j = 0; j < n; j++) {
            values[k + j] = buf[j] != fmi2False;
        }
    }
    return fmi3OK;
}

fmi3Status fmi3SetBoolean(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, const fmi3Boolean values[], size_t nValues)
{
    fmi2Boolean *buf;
    fmi2Status s;
    WRAP(fmi3SetBoolean);
    if (!well_formed(w, valueReferences, nValueReferences, values, nValues, "fmi3SetBoolean")) {
        return fmi3Error;
    }
    if (nValueReferences == 0) {
        return fmi3OK;
    }
    buf = (fmi2Boolean *)malloc(nValueReferences * sizeof *buf);
    if (!buf) {
        return FAIL(w, "out of memory");
    }
    for (size_t k = 0; k < nValueReferences; k++) {
        buf[k] = values[k] ? fmi2True : fmi2False;
    }
    s = instance_set_boolean(w->inner, (const fmi2ValueReference *)valueReferences, nValueReferences,
                       buf);
    free(buf);
    return status3(s);
}

fmi3Status fmi3GetString(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                         size_t nValueReferences, fmi3String values[], size_t nValues)
{
    WRAP(fmi3GetString);
    if (!well_formed(w, valueReferences, nValueReferences, values, nValues, "fmi3GetString")) {
        return fmi3Error;
    }
    return status3(instance_get_string(w->inner, (const fmi2ValueReference *)valueReferences,
                            nValueReferences, values));
}

fmi3Status fmi3SetString(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                         size_t nValueReferences, const fmi3String values[], size_t nValues)
{
    WRAP(fmi3SetString);
    if (!well_formed(w, valueReferences, nValueReferences, values, nValues, "fmi3SetString")) {
        return fmi3Error;
    }
    return status3(instance_set_string(w->inner, (const fmi2ValueReference *)valueReferences,
                            nValueReferences, values));
}
