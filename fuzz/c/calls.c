/* libFuzzer target: FMI 2.0 call sequences with hostile arguments against a native FMU's glue.
 *
 * Compiled with the FMU's shipped sources/ like state.c (fuzz/targets.py). Each input byte picks
 * a call (instantiate, setup, initialize, step, set/get of every type, states, serialize /
 * deserialize, terminate, reset, free) and the bytes after it its arguments (value references
 * of any number, NaN/inf/huge/negative reals, odd strings), so that the state table's edges are
 * tried in any order. Calls on a freed instance are not made (the pointer is gone: that is the
 * host's bug, not the FMU's). The two work-bound parameters are kept small when set (a legal
 * huge bound only measures how long a huge step takes). Refusals are expected; crashes, leaks,
 * sanitizer reports and hangs are findings. Without -DFUZZ_LIBFUZZER main() replays files. */
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "glue.h" /* after the FMI header: N_VARS, VARS[] */
#include "guid.h"

static const double REALS[] = {0.0, -0.0, 1.0, -1.0, 0.3, 1.0 / 400, 1e308, -1e308, 0.0 / 0.0,
                               1.0 / 0.0, -1.0 / 0.0, 5e-324, 1e-300, 9007199254740992.0, 0.01};
static const int INTS[] = {0, 1, -1, 2, 7, 2147483647, -2147483647 - 1, 1000, -1000};
static const char *STRINGS[] = {"observer", "difference", "measured", "", "%s%n%x", "\xff\xfe"};

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status,
                   fmi2String category, fmi2String message, ...)
{
    (void)env, (void)name, (void)status, (void)category, (void)message;
}
static const fmi2CallbackFunctions CALLBACKS = {logger, calloc, free, NULL, NULL};

#include "input.h" /* Input, next(), PICK */

static fmi2ValueReference any_vr(Input *in)
{
    const unsigned b = next(in);
    return b == 255 ? 0xFFFFFFFFu : b < 250 ? (fmi2ValueReference)(b % (N_VARS + 3)) : b;
}

static int work_bound(fmi2ValueReference vr)
{
    return vr < N_VARS && (strcmp(VARS[vr].name, "max_rhs_evaluations") == 0 ||
                           strcmp(VARS[vr].name, "max_samples_per_step") == 0);
}

static void set_reals(Input *in, fmi2Component c, const fmi2ValueReference *vr, size_t nvr)
{
    fmi2Real v[4];
    for (size_t k = 0; k < nvr; k++) {
        v[k] = PICK(in, REALS);
    }
    fmi2SetReal(c, vr, nvr, v);
}

static void set_integers(Input *in, fmi2Component c, const fmi2ValueReference *vr, size_t nvr)
{
    fmi2Integer v[4];
    for (size_t k = 0; k < nvr; k++) {
        v[k] = work_bound(vr[k]) ? (fmi2Integer)(next(in) % 50) : PICK(in, INTS);
    }
    fmi2SetInteger(c, vr, nvr, v);
}

static void set_booleans(Input *in, fmi2Component c, const fmi2ValueReference *vr, size_t nvr)
{
    fmi2Boolean v[4];
    for (size_t k = 0; k < nvr; k++) {
        v[k] = (fmi2Boolean)PICK(in, INTS);
    }
    fmi2SetBoolean(c, vr, nvr, v);
}

static void set_strings(Input *in, fmi2Component c, const fmi2ValueReference *vr, size_t nvr)
{
    char text[600];
    fmi2String v[4];
    const size_t len = next(in) * 2;
    memset(text, 'x', len);
    text[len] = '\0';
    for (size_t k = 0; k < nvr; k++) {
        v[k] = next(in) & 1 ? text : PICK(in, STRINGS);
    }
    fmi2SetString(c, vr, nvr, v);
}

static void get_all(fmi2Component c, const fmi2ValueReference *vr, size_t nvr)
{
    fmi2Real r[4];
    fmi2Integer i[4];
    fmi2Boolean b[4];
    fmi2String s[4];
    fmi2GetReal(c, vr, nvr, r);
    fmi2GetInteger(c, vr, nvr, i);
    fmi2GetBoolean(c, vr, nvr, b);
    fmi2GetString(c, vr, nvr, s);
}

/* serialize one state slot, maybe flip a bit, deserialize into the other */
static void round_trip(Input *in, fmi2Component c, fmi2FMUstate states[2])
{
    const int k = next(in) & 1;
    size_t n = 0;
    uint8_t *bytes;
    if (!states[k] || fmi2SerializedFMUstateSize(c, states[k], &n) != fmi2OK ||
        !(bytes = malloc(n))) {
        return;
    }
    if (fmi2SerializeFMUstate(c, states[k], (fmi2Byte *)bytes, n) == fmi2OK) {
        if (n && next(in) & 1) {
            bytes[next(in) * 31 % n] ^= (uint8_t)(1u << (next(in) % 8));
        }
        fmi2DeSerializeFMUstate(c, (const fmi2Byte *)bytes, n, &states[k ^ 1]);
    }
    free(bytes);
}

