/*
 * duffid_linalg.c - small dense linear algebra of the estimator core.
 *
 * C99, libm only, no allocation, no static mutable state.
 */
#include "duffid_linalg.h"

#include <float.h>
#include <math.h>

double duffid_la_pairwise_sum(const double *a, int n, int stride)
{
    int i;
    double res;
    if (n < 8) {
        res = 0.0;
        for (i = 0; i < n; i++) {
            res += a[i * stride];
        }
        return res;
    }
    if (n <= 128) {
        double r[8];
        int j;
        for (j = 0; j < 8; j++) {
            r[j] = a[j * stride];
        }
        for (i = 8; i < n - (n % 8); i += 8) {
            for (j = 0; j < 8; j++) {
                r[j] += a[(i + j) * stride];
            }
        }
        res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
        for (; i < n; i++) {
            res += a[i * stride];
        }
        return res;
    }
    {
        int n2 = n / 2;
        n2 -= n2 % 8;
        return duffid_la_pairwise_sum(a, n2, stride) +
               duffid_la_pairwise_sum(a + n2 * stride, n - n2, stride);
    }
}

void duffid_la_qr_accumulate(double *R, int p, double s, double *B, int m)
{
    int i, j, k;
    for (i = 0; i < p * p; i++) {
        R[i] *= s;
    }
    for (j = 0; j < p; j++) {
        double alpha = R[j * p + j];
        double xnorm2 = 0.0;
        double xnorm, beta, tau, scal;
        for (i = 0; i < m; i++) {
            xnorm2 += B[i * p + j] * B[i * p + j];
        }
        if (xnorm2 == 0.0) {
            continue; /* H = I (LAPACK's dlarfg with tau = 0) */
        }
        xnorm = sqrt(xnorm2);
        beta = -copysign(hypot(alpha, xnorm), alpha);
        tau = (beta - alpha) / beta;
        scal = 1.0 / (alpha - beta);
        for (i = 0; i < m; i++) {
            B[i * p + j] *= scal; /* Householder vector v = (1, B[:, j]) */
        }
        R[j * p + j] = beta;
        for (k = j + 1; k < p; k++) {
            double w = R[j * p + k];
            for (i = 0; i < m; i++) {
                w += B[i * p + j] * B[i * p + k];
            }
            w *= tau;
            R[j * p + k] -= w;
            for (i = 0; i < m; i++) {
                B[i * p + k] -= w * B[i * p + j];
            }
        }
        for (i = 0; i < m; i++) {
            B[i * p + j] = 0.0;
        }
    }
}

static double column_norm(int n, const double *a, int col)
{
    double big = 0.0, sum = 0.0;
    int i;
    for (i = 0; i < n; i++) {
        double v = fabs(a[i * n + col]);
        if (v > big) {
            big = v;
        }
    }
    if (big == 0.0 || !(big <= DBL_MAX)) {
        return big;
    }
    for (i = 0; i < n; i++) {
        double v = a[i * n + col] / big;
        sum += v * v;
    }
    return big * sqrt(sum);
}

int duffid_la_jacobi_svd(int n, double *a, double *sv, double *v)
{
    const int max_sweeps = 80;
    int sweep, i, j, p, q, converged = 0;

    for (i = 0; i < n; i++) {
        for (j = 0; j < n; j++) {
            v[i * n + j] = (i == j) ? 1.0 : 0.0;
        }
    }
    for (sweep = 1; sweep <= max_sweeps; sweep++) {
        int rotated = 0;
        for (p = 0; p < n - 1; p++) {
            for (q = p + 1; q < n; q++) {
                double alpha = 0.0, beta = 0.0, gamma = 0.0, zeta, t, c, s;
                for (i = 0; i < n; i++) {
                    double ap = a[i * n + p], aq = a[i * n + q];
                    alpha += ap * ap;
                    beta += aq * aq;
                    gamma += ap * aq;
                }
                if (gamma == 0.0 || !(fabs(gamma) > DBL_EPSILON * sqrt(alpha) * sqrt(beta))) {
                    continue;
                }
                rotated = 1;
                zeta = (beta - alpha) / (2.0 * gamma);
                if (fabs(zeta) > 1e150) {
                    t = 0.5 / zeta;
                } else {
                    t = copysign(1.0, zeta) / (fabs(zeta) + sqrt(1.0 + zeta * zeta));
                }
                c = 1.0 / sqrt(1.0 + t * t);
                s = c * t;
                for (i = 0; i < n; i++) {
                    double ap = a[i * n + p], aq = a[i * n + q];
                    a[i * n + p] = c * ap - s * aq;
                    a[i * n + q] = s * ap + c * aq;
                }
                for (i = 0; i < n; i++) {
                    double vp = v[i * n + p], vq = v[i * n + q];
                    v[i * n + p] = c * vp - s * vq;
                    v[i * n + q] = s * vp + c * vq;
                }
            }
        }
        if (!rotated) {
            converged = 1;
            break;
        }
    }
    for (j = 0; j < n; j++) {
        sv[j] = column_norm(n, a, j);
        if (sv[j] > 0.0) {
            for (i = 0; i < n; i++) {
                a[i * n + j] /= sv[j];
            }
        }
    }
    /* sort descending (selection sort; NaN last), permuting U and V alike */
    for (j = 0; j < n - 1; j++) {
        int best = j;
        for (p = j + 1; p < n; p++) {
            if (sv[p] > sv[best] || (sv[best] != sv[best] && sv[p] == sv[p])) {
                best = p;
            }
        }
        if (best != j) {
            double tmp = sv[j];
            sv[j] = sv[best];
            sv[best] = tmp;
            for (i = 0; i < n; i++) {
                tmp = a[i * n + j];
                a[i * n + j] = a[i * n + best];
                a[i * n + best] = tmp;
                tmp = v[i * n + j];
                v[i * n + j] = v[i * n + best];
                v[i * n + best] = tmp;
            }
        }
    }
    return converged ? sweep : -1;
}

double duffid_la_det(int n, double *a)
{
    int i, j, k;
    double sign = 1.0, logdet = 0.0;
    for (k = 0; k < n; k++) {
        int piv = k;
        double big = fabs(a[k * n + k]);
        double inv;
        for (i = k + 1; i < n; i++) {
            if (fabs(a[i * n + k]) > big) {
                big = fabs(a[i * n + k]);
                piv = i;
            }
        }
        if (a[piv * n + k] == 0.0) {
            return 0.0; /* singular: numpy reports sign 0, det 0 */
        }
        if (piv != k) {
            for (j = 0; j < n; j++) {
                double tmp = a[k * n + j];
                a[k * n + j] = a[piv * n + j];
                a[piv * n + j] = tmp;
            }
            sign = -sign;
        }
        inv = 1.0 / a[k * n + k];
        for (i = k + 1; i < n; i++) {
            double l = a[i * n + k] * inv;
            a[i * n + k] = l;
            for (j = k + 1; j < n; j++) {
                a[i * n + j] -= l * a[k * n + j];
            }
        }
    }
    for (k = 0; k < n; k++) {
        double d = a[k * n + k];
        if (d < 0.0) {
            sign = -sign;
        }
        logdet += log(fabs(d));
    }
    return sign * exp(logdet);
}
