/* The FMUs' own compute for benchmarks/master_overhead.py: one FMI 2.0 co-simulation FMU stepped
 * alone, with no master around it: before each step its inputs are set from a table (the values
 * it got in a co-simulation, so it computes exactly what it computed there), then fmi2DoStep.
 * Returns the CPU seconds the n_steps took (CLOCK_PROCESS_CPUTIME_ID around the whole loop: on
 * a shared machine, time spent waiting for a core is not counted), or -1 when a call
 * failed. No output is read and nothing is recorded: that is the master's work.
 */
#define _POSIX_C_SOURCE 199309L
#include <stddef.h>
#include <time.h>

typedef int (*set_real_t)(void *, const unsigned *, size_t, const double *);
typedef int (*do_step_t)(void *, double, double, int);

double step_alone(void *component, void *set_real, void *do_step, const unsigned *in_vr,
                  int n_in, const double *inputs, double t0, double h, long n_steps)
{
    set_real_t set = (set_real_t)set_real;
    do_step_t step = (do_step_t)do_step;
    struct timespec a, b;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &a);
    for (long i = 0; i < n_steps; i++) {
        if (n_in > 0 && set(component, in_vr, (size_t)n_in, inputs + (size_t)i * (size_t)n_in) > 1) {
            return -1.0;
        }
        if (step(component, t0 + (double)i * h, h, 1) > 1) {
            return -1.0;
        }
    }
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &b);
    return (double)(b.tv_sec - a.tv_sec) + 1e-9 * (double)(b.tv_nsec - a.tv_nsec);
}
