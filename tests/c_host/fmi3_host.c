/* A minimal FMI 3.0 co-simulation importer for the tests: no Python, no libpython linked.
 *
 *   fmi3_host UNZIPDIR MODEL_ID TOKEN STOP STEP EVENTS [VR=VALUE ...]
 *
 * EVENTS = 1: instantiate with eventModeUsed and earlyReturnAllowed; after every fmi3DoStep that
 * reports eventHandlingNeeded, run Event Mode (fmi3EnterEventMode, fmi3UpdateDiscreteStates until
 * done, fmi3EnterStepMode) and print "event,<lastSuccessfulTime %.17g>,<earlyReturn>".  After an
 * early return the next step goes from lastSuccessfulTime to the next grid point k*STEP.
 * EVENTS = 0: neither (the FMU handles its events inside each step, as in FMI 2.0).
 * VR=VALUE: Float64 parameters set in Initialization Mode (Int32 if VALUE has the form iN).
 * Prints "end,<time>" after the last step.  The FMU's log goes to stderr.  Exit status 0 if the
 * run reached STOP, 1 if a call failed. */
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "fmi3Functions.h"

static void logger(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message)
{
    fprintf(stderr, "[%d|%s] %s\n", (int)status, category ? category : "", message ? message : "");
}

#define LOAD(name) name##TYPE *name = (name##TYPE *)dlsym(lib, #name); if (!name) { fprintf(stderr, "missing %s\n", #name); return 2; }

int main(int argc, char **argv)
{
    if (argc < 7) { fprintf(stderr, "usage: see the source\n"); return 2; }
    char path[4096], resources[4200];
    snprintf(path, sizeof path, "%s/binaries/x86_64-linux/%s.so", argv[1], argv[2]);
    void *lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!lib) { fprintf(stderr, "dlopen: %s\n", dlerror()); return 2; }
    LOAD(fmi3InstantiateCoSimulation) LOAD(fmi3EnterInitializationMode) LOAD(fmi3ExitInitializationMode)
    LOAD(fmi3DoStep) LOAD(fmi3SetFloat64) LOAD(fmi3SetInt32) LOAD(fmi3EnterEventMode)
    LOAD(fmi3UpdateDiscreteStates) LOAD(fmi3EnterStepMode) LOAD(fmi3Terminate) LOAD(fmi3FreeInstance)
    snprintf(resources, sizeof resources, "%s/resources/", argv[1]);
    double stop = atof(argv[4]), h = atof(argv[5]);
    int events = atoi(argv[6]);
    fmi3Instance c = fmi3InstantiateCoSimulation("host", argv[3], resources, fmi3False, fmi3False, events, events,
                                                 NULL, 0, NULL, logger, NULL);
    if (!c) { fprintf(stderr, "fmi3InstantiateCoSimulation returned NULL\n"); return 3; }
    int rc = 1;
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
    printf("end,%.17g\n", t);
    rc = 0;
    fmi3Terminate(c);
done:
    fmi3FreeInstance(c);
    dlclose(lib);
    return rc;
}
