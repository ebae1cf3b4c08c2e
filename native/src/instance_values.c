/* The instance core's getters and setters (see instance.c): fmi2Get/SetReal and the FMI 3.0
 * getters and setters over them. Every call is checked whole before anything changes: known value
 * references of the right type, no output or computed variable set, parameters only while they may
 * be (FMI 2.0: before initialization ends, tunable ones between steps or in Event Mode), finite
 * inputs, parameters that pass check_parameter and, when tunable, the model's own check.
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "fmi2Functions.h"
#include "glue.h"
#include "instance.h"

/* --- getters and setters ---------------------------------------------------------------------- */

static fmi2Status check_access(Instance *inst, const fmi2ValueReference vr[], size_t nvr,
                               const void *value, VarType type, int setting)
{
    if (nvr > 0 && (!vr || !value)) {
        return ERROR(inst, "value reference or value array is NULL");
    }
    for (size_t k = 0; k < nvr; k++) {
        if (vr[k] >= N_VARS) {
            return ERROR(inst, "unknown value reference %u", (unsigned)vr[k]);
        }
        if (VARS[vr[k]].type != type) {
            return ERROR(inst, "variable %s is not of type %s", VARS[vr[k]].name,
                         inst->type_names[type]);
        }
        if (setting) {
            const VarInfo *v = &VARS[vr[k]];
            if (v->causality == C_OUTPUT) {
                return ERROR(inst, "variable %s is an output: it cannot be set", v->name);
            }
            if (v->causality == C_LOCAL) {
                return ERROR(inst, "variable %s is computed by the model: it cannot be set",
                             v->name);
            }
            /* FMI 2.0: after initialization only tunable parameters may be set, between
             * steps (co-simulation) or in Event Mode (Model Exchange) */
            if (v->causality == C_PARAMETER && inst->s.phase > S_INITIALIZATION &&
                !(v->tunable &&
                  (inst->s.phase == S_STEP_COMPLETE || inst->s.phase == S_EVENT_MODE))) {
                return ERROR(inst, "parameter %s is fixed: it cannot be set after initialization",
                             v->name);
            }
        }
    }
    if (!setting && inst->s.dirty && inst->s.phase == S_INITIALIZATION && initialize(inst)) {
        return ERROR(inst, "%s", inst->msg);
    }
    if (!setting && inst->type == fmi2ModelExchange && inst->s.phase > S_INITIALIZATION) {
        return me_update(inst);
    }
    return fmi2OK;
}

static int sets_parameter(const fmi2ValueReference vr[], size_t nvr)
{
    for (size_t k = 0; k < nvr; k++) {
        if (VARS[vr[k]].causality == C_PARAMETER) {
            return 1;
        }
    }
    return 0;
}

static void mark_dirty(Instance *inst)
{
    if (inst->s.phase <= S_INITIALIZATION || inst->type == fmi2ModelExchange) {
        inst->s.dirty = 1;
    }
}

/* The four getters differ only in their type and in how a stored value is read. */
#define GETTER(function, ctype, var_type, stored)                                                 \
    fmi2Status function(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,             \
                        ctype value[])                                                          \
    {                                                                                           \
        Instance *inst = (Instance *)c;                                                         \
        fmi2Status status = check_access(inst, vr, nvr, value, var_type, 0);                    \
        for (size_t k = 0; status == fmi2OK && k < nvr; k++) {                                  \
            value[k] = stored;                                                                  \
        }                                                                                       \
        return status;                                                                          \
    }

GETTER(instance_get_real, fmi2Real, T_REAL, inst->s.d.r[vr[k]])
GETTER(instance_get_integer, fmi2Integer, T_INTEGER, inst->s.d.i[vr[k]])
GETTER(instance_get_boolean, fmi2Boolean, T_BOOLEAN, inst->s.d.i[vr[k]] ? fmi2True : fmi2False)
GETTER(instance_get_string, fmi2String, T_STRING, inst->s.d.s[vr[k]])

/* value[k] of a setter's array, of the given type, written into d (the instance's or a copy). */
static void store(Data *d, fmi2ValueReference vr, const void *value, VarType type, size_t k)
{
    switch (type) {
    case T_REAL:
        d->r[vr] = ((const fmi2Real *)value)[k];
        break;
    case T_INTEGER:
        d->i[vr] = ((const fmi2Integer *)value)[k];
        break;
    case T_BOOLEAN:
        d->i[vr] = ((const fmi2Boolean *)value)[k] ? 1 : 0;
        break;
    case T_STRING:
        memset(d->s[vr], 0, STRING_MAX);
        strcpy(d->s[vr], ((const fmi2String *)value)[k]);
        break;
    }
}

/* A setter's values, all checked before anything changes: strings present and short enough,
 * inputs finite, parameters that pass check_parameter and, after initialization (tunable ones),
 * the model's own check of the new values together. */
static fmi2Status check_values(Instance *inst, const fmi2ValueReference vr[], size_t nvr,
                               const void *value, VarType type)
{
    for (size_t k = 0; k < nvr; k++) {
        const VarInfo *v = &VARS[vr[k]];
        if (type == T_STRING) {
            const char *text = ((const fmi2String *)value)[k];
            if (!text || strlen(text) >= STRING_MAX) {
                return ERROR(inst, "string value for %s is NULL or longer than %d characters",
                             v->name, STRING_MAX - 1);
            }
            continue;
        }
        double x = type == T_REAL      ? ((const fmi2Real *)value)[k]
                   : type == T_INTEGER ? ((const fmi2Integer *)value)[k]
                                       : ((const fmi2Boolean *)value)[k] != fmi2False;
        if (v->causality == C_INPUT && !isfinite(x)) {
            return ERROR(inst, "input %s is not finite (%g)", v->name, x);
        }
        if (v->causality == C_PARAMETER && check_parameter((int)vr[k], x, inst->msg)) {
            return ERROR(inst, "%s", inst->msg);
        }
    }
    if (inst->s.phase > S_INITIALIZATION && sets_parameter(vr, nvr)) {
        Data tmp = inst->s.d;
        for (size_t k = 0; k < nvr; k++) {
            store(&tmp, vr[k], value, type, k);
        }
        if (model_check_tunable(&tmp, inst->msg)) {
            return ERROR(inst, "%s", inst->msg);
        }
    }
    return fmi2OK;
}

static fmi2Status set_values(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                             const void *value, VarType type)
{
    Instance *inst = (Instance *)c;
    fmi2Status status = check_access(inst, vr, nvr, value, type, 1);
    if (status == fmi2OK) {
        status = check_values(inst, vr, nvr, value, type);
    }
    if (status != fmi2OK) {
        return status;
    }
    for (size_t k = 0; k < nvr; k++) {
        store(&inst->s.d, vr[k], value, type, k);
    }
    mark_dirty(inst);
    return fmi2OK;
}

#define SETTER(function, ctype, var_type)                                                        \
    fmi2Status function(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,             \
                        const ctype value[])                                                    \
    {                                                                                           \
        return set_values(c, vr, nvr, value, var_type);                                         \
    }

SETTER(instance_set_real, fmi2Real, T_REAL)
SETTER(instance_set_integer, fmi2Integer, T_INTEGER)
SETTER(instance_set_boolean, fmi2Boolean, T_BOOLEAN)
SETTER(instance_set_string, fmi2String, T_STRING)
