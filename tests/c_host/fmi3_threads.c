/* A multi-threaded FMI 3.0 co-simulation importer for the concurrency tests: no Python, no
 * libpython linked. Each argument UNZIPDIR:MODEL_ID:TOKEN#VR is one thread; the threads load their
 * FMU's library (several threads may share one), wait at a barrier, call
 * fmi3InstantiateCoSimulation (eventModeUsed, earlyReturnAllowed) at the same moment, then
 * initialize and step to 1 s on a 1 ms grid, handling every early return in Event Mode, and
 * report
 *
 *   <thread> ok <t reached> <the Float64 output VR after the run> <events>    or    <thread> failed <where>
 *
 * one line per thread. Exit status 0 if every thread reached the end. */
#include <dlfcn.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "fmi3Functions.h"

typedef struct {
    int index;
    char dir[4096], id[256], token[256];
    unsigned vr;
    char result[512];
} Job;

static pthread_barrier_t barrier;

static void logger(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message)
{
    (void)env, (void)status, (void)category, (void)message; /* quiet: the result line says enough */
}

#define SYM(T, name) T *name = (T *)dlsym(lib, #name)

static void *run(void *arg)
{
    Job *job = arg;
    char path[4400], resources[4400];
    snprintf(path, sizeof path, "%s/binaries/x86_64-linux/%s.so", job->dir, job->id);
    void *lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        snprintf(job->result, sizeof job->result, "failed dlopen: %s", dlerror());
        pthread_barrier_wait(&barrier);
        return NULL;
    }
    SYM(fmi3InstantiateCoSimulationTYPE, fmi3InstantiateCoSimulation);
    SYM(fmi3EnterInitializationModeTYPE, fmi3EnterInitializationMode);
    SYM(fmi3ExitInitializationModeTYPE, fmi3ExitInitializationMode);
    SYM(fmi3UpdateDiscreteStatesTYPE, fmi3UpdateDiscreteStates);
    SYM(fmi3EnterStepModeTYPE, fmi3EnterStepMode);
    SYM(fmi3EnterEventModeTYPE, fmi3EnterEventMode);
    SYM(fmi3DoStepTYPE, fmi3DoStep);
    SYM(fmi3GetFloat64TYPE, fmi3GetFloat64);
    SYM(fmi3FreeInstanceTYPE, fmi3FreeInstance);
    snprintf(resources, sizeof resources, "%s/resources/", job->dir);
    char name[32];
    snprintf(name, sizeof name, "thread%d", job->index);
    pthread_barrier_wait(&barrier); /* every thread instantiates at once */
    fmi3Instance c = fmi3InstantiateCoSimulation(name, job->token, resources, fmi3False, fmi3False, fmi3True, fmi3True,
                                                 NULL, 0, NULL, logger, NULL);
    if (!c) {
        snprintf(job->result, sizeof job->result, "failed fmi3InstantiateCoSimulation returned NULL");
        return NULL;
    }
    fmi3Boolean more, term, nominals, values, next_defined, handle, early;
    double next_time, last, t = 0.0;
    int events = 0;
    if (fmi3EnterInitializationMode(c, fmi3False, 0.0, 0.0, fmi3False, 0.0) > fmi3Warning ||
        fmi3ExitInitializationMode(c) > fmi3Warning ||
        fmi3UpdateDiscreteStates(c, &more, &term, &nominals, &values, &next_defined, &next_time) > fmi3Warning ||
        fmi3EnterStepMode(c) > fmi3Warning) {
        snprintf(job->result, sizeof job->result, "failed initialization");
        fmi3FreeInstance(c);
        return NULL;
    }
    for (int k = 1; k <= 1000;) {
        double target = k * 1e-3;
        if (fmi3DoStep(c, t, target - t, fmi3True, &handle, &term, &early, &last) > fmi3Warning) {
            snprintf(job->result, sizeof job->result, "failed fmi3DoStep at t = %g", t);
            fmi3FreeInstance(c);
            return NULL;
        }
        t = early ? last : target;
        if (!early) ++k;
        if (handle) {
            ++events;
            if (fmi3EnterEventMode(c) > fmi3Warning ||
                fmi3UpdateDiscreteStates(c, &more, &term, &nominals, &values, &next_defined, &next_time) > fmi3Warning ||
                fmi3EnterStepMode(c) > fmi3Warning) {
                snprintf(job->result, sizeof job->result, "failed Event Mode at t = %g", t);
                fmi3FreeInstance(c);
                return NULL;
            }
        }
    }
    fmi3ValueReference vr = job->vr;
    double y = 0.0;
    fmi3GetFloat64(c, &vr, 1, &y, 1);
    snprintf(job->result, sizeof job->result, "ok %.17g %.17g %d", t, y, events);
    fmi3FreeInstance(c);
    return NULL;
}

int main(int argc, char **argv)
{
    int n = argc - 1;
    if (n < 1) { fprintf(stderr, "usage: fmi3_threads UNZIPDIR:MODEL_ID:TOKEN#VR ...\n"); return 2; }
    Job *jobs = calloc((size_t)n, sizeof *jobs);
    pthread_t *threads = calloc((size_t)n, sizeof *threads);
    pthread_barrier_init(&barrier, NULL, (unsigned)n);
    for (int i = 0; i < n; ++i) {
        jobs[i].index = i;
        char *a = argv[i + 1], *p = strchr(a, ':'), *q = p ? strchr(p + 1, ':') : NULL;
        if (!p || !q) { fprintf(stderr, "bad argument %s\n", a); return 2; }
        snprintf(jobs[i].dir, sizeof jobs[i].dir, "%.*s", (int)(p - a), a);
        snprintf(jobs[i].id, sizeof jobs[i].id, "%.*s", (int)(q - p - 1), p + 1);
        snprintf(jobs[i].token, sizeof jobs[i].token, "%s", q + 1);
        char *hash = strchr(jobs[i].token, '#');
        if (hash) { jobs[i].vr = (unsigned)atoi(hash + 1); *hash = '\0'; }
    }
    for (int i = 0; i < n; ++i) pthread_create(&threads[i], NULL, run, &jobs[i]);
    int failed = 0;
    for (int i = 0; i < n; ++i) {
        pthread_join(threads[i], NULL);
        printf("%d %s\n", i, jobs[i].result);
        failed |= strncmp(jobs[i].result, "ok", 2) != 0;
    }
    return failed;
}
