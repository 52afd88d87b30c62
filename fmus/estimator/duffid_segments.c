/*
 * duffid_segments.c - the simulation check's segments (duffid_segments.h): each segment's
 * initial state fitted to its first samples by Levenberg-Marquardt, then the segment
 * simulated from it. The model's RK4 step comes from the generated file compiled with this one.
 */
#include "duffid_segments.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Largest evaluations of the initial-state fit (scipy's least_squares max_nfev of the Python
 * path), its step and cost tolerances, and the largest damping tried. */
#define FIT_EVALUATIONS 50
#define FIT_TOLERANCE 1e-12
#define FIT_MAX_DAMPING 1e16

typedef struct {
    int n, nf, substeps;
    double h;
    const double *p;
    const double *stages;   /* of the segment's first step */
    double *z, *z_next, *work;
} simulation;

/* The state from sample i - 1 to sample i (substeps RK4 steps; with its sensitivities). */
static void advance(simulation *s, long i, int sensitivities)
{
    for (int k = 0; k < s->substeps; k++) {
        const double *u = s->stages + ((i - 1) * s->substeps + k) * 3 * s->nf;
        double *swap;
        if (sensitivities)
            duffid_segment_step_sens(s->z, u, s->p, s->h, s->z_next, s->work);
        else
            duffid_segment_step(s->z, u, s->p, s->h, s->z_next, s->work);
        swap = s->z; s->z = s->z_next; s->z_next = swap;
    }
}

/* Simulate samples 0..count-1 from z0 (2n) without sensitivities; the sum of squared scaled
 * errors against x (count x n) over the first `fit` samples; displacements to out if not NULL. */
static double simulate_plain(simulation *s, const double *z0, const double *x, long count, long fit,
                             double scale_x, double *out)
{
    int n = s->n;
    double cost = 0.0;
    memcpy(s->z, z0, (size_t)(2 * n) * sizeof(double));
    for (long i = 0; i < count; i++) {
        if (i > 0)
            advance(s, i, 0);
        for (int d = 0; d < n; d++) {
            if (out != NULL)
                out[i * n + d] = s->z[d];
            if (i < fit) {
                double e = (s->z[d] - x[i * n + d]) / scale_x;
                cost += e * e;
            }
        }
        if (out == NULL && i + 1 >= fit)
            break;
    }
    return cost;
}

/* The normal equations (a = J^T J, g = J^T r in the scaled state) and the cost over the
 * first `fit` samples, from the sensitivity step. */
static double normal_equations(simulation *s, const double *z0, const double *x, long fit, double scale_x,
                               const double *scales, double *a, double *g)
{
    int n = s->n, m = 2 * n;
    long size = m + (long)m * m;
    double cost = 0.0;
    memset(s->z, 0, (size_t)size * sizeof(double));
    memcpy(s->z, z0, (size_t)m * sizeof(double));
    for (int c = 0; c < m; c++)
        s->z[m + c * m + c] = 1.0;
    memset(a, 0, (size_t)(m * m) * sizeof(double));
    memset(g, 0, (size_t)m * sizeof(double));
    for (long i = 0; i < fit; i++) {
        if (i > 0)
            advance(s, i, 1);
        for (int d = 0; d < n; d++) {
            double r = (s->z[d] - x[i * n + d]) / scale_x, row[64];
            for (int c = 0; c < m; c++) {
                double v = s->z[m + c * m + d] * scales[c] / scale_x;
                row[c] = isfinite(v) ? v : 0.0;
            }
            cost += r * r;
            for (int c = 0; c < m; c++) {
                g[c] += row[c] * r;
                for (int e = 0; e < m; e++)
                    a[c * m + e] += row[c] * row[e];
            }
        }
    }
    return cost;
}

/* Solve (a + damping diag(a)) delta = -g by Gaussian elimination with partial pivoting;
 * 0 when singular. */
