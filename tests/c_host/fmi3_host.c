/* A minimal FMI 3.0 co-simulation importer for the tests: no Python, no libpython linked.
 *
 *   fmi3_host UNZIPDIR MODEL_ID TOKEN STOP STEP EVENTS [VR=VALUE ...]
 *
 * EVENTS = 2: model exchange instead, integrated by explicit Euler with step STEP; a sign change
 * of an event indicator between two steps enters Event Mode; prints
 * "event,<time>,<valuesOfContinuousStatesChanged>" for each.
 *
 * EVENTS = 1: instantiate with eventModeUsed and earlyReturnAllowed; after every fmi3DoStep that
 * reports eventHandlingNeeded, run Event Mode (fmi3EnterEventMode, fmi3UpdateDiscreteStates until
 * done, fmi3EnterStepMode) and print "event,<lastSuccessfulTime %.17g>,<earlyReturn>".  After an
 * early return the next step goes from lastSuccessfulTime to the next grid point k*STEP.
 * EVENTS = 0: neither (the FMU handles its events inside each step, as in FMI 2.0).
 * VR=VALUE: Float64 parameters set in Initialization Mode (Int32 if VALUE has the form iN).
 * Prints "end,<time>" after the last step.  The FMU's log goes to stderr.  Exit status 0 if the
 * run reached STOP, 1 if a call failed.
 *
 * The same source builds for Windows with zig cc (LoadLibrary, binaries/x86_64-windows/<id>.dll;
 * the tests run it under wine against the native FMUs' Windows binaries) and for aarch64 Linux
 * (binaries/aarch64-linux/<id>.so, run under qemu-aarch64). */
#ifdef _WIN32
#include <windows.h>
#define PLATFORM "x86_64-windows"
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
#define PLATFORM "x86_64-linux"
#endif
#define SUFFIX ".so"
#define OPEN(path) dlopen(path, RTLD_NOW | RTLD_LOCAL)
#define SYMBOL(lib, name) dlsym(lib, name)
#define CLOSE(lib) dlclose(lib)
#define OPEN_ERROR() dlerror()
#endif
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "fmi3Functions.h"

static void logger(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message)
{
    fprintf(stderr, "[%d|%s] %s\n", (int)status, category ? category : "", message ? message : "");
}

#define LOAD(name) name##TYPE *name = (name##TYPE *)SYMBOL(lib, #name); if (!name) { fprintf(stderr, "missing %s\n", #name); return 2; }

#define MAXN 64

/* The end of a run: "end,<t>" and fmi3Terminate after success, then fmi3FreeInstance, dlclose;
 * the exit status (0 success, 1 a call failed). */
static int finish(void *lib, fmi3Instance c, int ok, double t)
{
    fmi3TerminateTYPE *terminate = (fmi3TerminateTYPE *)SYMBOL(lib, "fmi3Terminate");
    fmi3FreeInstanceTYPE *free_instance = (fmi3FreeInstanceTYPE *)SYMBOL(lib, "fmi3FreeInstance");
    if (ok) {
        printf("end,%.17g\n", t);
        terminate(c);
    }
    free_instance(c);
    CLOSE(lib);
    return ok ? 0 : 1;
}

static int model_exchange(void *lib, char **argv, int argc, const char *resources, double stop, double h)
{
    LOAD(fmi3InstantiateModelExchange) LOAD(fmi3EnterInitializationMode) LOAD(fmi3ExitInitializationMode)
    LOAD(fmi3SetFloat64) LOAD(fmi3EnterEventMode) LOAD(fmi3UpdateDiscreteStates) LOAD(fmi3EnterContinuousTimeMode)
    LOAD(fmi3GetNumberOfContinuousStates) LOAD(fmi3GetNumberOfEventIndicators) LOAD(fmi3GetContinuousStates)
    LOAD(fmi3SetContinuousStates) LOAD(fmi3GetContinuousStateDerivatives) LOAD(fmi3GetEventIndicators)
    LOAD(fmi3SetTime) LOAD(fmi3CompletedIntegratorStep)
    fmi3Instance c = fmi3InstantiateModelExchange("host", argv[3], resources, fmi3False, fmi3False, NULL, logger);
    if (!c) { fprintf(stderr, "fmi3InstantiateModelExchange returned NULL\n"); return 3; }
    size_t nx = 0, nz = 0;
    double x[MAXN], dx[MAXN], z[MAXN], znew[MAXN], next_time, t = 0.0;
    fmi3Boolean more, terminate, nominals, values, next_defined, enter, changed;
    if (fmi3EnterInitializationMode(c, fmi3False, 0.0, 0.0, fmi3True, stop) > fmi3Warning) goto done;
    for (int a = 7; a < argc; ++a) {
        fmi3ValueReference vr = (fmi3ValueReference)strtoul(argv[a], NULL, 10);
        double v = atof(strchr(argv[a], '=') + 1);
        if (fmi3SetFloat64(c, &vr, 1, &v, 1) > fmi3Warning) goto done;
    }
    if (fmi3ExitInitializationMode(c) > fmi3Warning) goto done;
    if (fmi3GetNumberOfContinuousStates(c, &nx) > fmi3Warning || fmi3GetNumberOfEventIndicators(c, &nz) > fmi3Warning) goto done;
    if (nx > MAXN || nz > MAXN) goto done;
    do {
        if (fmi3UpdateDiscreteStates(c, &more, &terminate, &nominals, &values, &next_defined, &next_time) > fmi3Warning) goto done;
    } while (more && !terminate);
    if (fmi3EnterContinuousTimeMode(c) > fmi3Warning) goto done;
    if (fmi3GetContinuousStates(c, x, nx) > fmi3Warning || fmi3GetEventIndicators(c, z, nz) > fmi3Warning) goto done;
    long steps = (long)(stop / h + 0.5);
    for (long k = 1; k <= steps; ++k) {
        if (fmi3GetContinuousStateDerivatives(c, dx, nx) > fmi3Warning) goto done;
        for (size_t i = 0; i < nx; ++i) x[i] += h * dx[i];
        t = k * h;
        if (fmi3SetTime(c, t) > fmi3Warning || fmi3SetContinuousStates(c, x, nx) > fmi3Warning) goto done;
        if (fmi3GetEventIndicators(c, znew, nz) > fmi3Warning) goto done;
        if (fmi3CompletedIntegratorStep(c, fmi3True, &enter, &terminate) > fmi3Warning) goto done;
        int crossed = 0;
        for (size_t i = 0; i < nz; ++i)
            crossed |= (z[i] > 0 && znew[i] <= 0) || (z[i] < 0 && znew[i] >= 0);
        if (crossed || enter) {
            if (fmi3EnterEventMode(c) > fmi3Warning) goto done;
            changed = fmi3False;
            do {
                if (fmi3UpdateDiscreteStates(c, &more, &terminate, &nominals, &values, &next_defined, &next_time) > fmi3Warning) goto done;
                changed |= values;
            } while (more && !terminate);
            if (fmi3EnterContinuousTimeMode(c) > fmi3Warning) goto done;
            if (fmi3GetContinuousStates(c, x, nx) > fmi3Warning || fmi3GetEventIndicators(c, znew, nz) > fmi3Warning) goto done;
            printf("event,%.17g,%d\n", t, (int)changed);
        }
        memcpy(z, znew, nz * sizeof *z);
        if (terminate) break;
    }
    return finish(lib, c, 1, t);
done:
    return finish(lib, c, 0, t);
}

