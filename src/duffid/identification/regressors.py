"""Integrated-by-parts regressors over a moving window, online (O(1)) and in batch.

Theory
------
Multiplying an equation term ``g^(d)(t)`` by ``tau^b`` (``tau = t - t0``) and integrating
``a + 1`` times from ``t0`` gives, by Cauchy's formula for repeated integrals, a kernel
integral over the window ``[t0, t]`` of length ``T``::

    int_0^T W(sigma) g^(d)(t - sigma) dsigma,   W(sigma) = sigma^a (T - sigma)^b / a!

With ``b >= d`` the kernel and its first ``d - 1`` derivatives vanish at ``sigma = T``,
so integration by parts leaves no initial conditions::

    = int_0^T W^(d)(sigma) g(t - sigma) dsigma + [a == 1 and d == 2] * T^b g(t)

The paper's rows ``I^0 .. I^3`` of eq. (16)-(17) are ``(a, b) = (1, 2) .. (4, 2)``; the
robust rows start at ``a = 2`` and carry no raw measurement term.

Each entry is a polynomial kernel, so it is a linear combination of the *moments*
``S_k = (1/N) sum_i c_i (i/N)^k g[n - i]`` of the samples in the window (``N``: samples
per reference length, ``c_i``: quadrature weights). :class:`SlidingMoments` updates them
in O(1) per sample: the window is covered by two blocks whose power sums are kept
about the boundary between them; a block is rebuilt from scratch every ``N`` samples,
so rounding errors never accumulate. Quadrature is Gregory's end-corrected trapezoid rule
with :data:`GREGORY_POINTS` corrected samples at each end (order ``GREGORY_POINTS + 1``;
fewer in windows of fewer than ``2 GREGORY_POINTS`` intervals, closed Newton-Cotes below
six). The order matters at few samples per period: the rule's error sits at the window's
ends, where the kernels do not vanish, and a lightly damped plant's damping is a small
share of each row (at 10 samples per period of a swept sine, a fourth-order rule put the
damping 8.7 % off, noise-free).

Rows are normalised by ``int_0^T W``: a row is then a weighted average of the equation
(units of force), and the ``d``-th derivative columns carry a factor ``T_ref^-d``.
"""
from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction
from functools import cache
from math import comb, factorial

import numpy as np

from ..errors import InputError

__all__ = [
    "row_exponents",
    "GREGORY_POINTS",
    "gregory_end",
    "gregory_points",
    "gregory_corrections",
    "KernelBank",
    "SlidingMoments",
    "batch_moments",
]

_NEWTON_COTES = {
    1: np.array([1, 1]) / 2,
    2: np.array([1, 4, 1]) / 3,
    3: np.array([3, 9, 9, 3]) / 8,
    4: np.array([14, 64, 24, 64, 14]) / 45,
    5: np.array([95, 375, 250, 250, 375, 95]) / 288,
}
#: Corrected samples at each end of a window in Gregory's rule (its order is one more).
GREGORY_POINTS = 7


def _bernoulli(n: int) -> Fraction:
    """The Bernoulli number ``B_n`` (``B_1 = -1/2``)."""
    B = [Fraction(1)]
    for m in range(1, n + 1):
        B.append(-sum(comb(m + 1, j) * B[j] for j in range(m)) / (m + 1))
    return B[n]


@cache
def gregory_end(points: int) -> tuple[Fraction, ...]:
    """Gregory's end corrections ``c_i - 1`` of the ``points`` samples at one end of a window
    (``i = 0`` the end sample), exact.

    They make the rule exact for polynomials of degree ``points - 1``: with weights ``1 +
    delta_i`` near each end and ``1`` inside, ``sum_i delta_i i^j`` must be ``-1/2`` for
    ``j = 0`` (the trapezoid's half weight) and the Euler-Maclaurin term ``B_(j+1) / (j+1)``
    for odd ``j`` (0 otherwise). ``gregory_end(3)`` is the classical ``(-5/8, 1/6, -1/24)``.
    """
    if points < 1:
        raise InputError(f"Gregory's rule needs at least one corrected sample, got {points}")
    rhs = [Fraction(-1, 2) if j == 0 else (_bernoulli(j + 1) / (j + 1) if j % 2 else Fraction(0))
           for j in range(points)]
    rows = [[Fraction(i) ** j for i in range(points)] + [rhs[j]] for j in range(points)]
    for c in range(points):  # Gauss-Jordan on the (exact, non-singular) Vandermonde system
        pivot = next(r for r in range(c, points) if rows[r][c] != 0)
        rows[c], rows[pivot] = rows[pivot], rows[c]
        for r in range(points):
            if r != c and rows[r][c] != 0:
                factor = rows[r][c] / rows[c][c]
                rows[r] = [a - factor * b for a, b in zip(rows[r], rows[c])]
    return tuple(rows[i][points] / rows[i][i] for i in range(points))


