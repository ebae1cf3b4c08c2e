/* A tiny FMI 3.0 co-simulation host with no Python in the process (the FMI 3 counterpart of
 * host.c): it loads two FMU libraries, wires them, initializes them (exchanging initial values)
 * and runs a Gauss-Seidel loop (first FMU first), writing recorded Float64 values as CSV. Half-way
 * it saves each FMU's state, serializes it, deserializes it into a new state and restores that
 * (so the state functions run under valgrind too). Used by tests/test_fmi3_robustness.py and,
 * cross-compiled for win64 (wine) and aarch64 Linux (qemu), tests/test_fmi3_platforms.py.
 *
 * usage: host3 A.so TOKEN_A B.so TOKEN_B STEPS H OUT.csv CONNECTIONS RECORD
 *   CONNECTIONS  comma-separated "A12>B34" (output vr 12 of A feeds input vr 34 of B)
 *   RECORD       comma-separated Float64 variables to record, e.g. "A53,B55"
 *   H            the step size, a number or a ratio such as "1/400"
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"
#include "host_common.h"


typedef struct {
    void *lib;
    fmi3Instance c;
    fmi3InstantiateCoSimulationTYPE *instantiate;
    fmi3FreeInstanceTYPE *free_instance;
    fmi3EnterInitializationModeTYPE *enter_init;
    fmi3ExitInitializationModeTYPE *exit_init;
    fmi3TerminateTYPE *terminate;
    fmi3DoStepTYPE *do_step;
    fmi3GetFloat64TYPE *get;
    fmi3SetFloat64TYPE *set;
    fmi3GetFMUStateTYPE *get_state;
    fmi3SetFMUStateTYPE *set_state;
    fmi3FreeFMUStateTYPE *free_state;
    fmi3SerializedFMUStateSizeTYPE *state_size;
    fmi3SerializeFMUStateTYPE *serialize;
    fmi3DeserializeFMUStateTYPE *deserialize;
} Fmu;

static void logger(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category,
                   fmi3String message)
{
    (void)env;
    fprintf(stderr, "[%d|%s] %s\n", (int)status, category ? category : "", message);
}

static void load(Fmu *f, const char *path)
{
    f->lib = load_library(path);
    f->instantiate = (fmi3InstantiateCoSimulationTYPE *)sym(f->lib, "fmi3InstantiateCoSimulation");
    f->free_instance = (fmi3FreeInstanceTYPE *)sym(f->lib, "fmi3FreeInstance");
    f->enter_init = (fmi3EnterInitializationModeTYPE *)sym(f->lib, "fmi3EnterInitializationMode");
    f->exit_init = (fmi3ExitInitializationModeTYPE *)sym(f->lib, "fmi3ExitInitializationMode");
    f->terminate = (fmi3TerminateTYPE *)sym(f->lib, "fmi3Terminate");
    f->do_step = (fmi3DoStepTYPE *)sym(f->lib, "fmi3DoStep");
    f->get = (fmi3GetFloat64TYPE *)sym(f->lib, "fmi3GetFloat64");
    f->set = (fmi3SetFloat64TYPE *)sym(f->lib, "fmi3SetFloat64");
    f->get_state = (fmi3GetFMUStateTYPE *)sym(f->lib, "fmi3GetFMUState");
    f->set_state = (fmi3SetFMUStateTYPE *)sym(f->lib, "fmi3SetFMUState");
    f->free_state = (fmi3FreeFMUStateTYPE *)sym(f->lib, "fmi3FreeFMUState");
    f->state_size = (fmi3SerializedFMUStateSizeTYPE *)sym(f->lib, "fmi3SerializedFMUStateSize");
    f->serialize = (fmi3SerializeFMUStateTYPE *)sym(f->lib, "fmi3SerializeFMUState");
    f->deserialize = (fmi3DeserializeFMUStateTYPE *)sym(f->lib, "fmi3DeserializeFMUState");
}

static void check(fmi3Status s, const char *what)
{
    if (s != fmi3OK && s != fmi3Warning) {
        fprintf(stderr, "%s failed with status %d\n", what, (int)s);
        exit(1);
    }
}

static double get(Fmu *f, fmi3ValueReference vr)
{
    double v;
    check(f->get(f->c, &vr, 1, &v, 1), "fmi3GetFloat64");
    return v;
}

static void set(Fmu *f, fmi3ValueReference vr, double v)
{
    check(f->set(f->c, &vr, 1, &v, 1), "fmi3SetFloat64");
}

static void exchange(Fmu *fmus, const Link *links, int n_links, int to)
{
    for (int k = 0; k < n_links; k++) {
        if (links[k].to == to) {
            set(&fmus[to], links[k].in, get(&fmus[links[k].from], links[k].out));
        }
    }
}

/* get the state, serialize it, deserialize it into a second state, restore that, free both */
static void round_trip_state(Fmu *f)
{
    fmi3FMUState saved = NULL, copy = NULL;
    size_t size = 0;
    fmi3Byte *bytes;
    check(f->get_state(f->c, &saved), "fmi3GetFMUState");
    check(f->state_size(f->c, saved, &size), "fmi3SerializedFMUStateSize");
    bytes = (fmi3Byte *)malloc(size);
    if (!bytes) {
        exit(2);
    }
    check(f->serialize(f->c, saved, bytes, size), "fmi3SerializeFMUState");
    check(f->deserialize(f->c, bytes, size, &copy), "fmi3DeserializeFMUState");
    check(f->set_state(f->c, copy), "fmi3SetFMUState");
    check(f->free_state(f->c, &saved), "fmi3FreeFMUState");
    check(f->free_state(f->c, &copy), "fmi3FreeFMUState");
    free(bytes);
}

