/*
 * duffid_linalg.h - small dense linear algebra of the estimator core (internal).
 *
 * Matrices are row-major with a leading dimension equal to their column count. Sizes
 * are at most DUFFID_LA_MAX x DUFFID_LA_MAX (workspaces are fixed arrays, no VLA).
 */
#ifndef DUFFID_LINALG_H
#define DUFFID_LINALG_H

#include <float.h>
#include <math.h>
#include <stddef.h>
#include <stdint.h>

#include "duffid_model.h" /* duffid_real, DUFFID_SINGLE */

#define DUFFID_LA_MAX 17

/* The real type's constants and math functions: RC(x) is the literal x in duffid_real (no
 * duffid_real arithmetic in a float build), R_SQRT and friends call the float or duffid_real function. */
#define RC(x) ((duffid_real)(x))
#if DUFFID_SINGLE
#define R_FN(name) name##f
#define R_EPS FLT_EPSILON
#define R_MAX FLT_MAX
#define R_ZETA_LIMIT RC(1e18)
#else
#define R_FN(name) name
#define R_EPS DBL_EPSILON
#define R_MAX DBL_MAX
#define R_ZETA_LIMIT RC(1e150)
#endif
#define R_INF ((duffid_real)INFINITY)
#define R_NAN ((duffid_real)NAN)
#define R_SQRT(x) R_FN(sqrt)(x)
#define R_FABS(x) R_FN(fabs)(x)
#define R_COPYSIGN(x, y) R_FN(copysign)(x, y)
#define R_HYPOT(x, y) R_FN(hypot)(x, y)
#define R_LOG(x) R_FN(log)(x)
#define R_EXP(x) R_FN(exp)(x)
#define R_POW(x, y) R_FN(pow)(x, y)
#define R_FLOOR(x) R_FN(floor)(x)
#define R_FMOD(x, y) R_FN(fmod)(x, y)

/* Sum of n values a[0], a[stride], ... in numpy's pairwise order (np.add.reduce over a
 * contiguous axis), so that reductions round like the Python reference. */
duffid_real duffid_la_pairwise_sum(const duffid_real *a, int n, int stride);

/* Triangular factor update by Householder reflections: the p x p upper triangular R
 * becomes the R factor of [s R; B] (B: m x p new rows stored column after column,
 * B[j * m + i]; destroyed). With R = 0 this is the QR factorisation of B. Diagonal signs
 * follow LAPACK (beta = -sign(alpha) norm). */
void duffid_la_qr_accumulate(duffid_real *R, int p, duffid_real s, duffid_real *B, int m);

/* The largest and smallest singular values of the n x n matrix a (row-major) by one-sided
 * (Hestenes) Jacobi, to rounding relative to each singular value. warm != 0: v holds the
 * right singular vectors of a nearby matrix (the previous sample's; column-major) and the
 * iteration starts from a v, whose columns are then nearly orthogonal, so one or two sweeps
 * suffice; warm == 0: v is set to the identity. v is updated to this matrix's right singular
 * vectors (to eps^(1/4): enough to start the next one). A rotation that moves no column by
 * more than sqrt(eps) of its norm only updates the tracked norms; the iteration stops after a
 * sweep whose rotations all moved the columns by less than eps^(1/4) (quadratic convergence:
 * the next would be such tracked updates), and those rotations leave V as it was.
 * Returns the sweeps, or -1 if the bound on sweeps was reached (the values are then
 * approximate). NaN in, NaN out. */
int duffid_la_singular_range(int n, const duffid_real *a, duffid_real *v, int warm, duffid_real *largest,
                             duffid_real *smallest);

/* inv = r^-1 for the n x n upper-triangular r (row-major, leading dimension ld); inv is
 * n x n, upper triangular. Returns 0, or k > 0 when the k-th diagonal entry is 0. */
int duffid_la_upper_inverse(int n, const duffid_real *r, int ld, duffid_real *inv);

/* Memory blocks: arrays carved one after the other, each aligned to DUFFID_LA_ALIGNMENT bytes
 * (base NULL: only counts the bytes). */
#define DUFFID_LA_ALIGNMENT 8u /* doubles and 64-bit integers */
#define DUFFID_LA_ALIGN_UP(v) (((v) + (DUFFID_LA_ALIGNMENT - 1u)) & ~(size_t)(DUFFID_LA_ALIGNMENT - 1u))
typedef struct {
    char *base;
    size_t used;
} duffid_la_carver;
void *duffid_la_carve(duffid_la_carver *c, size_t count, size_t item);
#define DUFFID_LA_CARVE(c, ptr, count) ((ptr) = duffid_la_carve((c), (size_t)(count), sizeof *(ptr)))

/* printf-style message into msg[size] (nothing when msg is NULL or size 0); with
 * -DDUFFID_NO_STDIO (targets without vsnprintf) the template only. */
void duffid_la_message(char *msg, size_t size, const char *fmt, ...);

