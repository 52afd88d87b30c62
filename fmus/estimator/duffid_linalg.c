/*
 * duffid_linalg.c - small dense linear algebra of the estimator core.
 *
 * C99, libm only, no allocation, no static mutable state.
 */
#include "duffid_linalg.h"

#include <stdarg.h>
#ifndef DUFFID_NO_STDIO
#include <stdio.h>
#endif
#include <string.h>


duffid_real duffid_la_pairwise_sum(const duffid_real *a, int n, int stride)
{
    int i;
    duffid_real res;
    if (n < 8) {
        res = RC(0.0);
        for (i = 0; i < n; i++) {
            res += a[i * stride];
        }
        return res;
    }
    if (n <= 128) {
        duffid_real r[8];
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

void duffid_la_qr_accumulate(duffid_real *R, int p, duffid_real s, duffid_real *B, int m)
{
    int i, j, k;
    if (s != RC(1.0)) {
        for (i = 0; i < p * p; i++) {
            R[i] *= s;
        }
    }
    for (j = 0; j < p; j++) {
        duffid_real *bj = B + j * m;
        duffid_real alpha = R[j * p + j], xnorm2 = RC(0.0), beta, tau, scal;
        for (i = 0; i < m; i++) {
            xnorm2 += bj[i] * bj[i];
        }
        if (xnorm2 == RC(0.0)) {
            continue; /* H = I (LAPACK's dlarfg with tau = 0) */
        }
        beta = -R_COPYSIGN(R_SQRT(alpha * alpha + xnorm2), alpha);
        tau = (beta - alpha) / beta;
        scal = RC(1.0) / (alpha - beta);
        for (i = 0; i < m; i++) {
            bj[i] *= scal; /* Householder vector v = (1, B[:, j]) */
        }
        R[j * p + j] = beta;
        for (k = j + 1; k < p; k++) {
            duffid_real *bk = B + k * m;
            duffid_real w = RC(0.0);
            for (i = 0; i < m; i++) {
                w += bj[i] * bk[i];
            }
            w = (w + R[j * p + k]) * tau;
            R[j * p + k] -= w;
            for (i = 0; i < m; i++) {
                bk[i] -= w * bj[i];
            }
        }
    }
}

int duffid_la_singular_range(int n, const duffid_real *a, duffid_real *v, int warm, duffid_real *largest,
                             duffid_real *smallest)
{
    const int max_sweeps = warm ? 12 : 40;
    const duffid_real exact2 = RC(16.0) * R_EPS * R_EPS, quadratic = R_SQRT(R_EPS);
    duffid_real col[DUFFID_LA_MAX * DUFFID_LA_MAX], norm[DUFFID_LA_MAX];
    int sweep, i, j, k, p, q, converged = 0;
    /* the columns of a V (warm: nearly orthogonal when a is near the matrix V came from),
     * stored column after column; v is column-major too */
    if (!warm) {
        for (i = 0; i < n * n; i++) {
            v[i] = RC(0.0);
        }
        for (i = 0; i < n; i++) {
            v[i * n + i] = RC(1.0);
        }
    }
    for (j = 0; j < n; j++) {
        duffid_real *cj = col + j * n, sum = RC(0.0);
        const duffid_real *vj = v + j * n;
        for (i = 0; i < n; i++) {
            duffid_real s = RC(0.0);
            for (k = 0; k < n; k++) {
                s += a[i * n + k] * vj[k];
            }
            cj[i] = s;
            sum += s * s;
        }
        norm[j] = sum;
    }
    for (sweep = 1; sweep <= max_sweeps && !converged; sweep++) {
        duffid_real largest_move = RC(0.0);
        for (p = 0; p < n - 1; p++) {
            duffid_real *cp = col + p * n, *vp = v + p * n;
            for (q = p + 1; q < n; q++) {
                duffid_real *cq = col + q * n, *vq = v + q * n;
                duffid_real gamma = RC(0.0), zeta, t, c, s, move, np = RC(0.0), nq = RC(0.0);
                if (!(norm[p] > RC(0.0) && norm[q] > RC(0.0))) {
                    continue;
                }
                for (i = 0; i < n; i++) {
                    gamma += cp[i] * cq[i];
                }
                if (!(gamma * gamma > exact2 * norm[p] * norm[q])) {
                    continue; /* orthogonal to rounding (or NaN: left alone) */
                }
                zeta = (norm[q] - norm[p]) / (RC(2.0) * gamma);
                if (R_FABS(zeta) > R_ZETA_LIMIT) {
                    t = RC(0.5) / zeta;
                } else {
                    t = R_COPYSIGN(RC(1.0), zeta) / (R_FABS(zeta) + R_SQRT(RC(1.0) + zeta * zeta));
                }
                /* the rotation moves column p by |t| |a_q| and column q by |t| |a_p|; move is
                 * the larger of the two relative to the column's own norm, squared. Below eps
                 * it changes the norms by less than eps (tracked: t gamma) and rotating the
                 * columns adds nothing */
                move = t * t * (norm[q] > norm[p] ? norm[q] / norm[p] : norm[p] / norm[q]);
                if (!(move > R_EPS)) {
                    norm[p] -= t * gamma;
                    norm[q] += t * gamma;
                    continue;
                }
                largest_move = move > largest_move ? move : largest_move;
                c = RC(1.0) / R_SQRT(RC(1.0) + t * t);
                s = c * t;
                for (i = 0; i < n; i++) { /* norms from the columns: the update formula cancels */
                    const duffid_real xp = cp[i], xq = cq[i];
                    cp[i] = c * xp - s * xq;
                    cq[i] = s * xp + c * xq;
                    np += cp[i] * cp[i];
                    nq += cq[i] * cq[i];
                }
                norm[p] = np;
                norm[q] = nq;
                if (!(move > quadratic)) {
                    continue; /* V is a starting point: a rotation by less than eps^(1/4) can wait */
                }
                for (i = 0; i < n; i++) {
                    const duffid_real xp = vp[i], xq = vq[i];
                    vp[i] = c * xp - s * xq;
                    vq[i] = s * xp + c * xq;
                }
            }
        }
        /* quadratic convergence: after a sweep whose rotations all moved the columns by less
         * than eps^(1/4), the next sweep's would move them by less than eps^(1/2) (move below
         * eps): only tracked updates, which change the norms below eps */
        converged = !(largest_move > quadratic);
    }
    {
        duffid_real hi = RC(0.0), lo = R_INF;
        for (j = 0; j < n; j++) {
            duffid_real s = norm[j] > RC(0.0) ? R_SQRT(norm[j]) : (norm[j] == norm[j] ? RC(0.0) : norm[j]);
            if (s != s) {
                hi = lo = s;
                break;
            }
            hi = s > hi ? s : hi;
            lo = s < lo ? s : lo;
        }
        *largest = hi;
        *smallest = lo;
    }
    return converged ? sweep - 1 : -1;
}

int duffid_la_upper_inverse(int n, const duffid_real *r, int ld, duffid_real *inv)
{
    int i, j, k;
    for (i = 0; i < n; i++) {
        if (r[i * ld + i] == RC(0.0)) {
            return i + 1;
        }
    }
    for (j = n - 1; j >= 0; j--) {
        inv[j * n + j] = RC(1.0) / r[j * ld + j];
        for (i = j - 1; i >= 0; i--) {
            duffid_real sum = RC(0.0);
            for (k = i + 1; k <= j; k++) {
                sum += r[i * ld + k] * inv[k * n + j];
            }
            inv[i * n + j] = -sum / r[i * ld + i];
        }
        for (i = j + 1; i < n; i++) {
            inv[i * n + j] = RC(0.0);
        }
    }
    return 0;
}

#if !DUFFID_SINGLE /* the paper method's determinants (double precision only) */
duffid_real duffid_la_det(int n, duffid_real *a)
{
    int i, j, k;
    duffid_real sign = RC(1.0), logdet = RC(0.0);
    for (k = 0; k < n; k++) {
        int piv = k;
        duffid_real big = R_FABS(a[k * n + k]);
        duffid_real inv;
        for (i = k + 1; i < n; i++) {
            if (R_FABS(a[i * n + k]) > big) {
                big = R_FABS(a[i * n + k]);
                piv = i;
            }
        }
        if (a[piv * n + k] == RC(0.0)) {
            return RC(0.0); /* singular: numpy reports sign 0, det 0 */
        }
        if (piv != k) {
            for (j = 0; j < n; j++) {
                duffid_real tmp = a[k * n + j];
                a[k * n + j] = a[piv * n + j];
                a[piv * n + j] = tmp;
            }
            sign = -sign;
        }
        inv = RC(1.0) / a[k * n + k];
        for (i = k + 1; i < n; i++) {
            duffid_real l = a[i * n + k] * inv;
            a[i * n + k] = l;
            for (j = k + 1; j < n; j++) {
                a[i * n + j] -= l * a[k * n + j];
            }
        }
    }
    for (k = 0; k < n; k++) {
        duffid_real d = a[k * n + k];
        if (d < RC(0.0)) {
            sign = -sign;
        }
        logdet += R_LOG(R_FABS(d));
    }
    return sign * R_EXP(logdet);
}
#endif

int duffid_la_solve(int n, duffid_real *a, duffid_real *b, int nrhs)
{
    int i, j, k;
    for (k = 0; k < n; k++) { /* LU with partial pivoting (the first largest |a_ik|, as dgetrf) */
        int piv = k;
        duffid_real big = R_FABS(a[k * n + k]);
        for (i = k + 1; i < n; i++) {
            if (R_FABS(a[i * n + k]) > big) {
                big = R_FABS(a[i * n + k]);
                piv = i;
            }
        }
        if (a[piv * n + k] == RC(0.0)) {
            return k + 1; /* exactly singular */
        }
        if (piv != k) {
            for (j = 0; j < n; j++) {
                duffid_real t = a[k * n + j];
                a[k * n + j] = a[piv * n + j];
                a[piv * n + j] = t;
            }
            for (j = 0; j < nrhs; j++) {
                duffid_real t = b[k * nrhs + j];
                b[k * nrhs + j] = b[piv * nrhs + j];
                b[piv * nrhs + j] = t;
            }
        }
        for (i = k + 1; i < n; i++) {
            duffid_real l = a[i * n + k] / a[k * n + k];
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
            duffid_real s = b[i * nrhs + j];
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
static void hessenberg(int n, duffid_real *a)
{
    int m, i, j;
    for (m = 2; m < n; m++) {
        duffid_real x = RC(0.0), y;
        i = m;
        for (j = m; j <= n; j++) {
            if (R_FABS(H(j, m - 1)) > R_FABS(x)) {
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
        if (x != RC(0.0)) {
            for (i = m + 1; i <= n; i++) {
                y = H(i, m - 1);
                if (y != RC(0.0)) {
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
            H(i, j) = RC(0.0);
        }
    }
}

int duffid_la_eigenvalues(int n, duffid_real *a, duffid_real *wr, duffid_real *wi)
{
    int nn, m, l, k, j, its, i, mmin;
    duffid_real z = RC(0.0), y, x, w, v, u, t, s, r = RC(0.0), q = RC(0.0), p = RC(0.0), anorm = RC(0.0);
    hessenberg(n, a);
    for (i = 1; i <= n; i++) {
        for (j = (i - 1 > 1 ? i - 1 : 1); j <= n; j++) {
            anorm += R_FABS(H(i, j));
        }
    }
    if (!(anorm <= R_MAX)) {
        return -1;
    }
    nn = n;
    t = RC(0.0);
    while (nn >= 1) { /* shifted QR iterations on the Hessenberg matrix (Francis duffid_real shift) */
        its = 0;
        do {
            for (l = nn; l >= 2; l--) {
                s = R_FABS(H(l - 1, l - 1)) + R_FABS(H(l, l));
                if (s == RC(0.0)) {
                    s = anorm;
                }
                if (R_FABS(H(l, l - 1)) + s == s) {
                    H(l, l - 1) = RC(0.0);
                    break;
                }
            }
            x = H(nn, nn);
            if (l == nn) { /* one root found */
                wr[nn - 1] = x + t;
                wi[nn - 1] = RC(0.0);
                nn--;
            } else {
                y = H(nn - 1, nn - 1);
                w = H(nn, nn - 1) * H(nn - 1, nn);
                if (l == nn - 1) { /* two roots found */
                    p = RC(0.5) * (y - x);
                    q = p * p + w;
                    z = R_SQRT(R_FABS(q));
                    x += t;
                    if (q >= RC(0.0)) {
                        z = p + R_COPYSIGN(z, p);
                        wr[nn - 2] = wr[nn - 1] = x + z;
                        if (z != RC(0.0)) {
                            wr[nn - 1] = x - w / z;
                        }
                        wi[nn - 2] = wi[nn - 1] = RC(0.0);
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
                        s = R_FABS(H(nn, nn - 1)) + R_FABS(H(nn - 1, nn - 2));
                        y = x = RC(0.75) * s;
                        w = -RC(0.4375) * s * s;
                    }
                    ++its;
                    for (m = nn - 2; m >= l; m--) {
                        z = H(m, m);
                        r = x - z;
                        s = y - z;
                        p = (r * s - w) / H(m + 1, m) + H(m, m + 1);
                        q = H(m + 1, m + 1) - z - r - s;
                        r = H(m + 2, m + 1);
                        s = R_FABS(p) + R_FABS(q) + R_FABS(r);
                        p /= s;
                        q /= s;
                        r /= s;
                        if (m == l) {
                            break;
                        }
                        u = R_FABS(H(m, m - 1)) * (R_FABS(q) + R_FABS(r));
                        v = R_FABS(p) * (R_FABS(H(m - 1, m - 1)) + R_FABS(z) + R_FABS(H(m + 1, m + 1)));
                        if (u + v == v) {
                            break;
                        }
                    }
                    for (i = m + 2; i <= nn; i++) {
                        H(i, i - 2) = RC(0.0);
                        if (i != m + 2) {
                            H(i, i - 3) = RC(0.0);
                        }
                    }
                    for (k = m; k <= nn - 1; k++) {
                        if (k != m) {
                            p = H(k, k - 1);
                            q = H(k + 1, k - 1);
                            r = RC(0.0);
                            if (k != nn - 1) {
                                r = H(k + 2, k - 1);
                            }
                            if ((x = R_FABS(p) + R_FABS(q) + R_FABS(r)) != RC(0.0)) {
                                p /= x;
                                q /= x;
                                r /= x;
                            }
                        }
                        s = R_COPYSIGN(R_SQRT(p * p + q * q + r * r), p);
                        if (s != RC(0.0)) {
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

duffid_real duffid_la_hypot(duffid_real a, duffid_real b)
{
    if (a == RC(0.0)) {
        return R_FABS(b);
    }
    if (b == RC(0.0)) {
        return R_FABS(a);
    }
#if DUFFID_SINGLE
    {
        duffid_real x = R_FABS(a), y = R_FABS(b), r;
        if (x < y) {
            r = x;
            x = y;
            y = r;
        }
        r = y / x;
        return x * R_SQRT(RC(1.0) + r * r);
    }
#else
    return R_HYPOT(a, b);
#endif
}

int duffid_la_factor_prepare(int n, const duffid_real *Raug, duffid_real *scale, duffid_real *U, duffid_real *Rinv)
{
    const int p = n + 1;
    int i, j;
    for (j = 0; j < n; j++) { /* column norms: np.linalg.norm(R, axis=0), rows in order */
        duffid_real sum = RC(0.0);
        for (i = 0; i <= j; i++) {
            sum += Raug[i * p + j] * Raug[i * p + j];
        }
        scale[j] = R_SQRT(sum);
    }
    for (j = 0; j < n; j++) {
        if (!(scale[j] > RC(0.0))) {
            return 1;
        }
    }
    for (i = 0; i < n; i++) {
        for (j = 0; j < n; j++) {
            U[i * n + j] = j >= i ? Raug[i * p + j] / scale[j] : RC(0.0);
        }
    }
    return duffid_la_upper_inverse(n, U, n, Rinv) != 0;
}

int duffid_la_factor_range(int n, const duffid_real *U, duffid_real cond_limit, duffid_real *v, int *warm,
                           duffid_real *cond)
{
    duffid_real c, hi, lo;
    duffid_la_singular_range(n, U, v, *warm, &hi, &lo);
    c = lo > RC(0.0) ? hi / lo : R_INF;
    if (!(c <= cond_limit)) { /* also NaN */
        *warm = 0;
        return 1;
    }
    *warm = 1;
    *cond = c;
    return 0;
}

int duffid_la_factor_condition(int n, const duffid_real *Raug, duffid_real cond_limit, duffid_real *scale,
                               duffid_real *U, duffid_real *Rinv, duffid_real *v, int *warm, duffid_real *cond)
{
    if (duffid_la_factor_prepare(n, Raug, scale, U, Rinv) != 0) {
        *warm = 0;
        return 1;
    }
    return duffid_la_factor_range(n, U, cond_limit, v, warm, cond);
}

void duffid_la_factor_unknowns(int n, const duffid_real *Raug, duffid_real rows, duffid_real overlap,
                               const duffid_real *scale, const duffid_real *Rinv, duffid_real *theta,
                               duffid_real *rse)
{
    const int p = n + 1;
    duffid_real dof, s2;
    int i, k;
    for (i = 0; i < n; i++) { /* theta = R^-1 d / scale: the triangular inverse is R^-1 */
        duffid_real sum = RC(0.0);
        for (k = i; k < n; k++) {
            sum += Rinv[i * n + k] * Raug[k * p + n];
        }
        theta[i] = sum / scale[i];
    }
    dof = rows - (duffid_real)n;
    if (dof <= RC(0.0)) {
        for (i = 0; i < n; i++) {
            rse[i] = R_INF;
        }
        return;
    }
    s2 = Raug[n * p + n] * Raug[n * p + n] / dof * overlap;
    for (i = 0; i < n; i++) {
        duffid_real sq[DUFFID_LA_MAX], std;
        for (k = 0; k < n - i; k++) {
            sq[k] = Rinv[i * n + i + k] * Rinv[i * n + i + k];
        }
        std = R_SQRT(s2 * duffid_la_pairwise_sum(sq, n - i, 1)) / scale[i];
        rse[i] = theta[i] != RC(0.0) ? std / R_FABS(theta[i]) : R_INF;
    }
}

int duffid_la_solve_factor(int n, const duffid_real *Raug, duffid_real rows, duffid_real overlap,
                           duffid_real cond_limit, duffid_real *scale, duffid_real *U, duffid_real *Rinv,
                           duffid_real *v, int *warm, duffid_real *theta, duffid_real *rse, duffid_real *cond)
{
    if (duffid_la_factor_condition(n, Raug, cond_limit, scale, U, Rinv, v, warm, cond) != 0) {
        return 1;
    }
    duffid_la_factor_unknowns(n, Raug, rows, overlap, scale, Rinv, theta, rse);
    return 0;
}

void duffid_la_message(char *msg, size_t size, const char *fmt, ...)
{
    va_list ap;
    if (msg == NULL || size == 0) {
        return;
    }
    va_start(ap, fmt);
#ifdef DUFFID_NO_STDIO /* targets without vsnprintf: the message template only */
    strncpy(msg, fmt, size - 1);
    msg[size - 1] = '\0';
#else
    vsnprintf(msg, size, fmt, ap);
#endif
    va_end(ap);
}

void *duffid_la_carve(duffid_la_carver *c, size_t count, size_t item)
{
    void *p = c->base != NULL ? (void *)(c->base + c->used) : NULL;
    c->used += DUFFID_LA_ALIGN_UP(count * item);
    return p;
}

/* ------------------------------------------------------------------ the displacements' noise level */
static const duffid_real NOISE_D4[5] = {RC(1.0), RC(-4.0), RC(6.0), RC(-4.0), RC(1.0)};
static const duffid_real NOISE_D6[7] = {RC(1.0), RC(-6.0), RC(15.0), RC(-20.0), RC(15.0), RC(-6.0), RC(1.0)};

void duffid_la_noise_reset(duffid_la_noise_level *level)
{
    memset(level, 0, sizeof *level);
}

void duffid_la_noise_push(duffid_la_noise_level *level, int n_dof, const duffid_real *x)
{
    duffid_real *h = level->hist;
    int j, k;
    if (level->count == DUFFID_LA_NOISE_HISTORY) { /* the oldest leaves */
        memmove(h, h + n_dof, (size_t)((DUFFID_LA_NOISE_HISTORY - 1) * n_dof) * sizeof(duffid_real));
        level->count--;
    }
    for (j = 0; j < n_dof; j++) {
        h[level->count * n_dof + j] = x[j];
    }
    level->count++;
    if (level->count >= 5) {
        const duffid_real *last = h + (level->count - 5) * n_dof;
        level->n4++;
        for (j = 0; j < n_dof; j++) {
            duffid_real d = RC(0.0);
            for (k = 0; k < 5; k++) {
                d += NOISE_D4[k] * last[k * n_dof + j];
            }
            level->m4[j] += (d * d - level->m4[j]) / (duffid_real)level->n4;
        }
    }
    if (level->count >= DUFFID_LA_NOISE_HISTORY) {
        level->n6++;
        for (j = 0; j < n_dof; j++) {
            duffid_real d = RC(0.0);
            for (k = 0; k < DUFFID_LA_NOISE_HISTORY; k++) {
                d += NOISE_D6[k] * h[k * n_dof + j];
            }
            level->m6[j] += (d * d - level->m6[j]) / (duffid_real)level->n6;
        }
    }
}

duffid_real duffid_la_noise_sigma(const duffid_la_noise_level *level, int j)
{
    duffid_real v = RC(0.0);
    if (level->n4 > 0) {
        const duffid_real v4 = level->m4[j] / RC(70.0);
        const duffid_real v6 = level->n6 > 0 ? level->m6[j] / RC(924.0) : v4;
        v = v6 < v4 ? v6 : v4;
    }
    return R_SQRT(v);
}