static void free_all(fmi2Component c, fmi2FMUstate states[2])
{
    for (int k = 0; k < 2; k++) {
        fmi2FreeFMUstate(c, &states[k]);
    }
    fmi2FreeInstance(c);
}

/* One call, op 0..19 (the input byte's meaning: keep it, the committed corpora rely on it), on
 * the instance *c (NULL for op 0 only). */
static void call(Input *in, unsigned op, fmi2Component *c, fmi2FMUstate states[2],
                 const fmi2ValueReference *vr, size_t nvr)
{
    switch (op) {
    case 0:
        if (!*c) {
            *c = fmi2Instantiate("fuzz", next(in) & 1 ? fmi2ModelExchange : fmi2CoSimulation,
                                 next(in) & 1 ? "{wrong}" : MODEL_GUID, "", &CALLBACKS, fmi2False,
                                 (fmi2Boolean)(next(in) & 1));
        }
        break;
    case 1:
        fmi2SetupExperiment(*c, (fmi2Boolean)(next(in) % 3), PICK(in, REALS), PICK(in, REALS),
                            (fmi2Boolean)(next(in) % 3), PICK(in, REALS));
        break;
    case 2: fmi2EnterInitializationMode(*c); break;
    case 3: fmi2ExitInitializationMode(*c); break;
    case 4: {
        const double t = PICK(in, REALS), h = PICK(in, REALS);
        fmi2DoStep(*c, t, h > 0.01 ? 0.01 : h, (fmi2Boolean)(next(in) % 3));
        break;
    }
    case 5: set_reals(in, *c, vr, nvr); break;
    case 6: set_integers(in, *c, vr, nvr); break;
    case 7: set_booleans(in, *c, vr, nvr); break;
    case 8: set_strings(in, *c, vr, nvr); break;
    case 9: get_all(*c, vr, nvr); break;
    case 10: fmi2GetFMUstate(*c, &states[next(in) & 1]); break;
    case 11: {
        fmi2FMUstate s = states[next(in) & 1];
        if (s) {
            fmi2SetFMUstate(*c, s);
        }
        break;
    }
    case 12: fmi2FreeFMUstate(*c, &states[next(in) & 1]); break;
    case 13: round_trip(in, *c, states); break;
    case 14: fmi2Terminate(*c); break;
    case 15: fmi2Reset(*c); break;
    case 16: {
        fmi2Real r[4];
        const fmi2Integer order[4] = {1, 2, 0, -1};
        fmi2GetRealOutputDerivatives(*c, vr, nvr, order, r);
        break;
    }
    case 17: {
        fmi2Real known[4] = {1, 1, 1, 1}, out[4];
        fmi2GetDirectionalDerivative(*c, vr, nvr, vr, nvr, known, out);
        break;
    }
    case 18: fmi2SetDebugLogging(*c, (fmi2Boolean)(next(in) & 1), 0, NULL); break;
    default:
        free_all(*c, states);
        *c = NULL;
        break;
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    Input in = {data, size};
    fmi2Component c = NULL;
    fmi2FMUstate states[2] = {NULL, NULL};
    int calls = 0;
    while (in.n && calls++ < 64) {
        const unsigned op = next(&in) % 20;
        fmi2ValueReference vr[4];
        size_t nvr = next(&in) % 4; /* 0..3 value references */
        for (size_t k = 0; k < nvr; k++) {
            vr[k] = any_vr(&in);
        }
        if (!c && op != 0) {
            continue;
        }
        call(&in, op, &c, states, vr, nvr);
    }
    if (c) {
        free_all(c, states);
    }
    return 0;
}

#ifndef FUZZ_LIBFUZZER
#include "replay.h"
int main(int argc, char **argv)
{
    if (argc == 3 && strcmp(argv[1], "--seed") == 0) { /* a run: set up, step, state, free */
        static const uint8_t run[] = {0, 0, 0, 0, 0,  1, 0, 1, 0, 0, 0, 0, 2, 0, 3, 0, 4, 0,
                                      5, 5, 0, 4, 0, 9, 2, 0, 1, 10, 0, 0, 13, 0, 0, 0, 11, 0,
                                      1, 4, 0, 4, 5, 0, 14, 0, 15, 0, 19, 0};
        return write_input(argv[2], "run", run, sizeof run);
    }
    return replay_files(argc, argv);
}
#endif
