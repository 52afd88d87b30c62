/*
 * qr_rls_floor.c - the floor the estimator's per-sample time is compared with (x86):
 * square-root recursive least squares by Givens rotations.
 *
 * The factor is the 5x5 upper-triangular [R | d] of 4 unknowns (m, b, k, kp of a 1-DOF
 * Duffing equation) and the right-hand side. Each sample brings 8 rows, from the record's
 * first displacement and force columns: for h = 1..8, central differences over h samples,
 *     [ (x[n] - 2 x[n-h] + x[n-2h]) / (h dt)^2,  (x[n] - x[n-2h]) / (2 h dt),
 *       x[n-h],  x[n-h]^3  |  f[n-h] ],
 * each rotated into the factor (4 Givens rotations, one square root each), after the factor
 * has been scaled by sqrt(lambda) (exponential forgetting, lambda = 0.999 per sample); then
 * one back substitution gives the 4 unknowns. That is the least work an online least-squares
 * identifier of this model does per sample. It is a cost floor, not an identifier to trust:
 * differences over up to 16 samples bias its estimates (printed only as a sanity check).
 *
 * Build: gcc -O2 -ffp-contract=off -DFLOOR_REAL=double|float -I<dir of embedded_record.h>
 *            qr_rls_floor.c -lm
 * Output: `time NS_PER_SAMPLE` (one untimed pass, then timed passes over the record, each from
 * a zero factor, until 0.2 s are timed) and the final unknowns.
 */
#define _POSIX_C_SOURCE 200112L
#include <stdio.h>
#include <tgmath.h>
#include <time.h>

#include "embedded_record.h"

#ifndef FLOOR_REAL
#define FLOOR_REAL double
#endif
typedef FLOOR_REAL real;

#define N_UNKNOWNS 4
#define N_COLS (N_UNKNOWNS + 1)
#define N_ROWS 8
#define HISTORY (2 * N_ROWS + 1)

static const real record_x[RECORD_N * RECORD_NDOF] = {RECORD_X};
static const real record_f[RECORD_N * RECORD_NFORCES] = {RECORD_F};

typedef struct {
    real r[N_UNKNOWNS][N_COLS]; /* [R | d], upper triangular */
    real theta[N_UNKNOWNS];
    real scale;                 /* sqrt(lambda) */
} floor_rls;

static void rotate_in(floor_rls *s, real row[N_COLS])
{
    int i, j;
    for (i = 0; i < N_UNKNOWNS; i++) {
        real a = s->r[i][i], b = row[i], rho, c, sn;
        if (b == 0) {
            continue;
        }
        rho = sqrt(a * a + b * b);
        c = a / rho;
        sn = b / rho;
        s->r[i][i] = rho;
        for (j = i + 1; j < N_COLS; j++) {
            real t = s->r[i][j];
            s->r[i][j] = c * t + sn * row[j];
            row[j] = c * row[j] - sn * t;
        }
    }
}

static void solve(floor_rls *s)
{
    int i, j;
    for (i = N_UNKNOWNS - 1; i >= 0; i--) {
        real v = s->r[i][N_UNKNOWNS];
        for (j = i + 1; j < N_UNKNOWNS; j++) {
            v -= s->r[i][j] * s->theta[j];
        }
        s->theta[i] = s->r[i][i] != 0 ? v / s->r[i][i] : 0;
    }
}

static void step(floor_rls *s, long n, real dt)
{
    int h, i, j;
    real row[N_COLS];
    for (i = 0; i < N_UNKNOWNS; i++) {
        for (j = i; j < N_COLS; j++) {
            s->r[i][j] *= s->scale;
        }
    }
    if (n >= HISTORY - 1) {
        for (h = 1; h <= N_ROWS; h++) {
            real x0 = record_x[n * RECORD_NDOF], x1 = record_x[(n - h) * RECORD_NDOF];
            real x2 = record_x[(n - 2 * h) * RECORD_NDOF], hd = (real)h * dt;
            row[0] = (x0 - 2 * x1 + x2) / (hd * hd);
            row[1] = (x0 - x2) / (2 * hd);
            row[2] = x1;
            row[3] = x1 * x1 * x1;
            row[4] = record_f[(n - h) * RECORD_NFORCES];
            rotate_in(s, row);
        }
    }
    solve(s);
}

static double now_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e9 + (double)ts.tv_nsec;
}

int main(void)
{
    static floor_rls s;
    const real dt = (real)RECORD_DT;
    double start, total = 0.0;
    long n, timed = 0;
    int pass, i, j;
    for (pass = 0; pass == 0 || total < 0.2e9; pass++) {
        for (i = 0; i < N_UNKNOWNS; i++) {
            for (j = 0; j < N_COLS; j++) {
                s.r[i][j] = 0;
            }
            s.theta[i] = 0;
        }
        s.scale = sqrt((real)0.999);
        start = now_ns();
        for (n = 0; n < RECORD_N; n++) {
            step(&s, n, dt);
        }
        if (pass > 0) {
            total += now_ns() - start;
            timed += RECORD_N;
        }
    }
    printf("time %.3f\n", total / (double)timed);
    printf("theta %.9g %.9g %.9g %.9g\n", (double)s.theta[0], (double)s.theta[1], (double)s.theta[2],
           (double)s.theta[3]);
    return 0;
}
