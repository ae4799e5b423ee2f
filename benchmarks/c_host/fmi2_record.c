/* Benchmark (b)'s C importer: runs one FMI 2.0 co-simulation FMU on a fixed grid and records every
 * output at every communication point in memory (as fmpy's simulate_fmu does), no Python in the
 * process, no libpython linked (dlopen RTLD_LOCAL).
 *
 *   fmi2_record UNZIPDIR MODEL_ID GUID STOP STEP REAL_VRS INT_VRS
 *
 * REAL_VRS / INT_VRS: comma-separated value references ("-" for none).  Prints one line:
 * "points N last_time T checksum S" (the checksum keeps the recorded values alive).  Exit status
 * 0 if the run reached STOP. */
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "fmi2Functions.h"

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...)
{
    if (status >= fmi2Warning) fprintf(stderr, "[%d|%s] %s\n", (int)status, category ? category : "", message);
}

static size_t parse_vrs(const char *text, fmi2ValueReference *out, size_t max)
{
    size_t n = 0;
    if (strcmp(text, "-") == 0) return 0;
    for (const char *p = text; *p && n < max; ++n) {
        out[n] = (fmi2ValueReference)strtoul(p, (char **)&p, 10);
        if (*p == ',') ++p;
    }
    return n;
}

#define LOAD(name) name##TYPE *name = (name##TYPE *)dlsym(lib, #name); if (!name) { fprintf(stderr, "missing %s\n", #name); return 2; }

int main(int argc, char **argv)
{
    if (argc != 8) { fprintf(stderr, "usage: see the source\n"); return 2; }
    char path[4096], uri[4200];
    snprintf(path, sizeof path, "%s/binaries/linux64/%s.so", argv[1], argv[2]);
    void *lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!lib) { fprintf(stderr, "dlopen: %s\n", dlerror()); return 2; }
    LOAD(fmi2Instantiate) LOAD(fmi2SetupExperiment) LOAD(fmi2EnterInitializationMode)
    LOAD(fmi2ExitInitializationMode) LOAD(fmi2DoStep) LOAD(fmi2GetReal) LOAD(fmi2GetInteger)
    LOAD(fmi2Terminate) LOAD(fmi2FreeInstance)
    snprintf(uri, sizeof uri, "file://%s/resources", argv[1]);
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    fmi2Component c = fmi2Instantiate("bench", fmi2CoSimulation, argv[3], uri, &cb, fmi2False, fmi2False);
    if (!c) { fprintf(stderr, "fmi2Instantiate returned NULL\n"); return 3; }
    double stop = atof(argv[4]), h = atof(argv[5]);
    fmi2ValueReference rv[256], iv[256];
    size_t nr = parse_vrs(argv[6], rv, 256), ni = parse_vrs(argv[7], iv, 256);
    long steps = (long)(stop / h + 0.5);
    double *reals = malloc(sizeof(double) * (size_t)(steps + 1) * (nr + 1));
    int *ints = malloc(sizeof(int) * (size_t)(steps + 1) * (ni + 1));
    int rc = 1;
    double t = 0.0;
    long k = 0;
    if (!reals || !ints) goto done;
    if (fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2True, stop) > fmi2Warning) goto done;
    if (fmi2EnterInitializationMode(c) > fmi2Warning) goto done;
    if (fmi2ExitInitializationMode(c) > fmi2Warning) goto done;
    for (k = 0; k <= steps; ++k) {
        t = k * h;
        if (k > 0 && fmi2DoStep(c, (k - 1) * h, t - (k - 1) * h, fmi2True) > fmi2Warning) goto done;
        if (fmi2GetReal(c, rv, nr, reals + k * (long)(nr + 1)) > fmi2Warning) goto done;
        if (fmi2GetInteger(c, iv, ni, ints + k * (long)(ni + 1)) > fmi2Warning) goto done;
    }
    rc = 0;
    fmi2Terminate(c);
done:;
    double sum = 0.0;
    for (long j = 0; reals && j < k * (long)(nr + 1); ++j) sum += reals[j];
    printf("points %ld last_time %.17g checksum %.17g\n", k, t, sum);
    fmi2FreeInstance(c);
    free(reals);
    free(ints);
    return rc;
}
