/* libFuzzer target: FMI 3.0 call sequences with hostile arguments against a native FMU's fmi3
 * glue (fmi3_glue.c, fmi3_cosim.c, fmi3_events.c, fmi3_stubs.c), as calls.c does for FMI 2.0.
 *
 * Compiled with the FMI 3.0 FMU's shipped sources/ (fuzz/targets.py). Each input byte picks a
 * call (instantiate for co-simulation or model exchange, initialization, event and step mode,
 * fmi3DoStep, set/get of Float64, Int32, Int64, Boolean, String, states and their serialization,
 * the event, clock and derivative functions, terminate, reset, free) and the bytes after it its
 * arguments: value references of any number (the FMI 2 table, time, the event indicators, far
 * out of range), NULL arrays, counts that do not match, NaN/inf/huge/negative reals and step
 * sizes, so that the state machine's edges are tried in any order. Calls on a freed instance are
 * not made (the pointer is gone: the host's bug). The work-bound parameters are kept small when
 * set, positive step sizes at most 0.01 s. Refusals are expected; crashes, leaks, sanitizer
 * reports and hangs are findings. Without -DFUZZ_LIBFUZZER main() replays files. */
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"
#include "glue.h" /* after the FMI header: N_VARS, VARS[] */
#include "guid.h"

static const double REALS[] = {0.0, -0.0, 1.0, -1.0, 0.3, 1.0 / 400, 1e308, -1e308, 0.0 / 0.0,
                               1.0 / 0.0, -1.0 / 0.0, 5e-324, 1e-300, 9007199254740992.0, 0.01};
static const int64_t INTS[] = {0, 1, -1, 2, 7, 2147483647, -2147483647 - 1, 1000, -1000,
                               INT64_MAX, INT64_MIN, 4294967296LL};
static const char *STRINGS[] = {"observer", "difference", "measured", "", "%s%n%x", "\xff\xfe"};

static void logger(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category,
                   fmi3String message)
{
    (void)env, (void)status, (void)category, (void)message;
}

#include "input.h" /* Input, next(), PICK */

static fmi3ValueReference any_vr(Input *in)
{
    const unsigned b = next(in);
    return b == 255 ? 0xFFFFFFFFu : b < 250 ? (fmi3ValueReference)(b % (N_VARS + 8)) : b * 977u;
}

static int work_bound(fmi3ValueReference vr)
{
    return vr < N_VARS && (strcmp(VARS[vr].name, "max_rhs_evaluations") == 0 ||
                           strcmp(VARS[vr].name, "max_samples_per_step") == 0);
}

/* The arguments of one call: value references, their count, and the count of values passed
 * (mostly equal; bit 7 of the count byte makes it differ, bit 6 passes NULL arrays). */
typedef struct {
    fmi3ValueReference vr[4];
    size_t nvr, nvalues;
    int null_arrays;
} Args;

static Args args(Input *in)
{
    Args a;
    const unsigned b = next(in);
    a.nvr = b % 4;
    a.nvalues = b & 0x80 ? (b >> 2) % 4 : a.nvr;
    a.null_arrays = (b & 0x40) != 0;
    for (size_t k = 0; k < a.nvr; k++) {
        a.vr[k] = any_vr(in);
    }
    return a;
}
#define VRS(a) ((a).null_arrays ? NULL : (a).vr)
#define VALS(a, v) ((a).null_arrays ? NULL : (v))

static fmi3Instance instantiate(Input *in)
{
    const unsigned b = next(in);
    const char *token = b & 2 ? "{wrong}" : MODEL_GUID;
    if (b & 1) {
        return fmi3InstantiateModelExchange("fuzz", token, "", fmi3False, (b & 4) != 0, NULL,
                                            logger);
    }
    return fmi3InstantiateCoSimulation("fuzz", token, "", fmi3False, (b & 4) != 0,
                                       (b & 8) != 0, (b & 16) != 0, NULL, 0, NULL, logger, NULL);
}