def gregory_points(n_intervals: int) -> int:
    """Corrected samples at each end of a window of ``n_intervals`` (at least 6) intervals:
    :data:`GREGORY_POINTS`, fewer where the two ends would meet."""
    return min(GREGORY_POINTS, (int(n_intervals) + 1) // 2)


def row_exponents(family: str, n_rows: int) -> tuple[tuple[int, int], ...]:
    """Exponents ``(a, b)`` of the row kernels ``sigma^a (T - sigma)^b / a!``.

    Parameters
    ----------
    family : {"paper", "integrals", "bernstein"}
        ``paper``: the paper's rows I^0, I^1, ... (``(1 + p, 2)``); ``integrals``: the
        same rows integrated twice more, I^2, I^3, ... (``(3 + p, 2)``), which filter the
        raw measurement term; ``bernstein``: ``(2 + p, 1 + n_rows - p)``, kernels that
        peak at different places across the window (better conditioned for many rows).
    n_rows : int
        Number of rows.
    """
    if n_rows < 1:
        raise InputError(f"n_rows must be >= 1, got {n_rows}")
    if family == "paper":
        return tuple((1 + p, 2) for p in range(n_rows))
    if family == "integrals":
        return tuple((3 + p, 2) for p in range(n_rows))
    if family == "bernstein":
        return tuple((2 + p, 1 + n_rows - p) for p in range(n_rows))
    raise InputError(f"unknown row family {family!r}; choose paper, integrals or bernstein")


def gregory_corrections(n_intervals: int) -> tuple[np.ndarray, np.ndarray]:
    """Quadrature weights minus one, for a window of ``n_intervals`` steps.

    Returns ``(offsets, deltas)``: sample offsets ``i`` (0 = newest sample) and
    ``c_i - 1`` for the weights ``c_i`` of the rule ``h * sum_i c_i g[n - i]``.
    """
    L = int(n_intervals)
    if L < 1:
        return np.zeros(1, dtype=int), np.array([-1.0])
    if L in _NEWTON_COTES:
        return np.arange(L + 1), _NEWTON_COTES[L] - 1.0
    p = gregory_points(L)
    end = np.array([float(d) for d in gregory_end(p)])
    return np.concatenate([np.arange(p), L - np.arange(p)]), np.concatenate([end, end])


@dataclass(frozen=True)
class KernelBank:
    """Polynomial coefficients of the row kernels for derivative orders 0..max_order.

    For row ``r`` and order ``d`` the normalised entry of a channel ``g`` is
    ``row_scale(tau)[r] * d_scale[d] * (sum_k coef[r,d,k] tau^expo[r,d,k] S_k + raw)``
    where ``tau = T / T_ref`` is the window length relative to the reference length.
    """

    rows: tuple[tuple[int, int], ...]
    max_order: int
    coef: np.ndarray
    expo: np.ndarray
    raw_b: np.ndarray  # exponent b of the raw term per row, -1 where none

    @classmethod
    def build(cls, rows: tuple[tuple[int, int], ...], max_order: int) -> "KernelBank":
        """Expand ``d^d/ds^d [s^a (tau - s)^b] / a!`` for every row and order."""
        for a, b in rows:
            if b < max_order or a < max_order - 1:
                raise InputError(
                    f"row kernel (a={a}, b={b}) cannot take derivatives of order {max_order}: "
                    "need b >= order (no initial conditions) and a >= order - 1")
        degree = max(a + b for a, b in rows)
        coef = np.zeros((len(rows), max_order + 1, degree + 1))
        expo = np.zeros_like(coef)
        raw_b = np.full(len(rows), -1)
        for r, (a, b) in enumerate(rows):
            for m in range(b + 1):  # s^a (tau - s)^b = sum_m C(b,m) (-1)^m tau^(b-m) s^(a+m)
                power = a + m
                for d in range(max_order + 1):
                    if power - d < 0:
                        continue
                    falling = factorial(power) // factorial(power - d)
                    coef[r, d, power - d] += comb(b, m) * (-1) ** m * falling / factorial(a)
                    expo[r, d, power - d] = b - m
            if a == 1 and max_order >= 2:
                raw_b[r] = b
        return cls(tuple(rows), max_order, coef, expo, raw_b)

    @property
    def degree(self) -> int:
        """Highest power of the moments needed."""
        return self.coef.shape[2] - 1

    def polynomials(self, tau: float | np.ndarray) -> np.ndarray:
        """Kernel coefficients for window length(s) ``tau``: shape (..., rows, orders, degree+1)."""
        tau = np.asarray(tau, dtype=float)[..., None, None, None]
        return self.coef * tau**self.expo

    def row_scale(self, tau: float | np.ndarray) -> np.ndarray:
        """``(a+b+1)! / (b! tau^(a+b+1))``: one over the integral of each row kernel."""
        tau = np.asarray(tau, dtype=float)[..., None]
        return self._norm / tau**self._norm_power

    def __post_init__(self) -> None:
        object.__setattr__(self, "_norm", np.array([factorial(a + b + 1) / factorial(b) for a, b in self.rows]))
        object.__setattr__(self, "_norm_power", np.array([a + b + 1 for a, b in self.rows], dtype=float))

    def entries(self, tau: float, moments: np.ndarray, newest: np.ndarray, t_ref: float) -> np.ndarray:
        """Normalised entries ``E[r, d, channel]`` for one window.

        Parameters
        ----------
        tau : float
            Window length over the reference length.
        moments : ndarray, shape (degree+1, channels)
            Quadrature-weighted moments ``S_k``.
        newest : ndarray, shape (channels,)
            The newest sample of each channel (raw terms of rows with ``a = 1``).
        t_ref : float
            Reference length [s].
        """
        E = self.polynomials(tau) @ moments
        raw = self.raw_b >= 0
        if raw.any():
            E[raw, 2, :] += (tau ** self.raw_b[raw])[:, None] * newest[None, :]
        d_scale = t_ref ** -np.arange(self.max_order + 1, dtype=float)
        return E * (self.row_scale(tau)[:, None, None] * d_scale[None, :, None])


    def within(self, tau: float, moments: np.ndarray, t_ref: float) -> np.ndarray:
        """Normalised entries of the kernels ``s w_r`` (``s``: a sample's age in reference
        lengths), each row normalised as its own: ``(s w)^(d) = s w^(d) + d w^(d-1)``, so the
        moments one power up and the entries of one order lower. A coefficient linear in time
        (a :class:`~duffid.identification.engine.DriftLine`) at ``t_now - s t_ref`` has the
        rows ``t_now E - t_ref within``.

        Parameters
        ----------
        tau : float
            Window length over the reference length.
        moments : ndarray, shape (degree+2, channels)
            Quadrature-weighted moments ``S_k``, one power more than :meth:`entries` takes.
        t_ref : float
            Reference length [s].
        """
        P = self.polynomials(tau)  # (s w vanishes with its first derivative at s = 0: no raw term)
        E = P @ moments[1:]
        orders = np.arange(1, self.max_order + 1, dtype=float)
        E[:, 1:] += orders[None, :, None] * (P[:, :-1] @ moments[:-1])
        d_scale = t_ref ** -np.arange(self.max_order + 1, dtype=float)
        return E * (self.row_scale(tau)[:, None, None] * d_scale[None, :, None])


class SlidingMoments:
    """O(1)-per-sample moments of the last ``L`` sample intervals of several channels.

    Parameters
    ----------
    n_ref : int
        Samples per reference length (``s = i / n_ref``); also the largest window, in
        sample intervals.
    degree : int
        Highest moment power.
    n_channels : int
        Number of channels.

    Notes
    -----
    The sums ``sum_i (i/n_ref)^k g[n-i]`` are kept about the newest sample. When a sample
    arrives every ``s`` grows by ``1/n_ref``, a product with the binomial matrix
    ``B[k, r] = C(k, r) n_ref^(r-k)`` whose entries are all positive (no cancellation);
    the sample leaving the window is subtracted. A shadow accumulator starts empty at
    some sample and replaces the main one as soon as it holds exactly the window, so no
    accumulator lives longer than two window lengths and rounding errors cannot build up.
    All storage is allocated here.
    """

    def __init__(self, n_ref: int, degree: int, n_channels: int) -> None:
        if n_ref < 1:
            raise InputError(f"the window needs at least one sample interval, got {n_ref}")
        self.n_ref = int(n_ref)
        self.degree = int(degree)
        self._q = np.arange(degree + 1, dtype=float)
        k, r = np.meshgrid(np.arange(degree + 1), np.arange(degree + 1), indexing="ij")
        binom = np.vectorize(comb)(k, np.minimum(r, k)).astype(float)
        self._shift = np.where(r <= k, binom * (1.0 / self.n_ref) ** np.maximum(k - r, 0), 0.0)
        self._buffer = np.zeros((self.n_ref + 2, n_channels))
        self._main = np.zeros((degree + 1, n_channels))
        self._shadow = np.zeros((degree + 1, n_channels))
        # the same sums of the samples with alternating signs (-1)^j g[j] (j: the sample's
        # index), for the rule at half the rate (rate_difference)
        self._alt = np.zeros((degree + 1, n_channels))
        self._alt_shadow = np.zeros((degree + 1, n_channels))
        self._rate_cache: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._corr_cache: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self.reset()

    def reset(self) -> None:
        """Forget every sample."""
        self._buffer[:] = 0.0
        self._main[:] = 0.0
        self._shadow[:] = 0.0
        self._alt[:] = 0.0
        self._alt_shadow[:] = 0.0
        self.n = -1          # index of the newest sample
        self.start = 0       # index of the oldest sample in the window
        self._shadow_from = 0  # first sample held by the shadow accumulator

    def corrections(self, L: int) -> np.ndarray:
        """The quadrature's end corrections for a window of ``L`` intervals: shape
        (samples corrected, degree+1), the weight of each corrected sample in each moment
        (before the moments' ``1/n_ref``)."""
        return self._corrections(L)[2]

    def _corrections(self, L: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        cached = self._corr_cache.get(L)
        if cached is None:
            offsets, deltas = gregory_corrections(L)
            powers = (offsets[:, None] / self.n_ref) ** self._q[None, :]
            cached = (offsets, deltas, powers * deltas[:, None])
            if L == self.n_ref or len(self._corr_cache) < 64:
                self._corr_cache[L] = cached
        return cached

    def push(self, g: np.ndarray, window: int) -> tuple[np.ndarray, int]:
        """Add the newest sample ``g`` (channels,) and return the window's moments.

        Parameters
        ----------
        g : ndarray
            Newest sample of each channel.
        window : int
            Requested window length in sample intervals (at most ``n_ref``). The window
            grows from the first sample until it has this length, then slides.

        Returns
        -------
        moments : ndarray, shape (degree+1, channels)
            ``S_k = (1/n_ref) sum_i c_i (i/n_ref)^k g[n-i]`` with quadrature weights ``c_i``.
        L : int
            Window length in sample intervals.
        """
        N = self.n_ref
        self.n += 1
        n = self.n
        sign = -1.0 if n % 2 else 1.0
        self._buffer[n % (N + 2)] = g
        for acc, shadow, value in ((self._main, self._shadow, g), (self._alt, self._alt_shadow, sign * g)):
            acc[:] = self._shift @ acc
            shadow[:] = self._shift @ shadow
            acc[0] += value
            shadow[0] += value
        new_start = max(self.start, n - min(int(window), N))
        for j in range(self.start, new_start):  # samples leaving the window
            s = (n - j) / N
            leaving = np.outer(s**self._q, self._buffer[j % (N + 2)])
            self._main -= leaving
            self._alt -= leaving if j % 2 == 0 else -leaving
        self.start = new_start
        if self._shadow_from < self.start:  # the shadow holds samples outside the window: rebuild
            self._shadow_from = self.start
            i = np.arange(n - self.start + 1)
            powers = ((i[:, None] / N) ** self._q[None, :]).T
            samples = self._buffer[(n - i) % (N + 2)]
            self._shadow[:] = powers @ samples
            self._alt_shadow[:] = powers @ (samples * np.where((n - i) % 2 == 0, 1.0, -1.0)[:, None])
        if self._shadow_from == self.start and n - self.start >= 1:
            # the shadow holds exactly the window: it becomes the main accumulator
            self._main[:] = self._shadow
            self._alt[:] = self._alt_shadow
            self._shadow[:] = 0.0
            self._alt_shadow[:] = 0.0
            self._shadow_from = n + 1
        L = n - self.start
        offsets, _, weighted = self._corrections(L)
        moments = self._main + weighted.T @ self._buffer[(n - offsets) % (N + 2)]
        return moments / N, L

    def _rate_weights(self, L: int) -> tuple[np.ndarray, np.ndarray]:
        """The samples and weights (x the powers) of :meth:`rate_difference` besides the
        alternating sums, for a window of ``L`` intervals: the rule's end corrections over
        the even part ``L_e`` of the window, minus the half-rate rule's (twice its
        corrections at every second sample), and the oldest sample when ``L`` is odd (it is
        outside ``L_e``)."""
        cached = self._rate_cache.get(L)
        if cached is None:
            even = L - L % 2
            fine_at, fine = gregory_corrections(even)
            coarse_at, coarse = gregory_corrections(even // 2)
            offsets = np.concatenate([fine_at, 2 * coarse_at, [L] if L % 2 else []]).astype(int)
            deltas = np.concatenate([fine, -2.0 * coarse, [-1.0] if L % 2 else []])
            cached = (offsets, ((offsets[:, None] / self.n_ref) ** self._q[None, :]) * deltas[:, None])
            if L == self.n_ref or len(self._rate_cache) < 64:
                self._rate_cache[L] = cached
        return cached

    def rate_difference(self) -> np.ndarray | None:
        """The window's moments by the rule minus those by the same rule at half the rate
        (every second sample, twice the step), over the window's even part ``L_e`` (its
        oldest sample left out when ``L`` is odd); None below two intervals. Both rules
        integrate the same samples, so their difference estimates the quadrature's error
        whatever kernel the moments then meet (the window's own, of length ``L``).

        The half-rate rule's interior is the samples at even distances from the newest
        with weight two: the sum over all samples plus the alternating sum, so the
        difference is minus the alternating sum plus the two rules' end corrections; the
        alternating sums are kept like the plain ones (on ``(-1)^j g[j]``), at the same
        cost. Returns the moments' difference, shape (degree+1, channels)."""
        N = self.n_ref
        n = self.n
        L = n - self.start
        if L < 2:
            return None
        offsets, weighted = self._rate_weights(L)
        alternating = self._alt if n % 2 == 0 else -self._alt  # sum_i (-1)^i (i/N)^k g[n-i]
        return (weighted.T @ self._buffer[(n - offsets) % (N + 2)] - alternating) / N


def batch_moments(G: np.ndarray, lengths: np.ndarray, n_ref: int, degree: int) -> np.ndarray:
    """Moments of every window of a whole record (the batch twin of :class:`SlidingMoments`).

    Parameters
    ----------
    G : ndarray, shape (n, channels)
        Channel samples.
    lengths : ndarray of int, shape (n,)
        Window length (sample intervals) ending at each sample; ``lengths[n] <= n`` and
        the window start ``n - lengths[n]`` never decreases.
    n_ref : int
        Samples per reference length.
    degree : int
        Highest moment power.

    Returns
    -------
    ndarray, shape (n, degree+1, channels)
    """
    n, n_ch = G.shape
    lengths = np.asarray(lengths, dtype=int)
    q = np.arange(degree + 1, dtype=float)
    out = np.zeros((n, degree + 1, n_ch))
    L_max = int(lengths.max()) if n else 0
    kernel = (np.arange(L_max + 1)[:, None] / n_ref) ** q[None, :]  # (L_max+1, degree+1)
    # one direct convolution per power and channel (an FFT would add errors relative to
    # the largest sample, swamping the small values at the start of a record)
    for k in range(degree + 1):
        for c in range(n_ch):
            out[:, k, c] = np.convolve(G[:, c], kernel[:, k])[:n]
    # windows shorter than L_max that do not start at the first sample: remove the
    # samples the full-length convolution took before their start
    for idx in np.flatnonzero(lengths < np.minimum(np.arange(n), L_max)):
        i = np.arange(lengths[idx] + 1, min(L_max, idx) + 1)
        out[idx] -= kernel[i].T @ G[idx - i]
    # quadrature end corrections
    for L in np.unique(lengths):
        rows = np.flatnonzero(lengths == L)
        offsets, deltas = gregory_corrections(int(L))
        weighted = (offsets[:, None] / n_ref) ** q[None, :] * deltas[:, None]  # (m, degree+1)
        samples = G[rows[:, None] - offsets[None, :]]  # (rows, m, ch)
        out[rows] += np.einsum("mk,rmc->rkc", weighted, samples)
    return out / n_ref
