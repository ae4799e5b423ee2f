/* An FMI 3.0 model-exchange importer for the tests, integrating with SUNDIALS CVODE the way
 * Reference-FMUs' fmusim (v0.0.39) does: BDF with root finding on the event indicators, and after
 * an event CVODE is re-initialized only if valuesOfContinuousStatesChanged — an event that changes
 * the mode but no state leaves the integrator as it was, so an indicator of the new mode that
 * starts at exactly zero makes CVODE stop ("Root found at and very near t").
 *
 *   fmi3_cvode UNZIPDIR MODEL_ID TOKEN STOP RTOL
 *
 * Prints "event,<time %.17g>,<valuesOfContinuousStatesChanged>" at each event and "end,<time>"
 * when it reached STOP; exit status 0 then, 1 if an FMI or CVODE call failed (CVODE's message on
 * stderr), 2-3 if the FMU does not load.  No Python, no libpython. */
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cvode/cvode.h>
#include <nvector/nvector_serial.h>
#include <sunlinsol/sunlinsol_dense.h>
#include <sunmatrix/sunmatrix_dense.h>

#include "fmi3Functions.h"

#define MAXN 64

typedef struct {
    fmi3Instance c;
    fmi3SetTimeTYPE *set_time;
    fmi3SetContinuousStatesTYPE *set_states;
    fmi3GetContinuousStateDerivativesTYPE *get_derivatives;
    fmi3GetEventIndicatorsTYPE *get_indicators;
    size_t nx, nz;
    int failed;
} Model;

static void logger(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message)
{
    fprintf(stderr, "[%d|%s] %s\n", (int)status, category ? category : "", message ? message : "");
}

static int rhs(sunrealtype t, N_Vector y, N_Vector ydot, void *data)
{
    Model *m = (Model *)data;
    if (m->set_time(m->c, t) > fmi3Warning || m->set_states(m->c, N_VGetArrayPointer(y), m->nx) > fmi3Warning ||
        m->get_derivatives(m->c, N_VGetArrayPointer(ydot), m->nx) > fmi3Warning) {
        m->failed = 1;
        return -1;
    }
    return 0;
}

static int roots(sunrealtype t, N_Vector y, sunrealtype *g, void *data)
{
    Model *m = (Model *)data;
    if (m->set_time(m->c, t) > fmi3Warning || m->set_states(m->c, N_VGetArrayPointer(y), m->nx) > fmi3Warning ||
        m->get_indicators(m->c, g, m->nz) > fmi3Warning) {
        m->failed = 1;
        return -1;
    }
    return 0;
}

#define LOAD(name) name##TYPE *name = (name##TYPE *)dlsym(lib, #name); if (!name) { fprintf(stderr, "missing %s\n", #name); return 2; }

