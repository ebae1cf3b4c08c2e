/* libFuzzer target: hostile serialized FMU states fed to a native FMU's deserializer.
 *
 * Compiled together with the FMU's own sources/ (as shipped in the .fmu, see fuzz/targets.py),
 * once per model and FMI version: -DFUZZ_FMI3 selects fmi3DeserializeFMUState, else
 * fmi2DeSerializeFMUstate. Per input: instantiate, initialize, deserialize the bytes; a state
 * that is accepted is set, stepped, its outputs read and it is serialized again and freed.
 * Nothing may crash, leak, hang or trip a sanitizer; refusals are the expected outcome.
 *
 * Input: byte 0 is a mode, the rest the serialized state. Mode bit 0 set: the harness writes the
 * right CRC-32 into the header (bytes 60..63, over bytes 0..59 and 64..end) before the call, so
 * that mutations get past the checksum to the field checks (check_snapshot, model_check_state);
 * bits 1-2: how many steps (0..3) to take after the state is set.
 *
 * Without -DFUZZ_LIBFUZZER main() below replays files (tests/test_fuzz_corpora.py); with
 * `--seed DIR` it writes the serialized states of a fresh and of a stepped instance as seeds. */
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "guid.h"

#ifdef FUZZ_FMI3
#include "fmi3Functions.h"
#include "glue.h" /* after the FMI header: N_VARS */
#include "instance.h" /* crc32_update: re-signs a mutated state */
typedef fmi3Instance Inst;
typedef fmi3FMUState State;
#define OK fmi3OK
#else
#include "fmi2Functions.h"
#include "glue.h" /* after the FMI header: N_VARS */
#include "instance.h" /* crc32_update: re-signs a mutated state */
typedef fmi2Component Inst;
typedef fmi2FMUstate State;
#define OK fmi2OK
#endif

#define DT (1.0 / 400.0)

#ifdef FUZZ_FMI3
static void logger3(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category,
                    fmi3String message)
{
    (void)env, (void)status, (void)category, (void)message;
}

static Inst make(void)
{
    Inst c = fmi3InstantiateCoSimulation("fuzz", MODEL_GUID, "", fmi3False, fmi3False, fmi3False,
                                         fmi3False, NULL, 0, NULL, logger3, NULL);
    if (c && fmi3EnterInitializationMode(c, fmi3False, 0.0, 0.0, fmi3False, 0.0) == OK) {
        fmi3ExitInitializationMode(c);
    }
    return c;
}
static int deserialize(Inst c, const uint8_t *b, size_t n, State *s)
{
    return fmi3DeserializeFMUState(c, b, n, s);
}
static int serialize(Inst c, State s, uint8_t **out, size_t *n)
{
    if (fmi3SerializedFMUStateSize(c, s, n) != OK || !(*out = malloc(*n))) {
        return 1;
    }
    return fmi3SerializeFMUState(c, s, *out, *n) != OK;
}
static void exercise(Inst c, State s, int steps)
{
    fmi3Boolean event, terminate, early;
    fmi3Float64 last, values[N_VARS];
    fmi3ValueReference vrs[N_VARS];
    uint8_t *bytes = NULL;
    size_t n = 0;
    for (int vr = 0; vr < N_VARS; vr++) {
        vrs[vr] = (fmi3ValueReference)vr;
    }
    if (fmi3SetFMUState(c, s) != OK) {
        return;
    }
    for (int k = 0; k < steps; k++) {
        fmi3DoStep(c, k * DT, DT, fmi3True, &event, &terminate, &early, &last);
    }
    for (int vr = 0; vr < N_VARS; vr++) { /* one at a time: a non-Float64 is refused alone */
        fmi3GetFloat64(c, &vrs[vr], 1, &values[vr], 1);
    }
    if (fmi3GetFMUState(c, &s) == OK && serialize(c, s, &bytes, &n) == 0) {
        State again = NULL;
        if (deserialize(c, bytes, n, &again) == OK) {
            fmi3FreeFMUState(c, &again);
        }
    }
    free(bytes);
}
static void release_state(Inst c, State *s)
{
    if (*s) {
        fmi3FreeFMUState(c, s);
    }
}
static void release(Inst c, State *s)
{
    release_state(c, s);
    fmi3FreeInstance(c);
}
static int snapshot(Inst c, State *s) { return fmi3GetFMUState(c, s) != OK; }
static int step(Inst c, double t)
{
    fmi3Boolean event, terminate, early;
    fmi3Float64 last;
    return fmi3DoStep(c, t, DT, fmi3True, &event, &terminate, &early, &last) != OK;
}
#else
static void logger2(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status,
                    fmi2String category, fmi2String message, ...)
{
    (void)env, (void)name, (void)status, (void)category, (void)message;
}
static const fmi2CallbackFunctions CALLBACKS = {logger2, calloc, free, NULL, NULL};

