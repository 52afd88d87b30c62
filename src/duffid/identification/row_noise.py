"""The rows' own noise: how the displacement's noise biases the online estimate.

The integrated-by-parts rows hold the displacement's channels (``x``, ``x^3``, deflections,
an equation's expressions of ``x``) on the *left* of the least squares, so their noise is
noise in the regressors ("errors in variables"): it biases every unknown through the
normal matrix ``A^T A``, by much more than the standard errors say where a channel is small
against its noise. Above resonance the displacement is small and ``(x + e)^3 - x^3`` is no
longer small against ``x^3``; a settled step's rows hold one displacement whose ``k x`` and
``kp x^3`` differ only by the noise.

The online identifier measures that bias as it goes. The displacement's noise level comes
from its 4th and 6th differences (white noise: variance ``70 s^2`` and ``924 s^2``; a smooth
signal barely reaches them); the rows' noise ``dA`` is the channels at the displacement plus
a pseudo-random white noise of that level, minus the channels, through the same moments,
kernels and assembly as the rows. Accumulated like the rows, ``N = dA^T dA`` and
``c = dA^T dD`` give the noise-corrected solution ``(A^T A - N)^-1 (A^T D - c)``; its
difference from the solution is a bias each stated error includes, and where the noise
carries :data:`NOISE_SHARE` or more of the rows' energy in some direction nothing rests on
them (the shift is infinite). The C core computes the same numbers
(``duffid_estimator.c``, same generator and the same order of operations).
"""
from __future__ import annotations

import numpy as np

__all__ = ["NOISE_SHARE", "NOISE_SEED", "NoiseLevel", "noise_sigmas", "noise_shift"]

#: Where the displacement's noise carries this share of the rows' energy in some direction
#: (``A^T A - N / NOISE_SHARE`` is not positive definite), their solution is not published.
NOISE_SHARE = 0.5

#: The seed of the rows' noise generator (xorshift32: the same integers in Python and C).
NOISE_SEED = 2463534242

#: Variance of the 4th and 6th differences of unit white noise (binomial coefficients squared).
_D4 = (1.0, -4.0, 6.0, -4.0, 1.0)
_D6 = (1.0, -6.0, 15.0, -20.0, 15.0, -6.0, 1.0)
_V4 = 70.0
_V6 = 924.0
_SQRT3 = 1.7320508075688772  # a uniform variable on [-sqrt 3, sqrt 3] has unit variance


class NoiseLevel:
    """The displacements' white-noise level and a generator of noise of that level.

    Parameters
    ----------
    n_dof : int
        Displacements per sample.
    """

    def __init__(self, n_dof: int) -> None:
        self.n_dof = int(n_dof)
        self.reset()

    def reset(self) -> None:
        """Forget every sample; the generator starts again from :data:`NOISE_SEED`."""
        self._state = NOISE_SEED
        self._history: list[np.ndarray] = []  # the newest last, at most 7
        self._m4 = np.zeros(self.n_dof)  # running means of the squared differences
        self._m6 = np.zeros(self.n_dof)
        self._n4 = 0
        self._n6 = 0

    def push(self, x: np.ndarray) -> None:
        """Take the displacements of one sample."""
        h = self._history
        h.append(np.array(x[: self.n_dof], dtype=float))
        if len(h) > len(_D6):
            h.pop(0)
        if len(h) >= len(_D4):
            d4 = sum(c * v for c, v in zip(_D4, h[-len(_D4):]))
            self._n4 += 1
            self._m4 += (d4 * d4 - self._m4) / self._n4
        if len(h) >= len(_D6):
            d6 = sum(c * v for c, v in zip(_D6, h))
            self._n6 += 1
            self._m6 += (d6 * d6 - self._m6) / self._n6

    def sigma(self) -> np.ndarray:
        """Each displacement's noise standard deviation so far (the smaller of the two
        differences' estimates; 0 before five samples)."""
        if self._n4 == 0:
            return np.zeros(self.n_dof)
        v4 = self._m4 / _V4
        v6 = self._m6 / _V6 if self._n6 else v4
        return np.sqrt(np.minimum(v4, v6))

    def uniform(self) -> float:
        """The next pseudo-random number of unit variance (uniform, xorshift32)."""
        s = self._state
        s ^= (s << 13) & 0xFFFFFFFF
        s ^= s >> 17
        s ^= (s << 5) & 0xFFFFFFFF
        self._state = s
        return (2.0 * (s / 4294967296.0) - 1.0) * _SQRT3

    def perturbed(self, x: np.ndarray) -> np.ndarray:
        """``x`` plus a pseudo-random white noise of the measured level."""
        out = np.array(x, dtype=float)
        sigma = self.sigma()
        for j in range(self.n_dof):
            out[j] += sigma[j] * self.uniform()
        return out