static int damped_step(int m, const double *a, const double *g, double damping, double *delta)
{
    double w[64 * 65];
    for (int r = 0; r < m; r++) {
        for (int c = 0; c < m; c++)
            w[r * (m + 1) + c] = a[r * m + c] + (r == c ? damping * (a[r * m + r] > 0 ? a[r * m + r] : 1e-300) : 0.0);
        w[r * (m + 1) + m] = -g[r];
    }
    for (int c = 0; c < m; c++) {
        int best = c;
        for (int r = c + 1; r < m; r++)
            if (fabs(w[r * (m + 1) + c]) > fabs(w[best * (m + 1) + c]))
                best = r;
        if (!(fabs(w[best * (m + 1) + c]) > 0.0))
            return 0;
        if (best != c)
            for (int k = 0; k <= m; k++) {
                double t = w[c * (m + 1) + k];
                w[c * (m + 1) + k] = w[best * (m + 1) + k];
                w[best * (m + 1) + k] = t;
            }
        for (int r = c + 1; r < m; r++) {
            double f = w[r * (m + 1) + c] / w[c * (m + 1) + c];
            for (int k = c; k <= m; k++)
                w[r * (m + 1) + k] -= f * w[c * (m + 1) + k];
        }
    }
    for (int r = m - 1; r >= 0; r--) {
        double v = w[r * (m + 1) + m];
        for (int k = r + 1; k < m; k++)
            v -= w[r * (m + 1) + k] * delta[k];
        delta[r] = v / w[r * (m + 1) + r];
    }
    for (int r = 0; r < m; r++)
        if (!isfinite(delta[r]))
            return 0;
    return 1;
}

/* The initial state (scaled: z / scales) that best reproduces the first `fit` samples,
 * started from `state` (kept when its own simulation is not finite). */
static void fit_state(simulation *s, const double *x, long fit, double scale_x, const double *scales,
                      double *state)
{
    int m = 2 * s->n;
    double a[64 * 64], g[64], delta[64], trial[64], z[64], damping = 1e-3;
    double cost = normal_equations(s, state, x, fit, scale_x, scales, a, g);
    int evaluations = 1;
    if (!isfinite(cost))
        return;
    while (evaluations < FIT_EVALUATIONS && damping <= FIT_MAX_DAMPING) {
        double cost_trial, size = 0.0, norm = 0.0;
        if (!damped_step(m, a, g, damping, delta)) {
            damping *= 10.0;
            continue;
        }
        for (int c = 0; c < m; c++) {
            trial[c] = state[c] / scales[c] + delta[c];
            z[c] = trial[c] * scales[c];
            size += delta[c] * delta[c];
            norm += trial[c] * trial[c];
        }
        cost_trial = simulate_plain(s, z, x, fit, fit, scale_x, NULL);
        evaluations++;
        if (isfinite(cost_trial) && cost_trial < cost) {
            int done = sqrt(size) <= FIT_TOLERANCE * (sqrt(norm) + FIT_TOLERANCE) ||
                       cost - cost_trial <= FIT_TOLERANCE * cost;
            memcpy(state, z, (size_t)m * sizeof(double));
            if (done)
                return;
            cost = normal_equations(s, state, x, fit, scale_x, scales, a, g);
            evaluations++;
            damping *= 0.1;
        } else {
            damping *= 10.0;
        }
    }
}

int duffid_simulate_segments(int n_dof, int n_forces, int substeps, double h, const double *p, long n,
                             const double *x, const double *stages, long n_seg, const long *start,
                             const long *length, const long *init, double dt, double scale_x, double *out,
                             double *x0, int *status)
{
    int m = 2 * n_dof;
    long size = m + (long)m * m, work = duffid_segment_work();
    double scales[64], *buffer;
    simulation s;
    (void)n;
    if (m > 64)
        return -1;
    buffer = (double *)malloc((size_t)(2 * size + (work > 0 ? work : 1)) * sizeof(double));
    if (buffer == NULL)
        return -1;
    s.n = n_dof; s.nf = n_forces; s.substeps = substeps; s.h = h; s.p = p;
    s.z = buffer; s.z_next = buffer + size; s.work = buffer + 2 * size;
    for (int c = 0; c < m; c++)
        scales[c] = c < n_dof ? scale_x : scale_x / dt;
    for (long j = 0; j < n_seg; j++) {
        const double *xs = x + start[j] * n_dof;
        double *state = x0 + j * m;
        long count = length[j], fit = init[j] < count ? init[j] : count;
        int finite = 1;
        s.stages = stages + start[j] * substeps * 3 * n_forces;
        /* the first displacement and a second-order one-sided difference for the velocity */
        for (int d = 0; d < n_dof; d++) {
            state[d] = xs[d];
            state[n_dof + d] = count < 3 ? (xs[n_dof + d] - xs[d]) / dt
                                         : (-3.0 * xs[d] + 4.0 * xs[n_dof + d] - xs[2 * n_dof + d]) / (2.0 * dt);
        }
        fit_state(&s, xs, fit, scale_x, scales, state);
        simulate_plain(&s, state, xs, count, 0, scale_x, out + start[j] * n_dof);
        for (long i = 0; i < count * n_dof && finite; i++)
            finite = isfinite(out[start[j] * n_dof + i]);
        status[j] = finite ? DUFFID_SEGMENT_OK : DUFFID_SEGMENT_ESCAPED;
    }
    free(buffer);
    return 0;
}