static void set_values(fmi3Instance c, Input *in, unsigned op)
{
    const Args a = args(in);
    switch (op) {
    case 0: {
        fmi3Float64 v[4];
        for (size_t k = 0; k < 4; k++) {
            v[k] = PICK(in, REALS);
        }
        fmi3SetFloat64(c, VRS(a), a.nvr, VALS(a, v), a.nvalues);
        break;
    }
    case 1: {
        fmi3Int32 v[4];
        for (size_t k = 0; k < 4; k++) {
            v[k] = k < a.nvr && work_bound(a.vr[k]) ? (fmi3Int32)(next(in) % 50)
                                                     : (fmi3Int32)PICK(in, INTS);
        }
        fmi3SetInt32(c, VRS(a), a.nvr, VALS(a, v), a.nvalues);
        break;
    }
    case 2: {
        fmi3Int64 v[4];
        for (size_t k = 0; k < 4; k++) {
            v[k] = k < a.nvr && work_bound(a.vr[k]) ? (fmi3Int64)(next(in) % 50) : PICK(in, INTS);
        }
        fmi3SetInt64(c, VRS(a), a.nvr, VALS(a, v), a.nvalues);
        break;
    }
    case 3: {
        fmi3Boolean v[4];
        for (size_t k = 0; k < 4; k++) {
            v[k] = (fmi3Boolean)(next(in) & 1);
        }
        fmi3SetBoolean(c, VRS(a), a.nvr, VALS(a, v), a.nvalues);
        break;
    }
    default: {
        char text[600];
        fmi3String v[4];
        const size_t len = next(in) * 2;
        memset(text, 'x', len);
        text[len] = '\0';
        for (size_t k = 0; k < 4; k++) {
            v[k] = next(in) & 1 ? text : next(in) & 1 ? NULL : PICK(in, STRINGS);
        }
        fmi3SetString(c, VRS(a), a.nvr, VALS(a, v), a.nvalues);
        break;
    }
    }
}

static void get_values(fmi3Instance c, Input *in)
{
    const Args a = args(in);
    fmi3Float64 r[4];
    fmi3Int32 i[4];
    fmi3Int64 l[4];
    fmi3Boolean b[4];
    fmi3String s[4];
    fmi3GetFloat64(c, VRS(a), a.nvr, VALS(a, r), a.nvalues);
    fmi3GetInt32(c, VRS(a), a.nvr, VALS(a, i), a.nvalues);
    fmi3GetInt64(c, VRS(a), a.nvr, VALS(a, l), a.nvalues);
    fmi3GetBoolean(c, VRS(a), a.nvr, VALS(a, b), a.nvalues);
    fmi3GetString(c, VRS(a), a.nvr, VALS(a, s), a.nvalues);
}

static void states(fmi3Instance c, Input *in, fmi3FMUState st[2], unsigned op)
{
    const int k = next(in) & 1;
    size_t n = 0;
    uint8_t *bytes;
    switch (op) {
    case 0: fmi3GetFMUState(c, &st[k]); break;
    case 1:
        if (st[k]) {
            fmi3SetFMUState(c, st[k]);
        }
        break;
    case 2: fmi3FreeFMUState(c, &st[k]); break;
    default:
        if (!st[k] || fmi3SerializedFMUStateSize(c, st[k], &n) != fmi3OK || !(bytes = malloc(n))) {
            break;
        }
        if (fmi3SerializeFMUState(c, st[k], bytes, n) == fmi3OK) {
            if (n && next(in) & 1) {
                bytes[next(in) * 31 % n] ^= (uint8_t)(1u << (next(in) % 8));
            }
            fmi3DeserializeFMUState(c, bytes, n, &st[k ^ 1]);
        }
        free(bytes);
        break;
    }
}

