/* The fuzz input read byte by byte, shared by the call-sequence harnesses (calls.c, calls3.c):
 * next() gives the next byte, 0 once the input is used up, so every input is a whole sequence. */
#ifndef FUZZ_INPUT_H
#define FUZZ_INPUT_H

#include <stddef.h>
#include <stdint.h>

typedef struct {
    const uint8_t *p;
    size_t n;
} Input;

static unsigned next(Input *in)
{
    if (!in->n) {
        return 0;
    }
    in->n--;
    return *in->p++;
}

/* one entry of a static table, chosen by the next byte */
#define PICK(in, table) (table[next(in) % (sizeof table / sizeof table[0])])

#endif
