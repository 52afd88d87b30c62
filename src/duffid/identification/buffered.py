"""Buffered identification with orthogonal functions (paper section 4, eqs. 34-45, Figure 15).

Every ``every`` samples the identifier takes the last window of ``N + 1`` samples
(length ``T = N dt``), and for each equation multiplied by ``tau^n`` (``tau = t - t0``,
``n`` the highest derivative order, 2 here) and integrated ``n`` times by parts, as in
eq. (38)::

    int^(n) tau^n g^(d) = sum_k (-1)^k C(d, k) n!/(n-k)! int^(n-d+k) tau^(n-k) g

it approximates the integrands ``tau^p g`` by ``r`` orthogonal functions (eq. 39),
replaces each ``m``-fold integral by the operational matrix ``P^m`` (eq. 40) and equates
the coefficients of the basis functions (eqs. 41-42). That gives ``r`` linear equations per
degree of freedom, ``[Theta]^T [A] = [B]`` (eq. 44), solved by the SVD pseudoinverse
(eq. 45) with the unknowns scaled to unit column norm; the condition number of the scaled
problem is reported. The coefficients that the truncated ``P`` corrupts
(:meth:`~duffid.identification.orthogonal.OrthogonalBasis.corrupted`) are left out.

In matrix terms each window costs ``n + 1`` products of fixed ``r' x (N+1)`` matrices
(``W_d``: quadrature, basis, ``P`` powers and ``tau`` powers folded together) with the
window's channel samples, then a small SVD: the embedded flow of Figure 15.

Forms
-----
``"per-dof"``
    The model's equations (:meth:`~duffid.models.chain.Chain.equations`), one least-squares
    problem per degree of freedom; an unforced DOF gives ratios ``b2/m2`` and the mass
    follows as for the online methods.
``"matrix"``
    Eqs. (36)-(37): ``M x'' + B x' + K x + Kp y^3 = f`` with every structurally non-zero
    entry of the matrices an unknown (``M[1,1]``, ``B[1,2]``, ``K[2,1]``, ``Kp[1,2]`` ...,
    1-based), the rows of unforced DOFs divided by their mass (``M[i,i] = 1``, its term
    moved to the right-hand side: the paper's ``f_bar = [f, -x2'']``). ``y`` holds the
    element deflections ``y_i = x_i - x_(i-1)``. The physical parameters follow from the
    entries by least squares on their linear relation (e.g. ``b2 = -B[1,2]``,
    ``b1 = B[1,1] + B[1,2]``, ``b2/m2 = B[2,2] = -B[2,1]``).

Accuracy (benchmarks/identification.py)
---------------------------------------
On the paper's noise-free 1-DOF case (one 0.25 s window) Legendre and Chebyshev with 24
terms are within 0.0005 % and 0.0015 %, limited by the cubic interpolation of the
samples; block-pulse and Haar (the same span, so the same estimates) have the
``O(1/r^2)`` error of ``P^2``: 0.85 % at 128 terms, 0.2 % with ``repeated="exact"``. One window of a decayed response is
poorly excited: on long records use ``accumulate=True`` or read the ``identified`` flag.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from math import comb, factorial
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from ..data.record import Record
from ..errors import InputError, RecordError
from ..models.chain import Chain, Channel
from ..models.regression import LinearTerm, Regression
from .engine import Estimate, Identification, check_record, combine_equations, solve_factor, triangular_factor
from .identifier import Identifier
from .options import BUFFERED_METHODS, check_options
from .orthogonal import make_basis, projection_matrix
from .row_noise import NoiseLevel, noise_shift, noise_sigmas

__all__ = [
    "METHODS",
    "DEFAULT_TERMS",
    "regression_from_model",
    "velocity_signs",
    "channel_slopes",
    "CHECK_SHARE",
    "check_rows",
    "solve_groups",
    "BufferedIdentifier",
    "BufferedIdentification",
    "identify_buffered",
]

#: Method names (one per basis).
METHODS = BUFFERED_METHODS
#: Default number of basis functions per method.
DEFAULT_TERMS = {"legendre": 24, "chebyshev": 24, "block-pulse": 128, "haar": 128}

#: A window's estimate is compared with the one from the first this share of its kept
#: coefficient equations (:func:`check_rows`; the lower-order coefficients, or for block-pulse
#: functions the window's first part), and their relative difference enters each relative
#: standard error in quadrature. Where the basis resolves the window's signals both agree to
#: rounding or noise; where it does not (a window holding more periods than its functions
#: follow) the estimate is no value of the plant, and its residual need not show it: a
#: structure (450 kg, 11.1 Hz) swept 0.5-2.5 natural frequencies, noise-free, in windows of 1 s
#: with 24 Legendre functions flagged a window identified with m 78 % and kp 82 % off (at 60 dB
#: m 95 %, kp 104 %; the estimates with 16, 20, 24 and 32 functions: m -83, -133, -33 and
#: -0.4 % in the first window), the first-rows estimate differing by 39-7,400 %.
CHECK_SHARE = 0.75

def check_rows(kept: int) -> int:
    """The coefficient equations per equation of the check of :data:`CHECK_SHARE` (of ``kept``)."""
    return int(CHECK_SHARE * kept)


def _options(method: str, options: Mapping[str, Any]) -> dict[str, Any]:
    """The method's options checked and merged with their defaults (the schema:
    :data:`duffid.identification.options.BUFFERED_OPTIONS`)."""
    if method not in METHODS:
        raise InputError(f"unknown buffered method {method!r}; choose one of {', '.join(METHODS)}")
    return check_options(method, options)


# ---------------------------------------------------------------------- structure
def velocity_signs(x: np.ndarray, deadband: float = 0.0) -> np.ndarray:
    """Sign of velocity from position increments, held while ``|dx| <= deadband``.

    Sample 0 has sign 0; the same rule as the online identifiers.
    """
    x = np.asarray(x, dtype=float)
    out = np.zeros_like(x)
    if len(x) < 2:
        return out
    dx = np.diff(x, axis=0)
    moving = np.abs(dx) > deadband
    idx = np.where(moving, np.arange(1, len(x))[:, None], 0)
    last = np.maximum.accumulate(idx, axis=0)  # sample index of the last move (0: none yet)
    signs = np.vstack([np.zeros((1, x.shape[1])), np.sign(dx)])
    out[1:] = np.where(last > 0, np.take_along_axis(signs, last, axis=0), 0.0)
    return out


def _chain_evaluator(channels: Sequence[Channel]) -> Callable[..., np.ndarray]:
    def evaluate(x: np.ndarray, f: np.ndarray, t: np.ndarray, sgn: np.ndarray) -> np.ndarray:
        cols = [sgn[:, c.index] if c.kind == "sign_velocity" else c.evaluate(x, f) for c in channels]
        return np.stack([np.broadcast_to(c, (len(x),)) for c in cols], axis=1)
    return evaluate


def regression_from_model(model: Chain, form: str = "per-dof") -> Regression:
    """The regression structure of a chain model, in per-DOF or matrix form (eqs. 36-37)."""
    equations = model.equations()
    channels: dict[Channel, None] = {}
    for eq in equations:
        for c in eq.channels:
            channels.setdefault(c, None)
    if form == "matrix":
        return _matrix_regression(model, equations, channels)
    if form != "per-dof":
        raise InputError(f"form must be 'per-dof' or 'matrix', got {form!r}")
    chans = list(channels)
    terms = []
    for eq in equations:
        ts = [LinearTerm(eq.unknowns.index(t.unknown), chans.index(t.channel), t.order, t.sign) for t in eq.lhs]
        ts += [LinearTerm(None, chans.index(t.channel), t.order, t.sign) for t in eq.rhs]
        terms.append(tuple(ts))

    def finish(solutions: list[dict[str, float]]) -> dict[str, float]:
        return model.from_canonical(combine_equations(model, solutions)[0])

    return Regression(model.name, tuple(eq.unknowns for eq in equations), tuple(terms),
                      tuple(c.label for c in chans), _chain_evaluator(chans), finish,
                      tuple(model.parameters), model.n_dof, model.n_forces)


def _matrix_regression(model: Chain, equations, channels) -> Regression:
    """Eqs. (36)-(37): the entries of M, B, K, K_j (on y^j), Fc, c as unknowns, row by row."""
    n = model.n_dof
    letters = {2: "M", 1: "B", 0: "K"}
    chans: list[Channel] = []
    entry_names: list[list[str]] = []
    entry_terms: list[list[LinearTerm]] = []
    relations: list[np.ndarray] = []  # entries = E @ theta, per equation

    def channel(c: Channel) -> int:
        if c not in chans:
            chans.append(c)
        return chans.index(c)

    for i, eq in enumerate(equations):
        names: list[str] = []
        terms: list[LinearTerm] = []
        contrib: dict[str, np.ndarray] = {}

        def add(name: str, ch: Channel, order: int, unknown: int, value: float) -> None:
            if name not in contrib:
                names.append(name)
                terms.append(LinearTerm(len(names) - 1, channel(ch), order, 1.0))
                contrib[name] = np.zeros(len(eq.unknowns))
            contrib[name][unknown] += value

        for t in eq.lhs:
            u = eq.unknowns.index(t.unknown)
            c = t.channel
            if c.kind == "x" or (c.kind == "deflection" and c.power == 1):
                j = c.index
                add(f"{letters[t.order]}[{i + 1},{j + 1}]", Channel("x", j), t.order, u, t.sign)
                if c.kind == "deflection" and j > 0:
                    add(f"{letters[t.order]}[{i + 1},{j}]", Channel("x", j - 1), t.order, u, -t.sign)
            elif c.kind == "deflection":
                label = "Kp" if c.power == 3 else f"K{c.power}"
                add(f"{label}[{i + 1},{c.index + 1}]", c, t.order, u, t.sign)
            elif c.kind == "sign_velocity":
                add(f"Fc[{i + 1},{c.index + 1}]", c, t.order, u, t.sign)
            else:
                add(f"c[{i + 1}]", c, t.order, u, t.sign)
        terms += [LinearTerm(None, channel(t.channel), t.order, t.sign) for t in eq.rhs]
        entry_names.append(names)
        entry_terms.append(terms)
        relations.append(np.array([contrib[k] for k in names]))

    def physical(entries: list[dict[str, float]]) -> list[dict[str, float]]:
        out = []
        for eq, names, E, sol in zip(equations, entry_names, relations, entries):
            values = np.array([sol[k] for k in names])
            if not np.all(np.isfinite(values)):
                out.append({k: np.nan for k in eq.unknowns})
                continue
            theta = np.linalg.lstsq(E, values, rcond=None)[0]
            out.append(dict(zip(eq.unknowns, theta)))
        return out

    def finish(entries: list[dict[str, float]]) -> dict[str, float]:
        return model.from_canonical(combine_equations(model, physical(entries))[0])

    def matrices(entries: list[dict[str, float]]) -> dict[str, np.ndarray]:
        out: dict[str, np.ndarray] = {"M": np.zeros((n, n))}
        for i in range(n):
            if i not in model.forced:
                out["M"][i, i] = 1.0
        for sol in entries:
            for key, value in sol.items():
                label, _, rest = key.partition("[")
                idx = [int(v) - 1 for v in rest.rstrip("]").split(",")]
                if label == "c":
                    out.setdefault("c", np.zeros(n))[idx[0]] = value
                else:
                    out.setdefault(label, np.zeros((n, n)))[idx[0], idx[1]] = value
        return out

    return Regression(model.name, tuple(tuple(n_) for n_ in entry_names), tuple(tuple(t) for t in entry_terms),
                      tuple(c.label for c in chans), _chain_evaluator(chans), finish,
                      tuple(model.parameters), model.n_dof, model.n_forces, matrices=matrices)


# ---------------------------------------------------------------------- kernels
def _window_kernels(method: str, n_terms: int, n_intervals: int, quadrature: str, order: int,
                    repeated: str = "power") -> tuple[np.ndarray, np.ndarray]:
    """Matrices ``W[d]`` (r' x (N+1)): window samples of a channel -> row entries of order d.

    Row ``j`` of ``W[d] @ g`` is the coefficient of ``phi_j`` in ``int^(n) tau^n g^(d)``
    (integrated by parts), in units of ``T^(2n-d)``. With ``repeated="power"`` the
    coefficients that the truncated ``P^m`` corrupts are left out: ``kept`` lists the others.
    """
    basis = make_basis(method, n_terms)
    Q = projection_matrix(basis, n_intervals, quadrature)
    n = order
    exact = repeated == "exact"
    powers = [basis.integration_matrix(m, exact) for m in range(n + 1)]
    s = np.arange(n_intervals + 1) / n_intervals
    kept = np.arange(n_terms) if exact else np.setdiff1d(np.arange(n_terms), basis.corrupted(n))
    W = np.zeros((n + 1, len(kept), n_intervals + 1))
    for d in range(n + 1):
        for k in range(d + 1):
            alpha = (-1) ** k * comb(d, k) * factorial(n) / factorial(n - k)
            W[d] += alpha * (powers[n - d + k].T @ (Q * s ** (n - k)))[kept]
    return W, kept


def channel_slopes(regression: Regression, x: np.ndarray, f: np.ndarray, t: np.ndarray,
                   signs: np.ndarray) -> np.ndarray:
    """Each channel's derivative by each measured signal, sample by sample (samples x
    (displacements, then forces) x channels): central differences over ``1e-4`` of the value."""
    measured = np.column_stack([np.asarray(x, dtype=float), np.asarray(f, dtype=float)])
    n_dof = regression.n_dof
    out = np.empty((len(measured), measured.shape[1], len(regression.channel_labels)))
    step = 1e-4 * np.maximum(np.abs(measured), np.finfo(float).tiny)
    for j in range(measured.shape[1]):
        up, down = measured.copy(), measured.copy()
        up[:, j] += step[:, j]
        down[:, j] -= step[:, j]
        width = (up[:, j] - down[:, j])[:, None]
        out[:, j] = (regression.evaluate(up[:, :n_dof], up[:, n_dof:], t, signs)
                     - regression.evaluate(down[:, :n_dof], down[:, n_dof:], t, signs)) / width
    return out


# ---------------------------------------------------------------------- identifier
class BufferedIdentifier(Identifier):
    """Buffered identifier (Figure 15): re-identify every ``every`` samples over the last window.

    Parameters
    ----------
    model : Chain or Regression
        Model structure (or a regression structure, e.g. from :mod:`duffid.models.equation`).
    dt : float
        Sampling period [s].
    method : {"legendre", "chebyshev", "block-pulse", "haar"}
        Orthogonal basis.
    **options
        The buffered methods' options (:data:`duffid.identification.options.BUFFERED_OPTIONS`:
        names, defaults, ranges and meanings in one place): ``window`` [s], ``n_terms`` (basis
        functions, at most the window's samples; Haar: a power of two), ``every``,
        ``quadrature``, ``form`` (``"matrix"``: chain models only), ``repeated`` (``"exact"``:
        4-5 times smaller errors for block-pulse and Haar), ``accumulate`` (False: each window
        alone, as the paper), ``max_condition``, ``max_uncertainty``, ``deadband`` [m].

    Notes
    -----
    Every re-identification publishes its estimate (Figure 15). It is flagged identified
    when the scaled problem's condition number is at most ``max_condition`` and the
    relative standard error of every unknown is at most ``max_uncertainty``: the larger of
    the coefficient equations' residual's and the measured noise's of the displacements and
    the forces (propagated through the window's kernels, :meth:`noise_products`), with the basis
    check's difference (:data:`CHECK_SHARE`) in quadrature. A window of a decayed response
    is poorly excited: its estimate is published but not flagged; ``accumulate=True`` keeps
    the information of the earlier windows.
    """

    def __init__(self, model: Chain | Regression, dt: float, method: str = "legendre", **options: Any) -> None:
        super().__init__(model, dt, method, _options(method, options))
        o = self.options
        if isinstance(model, Regression):
            if o["form"] != "per-dof":
                raise InputError("option form='matrix' needs a chain model, not a regression structure")
            self.regression = model
        else:
            self.regression = regression_from_model(model, o["form"])
        N = int(round(o["window"] / self.dt))
        if N < 3:
            raise InputError(f"window {o['window']} s holds {N} sample intervals of {self.dt} s; at least 3 are needed")
        if o["n_terms"] is None:  # the default, capped by the window (Haar: a power of two)
            r = min(DEFAULT_TERMS[method], N)
            o["n_terms"] = r = 2 ** int(np.log2(r)) if method == "haar" else r
        r = o["n_terms"]
        if r > N:
            raise InputError(f"n_terms {r} exceeds the {N} sample intervals of the window: "
                             "use fewer basis functions or a longer window")
        self.n_intervals = N
        self.every = int(o["every"] or N)
        make_basis(method, r)  # validate (Haar: power of two)
        self._W, self.kept = _window_kernels(method, r, N, o["quadrature"], self.regression.max_order,
                                             o["repeated"])
        if len(self.kept) < max(len(u) for u in self.regression.unknowns):
            raise InputError(f"{len(self.kept)} usable coefficients cannot determine "
                             f"{max(len(u) for u in self.regression.unknowns)} unknowns: raise n_terms")
        self._maps = self.regression.assembly()
        self._groups = solve_groups(self.regression)
        n_ch = len(self.regression.channel_labels)
        self._buffer = np.zeros((N + 1, n_ch))
        self._slope_buffer = np.zeros((N + 1, self.regression.n_dof + self.regression.n_forces, n_ch))
        # accumulate: a sample's noise enters this many windows (their noise products are summed
        # as if independent, times this: a bound by Cauchy-Schwarz; windows that share only an
        # end sample, as back-to-back ones, count as independent)
        self._shared_windows = -(-N // self.every)
        self.reset()

    @property
    def kernels(self) -> np.ndarray:
        """The window's kernels ``W[d]`` (orders x kept coefficients x samples), read-only:
        ``W[d] @ G`` gives the row entries of order ``d`` (before the ``T^-d`` scale)."""
        view = self._W.view()
        view.flags.writeable = False
        return view

    @property
    def window(self) -> float:
        """Window length [s]."""
        return round(self.n_intervals * self.dt, 12)

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """Public parameter names, in output order."""
        return self.regression.parameter_names

    def reset(self) -> None:
        """Forget all samples."""
        self.n = -1
        self._last_x: np.ndarray | None = None
        self._sign = np.zeros(self.regression.n_dof)
        self._buffer[:] = 0.0
        self._factors: list[np.ndarray | None] = [None] * len(self._groups)
        self._checks: list[np.ndarray | None] = [None] * len(self._groups)  # CHECK_SHARE's
        self._rows = [0.0] * len(self._groups)
        # accumulate: the rows' noise (row_noise), accumulated as the rows
        self._noise_level = NoiseLevel(self.regression.n_dof)
        self._noise_buffer = np.zeros_like(self._buffer)
        self._noise: list[tuple[np.ndarray, np.ndarray] | None] = [None] * len(self._groups)
        self._slope_buffer[:] = 0.0
        self._force_level = NoiseLevel(self.regression.n_forces)  # the force sensors' noise
        self._products: list[np.ndarray | None] = [None] * len(self._groups)  # accumulated noise products
        self._estimate = {k: np.nan for k in self.parameter_names}
        self._cond = np.inf
        self._rse = np.nan
        self._solutions: list[dict[str, float]] | None = None
        self.windows = 0

    # -------------------------------------------------------------- core
    def entries(self, G: np.ndarray) -> np.ndarray:
        """Row entries ``E[row, order, channel]`` of one window of channel samples ``G`` (N+1, channels)."""
        V = self._W @ G  # (orders, rows, channels)
        T = self.window
        V = V * (T ** -np.arange(self._W.shape[0], dtype=float))[:, None, None]
        return np.transpose(V, (1, 0, 2))

    def systems(self, G: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        """``(A, D)`` of every equation for one window (``A theta = D``, eq. 44 transposed)."""
        E = self.entries(G)
        flat = E.reshape(E.shape[0], -1)
        return [(flat @ lhs, flat @ rhs) for lhs, rhs in self._maps]

    def block_systems(self, G: np.ndarray, dG: np.ndarray | None = None
                      ) -> list[tuple[list[int], list[str], np.ndarray, np.ndarray]]:
        """``(equations, unknown names, A, D)`` of each least-squares problem of one window
        (the equations that share unknowns stacked, each scaled to unit norm); with the
        channels' noise ``dG`` also its rows ``dA, dD`` (scaled as the rows)."""
        return self._blocks(self.systems(G), None if dG is None else self.systems(dG))

    def _blocks(self, systems, noise) -> list[tuple[list[int], list[str], np.ndarray, np.ndarray]]:
        """:meth:`block_systems` of the equations' ``systems`` (and their ``noise``)."""
        return [(eqs, names, *_stack(systems, eqs, names, self.regression.unknowns, noise))
                for eqs, names in self._groups]

    def _check_factors(self, systems) -> list[np.ndarray]:
        """Each least-squares problem's factor of the first :func:`check_rows` coefficient
        equations of each of its equations' ``systems`` (:data:`CHECK_SHARE`)."""
        rows = check_rows(len(self.kept))
        first = [(A[:rows], D[:rows]) for A, D in systems]
        return [triangular_factor(np.column_stack(_stack(first, eqs, names, self.regression.unknowns)),
                                  len(names) + 1) for eqs, names in self._groups]

    def solve_window(self, G: np.ndarray, dG: np.ndarray | None = None, slopes: np.ndarray | None = None,
                     sigma: np.ndarray | None = None) -> Estimate:
        """Identify from one window of channel samples ``G`` and update the estimate.

        With the channels' ``slopes`` (:func:`channel_slopes` of the window's samples) and the
        measured signals' noise levels ``sigma`` (:class:`NoiseLevel` of the displacements, then
        of the forces, at the window's last sample), each unknown's standard error is at least
        the one that noise gives (:meth:`noise_products`). The residual of the coefficient
        equations does not show it: the noise reaches them through the same operational
        matrices and is correlated along the unknowns' own directions. The structure (450 kg,
        11.1 Hz) swept 0.5-2.5 natural frequencies at 60 dB in 0.25 s windows: kp spread
        3.4-9.2 % over 30 draws, its residual's error said 0.6-2.9 %, the noise's 3.4-9.1 %;
        windows flagged identified at the default 5 % were up to 36 % off; with the force's
        noise at 30-40 dB, up to 43 % off.

        With ``accumulate``, ``dG`` is the window's channels' change under a noise of the
        displacements' measured level (:mod:`~duffid.identification.row_noise`): the rows'
        noise is accumulated as the rows, and the noise-corrected solution's shift enters
        each unknown's relative standard error (where the noise dominates the rows, the
        estimate is not flagged). A settled step accumulated 48 windows of 0.25 s of one
        displacement, whose ``k x`` and ``kp x^3`` differ only by its noise: kp was flagged
        identified 14-17 % off."""
        solutions: list[dict[str, float]] = [dict() for _ in self.regression.unknowns]
        cond, worst = 0.0, 0.0
        accumulate = self.options["accumulate"]
        systems = self.systems(G)  # once for the solve and its check
        checks = self._check_factors(systems)
        noises = self.systems(dG) if accumulate and dG is not None else None
        noisy = slopes is not None and sigma is not None and bool(np.any(np.asarray(sigma) > 0))
        for g, (eqs, names, A, D, *noise) in enumerate(self._blocks(systems, noises)):
            R = triangular_factor(np.column_stack([A, D]), len(names) + 1)
            check = checks[g]
            rows = float(len(A))
            if accumulate and self._factors[g] is not None:
                R = triangular_factor(np.vstack([self._factors[g], R]), len(names) + 1)
                check = triangular_factor(np.vstack([self._checks[g], check]), len(names) + 1)
                rows += self._rows[g]
            self._factors[g], self._checks[g], self._rows[g] = R, check, rows
            theta, c, rse = solve_factor(R, rows, 1.0)[:3]
            # ... and the first rows' estimate (CHECK_SHARE): a basis that does not resolve the
            # window's signals gives estimates that move with the equations taken
            first = solve_factor(check, rows, 1.0)[0]
            with np.errstate(divide="ignore", invalid="ignore"):
                moved = np.abs((first - theta) / theta)
            if noisy and np.all(np.isfinite(theta)):
                products = self.noise_products(systems, eqs, names, A, theta, slopes, sigma)
                if accumulate:
                    if self._products[g] is not None:
                        products = products + self._products[g]
                    self._products[g] = products
                    products = products * self._shared_windows
                rse = np.maximum(rse, _noise_errors(R, products, theta))
            rse = np.hypot(rse, np.where(np.isfinite(moved), moved, np.inf))
            if noise:
                dA, dD = noise
                gram, cross = dA.T @ dA, dA.T @ dD
                if self._noise[g] is not None:
                    gram, cross = gram + self._noise[g][0], cross + self._noise[g][1]
                self._noise[g] = (gram, cross)
                shift = noise_shift(R, gram, cross)
                with np.errstate(divide="ignore", invalid="ignore"):
                    rse = np.where(shift != 0, np.hypot(rse, np.abs(shift / theta)), rse)
            if not np.any(R[:, -1]):
                # no force (or other known term) in the rows, e.g. a ring-down: the scale is free
                # (the least-squares solution would be 0); the last determined values are held
                for i in eqs:
                    solutions[i] = dict(self._solutions[i]) if self._solutions is not None else \
                        {k: np.nan for k in self.regression.unknowns[i]}
                cond, worst = np.inf, np.inf
                continue
            cond = max(cond, c)
            worst = max(worst, float(np.max(rse)) if len(rse) else 0.0)
            values = dict(zip(names, theta))
            for i in eqs:
                solutions[i] = {k: values[k] for k in self.regression.unknowns[i]}
        self._solutions = solutions
        self._estimate = self.regression.finish(solutions)
        self._cond, self._rse = cond, worst
        self.windows += 1
        return self._current()

    def noise_products(self, systems, eqs: list[int], names: list[str], A: np.ndarray, theta: np.ndarray,
                       slopes: np.ndarray, sigma: np.ndarray) -> np.ndarray:
        """``S = sum_j sigma_j^2 (A^T M_j)(A^T M_j)^T`` of one least-squares problem.

        A noise ``e`` on measured signal ``j`` (a displacement or a force) moves the
        coefficient equations' residual
        ``A theta - D`` by ``M_j e`` (linearised at ``theta``):
        ``M_j = sum_d T^-d W[d] diag(J_d)``, ``J_d = sum_c w[d, c] dG_c/dj`` with
        ``w = lhs theta - rhs`` the equation's weight of each (order, channel). White noise of
        level ``sigma_j`` moves the unknowns with covariance ``G^-1 S G^-1``, ``G = A^T A``.
        """
        reg = self.regression
        n_ord, n_ch = self._W.shape[0], len(reg.channel_labels)
        kernels = self._W * (self.window ** -np.arange(n_ord, dtype=float))[:, None, None]
        S = np.zeros((len(names), len(names)))
        for j in range(slopes.shape[1]):
            if not sigma[j] > 0:
                continue
            blocks = []
            for i in eqs:
                lhs, rhs = self._maps[i]
                weights = lhs @ theta[[names.index(u) for u in reg.unknowns[i]]] - rhs
                M = np.einsum("drs,sd->rs", kernels, slopes[:, j] @ weights.reshape(n_ord, n_ch).T)
                blocks.append(M / _row_scale(systems[i]) if len(eqs) > 1 else M)
            q = A.T @ np.vstack(blocks)
            S += sigma[j] ** 2 * (q @ q.T)
        return S

    def _current(self) -> Estimate:
        o = self.options
        ok = bool(self._cond <= o["max_condition"] and self._rse <= o["max_uncertainty"]
                  and all(np.isfinite(v) for v in self._estimate.values()))
        return Estimate(self.n * self.dt, dict(self._estimate), ok, self._cond, self._rse,
                        self.window if self.windows else 0.0)

    def _channel_noise(self, x: np.ndarray, f: np.ndarray, t: np.ndarray, signs: np.ndarray,
                       G: np.ndarray) -> np.ndarray:
        """The channels' change (samples x channels) when each sample's displacements take a
        pseudo-random noise of their measured level (:class:`NoiseLevel`, sample by sample)."""
        noisy = np.empty_like(x, dtype=float)
        for k in range(len(x)):
            self._noise_level.push(x[k])
            noisy[k] = self._noise_level.perturbed(x[k])
        return self.regression.evaluate(noisy, f, t, signs) - G

    def matrices(self) -> dict[str, np.ndarray] | None:
        """The identified matrices of eq. (36) (form="matrix"), else None."""
        if self.regression.matrices is None or self._solutions is None:
            return None
        return self.regression.matrices(self._solutions)

    def _due(self) -> bool:
        N = self.n_intervals
        return self.n >= N and (self.n - N) % self.every == 0

    # -------------------------------------------------------------- online
    def update(self, x: float | np.ndarray, f: float | np.ndarray, t: float | None = None) -> Estimate:
        """Consume one sample (displacements, forces, optional time) and return the estimate.

        The estimate changes only when a re-identification is due; NaN before the
        first full window. ``t`` (default ``n * dt``) only matters for equations that use
        the time signal.
        """
        reg = self.regression
        x, f = self.checked_sample(x, f)
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(f))):
            raise InputError(f"{reg.name}: sample {self.n + 1} is not finite (x={x}, f={f})")
        self.n += 1
        if self._last_x is not None:
            dx = x - self._last_x
            self._sign = np.where(np.abs(dx) > self.options["deadband"], np.sign(dx), self._sign)
        self._last_x = x.copy()
        time = self.n * self.dt if t is None else float(t)
        size = self.n_intervals + 1
        sample = (x[None, :], f[None, :], np.array([time]), self._sign[None, :])
        g = reg.evaluate(*sample)[0]
        self._buffer[self.n % size] = g
        self._slope_buffer[self.n % size] = channel_slopes(reg, *sample)[0]
        self._noise_level.push(x)
        self._force_level.push(f)
        if self.options["accumulate"]:
            noisy = self._noise_level.perturbed(x)
            self._noise_buffer[self.n % size] = reg.evaluate(noisy[None, :], *sample[1:])[0] - g
        if self._due():  # the ring buffer, oldest sample first
            order = np.arange(self.n + 1, self.n + 1 + size) % size
            return self.solve_window(self._buffer[order], self._noise_buffer[order], self._slope_buffer[order],
                                     np.concatenate([self._noise_level.sigma(), self._force_level.sigma()]))
        return self._current()

    def identify_record(self, record: Record) -> "BufferedIdentification":
        """Identify over a whole record (vectorised; the same estimates as :meth:`update`)."""
        reg = self.regression
        check_record(record, reg)
        if abs(record.dt - self.dt) > 1e-9 * self.dt:
            raise RecordError(f"{record.source}: sampled every {record.dt} s, the identifier expects {self.dt} s")
        N = self.n_intervals
        if record.n_samples < N + 1:
            raise RecordError(f"{record.source}: {record.n_samples} samples ({record.duration:g} s) are fewer than "
                              f"one window of {N + 1} samples ({self.window:g} s); shorten the window")
        self.reset()
        signs = velocity_signs(record.x, self.options["deadband"])
        G = reg.evaluate(record.x, record.f, record.t, signs)
        dG = self._channel_noise(record.x, record.f, record.t, signs, G) if self.options["accumulate"] else None
        slopes = channel_slopes(reg, record.x, record.f, record.t, signs)
        sigmas = np.column_stack([noise_sigmas(record.x), noise_sigmas(record.f)])
        names = self.parameter_names
        n = record.n_samples
        history = {k: np.full(n, np.nan) for k in names}
        condition = np.full(n, np.inf)
        flags = np.zeros(n, dtype=bool)
        ends = np.arange(N, n, self.every)
        t_windows, conds, stated = [], [], []
        for i, end in enumerate(ends):
            self.n = int(end)
            est = self.solve_window(G[end - N: end + 1], None if dG is None else dG[end - N: end + 1],
                                    slopes[end - N: end + 1], sigmas[end])
            stop = ends[i + 1] if i + 1 < len(ends) else n
            for k in names:
                history[k][end:stop] = est.parameters[k]
            condition[end:stop] = est.condition
            flags[end:stop] = est.identified
            t_windows.append(float(record.t[end] - record.t[0]))
            conds.append(est.condition)
            stated.append(est.uncertainty)
        self.n = n - 1
        final = {k: float(history[k][-1]) for k in names}
        options = dict(self.options)
        options["every"] = self.every
        return BufferedIdentification(
            model=reg.name, method=self.method, parameters=final, t=record.t - record.t[0],
            history=history, condition=condition, identified=flags,
            t_identified=float(record.t[np.argmax(flags)] - record.t[0]) if flags.any() else None,
            window=self.window, options=options, source=record.source,
            t_windows=np.array(t_windows), window_condition=np.array(conds), window_uncertainty=np.array(stated),
            used_terms=len(self.kept), matrices=self.matrices())


