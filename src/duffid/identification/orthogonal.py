"""Orthogonal bases on a window, their operational matrices of integration, projections.

A signal ``g`` on a window of length ``T`` is approximated in normalised time
``s = (t - t0) / T`` in ``[0, 1]`` by ``r`` orthogonal functions::

    g(s) ~ c^T phi(s),    c_k = int_0^1 g phi_k w ds / int_0^1 phi_k^2 w ds

and integrals become matrix products (paper eq. 40)::

    int_0^s phi(u) du ~ P phi(s),  so  int_0^s g ~ (c^T P) phi(s)  (times T in seconds).

Bases (all on ``[0, 1]``)
-------------------------
``legendre``
    Shifted Legendre polynomials ``P_k(2s - 1)``, weight 1. ``P`` is the exact Legendre
    series of each integral, truncated to ``r`` terms (:mod:`numpy.polynomial`).
``chebyshev``
    Shifted Chebyshev polynomials of the first kind ``T_k(2s - 1)``, weight
    ``1 / sqrt(s (1 - s))``; ``P`` is the truncated Chebyshev series of each integral.
``block-pulse``
    ``r`` unit pulses of width ``1/r``; ``P = (1/r) (I/2 + strictly upper ones)``.
``haar``
    ``r = 2^J`` orthonormal Haar functions ``phi_H = H phi_B``; ``P_H = H P_B H^-1``.

What is exact
-------------
For a polynomial of degree ``<= r - 1 - n`` the polynomial bases give ``c P^n`` equal to the
coefficients of the ``n``-fold integral. Truncation drops the term of degree ``r`` of the
integral of ``phi_(r-1)``; applied again it corrupts the last coefficient (and, for
Chebyshev, whose integrals carry a constant, also the first):
:meth:`OrthogonalBasis.corrupted` lists them, and the identifier leaves them out.
Block-pulse and Haar ``P`` are exact for one integration of functions that are constant on
the blocks (steps at block edges); repeated integration is an ``O(1/r^2)`` approximation.

Coefficients of sampled signals
-------------------------------
:func:`projection_matrix` returns ``Q`` with ``c = Q g`` for ``N + 1`` equally spaced
samples. ``"gauss"`` integrates the local cubic interpolant of the samples times each
basis function by Gauss-Legendre rules on every sample interval (split at the basis'
discontinuities; for Chebyshev in ``theta = arccos(1 - 2s)``, which removes the weight's
end singularities), with enough nodes to follow the basis' oscillations: errors are those
of cubic interpolation, O(dt^4). ``"simpson"`` applies Simpson's rule to the same
interpolant on subintervals fine enough for the basis; ``"trapezoid"`` is the plain
composite trapezoid rule on the samples, which cannot follow basis functions of high
order: the coefficients that should be ~0 come out ~1e-2, and the identified parameters
are off by 50-200 % on the paper's 1-DOF case at 64 terms (kept to show it).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from math import ceil, factorial, log2

import numpy as np
from numpy.polynomial import chebyshev as npcheb
from numpy.polynomial import legendre as npleg
from scipy import sparse

from ..errors import InputError

__all__ = [
    "BASES",
    "QUADRATURES",
    "OrthogonalBasis",
    "Legendre",
    "Chebyshev",
    "BlockPulse",
    "Haar",
    "make_basis",
    "projection_matrix",
]

BASES = ("legendre", "chebyshev", "block-pulse", "haar")
QUADRATURES = ("gauss", "simpson", "trapezoid")


@dataclass(frozen=True)
class OrthogonalBasis:
    """``n_terms`` orthogonal functions on ``[0, 1]`` (base class).

    Parameters
    ----------
    n_terms : int
        Number of functions ``r``.
    """

    n_terms: int
    name = "basis"
    #: True for polynomial bases (smooth functions, truncated operational matrix).
    polynomial = False

    def __post_init__(self) -> None:
        if int(self.n_terms) != self.n_terms or self.n_terms < 2:
            raise InputError(f"{self.name}: n_terms must be an integer >= 2, got {self.n_terms!r}")
        object.__setattr__(self, "n_terms", int(self.n_terms))

    def __call__(self, s: np.ndarray) -> np.ndarray:
        """Values of the functions at ``s`` in ``[0, 1]``: shape (len(s), r)."""
        raise NotImplementedError

    def weight(self, s: np.ndarray) -> np.ndarray:
        """Weight function of the inner product."""
        return np.ones_like(np.asarray(s, dtype=float))

    def norms(self) -> np.ndarray:
        """``int_0^1 phi_k^2 w ds`` for every function."""
        raise NotImplementedError

    def breakpoints(self) -> np.ndarray:
        """Points of ``(0, 1)`` where the functions jump (piecewise-constant bases)."""
        return np.zeros(0)

    def operational_matrix(self) -> np.ndarray:
        """``P`` (r x r) with ``int_0^s phi ~ P phi(s)`` on the unit window."""
        return _operational_matrix(self)

    def _operational_matrix(self) -> np.ndarray:
        raise NotImplementedError

    def integration_matrix(self, m: int, exact: bool = False) -> np.ndarray:
        """Operational matrix of ``m``-fold integration: ``int^(m) phi ~ P_m phi``.

        ``exact=False``: ``P^m`` (the paper's eq. 40). ``exact=True``: the projection of
        the exact ``m``-fold integral of each function onto the basis: for the polynomial
        bases the leading block of ``P^m`` of a basis with ``m`` more terms (nothing is
        corrupted), for block-pulse functions the classical matrix of repeated
        integration (diagonal ``h^m/(m+1)!``; ``h^m/(m+1)! ((k+1)^(m+1) - 2k^(m+1) +
        (k-1)^(m+1))`` at ``k`` blocks to the right), for Haar ``H P_m H^-1``.
        """
        m = int(m)
        if m < 0:
            raise InputError(f"integration order must be >= 0, got {m}")
        r = self.n_terms
        if m == 0:
            return np.eye(r)
        if not exact:
            return np.linalg.matrix_power(self.operational_matrix(), m)
        return self._exact_integration(m)

    def _exact_integration(self, m: int) -> np.ndarray:
        r = self.n_terms
        return np.linalg.matrix_power(type(self)(r + m).operational_matrix(), m)[:r, :r]

    def corrupted(self, power: int) -> tuple[int, ...]:
        """Coefficients that truncation corrupts in ``c P^k`` for some ``k <= power``.

        Compares the truncated ``P^k`` with the leading block of the operational matrix of
        a basis with ``power + 2`` more terms (exact for polynomial bases). Block-pulse and
        Haar matrices are not truncations of a larger exact operator: nothing is listed.
        """
        if not self.polynomial or power < 2:
            return ()
        r = self.n_terms
        small = self.operational_matrix()
        large = type(self)(r + power + 2).operational_matrix()
        bad: set[int] = set()
        Ps, Pl = np.eye(r), np.eye(r + power + 2)
        for _ in range(power):
            Ps, Pl = Ps @ small, Pl @ large
            diff = np.abs(Ps - Pl[:r, :r]).max(axis=0)
            bad.update(np.flatnonzero(diff > 1e-12 * np.abs(Pl[:r, :r]).max()).tolist())
        return tuple(sorted(bad))

    # coefficient quadrature helpers -----------------------------------------
    def _to_theta(self) -> bool:
        """Integrate in ``theta = arccos(1 - 2s)`` (removes the Chebyshev weight)."""
        return False


@dataclass(frozen=True)
class Legendre(OrthogonalBasis):
    """Shifted Legendre polynomials ``P_k(2s - 1)``, ``k = 0 .. r-1``."""

    name = "legendre"
    polynomial = True

    def __call__(self, s: np.ndarray) -> np.ndarray:
        return npleg.legvander(2.0 * np.asarray(s, dtype=float) - 1.0, self.n_terms - 1)

    def norms(self) -> np.ndarray:
        return 1.0 / (2.0 * np.arange(self.n_terms) + 1.0)

    def _operational_matrix(self) -> np.ndarray:
        return _series_integrals(npleg.Legendre, self.n_terms)


@dataclass(frozen=True)
class Chebyshev(OrthogonalBasis):
    """Shifted Chebyshev polynomials of the first kind ``T_k(2s - 1)``."""

    name = "chebyshev"
    polynomial = True

    def __call__(self, s: np.ndarray) -> np.ndarray:
        return npcheb.chebvander(2.0 * np.asarray(s, dtype=float) - 1.0, self.n_terms - 1)

    def weight(self, s: np.ndarray) -> np.ndarray:
        s = np.asarray(s, dtype=float)
        with np.errstate(divide="ignore"):
            return 1.0 / np.sqrt(s * (1.0 - s))

    def norms(self) -> np.ndarray:
        out = np.full(self.n_terms, np.pi / 2.0)
        out[0] = np.pi
        return out

    def _operational_matrix(self) -> np.ndarray:
        return _series_integrals(npcheb.Chebyshev, self.n_terms)

    def _to_theta(self) -> bool:
        return True


@dataclass(frozen=True)
class BlockPulse(OrthogonalBasis):
    """``r`` unit pulses on the blocks ``[k/r, (k+1)/r)``."""

    name = "block-pulse"

    def __call__(self, s: np.ndarray) -> np.ndarray:
        s = np.asarray(s, dtype=float)
        block = np.clip(np.floor(s * self.n_terms).astype(int), 0, self.n_terms - 1)
        out = np.zeros((s.size, self.n_terms))
        out[np.arange(s.size), block.ravel()] = 1.0
        return out

    def norms(self) -> np.ndarray:
        return np.full(self.n_terms, 1.0 / self.n_terms)

    def breakpoints(self) -> np.ndarray:
        return np.arange(1, self.n_terms) / self.n_terms

    def _operational_matrix(self) -> np.ndarray:
        r = self.n_terms
        return (0.5 * np.eye(r) + np.triu(np.ones((r, r)), 1)) / r

    def _exact_integration(self, m: int) -> np.ndarray:
        r = self.n_terms
        k = np.arange(r, dtype=float)
        band = (k + 1) ** (m + 1) - 2.0 * k ** (m + 1) + np.abs(k - 1) ** (m + 1)
        band[0] = 1.0
        P = np.zeros((r, r))
        for offset in range(r):
            P += np.diag(np.full(r - offset, band[offset]), offset)
        return P / (r**m * factorial(m + 1))


@dataclass(frozen=True)
class Haar(OrthogonalBasis):
    """``r = 2^J`` orthonormal Haar functions: ``h_0 = 1``, ``h_(2^j + k)`` of level ``j``."""

    name = "haar"

    def __post_init__(self) -> None:
        super().__post_init__()
        if 2 ** round(log2(self.n_terms)) != self.n_terms:
            raise InputError(f"haar: n_terms must be a power of two, got {self.n_terms}")

    def matrix(self) -> np.ndarray:
        """``H`` (r x r): the Haar functions' values on the r blocks, ``phi_H = H phi_B``."""
        return _haar_matrix(self.n_terms)

    def __call__(self, s: np.ndarray) -> np.ndarray:
        return BlockPulse(self.n_terms)(s) @ self.matrix().T

    def norms(self) -> np.ndarray:
        return np.ones(self.n_terms)

    def breakpoints(self) -> np.ndarray:
        return np.arange(1, self.n_terms) / self.n_terms

    def _operational_matrix(self) -> np.ndarray:
        return self._from_block_pulse(BlockPulse(self.n_terms).operational_matrix())

    def _exact_integration(self, m: int) -> np.ndarray:
        return self._from_block_pulse(BlockPulse(self.n_terms).integration_matrix(m, exact=True))

    def _from_block_pulse(self, P: np.ndarray) -> np.ndarray:
        H = self.matrix()
        return H @ P @ H.T / self.n_terms  # H^-1 = H^T / r


def make_basis(name: str, n_terms: int) -> OrthogonalBasis:
    """Basis by name: ``legendre``, ``chebyshev``, ``block-pulse`` or ``haar``."""
    classes = {"legendre": Legendre, "chebyshev": Chebyshev, "block-pulse": BlockPulse, "haar": Haar}
    if name not in classes:
        raise InputError(f"unknown basis {name!r}; choose one of {', '.join(BASES)}")
    return classes[name](n_terms)


@lru_cache(maxsize=32)
def _operational_matrix(basis: OrthogonalBasis) -> np.ndarray:
    P = basis._operational_matrix()
    P.setflags(write=False)
    return P


def _series_integrals(cls, r: int) -> np.ndarray:
    """Rows: the series of ``int_0^s phi_k`` on the domain [0, 1], truncated to ``r`` terms."""
    P = np.zeros((r, r))
    for k in range(r):
        coef = cls.basis(k, domain=[0.0, 1.0]).integ(lbnd=0.0).coef[:r]
        P[k, : len(coef)] = coef
    P[np.abs(P) < 1e-15] = 0.0
    return P


@lru_cache(maxsize=8)
def _haar_matrix(r: int) -> np.ndarray:
    H = np.zeros((r, r))
    H[0] = 1.0
    level = 0
    while 2**level < r:
        width = r // 2**level  # blocks per support
        for k in range(2**level):
            row = 2**level + k
            H[row, k * width: k * width + width // 2] = 2.0 ** (level / 2)
            H[row, k * width + width // 2: (k + 1) * width] = -(2.0 ** (level / 2))
        level += 1
    H.setflags(write=False)
    return H


# ---------------------------------------------------------------------- projection
def _lagrange_cubic(u: np.ndarray) -> np.ndarray:
    """Weights of the cubic through nodes 0, 1, 2, 3 at local coordinates ``u``: (len, 4)."""
    return np.stack([-(u - 1) * (u - 2) * (u - 3) / 6.0, u * (u - 2) * (u - 3) / 2.0,
                     -u * (u - 1) * (u - 3) / 2.0, u * (u - 1) * (u - 2) / 6.0], axis=1)


def _nodes(basis: OrthogonalBasis, n_intervals: int, quadrature: str) -> tuple[np.ndarray, np.ndarray]:
    """Quadrature nodes ``s`` in [0, 1] and weights (weight function included)."""
    N = n_intervals
    r = basis.n_terms
    edges = np.union1d(np.arange(N + 1) / N, basis.breakpoints())
    edges = edges[np.concatenate([[True], np.diff(edges) > 1e-13])]
    edges[-1] = 1.0
    theta = basis._to_theta()
    lo, hi = edges[:-1], edges[1:]
    if theta:  # integrate in theta: w(s) ds = d theta
        lo, hi = np.arccos(1.0 - 2.0 * lo), np.arccos(1.0 - 2.0 * hi)
    width = hi - lo
    # phase a basis function of order r runs through on each subinterval (in theta)
    phase = r * np.abs(np.arccos(1.0 - 2.0 * edges[1:]) - np.arccos(1.0 - 2.0 * edges[:-1]))
    if quadrature == "trapezoid":
        x = np.concatenate([lo, hi])
        w = np.concatenate([width, width]) / 2.0
    else:
        if not basis.polynomial:
            counts = np.full(len(lo), 2 if quadrature == "gauss" else 1)
        elif quadrature == "gauss":
            counts = 5 + np.ceil(0.5 * phase).astype(int)
            if not theta:  # a cubic times a polynomial of degree r-1 is exact with (r+3)/2 nodes
                counts = np.minimum(counts, ceil((r + 3) / 2))
        else:
            counts = 2 + np.ceil(2.0 * phase).astype(int)  # Simpson panels per subinterval
        xs, ws = [], []
        for q in np.unique(counts):
            sel = counts == q
            if quadrature == "gauss":
                t, wt = np.polynomial.legendre.leggauss(int(q))
                t, wt = (t + 1.0) / 2.0, wt / 2.0
            else:  # q Simpson panels: points 0, 1/(2q), ..., 1 with weights (1 4 2 4 ... 4 1)/(6q)
                t = np.linspace(0.0, 1.0, 2 * q + 1)
                wt = np.ones(2 * q + 1)
                wt[1:-1:2], wt[2:-1:2] = 4.0, 2.0
                wt = wt / (6.0 * q)
            xs.append((lo[sel, None] + width[sel, None] * t[None, :]).ravel())
            ws.append((width[sel, None] * wt[None, :]).ravel())
        x, w = np.concatenate(xs), np.concatenate(ws)
    s = (1.0 - np.cos(x)) / 2.0 if theta else x
    if not theta:
        w = w * basis.weight(s)
    return np.clip(s, 0.0, 1.0), w


@lru_cache(maxsize=32)
def projection_matrix(basis: OrthogonalBasis, n_intervals: int, quadrature: str = "gauss") -> np.ndarray:
    """Matrix ``Q`` (r x (N+1)) giving the basis coefficients ``c = Q g`` of ``N + 1`` samples.

    Parameters
    ----------
    basis : OrthogonalBasis
        Basis on the window.
    n_intervals : int
        ``N``: sample intervals in the window (samples at ``s = i / N``), at least 3.
    quadrature : {"gauss", "simpson", "trapezoid"}
        Rule for the coefficient integrals, see the module documentation.

    Returns
    -------
    ndarray
        Read-only ``Q``; rows are divided by the functions' norms.
    """
    if quadrature not in QUADRATURES:
        raise InputError(f"unknown quadrature {quadrature!r}; choose one of {', '.join(QUADRATURES)}")
    N = int(n_intervals)
    if N < 3:
        raise InputError(f"a window needs at least 3 sample intervals, got {n_intervals!r}")
    s, w = _nodes(basis, N, quadrature)
    if quadrature == "trapezoid":
        # plain rule on the samples: the nodes are sample points (or block edges between
        # them, where the samples are interpolated linearly)
        pos = s * N
        j0 = np.clip(np.floor(pos).astype(int), 0, N - 1)
        frac = pos - j0
        rows = np.repeat(np.arange(len(s)), 2)
        cols = np.stack([j0, j0 + 1], axis=1).ravel()
        vals = np.stack([1.0 - frac, frac], axis=1).ravel()
    else:
        interval = np.clip(np.floor(s * N).astype(int), 0, N - 1)
        j0 = np.clip(interval - 1, 0, N - 3)
        lag = _lagrange_cubic(s * N - j0)
        rows = np.repeat(np.arange(len(s)), 4)
        cols = (j0[:, None] + np.arange(4)[None, :]).ravel()
        vals = lag.ravel()
    S = sparse.csr_matrix((vals, (rows, cols)), shape=(len(s), N + 1))
    Q = np.asarray((S.T @ (basis(s) * w[:, None])).T) / basis.norms()[:, None]
    Q.setflags(write=False)
    return Q
