/* The instance core of every native model, written once (see glue.h and instance.h): what the
 * FMI 2.0 glue (fmi2_glue.c) and the FMI 3.0 glue (fmi3_*.c) both call. Its messages name the
 * FMI 2.0 functions; the FMI 3.0 glue's logger renames them.
 *
 * State machine (FMI 2.0, section 4.2.4): instantiated -> initialization mode -> step complete
 * -> terminated; a call out of order returns fmi2Error with a logged message and changes nothing.
 * Errors are always logged (whatever fmi2SetDebugLogging says); other messages only with logging
 * on. Parameter values are checked when set (finite, >= min) and again before initialization;
 * non-finite inputs are refused when set. A step that cannot be taken returns fmi2Discard and
 * leaves the instance at the step's start; fmi2GetBooleanStatus(fmi2Terminated) then says true,
 * so that a master which can only retry the same step (fmpy simulate) stops. A serialized FMU
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

#define INSTANCE_MAGIC 0x494d5049u /* "IMPI" */
#define STATE_MAGIC 0x494d5053u    /* "IMPS" */

/* What fmi2GetFMUstate hands out: a Snapshot behind a tag that says whose it is, so that a
 * foreign or freed pointer given back to fmi2SetFMUstate / fmi2FreeFMUstate is refused. */
typedef struct {
    unsigned magic; /* STATE_MAGIC while allocated; fmi2FreeFMUstate clears it */
    unsigned n_vars;
    char identifier[32];
    Snapshot s;
} StateBox;

/* A serialized FMU state (format 2): this header, then the Snapshot's bytes. The header has the
 * same layout on every platform (fixed-width fields, 64 bytes); the checksum (CRC-32, the one of
 * zlib and of the Python FMUs' states) covers the header before it and the whole body, so a state
 * that is not one this FMU wrote (bytes flipped, cut, added, or another build's) is refused before
 * any of it is read. A body that passes the checksum is still checked field by field
 * (check_snapshot, check_finite): a checksum is no proof of origin, anyone can recompute it. */
#define SERIAL_MAGIC "IMPCNAT2"         /* native state, format 2 */
#define SERIAL_MAGIC_FORMAT1 0x494d5043u /* format 1 (no checksum): the first 4 bytes, "CPMI" */
#define SERIAL_GUID_MAX 40
typedef struct {
    char magic[8];                /* SERIAL_MAGIC */
    uint32_t n_vars;              /* N_VARS */
    uint32_t body_size;           /* sizeof(Snapshot) */
    char guid[SERIAL_GUID_MAX];   /* MODEL_GUID of the build that wrote it, NUL-padded */
    uint32_t flags;               /* 0 */
    uint32_t crc;                 /* CRC-32 of the 60 bytes above and of the body */
} SerialHeader;
typedef char serial_header_is_64_bytes[sizeof(SerialHeader) == 64 ? 1 : -1];
typedef char guid_fits_the_header[sizeof MODEL_GUID <= SERIAL_GUID_MAX ? 1 : -1];

int fail(char *msg, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, MSG_MAX, fmt, ap);
    va_end(ap);
    return 1;
}

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

static void set_start_values(Data *d)
{
    memset(d, 0, sizeof *d);
    for (int vr = 0; vr < N_VARS; vr++) {
        const VarInfo *v = &VARS[vr];
        if (v->type == T_REAL) {
            d->r[vr] = v->start;
        } else if (v->type == T_STRING) {
            strncpy(d->s[vr], v->start_string ? v->start_string : "", STRING_MAX - 1);
        } else {
            d->i[vr] = (int)v->start;
        }
    }
}

/* A parameter value the model can accept at all: finite, and not below its minimum. */
static int check_parameter(int vr, double value, char *msg)
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

static int initialize(Instance *inst)
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
    if (model_initialize(&tmp, inst->msg)) {
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
    set_start_values(&inst->s.d);
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
    if (!instance_ok((Instance *)c, "fmi2SetDebugLogging")) {
        return fmi2Error;
    }
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
    if (!instance_ok(inst, "fmi2SetupExperiment")) {
        return fmi2Error;
    }
    if (inst->s.phase != S_INSTANTIATED) {
        return ERROR(inst, "fmi2SetupExperiment must come before fmi2EnterInitializationMode");
    }
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
    if (!instance_ok(inst, "fmi2EnterInitializationMode")) {
        return fmi2Error;
    }
    if (inst->s.phase != S_INSTANTIATED) {
        return ERROR(inst, "fmi2EnterInitializationMode called twice or after initialization");
    }
    inst->s.phase = S_INITIALIZATION;
    inst->s.dirty = 1;
    return fmi2OK;
}

