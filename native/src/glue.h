/* The model API of the native FMUs: what a model provides, and the Data it works on.
 *
 * Each model folder (native/plant, native/controller) holds config.h (generated from the model's
 * Python variable table: value references, types, start values, ranges), model.h (its ModelState:
 * plain data, copied for FMU states) and model.c (model_initialize, model_step). The instance core (instance.c,
 * instance.h) drives any model through these functions on the Data below; the FMI 2.0 glue
 * (fmi2_glue.c) and the FMI 3.0 glue (fmi3_*.c) call the core.
 *
 * Conventions mirror the Python FMUs (impedance_cosim/fmi/fmi2_slave.py):
 * - variables are stored by value reference: Real in r[], Integer and Boolean in i[], String in s[];
 * - model_initialize builds the initial state and outputs from parameters and inputs (it may be
 *   called several times during initialization mode, whenever a getter needs fresh outputs);
 * - model_step advances from t to t + h, writing only d->m and the outputs in d->r (parameters
 *   and inputs are read-only); the glue restores both when the step is refused, so the instance
 *   stays at the step's start.
 * - model_step does a bounded amount of work: it refuses a step that would need more internal
 *   steps or samples than the model's step-bound parameter allows.
 * All return 0 on success, or 1 after writing a message that names the problem into msg.
 */
#ifndef GLUE_H
#define GLUE_H

#include <stddef.h>
#include <string.h>

#define STRING_MAX 64
#define MSG_MAX 512

typedef enum { T_REAL, T_INTEGER, T_BOOLEAN, T_STRING } VarType;
typedef enum { C_PARAMETER, C_INPUT, C_OUTPUT, C_LOCAL } Causality;

typedef struct {
    const char *name;
    VarType type;
    Causality causality;
    double start;             /* Real, Integer and Boolean start values */
    const char *start_string; /* String start value */
    int has_min;
    double min;
    int tunable; /* a parameter that may be set between steps (CS) or in Event Mode (ME) */
} VarInfo;

/* A model compiled as a part of another FMU (native/closedloop) names its own headers:
 * MODEL_CONFIG_HEADER and MODEL_STATE_HEADER, defined before this file is included. */
#ifdef MODEL_CONFIG_HEADER
#include MODEL_CONFIG_HEADER
#else
#include "config.h" /* N_VARS, VR_<name>, MODEL_IDENTIFIER_STR, VARS[] */
#endif
#ifdef MODEL_STATE_HEADER
#include MODEL_STATE_HEADER
#else
#include "model.h" /* ModelState */
#endif

typedef struct {
    double r[N_VARS];
    int i[N_VARS];
    char s[N_VARS][STRING_MAX];
    ModelState m;
    double start_time;
} Data;

/* Data at the variables' start values, everything else zero: what instantiation and reset give
 * (the instance core, the closed loop's parts and the model tests' shim all start from it). */
static inline void data_start(Data *d, double start_time)
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
    d->start_time = start_time;
}

/* How the model API links: externally in the model's own FMU; internally where the closed loop
 * compiles the model as one of its two parts (part_api.h defines MODEL_LINKAGE as static first:
 * a function declared static here and defined without a storage class in model.c is static), so
 * the two models' model_* functions and tables never meet in the closed loop's library. */
#ifndef MODEL_LINKAGE
#define MODEL_LINKAGE
#define MODEL_TABLES_EXTERN
#endif

MODEL_LINKAGE int model_initialize(Data *d, char *msg);
MODEL_LINKAGE int model_step(Data *d, double t, double h, char *msg);
/* Check new values of tunable parameters (set into d after initialization); 0 if usable, else
 * 1 with msg set. The model reads them from its next step on. */
MODEL_LINKAGE int model_check_tunable(const Data *d, char *msg);
/* A ModelState from outside (a deserialized FMU state), checked before the model may use it:
 * every counter, index and enumeration in range, and the reals the model needs finite (the glue
 * has checked the parameters and inputs in d). 0 if usable, else 1 with the reason in msg. */
MODEL_LINKAGE int model_check_state(const Data *d, char *msg);

/* The reals of the model's ModelState (name, byte offset, count), for the check that a
 * serialized state holds only finite numbers: every double in ModelState is listed. */
typedef struct {
    const char *name;
    size_t offset;
    int count;
} StateReals;
#ifdef MODEL_TABLES_EXTERN /* (a part's are static, defined in its model.c with MODEL_LINKAGE) */
extern const StateReals MODEL_STATE_REALS[];
extern const int N_MODEL_STATE_REALS;
#endif

/* The work of one FMI 3.0 fmi3DoStep so far, across the model steps it restarts at the switches
 * (model_step_early): zeroed at the start of each fmi3DoStep, so the model's per-step bounds
 * (max_rhs_evaluations, the switches per step) hold for the fmi3DoStep call whole. */
typedef struct {
    long long rhs_evaluations;
    int switches;
} StepWork;

/* snprintf into msg (MSG_MAX bytes); returns 1 so models can write `return fail(msg, ...)` */
int fail(char *msg, const char *fmt, ...);

#endif
