/* CPython compatibility for the native plant: random.Random (MT19937) seeded from an int and its
 * gauss() method, reproduced bit for bit (CPython 3.11, Modules/_randommodule.c and
 * Lib/random.py).
 *
 * The generator is plain data (no pointers), so it can live in a ModelState that the FMU glue
 * copies with memcpy for fmi2GetFMUstate / fmi2SetFMUstate. */
#ifndef PYRANDOM_H
#define PYRANDOM_H

#include <stddef.h>
#include <stdint.h>

#define PYRANDOM_N 624

typedef struct {
    uint32_t mt[PYRANDOM_N]; /* MT19937 state (Random.getstate()[1][:624]) */
    int32_t index;           /* position in mt (Random.getstate()[1][624]) */
    int32_t has_gauss_next;  /* 0: gauss_next is None */
    double gauss_next;       /* the cached second normal deviate of gauss() */
} PyRandom;

/* random.Random(seed): init_by_array with the 32-bit words of abs(seed); gauss_next = None. */
void pyrandom_seed(PyRandom *r, int64_t seed);

/* random.Random.random(): 53-bit float in [0, 1). */
double pyrandom_random(PyRandom *r);

/* random.Random.gauss(mu, sigma). */
double pyrandom_gauss(PyRandom *r, double mu, double sigma);

#endif
