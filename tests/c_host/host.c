/* A tiny FMI 2.0 co-simulation host with no Python in the process: it loads two FMU libraries,
 * wires them, initializes them (exchanging initial values) and runs a Gauss-Seidel loop
 * (first FMU first), writing recorded values as CSV. Used by tests/test_native.py, also under
 * valgrind, and cross-compiled for win64 (run under wine) and aarch64 Linux (run under qemu) by
 * tests/test_platforms.py.
 *
 * usage: host A.so GUID_A RES_A B.so GUID_B RES_B STEPS H OUT.csv CONNECTIONS RECORD [PARAMS]
 *   CONNECTIONS  comma-separated "A12>B34" (output vr 12 of A feeds input vr 34 of B)
 *   RECORD       comma-separated Real variables to record, e.g. "A53,B55"
 *   PARAMS       optional comma-separated Real parameters, e.g. "B31=80"
 *   H            the step size, a number or a ratio such as "1/400" (divided here, so every
 *                platform's C library gets the same double)
 */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "host_common.h"


typedef struct {
    void *lib;
    fmi2Component c;
    fmi2InstantiateTYPE *instantiate;
    fmi2FreeInstanceTYPE *free_instance;
    fmi2SetupExperimentTYPE *setup;
    fmi2EnterInitializationModeTYPE *enter_init;
    fmi2ExitInitializationModeTYPE *exit_init;
    fmi2TerminateTYPE *terminate;
    fmi2DoStepTYPE *do_step;
    fmi2GetRealTYPE *get_real;
    fmi2SetRealTYPE *set_real;
} Fmu;

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status,
                   fmi2String category, fmi2String message, ...)
{
    va_list ap;
    (void)env;
    fprintf(stderr, "[%s|%d|%s] ", name, (int)status, category ? category : "");
    va_start(ap, message);
    vfprintf(stderr, message, ap);
    va_end(ap);
    fputc('\n', stderr);
}

static void load(Fmu *f, const char *path)
{
    f->lib = load_library(path);
    f->instantiate = (fmi2InstantiateTYPE *)sym(f->lib, "fmi2Instantiate");
    f->free_instance = (fmi2FreeInstanceTYPE *)sym(f->lib, "fmi2FreeInstance");
    f->setup = (fmi2SetupExperimentTYPE *)sym(f->lib, "fmi2SetupExperiment");
    f->enter_init = (fmi2EnterInitializationModeTYPE *)sym(f->lib, "fmi2EnterInitializationMode");
    f->exit_init = (fmi2ExitInitializationModeTYPE *)sym(f->lib, "fmi2ExitInitializationMode");
    f->terminate = (fmi2TerminateTYPE *)sym(f->lib, "fmi2Terminate");
    f->do_step = (fmi2DoStepTYPE *)sym(f->lib, "fmi2DoStep");
    f->get_real = (fmi2GetRealTYPE *)sym(f->lib, "fmi2GetReal");
    f->set_real = (fmi2SetRealTYPE *)sym(f->lib, "fmi2SetReal");
}

static void check(fmi2Status s, const char *what)
{
    if (s != fmi2OK && s != fmi2Warning) {
        fprintf(stderr, "%s failed with status %d\n", what, (int)s);
        exit(1);
    }
}

static double get(Fmu *f, fmi2ValueReference vr)
{
    double v;
    check(f->get_real(f->c, &vr, 1, &v), "fmi2GetReal");
    return v;
}

static void set(Fmu *f, fmi2ValueReference vr, double v)
{
    check(f->set_real(f->c, &vr, 1, &v), "fmi2SetReal");
}

static void exchange(Fmu *fmus, const Link *links, int n_links, int to)
{
    for (int k = 0; k < n_links; k++) {
        if (links[k].to == to) {
            set(&fmus[to], links[k].in, get(&fmus[links[k].from], links[k].out));
        }
    }
}

int main(int argc, char **argv)
{
    Fmu fmus[2];
    Link links[MAX_LINKS];
    int n_links = 0, n_rec = 0, rec_fmu[MAX_LINKS];
    unsigned int rec_vr[MAX_LINKS]; /* fmi2/fmi3 value references are unsigned int */
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    long steps;
    double h;
    FILE *out;
    char *tok;

    if (argc < 12) {
        fprintf(stderr, "usage: %s A.so GUID_A RES_A B.so GUID_B RES_B STEPS H OUT CONN REC [P]\n",
                argv[0]);
        return 2;
    }
    steps = atol(argv[7]);
    h = parse_step(argv[8]);
    n_links = parse_links(argv[10], links);
    n_rec = parse_record(argv[11], rec_fmu, rec_vr);
    for (int k = 0; k < 2; k++) {
        load(&fmus[k], argv[1 + 3 * k]);
        fmus[k].c = fmus[k].instantiate(k ? "B" : "A", fmi2CoSimulation, argv[2 + 3 * k],
                                        argv[3 + 3 * k], &cb, fmi2False, fmi2False);
        if (!fmus[k].c) {
            fprintf(stderr, "fmi2Instantiate failed for %s\n", argv[1 + 3 * k]);
            return 1;
        }
        check(fmus[k].setup(fmus[k].c, fmi2False, 0.0, 0.0, fmi2True, steps * h), "setup");
    }
    if (argc > 12) {
        for (tok = strtok(argv[12], ","); tok; tok = strtok(NULL, ",")) {
            unsigned vr;
            double v;
            char which;
            if (sscanf(tok, "%c%u=%lf", &which, &vr, &v) != 3) {
                fprintf(stderr, "bad parameter %s\n", tok);
                return 2;
            }
            set(&fmus[which - 'A'], vr, v);
        }
    }
    for (int k = 0; k < 2; k++) {
        check(fmus[k].enter_init(fmus[k].c), "fmi2EnterInitializationMode");
    }
    for (int pass = 0; pass < 3; pass++) { /* initial values: B from A, A from B, repeated */
        exchange(fmus, links, n_links, 0);
        exchange(fmus, links, n_links, 1);
    }
    for (int k = 0; k < 2; k++) {
        check(fmus[k].exit_init(fmus[k].c), "fmi2ExitInitializationMode");
    }
    out = fopen(argv[9], "w");
    if (!out) {
        perror(argv[9]);
        return 2;
    }
    for (long i = 0; i <= steps; i++) {
        if (i > 0) {
            const double t = (i - 1) * h;
            for (int k = 0; k < 2; k++) { /* Gauss-Seidel, A first */
                exchange(fmus, links, n_links, k);
                check(fmus[k].do_step(fmus[k].c, t, h, fmi2True), "fmi2DoStep");
            }
        }
        fprintf(out, "%.17g", i * h);
        for (int r = 0; r < n_rec; r++) {
            fprintf(out, ",%.17g", get(&fmus[rec_fmu[r]], rec_vr[r]));
        }
        fputc('\n', out);
    }
    fclose(out);
    for (int k = 0; k < 2; k++) {
        check(fmus[k].terminate(fmus[k].c), "fmi2Terminate");
        fmus[k].free_instance(fmus[k].c);
        close_library(fmus[k].lib);
    }
    return 0;
}
