"""Online algebraic identification (paper sections 2-3) and its robust variant.

Two methods share the integrated-by-parts regressors of :mod:`duffid.identification.regressors`:

``"robust"`` (default)
    Rows ``sigma^a (T - sigma)^b`` with ``a >= 2`` (no raw measurement term), a window
    that grows from the first sample and then slides, Gregory quadrature, rows
    normalised to force units, unknowns equilibrated, all rows of all past windows
    accumulated in a QR-updated least-squares problem (optionally with exponential
    forgetting), a conditioning figure per step and an ``identified`` flag. Until the
    problem is well conditioned the estimate is NaN.
``"paper"``
    Eqs. (16)-(19) as printed (with NOTES.md's corrections of eq. 12): fixed ``t0`` at the
    first sample, rows ``I^0 .. I^(p-1)`` from cascaded integrators, raw Cramer
    determinants and the filtered ratio with gain ``gamma``. Known weaknesses: every
    zero crossing of the determinant flips the sign of the estimate (``sign_in_numerator``
    applies NOTES.md's fix), determinants are tiny and the fixed ``t0`` loses float64
    accuracy on long records.

Both work per degree of freedom; an unforced DOF yields its parameters divided by its
mass, and the mass follows from a stiffness identified on an absolute scale in a
neighbouring equation (``m2 = k2 / (k2/m2)`` for the 2-DOF chain of the paper).
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field, replace
from typing import Any, Mapping

import numpy as np

from ..data.record import Record
from ..errors import InputError, RecordError
from ..models.chain import Chain, Channel, Equation
from .identifier import Identifier
from .options import ONLINE_METHODS, check_online_options
from .orthogonal import BASES
from .regressors import KernelBank, SlidingMoments, row_exponents
from .row_noise import NoiseLevel, noise_shift

__all__ = ["OnlineIdentifier", "check_record", "Identification", "Estimate", "METHODS",
           "STATUSES", "CHANGE_WINDOWS", "CHANGE_SURPRISE", "CHANGE_ALONE_SHARE", "MAX_LINE_UNKNOWNS", "DRIFT_SIGMAS", "DRIFT_BIAS_SIGMAS", "WINDOW_EQUATIONS", "WINDOW_INFLATION", "BATCH_WINDOWS", "accumulated_rows", "OFFSET_SIGMAS", "FORCE_VARIATION", "DriftLine", "MIN_SHARE", "LOSS_FACTOR", "GROWTH_STEADY", "OUTLIER_SIGMAS", "OUTLIER_RANGE", "JUMP_FACTOR", "JUMP_RANGE", "JUMP_ISOLATION", "JUMP_ERROR", "MIN_WINDOW_PERIODS", "MIN_UNCHECKED_SAMPLES", "status_codes", "prior_sizes", "filtered_cramer", "combine_equations",
           "auto_window", "Integrators", "solve_factor", "recent_solution", "triangular_factor", "equilibrated_condition"]

#: The online methods (OnlineIdentifier, :data:`duffid.identification.options.ONLINE_METHODS`)
#: and the buffered orthogonal-function methods of section 4 (duffid.identification.buffered);
#: identify() accepts all of them.
METHODS = ONLINE_METHODS + BASES

#: Status of a parameter; its index is the status code of the C core (DUFFID_STATUS_*) and of
#: the estimator FMUs' ``<name>_status`` outputs. ``uncertain``: not (yet) determined well
#: enough, or a sensor offset the record cannot rule out would move it (:data:`OFFSET_SIGMAS`);
#: ``published``: its relative standard error stayed within ``max_uncertainty`` for
#: ``settle`` s, the value is shown; ``not excited``: its term carries less than
#: :data:`MIN_SHARE` of the force balance; ``lost``: it was published and has not been
#: trustworthy for ``settle`` s since (its error above :data:`LOSS_FACTOR` times
#: ``max_uncertainty``, or its value non-physical, or the estimate moved from the value by more
#: than that, or an offset would move it: the value is withdrawn); ``changed``: the recent data contradict the value it had
#: (see :data:`CHANGE_WINDOWS`): the value is withdrawn and the parameter is identified again
#: from the samples after the change.
STATUSES = ("uncertain", "published", "not excited", "lost", "changed")


def status_codes() -> str:
    """The status codes of the C core and the estimator FMUs in words: ``"0 uncertain, ..."``."""
    return ", ".join(f"{code} {name}" for code, name in enumerate(STATUSES))


#: A term carrying less than this share of its equation's force balance is "not excited".
MIN_SHARE = 0.01
#: A published parameter is lost once its error stayed above this many times
#: ``max_uncertainty`` for ``settle`` s (a band, so that an error hovering at the limit
#: does not switch the value on and off).
LOSS_FACTOR = 2.0
#: A growing window's estimate is published once it has stayed within half of
#: ``max_uncertainty`` of one value while the window grew by this share of its length.
GROWTH_STEADY = 0.25

#: The accumulated least squares of full windows counts the rows of a window's length of
#: samples as this many independent equations in the degrees of freedom of its residual: its
#: ``n`` unknowns use up ``n / WINDOW_EQUATIONS`` windows of rows (:func:`accumulated_rows`).
#: The rows of overlapping windows share their samples' noise, so the residual of the rows of
#: a few windows understates the noise the unknowns absorbed, and their standard errors with
#: it (by at most :data:`WINDOW_INFLATION`; before the rows span a window they are not credible
#: at all: a held value is not withdrawn for its error then). Chosen on the constant plant of
#: ``benchmarks/tracking.py`` (20 seeds, 6 s each): the root-mean-square ratio of kp's error to
#: its stated error over the published samples of its first two, three and four windows was
#: 2.8, 2.3 and 1.9 when only ``n`` rows were used up, and is 1.5 now, as over the rest of the
#: record (1.4-1.6; 1.4-1.8 before); m's and k's are 0.5-0.8 there (0.8-1.3 before). With 2
#: kp's was 1.0-1.2, but the first published values came 0.1-0.4 s later.
WINDOW_EQUATIONS = 4.0
#: The largest factor by which :data:`WINDOW_EQUATIONS` raises a standard error (the rows of
#: less than ``n / WINDOW_EQUATIONS`` windows would have none to spare). Without it, values
#: published from the growing window were withdrawn as the first full windows came (in 9 of
#: the 20 constant records); with it alone in 5; with it and the hold until the rows span a
#: window (see above) in none.
WINDOW_INFLATION = 2.0

#: The accumulated least squares of full windows also estimates its unknowns' covariance by
#: batch means, ``G^-1 V G^-1`` (``G = A^T A``): ``V`` sums the outer products of the rows'
#: scores ``A^T r`` (``r`` their residuals against the previous sample's solution) over blocks of
#: this many windows' samples, with each pair of neighbouring blocks' cross products (the rows of
#: windows less than a window apart share samples), times ``b / (b - n)`` for ``b`` blocks and
#: ``n`` unknowns (the solution has absorbed some of the residuals). Unlike the residual's
#: variance of :func:`solve_factor`, it follows how each unknown's rows correlate: on a step
#: with a multisine (30 kg, 60 dB, 24 seeds) the root-mean-square ratio of k's error to its
#: stated error over the published samples was 1.79 and kp's 1.58 (7.5 and 6.0 % beyond 3
#: stated errors), b's 0.18; with the batch means 1.03 and 0.96 (1.0 and 0.8 %). Each error is
#: the larger of the two once more blocks than unknowns have closed. The change test keeps the
#: residual's errors: a drifting plant's residuals correlate over the whole record, so the batch
#: means grow with the drift, and the drifts of ``benchmarks/tracking.py`` were flagged 1.5-3 s
#: late (a published value went stale meanwhile).
BATCH_WINDOWS = 1

#: Samples before any solution is identified (and half the shortest record).
MIN_SAMPLES = 8

#: The change test (robust method): beside the least squares over every full window since
#: the start (or the latest change), a second one forgets with the time constant
#: ``change_memory`` (default: this many windows). Once an unknown of an equation differs
#: between the two by more than ``change_threshold`` combined standard errors and by more than
#: a published value may move (:data:`LOSS_FACTOR` times ``max_uncertainty``) for ``settle`` s,
#: the plant has changed: both restart with the first window after the change, the departed
#: parameters that had a value are ``changed`` and the equation's others ``uncertain`` until
#: they are determined again (a restarted estimate, like a growing window's, must also have
#: stayed put for :data:`GROWTH_STEADY` of a window).
CHANGE_WINDOWS = 2.0
#: The change test's accelerator: once a window's prediction error (the ``residual`` of
#: :class:`Estimate`) has been this many times the relative residual of the rows accumulated
#: so far for ``settle`` s, the recent estimate forgets everything before it (and skips the
#: windows that straddle it), so that a sudden change is not blurred by the samples before it.
CHANGE_SURPRISE = 12.0
#: The change test's second rule, for a plant that drifts: the recent estimate follows a
#: drift only with a lag and with a bias of its own (a drift is not a constant plant over its
#: memory either), so it seldom departs by ``change_threshold`` standard errors. A departure of
#: at least this share of ``change_threshold`` standard errors that also exceeds the band a
#: published value may move (:data:`LOSS_FACTOR` times ``max_uncertainty``) and lasts the recent
#: estimate's memory (``change_memory``) is a change too.
CHANGE_DRIFT_SHARE = 0.5
#: The change test's confirmation, a likelihood ratio of one changed unknown against all: either
#: rule counts an unknown only while changing it alone (every other unknown kept at the
#: accumulated values) reduces the accumulated estimate's prediction error on the recent rows
#: by at least this share of what the recent solution reduces it by (see :func:`_alone`). A
#: changed parameter explains the recent rows' misfit on its own; a constant plant whose
#: estimator bias moves with the excitation (a swept sine narrows the band of the recent rows,
#: whose solution then slides along an almost collinear pair such as the mass and the
#: stiffness, fitting their noise) is fitted better only by moving the unknowns jointly.
CHANGE_ALONE_SHARE = 0.5
#: After a change, the unknowns that departed are lines in time (:class:`DriftLine`): a plant
#: that drifts is followed instead of being restarted again and again. This many unknowns at
#: most in an equation's accumulated least squares (its own and the lines' rates; a departed
#: unknown beyond it stays a constant).
MAX_LINE_UNKNOWNS = 16
#: The change test's drift probe: beside the accumulated least squares, a third one fits a line
#: in time to every unknown (as many as :data:`MAX_LINE_UNKNOWNS` allows) over the same rows,
#: one of each sample's rows in turn (fixed work: the rows of neighbouring samples share
#: their window). An unknown whose value is determined (relative standard error at most
#: ``max_uncertainty``) drifts once its rate is more than this many standard errors from zero,
#: its line's end is further from the accumulated value than a published value may move
#: (:data:`LOSS_FACTOR` times ``max_uncertainty``), and it alone explains the lines' gain over
#: constants (:data:`CHANGE_ALONE_SHARE`), for ``settle`` s: the equation restarts with it as a
#: line (:class:`DriftLine`). A drift is a long departure: the rates over the accumulated
#: rows see it sooner than the recent estimate's lag. Measured while choosing it: on the 29
#: constant plants of ``benchmarks/trust.py`` the statistic stayed below 2.2 (once 50, for a
#: single sample, on a swept sine); a drift of 20 % over 6 s crossed 4 after 0.8-1.5 s.
DRIFT_SIGMAS = 4.0
#: Until the drift probe restarts an equation, its unknowns are constants fitted to rows of a
#: plant that may be drifting: a constant lags a drift by the span from the rows' mean time to
#: now. A published value's standard error includes that lag's drift, the probe's rate beyond
#: this many of its standard errors times the span, in quadrature, for an unknown whose rate
#: alone explains the lines' gain (:data:`CHANGE_ALONE_SHARE`; without that, the free decay after
#: a hammer blow, which cannot tell the unknowns' common scale, showed a joint slide of all
#: four and withdrew every value). Measured when it was introduced, before the lines weighed
#: each sample by its own time, on a stiffness drifting by 20 % over 6 s
#: (``benchmarks/tracking.py``, 3 seeds each way): the published samples of k further than 3
#: stated errors from the truth fell from 815-1,906 to 462-1,811 (the rest: before the rates
#: are significant).
DRIFT_BIAS_SIGMAS = 3.0
#: The offset probe (the online twin of ``identify``'s offset check, robust method): beside the
#: accumulated least squares of an equation without a constant term, a fourth one adds an
#: unknown constant force (a force sensor's bias; with a linear spring also a displacement
#: sensor's offset) to the same rows, one of each sample's rows in turn. The constant moves
#: each unknown by ``-R11^-1 R12 c`` (the factor ``[[R11, R12], [0, r]]`` of ``[A, 1]``); a value
#: is not published (and a published one is lost after ``settle`` s) while the constant is more
#: than this many standard errors from zero and moves it by more than ``max_uncertainty``: the
#: record cannot rule out a sensor offset that makes the value wrong. Only while the rows' force
#: balance varies (:data:`FORCE_VARIATION`): a force that is constant over the rows (a step
#: from the first sample) cannot tell a sensor's bias from the force, and the values then
#: assume there is none, as ``identify`` does. Measured while choosing
#: it: on the 26 records of ``benchmarks/trust.py`` without an offset the statistic stayed
#: below 3.3 after the first tenth of each record where a value could move (12.7 on a swept sine
#: at 500 Hz whose discretization bias the constant absorbs; nothing is published there), and
#: no publication changed; with a force offset of 5 % or a displacement offset of 3 % of the
#: peak it reached 7-519, and a step whose displacement offset made k 6.5 % wrong is no longer
#: published. The same factor as ``identify``'s offset check (3 standard errors).
OFFSET_SIGMAS = 3.0
#: A force whose standard deviation is below this fraction of its mean magnitude "hardly varies"
#: (it cannot separate a constant offset from the stiffness): ``identify``'s offset check over
#: the record's samples, the offset probe over its rows' right-hand sides.
FORCE_VARIATION = 0.05


# ---------------------------------------------------------------------- channels
class _Channels:
    """Evaluates the distinct channels of all equations: sgn(velocity) from position
    increments, and a model's own expression channels (an equation model's channel
    function of x, f, t and the signs of velocity) at the sample's time."""

    def __init__(self, channels: tuple[Channel, ...], deadband: float, dt: float,
                 expressions: Any = None) -> None:
        self.channels = channels
        self.deadband = float(deadband)
        self.dt = dt
        self.expressions = expressions
        n_x = max([c.index + 1 for c in channels if c.kind in ("x", "deflection", "sign_velocity")] + [0])
        if expressions is not None:
            n_x = max(n_x, expressions.n_dof)
        self._signed = expressions is not None or any(c.kind == "sign_velocity" for c in channels)
        self._n_x = n_x
        self.reset()

    def reset(self) -> None:
        self._last_x: np.ndarray | None = None
        self._sign = np.zeros(self._n_x)
        self._n = -1

    def evaluate(self, x: np.ndarray, f: np.ndarray) -> np.ndarray:
        self._n += 1
        if self._signed:
            if self._last_x is not None:
                dx = x - self._last_x
                moving = np.abs(dx) > self.deadband
                self._sign = np.where(moving, np.sign(dx), self._sign)
            self._last_x = x.copy()
        return self.at(x, f)

    def at(self, x: np.ndarray, f: np.ndarray) -> np.ndarray:
        """The channels of ``x, f`` at the latest sample's time and signs of velocity (no
        step: the rows' noise evaluates them at a perturbed displacement)."""
        values = None if self.expressions is None else self.expressions.channel_values(x, f, self._n * self.dt,
                                                                                        self._sign)
        out = np.empty(len(self.channels))
        for i, c in enumerate(self.channels):
            if c.kind == "sign_velocity":
                out[i] = self._sign[c.index]
            elif c.kind == "expression":
                out[i] = values[c.index]
            else:
                out[i] = c.evaluate(x, f)
        return out