int main(int argc, char **argv)
{
    if (argc != 6) {
        fprintf(stderr, "usage: fmi3_cvode UNZIPDIR MODEL_ID TOKEN STOP RTOL\n");
        return 2;
    }
    char path[4096], resources[4096];
    snprintf(path, sizeof path, "%s/binaries/x86_64-linux/%s.so", argv[1], argv[2]);
    snprintf(resources, sizeof resources, "%s/resources/", argv[1]);
    double stop = atof(argv[4]), rtol = atof(argv[5]);
    void *lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!lib) { fprintf(stderr, "%s\n", dlerror()); return 2; }
    LOAD(fmi3InstantiateModelExchange) LOAD(fmi3EnterInitializationMode) LOAD(fmi3ExitInitializationMode)
    LOAD(fmi3EnterEventMode) LOAD(fmi3UpdateDiscreteStates) LOAD(fmi3EnterContinuousTimeMode)
    LOAD(fmi3GetNumberOfContinuousStates) LOAD(fmi3GetNumberOfEventIndicators) LOAD(fmi3GetContinuousStates)
    LOAD(fmi3SetContinuousStates) LOAD(fmi3GetContinuousStateDerivatives) LOAD(fmi3GetEventIndicators)
    LOAD(fmi3SetTime) LOAD(fmi3CompletedIntegratorStep) LOAD(fmi3Terminate) LOAD(fmi3FreeInstance)
    Model m = {0};
    m.set_time = fmi3SetTime, m.set_states = fmi3SetContinuousStates;
    m.get_derivatives = fmi3GetContinuousStateDerivatives, m.get_indicators = fmi3GetEventIndicators;
    m.c = fmi3InstantiateModelExchange("cvode", argv[3], resources, fmi3False, fmi3False, NULL, logger);
    if (!m.c) { fprintf(stderr, "fmi3InstantiateModelExchange returned NULL\n"); return 3; }
    int ok = 0;
    double t = 0.0;
    fmi3Boolean more = fmi3True, terminate, nominals, values = fmi3False, next_defined, enter, stop_now;
    double next_time;
    SUNContext ctx = NULL;
    void *cv = NULL;
    N_Vector y = NULL;
    SUNMatrix A = NULL;
    SUNLinearSolver LS = NULL;
    if (fmi3EnterInitializationMode(m.c, fmi3False, 0.0, 0.0, fmi3True, stop) > fmi3Warning) goto done;
    if (fmi3ExitInitializationMode(m.c) > fmi3Warning) goto done;
    while (more)
        if (fmi3UpdateDiscreteStates(m.c, &more, &terminate, &nominals, &values, &next_defined, &next_time) >
            fmi3Warning) goto done;
    if (fmi3EnterContinuousTimeMode(m.c) > fmi3Warning) goto done;
    if (fmi3GetNumberOfContinuousStates(m.c, &m.nx) > fmi3Warning ||
        fmi3GetNumberOfEventIndicators(m.c, &m.nz) > fmi3Warning || m.nx == 0 || m.nx > MAXN || m.nz > MAXN)
        goto done;
    if (SUNContext_Create(NULL, &ctx)) goto done;
    y = N_VNew_Serial((sunindextype)m.nx, ctx);
    if (fmi3GetContinuousStates(m.c, N_VGetArrayPointer(y), m.nx) > fmi3Warning) goto done;
    cv = CVodeCreate(CV_BDF, ctx);
    A = SUNDenseMatrix((sunindextype)m.nx, (sunindextype)m.nx, ctx);
    LS = SUNLinSol_Dense(y, A, ctx);
    if (CVodeInit(cv, rhs, t, y) || CVodeSStolerances(cv, rtol, rtol * 1e-2) || CVodeSetUserData(cv, &m) ||
        CVodeSetLinearSolver(cv, LS, A) || CVodeRootInit(cv, (int)m.nz, roots) || CVodeSetMaxNumSteps(cv, 1000000) ||
        CVodeSetStopTime(cv, stop))
        goto done;
    while (t < stop) {
        sunrealtype tret;
        int flag = CVode(cv, stop, y, &tret, CV_ONE_STEP);
        if (flag < 0 || m.failed) goto done;
        t = tret;
        fmi3SetTime(m.c, t);
        fmi3SetContinuousStates(m.c, N_VGetArrayPointer(y), m.nx);
        if (fmi3CompletedIntegratorStep(m.c, fmi3True, &enter, &stop_now) > fmi3Warning) goto done;
        if (flag == CV_ROOT_RETURN || enter) {
            if (fmi3EnterEventMode(m.c) > fmi3Warning) goto done;
            int changed = 0;
            more = fmi3True;
            while (more) {
                if (fmi3UpdateDiscreteStates(m.c, &more, &terminate, &nominals, &values, &next_defined, &next_time) >
                    fmi3Warning) goto done;
                changed |= values != 0;
            }
            if (fmi3EnterContinuousTimeMode(m.c) > fmi3Warning) goto done;
            printf("event,%.17g,%d\n", t, changed);
            if (changed) {  /* fmusim: re-initialize only when a state changed */
                if (fmi3GetContinuousStates(m.c, N_VGetArrayPointer(y), m.nx) > fmi3Warning) goto done;
                if (CVodeReInit(cv, t, y)) goto done;
            }
        }
    }
    ok = 1;
    printf("end,%.17g\n", t);
    fmi3Terminate(m.c);
done:
    fmi3FreeInstance(m.c);
    if (cv) CVodeFree(&cv);
    if (LS) SUNLinSolFree(LS);
    if (A) SUNMatDestroy(A);
    if (y) N_VDestroy(y);
    if (ctx) SUNContext_Free(&ctx);
    dlclose(lib);
    return ok ? 0 : 1;
}
