/* The instance core of every native model, written once (see glue.h and instance.h): what the
 * FMI 2.0 glue (fmi2_glue.c) and the FMI 3.0 glue (fmi3_*.c) both call. Its messages name the
 * glue's entry point and types (Instance.fn, type_names). Here: the lifecycle and the step;
 * the getters and setters are in instance_values.c, the FMU state in instance_state.c.
 *
 * The phase follows the FMI 2.0 state machine (section 4.2.4): instantiated -> initialization
 * mode -> step complete -> terminated. Whether a call is legal in the phase is the glue's to
 * decide (fmi2_states.h, fmi3_states.h): the core makes the transitions its callers ask for.
 * Errors are always logged (whatever fmi2SetDebugLogging says); other messages only with logging
 * on. Parameter values are checked when set (finite, >= min) and again before initialization;
 * non-finite inputs are refused when set. A step that cannot be taken, or whose outputs would not
 * be finite, returns fmi2Discard and leaves the instance at the step's start;
 * fmi2GetBooleanStatus(fmi2Terminated) then says true, so that a master which can only retry the
 * same step (fmpy simulate) stops. A serialized FMU
 * state carries a CRC-32 over all its bytes and holds finite numbers only: anything else is
 * refused (fmi2Error, logged), and so is the state of another build (see SerialHeader).
 */
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "glue.h"
#include "guid.h" /* MODEL_GUID, written by the build */
#include "instance.h" /* Phase, Snapshot, Instance; the Model Exchange side is instance_me.c */
#include "pyrepr.h"

#define INSTANCE_MAGIC 0x494d5049u /* "IMPI" */

void log_message(Instance *inst, fmi2Status status, const char *category, const char *fmt, ...)
{
    char text[MSG_MAX + 64];
    va_list ap;
    if (!inst || !inst->cb.logger) {
        return;
    }
    if (status == fmi2OK && !inst->logging_on) {
        return;
    }
    char safe[2 * (MSG_MAX + 64)];
    size_t k = 0;
    va_start(ap, fmt);
    vsnprintf(text, sizeof text, fmt, ap);
    va_end(ap);
    /* The message itself, not "%s" + argument: many hosts (fmpy) ignore the variadic part. It is
     * still a format string to printf-style hosts, so '%' is doubled. */
    for (const char *p = text; *p && k + 2 < sizeof safe; p++) {
        if (*p == '%') {
            safe[k++] = '%';
        }
        safe[k++] = *p;
    }
    safe[k] = '\0';
    inst->cb.logger(inst->cb.componentEnvironment, inst->name, status, category, safe);
}

const char *const FMI2_TYPE_NAMES[] = {"Real", "Integer", "Boolean", "String"};
const char *const FMI3_TYPE_NAMES[] = {"Float64", "Int32", "Boolean", "String"};

void log_fn_error(Instance *inst, const char *fmt, ...)
{
    char text[MSG_MAX];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(text, sizeof text, fmt, ap);
    va_end(ap);
    log_message(inst, fmi2Error, "logStatusError", "%s: %s", inst->fn, text);
}

int instance_ok(const Instance *inst, const char *function)
{
    if (!inst) {
        fprintf(stderr, "%s: %s called with a NULL instance: refused\n", MODEL_IDENTIFIER_STR,
                function);
        return 0;
    }
    if (inst->magic != INSTANCE_MAGIC) {
        fprintf(stderr, "%s: %s called with a freed or foreign instance: refused\n",
                MODEL_IDENTIFIER_STR, function);
        return 0;
    }
    return 1;
}

/* A parameter value the model can accept at all: finite, and not below its minimum. */
int check_parameter(int vr, double value, char *msg)
{
    const VarInfo *v = &VARS[vr];
    if (v->type == T_REAL && !isfinite(value)) {
        return fail(msg, "parameter %s must be finite (got %g)", v->name, value);
    }
    if (v->has_min && value < v->min) {
        return fail(msg, "parameter %s must be >= %g (got %.17g)", v->name, v->min, value);
    }
    return 0;
}

/* Every real output finite: a step or an initialization whose numbers overflowed is refused, so a
 * host never reads a non-finite output after OK (a diverging loop stops at that step). 0 if all
 * are finite, else 1 with msg naming the first that is not. */
static int check_outputs(const Data *d, char *msg)
{
    for (int vr = 0; vr < N_VARS; vr++) {
        if (VARS[vr].type == T_REAL && VARS[vr].causality == C_OUTPUT && !isfinite(d->r[vr])) {
            char value[32];
            py_float_repr(d->r[vr], value, sizeof value); /* as the Python models say it */
            return fail(msg, "output %s is not finite (%s): the computation overflowed",
                        VARS[vr].name, value);
        }
    }
    return 0;
}

int initialize(Instance *inst)
{
    Data tmp = inst->s.d;
    for (int vr = 0; vr < N_VARS; vr++) {
        const VarInfo *v = &VARS[vr];
        if (v->causality != C_PARAMETER || v->type == T_STRING) {
            continue;
        }
        if (check_parameter(vr, v->type == T_REAL ? tmp.r[vr] : tmp.i[vr], inst->msg)) {
            return 1;
        }
    }
    inst->msg[0] = '\0';
    if (model_initialize(&tmp, inst->msg) || check_outputs(&tmp, inst->msg)) {
        return 1;
    }
    /* a message left by a successful model_initialize is a warning (e.g. the controller's
     * sample 0 at a singular pose): logged, and initialization goes on (status OK) */
    if (inst->msg[0] != '\0') {
        log_message(inst, fmi2Warning, "logStatusWarning", "%s", inst->msg);
        inst->msg[0] = '\0';
    }
    if (inst->type == fmi2ModelExchange && me_initialize(&tmp, inst->msg)) {
        return 1;
    }
    inst->s.d = tmp;
    inst->s.dirty = 0;
    return 0;
}

