/* A multi-threaded FMI 2.0 co-simulation importer for the concurrency tests: no Python, no
 * libpython linked. Each argument UNZIPDIR:MODEL_ID:GUID is one thread; the threads load their
 * FMU's library (several threads may share one), wait at a barrier, call fmi2Instantiate at the
 * same moment, then initialize and take 100 steps of 1 ms each, and report
 *
 *   <thread> ok <t reached> <first real output after the run>     or     <thread> failed <where>
 *
 * one line per thread. Exit status 0 if every thread reached the end. */
#include <dlfcn.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "fmi2Functions.h"

#define STEPS 100

typedef struct {
    int index;
    char dir[4096], id[256], guid[256];
    unsigned vr; /* a Real output read after the run */
    char result[512];
} Job;

static pthread_barrier_t barrier;

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2String category_unused_status_order,
                   ...)
{
    (void)env; (void)name; (void)category_unused_status_order; /* quiet: the result line says enough */
}

static void *run(void *arg)
{
    Job *job = arg;
    char path[4400], uri[4400];
    snprintf(path, sizeof path, "%s/binaries/linux64/%s.so", job->dir, job->id);
    void *lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        snprintf(job->result, sizeof job->result, "failed dlopen: %s", dlerror());
        pthread_barrier_wait(&barrier);
        return NULL;
    }
    fmi2InstantiateTYPE *inst = (fmi2InstantiateTYPE *)dlsym(lib, "fmi2Instantiate");
    fmi2SetupExperimentTYPE *setup = (fmi2SetupExperimentTYPE *)dlsym(lib, "fmi2SetupExperiment");
    fmi2EnterInitializationModeTYPE *enter = (fmi2EnterInitializationModeTYPE *)dlsym(lib, "fmi2EnterInitializationMode");
    fmi2ExitInitializationModeTYPE *exit_ = (fmi2ExitInitializationModeTYPE *)dlsym(lib, "fmi2ExitInitializationMode");
    fmi2DoStepTYPE *step = (fmi2DoStepTYPE *)dlsym(lib, "fmi2DoStep");
    fmi2GetRealTYPE *get = (fmi2GetRealTYPE *)dlsym(lib, "fmi2GetReal");
    fmi2FreeInstanceTYPE *freei = (fmi2FreeInstanceTYPE *)dlsym(lib, "fmi2FreeInstance");
    snprintf(uri, sizeof uri, "file://%s/resources", job->dir);
    fmi2CallbackFunctions cb = {(fmi2CallbackLogger)logger, calloc, free, NULL, NULL};
    char name[32];
    snprintf(name, sizeof name, "thread%d", job->index);
    pthread_barrier_wait(&barrier); /* every thread instantiates at once */
    fmi2Component c = inst(name, fmi2CoSimulation, job->guid, uri, &cb, fmi2False, fmi2True);
    if (!c) {
        snprintf(job->result, sizeof job->result, "failed fmi2Instantiate returned NULL");
        return NULL;
    }
    if (setup(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) > fmi2Warning || enter(c) > fmi2Warning || exit_(c) > fmi2Warning) {
        snprintf(job->result, sizeof job->result, "failed initialization");
        freei(c);
        return NULL;
    }
    double t = 0.0;
    for (int k = 0; k < STEPS; ++k, t = k * 1e-3)
        if (step(c, t, 1e-3, fmi2True) > fmi2Warning) {
            snprintf(job->result, sizeof job->result, "failed fmi2DoStep at t = %g", t);
            freei(c);
            return NULL;
        }
    fmi2ValueReference vr = job->vr;
    double y = 0.0;
    get(c, &vr, 1, &y);
    snprintf(job->result, sizeof job->result, "ok %.17g %.17g", t, y);
    freei(c);
    return NULL;
}

int main(int argc, char **argv)
{
    int n = argc - 1;
    if (n < 1) { fprintf(stderr, "usage: fmi2_threads UNZIPDIR:MODEL_ID:GUID#VR ...\n"); return 2; }
    Job *jobs = calloc((size_t)n, sizeof *jobs);
    pthread_t *threads = calloc((size_t)n, sizeof *threads);
    pthread_barrier_init(&barrier, NULL, (unsigned)n);
    for (int i = 0; i < n; ++i) {
        jobs[i].index = i;
        char *a = argv[i + 1], *p = strchr(a, ':'), *q = p ? strchr(p + 1, ':') : NULL;
        if (!p || !q) { fprintf(stderr, "bad argument %s\n", a); return 2; }
        snprintf(jobs[i].dir, sizeof jobs[i].dir, "%.*s", (int)(p - a), a);
        snprintf(jobs[i].id, sizeof jobs[i].id, "%.*s", (int)(q - p - 1), p + 1);
        snprintf(jobs[i].guid, sizeof jobs[i].guid, "%s", q + 1);
        char *hash = strchr(jobs[i].guid, '#'); /* GUID#VR: the Real output to report */
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