fmi2Status instance_exit_initialization(fmi2Component c)
{
    Instance *inst = (Instance *)c;
    if (!instance_ok(inst, "fmi2ExitInitializationMode")) {
        return fmi2Error;
    }
    if (inst->s.phase != S_INITIALIZATION) {
        return ERROR(inst, "fmi2ExitInitializationMode called outside initialization mode");
    }
    if (inst->s.dirty && initialize(inst)) {
        return ERROR(inst, "%s", inst->msg);
    }
    inst->s.phase = inst->type == fmi2ModelExchange ? S_EVENT_MODE : S_STEP_COMPLETE;
    return fmi2OK;
}

fmi2Status instance_terminate(fmi2Component c)
{
    Instance *inst = (Instance *)c;
    if (!instance_ok(inst, "fmi2Terminate")) {
        return fmi2Error;
    }
    if (inst->s.phase < S_STEP_COMPLETE || inst->s.phase == S_TERMINATED) {
        return ERROR(inst, "fmi2Terminate called before initialization finished or twice");
    }
    inst->s.phase = S_TERMINATED;
    return fmi2OK;
}

fmi2Status instance_reset(fmi2Component c)
{
    Instance *inst = (Instance *)c;
    if (!instance_ok(inst, "fmi2Reset")) {
        return fmi2Error;
    }
    set_start_values(&inst->s.d);
    inst->s.phase = S_INSTANTIATED;
    inst->s.dirty = 1;
    inst->s.last_time = 0.0;
    inst->s.me_time_set = 0;
    inst->step_refused = 0;
    return fmi2OK;
}

/* --- getters and setters ---------------------------------------------------------------------- */

