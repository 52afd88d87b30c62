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

int duffid_la_solve(int n, double *a, double *b, int nrhs)
{
    int i, j, k;
    for (k = 0; k < n; k++) { /* LU with partial pivoting (the first largest |a_ik|, as dgetrf) */
        int piv = k;
        double big = fabs(a[k * n + k]);
        for (i = k + 1; i < n; i++) {
            if (fabs(a[i * n + k]) > big) {
                big = fabs(a[i * n + k]);
                piv = i;
            }
        }
        if (a[piv * n + k] == 0.0) {
            return k + 1; /* exactly singular */
        }
        if (piv != k) {
            for (j = 0; j < n; j++) {
                double t = a[k * n + j];
                a[k * n + j] = a[piv * n + j];
                a[piv * n + j] = t;
            }
            for (j = 0; j < nrhs; j++) {
                double t = b[k * nrhs + j];
                b[k * nrhs + j] = b[piv * nrhs + j];
                b[piv * nrhs + j] = t;
            }
        }
        for (i = k + 1; i < n; i++) {
            double l = a[i * n + k] / a[k * n + k];
            a[i * n + k] = l;
            for (j = k + 1; j < n; j++) {
                a[i * n + j] -= l * a[k * n + j];
            }
            for (j = 0; j < nrhs; j++) {
                b[i * nrhs + j] -= l * b[k * nrhs + j];
            }
        }
    }
    for (j = 0; j < nrhs; j++) { /* back substitution */
        for (i = n - 1; i >= 0; i--) {
            double s = b[i * nrhs + j];
            for (k = i + 1; k < n; k++) {
                s -= a[i * n + k] * b[k * nrhs + j];
            }
            b[i * nrhs + j] = s / a[i * n + i];
        }
    }
    return 0;
}

/* 1-based element (i, j) of the n x n row-major matrix a */
#define H(i, j) a[((i) - 1) * n + ((j) - 1)]

/* Reduction to upper Hessenberg form by stabilised elementary similarity transformations
 * (the eigenvalues are those of a); the part below the subdiagonal is zeroed. */
static void hessenberg(int n, double *a)
{
    int m, i, j;
    for (m = 2; m < n; m++) {
        double x = 0.0, y;
        i = m;
        for (j = m; j <= n; j++) {
            if (fabs(H(j, m - 1)) > fabs(x)) {
                x = H(j, m - 1);
                i = j;
            }
        }
        if (i != m) {
            for (j = m - 1; j <= n; j++) {
                y = H(i, j);
                H(i, j) = H(m, j);
                H(m, j) = y;
            }
            for (j = 1; j <= n; j++) {
                y = H(j, i);
                H(j, i) = H(j, m);
                H(j, m) = y;
            }
        }
        if (x != 0.0) {
            for (i = m + 1; i <= n; i++) {
                y = H(i, m - 1);
                if (y != 0.0) {
                    y /= x;
                    H(i, m - 1) = y;
                    for (j = m; j <= n; j++) {
                        H(i, j) -= y * H(m, j);
                    }
                    for (j = 1; j <= n; j++) {
                        H(j, m) += y * H(j, i);
                    }
                }
            }
        }
    }
    for (i = 3; i <= n; i++) {
        for (j = 1; j < i - 1; j++) {
            H(i, j) = 0.0;
        }
    }
}

