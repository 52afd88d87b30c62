/*
 * duffid_sensitivities.c - the refinement's stretches simulated with their sensitivities
 * (duffid_sensitivities.h). The model's RK4 step and acceleration come from the generated
 * file compiled with this one.
 */
#include "duffid_sensitivities.h"

#include <stdlib.h>
#include <string.h>

/* The outputs of one sample: y (n) and dy (n x n_sens, row by row) from the state [z; vec S]
 * (velocities: the rows after the displacements; accelerations: the model's right-hand side
 * under the forces f, its derivatives chained with S). */
static void sample_output(int n, int n_free, int n_sens, int output, const double *state, const double *f,
                          const double *p, double *acc, double *d_state, double *d_free, double *work,
                          double *y, double *dy)
{
    int m = 2 * n;
    const double *S = state + m;
    if (output != DUFFID_OUTPUT_ACCELERATION) {
        int first = output == DUFFID_OUTPUT_DISPLACEMENT ? 0 : n;
        for (int i = 0; i < n; i++) {
            y[i] = state[first + i];
            for (int k = 0; k < n_sens; k++)
                dy[i * n_sens + k] = S[k * m + first + i];
        }
        return;
    }
    duffid_sensitivity_acceleration(state, f, p, acc, d_state, d_free, work);
    for (int i = 0; i < n; i++) {
        y[i] = acc[i];
        for (int k = 0; k < n_sens; k++) {
            double v = k < n_free ? d_free[k * n + i] : 0.0;
            for (int r = 0; r < m; r++)
                v += d_state[r * n + i] * S[k * m + r];
            dy[i * n_sens + k] = v;
        }
    }
}

int duffid_simulate_sensitivities(int n_dof, int n_forces, int n_free, int substeps, double h, const double *p,
                                  const double *stages, long n_str, const long *start, const long *length,
                                  const double *z0, int output, double *y, double *dy)
{
    int n = n_dof, m = 2 * n_dof, n_sens = n_free + 2 * n_dof, row = 3 * n_forces;
    long size = m + (long)m * n_sens, work_size = duffid_sensitivity_work(), done = 0;
    double *buffer, *z, *z_next, *work, *acc, *d_state, *d_free;
    if (output < DUFFID_OUTPUT_DISPLACEMENT || output > DUFFID_OUTPUT_ACCELERATION)
        return -1;
    buffer = (double *)malloc((size_t)(2 * size + (work_size > 0 ? work_size : 1) + n + n * m + n * (n_free + 1)) *
                              sizeof(double));
    if (buffer == NULL)
        return -1;
    z = buffer;
    z_next = z + size;
    work = z_next + size;
    acc = work + (work_size > 0 ? work_size : 1);
    d_state = acc + n;
    d_free = d_state + n * m;
    for (long j = 0; j < n_str; j++) {
        const double *u = stages + start[j] * substeps * row;
        long count = length[j];
        /* the initial state, its sensitivities: none to the parameters, identity to itself */
        memset(z, 0, (size_t)size * sizeof(double));
        memcpy(z, z0 + j * m, (size_t)m * sizeof(double));
        for (int c = 0; c < m; c++)
            z[m + (n_free + c) * m + c] = 1.0;
        for (long i = 0; i < count; i++) {
            /* the force at sample s = start + i: the end of the step before it (the same value
             * as the start of its own step, which the record's last sample does not have) */
            long s = start[j] + i;
            const double *f = s > 0 ? stages + (s * substeps - 1) * row + 2 * n_forces : stages;
            if (i > 0)
                for (int k = 0; k < substeps; k++) {
                    double *swap;
                    duffid_sensitivity_step(z, u + ((i - 1) * substeps + k) * row, p, h, z_next, work);
                    swap = z; z = z_next; z_next = swap;
                }
            sample_output(n, n_free, n_sens, output, z, f, p, acc, d_state, d_free, work, y + (done + i) * n,
                          dy + (done + i) * n * n_sens);
        }
        done += count;
    }
    free(buffer);
    return 0;
}