/* ---------------------------------------------------------------------------------------------- */

fmi2Component instance_new(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                              fmi2Boolean loggingOn)
{
    Instance *inst;
    (void)fmuResourceLocation;
    (void)visible;
    if (!functions || !functions->logger) {
        return NULL;
    }
    inst = (Instance *)calloc(1, sizeof(Instance));
    if (!inst) {
        functions->logger(functions->componentEnvironment, instanceName, fmi2Error,
                          "logStatusError", "%s", "out of memory");
        return NULL;
    }
    inst->magic = INSTANCE_MAGIC;
    inst->cb = *functions;
    strncpy(inst->name, instanceName ? instanceName : "", sizeof inst->name - 1);
    inst->logging_on = loggingOn;
    inst->type = fmuType;
    inst->fn = "fmi2Instantiate";
    inst->type_names = FMI2_TYPE_NAMES;
    if (fmuType != fmi2CoSimulation && !(fmuType == fmi2ModelExchange && ME_SUPPORTED)) {
        log_message(inst, fmi2Error, "logStatusError", "%s supports co-simulation only",
                    MODEL_IDENTIFIER_STR);
        free(inst);
        return NULL;
    }
    if (!fmuGUID || strcmp(fmuGUID, MODEL_GUID) != 0) {
        log_message(inst, fmi2Error, "logStatusError", "GUID %s does not match this FMU's %s",
                    fmuGUID ? fmuGUID : "(null)", MODEL_GUID);
        free(inst);
        return NULL;
    }
    data_start(&inst->s.d, 0.0);
    inst->s.phase = S_INSTANTIATED;
    inst->s.dirty = 1;
    return inst;
}

void instance_free(fmi2Component c)
{
    Instance *inst = (Instance *)c;
    if (!instance_ok(inst, "fmi2FreeInstance")) {
        return; /* freeing twice (or a foreign pointer) would corrupt the host's heap */
    }
    *(volatile unsigned *)&inst->magic = 0; /* volatile: a plain store before free() is dead */
    free(inst);
}

fmi2Status instance_set_logging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[])
{
    (void)nCategories;
    (void)categories;
    ((Instance *)c)->logging_on = loggingOn;
    return fmi2OK;
}

fmi2Status instance_setup(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    Instance *inst = (Instance *)c;
    (void)toleranceDefined;
    (void)tolerance;
    (void)stopTimeDefined;
    (void)stopTime;
    if (!isfinite(startTime)) {
        return ERROR(inst, "start time must be finite");
    }
    inst->s.d.start_time = startTime;
    inst->s.last_time = startTime;
    inst->s.dirty = 1;
    return fmi2OK;
}

fmi2Status instance_enter_initialization(fmi2Component c)
{
    Instance *inst = (Instance *)c;
    inst->s.phase = S_INITIALIZATION;
    inst->s.dirty = 1;
    return fmi2OK;
}

fmi2Status instance_exit_initialization(fmi2Component c)
{
    Instance *inst = (Instance *)c;
    if (inst->s.dirty && initialize(inst)) {
        return ERROR(inst, "%s", inst->msg);
    }
    inst->s.phase = inst->type == fmi2ModelExchange ? S_EVENT_MODE : S_STEP_COMPLETE;
    return fmi2OK;
}

fmi2Status instance_terminate(fmi2Component c)
{
    Instance *inst = (Instance *)c;
    inst->s.phase = S_TERMINATED;
    return fmi2OK;
}

fmi2Status instance_reset(fmi2Component c)
{
    Instance *inst = (Instance *)c;
    data_start(&inst->s.d, 0.0);
    inst->s.phase = S_INSTANTIATED;
    inst->s.dirty = 1;
    inst->s.last_time = 0.0;
    inst->s.me_time_set = 0;
    inst->step_refused = 0;
    return fmi2OK;
}

/* --- stepping ------------------------------------------------------------------------------- */

fmi2Status instance_do_step(fmi2Component c, fmi2Real currentCommunicationPoint,
                            fmi2Real communicationStepSize,
                            fmi2Boolean noSetFMUStatePriorToCurrentPoint, Stepper step)
{
    Instance *inst = (Instance *)c;
    ModelState backup_m;
    double backup_r[N_VARS];
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!isfinite(currentCommunicationPoint)) { /* NaN would pass the model's time check */
        return ERROR_FN(inst, "communication point %g is not finite",
                     currentCommunicationPoint);
    }
    /* A model step writes only the model state and the outputs: back those up, restore them if
     * the step is refused (cheaper than stepping a full copy of Data). */
    backup_m = inst->s.d.m;
    memcpy(backup_r, inst->s.d.r, sizeof backup_r);
    if (step(&inst->s.d, currentCommunicationPoint, communicationStepSize, inst->msg) ||
        check_outputs(&inst->s.d, inst->msg)) {
        inst->s.d.m = backup_m;
        memcpy(inst->s.d.r, backup_r, sizeof backup_r);
        log_message(inst, fmi2Error, "logStatusError", "at t=%.17g: %s",
                    currentCommunicationPoint, inst->msg);
        inst->s.last_time = currentCommunicationPoint;
        inst->step_refused = 1;
        return fmi2Discard;
    }
    inst->s.last_time = currentCommunicationPoint + communicationStepSize;
    inst->step_refused = 0;
    return fmi2OK;
}
