/* libFuzzer target: hostile parameter values for the closed-loop FMU (native/closedloop, the
 * plant and the controller stepped inside one FMI 3.0 co-simulation FMU).
 *
 * Compiled with PaperClosedLoop-observer.fmu's shipped sources/ (fuzz/targets.py). Per input:
 * instantiate; then groups of 3 bytes set parameters: byte 0 picks a parameter (the table
 * VARS[] of its config.h) and whether it is set before or during initialization mode, bytes 1-2
 * its value (Float64: NaN, inf, 5e-324, huge, negative, or two bytes as a float's exponent and
 * sign; Int32/Int64: extremes; Boolean; String: odd texts). Then initialize and take up to 8
 * steps of 1/400 s, reading every Float64 output after each. The work bounds (the parameters
 * max_rhs_evaluations, max_samples_per_step, euler_substeps) get small values: a legal huge
 * bound only measures how long a huge step takes. Refusals are expected; crashes, leaks,
 * sanitizer reports and hangs are findings, and so is an output that is not finite after
 * initialization or a step that returned fmi3OK (the core refuses such a step). Without
 * -DFUZZ_LIBFUZZER main() replays files. */
#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"
#include "glue.h" /* after the FMI header: N_VARS, VARS[] */
#include "guid.h"

static const double REALS[] = {0.0, -0.0, 1.0, -1.0, 0.3, 1.0 / 400, 1e308, -1e308, 0.0 / 0.0,
                               1.0 / 0.0, -1.0 / 0.0, 5e-324, 1e-300, 9007199254740992.0, 1e6,
                               -1e-9};
static const int64_t INTS[] = {0, 1, -1, 2, 3, 7, 2147483647, -2147483647 - 1, INT64_MAX,
                               INT64_MIN, 4294967297LL};
static const char *STRINGS[] = {"observer", "difference", "measured", "", "%s%n", "\xff\xfe",
                                "zoh", "tustin", "backward_euler", "exact"};

static void logger(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category,
                   fmi3String message)
{
    (void)env;
    if (getenv("FUZZ_LOG")) { /* FUZZ_LOG=1 replay-binary FILE: what the FMU said */
        fprintf(stderr, "[%d] %s: %s\n", (int)status, category, message);
    }
}

static int work_bound(const char *name)
{
    return strstr(name, "max_rhs_evaluations") || strstr(name, "max_samples_per_step") ||
           strstr(name, "euler_substeps");
}

static double real_value(uint8_t a, uint8_t b)
{
    if (a < 128) {
        return REALS[a % (sizeof REALS / sizeof REALS[0])];
    }
    return ldexp(b & 1 ? -1.0 - b / 512.0 : 1.0 + b / 512.0, (int)(a & 0x7F) * 16 - 1024);
}

static void set_parameter(fmi3Instance c, uint8_t pick, uint8_t a, uint8_t b)
{
    const fmi3ValueReference vr = (fmi3ValueReference)(pick % N_VARS);
    const VarInfo *v = &VARS[vr];
    if (v->type == T_REAL) {
        const double x = real_value(a, b);
        fmi3SetFloat64(c, &vr, 1, &x, 1);
    } else if (v->type == T_INTEGER) {
        const int64_t x = work_bound(v->name) ? (int64_t)(a % 50) - 1
                                              : INTS[a % (sizeof INTS / sizeof INTS[0])];
        if (b & 1) {
            fmi3SetInt64(c, &vr, 1, &x, 1);
        } else {
            const fmi3Int32 y = (fmi3Int32)x;
            fmi3SetInt32(c, &vr, 1, &y, 1);
        }
    } else if (v->type == T_BOOLEAN) {
        const fmi3Boolean x = (fmi3Boolean)(a & 1);
        fmi3SetBoolean(c, &vr, 1, &x, 1);
    } else {
        const fmi3String x = STRINGS[a % (sizeof STRINGS / sizeof STRINGS[0])];
        fmi3SetString(c, &vr, 1, &x, 1);
    }
}

/* Every Float64 output after a call that returned fmi3OK: finite, or abort. */
static void check_outputs(fmi3Instance c)
{
    for (fmi3ValueReference vr = 0; vr < N_VARS; vr++) {
        double x;
        if (VARS[vr].type == T_REAL && VARS[vr].causality == C_OUTPUT &&
            fmi3GetFloat64(c, &vr, 1, &x, 1) == fmi3OK && !isfinite(x)) {
            fprintf(stderr, "output %s is %g after a call that returned fmi3OK\n", VARS[vr].name,
                    x);
            abort();
        }
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    fmi3Instance c;
    size_t k = 1;
    int initializing = 0, ok;
    if (size < 1) {
        return 0;
    }
    c = fmi3InstantiateCoSimulation("fuzz", MODEL_GUID, "", fmi3False, fmi3False, fmi3False,
                                    fmi3False, NULL, 0, NULL, logger, NULL);
    if (!c) {
        return 0;
    }
    for (; k + 3 <= size && k < 1 + 3 * 24; k += 3) {
        if (!initializing && data[k] & 0x80) { /* the rest during initialization mode */
            initializing = 1;
            fmi3EnterInitializationMode(c, fmi3False, 0.0, 0.0, fmi3False, 0.0);
        }
        set_parameter(c, data[k] & 0x7F, data[k + 1], data[k + 2]);
    }
    ok = (initializing || fmi3EnterInitializationMode(c, fmi3False, 0.0, 0.0, fmi3False, 0.0) ==
                              fmi3OK) &&
         fmi3ExitInitializationMode(c) == fmi3OK;
    if (ok) {
        check_outputs(c);
    }
    for (int n = 0; ok && n < data[0] % 9; n++) {
        fmi3Boolean event, terminate, early;
        fmi3Float64 last;
        ok = fmi3DoStep(c, n / 400.0, 1.0 / 400.0, fmi3False, &event, &terminate, &early,
                        &last) == fmi3OK;
        if (ok) {
            check_outputs(c);
        }
    }
    fmi3FreeInstance(c);
    return 0;
}

#ifndef FUZZ_LIBFUZZER
#include "replay.h"
int main(int argc, char **argv)
{
    if (argc == 3 && strcmp(argv[1], "--seed") == 0) { /* the defaults, 8 steps; one value */
        static const uint8_t runs[][4] = {{8}, {8, 3, 0, 0}, {4, 0x85, 1, 0}};
        for (size_t r = 0; r < sizeof runs / sizeof runs[0]; r++) {
            char name[16];
            snprintf(name, sizeof name, "run%u", (unsigned)r);
            if (write_input(argv[2], name, runs[r], r ? 4 : 1)) {
                return 1;
            }
        }
        return 0;
    }
    return replay_files(argc, argv);
}
#endif