static Inst make(void)
{
    Inst c = fmi2Instantiate("fuzz", fmi2CoSimulation, MODEL_GUID, "", &CALLBACKS, fmi2False,
                             fmi2False);
    if (c && fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) == OK &&
        fmi2EnterInitializationMode(c) == OK) {
        fmi2ExitInitializationMode(c);
    }
    return c;
}
static int deserialize(Inst c, const uint8_t *b, size_t n, State *s)
{
    return fmi2DeSerializeFMUstate(c, (const fmi2Byte *)b, n, s);
}
static int serialize(Inst c, State s, uint8_t **out, size_t *n)
{
    if (fmi2SerializedFMUstateSize(c, s, n) != OK || !(*out = malloc(*n))) {
        return 1;
    }
    return fmi2SerializeFMUstate(c, s, (fmi2Byte *)*out, *n) != OK;
}
static void exercise(Inst c, State s, int steps)
{
    fmi2Real values[N_VARS];
    fmi2ValueReference vrs[N_VARS];
    uint8_t *bytes = NULL;
    size_t n = 0;
    for (int vr = 0; vr < N_VARS; vr++) {
        vrs[vr] = (fmi2ValueReference)vr;
    }
    if (fmi2SetFMUstate(c, s) != OK) {
        return;
    }
    for (int k = 0; k < steps; k++) {
        fmi2DoStep(c, k * DT, DT, fmi2True);
    }
    for (int vr = 0; vr < N_VARS; vr++) { /* one at a time: a non-Real is refused alone */
        fmi2GetReal(c, &vrs[vr], 1, &values[vr]);
    }
    if (fmi2GetFMUstate(c, &s) == OK && serialize(c, s, &bytes, &n) == 0) {
        State again = NULL;
        if (deserialize(c, bytes, n, &again) == OK) {
            fmi2FreeFMUstate(c, &again);
        }
    }
    free(bytes);
}
static void release_state(Inst c, State *s)
{
    if (*s) {
        fmi2FreeFMUstate(c, s);
    }
}
static void release(Inst c, State *s)
{
    release_state(c, s);
    fmi2FreeInstance(c);
}
static int snapshot(Inst c, State *s) { return fmi2GetFMUstate(c, s) != OK; }
static int step(Inst c, double t) { return fmi2DoStep(c, t, DT, fmi2True) != OK; }
#endif

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    uint8_t *bytes;
    size_t n;
    State s = NULL;
    Inst c;
    if (size < 1) {
        return 0;
    }
    n = size - 1;
    bytes = malloc(n ? n : 1); /* a buffer of exactly n bytes: ASan sees any over-read */
    if (!bytes) {
        return 0;
    }
    memcpy(bytes, data + 1, n);
    if ((data[0] & 1) && n >= 64) {
        uint32_t crc = crc32_update(crc32_update(0, bytes, 60), bytes + 64, n - 64);
        memcpy(bytes + 60, &crc, sizeof crc);
    }
    c = make();
    if (c) {
        if (deserialize(c, bytes, n, &s) == OK) {
            exercise(c, s, (data[0] >> 1) & 3);
        }
        release(c, &s);
    }
    free(bytes);
    return 0;
}

#ifndef FUZZ_LIBFUZZER
#include "replay.h"
static int write_seed(const char *dir, const char *name, Inst c, int mode)
{
    char path[4096];
    uint8_t *bytes = NULL;
    size_t n = 0;
    State s = NULL;
    FILE *out;
    int bad = snapshot(c, &s) || serialize(c, s, &bytes, &n);
    snprintf(path, sizeof path, "%s/%s", dir, name);
    out = bad ? NULL : fopen(path, "wb");
    bad = !out || fputc(mode, out) == EOF || fwrite(bytes, 1, n, out) != n;
    if (out && fclose(out) != 0) {
        bad = 1;
    }
    free(bytes);
    release_state(c, &s);
    return bad;
}

int main(int argc, char **argv)
{
    if (argc == 3 && strcmp(argv[1], "--seed") == 0) { /* seeds: a fresh and a stepped state */
        Inst c = make();
        State none = NULL;
        int bad = !c || write_seed(argv[2], "initialized", c, 0);
        for (int k = 0; c && k < 40; k++) {
            bad |= step(c, k * DT);
        }
        bad |= !c || write_seed(argv[2], "stepped", c, 2);
        if (c) {
            release(c, &none);
        }
        return bad;
    }
    return replay_files(argc, argv);
}
#endif