def solve_groups(reg: Regression) -> list[tuple[list[int], list[str]]]:
    """(equations, unknown names) of each least-squares problem: the equations sharing unknown
    names (a joint regression) together, else one problem per equation."""
    if not reg.joint:
        return [([i], list(u)) for i, u in enumerate(reg.unknowns)]
    parent = list(range(len(reg.unknowns)))

    def root(i: int) -> int:
        while parent[i] != i:
            i = parent[i]
        return i

    owner: dict[str, int] = {}
    for i, names in enumerate(reg.unknowns):
        for k in names:
            if k in owner:
                parent[root(i)] = root(owner[k])
            else:
                owner[k] = i
    groups: dict[int, list[int]] = {}
    for i in range(len(reg.unknowns)):
        groups.setdefault(root(i), []).append(i)
    out = []
    for eqs in groups.values():
        names: list[str] = []
        for i in eqs:
            names += [k for k in reg.unknowns[i] if k not in names]
        out.append((eqs, names))
    return out


def _row_scale(system: tuple[np.ndarray, np.ndarray]) -> float:
    """The norm of one equation's ``[A D]`` (1 if 0): its rows' scale in a joint problem."""
    scale = float(np.linalg.norm(np.column_stack(system)))
    return scale if scale > 0 else 1.0


