/* Minimal FMI 2.0 co-simulation host for duffid's estimator FMUs (1-DOF).
 *
 * Loads the FMU's shared library with dlopen/dlsym (no fmpy), feeds one sample (x, f) per
 * doStep and prints the final estimates m b k kp, one per line (%.17g). Used by
 * tests/test_fmu_estimator.py to compare with fmpy.
 *
 *   fmu_host <binary.so> <guid> <resourceURI> <dt> <samples.txt>   (lines "x f")
 *
 * Build: gcc -std=c99 -Wall -Wextra -Werror -I<fmpy>/c-code fmu_host.c -o fmu_host -ldl
 */
#define _POSIX_C_SOURCE 200809L
#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...)
{
    va_list args;
    (void)env;
    fprintf(stderr, "[%s] %d %s: ", name, (int)status, category);
    va_start(args, message);
    vfprintf(stderr, message, args);
    va_end(args);
    fputc('\n', stderr);
}

static void *symbol(void *lib, const char *name)
{
    void *p = dlsym(lib, name);
    if (p == NULL) {
        fprintf(stderr, "missing symbol %s\n", name);
        exit(2);
    }
    return p;
}

#define LOAD(type, name) type name; *(void **)(&name) = symbol(lib, #name)

int main(int argc, char **argv)
{
    void *lib;
    fmi2Component c;
    fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
    double dt, x, f, t = 0.0, est[4];
    fmi2ValueReference vr_in[2], vr_out[4] = {0, 0, 0, 0};
    FILE *samples;
    int i;
    if (argc != 6) {
        fprintf(stderr, "usage: %s binary guid resourceURI dt samples\n", argv[0]);
        return 2;
    }
    dt = atof(argv[4]);
    lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (lib == NULL) {
        fprintf(stderr, "dlopen: %s\n", dlerror());
        return 2;
    }
    {
        LOAD(fmi2InstantiateTYPE *, fmi2Instantiate);
        LOAD(fmi2SetupExperimentTYPE *, fmi2SetupExperiment);
        LOAD(fmi2EnterInitializationModeTYPE *, fmi2EnterInitializationMode);
        LOAD(fmi2ExitInitializationModeTYPE *, fmi2ExitInitializationMode);
        LOAD(fmi2SetRealTYPE *, fmi2SetReal);
        LOAD(fmi2GetRealTYPE *, fmi2GetReal);
        LOAD(fmi2DoStepTYPE *, fmi2DoStep);
        LOAD(fmi2TerminateTYPE *, fmi2Terminate);
        LOAD(fmi2FreeInstanceTYPE *, fmi2FreeInstance);
        /* value references of the layout documented in fmus/estimator/fmu_model_estimator.c */
        vr_in[0] = 1; /* x */
        vr_in[1] = 2; /* f */
        for (i = 0; i < 4; i++) vr_out[i] = (fmi2ValueReference)(3 + i); /* m_hat .. kp_hat */
        c = fmi2Instantiate("host", fmi2CoSimulation, argv[2], argv[3], &callbacks, fmi2False, fmi2False);
        if (c == NULL) return 1;
        if (fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) != fmi2OK ||
            fmi2EnterInitializationMode(c) != fmi2OK || fmi2ExitInitializationMode(c) != fmi2OK)
            return 1;
        samples = fopen(argv[5], "r");
        if (samples == NULL) return 2;
        while (fscanf(samples, "%lf %lf", &x, &f) == 2) {
            double u[2];
            u[0] = x;
            u[1] = f;
            if (fmi2SetReal(c, vr_in, 2, u) != fmi2OK || fmi2DoStep(c, t, dt, fmi2True) != fmi2OK) return 1;
            t += dt;
        }
        fclose(samples);
        if (fmi2GetReal(c, vr_out, 4, est) != fmi2OK) return 1;
        for (i = 0; i < 4; i++) printf("%.17g\n", est[i]);
        fmi2Terminate(c);
        fmi2FreeInstance(c);
    }
    dlclose(lib);
    return 0;
}
