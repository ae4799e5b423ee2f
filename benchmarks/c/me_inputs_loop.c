/* The cost of an input change in FMI 3.0 model exchange: a fixed-step explicit Euler importer that
 * sets one Float64 input before each evaluation (an importer with a continuous input sets it at every
 * right-hand side), then the time, the states, and asks the derivatives and the event indicators.
 * Run it under callgrind with VARY 0 (the input held) and VARY 1 (u = U0 + sin t): the difference
 * of the instructions over N is the work of one input change (docs/performance.md, 2026-12-07).
 *
 *   me_inputs_loop LIBRARY TOKEN INPUT_VR U0 NX NZ VARY N
 *
 * Prints the last states and the sum of the first indicator (the bits to compare between builds);
 * exit status 0, 2-3 if the FMU does not load, 4-5 if an FMI call failed. */
#include <dlfcn.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "fmi3Functions.h"

#define MAXN 64

static void logger(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message)
{
    fprintf(stderr, "[%d|%s] %s\n", (int)status, category ? category : "", message ? message : "");
}

#define LOAD(name) name##TYPE *name = (name##TYPE *)dlsym(lib, #name)

int main(int argc, char **argv)
{
    if (argc != 9) {
        fprintf(stderr, "usage: me_inputs_loop LIBRARY TOKEN INPUT_VR U0 NX NZ VARY N\n");
        return 2;
    }
    void *lib = dlopen(argv[1], RTLD_NOW);
    if (!lib) {
        fprintf(stderr, "%s\n", dlerror());
        return 2;
    }
    fmi3ValueReference vr = (fmi3ValueReference)atol(argv[3]);
    double u0 = atof(argv[4]);
    size_t nx = (size_t)atol(argv[5]), nz = (size_t)atol(argv[6]);
    int vary = atoi(argv[7]);
    long n = atol(argv[8]);
    if (nx > MAXN || nz > MAXN || nz < 1) return 2;
    LOAD(fmi3InstantiateModelExchange); LOAD(fmi3EnterInitializationMode); LOAD(fmi3ExitInitializationMode);
    LOAD(fmi3UpdateDiscreteStates); LOAD(fmi3EnterContinuousTimeMode); LOAD(fmi3SetTime);
    LOAD(fmi3SetContinuousStates); LOAD(fmi3GetContinuousStates); LOAD(fmi3GetContinuousStateDerivatives);
    LOAD(fmi3GetEventIndicators); LOAD(fmi3SetFloat64); LOAD(fmi3FreeInstance);
    fmi3Instance c = fmi3InstantiateModelExchange("me", argv[2], NULL, fmi3False, fmi3False, NULL, logger);
    if (!c) return 3;
    if (fmi3EnterInitializationMode(c, fmi3False, 0.0, 0.0, fmi3False, 0.0) > fmi3Warning ||
        fmi3ExitInitializationMode(c) > fmi3Warning)
        return 4;
    fmi3Boolean need = fmi3True, term, nominals, values, next;
    fmi3Float64 t_next;
    while (need)
        if (fmi3UpdateDiscreteStates(c, &need, &term, &nominals, &values, &next, &t_next) > fmi3Warning) return 4;
    fmi3EnterContinuousTimeMode(c);
    double x[MAXN], dx[MAXN], z[MAXN], h = 1e-6, sum = 0.0;
    fmi3GetContinuousStates(c, x, nx);
    for (long k = 1; k <= n; ++k) {
        double t = k * h, u = vary ? u0 + sin(t) : u0;
        if (fmi3SetFloat64(c, &vr, 1, &u, 1) > fmi3Warning) return 5;
        fmi3SetTime(c, t);
        fmi3SetContinuousStates(c, x, nx);
        if (fmi3GetContinuousStateDerivatives(c, dx, nx) > fmi3Warning || fmi3GetEventIndicators(c, z, nz) > fmi3Warning)
            return 5;
        for (size_t i = 0; i < nx; ++i) x[i] += h * dx[i];
        sum += z[0];
    }
    printf("x");
    for (size_t i = 0; i < nx; ++i) printf(" %.17g", x[i]);
    printf(" z %.17g\n", sum);
    fmi3FreeInstance(c);
    return 0;
}
