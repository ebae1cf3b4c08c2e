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
    if (!instance_ok(inst, setting ? "a setter" : "a getter")) {
        return fmi2Error;
    }
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

fmi2Status instance_get_real(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                       fmi2Real value[])
{
    Instance *inst = (Instance *)c;
    fmi2Status status = check_access(inst, vr, nvr, value, T_REAL, 0);
    if (status != fmi2OK) {
        return status;
    }
    for (size_t k = 0; k < nvr; k++) {
        value[k] = inst->s.d.r[vr[k]];
    }
    return fmi2OK;
}

fmi2Status instance_get_integer(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Integer value[])
{
    Instance *inst = (Instance *)c;
    fmi2Status status = check_access(inst, vr, nvr, value, T_INTEGER, 0);
    if (status != fmi2OK) {
        return status;
    }
    for (size_t k = 0; k < nvr; k++) {
        value[k] = inst->s.d.i[vr[k]];
    }
    return fmi2OK;
}

fmi2Status instance_get_boolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Boolean value[])
{
    Instance *inst = (Instance *)c;
    fmi2Status status = check_access(inst, vr, nvr, value, T_BOOLEAN, 0);
    if (status != fmi2OK) {
        return status;
    }
    for (size_t k = 0; k < nvr; k++) {
        value[k] = inst->s.d.i[vr[k]] ? fmi2True : fmi2False;
    }
    return fmi2OK;
}

fmi2Status instance_get_string(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         fmi2String value[])
{
    Instance *inst = (Instance *)c;
    fmi2Status status = check_access(inst, vr, nvr, value, T_STRING, 0);
    if (status != fmi2OK) {
        return status;
    }
    for (size_t k = 0; k < nvr; k++) {
        value[k] = inst->s.d.s[vr[k]];
    }
    return fmi2OK;
}

fmi2Status instance_set_real(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                       const fmi2Real value[])
{
    Instance *inst = (Instance *)c;
    fmi2Status status = check_access(inst, vr, nvr, value, T_REAL, 1);
    if (status != fmi2OK) {
        return status;
    }
    for (size_t k = 0; k < nvr; k++) { /* check all before changing anything */
        const VarInfo *v = &VARS[vr[k]];
        if (v->causality == C_INPUT && !isfinite(value[k])) {
            return ERROR(inst, "input %s is not finite (%g)", v->name, value[k]);
        }
        if (v->causality == C_PARAMETER && check_parameter((int)vr[k], value[k], inst->msg)) {
            return ERROR(inst, "%s", inst->msg);
        }
    }
    if (inst->s.phase > S_INITIALIZATION && sets_parameter(vr, nvr)) {
        Data tmp = inst->s.d; /* tunable parameters: the model checks the new values */
        for (size_t k = 0; k < nvr; k++) {
            tmp.r[vr[k]] = value[k];
        }
        if (model_check_tunable(&tmp, inst->msg)) {
            return ERROR(inst, "%s", inst->msg);
        }
    }
    for (size_t k = 0; k < nvr; k++) {
        inst->s.d.r[vr[k]] = value[k];
    }
    mark_dirty(inst);
    return fmi2OK;
}

fmi2Status instance_set_integer(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Integer value[])
{
    Instance *inst = (Instance *)c;
    fmi2Status status = check_access(inst, vr, nvr, value, T_INTEGER, 1);
    if (status != fmi2OK) {
        return status;
    }
    for (size_t k = 0; k < nvr; k++) {
        if (VARS[vr[k]].causality == C_PARAMETER &&
            check_parameter((int)vr[k], value[k], inst->msg)) {
            return ERROR(inst, "%s", inst->msg);
        }
    }
    for (size_t k = 0; k < nvr; k++) {
        inst->s.d.i[vr[k]] = value[k];
    }
    mark_dirty(inst);
    return fmi2OK;
}

fmi2Status instance_set_boolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Boolean value[])
{
    Instance *inst = (Instance *)c;
    fmi2Status status = check_access(inst, vr, nvr, value, T_BOOLEAN, 1);
    if (status != fmi2OK) {
        return status;
    }
    for (size_t k = 0; k < nvr; k++) {
        inst->s.d.i[vr[k]] = value[k] ? 1 : 0;
    }
    mark_dirty(inst);
    return fmi2OK;
}

fmi2Status instance_set_string(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         const fmi2String value[])
{
    Instance *inst = (Instance *)c;
    fmi2Status status = check_access(inst, vr, nvr, value, T_STRING, 1);
    if (status != fmi2OK) {
        return status;
    }
    for (size_t k = 0; k < nvr; k++) {
        if (!value[k] || strlen(value[k]) >= STRING_MAX) {
            return ERROR(inst, "string value for %s is NULL or longer than %d characters",
                         VARS[vr[k]].name, STRING_MAX - 1);
        }
    }
    for (size_t k = 0; k < nvr; k++) {
        memset(inst->s.d.s[vr[k]], 0, STRING_MAX);
        strcpy(inst->s.d.s[vr[k]], value[k]);
    }
    mark_dirty(inst);
    return fmi2OK;
}
