/* The instance of a native FMU and the instance core over it (instance.c, instance_me.c), which
 * the FMI 2.0 glue (fmi2_glue.c, fmi2_me.c) and the FMI 3.0 glue (fmi3_*.c) both call.
 *
 * Phases follow the FMI 2.0 state machines: co-simulation (section 4.2.4) steps in
 * S_STEP_COMPLETE; Model Exchange (section 3.2.3) alternates between S_EVENT_MODE and
 * S_CONTINUOUS_TIME. The phase is the core's own (it decides whether outputs are stale, parameters
 * fixed, initialization done) and the FMI 2.0 glue's state; each glue checks the legality of its
 * calls itself (fmi2_states.h, fmi3_states.h). A model offers Model Exchange when its generated config.h defines
 * MODEL_EXCHANGE (with N_STATES, N_EVENT_INDICATORS and DERIVATIVE_VRS[]) and its model.c
 * implements the model_me_* functions of model_me.h.
 */
#ifndef INSTANCE_H
#define INSTANCE_H

#include <stdint.h>

#include "fmi2Functions.h"
#include "glue.h"

typedef enum {
    S_INSTANTIATED,
    S_INITIALIZATION,
    S_STEP_COMPLETE,   /* co-simulation: between steps */
    S_EVENT_MODE,      /* Model Exchange */
    S_CONTINUOUS_TIME, /* Model Exchange */
    S_TERMINATED
} Phase;

typedef struct {
    Data d;
    Phase phase;
    int dirty; /* outputs must be recomputed before they are read (initialization mode; and under
                  Model Exchange after a new time, state or input) */
    double last_time;
    double me_time;     /* Model Exchange: the time set by fmi2SetTime */
    int me_time_set;    /* Model Exchange: fmi2SetTime was called (else the time is the start) */
    int event_switches; /* Model Exchange: discrete-state switches in the current event */
} Snapshot; /* everything an FMU state holds */

typedef struct {
    unsigned magic; /* INSTANCE_MAGIC while alive; fmi2FreeInstance clears it */
    Snapshot s;
    fmi2CallbackFunctions cb;
    char name[128];
    int logging_on;
    fmi2Type type; /* fmi2CoSimulation or fmi2ModelExchange */
    const char *fn; /* the glue's entry point being served (set by its state check): messages
                       name it */
    const char *const *type_names; /* the glue's names of VarType (Real or Float64, ...) */
    int step_refused; /* the last fmi2DoStep returned fmi2Discard: fmi2Terminated is true then
                         (the same step would be refused again; not part of an FMU state) */
    char msg[MSG_MAX];
} Instance;

/* VarType's names in FMI 2.0 (instance_new's default) and FMI 3.0 (set by the FMI 3 glue) */
extern const char *const FMI2_TYPE_NAMES[];
extern const char *const FMI3_TYPE_NAMES[];

/* Initialize the instance's Data from its parameters and inputs (model_initialize, and under
 * Model Exchange me_initialize; instance.c): 0, or 1 with the reason in inst->msg. */
int initialize(Instance *inst);

/* A parameter value the model can accept at all: finite, and not below its minimum (instance.c;
 * 0, or 1 with msg set). */
int check_parameter(int vr, double value, char *msg);

/* CRC-32 (IEEE 802.3, as zlib's crc32) of n bytes, continuing from crc (0 to start): the
 * checksum of a serialized FMU state (instance_state.c; the state fuzzer re-signs with it). */
uint32_t crc32_update(uint32_t crc, const unsigned char *p, size_t n);

/* Log through the host's logger: errors always, other messages when logging is on. */
void log_message(Instance *inst, fmi2Status status, const char *category, const char *fmt, ...);

#define ERROR(inst, ...) (log_message((inst), fmi2Error, "logStatusError", __VA_ARGS__), fmi2Error)
/* An error naming the entry point being served: "<inst->fn>: <message>". */
void log_fn_error(Instance *inst, const char *fmt, ...);
#define ERROR_FN(inst, ...) (log_fn_error((inst), __VA_ARGS__), fmi2Error)