def noise_sigmas(x: np.ndarray) -> np.ndarray:
    """:meth:`NoiseLevel.sigma` after each sample of ``x`` (samples x displacements), all at
    once: equal to pushing the samples one by one, to rounding."""
    x = np.asarray(x, dtype=float).reshape(len(x), -1)
    out = np.zeros_like(x)

    def running(weights: tuple[float, ...], variance: float) -> np.ndarray:
        diff = sum(c * x[k:len(x) - len(weights) + 1 + k] for k, c in enumerate(weights))
        return np.cumsum(diff**2, axis=0) / np.arange(1, len(diff) + 1)[:, None] / variance

    if len(x) >= len(_D4):
        v = running(_D4, _V4)
        if len(x) >= len(_D6):
            v[2:] = np.minimum(v[2:], running(_D6, _V6))
        out[len(_D4) - 1:] = np.sqrt(v)
    return out


def _forward(R: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``R^-T b`` for an upper-triangular ``R`` (forward substitution, as the C core)."""
    n = len(b)
    w = np.zeros(n)
    for i in range(n):
        w[i] = (b[i] - R[:i, i] @ w[:i]) / R[i, i]
    return w


def _backward(R: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``R^-1 b`` for an upper-triangular ``R``."""
    n = len(b)
    x = np.zeros(n)
    for i in range(n - 1, -1, -1):
        x[i] = (b[i] - R[i, i + 1:] @ x[i + 1:]) / R[i, i]
    return x


def _cholesky(S: np.ndarray) -> np.ndarray | None:
    """The lower Cholesky factor of the symmetric ``S`` (its lower triangle), None unless
    positive definite."""
    n = len(S)
    L = np.zeros((n, n))
    for j in range(n):
        d = S[j, j] - L[j, :j] @ L[j, :j]
        if not d > 0.0:
            return None
        L[j, j] = np.sqrt(d)
        for i in range(j + 1, n):
            L[i, j] = (S[i, j] - L[i, :j] @ L[j, :j]) / L[j, j]
    return L


def noise_shift(R_aug: np.ndarray, gram: np.ndarray, cross: np.ndarray) -> np.ndarray:
    """How the rows' noise moves the solution of the factor ``R_aug`` of ``[A D]``.

    Parameters
    ----------
    R_aug : ndarray
        The upper-triangular factor, ``(n + 1) x (n + 1)``.
    gram, cross : ndarray
        ``N = dA^T dA`` (``n x n``) and ``c = dA^T dD`` of the rows' noise, accumulated as
        the rows.

    Returns
    -------
    ndarray
        ``(A^T A - N)^-1 (A^T D - c)`` minus the solution, computed in the factor's
        coordinates (``M = R^-T N R^-1``, shift ``= R^-1 (I - M)^-1 (M z - R^-T c)``);
        infinite where the noise carries :data:`NOISE_SHARE` or more of the rows' energy in
        some direction (``NOISE_SHARE I - M`` is not positive definite); zeros without noise
        or for a singular factor.
    """
    n = R_aug.shape[0] - 1
    R, z = R_aug[:n, :n], R_aug[:n, n]
    if not np.any(gram) or not np.all(np.diag(R) != 0):
        return np.zeros(n)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        Y = np.column_stack([_forward(R, gram[:, k]) for k in range(n)])  # R^-T N
        M = np.column_stack([_forward(R, Y[k, :]) for k in range(n)])  # R^-T N R^-1 (M[i, k])
        if _cholesky(NOISE_SHARE * np.eye(n) - M) is None:
            return np.full(n, np.inf)
        L = _cholesky(np.eye(n) - M)
        if L is None:
            return np.full(n, np.inf)
        rhs = M @ z - _forward(R, cross)
        y = np.zeros(n)
        for i in range(n):  # L y = rhs
            y[i] = (rhs[i] - L[i, :i] @ y[:i]) / L[i, i]
        s = np.zeros(n)
        for i in range(n - 1, -1, -1):  # L^T s = y
            s[i] = (y[i] - L[i + 1:, i] @ s[i + 1:]) / L[i, i]
        return _backward(R, s)
