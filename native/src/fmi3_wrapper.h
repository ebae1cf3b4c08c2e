/* The FMI 3.0 instance of the native FMUs, shared by fmi3_glue.c (the FMI 2.0 layer, lifecycle,
 * values, FMU state, co-simulation), fmi3_events.c (Model Exchange, the clock of Scheduled
 * Execution) and fmi3_stubs.c (what these FMUs do not provide). A Wrapper holds the FMI 2.0
 * instance (instance.h), which has all the state, and what FMI 3.0 adds to it. */
#ifndef FMI3_WRAPPER_H
#define FMI3_WRAPPER_H

#include "fmi3Functions.h"
#include "fmi2_hidden.h" /* the FMI 2 layer's functions, under their internal names */
#include "glue.h"
#include "instance.h"
#include "fmi3_config.h" /* VR_TIME, VR_INDICATOR; HAS_CLOCK, VR_CLOCK, CLOCK_PERIOD_VR;
                            HAS_EARLY_RETURN: written by the build */

#define WRAPPER_MAGIC 0x494d5033u /* "IMP3" */

typedef enum { K_ME, K_CS, K_SE } Kind;

typedef struct {
    unsigned magic; /* WRAPPER_MAGIC while alive; fmi3FreeInstance clears it */
    Instance *inner; /* the FMI 2 instance (fmi2_glue.c): all the state */
    Kind kind;
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log;
    int early_return; /* co-simulation: the importer allows early return, the model offers it */
    double reached;   /* where the last model step stopped */
} Wrapper;

/* An fmi2Status as fmi3Status (the same numbers; fmi2Pending, never returned, as fmi3Error). */
fmi3Status status3(fmi2Status s);
/* The wrapper, if instance is a live FMI 3 instance of this FMU (else NULL, said on stderr:
 * the host's logger lives in the instance and cannot be trusted then). */
Wrapper *wrapper_of(fmi3Instance instance, const char *function);

/* First line of every entry point: w, or return fmi3Error. */
#define WRAP(function)                                                                         \
    Wrapper *w = wrapper_of(instance, function);                                                     \
    if (!w) {                                                                                  \
        return fmi3Error;                                                                      \
    }

#define FAIL(w, ...) (log_message((w)->inner, fmi2Error, "logStatusError", __VA_ARGS__), fmi3Error)

#endif