int main(int argc, char **argv)
{
    Fmu fmus[2];
    Link links[MAX_LINKS];
    int n_links = 0, n_rec = 0, rec_fmu[MAX_LINKS];
    unsigned int rec_vr[MAX_LINKS];
    long steps;
    double h;
    FILE *out;

    if (argc != 10) {
        fprintf(stderr, "usage: %s A.so TOKEN_A B.so TOKEN_B STEPS H OUT CONN REC\n", argv[0]);
        return 2;
    }
    steps = atol(argv[5]);
    h = parse_step(argv[6]);
    n_links = parse_links(argv[8], links);
    n_rec = parse_record(argv[9], rec_fmu, rec_vr);
    for (int k = 0; k < 2; k++) {
        load(&fmus[k], argv[1 + 2 * k]);
        fmus[k].c = fmus[k].instantiate(k ? "B" : "A", argv[2 + 2 * k], NULL, fmi3False,
                                        fmi3False, fmi3False, fmi3False, NULL, 0, NULL, logger,
                                        NULL);
        if (!fmus[k].c) {
            fprintf(stderr, "fmi3InstantiateCoSimulation failed for %s\n", argv[1 + 2 * k]);
            return 1;
        }
        check(fmus[k].enter_init(fmus[k].c, fmi3False, 0.0, 0.0, fmi3True, steps * h),
              "fmi3EnterInitializationMode");
    }
    for (int pass = 0; pass < 3; pass++) { /* initial values: B from A, A from B, repeated */
        exchange(fmus, links, n_links, 0);
        exchange(fmus, links, n_links, 1);
    }
    for (int k = 0; k < 2; k++) {
        check(fmus[k].exit_init(fmus[k].c), "fmi3ExitInitializationMode");
    }
    out = fopen(argv[7], "w");
    if (!out) {
        perror(argv[7]);
        return 2;
    }
    for (long i = 0; i <= steps; i++) {
        if (i > 0) {
            const double t = (i - 1) * h;
            for (int k = 0; k < 2; k++) { /* Gauss-Seidel, A first */
                fmi3Boolean event, stop, early;
                fmi3Float64 last;
                exchange(fmus, links, n_links, k);
                check(fmus[k].do_step(fmus[k].c, t, h, fmi3True, &event, &stop, &early, &last),
                      "fmi3DoStep");
                if (event || stop || early || last != t + h) {
                    fprintf(stderr, "fmi3DoStep at t=%g: unexpected results\n", t);
                    return 1;
                }
            }
        }
        if (i == steps / 2) {
            round_trip_state(&fmus[0]);
            round_trip_state(&fmus[1]);
        }
        fprintf(out, "%.17g", i * h);
        for (int r = 0; r < n_rec; r++) {
            fprintf(out, ",%.17g", get(&fmus[rec_fmu[r]], rec_vr[r]));
        }
        fputc('\n', out);
    }
    fclose(out);
    for (int k = 0; k < 2; k++) {
        check(fmus[k].terminate(fmus[k].c), "fmi3Terminate");
        fmus[k].free_instance(fmus[k].c);
        close_library(fmus[k].lib);
    }
    return 0;
}
