/*
 * duffid_linalg.h - small dense linear algebra of the estimator core (internal).
 *
 * Matrices are row-major with a leading dimension equal to their column count. Sizes
 * are at most DUFFID_LA_MAX x DUFFID_LA_MAX (workspaces are fixed arrays, no VLA).
 */
#ifndef DUFFID_LINALG_H
#define DUFFID_LINALG_H

#define DUFFID_LA_MAX 17

/* Sum of n values a[0], a[stride], ... in numpy's pairwise order (np.add.reduce over a
 * contiguous axis), so that reductions round like the Python reference. */
double duffid_la_pairwise_sum(const double *a, int n, int stride);

/* Triangular factor update by Householder reflections: the p x p upper triangular R
 * becomes the R factor of [s R; B] (B: m x p new rows, destroyed). With R = 0 this is
 * the QR factorisation of B. Diagonal signs follow LAPACK (beta = -sign(alpha) norm). */
void duffid_la_qr_accumulate(double *R, int p, double s, double *B, int m);

/* One-sided (Hestenes) Jacobi SVD of the n x n matrix a = U diag(sv) V^T.
 * On return a holds U (columns of unit length where sv > 0), sv the singular values in
 * descending order and v the n x n matrix V. Returns the number of sweeps, or -1 if
 * the iteration did not converge (the result is then approximate). */
int duffid_la_jacobi_svd(int n, double *a, double *sv, double *v);

/* Determinant by LU with partial pivoting, returned as numpy's det does:
 * sign * exp(sum log |u_ii|) (0 for an exactly singular matrix). a is destroyed. */
double duffid_la_det(int n, double *a);

/* Solve a X = b for the n x nrhs matrix b (overwritten by X) by LU with partial pivoting
 * (np.linalg.solve); a is destroyed. Returns 0, or k > 0 when the k-th pivot is exactly 0. */
int duffid_la_solve(int n, double *a, double *b, int nrhs);

/* Eigenvalues wr + i wi of the general n x n matrix a (np.linalg.eigvals to rounding):
 * reduction to Hessenberg form, then shifted QR iterations. a is destroyed. Returns 0, or
 * -1 if a holds a non-finite value or the iteration did not converge. */
int duffid_la_eigenvalues(int n, double *a, double *wr, double *wi);

#endif /* DUFFID_LINALG_H */