/* Every entry point first checks that c is a live instance of this FMU (the FMI 2.0 glue's
 * LEGAL, the FMI 3.0 glue's WRAP over the wrapper that owns it; the core's functions then trust
 * it, except instance_free): not NULL, and carrying INSTANCE_MAGIC, which fmi2FreeInstance clears. This catches a second fmi2FreeInstance and most
 * calls on a freed instance, but not all: once the allocator has reused the freed block for a new
 * instance, a stale pointer to it looks valid again (and reading a freed block is itself undefined
 * behaviour that merely happens to work with common allocators). The host's logger cannot be
 * trusted for such a call (it lives in the instance), so the refusal goes to stderr. Returns 1
 * for a live instance, else 0. */
int instance_ok(const Instance *inst, const char *function);

/* instance_me.c: after model_initialize under Model Exchange, check that the model's settings make
 * sense there and compute outputs and derivatives (0, or 1 with a message in msg). */
int me_initialize(Data *d, char *msg);
/* instance_me.c: recompute outputs and derivatives at the current state and inputs if needed. */
fmi2Status me_update(Instance *inst);

#include "model_me.h" /* ME_SUPPORTED, the model_me_* functions */

/* The instance core (instance.c), called by the FMI 2.0 glue (fmi2_glue.c: each fmi2* function
 * calls the one named after it) and by the FMI 3.0 glue (fmi3_*.c). Messages name the glue's
 * entry point (inst->fn) and types (inst->type_names). */
typedef int (*Stepper)(Data *d, double t, double h, char *msg); /* model_step, or a variant */
fmi2Component instance_new(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                           fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                           fmi2Boolean visible, fmi2Boolean loggingOn);
void instance_free(fmi2Component c);
fmi2Status instance_set_logging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                                const fmi2String categories[]);
fmi2Status instance_setup(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                          fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime);
fmi2Status instance_enter_initialization(fmi2Component c);
fmi2Status instance_exit_initialization(fmi2Component c);
fmi2Status instance_terminate(fmi2Component c);
fmi2Status instance_reset(fmi2Component c);
fmi2Status instance_get_real(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                             fmi2Real value[]);
fmi2Status instance_get_integer(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                fmi2Integer value[]);
fmi2Status instance_get_boolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                fmi2Boolean value[]);
fmi2Status instance_get_string(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                               fmi2String value[]);
fmi2Status instance_set_real(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                             const fmi2Real value[]);
fmi2Status instance_set_integer(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                const fmi2Integer value[]);
fmi2Status instance_set_boolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                const fmi2Boolean value[]);
fmi2Status instance_set_string(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                               const fmi2String value[]);
fmi2Status instance_do_step(fmi2Component c, fmi2Real currentCommunicationPoint,
                            fmi2Real communicationStepSize,
                            fmi2Boolean noSetFMUStatePriorToCurrentPoint, Stepper step);
fmi2Status instance_get_state(fmi2Component c, fmi2FMUstate *state);
fmi2Status instance_set_state(fmi2Component c, fmi2FMUstate state);
fmi2Status instance_free_state(fmi2Component c, fmi2FMUstate *state);
fmi2Status instance_serialized_size(fmi2Component c, fmi2FMUstate state, size_t *size);
fmi2Status instance_serialize(fmi2Component c, fmi2FMUstate state, fmi2Byte serializedState[],
                              size_t size);
fmi2Status instance_deserialize(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                fmi2FMUstate *state);

/* The Model Exchange side (instance_me.c; models whose config.h defines MODEL_EXCHANGE). */
fmi2Status instance_enter_event_mode(fmi2Component c);
fmi2Status instance_new_discrete_states(fmi2Component c, fmi2EventInfo *eventInfo);
fmi2Status instance_enter_continuous_time_mode(fmi2Component c);
fmi2Status instance_completed_integrator_step(fmi2Component c,
                                              fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                              fmi2Boolean *enterEventMode,
                                              fmi2Boolean *terminateSimulation);
fmi2Status instance_set_time(fmi2Component c, fmi2Real time);
fmi2Status instance_set_continuous_states(fmi2Component c, const fmi2Real x[], size_t nx);
fmi2Status instance_get_continuous_states(fmi2Component c, fmi2Real x[], size_t nx);
fmi2Status instance_get_nominals(fmi2Component c, fmi2Real x_nominal[], size_t nx);
fmi2Status instance_get_derivatives(fmi2Component c, fmi2Real derivatives[], size_t nx);
fmi2Status instance_get_event_indicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni);


#endif
