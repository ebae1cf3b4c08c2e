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

static const fmi2CallbackFunctions CALLBACKS = {logger, calloc, free, NULL, NULL};

/* The FMI 2.0 functions the host calls, all looked up before the first call. */
typedef struct {
    fmi2InstantiateTYPE *fmi2Instantiate;
    fmi2SetupExperimentTYPE *fmi2SetupExperiment;
    fmi2EnterInitializationModeTYPE *fmi2EnterInitializationMode;
    fmi2ExitInitializationModeTYPE *fmi2ExitInitializationMode;
    fmi2SetRealTYPE *fmi2SetReal;
    fmi2DoStepTYPE *fmi2DoStep;
    fmi2GetFMUstateTYPE *fmi2GetFMUstate;
    fmi2SetFMUstateTYPE *fmi2SetFMUstate;
    fmi2SerializedFMUstateSizeTYPE *fmi2SerializedFMUstateSize;
    fmi2SerializeFMUstateTYPE *fmi2SerializeFMUstate;
    fmi2DeSerializeFMUstateTYPE *fmi2DeSerializeFMUstate;
} Fmi;

#define FN(type, name) f->name = (type *)sym(lib, #name)

static void load(void *lib, Fmi *f)
{
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
}

/* The instance set up with INPUTS, initialized and STEPS steps on; NULL when a call failed. */
static fmi2Component run(const Fmi *f, const char *guid, char *inputs, int steps)
{
    fmi2Component c = f->fmi2Instantiate("s", fmi2CoSimulation, guid, "", &CALLBACKS, fmi2False,
                                         fmi2False);
    if (!c || f->fmi2SetupExperiment(c, 0, 0.0, 0.0, 0, 0.0) != fmi2OK) {
        return NULL;
    }
    for (char *p = strcmp(inputs, "-") ? strtok(inputs, ",") : NULL; p; p = strtok(NULL, ",")) {
        const fmi2ValueReference vr = (fmi2ValueReference)strtoul(p, &p, 10);
        const fmi2Real value = strtod(p + 1, NULL);
        if (f->fmi2SetReal(c, &vr, 1, &value) != fmi2OK) {
            return NULL;
        }
    }
    if (f->fmi2EnterInitializationMode(c) != fmi2OK ||
        f->fmi2ExitInitializationMode(c) != fmi2OK) {
        return NULL;
    }
    for (int k = 0; k < steps; k++) {
        if (f->fmi2DoStep(c, k / 400.0, 1 / 400.0, fmi2True) != fmi2OK) {
            return NULL;
        }
    }
    return c;
}

/* "write OUT": the serialized state into the file; 0, or 1 when anything failed. */
static int write_state(const Fmi *f, fmi2Component c, const char *path)
{
    fmi2FMUstate state = NULL;
    size_t size = 0;
    FILE *out = fopen(path, "wb");
    char *buf;
    if (!out || f->fmi2GetFMUstate(c, &state) != fmi2OK ||
        f->fmi2SerializedFMUstateSize(c, state, &size) != fmi2OK || !(buf = malloc(size)) ||
        f->fmi2SerializeFMUstate(c, state, buf, size) != fmi2OK ||
        fwrite(buf, 1, size, out) != size || fclose(out) != 0) {
        return 1;
    }
    printf("wrote %lu bytes\n", (unsigned long)size);
    return 0;
}

/* "read FILE...": each file deserialized, a state accepted set and one more step taken; 1 when
 * a file cannot be opened. */
static int read_states(const Fmi *f, fmi2Component c, int steps, int n_files, char **files)
{
    for (int k = 0; k < n_files; k++) {
        FILE *in = fopen(files[k], "rb");
        static char buf[1 << 16];
        fmi2FMUstate restored = NULL;
        fmi2Status status;
        size_t n;
        if (!in) {
            return 1;
        }
        n = fread(buf, 1, sizeof buf, in);
        fclose(in);
        status = f->fmi2DeSerializeFMUstate(c, buf, n, &restored);
        if (status == fmi2OK) {
            printf("%s %d step=%d\n", files[k], (int)status,
                   f->fmi2SetFMUstate(c, restored) == fmi2OK &&
                           f->fmi2DoStep(c, steps / 400.0, 1 / 400.0, fmi2True) == fmi2OK
                       ? 0
                       : 1);
        } else {
            printf("%s %d\n", files[k], (int)status);
        }
    }
    return 0;
}

int main(int argc, char **argv)
{
    void *lib;
    Fmi f;
    fmi2Component c;
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
    load(lib, &f);
    steps = atoi(argv[3]);
    c = run(&f, argv[2], argv[4], steps);
    if (!c) {
        return 1;
    }
    if (strcmp(argv[5], "write") == 0) {
        return write_state(&f, c, argv[6]);
    }
    return read_states(&f, c, steps, argc - 6, argv + 6);
}
