/* See pyrandom.h. The generator follows CPython 3.11 Modules/_randommodule.c (MT19937 by
 * Matsumoto and Nishimura, init_by_array, genrand_res53) and gauss() follows Lib/random.py. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "pyrandom.h"

#define N PYRANDOM_N
#define M 397
#define MATRIX_A 0x9908b0dfU
#define UPPER_MASK 0x80000000U
#define LOWER_MASK 0x7fffffffU

/* random.py: TWOPI = 2.0 * pi, with math.pi the double nearest to pi */
#define PY_PI 3.141592653589793238462643383279502884197
#define TWOPI (2.0 * PY_PI)

static void init_genrand(PyRandom *r, uint32_t s)
{
    uint32_t *mt = r->mt;
    int mti;
    mt[0] = s;
    for (mti = 1; mti < N; mti++) {
        mt[mti] = (1812433253U * (mt[mti - 1] ^ (mt[mti - 1] >> 30)) + (uint32_t)mti);
    }
    r->index = mti;
}

static void init_by_array(PyRandom *r, const uint32_t init_key[], size_t key_length)
{
    uint32_t *mt = r->mt;
    size_t i, j, k;
    init_genrand(r, 19650218U);
    i = 1;
    j = 0;
    k = (N > key_length ? N : key_length);
    for (; k; k--) {
        mt[i] = (mt[i] ^ ((mt[i - 1] ^ (mt[i - 1] >> 30)) * 1664525U)) + init_key[j] + (uint32_t)j;
        i++;
        j++;
        if (i >= N) {
            mt[0] = mt[N - 1];
            i = 1;
        }
        if (j >= key_length) {
            j = 0;
        }
    }
    for (k = N - 1; k; k--) {
        mt[i] = (mt[i] ^ ((mt[i - 1] ^ (mt[i - 1] >> 30)) * 1566083941U)) - (uint32_t)i;
        i++;
        if (i >= N) {
            mt[0] = mt[N - 1];
            i = 1;
        }
    }
    mt[0] = 0x80000000U; /* MSB is 1; assuring non-zero initial array */
}

void pyrandom_seed(PyRandom *r, int64_t seed)
{
    /* random_seed(): n = abs(arg), key = its 32-bit words, least significant first */
    const uint64_t n = seed < 0 ? (uint64_t)0 - (uint64_t)seed : (uint64_t)seed;
    uint32_t key[2];
    key[0] = (uint32_t)(n & 0xffffffffU);
    key[1] = (uint32_t)(n >> 32);
    init_by_array(r, key, key[1] != 0 ? 2 : 1);
    r->has_gauss_next = 0;
    r->gauss_next = 0.0;
}

static uint32_t genrand_uint32(PyRandom *r)
{
    static const uint32_t mag01[2] = {0x0U, MATRIX_A};
    uint32_t *mt = r->mt;
    uint32_t y;
    if (r->index >= N) { /* generate N words at one time */
        int kk;
        for (kk = 0; kk < N - M; kk++) {
            y = (mt[kk] & UPPER_MASK) | (mt[kk + 1] & LOWER_MASK);
            mt[kk] = mt[kk + M] ^ (y >> 1) ^ mag01[y & 0x1U];
        }
        for (; kk < N - 1; kk++) {
            y = (mt[kk] & UPPER_MASK) | (mt[kk + 1] & LOWER_MASK);
            mt[kk] = mt[kk + (M - N)] ^ (y >> 1) ^ mag01[y & 0x1U];
        }
        y = (mt[N - 1] & UPPER_MASK) | (mt[0] & LOWER_MASK);
        mt[N - 1] = mt[M - 1] ^ (y >> 1) ^ mag01[y & 0x1U];
        r->index = 0;
    }
    y = mt[r->index++];
    y ^= (y >> 11);
    y ^= (y << 7) & 0x9d2c5680U;
    y ^= (y << 15) & 0xefc60000U;
    y ^= (y >> 18);
    return y;
}

double pyrandom_random(PyRandom *r)
{
    const uint32_t a = genrand_uint32(r) >> 5;
    const uint32_t b = genrand_uint32(r) >> 6;
    return ((double)a * 67108864.0 + (double)b) * (1.0 / 9007199254740992.0);
}

double pyrandom_gauss(PyRandom *r, double mu, double sigma)
{
    double z = r->gauss_next;
    const int have = r->has_gauss_next;
    r->has_gauss_next = 0;
    r->gauss_next = 0.0;
    if (!have) {
        const double x2pi = pyrandom_random(r) * TWOPI;
        const double g2rad = sqrt(-2.0 * log(1.0 - pyrandom_random(r)));
        z = cos(x2pi) * g2rad;
        r->gauss_next = sin(x2pi) * g2rad;
        r->has_gauss_next = 1;
    }
    return mu + z * sigma;
}
