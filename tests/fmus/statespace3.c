/*
 * statespace3.c - a StateSpace-like FMI 3.0 test model (duffid's own code): the linear system
 *     der(x) = A x + B u,  y = C x + D u,  x(t0) = x0
 * with m inputs, n states and r outputs given by structural parameters (arrays sized by them),
 * advanced by one explicit Euler step per doStep.
 */
#include <string.h>

#include "typed_fmu.h"
#include "typed_model.h"

static size_t count(Model *m, int index) { return (size_t)((unsigned long long *)model_values(m, index))[0]; }

void model_initialize(Model *m)
{
    memcpy(model_values(m, V_x), model_values(m, V_x0), count(m, V_n) * sizeof(double));
}

void model_calculate(Model *m)
{
    size_t i, j, nu = count(m, V_m), nx = count(m, V_n), ny = count(m, V_r);
    const double *C = model_values(m, V_C), *D = model_values(m, V_D), *x = model_values(m, V_x);
    const double *u = model_values(m, V_u);
    double *y = model_values(m, V_y);
    for (i = 0; i < ny; i++) {
        double s = 0;
        for (j = 0; j < nx; j++) s += C[i * nx + j] * x[j];
        for (j = 0; j < nu; j++) s += D[i * nu + j] * u[j];
        y[i] = s;
    }
}

void model_step(Model *m, double h)
{
    size_t i, j, nu = count(m, V_m), nx = count(m, V_n);
    const double *A = model_values(m, V_A), *B = model_values(m, V_B), *u = model_values(m, V_u);
    double *x = model_values(m, V_x), dx[16];
    for (i = 0; i < nx && i < 16; i++) {
        double s = 0;
        for (j = 0; j < nx; j++) s += A[i * nx + j] * x[j];
        for (j = 0; j < nu; j++) s += B[i * nu + j] * u[j];
        dx[i] = s;
    }
    for (i = 0; i < nx && i < 16; i++) x[i] += h * dx[i];
}

MODEL_WITHOUT_EVENTS