/* sqrt(a^2 + b^2) without overflow: libm's hypot in double, the FPU's square root in float
 * (hypotf is a libm call on a microcontroller). */
duffid_real duffid_la_hypot(duffid_real a, duffid_real b);

/* A solution whose column-equilibrated condition number exceeds this is singular to the
 * arithmetic (identification.solve_factor's 1e14 in double). In single precision the limit
 * follows the precision: beyond 0.01 / eps, rounding alone moves a solution by 1 %. */
#if DUFFID_SINGLE
#define DUFFID_LA_COND_SINGULAR (RC(0.01) / R_EPS)
#else
#define DUFFID_LA_COND_SINGULAR RC(1e14)
#endif

/* identification.solve_factor on the (n + 1) x (n + 1) upper-triangular factor Raug of
 * [A D] (row-major): the condition number of the column-equilibrated factor (*cond, by the
 * Jacobi iteration warm-started from v when *warm), the unknowns theta and their relative
 * standard errors rse (s^2 = Raug[n][n]^2 / (rows - n) x overlap; infinite when rows <= n).
 * Workspace: scale[n] (the column norms, kept for the caller), U and Rinv (n x n).
 * Returns 0, or 1 when the factor is singular (a zero column, a zero pivot, a non-finite
 * condition or one above cond_limit): theta, rse and *cond are then unset and *warm = 0. */
int duffid_la_solve_factor(int n, const duffid_real *Raug, duffid_real rows, duffid_real overlap,
                           duffid_real cond_limit, duffid_real *scale, duffid_real *U, duffid_real *Rinv,
                           duffid_real *v, int *warm, duffid_real *theta, duffid_real *rse, duffid_real *cond);
/* Its parts, for callers that spread the work over several samples: the column scales, the
 * equilibrated factor U and its triangular inverse (0, or 1 for a zero column or pivot);
 * the condition number of U (0, or 1 when non-finite or above cond_limit; *warm as above);
 * both (duffid_la_factor_condition); the unknowns and their errors from those. */
int duffid_la_factor_prepare(int n, const duffid_real *Raug, duffid_real *scale, duffid_real *U, duffid_real *Rinv);
int duffid_la_factor_range(int n, const duffid_real *U, duffid_real cond_limit, duffid_real *v, int *warm,
                           duffid_real *cond);
int duffid_la_factor_condition(int n, const duffid_real *Raug, duffid_real cond_limit, duffid_real *scale,
                               duffid_real *U, duffid_real *Rinv, duffid_real *v, int *warm, duffid_real *cond);
void duffid_la_factor_unknowns(int n, const duffid_real *Raug, duffid_real rows, duffid_real overlap,
                               const duffid_real *scale, const duffid_real *Rinv, duffid_real *theta,
                               duffid_real *rse);

/* Determinant by LU with partial pivoting, returned as numpy's det does:
 * sign * exp(sum log |u_ii|) (0 for an exactly singular matrix). a is destroyed. */
duffid_real duffid_la_det(int n, duffid_real *a); /* not in a float build */

/* Solve a X = b for the n x nrhs matrix b (overwritten by X) by LU with partial pivoting
 * (np.linalg.solve); a is destroyed. Returns 0, or k > 0 when the k-th pivot is exactly 0. */
int duffid_la_solve(int n, duffid_real *a, duffid_real *b, int nrhs);

/* Eigenvalues wr + i wi of the general n x n matrix a (np.linalg.eigvals to rounding):
 * reduction to Hessenberg form, then shifted QR iterations. a is destroyed. Returns 0, or
 * -1 if a holds a non-finite value or the iteration did not converge. */
int duffid_la_eigenvalues(int n, duffid_real *a, duffid_real *wr, duffid_real *wi);

/* row_noise.NoiseLevel's measurement: each displacement's white-noise level from the running
 * mean squares of its 4th and 6th differences (white noise: 70 and 924 times its variance; a
 * smooth signal barely reaches them). */
#define DUFFID_LA_NOISE_HISTORY 7 /* the displacements kept: a 6th difference's */
typedef struct {
    int count;                                                 /* displacements in hist */
    duffid_real hist[DUFFID_LA_NOISE_HISTORY * DUFFID_MAX_DOF]; /* the latest, oldest first:
                                                                * [slot * n_dof + j] */
    duffid_real m4[DUFFID_MAX_DOF], m6[DUFFID_MAX_DOF];        /* running mean squares */
    int64_t n4, n6;                                            /* differences in them */
} duffid_la_noise_level;
void duffid_la_noise_reset(duffid_la_noise_level *level);
/* NoiseLevel.push: take the n_dof displacements x of one sample */
void duffid_la_noise_push(duffid_la_noise_level *level, int n_dof, const duffid_real *x);
/* NoiseLevel.sigma: displacement j's noise standard deviation (the smaller of the two
 * differences' estimates; 0 before five samples) */
duffid_real duffid_la_noise_sigma(const duffid_la_noise_level *level, int j);

#endif /* DUFFID_LINALG_H */
