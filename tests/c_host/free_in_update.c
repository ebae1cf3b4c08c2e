/* Issue 34: fmi3FreeInstance called from inside the intermediate update callback. The FMU must
 * refuse it (the instance stays alive; fmi3DoStep goes on with it), so that under valgrind there
 * is no read of a freed block. Usage: free_in_update LIB.so GUID VR_TAU2 VR_X; prints the
 * statuses and the number of callbacks, exits 0 (valgrind's --error-exitcode says the rest). */
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>

#include "fmi3Functions.h"

static fmi3Instance instance;
static fmi3FreeInstanceTYPE *free_instance;
static int callbacks;

static void log_message(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category,
                        fmi3String message)
{
    (void)env, (void)category;
    printf("log %d: %s\n", (int)status, message);
}

static void update(fmi3InstanceEnvironment env, fmi3Float64 t, fmi3Boolean clocksTicked,
                   fmi3Boolean setRequested, fmi3Boolean getAllowed, fmi3Boolean canReturnEarly,
                   fmi3Boolean *earlyReturnRequested, fmi3Float64 *earlyReturnTime)
{
    (void)env, (void)clocksTicked, (void)setRequested, (void)getAllowed, (void)canReturnEarly;
    callbacks++;
    free_instance(instance); /* not allowed here: must be refused */
    *earlyReturnRequested = fmi3False;
    *earlyReturnTime = t;
}

#define LOAD(name) ((name##TYPE *)dlsym(lib, #name))

int main(int argc, char **argv)
{
    void *lib;
    fmi3ValueReference tau2, x;
    fmi3Float64 push = 60.0, value = 0.0, last = 0.0;
    fmi3Boolean event, terminate, early;
    fmi3Status s1, s2, g;
    if (argc != 5 || !(lib = dlopen(argv[1], RTLD_NOW))) {
        fprintf(stderr, "usage: free_in_update LIB.so GUID VR_TAU2 VR_X\n");
        return 2;
    }
    tau2 = (fmi3ValueReference)atoi(argv[3]);
    x = (fmi3ValueReference)atoi(argv[4]);
    free_instance = LOAD(fmi3FreeInstance);
    instance = LOAD(fmi3InstantiateCoSimulation)("p", argv[2], NULL, fmi3False, fmi3False,
                                                 fmi3False, fmi3False, NULL, 0, NULL,
                                                 log_message, update);
    if (!instance) {
        return 2;
    }
    LOAD(fmi3EnterInitializationMode)(instance, fmi3False, 0.0, 0.0, fmi3False, 0.0);
    LOAD(fmi3ExitInitializationMode)(instance);
    LOAD(fmi3SetFloat64)(instance, &tau2, 1, &push, 1);
    s1 = LOAD(fmi3DoStep)(instance, 0.0, 2.0, fmi3True, &event, &terminate, &early, &last);
    g = LOAD(fmi3GetFloat64)(instance, &x, 1, &value, 1);
    s2 = LOAD(fmi3DoStep)(instance, 2.0, 0.0025, fmi3True, &event, &terminate, &early, &last);
    printf("callbacks=%d step=%d get=%d step_after=%d last=%g\n", callbacks, (int)s1, (int)g,
           (int)s2, last);
    free_instance(instance);
    dlclose(lib);
    return 0;
}
