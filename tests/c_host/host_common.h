/* What the test hosts (host.c for FMI 2.0, host3.c for FMI 3.0, state_host.c) share: loading an
 * FMU's library on Windows and POSIX, its functions by name, and the command-line lists of the
 * two-FMU hosts (the step size, the links "A12>B34", the recorded variables "A53,B55"). Static
 * inline functions: each host is one translation unit and uses what it needs. */
#ifndef HOST_COMMON_H
#define HOST_COMMON_H

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifdef _WIN32
#include <windows.h>
static inline void *open_library(const char *path) { return (void *)LoadLibraryA(path); }
static inline void *library_symbol(void *lib, const char *name)
{
    FARPROC f = GetProcAddress((HMODULE)lib, name);
    void *p;
    memcpy(&p, &f, sizeof p); /* function pointer to void *, as dlsym returns it */
    return p;
}
static inline void close_library(void *lib) { FreeLibrary((HMODULE)lib); }
static inline const char *library_error(void)
{
    static char text[64];
    snprintf(text, sizeof text, "LoadLibrary failed with error %lu", (unsigned long)GetLastError());
    return text;
}
#else
#include <dlfcn.h>
static inline void *open_library(const char *path) { return dlopen(path, RTLD_NOW | RTLD_LOCAL); }
static inline void *library_symbol(void *lib, const char *name) { return dlsym(lib, name); }
static inline void close_library(void *lib) { dlclose(lib); }
static inline const char *library_error(void) { return dlerror(); }
#endif

#define MAX_LINKS 64

/* The library's function `name`, or exit 2 naming it. */
static inline void *sym(void *lib, const char *name)
{
    void *f = library_symbol(lib, name);
    if (!f) {
        fprintf(stderr, "missing symbol %s\n", name);
        exit(2);
    }
    return f;
}

/* The library at path, or exit 2 saying why. */
static inline void *load_library(const char *path)
{
    void *lib = open_library(path);
    if (!lib) {
        fprintf(stderr, "loading %s: %s\n", path, library_error());
        exit(2);
    }
    return lib;
}

/* A step size given as a number or a ratio such as "1/400" (divided here, so every platform's C
 * library gets the same double). */
static inline double parse_step(const char *text)
{
    const char *slash = strchr(text, '/');
    return slash ? atof(text) / atof(slash + 1) : atof(text);
}

typedef struct {
    int from, to;          /* 0 for FMU A, 1 for B */
    unsigned int out, in; /* value references */
} Link;

/* "A12>B34,..." (output 12 of A feeds input 34 of B) into links; how many, or exit 2. */
static inline int parse_links(char *spec, Link *links)
{
    int n = 0;
    for (char *tok = strtok(spec, ","); tok && n < MAX_LINKS; tok = strtok(NULL, ",")) {
        char a, b;
        unsigned o, i;
        if (sscanf(tok, "%c%u>%c%u", &a, &o, &b, &i) != 4) {
            fprintf(stderr, "bad connection %s\n", tok);
            exit(2);
        }
        links[n++] = (Link){a - 'A', b - 'A', o, i};
    }
    return n;
}

/* "A53,B55,..." (the variables to record) into fmu[] and vr[]; how many. */
static inline int parse_record(char *spec, int *fmu, unsigned int *vr)
{
    int n = 0;
    for (char *tok = strtok(spec, ","); tok && n < MAX_LINKS; tok = strtok(NULL, ",")) {
        fmu[n] = tok[0] - 'A';
        vr[n++] = (unsigned int)atoi(tok + 1);
    }
    return n;
}

#endif
