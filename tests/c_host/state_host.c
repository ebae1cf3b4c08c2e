/* FMU states on every platform, with no Python in the process: loads one native FMU library
 * (FMI 2.0 co-simulation), initializes it, takes STEPS steps of 1/400 s with the Real inputs
 * given, then either writes its serialized state to a file ("write OUT") or deserializes each
 * file given ("read FILE..."), printing one line "FILE STATUS" per file; a state accepted is set
 * and one more step taken ("FILE 0 step=STATUS"). Used by tests/test_native_state_integrity.py,
 * cross-compiled for win64 (run under wine) and aarch64 Linux (run under qemu).
 *
 * usage: state_host LIB GUID STEPS INPUTS write OUT | read FILE...
 *   INPUTS  comma-separated Real values "12=30,13=20" (value reference=value), or "-"
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "host_common.h"


static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status,
                   fmi2String category, fmi2String message, ...)
{
    (void)env, (void)name, (void)category;
    printf("log %d %s\n", (int)status, message);
}

#define FN(type, name) type *name = (type *)sym(lib, #name)

int main(int argc, char **argv)
{
    void *lib;
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    fmi2Component c;
    fmi2FMUstate state = NULL;
    size_t size = 0;
    int steps;
    if (argc < 7) {
        fprintf(stderr, "usage: state_host LIB GUID STEPS INPUTS write OUT | read FILE...\n");
        return 2;
    }
    lib = open_library(argv[1]);
    if (!lib) {
        fprintf(stderr, "cannot load %s\n", argv[1]);
        return 1;
    }
    FN(fmi2InstantiateTYPE, fmi2Instantiate);
    FN(fmi2SetupExperimentTYPE, fmi2SetupExperiment);
    FN(fmi2EnterInitializationModeTYPE, fmi2EnterInitializationMode);
    FN(fmi2ExitInitializationModeTYPE, fmi2ExitInitializationMode);
    FN(fmi2SetRealTYPE, fmi2SetReal);
    FN(fmi2DoStepTYPE, fmi2DoStep);
    FN(fmi2GetFMUstateTYPE, fmi2GetFMUstate);
    FN(fmi2SetFMUstateTYPE, fmi2SetFMUstate);
    FN(fmi2SerializedFMUstateSizeTYPE, fmi2SerializedFMUstateSize);
    FN(fmi2SerializeFMUstateTYPE, fmi2SerializeFMUstate);
    FN(fmi2DeSerializeFMUstateTYPE, fmi2DeSerializeFMUstate);
    c = fmi2Instantiate("s", fmi2CoSimulation, argv[2], "", &cb, fmi2False, fmi2False);
    if (!c || fmi2SetupExperiment(c, 0, 0.0, 0.0, 0, 0.0) != fmi2OK) {
        return 1;
    }
    for (char *p = strcmp(argv[4], "-") ? strtok(argv[4], ",") : NULL; p; p = strtok(NULL, ",")) {
        const fmi2ValueReference vr = (fmi2ValueReference)strtoul(p, &p, 10);
        const fmi2Real value = strtod(p + 1, NULL);
        if (fmi2SetReal(c, &vr, 1, &value) != fmi2OK) {
            return 1;
        }
    }
    if (fmi2EnterInitializationMode(c) != fmi2OK || fmi2ExitInitializationMode(c) != fmi2OK) {
        return 1;
    }
    steps = atoi(argv[3]);
    for (int k = 0; k < steps; k++) {
        if (fmi2DoStep(c, k / 400.0, 1 / 400.0, fmi2True) != fmi2OK) {
            return 1;
        }
    }
    if (strcmp(argv[5], "write") == 0) {
        FILE *out = fopen(argv[6], "wb");
        char *buf;
        if (!out || fmi2GetFMUstate(c, &state) != fmi2OK ||
            fmi2SerializedFMUstateSize(c, state, &size) != fmi2OK || !(buf = malloc(size)) ||
            fmi2SerializeFMUstate(c, state, buf, size) != fmi2OK ||
            fwrite(buf, 1, size, out) != size || fclose(out) != 0) {
            return 1;
        }
        printf("wrote %lu bytes\n", (unsigned long)size);
        return 0;
    }
    for (int k = 6; k < argc; k++) {
        FILE *in = fopen(argv[k], "rb");
        static char buf[1 << 16];
        fmi2FMUstate restored = NULL;
        fmi2Status status;
        size_t n;
        if (!in) {
            return 1;
        }
        n = fread(buf, 1, sizeof buf, in);
        fclose(in);
        status = fmi2DeSerializeFMUstate(c, buf, n, &restored);
        if (status == fmi2OK) {
            printf("%s %d step=%d\n", argv[k], (int)status,
                   fmi2SetFMUstate(c, restored) == fmi2OK &&
                           fmi2DoStep(c, steps / 400.0, 1 / 400.0, fmi2True) == fmi2OK
                       ? 0
                       : 1);
        } else {
            printf("%s %d\n", argv[k], (int)status);
        }
    }
    return 0;
}