static void events(fmi3Instance c, Input *in, unsigned op)
{
    const Args a = args(in);
    fmi3Boolean f[5];
    fmi3Float64 r[4], x[16];
    size_t n = 0;
    switch (op) {
    case 0: fmi3EnterEventMode(c); break;
    case 1: fmi3UpdateDiscreteStates(c, &f[0], &f[1], &f[2], &f[3], &f[4], &r[0]); break;
    case 2: fmi3EnterStepMode(c); break;
    case 3: fmi3EnterContinuousTimeMode(c); break;
    case 4: fmi3SetTime(c, PICK(in, REALS)); break;
    case 5:
        if (fmi3GetNumberOfContinuousStates(c, &n) == fmi3OK && n <= 16) {
            fmi3GetContinuousStates(c, x, n);
            fmi3GetContinuousStateDerivatives(c, x, n);
        }
        if (fmi3GetNumberOfEventIndicators(c, &n) == fmi3OK && n <= 16) {
            fmi3GetEventIndicators(c, x, n);
        }
        break;
    case 6: {
        const fmi3Int32 order[4] = {1, 2, 0, -1};
        fmi3GetOutputDerivatives(c, VRS(a), a.nvr, order, VALS(a, r), a.nvalues);
        break;
    }
    case 7: {
        const fmi3Float64 seed[4] = {1, 1, 1, 1};
        fmi3GetDirectionalDerivative(c, VRS(a), a.nvr, a.vr, a.nvr, seed, a.nvalues,
                                     VALS(a, r), a.nvalues);
        break;
    }
    default: {
        fmi3IntervalQualifier q[4];
        fmi3Clock clocks[4];
        fmi3GetIntervalDecimal(c, VRS(a), a.nvr, VALS(a, r), q);
        fmi3GetClock(c, VRS(a), a.nvr, VALS(a, clocks));
        break;
    }
    }
}

static void step(fmi3Instance c, Input *in)
{
    const double t = PICK(in, REALS), h = PICK(in, REALS);
    fmi3Boolean event, terminate, early;
    fmi3Float64 last;
    if (next(in) % 8 == 0) { /* a NULL output argument */
        fmi3DoStep(c, t, h > 0.01 ? 0.01 : h, fmi3False, NULL, &terminate, &early, &last);
        return;
    }
    fmi3DoStep(c, t, h > 0.01 ? 0.01 : h, (fmi3Boolean)(next(in) & 1), &event, &terminate,
               &early, &last);
}

static void release(fmi3Instance *c, fmi3FMUState st[2])
{
    for (int k = 0; k < 2; k++) {
        fmi3FreeFMUState(*c, &st[k]);
    }
    fmi3FreeInstance(*c);
    *c = NULL;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    Input in = {data, size};
    fmi3Instance c = NULL;
    fmi3FMUState st[2] = {NULL, NULL};
    int calls = 0;
    while (in.n && calls++ < 64) {
        const unsigned op = next(&in) % 32;
        if (!c) {
            if (op == 0) {
                c = instantiate(&in);
            }
            continue;
        }
        if (op == 1) {
            fmi3EnterInitializationMode(c, (fmi3Boolean)(next(&in) & 1), PICK(&in, REALS),
                                        PICK(&in, REALS), (fmi3Boolean)(next(&in) & 1),
                                        PICK(&in, REALS));
        } else if (op == 2) {
            fmi3ExitInitializationMode(c);
        } else if (op >= 3 && op <= 5) {
            step(c, &in);
        } else if (op >= 6 && op <= 10) {
            set_values(c, &in, op - 6);
        } else if (op == 11 || op == 12) {
            get_values(c, &in);
        } else if (op >= 13 && op <= 16) {
            states(c, &in, st, op - 13);
        } else if (op >= 17 && op <= 25) {
            events(c, &in, op - 17);
        } else if (op == 26) {
            fmi3Terminate(c);
        } else if (op == 27) {
            fmi3Reset(c);
        } else if (op == 28) {
            fmi3SetDebugLogging(c, (fmi3Boolean)(next(&in) & 1), 0, NULL);
        } else if (op == 31) {
            release(&c, st);
        }
    }
    if (c) {
        release(&c, st);
    }
    return 0;
}

#ifndef FUZZ_LIBFUZZER
#include "replay.h"
int main(int argc, char **argv)
{
    if (argc == 3 && strcmp(argv[1], "--seed") == 0) { /* a run: set up, step, state, free */
        static const uint8_t run[] = {0, 0,  6, 1, 3, 0, 1, 1, 0, 0, 0, 0, 2,  3, 5, 0, 1,
                                      4, 14, 6, 1, 0, 4, 11, 2, 1, 2, 13, 0, 16, 0, 0, 0,
                                      14, 0, 3, 14, 0, 1, 17, 0, 19, 0, 26, 27, 31};
        return write_input(argv[2], "run", run, sizeof run);
    }
    return replay_files(argc, argv);
}
#endif
