/* The instance of a native FMU, shared by the co-simulation glue (fmi2_glue.c) and the
 * Model Exchange entry points (fmi2_me.c).
 *
 * Phases follow the FMI 2.0 state machines: co-simulation (section 4.2.4) steps in
 * S_STEP_COMPLETE; Model Exchange (section 3.2.3) alternates between S_EVENT_MODE and
 * S_CONTINUOUS_TIME. A model offers Model Exchange when its generated config.h defines
 * MODEL_EXCHANGE (with N_STATES, N_EVENT_INDICATORS and DERIVATIVE_VRS[]) and its model.c
 * implements the model_me_* functions of model_me.h.
 */
#ifndef INSTANCE_H
#define INSTANCE_H

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
    int step_refused; /* the last fmi2DoStep returned fmi2Discard: fmi2Terminated is true then
                         (the same step would be refused again; not part of an FMU state) */
    char msg[MSG_MAX];
} Instance;

/* Log through the host's logger: errors always, other messages when logging is on. */
void log_message(Instance *inst, fmi2Status status, const char *category, const char *fmt, ...);

#define ERROR(inst, ...) (log_message((inst), fmi2Error, "logStatusError", __VA_ARGS__), fmi2Error)

/* Every entry point first checks that c is a live instance of this FMU: not NULL, and carrying
 * INSTANCE_MAGIC, which fmi2FreeInstance clears. This catches a second fmi2FreeInstance and most
 * calls on a freed instance, but not all: once the allocator has reused the freed block for a new
 * instance, a stale pointer to it looks valid again (and reading a freed block is itself undefined
 * behaviour that merely happens to work with common allocators). The host's logger cannot be
 * trusted for such a call (it lives in the instance), so the refusal goes to stderr. Returns 1
 * for a live instance, else 0. */
int instance_ok(const Instance *inst, const char *function);

/* fmi2_me.c: after model_initialize under Model Exchange, check that the model's settings make
 * sense there and compute outputs and derivatives (0, or 1 with a message in msg). */
int me_initialize(Data *d, char *msg);
/* fmi2_me.c: recompute outputs and derivatives at the current state and inputs if needed. */
fmi2Status me_update(Instance *inst);

#include "model_me.h" /* ME_SUPPORTED, the model_me_* functions */

#endif