def _noise_errors(R_aug: np.ndarray, products: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Relative standard errors ``sqrt(diag(G^-1 S G^-1)) / |theta|`` of the noise products ``S``
    (:meth:`BufferedIdentifier.noise_products`), ``G = R^T R`` from the factor of ``[A D]``."""
    n = len(theta)
    try:
        Rinv = np.linalg.inv(R_aug[:n, :n])
    except np.linalg.LinAlgError:
        return np.full(n, np.inf)
    K = Rinv @ Rinv.T
    std = np.sqrt(np.maximum(np.diag(K @ products @ K), 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(theta != 0, std / np.abs(theta), np.inf)


def _stack(systems, eqs: list[int], names: list[str], unknowns, noise=None) -> tuple[np.ndarray, ...]:
    """Rows of the equations ``eqs`` over the unknowns ``names``; blocks scaled to unit norm
    (with ``noise``, the rows' noise of the same equations after them, scaled alike)."""
    if len(eqs) == 1:
        return systems[eqs[0]] + (() if noise is None else noise[eqs[0]])
    As, Ds, dAs, dDs = [], [], [], []
    for i in eqs:
        A, D = systems[i]
        columns = [names.index(k) for k in unknowns[i]]
        full = np.zeros((len(A), len(names)))
        full[:, columns] = A
        scale = _row_scale(systems[i])
        As.append(full / scale)
        Ds.append(D / scale)
        if noise is not None:
            dA = np.zeros((len(A), len(names)))
            dA[:, columns] = noise[i][0]
            dAs.append(dA / scale)
            dDs.append(noise[i][1] / scale)
    stacked = (np.vstack(As), np.concatenate(Ds))
    return stacked if noise is None else stacked + (np.vstack(dAs), np.concatenate(dDs))


# ---------------------------------------------------------------------- result
@dataclass
class BufferedIdentification(Identification):
    """:class:`~duffid.identification.engine.Identification` of a buffered method.

    Extra attributes
    ----------------
    t_windows : ndarray
        Times of the re-identifications (end of each window) [s].
    window_condition : ndarray
        Condition number of the scaled problem at each re-identification.
    window_uncertainty : ndarray
        The largest relative standard error of each re-identification (the residual's or the
        measured signals' noise's, with the basis check's difference).
    used_terms : int
        Coefficient equations per DOF and window (``n_terms`` minus the corrupted ones).
    matrices : dict or None
        ``M, B, K, Kp`` ... of eq. (36) for ``form="matrix"``.
    """

    t_windows: np.ndarray = field(default_factory=lambda: np.zeros(0))
    window_condition: np.ndarray = field(default_factory=lambda: np.zeros(0))
    window_uncertainty: np.ndarray = field(default_factory=lambda: np.zeros(0))
    used_terms: int = 0
    matrices: dict[str, np.ndarray] | None = None

    def to_dict(self) -> dict[str, Any]:
        """As :meth:`Identification.to_dict`, plus ``matrices`` for the matrix form."""
        out = super().to_dict()
        if self.matrices is not None:
            out["matrices"] = {k: [_clean(v) for v in m.ravel()] if m.ndim == 1 else
                               [[_clean(v) for v in row] for row in m] for k, m in self.matrices.items()}
        return out

    def to_json(self) -> str:
        """:meth:`to_dict` as a JSON string."""
        return json.dumps(self.to_dict())


def _clean(value: float) -> float | None:
    return float(value) if np.isfinite(value) else None


def identify_buffered(record: Record, model: Chain | Regression, method: str = "legendre",
                      **options: Any) -> BufferedIdentification:
    """Buffered identification of ``model`` from ``record`` with an orthogonal basis.

    Parameters
    ----------
    record : Record
        Forces and displacements, evenly sampled.
    model : Chain or Regression
        Model structure.
    method : {"legendre", "chebyshev", "block-pulse", "haar"}
        Basis.
    **options
        See :class:`BufferedIdentifier`.

    Returns
    -------
    BufferedIdentification
    """
    record.require_displacement("the buffered methods")
    if isinstance(model, Chain):
        check_record(record, model)
    return BufferedIdentifier(model, record.dt, method, **options).identify_record(record)