int duffid_la_eigenvalues(int n, double *a, double *wr, double *wi)
{
    int nn, m, l, k, j, its, i, mmin;
    double z = 0.0, y, x, w, v, u, t, s, r = 0.0, q = 0.0, p = 0.0, anorm = 0.0;
    hessenberg(n, a);
    for (i = 1; i <= n; i++) {
        for (j = (i - 1 > 1 ? i - 1 : 1); j <= n; j++) {
            anorm += fabs(H(i, j));
        }
    }
    if (!(anorm <= DBL_MAX)) {
        return -1;
    }
    nn = n;
    t = 0.0;
    while (nn >= 1) { /* shifted QR iterations on the Hessenberg matrix (Francis double shift) */
        its = 0;
        do {
            for (l = nn; l >= 2; l--) {
                s = fabs(H(l - 1, l - 1)) + fabs(H(l, l));
                if (s == 0.0) {
                    s = anorm;
                }
                if (fabs(H(l, l - 1)) + s == s) {
                    H(l, l - 1) = 0.0;
                    break;
                }
            }
            x = H(nn, nn);
            if (l == nn) { /* one root found */
                wr[nn - 1] = x + t;
                wi[nn - 1] = 0.0;
                nn--;
            } else {
                y = H(nn - 1, nn - 1);
                w = H(nn, nn - 1) * H(nn - 1, nn);
                if (l == nn - 1) { /* two roots found */
                    p = 0.5 * (y - x);
                    q = p * p + w;
                    z = sqrt(fabs(q));
                    x += t;
                    if (q >= 0.0) {
                        z = p + copysign(z, p);
                        wr[nn - 2] = wr[nn - 1] = x + z;
                        if (z != 0.0) {
                            wr[nn - 1] = x - w / z;
                        }
                        wi[nn - 2] = wi[nn - 1] = 0.0;
                    } else {
                        wr[nn - 2] = wr[nn - 1] = x + p;
                        wi[nn - 2] = -z;
                        wi[nn - 1] = z;
                    }
                    nn -= 2;
                } else {
                    if (its == 60) {
                        return -1;
                    }
                    if (its == 10 || its == 20) { /* exceptional shift */
                        t += x;
                        for (i = 1; i <= nn; i++) {
                            H(i, i) -= x;
                        }
                        s = fabs(H(nn, nn - 1)) + fabs(H(nn - 1, nn - 2));
                        y = x = 0.75 * s;
                        w = -0.4375 * s * s;
                    }
                    ++its;
                    for (m = nn - 2; m >= l; m--) {
                        z = H(m, m);
                        r = x - z;
                        s = y - z;
                        p = (r * s - w) / H(m + 1, m) + H(m, m + 1);
                        q = H(m + 1, m + 1) - z - r - s;
                        r = H(m + 2, m + 1);
                        s = fabs(p) + fabs(q) + fabs(r);
                        p /= s;
                        q /= s;
                        r /= s;
                        if (m == l) {
                            break;
                        }
                        u = fabs(H(m, m - 1)) * (fabs(q) + fabs(r));
                        v = fabs(p) * (fabs(H(m - 1, m - 1)) + fabs(z) + fabs(H(m + 1, m + 1)));
                        if (u + v == v) {
                            break;
                        }
                    }
                    for (i = m + 2; i <= nn; i++) {
                        H(i, i - 2) = 0.0;
                        if (i != m + 2) {
                            H(i, i - 3) = 0.0;
                        }
                    }
                    for (k = m; k <= nn - 1; k++) {
                        if (k != m) {
                            p = H(k, k - 1);
                            q = H(k + 1, k - 1);
                            r = 0.0;
                            if (k != nn - 1) {
                                r = H(k + 2, k - 1);
                            }
                            if ((x = fabs(p) + fabs(q) + fabs(r)) != 0.0) {
                                p /= x;
                                q /= x;
                                r /= x;
                            }
                        }
                        s = copysign(sqrt(p * p + q * q + r * r), p);
                        if (s != 0.0) {
                            if (k == m) {
                                if (l != m) {
                                    H(k, k - 1) = -H(k, k - 1);
                                }
                            } else {
                                H(k, k - 1) = -s * x;
                            }
                            p += s;
                            x = p / s;
                            y = q / s;
                            z = r / s;
                            q /= p;
                            r /= p;
                            for (j = k; j <= nn; j++) {
                                p = H(k, j) + q * H(k + 1, j);
                                if (k != nn - 1) {
                                    p += r * H(k + 2, j);
                                    H(k + 2, j) -= p * z;
                                }
                                H(k + 1, j) -= p * y;
                                H(k, j) -= p * x;
                            }
                            mmin = nn < k + 3 ? nn : k + 3;
                            for (i = l; i <= mmin; i++) {
                                p = x * H(i, k) + y * H(i, k + 1);
                                if (k != nn - 1) {
                                    p += z * H(i, k + 2);
                                    H(i, k + 2) -= p * r;
                                }
                                H(i, k + 1) -= p * q;
                                H(i, k) -= p;
                            }
                        }
                    }
                }
            }
        } while (l < nn - 1);
    }
    return 0;
}
#undef H