static fmi2Status check_access(Instance *inst, const fmi2ValueReference vr[], size_t nvr,
                               const void *value, VarType type, int setting)
{
    static const char *type_names[] = {"Real", "Integer", "Boolean", "String"};
    static const char *getters[] = {"fmi2GetReal", "fmi2GetInteger", "fmi2GetBoolean",
                                    "fmi2GetString"};
    static const char *setters[] = {"fmi2SetReal", "fmi2SetInteger", "fmi2SetBoolean",
                                    "fmi2SetString"};
    if (!instance_ok(inst, setting ? setters[type] : getters[type])) {
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
                         type_names[type]);
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
            if (inst->s.phase == S_TERMINATED) {
                return ERROR(inst, "variable %s cannot be set after fmi2Terminate", v->name);
            }
        }
    }
    if (!setting && inst->s.phase == S_INSTANTIATED && nvr > 0) {
        return ERROR(inst, "values can be read only from initialization mode on");
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

/* --- stepping ------------------------------------------------------------------------------- */

fmi2Status instance_do_step(fmi2Component c, fmi2Real currentCommunicationPoint,
                            fmi2Real communicationStepSize,
                            fmi2Boolean noSetFMUStatePriorToCurrentPoint, Stepper step)
{
    Instance *inst = (Instance *)c;
    ModelState backup_m;
    double backup_r[N_VARS];
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!instance_ok(inst, "fmi2DoStep")) {
        return fmi2Error;
    }
    if (inst->s.phase != S_STEP_COMPLETE) {
        return ERROR(inst, "fmi2DoStep called before initialization finished or after "
                           "fmi2Terminate");
    }
    if (!isfinite(currentCommunicationPoint)) { /* NaN would pass the model's time check */
        return ERROR(inst, "fmi2DoStep: communication point %g is not finite",
                     currentCommunicationPoint);
    }
    /* A model step writes only the model state and the outputs: back those up, restore them if
     * the step is refused (cheaper than stepping a full copy of Data). */
    backup_m = inst->s.d.m;
    memcpy(backup_r, inst->s.d.r, sizeof backup_r);
    if (step(&inst->s.d, currentCommunicationPoint, communicationStepSize, inst->msg)) {
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

/* --- FMU state -------------------------------------------------------------------------------- */

/* A state from outside (fmi2DeSerializeFMUstate, or memory the host may have overwritten) before
 * it becomes the instance's: every field the glue or the model reads is in range. Parameters
 * pass the same checks as when they are set, inputs are finite, Booleans 0 or 1, strings
 * NUL-terminated within STRING_MAX, times finite; the model's own state (counters, indices,
 * enumerations) is checked by model_check_state once initialization has built it. */
static int check_snapshot(const Snapshot *s, fmi2Type type, char *msg)
{
    const unsigned phase = (unsigned)s->phase;
    const int me_phase = s->phase == S_EVENT_MODE || s->phase == S_CONTINUOUS_TIME;
    int built;
    if (phase > (unsigned)S_TERMINATED) {
        return fail(msg, "phase %u is not a phase of the FMI state machine", phase);
    }
    if (me_phase != (type == fmi2ModelExchange) && s->phase != S_INSTANTIATED &&
        s->phase != S_INITIALIZATION && s->phase != S_TERMINATED) {
        return fail(msg, "phase %u belongs to the other interface (co-simulation / Model "
                         "Exchange) than this instance's", phase);
    }
    if (s->me_time_set != 0 && s->me_time_set != 1) {
        return fail(msg, "flag 'me_time_set' is %d, not 0 or 1", s->me_time_set);
    }
    if (!isfinite(s->me_time) || s->event_switches < 0 || s->event_switches > 1000) {
        return fail(msg, "Model Exchange time not finite or event counter out of range");
    }
    if (s->dirty != 0 && s->dirty != 1) {
        return fail(msg, "flag 'dirty' is %d, not 0 or 1", s->dirty);
    }
    if (!isfinite(s->last_time) || !isfinite(s->d.start_time)) {
        return fail(msg, "a time is not finite");
    }
    for (int vr = 0; vr < N_VARS; vr++) {
        const VarInfo *v = &VARS[vr];
        if (v->type == T_STRING) {
            if (!memchr(s->d.s[vr], '\0', STRING_MAX)) {
                return fail(msg, "string %s is not NUL-terminated within %d bytes", v->name,
                            STRING_MAX);
            }
            continue;
        }
        if (v->type == T_BOOLEAN && s->d.i[vr] != 0 && s->d.i[vr] != 1) {
            return fail(msg, "Boolean %s is %d, not 0 or 1", v->name, s->d.i[vr]);
        }
        if (v->causality == C_PARAMETER &&
            check_parameter(vr, v->type == T_REAL ? s->d.r[vr] : s->d.i[vr], msg)) {
            return 1;
        }
        if (v->causality == C_INPUT && v->type == T_REAL && !isfinite(s->d.r[vr])) {
            return fail(msg, "input %s is not finite (%g)", v->name, s->d.r[vr]);
        }
    }
    built = s->phase >= S_STEP_COMPLETE || (s->phase == S_INITIALIZATION && !s->dirty);
    /* (under Model Exchange, states and inputs may change the outputs after initialization:
     * dirty is then legitimately 1 in event or continuous-time mode, with the model built) */
    /* (tunable parameters may have changed since initialization: their model-level checks) */
    return built ? model_check_tunable(&s->d, msg) || model_check_state(&s->d, msg) : 0;
}

/* A pointer from fmi2GetFMUstate / fmi2DeSerializeFMUstate of this FMU, not yet freed (as far
 * as can be told: the same limits as instance_ok). */
static int state_ok(Instance *inst, const StateBox *box, const char *function)
{
    if (box->magic != STATE_MAGIC || box->n_vars != N_VARS ||
        strncmp(box->identifier, MODEL_IDENTIFIER_STR, sizeof box->identifier) != 0) {
        log_message(inst, fmi2Error, "logStatusError",
                    "%s: the FMU state is not a live state of this %s FMU (freed, foreign or "
                    "overwritten): refused", function, MODEL_IDENTIFIER_STR);
        return 0;
    }
    return 1;
}

/* *state itself when it is a live state, a new one when it is NULL, else NULL (logged). */
static StateBox *state_for_writing(Instance *inst, fmi2FMUstate *state, const char *function)
{
    StateBox *box = (StateBox *)*state;
    if (box) {
        return state_ok(inst, box, function) ? box : NULL;
    }
    box = (StateBox *)calloc(1, sizeof(StateBox));
    if (!box) {
        log_message(inst, fmi2Error, "logStatusError", "out of memory for an FMU state");
        return NULL;
    }
    box->magic = STATE_MAGIC;
    box->n_vars = N_VARS;
    strncpy(box->identifier, MODEL_IDENTIFIER_STR, sizeof box->identifier - 1);
    *state = box;
    return box;
}

fmi2Status instance_get_state(fmi2Component c, fmi2FMUstate *state)
{
    Instance *inst = (Instance *)c;
    StateBox *box;
    if (!instance_ok(inst, "fmi2GetFMUstate")) {
        return fmi2Error;
    }
    if (!state) {
        return ERROR(inst, "fmi2GetFMUstate: the state pointer is NULL");
    }
    box = state_for_writing(inst, state, "fmi2GetFMUstate");
    if (!box) {
        return fmi2Error;
    }
    box->s = inst->s;
    return fmi2OK;
}

fmi2Status instance_set_state(fmi2Component c, fmi2FMUstate state)
{
    Instance *inst = (Instance *)c;
    const StateBox *box = (const StateBox *)state;
    if (!instance_ok(inst, "fmi2SetFMUstate")) {
        return fmi2Error;
    }
    if (!box) {
        return ERROR(inst, "fmi2SetFMUstate: the state is NULL");
    }
    if (!state_ok(inst, box, "fmi2SetFMUstate")) {
        return fmi2Error;
    }
    if (check_snapshot(&box->s, inst->type, inst->msg)) {
        return ERROR(inst, "fmi2SetFMUstate: invalid FMU state (%s): refused", inst->msg);
    }
    inst->s = box->s;
    return fmi2OK;
}

fmi2Status instance_free_state(fmi2Component c, fmi2FMUstate *state)
{
    Instance *inst = (Instance *)c;
    StateBox *box;
    if (!instance_ok(inst, "fmi2FreeFMUstate")) {
        return fmi2Error;
    }
    if (!state || !*state) {
        return fmi2OK; /* FMI 2.0: a NULL state is ignored */
    }
    box = (StateBox *)*state;
    if (!state_ok(inst, box, "fmi2FreeFMUstate")) {
        return fmi2Error; /* freeing it could corrupt the host's heap */
    }
    *(volatile unsigned *)&box->magic = 0; /* volatile: see fmi2FreeInstance */
    free(box);
    *state = NULL;
    return fmi2OK;
}

/* CRC-32 (IEEE 802.3, reflected, as zlib's crc32) of n bytes, continuing from crc (0 to start).
 * Bitwise and branch-free: states are a few kilobytes, serialized rarely. */
static uint32_t crc32_update(uint32_t crc, const unsigned char *p, size_t n)
{
    crc = ~crc;
    while (n--) {
        crc ^= *p++;
        for (int k = 0; k < 8; k++) {
            crc = (crc >> 1) ^ (0xEDB88320u & (0u - (crc & 1u)));
        }
    }
    return ~crc;
}

/* The checksum a header and body must carry: over the header up to its crc field, then the body. */
static uint32_t serial_crc(const SerialHeader *header, const unsigned char *body)
{
    const uint32_t crc = crc32_update(0, (const unsigned char *)header, offsetof(SerialHeader, crc));
    return crc32_update(crc, body, sizeof(Snapshot));
}

/* A serialized state holds finite numbers only: every Real slot, the times and every double of
 * the model's state (in memory a state may hold what a run reached, e.g. an overflowed observer;
 * such a state is not serialized, so nothing refused on the way in was ever written). */
static int check_finite(const Snapshot *s, char *msg)
{
    if (!isfinite(s->d.start_time) || !isfinite(s->last_time) || !isfinite(s->me_time)) {
        return fail(msg, "a time (start, last communication point or Model Exchange time) is "
                         "not finite");
    }
    for (int vr = 0; vr < N_VARS; vr++) {
        if (!isfinite(s->d.r[vr])) {
            return fail(msg, "the value of %s is not finite (%g)", VARS[vr].name, s->d.r[vr]);
        }
    }
    for (int k = 0; k < N_MODEL_STATE_REALS; k++) {
        const StateReals *f = &MODEL_STATE_REALS[k];
        for (int j = 0; j < f->count; j++) {
            double x;
            memcpy(&x, (const char *)&s->d.m + f->offset + j * sizeof x, sizeof x);
            if (!isfinite(x)) {
                return fail(msg, "%s[%d] is not finite (%g)", f->name, j, x);
            }
        }
    }
    return 0;
}

/* The header this build writes, without its checksum (crc = 0). */
static void serial_header(SerialHeader *header)
{
    memset(header, 0, sizeof *header);
    memcpy(header->magic, SERIAL_MAGIC, sizeof header->magic);
    header->n_vars = N_VARS;
    header->body_size = (uint32_t)sizeof(Snapshot);
    memcpy(header->guid, MODEL_GUID, sizeof MODEL_GUID);
}

fmi2Status instance_serialized_size(fmi2Component c, fmi2FMUstate state, size_t *size)
{
    Instance *inst = (Instance *)c;
    if (!instance_ok(inst, "fmi2SerializedFMUstateSize")) {
        return fmi2Error;
    }
    if (!state || !size) {
        return ERROR(inst, "fmi2SerializedFMUstateSize: NULL state or size");
    }
    if (!state_ok(inst, (const StateBox *)state, "fmi2SerializedFMUstateSize")) {
        return fmi2Error;
    }
    *size = sizeof(SerialHeader) + sizeof(Snapshot);
    return fmi2OK;
}

fmi2Status instance_serialize(fmi2Component c, fmi2FMUstate state, fmi2Byte serializedState[],
                                 size_t size)
{
    Instance *inst = (Instance *)c;
    const StateBox *box = (const StateBox *)state;
    SerialHeader header;
    if (!instance_ok(inst, "fmi2SerializeFMUstate")) {
        return fmi2Error;
    }
    if (!state || !serializedState || size < sizeof header + sizeof(Snapshot)) {
        return ERROR(inst, "fmi2SerializeFMUstate: NULL state or buffer smaller than %lu bytes",
                     (unsigned long)(sizeof header + sizeof(Snapshot)));
    }
    if (!state_ok(inst, box, "fmi2SerializeFMUstate")) {
        return fmi2Error;
    }
    if (check_finite(&box->s, inst->msg)) {
        return ERROR(inst, "fmi2SerializeFMUstate: the state holds a number that is not finite "
                           "(%s): not serialized (it could not be restored)", inst->msg);
    }
    serial_header(&header);
    header.crc = serial_crc(&header, (const unsigned char *)&box->s);
    memcpy(serializedState, &header, sizeof header);
    memcpy(serializedState + sizeof header, &box->s, sizeof(Snapshot));
    return fmi2OK;
}

/* Bytes from outside, checked in order: big enough for a header, our magic (with a word for a
 * state of an older build), this FMU's layout and build, the exact size, the checksum; then the
 * body's fields (check_finite, check_snapshot). 0 with the body in *body, else 1 with msg set. */
static int decode_state(const unsigned char *bytes, size_t size, Snapshot *body, char *msg)
{
    const size_t expected = sizeof(SerialHeader) + sizeof(Snapshot);
    SerialHeader header, ours;
    uint32_t format1;
    if (size < sizeof header) {
        return fail(msg, "%lu bytes, not a state of this FMU (%lu bytes)", (unsigned long)size,
                    (unsigned long)expected);
    }
    memcpy(&header, bytes, sizeof header);
    memcpy(&format1, bytes, sizeof format1);
    if (format1 == SERIAL_MAGIC_FORMAT1) {
        return fail(msg, "written by an older build of a native FMU (state format 1, without a "
                         "checksum); states do not carry across builds");
    }
    if (memcmp(header.magic, SERIAL_MAGIC, sizeof header.magic) != 0) {
        return fail(msg, "not a serialized state of a native FMU (bad magic)");
    }
    serial_header(&ours);
    if (memcmp(&header, &ours, offsetof(SerialHeader, crc)) != 0) { /* every byte up to crc */
        return fail(msg, "written by another FMU or another build (this is %s, GUID %s); states "
                         "do not carry across builds", MODEL_IDENTIFIER_STR, MODEL_GUID);
    }
    if (size != expected) {
        return fail(msg, "%lu bytes, expected %lu (truncated or extended)", (unsigned long)size,
                    (unsigned long)expected);
    }
    if (serial_crc(&header, bytes + sizeof header) != header.crc) {
        return fail(msg, "checksum mismatch (the bytes are not the ones this FMU wrote)");
    }
    memcpy(body, bytes + sizeof header, sizeof *body);
    return check_finite(body, msg);
}

fmi2Status instance_deserialize(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *state)
{
    Instance *inst = (Instance *)c;
    Snapshot body;
    StateBox *box;
    if (!instance_ok(inst, "fmi2DeSerializeFMUstate")) {
        return fmi2Error;
    }
    if (!state) {
        return ERROR(inst, "fmi2DeSerializeFMUstate: the state pointer is NULL");
    }
    if (!serializedState) {
        return ERROR(inst, "fmi2DeSerializeFMUstate: serialized state refused: NULL bytes");
    }
    if (decode_state((const unsigned char *)serializedState, size, &body, inst->msg) ||
        check_snapshot(&body, inst->type, inst->msg)) {
        return ERROR(inst, "fmi2DeSerializeFMUstate: serialized state refused: %s", inst->msg);
    }
    box = state_for_writing(inst, state, "fmi2DeSerializeFMUstate");
    if (!box) {
        return fmi2Error;
    }
    box->s = body;
    return fmi2OK;
}
