/* The replay main() of a fuzz harness built without libFuzzer: each file named on the command
 * line is one input to LLVMFuzzerTestOneInput (tests/test_fuzz_corpora.py). */
#ifndef IMPCOSIM_FUZZ_REPLAY_H
#define IMPCOSIM_FUZZ_REPLAY_H
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static int replay_files(int argc, char **argv)
{
    for (int k = 1; k < argc; k++) {
        FILE *in = fopen(argv[k], "rb");
        uint8_t *buf = NULL;
        long n;
        if (!in || fseek(in, 0, SEEK_END) != 0 || (n = ftell(in)) < 0 ||
            fseek(in, 0, SEEK_SET) != 0 || !(buf = malloc((size_t)n + 1)) ||
            fread(buf, 1, (size_t)n, in) != (size_t)n) {
            fprintf(stderr, "cannot read %s\n", argv[k]);
            return 2;
        }
        fclose(in);
        LLVMFuzzerTestOneInput(buf, (size_t)n);
        free(buf);
    }
    printf("replayed %d files\n", argc - 1);
    return 0;
}
/* A seed input for the fuzzer (--seed DIR): bytes written as DIR/name; 0, or 1 if it could not
 * be written. */
static int write_input(const char *dir, const char *name, const uint8_t *bytes, size_t n)
{
    char path[4096];
    FILE *out;
    snprintf(path, sizeof path, "%s/%s", dir, name);
    out = fopen(path, "wb");
    if (!out) {
        return 1;
    }
    return (fwrite(bytes, 1, n, out) != n) | (fclose(out) != 0);
}
#endif
