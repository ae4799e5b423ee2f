/* A minimal FMI 2.0 co-simulation importer for the tests: no Python, no libpython linked.
 *
 *   fmi2_host UNZIPDIR MODEL_ID GUID STOP STEP REAL_VRS INT_VRS [VR=VALUE ...]
 *
 * REAL_VRS / INT_VRS: comma-separated value references to read after every step ("-" for none);
 * VR=VALUE: Real parameters set before initialization.  Prints one CSV line per communication
 * point: time, the reals (%.17g), the integers.  The FMU's log goes to stderr.  Exit status 0 if
 * the run reached STOP, 1 otherwise.
 *
 * The same source builds for Windows with zig cc (LoadLibrary, binaries/win64/<id>.dll; the
 * tests run it under wine against the native FMUs' Windows binaries) and for aarch64 Linux
 * (binaries/aarch64-linux/<id>.so, run under qemu-aarch64).
 *
 * Built with -DRECORD_IN_MEMORY (benchmark (b), benchmarks/bench_fmu.py) it keeps every value in
 * memory instead, as fmpy's simulate_fmu does, and prints one summary line at the end, with the
 * CPU time of the stepping loop alone (from the first fmi2DoStep to the last read). */
#ifdef _WIN32
#include <windows.h>
#define PLATFORM "win64"
#define SUFFIX ".dll"
#define OPEN(path) ((void *)LoadLibraryA(path))
#define SYMBOL(lib, name) ((void *)GetProcAddress((HMODULE)(lib), name))
#define CLOSE(lib) FreeLibrary((HMODULE)(lib))
#define OPEN_ERROR() "LoadLibrary failed"
#else
#include <dlfcn.h>
#if defined(__aarch64__)
#define PLATFORM "aarch64-linux"
#else
#define PLATFORM "linux64"
#endif
#define SUFFIX ".so"
#define OPEN(path) dlopen(path, RTLD_NOW | RTLD_LOCAL)
#define SYMBOL(lib, name) dlsym(lib, name)
#define CLOSE(lib) dlclose(lib)
#define OPEN_ERROR() dlerror()
#endif
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include "fmi2Functions.h"

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...)
{
    va_list ap;
    va_start(ap, message);
    fprintf(stderr, "[%d|%s] ", (int)status, category ? category : "");
    vfprintf(stderr, message, ap);
    fputc('\n', stderr);
    va_end(ap);
}

static size_t parse_vrs(const char *text, fmi2ValueReference *out)
{
    size_t n = 0;
    if (strcmp(text, "-") == 0) return 0;
    for (const char *p = text; *p; ++n) {
        out[n] = (fmi2ValueReference)strtoul(p, (char **)&p, 10);
        if (*p == ',') ++p;
    }
    return n;
}

#define LOAD(name) name##TYPE *name = (name##TYPE *)SYMBOL(lib, #name); if (!name) { fprintf(stderr, "missing %s\n", #name); return 2; }

int main(int argc, char **argv)
{
    if (argc < 8) { fprintf(stderr, "usage: see the source\n"); return 2; }
    char path[4096], uri[4200];
    snprintf(path, sizeof path, "%s/binaries/" PLATFORM "/%s" SUFFIX, argv[1], argv[2]);
    void *lib = OPEN(path);
    if (!lib) { fprintf(stderr, "loading %s: %s\n", path, OPEN_ERROR()); return 2; }
    LOAD(fmi2Instantiate) LOAD(fmi2SetupExperiment) LOAD(fmi2EnterInitializationMode)
    LOAD(fmi2ExitInitializationMode) LOAD(fmi2DoStep) LOAD(fmi2GetReal) LOAD(fmi2GetInteger)
    LOAD(fmi2SetReal) LOAD(fmi2Terminate) LOAD(fmi2FreeInstance)
    snprintf(uri, sizeof uri, "file://%s/resources", argv[1]);
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    fmi2Component c = fmi2Instantiate("host", fmi2CoSimulation, argv[3], uri, &cb, fmi2False, fmi2False);
    if (!c) { fprintf(stderr, "fmi2Instantiate returned NULL\n"); return 3; }
    double stop = atof(argv[4]), h = atof(argv[5]);
    fmi2ValueReference rv[256], iv[256];
    size_t nr = parse_vrs(argv[6], rv), ni = parse_vrs(argv[7], iv);
    long steps = (long)(stop / h + 0.5);
#ifdef RECORD_IN_MEMORY
    struct timespec c0 = {0, 0}, c1 = {0, 0};
    double *r_all = malloc(sizeof(double) * (size_t)(steps + 1) * (nr + 1));
    int *n_all = malloc(sizeof(int) * (size_t)(steps + 1) * (ni + 1));
    if (!r_all || !n_all) return 4;
#else
    double r[256];
    int n[256];
#endif
    int rc = 1;
    long k = 0;
    if (fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2True, stop) > fmi2Warning) goto done;
    if (fmi2EnterInitializationMode(c) > fmi2Warning) goto done;
    for (int a = 8; a < argc; ++a) {
        fmi2ValueReference vr = (fmi2ValueReference)strtoul(argv[a], NULL, 10);
        double v = atof(strchr(argv[a], '=') + 1);
        if (fmi2SetReal(c, &vr, 1, &v) > fmi2Warning) goto done;
    }
    if (fmi2ExitInitializationMode(c) > fmi2Warning) goto done;
#ifdef RECORD_IN_MEMORY
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &c0);
#endif
    for (k = 0; k <= steps; ++k) {
        double t = k * h;
        if (k > 0 && fmi2DoStep(c, (k - 1) * h, t - (k - 1) * h, fmi2True) > fmi2Warning) goto done;
#ifdef RECORD_IN_MEMORY
        double *r = r_all + k * (long)(nr + 1);
        int *n = n_all + k * (long)(ni + 1);
        r[nr] = t;
#endif
        /* (no call for a type with nothing to read: what a user reading y only does) */
        if ((nr && fmi2GetReal(c, rv, nr, r) > fmi2Warning) || (ni && fmi2GetInteger(c, iv, ni, n) > fmi2Warning))
            goto done;
#ifndef RECORD_IN_MEMORY
        printf("%.17g", t);
        for (size_t i = 0; i < nr; ++i) printf(",%.17g", r[i]);
        for (size_t i = 0; i < ni; ++i) printf(",%d", n[i]);
        putchar('\n');
#endif
    }
    rc = 0;
#ifdef RECORD_IN_MEMORY
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &c1);
#endif
    fmi2Terminate(c);
done:
#ifdef RECORD_IN_MEMORY
    printf("recorded %ld points, last t = %.17g, loop cpu %.9f s\n", k, k ? r_all[(k - 1) * (long)(nr + 1) + nr] : 0.0,
           (double)(c1.tv_sec - c0.tv_sec) + 1e-9 * (double)(c1.tv_nsec - c0.tv_nsec));
    free(r_all);
    free(n_all);
#endif
    fmi2FreeInstance(c);
    CLOSE(lib);
    return rc;
}