int main(int argc, char **argv)
{
    if (argc < 7) { fprintf(stderr, "usage: see the source\n"); return 2; }
    char path[4096], resources[4200];
    snprintf(path, sizeof path, "%s/binaries/" PLATFORM "/%s" SUFFIX, argv[1], argv[2]);
    void *lib = OPEN(path);
    if (!lib) { fprintf(stderr, "loading %s: %s\n", path, OPEN_ERROR()); return 2; }
    LOAD(fmi3InstantiateCoSimulation) LOAD(fmi3EnterInitializationMode) LOAD(fmi3ExitInitializationMode)
    LOAD(fmi3DoStep) LOAD(fmi3SetFloat64) LOAD(fmi3SetInt32) LOAD(fmi3EnterEventMode)
    LOAD(fmi3UpdateDiscreteStates) LOAD(fmi3EnterStepMode)
    snprintf(resources, sizeof resources, "%s/resources/", argv[1]);
    double stop = atof(argv[4]), h = atof(argv[5]);
    int events = atoi(argv[6]);
    if (events == 2) return model_exchange(lib, argv, argc, resources, stop, h);
    fmi3Instance c = fmi3InstantiateCoSimulation("host", argv[3], resources, fmi3False, fmi3False, events, events,
                                                 NULL, 0, NULL, logger, NULL);
    if (!c) { fprintf(stderr, "fmi3InstantiateCoSimulation returned NULL\n"); return 3; }
    fmi3Boolean more, terminate, nominals, values, next_defined, handle, early;
    double next_time, t = 0.0, last;
    if (fmi3EnterInitializationMode(c, fmi3False, 0.0, 0.0, fmi3True, stop) > fmi3Warning) goto done;
    for (int a = 7; a < argc; ++a) {
        fmi3ValueReference vr = (fmi3ValueReference)strtoul(argv[a], NULL, 10);
        const char *value = strchr(argv[a], '=') + 1;
        if (value[0] == 'i') {
            fmi3Int32 v = atoi(value + 1);
            if (fmi3SetInt32(c, &vr, 1, &v, 1) > fmi3Warning) goto done;
        } else {
            double v = atof(value);
            if (fmi3SetFloat64(c, &vr, 1, &v, 1) > fmi3Warning) goto done;
        }
    }
    if (fmi3ExitInitializationMode(c) > fmi3Warning) goto done;
    if (events) {
        do {
            if (fmi3UpdateDiscreteStates(c, &more, &terminate, &nominals, &values, &next_defined, &next_time) > fmi3Warning) goto done;
        } while (more && !terminate);
        if (fmi3EnterStepMode(c) > fmi3Warning) goto done;
    }
    long steps = (long)(stop / h + 0.5), k = 1;
    while (k <= steps) {
        double target = k * h;
        if (fmi3DoStep(c, t, target - t, fmi3True, &handle, &terminate, &early, &last) > fmi3Warning) goto done;
        t = early ? last : target;
        if (!early) ++k;
        if (handle) {
            printf("event,%.17g,%d\n", last, (int)early);
            if (fmi3EnterEventMode(c) > fmi3Warning) goto done;
            do {
                if (fmi3UpdateDiscreteStates(c, &more, &terminate, &nominals, &values, &next_defined, &next_time) > fmi3Warning) goto done;
            } while (more && !terminate);
            if (fmi3EnterStepMode(c) > fmi3Warning) goto done;
        }
        if (terminate) break;
    }
    return finish(lib, c, 1, t);
done:
    return finish(lib, c, 0, t);
}