class _Assembly:
    """Maps kernel entries ``E[row, order, channel]`` to ``A`` (rows x unknowns) and ``D``;
    the equations of a joint block (:attr:`Equation.parts` > 1) each give their rows."""

    def __init__(self, equation: Equation, channels: tuple[Channel, ...], max_order: int) -> None:
        n_ch = len(channels)
        self.unknowns = equation.unknowns
        parts = equation.parts
        self.lhs = np.zeros((parts, (max_order + 1) * n_ch, len(equation.unknowns)))
        self.rhs = np.zeros((parts, (max_order + 1) * n_ch))
        for term in equation.lhs:
            self.lhs[term.part, term.order * n_ch + channels.index(term.channel),
                     equation.unknowns.index(term.unknown)] += term.sign
        for term in equation.rhs:
            self.rhs[term.part, term.order * n_ch + channels.index(term.channel)] += term.sign

    def __call__(self, E: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        flat = E.reshape(E.shape[:-2] + (-1,))
        if len(self.lhs) == 1:
            return flat @ self.lhs[0], flat @ self.rhs[0]
        return (np.concatenate([flat @ lhs for lhs in self.lhs], axis=-2),
                np.concatenate([flat @ rhs for rhs in self.rhs], axis=-1))


class _JumpMoments:
    """The power moments of the force jumps inside the window (:data:`JUMP_ERROR`): a jump
    ``df`` between samples ``k - 1`` and ``k`` is a sample of ``df`` at the interval's middle,
    ``S_q = (1/N) sum df ((n - k + 1/2) / N)^q`` over the jumps whose interval is inside the
    window. Fixed work per sample: the sums move one sample further by a binomial (Taylor)
    shift, a jump leaving the window is subtracted, and the sums are exactly zero without a
    jump (the C core keeps a flag per sample of its ring and takes ``df`` from there)."""

    def __init__(self, n_ref: int, degree: int, n_forces: int) -> None:
        self.n_ref = int(n_ref)
        self.degree = int(degree)
        self.sums = np.zeros((degree + 1, n_forces))
        self.reset()

    def reset(self) -> None:
        self.sums[:] = 0.0
        self._jumps: dict[int, np.ndarray] = {}  # sample k (the interval k-1..k) -> df

    @property
    def any(self) -> bool:
        """Whether a jump is inside the window."""
        return bool(self._jumps)

    def _powers(self, position: float) -> np.ndarray:
        out = np.empty(self.degree + 1)
        out[0] = 1.0
        for q in range(1, self.degree + 1):
            out[q] = out[q - 1] * position
        return out

    def step(self, n: int, start: int, jump: np.ndarray | None) -> np.ndarray:
        """The moments at sample ``n`` (the window's oldest sample ``start``) after the jump
        ``jump`` between samples ``n - 2`` and ``n - 1`` (None: none); shape (degree+1, forces)."""
        if self._jumps:  # one sample further: S_q <- sum_r C(q, r) h^(q-r) S_r, h = 1/N
            h = 1.0 / self.n_ref
            for q in range(self.degree, 0, -1):
                total, c, hp = self.sums[q].copy(), 1.0, 1.0
                for r in range(q - 1, -1, -1):
                    c = c * (r + 1) / (q - r)
                    hp *= h
                    total += c * hp * self.sums[r]
                self.sums[q] = total
            for k in [k for k in self._jumps if k - 1 < start]:  # its interval left the window
                self.sums -= np.outer(self._powers((n - k + 0.5) / self.n_ref), self._jumps.pop(k))
        if jump is not None and n - 2 >= start:
            self._jumps[n - 1] = jump
            self.sums += np.outer(self._powers(1.5 / self.n_ref), jump)
        if not self._jumps:
            self.sums[:] = 0.0
        return self.sums / self.n_ref


def _published_error(rse: np.ndarray, theta: np.ndarray, jump_shift: np.ndarray,
                     rate_shift: np.ndarray, drift_shift: np.ndarray, noise: np.ndarray) -> np.ndarray:
    """Each unknown's relative standard error with the jumps' bias (:data:`JUMP_ERROR` times
    its shift), the rate change's beyond :data:`RATE_NOISE` standard errors, the drift
    probe's drift to now (:data:`DRIFT_BIAS_SIGMAS`) and the rows' noise bias
    (:func:`~duffid.identification.row_noise.noise_shift`), in quadrature."""
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        jump = np.where(jump_shift != 0, JUMP_ERROR * np.abs(jump_shift / theta), 0.0)
        change = np.where(rate_shift != 0, np.abs(rate_shift / theta), 0.0)
        rate = np.sqrt(np.maximum(change**2 - (RATE_NOISE * rse) ** 2, 0.0))
        drift = np.where(drift_shift != 0, np.abs(drift_shift / theta), 0.0)
        bias = np.where(noise != 0, np.abs(noise / theta), 0.0)
        return np.where((jump_shift != 0) | (rate_shift != 0) | (drift_shift != 0) | (noise != 0),
                        np.sqrt(rse**2 + jump**2 + rate**2 + drift**2 + bias**2), rse)


def _batch_relative(solver: "_QRLeastSquares", theta: np.ndarray, C: np.ndarray | None = None) -> np.ndarray:
    """The relative batch-means errors (:data:`BATCH_WINDOWS`) of the unknowns ``theta = C z``
    (``z`` the factor's right-hand column; ``C`` None: ``R^-1``, the unknowns themselves); NaN
    until more blocks than unknowns have closed."""
    n = solver.n
    if not (solver.blocks > n and solver.scored > 0) or not np.all(np.isfinite(theta)):
        return np.full(len(theta), np.nan)
    R = solver.R[:n, :n]
    scale = np.linalg.norm(R, axis=0)
    Rinv = np.linalg.inv(R / scale) / scale[:, None]
    K = (Rinv if C is None else C) @ Rinv.T  # the unknowns' rows of G^-1
    var = np.einsum("ij,jk,ik->i", K, solver.scores, K) * (solver.rows / solver.scored) * (
        solver.blocks / (solver.blocks - n))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(theta != 0, np.sqrt(np.maximum(var, 0.0)) / np.abs(theta), np.inf)


def _jump_shift(R: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``(R^T R)^-1 v`` for the factor ``R`` (n x n) of the rows and ``v = A^T J``: how the
    rows' error column ``J`` moves the unknowns (:data:`JUMP_ERROR`)."""
    n = len(v)
    if not np.any(v) or not np.all(np.diag(R) != 0):
        return np.zeros(n)
    w = np.zeros(n)
    for i in range(n):  # R^T w = v (forward)
        w[i] = (v[i] - R[:i, i] @ w[:i]) / R[i, i]
    return _back_substitution(R, w)


# ---------------------------------------------------------------------- outliers
#: A displacement sample further than this many robust standard deviations from the
#: quadratic through the three samples before it is held back one sample: if the next
#: sample agrees with the samples before it, the held one was an isolated glitch (a spike,
#: a dropout to 0, a wrapped encoder count) and is replaced; a glitch may last two samples
#: (see :class:`_OutlierGuard`).
OUTLIER_SIGMAS = 12.0
#: The outlier test's scale is never below this share of the range the displacement has
#: covered (a noise-free record's smooth differences are no scale).
OUTLIER_RANGE = 1e-4
#: Memory of the running scale of the prediction residuals [samples].
OUTLIER_MEMORY = 64.0
_GAUSS_MEAN_ABS = 1.2533141373155003  # sigma / mean|r| of a normal distribution

# ---------------------------------------------------------------------- force jumps
#: A force that changes between two samples by more than this many times its running mean
#: change (memory :data:`OUTLIER_MEMORY` samples) and by more than :data:`JUMP_RANGE` of the
#: largest force seen jumped between them (a step, an impact's onset): no quadrature
#: through samples integrates that interval, and the rows of every window holding it are
#: biased to first order in the sampling step (a 2-DOF step at 1 kHz: damping 6-8 % off,
#: stated within 1 %): that bias is part of the standard errors (:data:`JUMP_ERROR`). With the
#: option ``jump_restart`` (off by default: a closed loop's switching controller jumps too, and
#: the restarts starve the change test) the robust method's window restarts with the sample
#: after the jump instead, as after :meth:`OnlineIdentifier.hold`.
JUMP_FACTOR = 20.0
#: A jump is never smaller than this share of the largest force magnitude seen (the steps of
#: a quantised or slowly varying force are no jumps).
JUMP_RANGE = 0.01
#: The auto window's longest length (``max_window``) must hold at least this many lowest natural
#: periods of the estimate, else nothing is published (:meth:`OnlineIdentifier._window_spans`).
MIN_WINDOW_PERIODS = 1.0
_UNBOUNDED = 2**62  # a window length beyond any buffer
#: ... and while a mass (a period parameter) is not excited, so that no natural period tells
#: what the window spans, it must hold at least this many samples: a 0.2 Hz plant seen through
#: 1 s windows of 20 samples (its mass never excited: the rows' quadrature errors decided the
#: solution) published k 70 % off; a 10 Hz step at 2 kHz (2,000 samples, its mass not excited)
#: publishes k within 0.3 %.
MIN_UNCHECKED_SAMPLES = 200
#: A force step is a jump only when the next change is at most this share of it: a steep but
#: continuous rise (an impact's onset, a half-sine of a few samples) changes by about as much
#: again at the next sample, and the quadrature integrates it to second order.
JUMP_ISOLATION = 0.5
#: Without ``jump_restart``, a jump's rows stay, and their bias is part of each unknown's
#: standard error: the quadrature integrates the interval of a jump ``df`` as a ramp, while the
#: force stepped somewhere inside it, so a row errs by up to this share of ``df`` times the
#: interval times the row's kernel there (exactly this share for a step at a sample instant, as a
#: zero-order hold or a simulated step gives). The rows' error column ``J`` (the jumps' kernel
#: entries, :class:`_JumpMoments`) moves the unknowns by ``(A^T A)^-1 A^T J`` times this share,
#: taken relative to each unknown in quadrature with its standard error. Measured on the 2-DOF
#: step of ``benchmarks/trust.py`` (a step at 1 kHz): the damping b1 was published 6.1 % off with
#: a stated error below 1 %, and is no longer published; the other values are published once
#: the rows after the jump outweigh those holding it.
JUMP_ERROR = 0.5
#: The quadrature's error is part of each unknown's standard error: the rows are formed again
#: by the same rule at half the rate (every second sample, :meth:`SlidingMoments.rate_difference`:
#: the same windows, no second estimator), and the change that the rows' difference makes to
#: the unknowns, ``(A^T A)^-1 A^T (D_d - A_d theta)``, is taken as their bias beyond this many
#: standard errors (half the samples: about one more standard error of noise), relative to each
#: unknown and in quadrature with its standard error, as ``identify`` takes its half-rate run.
#: Measured (``benchmarks/quadrature.py``, a 10 Hz plant under a swept sine to 25 Hz): at 8
#: samples per period of the highest frequency the damping was published 6.6 % off with a stated
#: 0.42 %, at 7.2 samples 11.3 % off with 0.52 %.
RATE_NOISE = 2.0


class _OutlierGuard:
    """Online exclusion of isolated displacement outliers: a suspect sample is held (one
    sample of delay, two for a glitch that may last two samples, only then) until the next
    samples tell whether it was a glitch. :meth:`admit` returns the samples to process now,
    in order.

    A sample further than the threshold from the quadratic through the three accepted before
    it is suspect. It was a glitch when the next sample agrees with that quadratic (two steps
    on); when the next one is off too, both are held, and they were a glitch of two samples
    when the third agrees with the quadratic (three steps on). A glitch is replaced by the
    quadratic through the two accepted samples before it and the one after.
    """

    def __init__(self, n_dof: int) -> None:
        self.n_dof = n_dof
        self.reset()

    def reset(self) -> None:
        n = self.n_dof
        self.h = np.zeros((3, n))       # accepted x at n-1, n-2, n-3
        self.count = 0                  # accepted samples
        self.mean_abs = np.zeros(n)     # running mean |prediction residual|
        self.lo = np.full(n, np.inf)
        self.hi = np.full(n, -np.inf)
        self.step = np.full(n, np.inf)  # smallest non-zero change (quantisation step)
        self.pending: list[tuple[int, np.ndarray, np.ndarray]] = []  # held samples (k, x, f)
        self.suspect = np.zeros(n, dtype=bool)  # ... the first one's suspect columns
        self.pair = np.zeros(n, dtype=bool)     # ... the columns whose glitch may last two samples
        self.threshold = np.zeros(n)
        self.found: list[tuple[int, int, float, float]] = []

    def _threshold(self) -> np.ndarray:
        step = np.where(np.isfinite(self.step), self.step, 0.0)
        scale = np.maximum(np.maximum(_GAUSS_MEAN_ABS * self.mean_abs, step), OUTLIER_RANGE * (self.hi - self.lo))
        return OUTLIER_SIGMAS * scale

    def _accept(self, x: np.ndarray, threshold: np.ndarray | None) -> None:
        h = self.h
        if self.count >= 3:
            r = np.abs(x - (3.0 * h[0] - 3.0 * h[1] + h[2]))
            if threshold is not None:
                r = np.minimum(r, threshold)
            self.mean_abs = r if self.count == 3 else self.mean_abs + (r - self.mean_abs) / OUTLIER_MEMORY
        if self.count >= 1:
            d = np.abs(x - h[0])
            self.step = np.where(d > 0.0, np.minimum(self.step, d), self.step)
        self.lo = np.minimum(self.lo, x)
        self.hi = np.maximum(self.hi, x)
        h[2] = h[1]
        h[1] = h[0]
        h[0] = x
        self.count += 1

    def _replace(self, index: int, j: int, value: float) -> None:
        k, x, _ = self.pending[index]
        self.found.append((k, j, float(x[j]), float(value)))
        x[j] = value

    def _release(self) -> list[tuple[np.ndarray, np.ndarray]]:
        out = []
        for _, x, f in self.pending:
            self._accept(x, self.threshold)
            out.append((x, f))
        self.pending = []
        return out

    def admit(self, k: int, x: np.ndarray, f: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        """Sample ``k`` (``x``, ``f``): the samples to process now."""
        out: list[tuple[np.ndarray, np.ndarray]] = []
        h = self.h
        if len(self.pending) == 1:
            ahead = 6.0 * h[0] - 8.0 * h[1] + 3.0 * h[2]  # the samples before, two steps on
            agree = np.abs(x - ahead) <= self.threshold
            for j in np.flatnonzero(self.suspect & agree):  # the quadratic through n-2, n-1, n+1
                self._replace(0, j, (3.0 * h[0, j] - h[1, j] + x[j]) / 3.0)
            self.pair = self.suspect & ~agree
            if self.pair.any():  # a glitch of two samples, or the motion: the next one tells
                self.pending.append((k, x.copy(), f.copy()))
                return out
            out += self._release()
        elif len(self.pending) == 2:
            ahead = 10.0 * h[0] - 15.0 * h[1] + 6.0 * h[2]  # three steps on
            for j in np.flatnonzero(self.pair & (np.abs(x - ahead) <= self.threshold)):
                # the quadratic through n-3, n-2 and n+1 at n-1 and n
                self._replace(0, j, -0.5 * h[1, j] + 4.0 / 3.0 * h[0, j] + x[j] / 6.0)
                self._replace(1, j, -0.5 * h[1, j] + h[0, j] + 0.5 * x[j])
            out += self._release()
        if self.count >= MIN_SAMPLES:
            threshold = self._threshold()
            suspect = np.abs(x - (3.0 * h[0] - 3.0 * h[1] + h[2])) > threshold
            if suspect.any():
                self.pending = [(k, x.copy(), f.copy())]
                self.suspect, self.threshold = suspect, threshold
                return out
            self._accept(x, threshold)
        else:
            self._accept(x, None)
        out.append((x, f))
        return out

    def flush(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """The held samples, if any (the record ended: nothing tells they were a glitch)."""
        return self._release()


# ---------------------------------------------------------------------- solvers
class _QRLeastSquares:
    """Least squares over rows of full-length windows, with exponential forgetting.

    The factor of the augmented matrix ``[A D]`` is updated by QR, so the unknowns are
    never formed through normal equations; its last diagonal entry is the residual norm.
    """

    def __init__(self, n_unknowns: int, forgetting_factor: float) -> None:
        self.n = n_unknowns
        self.lam = float(forgetting_factor)
        self.R = np.zeros((n_unknowns + 1, n_unknowns + 1))
        self.rows = 0.0
        self.times = 0.0  # the rows' times (since a drifting equation's origin), weighted as the rows
        self.jump = np.zeros(n_unknowns)  # A^T J, the rows' jump errors (JUMP_ERROR)
        self.rate = np.zeros(n_unknowns)  # A^T Q, the rows' change at half the rate (RATE_NOISE)
        self.gram = np.zeros((n_unknowns, n_unknowns))  # dA^T dA and dA^T dD: the rows' noise (row_noise)
        self.cross = np.zeros(n_unknowns)
        # the rows' scores A^T r by blocks of a window (BATCH_WINDOWS): the open block's, the
        # last closed one's, their sum of products, the samples in the open block, and the
        # rows and the blocks the closed blocks hold (both weighted as the rows)
        self.score = np.zeros(n_unknowns)
        self.last_score = np.zeros(n_unknowns)
        self.scores = np.zeros((n_unknowns, n_unknowns))
        self.block = 0
        self.scored = self.blocks = 0.0

    def reset(self) -> None:
        self.R[:] = 0.0
        self.rows = self.times = 0.0
        self.jump[:] = 0.0
        self.rate[:] = 0.0
        self.gram[:] = 0.0
        self.cross[:] = 0.0
        self.score[:] = 0.0
        self.last_score[:] = 0.0
        self.scores[:] = 0.0
        self.block = 0
        self.scored = self.blocks = 0.0

    def update(self, A: np.ndarray, D: np.ndarray, time: float = 0.0, J: np.ndarray | None = None,
               Q: np.ndarray | None = None, noise: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        stacked = np.vstack([np.sqrt(self.lam) * self.R, np.column_stack([A, D])])
        self.R = triangular_factor(stacked, self.n + 1)
        self.rows = self.lam * self.rows + len(A)
        self.times = self.lam * self.times + len(A) * time
        if J is not None or np.any(self.jump):
            self.jump = self.lam * self.jump + (0.0 if J is None else A.T @ J)
        if Q is not None or np.any(self.rate):
            self.rate = self.lam * self.rate + (0.0 if Q is None else A.T @ Q)
        if noise is not None:
            dA, dD = noise
            self.gram = self.lam * self.gram + dA.T @ dA
            self.cross = self.lam * self.cross + dA.T @ dD
        else:
            self.gram *= self.lam
            self.cross *= self.lam

    def add_scores(self, A: np.ndarray, residual: np.ndarray, block: int) -> None:
        """Add the rows ``A`` (just accumulated by :meth:`update`) with their residuals against
        the previous solution to the open block's score; close it after ``block`` samples."""
        self.score = self.lam * self.score + A.T @ residual
        self.scores *= self.lam**2
        self.scored *= self.lam
        self.blocks *= self.lam
        self.block += 1
        if self.block >= block:
            u, p = self.score, self.last_score
            self.scores += np.outer(u, u) + np.outer(u, p) + np.outer(p, u)
            self.last_score = u
            self.score = np.zeros(self.n)
            self.block = 0
            self.blocks += 1.0
            self.scored = self.rows

    def noise_shift(self) -> np.ndarray:
        """How the accumulated rows' noise moves the unknowns (:func:`noise_shift`)."""
        return noise_shift(self.R, self.gram, self.cross)

    def jump_shift(self) -> np.ndarray:
        """How the accumulated rows' jump errors move the unknowns (:func:`_jump_shift`)."""
        return _jump_shift(self.R[:self.n, :self.n], self.jump)

    def rate_shift(self) -> np.ndarray:
        """How the accumulated rows' change at half the rate moves the unknowns (RATE_NOISE)."""
        return _jump_shift(self.R[:self.n, :self.n], self.rate)

    @property
    def mean_time(self) -> float:
        """The weighted mean time of the rows it holds."""
        return self.times / self.rows if self.rows > 0 else 0.0


def _back_substitution(R: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``R^-1 b`` for an upper-triangular ``R`` (small: no LAPACK call)."""
    x = np.zeros(len(b))
    for i in range(len(b) - 1, -1, -1):
        x[i] = (b[i] - R[i, i + 1:] @ x[i + 1:]) / R[i, i]
    return x


def triangular_factor(M: np.ndarray, size: int) -> np.ndarray:
    """The upper-triangular factor of ``M``'s QR decomposition, padded with zero rows to
    ``size x size`` (the least-squares state accumulated by the online and buffered methods)."""
    R = np.linalg.qr(M, mode="r")
    out = np.zeros((size, size))
    out[: R.shape[0]] = R[:size]
    return out


def accumulated_rows(rows: float, n: int, per_sample: int, L: float) -> float:
    """The row count that gives the accumulated least squares of full windows its degrees of
    freedom (:data:`WINDOW_EQUATIONS`): ``rows - n per_sample L / WINDOW_EQUATIONS`` for
    :func:`solve_factor`'s ``rows - n``, at least ``(rows - n) / WINDOW_INFLATION**2``.

    Parameters
    ----------
    rows : float
        The rows the factor holds (weighted by the forgetting).
    n : int
        Its unknowns.
    per_sample : int
        Rows each sample adds (a window's kernels, per equation of the block).
    L : float
        The windows' length (intervals).
    """
    return max(rows - n * (per_sample * L / WINDOW_EQUATIONS - 1.0), (rows - n) / WINDOW_INFLATION**2 + n)


def solve_factor(R_aug: np.ndarray, rows: float, overlap: float
                  ) -> tuple[np.ndarray, float, np.ndarray, np.ndarray, float]:
    """Solve the least-squares problem held in the factor ``R_aug`` of ``[A D]``.

    Returns the unknowns, the condition number of the column-equilibrated factor, the
    relative standard error of each unknown: ``sqrt(diag(cov)) / |theta|`` with
    ``cov = s^2 (R^T R)^-1``, ``s^2 = residual^2 / (rows - n)`` inflated by ``overlap``
    (consecutive windows share samples, so their residuals are not independent), and the
    share of each term and of the right-hand side in the force balance:
    ``|theta_i| ||A_i||`` and ``||D||`` over the root of the sum of their squares.
    """
    n = R_aug.shape[0] - 1
    R = R_aug[:n, :n]
    scale = np.linalg.norm(R, axis=0)
    nan = np.full(n, np.nan)
    if not np.all(scale > 0):
        return nan, np.inf, np.full(n, np.inf), nan, np.nan
    U, sv, Vt = np.linalg.svd(R / scale)
    cond = float(sv[0] / sv[-1]) if sv[-1] > 0 else np.inf
    if not np.isfinite(cond) or cond > 1e14:
        return nan, np.inf, np.full(n, np.inf), nan, np.nan
    Rinv = (Vt.T / sv) @ U.T
    theta = Rinv @ R_aug[:n, n] / scale
    terms = np.abs(theta) * scale
    rhs = float(np.sqrt(np.sum(R_aug[:, n] ** 2)))
    balance = float(np.sqrt(np.sum(np.append(terms**2, rhs**2))))
    share, rhs_share = (terms / balance, rhs / balance) if balance > 0 else (nan, np.nan)
    dof = rows - n
    if dof <= 0:
        return theta, cond, np.full(n, np.inf), share, rhs_share
    s2 = R_aug[n, n] ** 2 / dof * overlap
    std = np.sqrt(s2 * np.sum(Rinv**2, axis=1)) / scale
    with np.errstate(divide="ignore", invalid="ignore"):
        rse = np.where(theta != 0, std / np.abs(theta), np.inf)
    return theta, cond, rse, share, rhs_share


def recent_solution(R_aug: np.ndarray, rows: float, overlap: float) -> tuple[np.ndarray, np.ndarray]:
    """The unknowns and relative standard errors of :func:`solve_factor`, without its condition
    number (the change test's recent estimate needs neither that nor the shares).

    The column-equilibrated factor ``U`` is inverted as a triangle; instead of the singular
    values, ``sqrt(n) |U^-1|_F`` (``|U|_F = sqrt(n)``: its columns have unit norm), which bounds
    the condition number from above and exceeds it by at most ``sqrt(n)`` times, must stay at
    most ``1e14`` (:func:`solve_factor`'s limit) for a solution.

    Parameters
    ----------
    R_aug : ndarray, shape (n + 1, n + 1)
        Upper-triangular factor of the rows ``[A D]``.
    rows : float
        Number of rows it holds (weighted by the forgetting).
    overlap : float
        Inflation of the residual variance, as :func:`solve_factor`'s.

    Returns
    -------
    theta : ndarray, shape (n,)
        The unknowns (NaN when the factor is singular or its bound above the limit).
    rse : ndarray, shape (n,)
        Their relative standard errors (inf when undetermined).
    """
    n = R_aug.shape[0] - 1
    R = R_aug[:n, :n]
    scale = np.linalg.norm(R, axis=0)
    nan, inf = np.full(n, np.nan), np.full(n, np.inf)
    if not np.all(scale > 0):
        return nan, inf
    U = R / scale
    if not np.all(np.diag(U) != 0):
        return nan, inf
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        Rinv = np.linalg.inv(U)
        bound = float(np.sqrt(n * np.sum(Rinv**2)))
    if not bound <= 1e14:  # also NaN
        return nan, inf
    theta = Rinv @ R_aug[:n, n] / scale
    dof = rows - n
    if dof <= 0:
        return theta, inf
    s2 = R_aug[n, n] ** 2 / dof * overlap
    std = np.sqrt(s2 * np.sum(Rinv**2, axis=1)) / scale
    with np.errstate(divide="ignore", invalid="ignore"):
        rse = np.where(theta != 0, std / np.abs(theta), np.inf)
    return theta, rse


class DriftLine:
    """The accumulated least squares of an equation whose ``drifting`` unknowns are linear in
    time (``theta_i + rate_i t``; the change test's answer to a plant that drifts).

    A least squares over the samples of a drifting plant is no value the plant had: it lags
    the drift by half the accumulated span and biases the other unknowns, and the change test
    would restart it again and again. Once the change test restarts an equation, each
    departed unknown gets its rate as one more unknown (at most :data:`MAX_LINE_UNKNOWNS` in
    all), whose rows weigh each sample's term by its own time since the restart (in s):
    ``t A_i - S_i`` with ``t`` the time of the window's newest sample and ``S`` the rows of the
    kernels times the samples' ages (:meth:`KernelBank.within`). The published value is the
    line at the newest sample with the standard error of that combination. (Rows ``t A_i``
    alone, every sample at the newest's time, put the line half a window late and the
    within-window drift into the other unknowns: on a stiffness drifting by 20 % over 6 s the
    stiffness lagged by 0.3 % and the damping was 1.7 % off with stated errors of 0.3 %.) The
    change test fits the same lines to its recent rows and compares both at the recent rows'
    mean time. An unknown stays a line until :meth:`OnlineIdentifier.reset`:
    after a step, or a drift that stops, its rate is about zero and costs precision (a line's
    end is known about half as well as a mean), not trust.

    Parameters
    ----------
    drifting : ndarray of bool, shape (n,)
        The equation's unknowns modelled as lines.
    """

    def __init__(self, drifting: np.ndarray) -> None:
        self.drifting = np.asarray(drifting, dtype=bool)
        self.index = np.flatnonzero(self.drifting)
        self.theta = np.full(len(self.drifting) + len(self.index), np.nan)  # values at t = 0, then rates
        self.inverse = np.full((len(self.theta), len(self.theta)), np.nan)  # theta = inverse @ R[:, -1]
        self.sigma = np.inf

    @property
    def size(self) -> int:
        """Unknowns of the accumulated least squares (the equation's and the rates)."""
        return len(self.theta)

    def rows(self, A: np.ndarray, time: float, S: np.ndarray | None = None) -> np.ndarray:
        """The accumulated rows of the equation's rows ``A`` whose window's newest sample is at
        ``time``: ``[A, time A_i - S_i]``, with ``S`` the rows of the time-weighted kernels
        (``t_ref`` times :meth:`KernelBank.within`'s): each sample's term weighted by its own
        time, not the newest's (without ``S``: the newest's)."""
        rates = time * A[:, self.index]
        return np.column_stack([A, rates if S is None else rates - S[:, self.index]])

    def solve(self, R_aug: np.ndarray, rows: float, overlap: float) -> tuple[float, np.ndarray, float]:
        """Solve the accumulated factor (as :func:`solve_factor`); returns its condition number,
        the shares of the equation's own terms and of the right-hand side."""
        theta, cond, _, share, rhs_share = solve_factor(R_aug, rows, overlap)
        self._inverse(R_aug, rows, overlap, theta)
        return cond, share[: len(self.drifting)], rhs_share

    def solve_recent(self, R_aug: np.ndarray, rows: float, overlap: float) -> None:
        """Solve the change test's recent factor (as :func:`recent_solution`)."""
        self._inverse(R_aug, rows, overlap, recent_solution(R_aug, rows, overlap)[0])

    def _inverse(self, R_aug: np.ndarray, rows: float, overlap: float, theta: np.ndarray) -> None:
        n = R_aug.shape[0] - 1
        self.theta = theta
        if not np.all(np.isfinite(theta)):
            self.sigma = np.inf
            return
        scale = np.linalg.norm(R_aug[:n, :n], axis=0)
        self.inverse = np.linalg.inv(R_aug[:n, :n] / scale) / scale[:, None]
        dof = rows - n
        self.sigma = float(np.sqrt(R_aug[n, n] ** 2 / dof * overlap)) if dof > 0 else np.inf

    def combination(self, time: float) -> np.ndarray:
        """The map from the factor's right-hand column to the equation's unknowns at ``time``."""
        n = len(self.drifting)
        C = self.inverse[:n].copy()
        C[self.index] += time * self.inverse[n:]
        return C

    def at(self, time: float) -> tuple[np.ndarray, np.ndarray]:
        """The equation's unknowns at ``time`` and their relative standard errors."""
        n = len(self.drifting)
        theta = self.theta[:n].copy()
        theta[self.index] += time * self.theta[n:]
        C = self.combination(time)
        std = self.sigma * np.linalg.norm(C, axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            rse = np.where(np.isfinite(theta) & (theta != 0), std / np.abs(theta), np.inf)
        return theta, rse


class Integrators:
    """Cascade of ``depth`` integrators per input channel, fixed t0 at the first sample."""

    def __init__(self, n_inputs: int, depth: int, dt: float, quadrature: str) -> None:
        self.dt = dt
        self.adams = quadrature == "adams3"
        self.y = np.zeros((depth + 1, n_inputs))   # y[0] = input, y[k] = k-fold integral
        self.prev1 = np.zeros_like(self.y)
        self.prev2 = np.zeros_like(self.y)
        self.count = 0

    def reset(self) -> None:
        self.y[:] = 0.0
        self.prev1[:] = 0.0
        self.prev2[:] = 0.0
        self.count = 0

    def push(self, u: np.ndarray) -> np.ndarray:
        h = self.dt
        self.prev2[:] = self.prev1
        self.prev1[:] = self.y
        self.y[0] = u
        for k in range(1, len(self.y)):
            if self.count == 0:
                self.y[k] = 0.0
            elif self.count == 1 or not self.adams:
                self.y[k] = self.prev1[k] + 0.5 * h * (self.y[k - 1] + self.prev1[k - 1])
            else:
                self.y[k] = self.prev1[k] + h / 12.0 * (
                    5.0 * self.y[k - 1] + 8.0 * self.prev1[k - 1] - self.prev2[k - 1])
        self.count += 1
        return self.y


# ---------------------------------------------------------------------- estimate
def _next_status(status: str, settled: int, unsettled: int, settle: int, good: bool, share: float) -> str:
    """A parameter's status after a sample (see :data:`STATUSES`): ``settled`` counts the
    samples since its error was last above ``max_uncertainty``, ``unsettled`` those since
    it was last within :data:`LOSS_FACTOR` times that; ``lost`` and ``changed`` last until it
    is published again (or not excited)."""
    published, not_excited, lost, changed = STATUSES[1], STATUSES[2], STATUSES[3], STATUSES[4]
    if settled >= settle:
        return published
    if status == published:
        return lost if unsettled >= settle else published
    if good and share < MIN_SHARE:
        return not_excited
    return status if status in (lost, changed) else STATUSES[0]


def _relative_residual(A: np.ndarray, D: np.ndarray, theta: np.ndarray) -> float:
    """The norm of the rows' prediction errors ``D - A theta`` over that of their force
    balance (the terms ``A_i theta_i`` and ``D``; NaN when ``theta`` is not finite or the
    balance is zero): the one-step prediction error of the window."""
    if not np.all(np.isfinite(theta)):
        return np.nan
    balance = float(np.sqrt(np.sum((A * theta) ** 2) + np.sum(D**2)))
    return float(np.linalg.norm(D - A @ theta)) / balance if balance > 0 else np.nan


def _relative_fit(R_aug: np.ndarray, theta: np.ndarray) -> float:
    """:func:`_relative_residual` of every row the factor ``R_aug`` of ``[A D]`` holds, at its
    solution ``theta`` (its residual norm over the norm of their force balance)."""
    n = R_aug.shape[0] - 1
    if not np.all(np.isfinite(theta)):
        return np.nan
    terms = np.linalg.norm(R_aug[:n, :n], axis=0) * theta
    balance = float(np.sqrt(np.sum(terms**2) + np.sum(R_aug[:, n] ** 2)))
    return abs(float(R_aug[n, n])) / balance if balance > 0 else np.nan


def _departure(theta: np.ndarray, rse: np.ndarray, recent: np.ndarray, recent_rse: np.ndarray) -> np.ndarray:
    """Per unknown, the difference between the recent and the accumulated solution in their
    combined standard errors (0 where either is undetermined)."""
    with np.errstate(invalid="ignore"):  # inf x 0 where an unknown is undetermined: not ok below
        combined = np.hypot(rse * np.abs(theta), recent_rse * np.abs(recent))
    ok = np.isfinite(theta) & np.isfinite(recent) & np.isfinite(combined) & (combined > 0)
    return np.where(ok, np.abs(recent - theta) / np.where(ok, combined, 1.0), 0.0)


def _alone(R_aug: np.ndarray, theta: np.ndarray, share: float) -> np.ndarray:
    """Per unknown, whether changing it alone reduces the prediction error of ``theta`` on the
    rows held in the factor ``R_aug`` of ``[A D]`` by at least ``share`` of what their own
    least-squares solution reduces it by.

    With ``r = R_aug [theta; -1]`` (the rows' residual under ``theta``, rotated; its last entry
    is minus their own residual), their own solution reduces the squared prediction error by
    ``|r[:n]|^2``, and the best change of unknown ``i`` alone by ``(c_i . r)^2 / |c_i|^2`` (``c_i``
    the factor's column ``i``). Compared without a division; a non-finite ``theta`` confirms none.

    Parameters
    ----------
    R_aug : ndarray, shape (n + 1, n + 1)
        Upper-triangular factor of the rows ``[A D]`` (the recent least squares).
    theta : ndarray, shape (n,)
        The solution whose prediction error is tested (the accumulated one).
    share : float
        The least share of the rows' own gain a change of one unknown must achieve.

    Returns
    -------
    ndarray of bool, shape (n,)
        Per unknown: its change alone is confirmed.
    """
    n = R_aug.shape[0] - 1
    if not np.all(np.isfinite(theta)):
        return np.zeros(n, dtype=bool)
    residual = R_aug @ np.append(theta, -1.0)
    columns = R_aug[:, :n]
    gain = float(np.sum(residual[:n] ** 2))
    return (columns.T @ residual) ** 2 >= share * np.sum(columns**2, axis=0) * gain


def prior_sizes(model: Chain, nominal: Mapping[str, float] | None) -> dict[str, float]:
    """Canonical sizes from the optional prior ``nominal`` (the option of that name, by
    public name); ValueError for a name the model does not have."""
    if not nominal:
        return {}
    unknown = set(nominal) - set(model.parameters)
    if unknown:
        raise InputError(f"option nominal: {model.name} has no parameter(s) {sorted(unknown)}; "
                         f"its parameters are {list(model.parameters)}")
    sizes = {}
    for public, size in nominal.items():
        name = model.canonical_name(public)
        # the public value is the canonical one or (the circuit's C = 1/k) its reciprocal
        probe = model.from_canonical({**model.canonical_parameters(), name: 2.0})[public]
        sizes[name] = abs(float(size)) if probe == 2.0 or size == 0 else 1.0 / abs(float(size))
    return sizes


@dataclass(frozen=True)
class Estimate:
    """One step of the online identifier.

    Attributes
    ----------
    t : float
        Time of the sample [s] (relative to the first sample).
    parameters : dict
        Estimates under the model's public names; NaN unless published (robust: see
        ``status``).
    identified : bool
        True when every parameter is published (robust: see ``status``; paper: a
        well-conditioned, finite solution).
    condition : float
        Largest condition number over the equations (column-equilibrated).
    uncertainty : float
        Largest relative standard error of a parameter (robust method; NaN for paper; the
        buffered methods: each window's, :class:`~duffid.identification.buffered.BufferedIdentifier`); relative to
        max(|estimate|, prior size) for a parameter given an optional prior (``nominal``).
    window : float
        Current window length [s].
    current : dict or None
        The estimator's solution at this sample (public names), trusted or not (NaN where
        the system is singular); None when the estimator does not report it. Input to
        :func:`duffid.identification.trust.assess`, never a published value.
    status : dict or None
        Public name -> one of :data:`STATUSES` (None when the estimator does not report it).
    outliers : int
        Isolated displacement outliers excluded so far (see :data:`OUTLIER_SIGMAS`); a
        suspect sample is processed one sample late, and meanwhile the previous estimate
        is repeated.
    std_errors : dict or None
        Standard error of each published value (public names, its unit; NaN where nothing is
        published); None when the estimator does not report it.
    residual : float
        The window's one-step prediction error: the norm of its rows' residuals under the
        previous solution over that of their force balance (NaN while there is none; the
        largest over the equations). It jumps when the plant stops fitting the estimate.
    """

    t: float
    parameters: dict[str, float]
    identified: bool
    condition: float
    uncertainty: float
    window: float
    current: dict[str, float] | None = None
    status: dict[str, str] | None = None
    outliers: int = 0
    std_errors: dict[str, float] | None = None
    residual: float = np.nan


class _EquationState:
    def __init__(self, equation: Equation, assembly: _Assembly) -> None:
        self.equation = equation
        self.assembly = assembly
        self.theta = np.empty(len(equation.unknowns))
        self.rse = np.empty(len(equation.unknowns))
        self.share = np.empty(len(equation.unknowns))
        self.departure = np.zeros(len(equation.unknowns))
        self.line: DriftLine | None = None  # the drifting unknowns' lines (None: none drifts)
        self.recent_line: DriftLine | None = None  # ... in the change test's recent estimate
        self.origin = 0  # ... the sample whose rows have time 0
        self.offset_probed = False  # the offset probe (OFFSET_SIGMAS) runs for this equation
        probed = min(len(equation.unknowns), max(MAX_LINE_UNKNOWNS - len(equation.unknowns), 0))
        # the drift probe's lines (DRIFT_SIGMAS): the first unknowns, as many as fit
        self.probe_line = DriftLine(np.arange(len(equation.unknowns)) < probed) if probed else None
        self.clear()

    def clear(self) -> None:
        self.theta[:] = np.nan
        self.cond = np.inf
        self.rse[:] = np.inf
        self.share[:] = np.nan
        self.rhs_share = np.nan
        self.departure[:] = 0.0
        self.departed = 0       # samples the departure has mattered in a row
        self.drifted = 0        # samples a smaller departure beyond the band has lasted in a row
        self.surprised = 0      # samples the prediction error has been surprising in a row
        self.resume = 0         # after a change: the first sample whose window follows it
        self.recent_resume = 0  # ... after a surprise: the same for the recent estimate
        self.residual = np.nan  # the window's prediction error (Estimate.residual)
        self.probed = 0          # samples the drift probe has found a drift in a row
        self.probe_fed = 0       # ... the rows it has had (it takes row probe_fed % rows next)
        self.offset_fed = 0      # the offset probe's rows (it takes row offset_fed % rows next)
        self.offset_moved = np.zeros(len(self.theta), dtype=bool)  # unknowns a constant moves
        self.jump_shift = np.zeros(len(self.theta))  # how the rows' jump errors move the unknowns
        self.rate_shift = np.zeros(len(self.theta))  # ... and their change at half the rate (RATE_NOISE)
        self.drift_shift = np.zeros(len(self.theta))  # ... and the drift probe's drift to now
        self.noise_shift = np.zeros(len(self.theta))  # ... and the rows' noise (row_noise)
        self.nominal = np.full(len(self.theta), np.inf)  # the residual's errors (BATCH_WINDOWS; the change test's)


class OnlineIdentifier(Identifier):
    """Online algebraic identifier: O(1) work and memory per sample.

    Parameters
    ----------
    model : Chain
        Model structure (e.g. :class:`~duffid.models.chain.Duffing1`); its parameter values are
        not used. A parameter is published once its relative standard error stayed at most
        ``max_uncertainty`` for ``settle`` s (a growing window's estimate must also have
        stayed put while the window grew by :data:`GROWTH_STEADY`; without a prior, only a
        physical value of an excited term; none that an unknown constant force would move,
        see :data:`OFFSET_SIGMAS`), withdrawn ("lost") once its error stayed above
        :data:`LOSS_FACTOR` times that, or its value non-physical, for ``settle`` s; "not
        excited" while its term carries less than :data:`MIN_SHARE` of the force balance
        (see :data:`STATUSES`). Every scale comes from the data, unless
        the optional prior ``nominal`` gives a parameter a size: then its standard error is
        taken relative to the larger of the estimate and that size (so that a parameter
        known to be small next to that size is published).
    dt : float
        Sampling period [s].
    method : {"robust", "paper"}
        Estimator, see the module documentation.
    **options
        Method options. ``robust``: ``window`` ("auto" or seconds), ``window_periods``
        (auto window in natural periods, 1.5), ``max_window`` (s, 1.0), ``forgetting``
        (time constant in s or None), ``rows`` ("integrals", "bernstein" or "paper"),
        ``n_rows`` (max(unknowns + 1, 8)), ``max_condition`` (1e6), ``max_uncertainty``
        (0.01), ``settle`` (s, 0.01), ``min_time`` (s, 0.01), ``deadband`` (m),
        ``nominal`` (None, or prior sizes by public name), ``jump_restart`` (False; True: a
        force jump between two samples restarts the window, see :data:`JUMP_FACTOR`).
        ``paper``: ``gamma`` (20), ``quadrature`` ("adams3" or "trapezoid"),
        ``sign_in_numerator`` (False), ``max_condition``, ``min_time``, ``deadband``.

    Examples
    --------
    >>> ident = OnlineIdentifier(Duffing1(), dt=1e-3)            # doctest: +SKIP
    >>> for x, f in samples:                                      # doctest: +SKIP
    ...     est = ident.update(x, f)
    """

    def __init__(self, model: Chain, dt: float, method: str = "robust", **options: Any) -> None:
        super().__init__(model, dt, method, check_online_options(method, options))
        self.equations = model.equations()
        self._prior = prior_sizes(model, self.options.get("nominal"))
        # robust: samples a parameter's error must stay small before it is published
        self._settle = max(int(round(self.options["settle"] / self.dt)), 1) if method == "robust" else 1
        channels: dict[Channel, None] = {}
        for eq in self.equations:
            for c in eq.channels:
                channels.setdefault(c, None)
        self.channels = tuple(channels)
        self._channels = _Channels(self.channels, self.options["deadband"], self.dt,
                                   model if any(c.kind == "expression" for c in self.channels) else None)
        self._sources = {k: model.share_sources(k) for k in model.canonical_parameters()}
        self._period_names = model.period_parameters()
        self._guard = _OutlierGuard(model.n_dof)
        joint = [eq for eq in self.equations if eq.parts > 1]
        if method == "paper" and joint:
            raise InputError(f"{model.name}: the paper method solves each equation alone, and "
                             f"{', '.join(joint[0].unknowns)} are shared by {joint[0].parts} equations solved "
                             "together: use the robust method or a buffered basis (legendre, ...)")
        max_order = max(eq.max_order for eq in self.equations)
        self._states = [_EquationState(eq, _Assembly(eq, self.channels, max_order)) for eq in self.equations]
        # the rows' error column of each equation: its force terms on the jumps (JUMP_ERROR)
        n_f = model.n_forces
        for st in self._states:
            st.jump_rhs = np.zeros((st.equation.parts, (max_order + 1) * n_f))
            for t in st.equation.rhs:
                if t.channel.kind == "force":
                    st.jump_rhs[t.part, t.order * n_f + t.channel.index] += t.sign
        constants = set(model.offset_parameters().values())  # equations with a constant force of their own
        for j, st in enumerate(self._states):
            st.offset_probed = method == "robust" and st.equation.parts == 1 and j not in constants
        o = self.options
        if method == "robust":
            fixed = o["window"] != "auto"
            seconds = o["window"] if fixed else o["max_window"]
            self.capacity = max(int(round(seconds / self.dt)), 2)
            self._target = self.capacity
            self._auto = not fixed
            n_rows = o["n_rows"] or max(max(len(eq.unknowns) for eq in self.equations) + 1, 8)
            self.bank = KernelBank.build(row_exponents(o["rows"], n_rows), max_order)
            self._moments = SlidingMoments(self.capacity, self.bank.degree, len(self.channels))
            # ... and with one power more, for the time-weighted entries of the lines' rows
            # (KernelBank.within; kept apart so that the rows' own moments round as before)
            # (only with the change test: no lines without it)
            self._timed_moments = None if o["change_threshold"] is None else SlidingMoments(
                self.capacity, self.bank.degree + 1, len(self.channels))
            self._jumps = _JumpMoments(self.capacity, self.bank.degree, model.n_forces)
            # the rows' noise (row_noise): the displacements' noise level and the moments of the
            # channels' change under a noise of that level
            self._noise_level = NoiseLevel(model.n_dof)
            self._noisy = np.array([c.kind in ("x", "deflection", "expression") for c in self.channels])
            self._noise_moments = SlidingMoments(self.capacity, self.bank.degree, len(self.channels))
            lam = 1.0 if o["forgetting"] is None else float(np.exp(-self.dt / o["forgetting"]))
            self._solvers = [_QRLeastSquares(len(eq.unknowns), lam) for eq in self.equations]
            # the change test's recent estimate (its forgetting factor follows the window)
            self._recent = [_QRLeastSquares(len(eq.unknowns), 1.0) for eq in self.equations]
            self._probes = [self._new_probe(st, lam) for st in self._states]
            self._offsets = [self._new_offset_probe(st, lam) for st in self._states]
            self._variations = [self._new_variation(st, lam) for st in self._states]
            self._one: tuple[int, np.ndarray] = (-1, np.empty(0))  # a constant's entries (L, E)
        else:
            self._paper_setup()
        self.reset()

    # -------------------------------------------------------------- common
    def reset(self) -> None:
        """Forget all samples (start a new identification)."""
        self.n = -1
        self._received = -1
        self._guard.reset()
        self._last: Estimate | None = None
        self._channels.reset()
        self._window_fixed = False
        self._window_capped = False
        canonical = self.model.canonical_parameters()
        self._steady = {k: 0 for k in canonical}
        # while the window grows: a period parameter's latest value that was steady
        self._period_seen = {k: np.nan for k in self._period_names}
        self._canonical: dict[str, float] = {}  # the latest sample's canonical values
        self._anchor = {k: np.nan for k in canonical}
        self._anchored = {k: 0 for k in canonical}
        self._settled = {k: 0 for k in canonical}
        self._unsettled = {k: 0 for k in canonical}
        self._status = {k: STATUSES[0] for k in canonical}
        self._fresh = {k: False for k in canonical}  # restarted since last published
        self._credible_from = {k: 0 for k in canonical}  # ... and its rows span a window from this sample
        self._spanned_from = -1  # the rows of full windows span a window from this sample (-1: none yet)
        self._value = {k: np.nan for k in canonical}  # the latest published value
        self._held = {name: np.nan for name in self.parameter_names}
        self._changed_now: dict[str, bool] = {}
        self._regrow = False  # after hold(): the window is growing again
        self._f_prev: np.ndarray | None = None  # the force of the previous sample processed
        self._jump_candidate: np.ndarray | None = None  # the previous sample's change, if a jump
        self._jump: np.ndarray | None = None  # an isolated jump before the previous sample
        self._f_change: np.ndarray | None = None  # running mean |change| of each force
        self._f_peak = np.zeros(self.model.n_forces)  # largest |force| seen
        if self.method == "robust":
            self._moments.reset()
            if self._timed_moments is not None:
                self._timed_moments.reset()
            self._noise_level.reset()
            self._noise_moments.reset()
            self._jumps.reset()
            self._set_target(self.capacity)
            self._solvers = [_QRLeastSquares(len(st.equation.unknowns), s.lam)
                             for st, s in zip(self._states, self._solvers)]
            self._recent = [_QRLeastSquares(len(st.equation.unknowns), s.lam)
                            for st, s in zip(self._states, self._recent)]
            self._probes = [self._new_probe(st, s.lam) for st, s in zip(self._states, self._solvers)]
            self._offsets = [self._new_offset_probe(st, s.lam) for st, s in zip(self._states, self._solvers)]
            self._variations = [self._new_variation(st, s.lam) for st, s in zip(self._states, self._solvers)]
        else:
            self._paper_reset()
        for st in self._states:
            st.clear()
            st.line = st.recent_line = None
            st.origin = 0

    def update(self, x: float | np.ndarray, f: float | np.ndarray) -> Estimate:
        """Consume one sample of displacements ``x`` and forces ``f``; return the estimate."""
        x, f = self.checked_sample(x, f)
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(f))):
            raise InputError(f"{self.model.name}: sample {self._received + 1} is not finite (x={x}, f={f})")
        self._received += 1
        estimate = None
        for xi, fi in self._guard.admit(self._received, x, f):
            estimate = self._process(xi, fi)
        return self._reported(estimate)

    def flush(self) -> Estimate | None:
        """Process the samples held back as a suspect outlier (at the end of a record: nothing
        tells they were a glitch); the estimate, or None if no sample was held."""
        estimate = None
        for xi, fi in self._guard.flush():
            estimate = self._process(xi, fi)
        return None if estimate is None else self._reported(estimate)

    @property
    def outliers(self) -> list[dict[str, Any]]:
        """The displacement samples excluded as isolated outliers: ``t`` [s from the first
        sample], ``column`` (x1, x2, ...), ``value`` and ``replaced_by``."""
        return [{"t": k * self.dt, "column": f"x{j + 1}", "value": v, "replaced_by": r}
                for k, j, v, r in self._guard.found]

    def _reported(self, estimate: Estimate | None) -> Estimate:
        """The estimate after the latest sample: ``estimate``, or the previous one while a
        suspect sample is held back."""
        if estimate is None:
            assert self._last is not None  # the first samples are never held
            estimate = self._last
        estimate = replace(estimate, t=self._received * self.dt, outliers=len(self._guard.found))
        self._last = estimate
        return estimate

    def hold(self) -> None:
        """The next sample does not follow the previous one: the plant was not excited or a
        sensor saturated, and the samples in between are not given (the ``enable`` input of
        the estimator FMUs). A sample held back as a suspect outlier is processed first; the
        window restarts with the next sample, while the least squares accumulated so far,
        the statuses and the published values are kept and reported unchanged until the
        window is full again (robust method; the paper method's integrals cannot skip
        samples: it restarts, as :meth:`reset`)."""
        if self.method != "robust":
            self.reset()
            return
        if self._last is None:
            return  # nothing received yet: the next sample is the first
        for xi, fi in self._guard.flush():
            self._reported(self._process(xi, fi))
        found = self._guard.found
        self._guard.reset()
        self._guard.found = found
        self._restart_window(regrow=True)
        self._f_prev = self._jump_candidate = None  # the next sample does not follow the previous one

    def _restart_window(self, regrow: bool) -> None:
        """The window restarts with the next sample; with ``regrow`` the previous estimate is
        reported until it is full again."""
        self._channels.reset()
        self._moments.reset()
        if self._timed_moments is not None:
            self._timed_moments.reset()
        self._noise_moments.reset()
        self._jumps.reset()
        self._regrow = regrow

    def _force_jumps(self, f: np.ndarray) -> bool:
        """Whether a force jumped between the previous sample processed and ``f`` (see
        :data:`JUMP_FACTOR`); updates the running scales and sets ``_jump``: the change from
        the sample before the previous one to it when that was a jump and ``f`` changed by at
        most :data:`JUMP_ISOLATION` of it (None: none)."""
        prev, self._f_prev = self._f_prev, np.array(f, dtype=float)
        self._f_peak = np.maximum(self._f_peak, np.abs(self._f_prev))
        candidate, self._jump_candidate = self._jump_candidate, None
        self._jump = None
        if prev is None:
            return False
        delta = self._f_prev - prev
        change = np.abs(delta)
        if candidate is not None:
            isolated = (candidate != 0) & (change <= JUMP_ISOLATION * np.abs(candidate))
            if isolated.any():
                self._jump = np.where(isolated, candidate, 0.0)
        if self._f_change is None:  # the first change sets the scale
            self._f_change = change
            return False
        jumps = (change > JUMP_FACTOR * self._f_change) & (change > JUMP_RANGE * self._f_peak)
        self._f_change = self._f_change + (change - self._f_change) / OUTLIER_MEMORY
        if jumps.any():
            self._jump_candidate = np.where(jumps, delta, 0.0)
        return bool(jumps.any())

    def _process(self, x: np.ndarray, f: np.ndarray) -> Estimate:
        if self.method == "robust" and self._force_jumps(f) and self.options["jump_restart"]:
            # once full windows have been accumulated, the previous estimate until the window
            # is full again; before, a growing window's solutions are its own: it grows anew
            self._restart_window(regrow=any(s.rows > 0 for s in self._solvers))
        self.n += 1
        g = self._channels.evaluate(x, f)
        if self.method == "robust":
            window = self._robust_step(g, self._row_noise(x, f, g))
            if window is None:  # after hold(): the previous estimate until the window is full
                assert self._last is not None
                return self._last
        else:
            window = self._paper_step(g)
        estimate = self._publish(window)
        if self.method == "robust":
            self._after_publish(window)
        return estimate

    def _publish(self, window_samples: int) -> Estimate:
        canonical, cond, rse, share, statistical = self._combine()
        self._canonical = canonical
        if self.method == "paper":
            # the paper's estimator outputs its estimate from the start (faithful)
            self._held = self.model.from_canonical(canonical)
            ok = self._window_ok(cond, window_samples) and all(
                np.isfinite(v) and self.model.is_physical(k, v) for k, v in canonical.items())
            status = {k: STATUSES[1] if ok else STATUSES[0] for k in self._held}
            return Estimate(self.n * self.dt, dict(self._held), ok, cond, np.nan, window_samples * self.dt,
                            dict(self._held), status)
        good = self._window_ok(cond, window_samples)
        # a growing window's solution rests on its own few rows, whose standard errors are not
        # credible: it is published only once it has stayed within max_uncertainty / 2 of
        # one value while the window grew by a quarter (GROWTH_STEADY); the least-squares
        # solution over full windows is once their rows span a window (its errors account
        # for the overlap of the windows)
        full = window_samples >= self._target
        if full and self._spanned_from < 0:
            # the first full windows' rows rest on one window's samples until they span
            # another: their standard errors are not credible before (as after a change)
            self._spanned_from = self.n + self._target
        spanned = self.n >= self._spanned_from >= 0  # a value not yet published waits for it
        tol = 0.5 * self.options["max_uncertainty"]
        settle = self._settle
        spans = self._window_spans(canonical, window_samples)  # before this sample's counts
        worst = 0.0
        trusted = {}
        for k, hit in self._changed_now.items():  # restarted by the change test: a value it had is changed
            had_value = self._status[k] in (STATUSES[1], STATUSES[3], STATUSES[4])
            self._status[k] = STATUSES[4] if hit and had_value else STATUSES[0]
            self._settled[k] = self._unsettled[k] = self._steady[k] = 0
            self._anchor[k] = self._value[k] = np.nan
            self._fresh[k] = True
            # the rows after a change start a window later (the equation's resume) and rest on
            # one window's samples until they span another: their standard errors are not
            # credible before (a drifting stiffness and the cubic one trade places)
            self._credible_from[k] = self.n + 2 * self._target
        self._changed_now = {}
        for k, v in canonical.items():
            relative = rse[k] if np.isfinite(v) and v != 0 else np.inf
            # ... without the quadrature's bias (RATE_NOISE): what the window rule and the
            # growing window's steadiness go by (a growing window's own rows say little of it)
            steady_relative = statistical[k] if np.isfinite(v) and v != 0 else np.inf
            if self._prior.get(k, 0.0) > 0 and np.isfinite(relative):  # the user's prior size
                relative = relative * abs(v) / max(abs(v), self._prior[k])
            if self._prior.get(k, 0.0) > 0 and np.isfinite(steady_relative):
                steady_relative = steady_relative * abs(v) / max(abs(v), self._prior[k])
            worst = max(worst, relative)
            # without a prior, a term that carries almost nothing of the force balance is not
            # published online however small its error looks (e.g. the mass at low frequency)
            excited = share[k] >= MIN_SHARE or self._prior.get(k, 0.0) > 0
            physical = self.model.is_physical(k, v)
            # a value that an unknown constant force would move is not publishable (OFFSET_SIGMAS)
            offset = any(self._states[j].offset_moved[self._states[j].equation.unknowns.index(key)]
                         for j, key in self._sources[k] if key is not None)
            determined = good and excited and physical and relative <= self.options["max_uncertainty"] and not offset
            steady = good and excited and physical and steady_relative <= self.options["max_uncertainty"] and not offset
            # ... and only while the window spans the plant's dynamics (_window_spans)
            small = determined and spans
            # a held value is withdrawn, too, once the estimate has moved away from it
            held = self._value[k]
            moved = self._status[k] == STATUSES[1] and not abs(v - held) <= LOSS_FACTOR * self.options[
                "max_uncertainty"] * abs(held)
            # ... not for its error before the full windows' rows span a window (not credible yet)
            large = moved or offset or not (good and physical and (
                relative <= LOSS_FACTOR * self.options["max_uncertainty"] or (full and not spanned)))
            self._steady[k] = self._steady[k] + 1 if steady else 0
            if not (np.isfinite(v) and abs(v - self._anchor[k]) <= tol * abs(self._anchor[k])):
                self._anchor[k], self._anchored[k] = v, self.n
            grown = self.n - self._anchored[k] >= GROWTH_STEADY * window_samples
            credible = (full and not self._fresh[k] and (spanned or self._status[k] == STATUSES[1])) or (grown and self.n >= self._credible_from[k])
            self._settled[k] = self._settled[k] + 1 if small and credible else 0
            self._unsettled[k] = self._unsettled[k] + 1 if large else 0
            self._status[k] = _next_status(self._status[k], self._settled[k], self._unsettled[k], settle,
                                           good, share[k])
            trusted[k] = v if self._settled[k] >= settle else np.nan
            if np.isfinite(trusted[k]):
                self._value[k] = v
            if self._status[k] == STATUSES[1]:
                self._fresh[k] = False
        public = self.model.from_canonical(trusted)
        status = {name: self._status[self.model.canonical_name(name)] for name in public}
        self._held = {name: (v if np.isfinite(v) else self._held[name]) if status[name] == STATUSES[1] else np.nan
                      for name, v in public.items()}
        ok = all(s == STATUSES[1] for s in status.values())
        current = self.model.from_canonical(canonical) if good else {k: np.nan for k in self._held}
        std_errors = {name: rse[self.model.canonical_name(name)] * abs(v) if np.isfinite(v) else np.nan
                      for name, v in self._held.items()}
        residual = max((st.residual for st in self._states if np.isfinite(st.residual)), default=np.nan)
        return Estimate(self.n * self.dt, dict(self._held), ok, cond, worst, window_samples * self.dt, current,
                        status, std_errors=std_errors, residual=residual)

    def _window_spans(self, canonical: Mapping[str, float], window_samples: int) -> bool:
        """Whether the window spans the plant's dynamics: a fixed window (the user's), or an
        auto window whose longest length (``max_window``) holds :data:`MIN_WINDOW_PERIODS`
        lowest natural periods: those of the estimate ``canonical`` once its masses and linear
        stiffnesses are steady (their standard errors small for ``settle``), those it was fixed
        from afterwards. While a period parameter is not excited (a quasi-static record, or a
        window too short to see the inertia) the periods are unknown: the window must then hold
        :data:`MIN_UNCHECKED_SAMPLES` samples."""
        if not self._auto:
            return True
        if self._window_fixed:
            return not self._window_capped
        unknown = False
        for k in self._period_names:
            if self._steady[k] < self._settle:
                if self._status[k] != STATUSES[2]:
                    return False  # not yet determined
                unknown = True
        if unknown:
            return window_samples >= MIN_UNCHECKED_SAMPLES
        return not self._capped(canonical)

    def _capped(self, canonical: Mapping[str, float]) -> bool:
        """Whether ``max_window`` holds fewer than :data:`MIN_WINDOW_PERIODS` lowest natural
        periods of ``canonical`` (False when they are not defined)."""
        longest = auto_window(self.model, canonical, self.dt, 0, _UNBOUNDED, MIN_WINDOW_PERIODS)
        return self.capacity < longest < _UNBOUNDED

    def _window_ok(self, cond: float, L: int) -> bool:
        o = self.options
        return bool(cond <= o["max_condition"] and L * self.dt >= o["min_time"] - 1e-12
                    and self.n >= MIN_SAMPLES)

    def _combine(self) -> tuple[dict[str, float], float, dict[str, float], dict[str, float], dict[str, float]]:
        """The canonical values, the condition, their published relative errors, the terms'
        shares, and the errors without the quadrature's bias (what the window rule goes by)."""
        solutions = [dict(zip(st.equation.unknowns, st.theta)) for st in self._states]
        # each unknown's standard error includes the bias of the jumps' rows (JUMP_ERROR), the
        # change of the rows at half the rate beyond the noise (RATE_NOISE), the drift
        # probe's drift to now (DRIFT_BIAS_SIGMAS) and the rows' noise (row_noise); the window
        # rule goes by the jumps' alone
        errors = [dict(zip(st.equation.unknowns, _published_error(st.rse, st.theta, st.jump_shift, st.rate_shift,
                                                                  st.drift_shift, st.noise_shift)))
                  for st in self._states]
        without = [dict(zip(st.equation.unknowns, _published_error(st.rse, st.theta, st.jump_shift,
                                                                   np.zeros_like(st.rse), np.zeros_like(st.rse),
                                                                   np.zeros_like(st.rse))))
                   for st in self._states]
        cond = max(st.cond for st in self._states)
        values, rse = combine_equations(self.model, solutions, errors)
        statistical = combine_equations(self.model, solutions, without)[1]
        return values, cond, rse, self._shares(values), statistical

    def _shares(self, canonical: Mapping[str, float]) -> dict[str, float]:
        """Share of each canonical parameter's term in the force balance of the equations
        it appears in (the largest); an unforced DOF's mass is its equation's right-hand side."""
        out = {}
        for name in canonical:
            found = []
            for j, key in self._sources[name]:
                st = self._states[j]
                found.append(float(st.rhs_share if key is None else st.share[st.equation.unknowns.index(key)]))
            found = [v for v in found if np.isfinite(v)]
            out[name] = max(found) if found else np.nan
        return out

    # -------------------------------------------------------------- robust
    def _row_noise(self, x: np.ndarray, f: np.ndarray, g: np.ndarray) -> np.ndarray:
        """The channels' change when the displacements take a pseudo-random noise of their
        measured level (:mod:`~duffid.identification.row_noise`; 0 for the other channels)."""
        self._noise_level.push(x)
        noisy = self._channels.at(self._noise_level.perturbed(x), f)
        return np.where(self._noisy, noisy - g, 0.0)

    def _robust_step(self, g: np.ndarray, dg: np.ndarray) -> int | None:
        moments, L = self._moments.push(g, self._target)
        noise_moments = self._noise_moments.push(dg, self._target)[0]
        timed_moments = None if self._timed_moments is None else self._timed_moments.push(g, self._target)[0]
        jumps = self._jumps.step(self._moments.n, self._moments.start, self._jump)
        if self._regrow:
            if L < self._target:
                return None
            self._regrow = False
        if L == 0:
            return 0
        E = self.bank.entries(L / self.capacity, moments, g, self.capacity * self.dt)
        dE = self.bank.entries(L / self.capacity, noise_moments, dg, self.capacity * self.dt)
        # the lines' rows (DriftLine) need the time-weighted entries
        lines = L >= self._target and timed_moments is not None
        self._robust_solve([st.assembly(E) for st in self._states], L, self._jump_columns(jumps, L),
                           self._rate_rows(L, lines), [st.assembly(dE) for st in self._states],
                           self._timed(L, timed_moments) if lines else None)
        return L

    def _timed(self, L: int, moments: np.ndarray) -> list[np.ndarray]:
        """Each equation's rows of its unknowns' terms with every sample weighted by its age,
        times the reference length (``S`` of :meth:`DriftLine.rows`), from ``moments`` of one
        power more than the kernels take."""
        t_ref = self.capacity * self.dt
        W = t_ref * self.bank.within(L / self.capacity, moments, t_ref)
        return [st.assembly(W)[0] for st in self._states]

    def _rate_rows(self, L: int, lines: bool) -> list[tuple[np.ndarray, np.ndarray, np.ndarray | None] | None]:
        """Each equation's rows by the rule minus the rows at half the rate over the window
        of ``L`` intervals (``A_d``, ``D_d``, :data:`RATE_NOISE`; the raw terms cancel) and, for
        ``lines``, their time-weighted entries (``S_d``, :meth:`_timed`); None below two
        intervals."""
        rate = self._moments.rate_difference()
        if rate is None:
            return [None] * len(self._states)
        E = self.bank.entries(L / self.capacity, rate, np.zeros(rate.shape[1]), self.capacity * self.dt)
        timed = self._timed(L, self._timed_moments.rate_difference()) if lines else [None] * len(self._states)
        return [st.assembly(E) + (S,) for st, S in zip(self._states, timed)]

    def _jump_columns(self, moments: np.ndarray, L: int) -> list[np.ndarray | None]:
        """Each equation's rows' error column ``J`` on the jumps inside the window
        (:data:`JUMP_ERROR`), None without a jump."""
        if not self._jumps.any:
            return [None] * len(self._states)
        E = self.bank.entries(L / self.capacity, moments, np.zeros(moments.shape[1]), self.capacity * self.dt)
        flat = E.reshape(E.shape[0], -1)
        return [np.concatenate([flat @ rhs for rhs in st.jump_rhs]) for st in self._states]

    def _set_target(self, samples: int) -> None:
        """Set the full window length (samples) and the change test's memory that follows it."""
        self._target = samples
        memory = self.options["change_memory"]
        tau = CHANGE_WINDOWS * samples * self.dt if memory == "auto" else float(memory)
        for s in self._recent:
            s.lam = float(np.exp(-self.dt / tau))
        self._memory = max(1, int(np.floor(tau / self.dt + 0.5)))  # samples of the recent memory

    def _robust_solve(self, systems: list[tuple[np.ndarray, np.ndarray]], L: int,
                      jumps: list[np.ndarray | None], rates: list[tuple[np.ndarray, np.ndarray, np.ndarray | None] | None],
                      noises: list[tuple[np.ndarray, np.ndarray]], timed: list[np.ndarray] | None = None) -> None:
        """Update the estimate with the rows of the current window (length ``L``).

        While the window grows, the current window alone is solved (like the paper's
        fixed t0); once it has its full length, the rows of every full window are
        accumulated (with forgetting), and the change test compares the solution with the
        recent one (see :data:`CHANGE_WINDOWS`). ``noises``: each equation's rows' noise
        ``dA, dD`` (:mod:`~duffid.identification.row_noise`).
        """
        full = L >= self._target
        threshold = self.options["change_threshold"]
        for j, (st, solver, recent, (A, D), J, rate, (dA, dD)) in enumerate(zip(
                self._states, self._solvers, self._recent, systems, jumps, rates, noises)):
            S = None if timed is None else timed[j]  # t_ref times the rows' time-weighted entries
            n = len(st.equation.unknowns)
            if not full:
                R = triangular_factor(np.column_stack([A, D]), n + 1)
                st.theta, st.cond, st.rse, st.share, st.rhs_share = solve_factor(R, len(A), 1.0)
                st.jump_shift = np.zeros(n) if J is None else _jump_shift(R[:n, :n], A.T @ J)
                Q = None if rate is None else rate[1] - rate[0] @ st.theta
                st.rate_shift = np.zeros(n) if Q is None or not np.all(np.isfinite(Q)) else \
                    _jump_shift(R[:n, :n], A.T @ Q)
                st.noise_shift = noise_shift(R, dA.T @ dA, dA.T @ dD)
                continue
            if self.n < st.resume:  # a window that holds samples from before the change
                continue
            line = st.line
            time = (self.n - st.origin) * self.dt  # the rows' time: their window's newest sample
            rows = A if line is None else line.rows(A, time, S)
            previous = st.theta.copy() if line is None else line.theta.copy()
            fit = _relative_fit(solver.R, previous)
            st.residual = _relative_residual(rows, D, previous)
            Q = None
            if rate is not None and np.all(np.isfinite(previous)):  # the rows' change at half the rate
                Q = rate[1] - (rate[0] if line is None else line.rows(rate[0], time, rate[2])) @ previous
            # the noise of the lines' columns: the newest time's (the window is short against it)
            noise = (dA if line is None else line.rows(dA, time), dD)
            solver.update(rows, D, J=J, Q=Q, noise=noise)
            if np.all(np.isfinite(previous)):
                solver.add_scores(rows, D - rows @ previous, BATCH_WINDOWS * self._target)
            if line is None:
                st.theta, st.cond, st.rse, st.share, st.rhs_share = solve_factor(
                    solver.R, accumulated_rows(solver.rows, n, len(A), L), float(L))
                batch = _batch_relative(solver, st.theta)
            else:
                st.cond, st.share, st.rhs_share = line.solve(
                    solver.R, accumulated_rows(solver.rows, line.size, len(A), L), float(L))
                st.theta, st.rse = line.at(time)
                batch = _batch_relative(solver, st.theta, line.combination(time))
            st.nominal = st.rse
            st.rse = np.where(batch > st.rse, batch, st.rse)
            shift = solver.jump_shift()
            st.jump_shift = shift[:n].copy()
            rate_shift = solver.rate_shift()
            st.rate_shift = rate_shift[:n].copy()
            bias = solver.noise_shift()
            st.noise_shift = bias[:n].copy() if np.all(np.isfinite(bias)) else np.full(n, np.inf)
            if line is not None:  # the lines' values now
                st.jump_shift[line.index] += shift[n:] * time
                st.rate_shift[line.index] += rate_shift[n:] * time
                if np.all(np.isfinite(bias)):
                    st.noise_shift[line.index] += bias[n:] * time
            self._offset_probe(j, A, D, L)
            if threshold is not None and self._drift_probe(j, A, D, time, L, S):
                continue
            if threshold is None or self.n < st.recent_resume:  # no test, or the recent estimate restarted
                continue
            recent.update(rows, D, time, noise=noise)
            if line is None:
                theta, rse = recent_solution(recent.R, recent.rows, float(L))
                bias = recent.noise_shift()  # ... with its rows' noise bias
                with np.errstate(divide="ignore", invalid="ignore"):
                    rse = np.where(bias != 0, np.hypot(rse, np.abs(bias / theta)), rse)
                then, then_rse = st.theta, st.nominal
            else:  # both drifting equations' lines where the recent rows are (their mean time)
                st.recent_line.solve_recent(recent.R, recent.rows, float(L))
                theta, rse = st.recent_line.at(recent.mean_time)
                then, then_rse = line.at(recent.mean_time)
            st.departure = _departure(then, then_rse, theta, rse)
            # a departure matters when significant and larger than a published value may move;
            # a smaller one beyond that band matters once it lasts the recent memory (a drift)
            wide = np.abs(theta - then) > LOSS_FACTOR * self.options["max_uncertainty"] * np.abs(then)
            # ... and only while a change of it alone explains the recent rows (CHANGE_ALONE_SHARE)
            wide &= _alone(recent.R, st.theta if line is None else line.theta, CHANGE_ALONE_SHARE)[:len(theta)]
            departed = (st.departure > threshold) & wide
            drifted = (st.departure > CHANGE_DRIFT_SHARE * threshold) & wide
            st.departed = st.departed + 1 if departed.any() else 0
            st.drifted = st.drifted + 1 if drifted.any() else 0
            st.surprised = st.surprised + 1 if st.residual > CHANGE_SURPRISE * fit else 0  # not while NaN
            if st.departed >= self._settle:
                self._restart(j, departed)
            elif st.drifted >= self._memory:
                self._restart(j, drifted)
            elif st.surprised >= self._settle:  # the recent estimate starts afresh after it
                recent.reset()
                st.departure[:] = 0.0
                st.departed = st.drifted = st.surprised = 0
                st.recent_resume = self.n + self._target

    @staticmethod
    def _new_offset_probe(st: _EquationState, lam: float) -> _QRLeastSquares | None:
        """The offset probe's least squares of an equation (None: it has a constant already)."""
        return _QRLeastSquares(len(st.equation.unknowns) + 1, lam) if st.offset_probed else None

    @staticmethod
    def _new_variation(st: _EquationState, lam: float) -> _QRLeastSquares | None:
        """The offset probe's rows' right-hand side against a constant (FORCE_VARIATION)."""
        return _QRLeastSquares(1, lam) if st.offset_probed else None

    def _constant_entries(self, L: int) -> np.ndarray:
        """The rows' entries of a constant channel (1) over a window of ``L`` intervals: its
        moments are the quadrature's power sums (no samples needed)."""
        if self._one[0] != L:
            N = self.capacity
            q = np.arange(self.bank.degree + 1, dtype=float)
            powers = ((np.arange(L + 1)[:, None] / N) ** q[None, :]).sum(axis=0)
            moments = (powers + self._moments.corrections(L).sum(axis=0)) / N
            self._one = (L, self.bank.entries(L / N, moments[:, None], np.ones(1), N * self.dt)[:, 0, 0])
        return self._one[1]

    def _offset_probe(self, j: int, A: np.ndarray, D: np.ndarray, L: int) -> None:
        """The offset probe (:data:`OFFSET_SIGMAS`) of equation ``j`` with one of the rows
        ``A, D``: marks the unknowns that an unknown constant force would move."""
        st, probe = self._states[j], self._offsets[j]
        if probe is None:
            return
        r = st.offset_fed % len(A)  # one row per sample, in turn
        st.offset_fed += 1
        one = self._constant_entries(L)[r:r + 1]
        probe.update(np.column_stack([A[r:r + 1], one]), D[r:r + 1])
        variation = self._variations[j]
        variation.update(one[:, None], D[r:r + 1])
        n, R = len(st.theta), probe.R
        dof = probe.rows - (n + 1)
        st.offset_moved[:] = False
        # the rows' right-hand side beyond a constant, relative to its constant part
        varies = abs(variation.R[1, 1]) > FORCE_VARIATION * abs(variation.R[0, 1])
        if dof <= 0 or not varies or not np.all(np.diag(R)[:n + 1] != 0):
            return
        constant = R[n, n + 1] / R[n, n]
        error = abs(R[n + 1, n + 1]) * np.sqrt(float(L) / dof) / abs(R[n, n])
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            plain = _back_substitution(R[:n, :n], R[:n, n + 1])
            moved = _back_substitution(R[:n, :n], R[:n, n]) * constant
            st.offset_moved[:] = (abs(constant) > OFFSET_SIGMAS * error) & (
                np.abs(moved) > self.options["max_uncertainty"] * np.abs(plain))

    @staticmethod
    def _new_probe(st: _EquationState, lam: float) -> _QRLeastSquares | None:
        """The drift probe's least squares of an equation (None: no unknown fits a line)."""
        return None if st.probe_line is None else _QRLeastSquares(st.probe_line.size, lam)

    def _drift_probe(self, j: int, A: np.ndarray, D: np.ndarray, time: float, L: int, S: np.ndarray) -> bool:
        """The drift probe (:data:`DRIFT_SIGMAS`) of equation ``j`` with one of the rows ``A, D``
        at ``time``; True when it restarted the equation.

        The rates need no full inverse: in the factor ``[[R11, R12], [0, R22]]`` of the columns
        ``[A, t A_i]``, the rows of the inverse that give the rates are ``[0, R22^-1]``."""
        st, probe, line = self._states[j], self._probes[j], self._states[j].probe_line
        if probe is None:
            return False
        r = st.probe_fed % len(A)  # one row per sample, in turn
        st.probe_fed += 1
        probe.update(line.rows(A[r:r + 1], time, S[r:r + 1]), D[r:r + 1], time)
        st.drift_shift[:] = 0.0
        n, index, p = len(line.drifting), line.index, line.size
        R, dof = probe.R, probe.rows - p
        hit = np.zeros(len(index), dtype=bool)
        if dof > 0 and np.all(np.diag(R)[:p] != 0):
            with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
                theta = _back_substitution(R[:p, :p], R[:p, p])
                rates, ends = theta[n:], theta[index] + theta[n:] * time
                errors = abs(R[p, p]) * np.sqrt(float(L) / dof) * np.linalg.norm(np.linalg.inv(R[n:p, n:p]), axis=1)
                band = LOSS_FACTOR * self.options["max_uncertainty"]
                # alone: the rate's column orthogonal to the constants explains the lines' gain (_alone)
                columns, gain = R[n:p, n:p], R[n:p, p]
                alone = (columns.T @ gain) ** 2 >= CHANGE_ALONE_SHARE * np.sum(columns**2, axis=0) * (gain @ gain)
                # the line's end is further from the accumulated value than that may move
                stale = np.abs(ends - st.theta[index]) > band * np.abs(ends)
                # the drift the rates show beyond DRIFT_BIAS_SIGMAS errors, from the rows' mean
                # time to now (half a window after the newest rows): a bias of the constants, of
                # those whose rate alone explains the lines' gain (a joint slide of every unknown,
                # as in a free decay that cannot tell their common scale, is no drift)
                span = abs(time + 0.5 * L * self.dt - probe.mean_time)
                bias = np.where(alone, rates**2 - (DRIFT_BIAS_SIGMAS * errors) ** 2, 0.0)
                st.drift_shift[index] = np.where(bias > 0, span * np.sqrt(np.where(bias > 0, bias, 0.0)), 0.0)
                if st.line is not None:  # a line's value is that of now already
                    st.drift_shift[st.line.drifting] = 0.0
                hit = ((np.abs(rates) > DRIFT_SIGMAS * errors) & stale & alone
                       & (st.nominal[index] <= self.options["max_uncertainty"]))  # (BATCH_WINDOWS)
        if st.line is not None:  # already lines
            hit &= ~st.line.drifting[index]
        st.probed = st.probed + 1 if hit.any() else 0
        if st.probed < self._settle:
            return False
        departed = np.zeros(n, dtype=bool)
        departed[index[hit]] = True
        self._restart(j, departed)
        return True

    def _restart(self, j: int, departed: np.ndarray) -> None:
        """Equation ``j``'s data contradict its estimate (the unknowns ``departed``): forget
        them, mark its parameters ``changed`` (the departed) or ``uncertain``; the departed
        unknowns are lines in time from then on (:class:`DriftLine`)."""
        st = self._states[j]
        keys = {key: bool(d) for key, d in zip(st.equation.unknowns, departed)}
        for name, sources in self._sources.items():
            for k, key in sources:
                if k == j:
                    hit = bool(np.any(departed)) if key is None else keys[key]
                    self._changed_now[name] = self._changed_now.get(name, False) or hit
        st.clear()
        st.resume = st.recent_resume = st.origin = self.n + self._target
        drifting = np.zeros(len(departed), dtype=bool) if st.line is None else st.line.drifting.copy()
        for i in np.flatnonzero(np.asarray(departed, dtype=bool) & ~drifting):
            if len(drifting) + np.count_nonzero(drifting) < MAX_LINE_UNKNOWNS:
                drifting[i] = True
        if drifting.any():
            st.line, st.recent_line = DriftLine(drifting), DriftLine(drifting)
        size = len(drifting) if st.line is None else st.line.size
        self._solvers[j] = _QRLeastSquares(size, self._solvers[j].lam)
        self._recent[j] = _QRLeastSquares(size, self._recent[j].lam)
        self._probes[j] = self._new_probe(st, self._solvers[j].lam)
        self._offsets[j] = self._new_offset_probe(st, self._solvers[j].lam)
        self._variations[j] = self._new_variation(st, self._solvers[j].lam)

    def _after_publish(self, L: int) -> None:
        """Fix the auto window once the masses and linear stiffnesses (the natural periods)
        and every excited parameter have kept a small standard error for ``settle`` s.

        While the window grows, a period parameter's latest steady value is remembered: one
        that a longer window no longer excites (the inertia of a plant driven below its
        resonance shows only in short windows) counts as known at that value. Without it the
        window grew to ``max_window`` whenever the mass was steady only before the stiffness
        was: ``benchmarks/tracking.py``'s quasi-static plant then showed a 10 % drop of its
        stiffness 12.7 % off for 5 s (the change test remembers two windows). The window is
        never fixed shorter than it has grown: a sweep at 30 dB fixed at 1.4 natural periods
        instead published its damping 26 % off with a stated 1 % (``benchmarks/trust.py``'s
        structure sweep; its rows' noise, see the notes)."""
        if not self._auto or self._window_fixed:
            return
        canonical = self._canonical
        for k in self._period_names:
            if self._steady[k] >= self._settle:
                self._period_seen[k] = canonical[k]
        if not self._window_known():
            return
        self._window_fixed = True
        seen = {k: v for k, v in self._period_seen.items() if self._steady[k] < self._settle}
        canonical = {**canonical, **seen}
        self._set_target(auto_window(self.model, canonical, self.dt, L, self.capacity,
                                     self.options["window_periods"]))
        # the longest window (max_window) must hold MIN_WINDOW_PERIODS lowest natural periods
        self._window_capped = self._capped(canonical)

    def _window_known(self) -> bool:
        """Every parameter that sets a natural period (masses, linear stiffnesses) steady (its
        standard error small for ``settle`` s) or no longer excited after it was, every other
        parameter steady or not excited."""
        return all(self._steady[k] >= self._settle or (self._status[k] == STATUSES[2] and (
            k not in self._period_names or np.isfinite(self._period_seen[k]))) for k in self._steady)

    # -------------------------------------------------------------- paper
    def _paper_setup(self) -> None:
        """Integrator banks of eqs. (16)-(17) (inputs tau^j g, j = 0..2) and of eq. (19)."""
        quadrature = self.options["quadrature"]
        n_ch = len(self.channels)
        self._paper = []
        for st in self._states:
            n_rows = len(st.equation.unknowns)
            regressors = Integrators(3 * n_ch, n_rows + 1, self.dt, quadrature)
            determinants = Integrators(n_rows + 1, 2, self.dt, quadrature)
            self._paper.append((regressors, determinants))

    def _paper_reset(self) -> None:
        for banks in self._paper:
            for bank in banks:
                bank.reset()

    def _paper_rows(self, y: np.ndarray, n_rows: int) -> np.ndarray:
        """Entries E[row, order, channel] of eq. (16)-(17) from the integrator outputs."""
        n_ch = len(self.channels)
        Y = y.reshape(y.shape[0], 3, n_ch)  # [k-fold integral, power j of tau, channel]
        E = np.zeros((n_rows, 3, n_ch))
        for p in range(n_rows):
            # order 2: tau^2 g - 4 I(tau g) + 2 II(g), then p more integrals
            E[p, 2] = Y[p, 2] - 4.0 * Y[p + 1, 1] + 2.0 * Y[p + 2, 0]
            E[p, 1] = Y[p + 1, 2] - 2.0 * Y[p + 2, 1]
            E[p, 0] = Y[p + 2, 2]
        return E

    def _paper_step(self, g: np.ndarray) -> int:
        tau = self.n * self.dt
        u = np.concatenate([g, tau * g, tau**2 * g])
        gamma = self.options["gamma"]
        for st, (integ, det_integ) in zip(self._states, self._paper):
            n_rows = len(st.equation.unknowns)
            y = integ.push(u)
            A, D = st.assembly(self._paper_rows(y, n_rows))
            st.theta = filtered_cramer(A, D, det_integ, gamma, tau, self.options["sign_in_numerator"])
            st.cond = equilibrated_condition(A)
        return self.n

    # -------------------------------------------------------------- state
    def identify_record(self, record: Record) -> "Identification":
        """Run the identifier over a record sample by sample (see also :func:`identify`)."""
        check_record(record, self.model, self.dt)
        self.reset()
        history = []
        for xi, fi in zip(record.x, record.f):
            history.append(self.update(xi, fi))
        last = self.flush()
        if last is not None:
            history[-1] = last
        result = Identification.from_estimates(self, record, history)
        result.outliers = self.outliers
        return result


def filtered_cramer(A: np.ndarray, D: np.ndarray, filters: Integrators, gamma: float, tau: float,
                    sign_in_numerator: bool) -> np.ndarray:
    """Eq. (19) for one sample: Cramer determinants of ``A theta = D``, then the ratio of
    the doubly integrated, exponentially weighted ``|Delta_i|`` and ``|Delta|`` (with the
    signs of the current sample), or, with ``sign_in_numerator``, of ``Delta_i sgn(Delta)``.

    ``filters`` integrates the ``len(D) + 1`` weighted determinants twice; NaN until the
    filtered ``|Delta|`` is positive.
    """
    m = len(D)
    delta = np.linalg.det(A)
    deltas = np.empty(m)
    for i in range(m):
        Ai = A.copy()
        Ai[:, i] = D
        deltas[i] = np.linalg.det(Ai)
    num = deltas * np.sign(delta) if sign_in_numerator else np.abs(deltas)
    weight = np.exp(-gamma * tau)
    z = filters.push(np.concatenate([weight * num, [weight * abs(delta)]]))[2]
    if z[m] > 0:
        ratio = z[:m] / z[m]
        return ratio if sign_in_numerator else np.sign(deltas) * np.sign(delta) * ratio
    return np.full(m, np.nan)


def equilibrated_condition(A: np.ndarray) -> float:
    """Condition number of ``A`` after scaling its rows and columns to unit norm (the
    condition the online methods compare with ``max_condition``)."""
    col = np.linalg.norm(A, axis=0)
    row = np.linalg.norm(A, axis=1)
    if not (np.all(col > 0) and np.all(row > 0)):
        return np.inf
    As = A / col
    As = As / np.linalg.norm(As, axis=1)[:, None]
    with np.errstate(all="ignore"):
        return float(np.linalg.cond(As))


def auto_window(model: Chain, canonical: Mapping[str, float], dt: float, current: int,
                capacity: int, periods: float) -> int:
    """Window length (samples) of ``periods`` lowest natural periods of the estimate.

    Never shorter than the current window nor longer than the buffer ``capacity``; if the
    estimate has no positive linear stiffness the window keeps its capacity.
    """
    try:
        omega = model.linear_natural_frequencies(canonical)
    except (KeyError, ValueError, np.linalg.LinAlgError, ZeroDivisionError):
        return capacity
    omega = omega[np.isfinite(omega) & (omega > 0)]
    if not len(omega):
        return capacity
    samples = int(round(periods * 2.0 * np.pi / omega.min() / dt))
    return int(min(max(samples, current), capacity))


def combine_equations(model: Any, solutions: list[dict[str, float]],
                      errors: list[dict[str, float]] | None = None) -> tuple[dict[str, float], dict[str, float]]:
    """Canonical parameters (and their relative standard errors) from the solutions of the
    model's equations (:meth:`~duffid.models.chain.Chain.combine_solutions`)."""
    return model.combine_solutions(solutions, errors)


# ---------------------------------------------------------------------- results
@dataclass
class Identification:
    """Result of :func:`identify` on a record.

    Attributes
    ----------
    model, method : str
        Model and method names.
    parameters : dict
        Final estimates (public names); NaN if the record never identified the model.
    t : ndarray
        Sample times [s].
    history : dict of ndarray
        Estimate of each parameter at each sample (NaN before identification).
    condition : ndarray
        Conditioning figure at each sample.
    identified : ndarray of bool
        Identified flag at each sample.
    t_identified : float or None
        First time the flag was set (checked by :func:`duffid.identification.trust.identify`: the end of
        the record when the estimator integrated it in one window).
    window : float
        Final window length [s].
    options : dict
        Method options used.
    source : str
        Where the record came from.
    estimates : dict
        The estimator's final solution (public names), whether the record supports it or
        not; ``parameters`` holds the values that passed the checks.
    assessment : duffid.identification.trust.Assessment or None
        What the record supports (status, uncertainty and fit per parameter, notes), set by
        :func:`duffid.identification.trust.identify`; None for a bare estimator run (:func:`estimate`, or
        ``identify(check=False)``), whose ``parameters`` are the estimator's final values,
        unchecked.
    online_status : dict
        The online estimator's own status of each parameter at the last sample (see
        :data:`STATUSES`); empty for the buffered methods.
    status : dict (read-only)
        The status that goes with ``parameters``: the assessment's where the record was
        checked (a value is shown only where it says ``published``), else ``online_status``.
    outliers : list of dict
        Displacement samples the online estimator excluded as isolated outliers
        (:attr:`OnlineIdentifier.outliers`).
    samples : int or None
        Samples of the record (None: one per entry of ``t``; a fit of the whole record keeps
        only its final value there).
    """

    model: str
    method: str
    parameters: dict[str, float]
    t: np.ndarray
    history: dict[str, np.ndarray]
    condition: np.ndarray
    identified: np.ndarray
    t_identified: float | None
    window: float
    options: dict[str, Any] = field(default_factory=dict)
    source: str = ""
    estimates: dict[str, float] = field(default_factory=dict)
    assessment: Any = None
    online_status: dict[str, str] = field(default_factory=dict)
    outliers: list[dict[str, Any]] = field(default_factory=list)
    samples: int | None = None

    @property
    def status(self) -> dict[str, str]:
        """The status of each value of ``parameters``: the assessment's for a checked record,
        else the online estimator's (``online_status``)."""
        return dict(self.assessment.status) if self.assessment is not None else dict(self.online_status)

    @classmethod
    def from_estimates(cls, ident: OnlineIdentifier, record: Record, estimates: list[Estimate]) -> "Identification":
        names = ident.parameter_names
        history = {name: np.array([e.parameters[name] for e in estimates]) for name in names}
        flags = np.array([e.identified for e in estimates])
        final = estimates[-1].current if estimates[-1].current is not None else estimates[-1].parameters
        return cls(
            model=ident.model.name, method=ident.method,
            parameters={name: float(history[name][-1]) for name in names},
            t=record.t - record.t[0], history=history,
            condition=np.array([e.condition for e in estimates]), identified=flags,
            t_identified=float(record.t[np.argmax(flags)] - record.t[0]) if flags.any() else None,
            window=estimates[-1].window, options=dict(ident.options), source=record.source,
            estimates={name: float(final[name]) for name in names},
            online_status=dict(estimates[-1].status or {}),
        )

    def errors(self, truth: Mapping[str, float]) -> dict[str, float]:
        """Relative errors of the final estimates against ``truth`` (in %)."""
        return {k: 100.0 * (self.parameters[k] - v) / v for k, v in truth.items() if k in self.parameters and v}

    def time_within(self, truth: Mapping[str, float], tolerance: float) -> dict[str, float | None]:
        """First time after which each estimate stays within ``tolerance`` (relative) of the truth."""
        out: dict[str, float | None] = {}
        for name, value in truth.items():
            h = self.history[name]
            bad = ~(np.abs(h - value) <= tolerance * abs(value))
            if bad.all():
                out[name] = None
            else:
                last_bad = np.flatnonzero(bad)
                out[name] = float(self.t[0]) if not len(last_bad) else (
                    float(self.t[last_bad[-1] + 1]) if last_bad[-1] + 1 < len(self.t) else None)
        return out

    @property
    def is_identified(self) -> bool:
        """True when every parameter is published at the end of the record (checked), or
        the estimator's own flag at the last sample (``check=False``)."""
        if self.assessment is not None:
            return self.assessment.identified
        return bool(self.identified[-1]) if len(self.identified) else False

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary: model, method, parameters (published values only, null
        otherwise), status, uncertainty, fit, notes, identified, window, ..."""
        def clean(v: float) -> float | None:
            return float(v) if np.isfinite(v) else None
        out = {
            "model": self.model,
            "method": self.method,
            "parameters": {k: clean(v) for k, v in self.parameters.items()},
            "identified": self.is_identified,
        }
        if self.assessment is not None:
            out.update(self.assessment.to_dict())
        elif self.online_status:
            out["status"] = dict(self.online_status)
        if self.outliers:
            out["outliers_excluded"] = [dict(o) for o in self.outliers]
        out.update({
            "t_identified": self.t_identified if self.is_identified else None,
            "condition": clean(self.condition[-1]) if len(self.condition) else None,
            "window": self.window,
            "samples": int(len(self.t)) if self.samples is None else int(self.samples),
            "source": self.source,
            "options": {k: v for k, v in self.options.items()},
        })
        return out

    def to_json(self) -> str:
        """:meth:`to_dict` as a JSON string."""
        return json.dumps(self.to_dict())


def check_record(record: Record, model: Any, dt: float | None = None) -> None:
    """Check that ``record`` fits ``model`` (anything with ``name``, ``n_dof``, ``n_forces``)."""
    record.require_displacement(f"the algebraic identification of {model.name}")
    if record.n_dof != model.n_dof:
        raise RecordError(f"{record.source}: model {model.name} needs {model.n_dof} displacement column(s), "
                          f"the record has {record.n_dof}")
    if record.n_forces != model.n_forces:
        raise RecordError(f"{record.source}: model {model.name} needs {model.n_forces} force column(s), "
                          f"the record has {record.n_forces}")
    record.require_samples(2 * MIN_SAMPLES, f"identification of {model.name}")
    if dt is not None and abs(record.dt - dt) > 1e-9 * dt:
        raise RecordError(f"{record.source}: sampled every {record.dt} s, the identifier expects {dt} s")
