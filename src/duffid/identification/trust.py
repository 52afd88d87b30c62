"""Whether an identified model may be published: the record is checked against the model.

The estimator always produces numbers; this module decides which of them the data support.
Nothing here depends on the parameter values of the model class (the paper's plant): every
scale comes from the record itself.

Checks, in order (:func:`assess`):

1. **Sampling.** The highest frequency the displacement carries (:func:`content_frequency`,
   99 % of its power above the noise floor) and the identified natural frequencies give the
   samples per period. :func:`identify` upsamples a record with fewer
   than :data:`SAMPLES_PER_PERIOD` (band-limited, the Silverbox rule) and says so; below
   :data:`MIN_SAMPLES_PER_PERIOD` nothing is published. The quadrature's remaining bias
   enters each stated uncertainty.
2. **The model explains the record.** The identified model, driven by the measured force
   from a fitted initial state, must reproduce the measured displacement (in segments of
   :data:`SEGMENT_PERIODS` natural periods, each started from the measured state, with
   :class:`duffid.identification.refine.OdeSimulator`): its normalised RMS error, beyond what the
   measurement noise alone explains (:func:`noise_level`), must stay below
   :data:`SIMULATION_TOLERANCE`. A record the model does not explain (a sensor offset,
   swapped columns, unmodelled friction, the wrong model) publishes nothing.
3. **Each parameter is determined.** Its standard error comes from the record: the
   identification is repeated on :data:`REPLICATES` copies of the record with measurement
   noise of the measured level added (a parametric bootstrap: coloured residuals, the
   estimator's own windows and its nonlinearity are all accounted for), and from every
   second sample (the quadrature's bias, of first order where the force jumps). Its term's share of
   the force balance (:func:`term_shares`) tells a parameter the record does not excite
   from one it excites but cannot pin down.
4. **Refinement.** When the algebraic (equation-error) estimate leaves an excited value
   undetermined, all values are refined by output-error least squares
   (:func:`duffid.identification.refine.refine` in stretches of :data:`SEGMENT_PERIODS` natural periods,
   each from its own fitted state), stated errors from its covariance and its change at half
   the sampling rate; kept only when it agrees with the algebraic values within 3 combined
   standard errors.

Status of each parameter (:data:`STATUSES`):

``published``
    the model explains the record and the relative standard error is at most
    ``max_uncertainty``: the value is shown;
``not excited``
    its term carries less than :data:`MIN_SHARE` of the force balance: the record says
    little about it (e.g. a cubic stiffness at small amplitude);
``uncertain``
    excited, but the record does not determine it well enough, or the model does not
    explain the record;
``lost``
    (online estimators) it was published earlier in the run and is no longer trustworthy.

Sensor offsets (``identify(..., offsets=...)``, CLI ``--offset``, :data:`OFFSETS`):

``force``
    an unknown constant force per DOF, ``c1``, ``c2``, ... on the left of the equation
    (``m x'' + ... + c1 = f``: the force sensor reads ``c1`` at zero force);
``displacement``
    the displacement sensor reads ``x_meas = x + x0`` (one-DOF models with a cubic spring:
    :class:`~duffid.models.chain.Duffing1`, :class:`~duffid.models.chain.DuffingCircuit`, a one-DOF
    chain of orders 1, 3). In the measured coordinate the spring becomes
    ``a1 x + a2 x^2 + a3 x^3`` plus a constant, so the chain of orders 1, 2, 3 with a
    constant is identified and mapped back (:func:`displacement_offset_values`):
    ``x0 = -a2 / (3 a3)``, ``kp = a3``, ``k = a1 - 3 a3 x0^2`` and the force bias
    ``c1 = constant + k x0 + kp x0^3``. The bootstrap repeats the identification and the
    mapping, so the stated uncertainties are those of the mapped values, and the simulation
    check compares the physical model with the measured displacement minus ``x0``. Only the
    cubic term separates ``x0`` from a force bias (without it both are a constant force):
    when the cubic spring carries less than :data:`MIN_SHARE` of the force balance, ``x0``
    is not published and only the combined constant force ``c1`` is;
``both``
    both, the force bias reported as a parameter too (with ``displacement`` it is
    estimated as well, since a force bias cannot be excluded, and reported in
    ``fit["offsets"]``).

An offset is published when its relative standard error is at most ``max_uncertainty``
or its standard error is at most ``max_uncertainty`` of the signal's spread (the
displacement's standard deviation for ``x0``, the force's RMS for ``c``): an offset
that is zero is then published as zero within its standard error.
"""
from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

import numpy as np

from ..data.record import Record
from ..errors import BuildError, InputError, RecordError
from ..models.chain import Chain, Duffing1, Duffing2
from ..models.registry import IdentifiableModel
from .batch import estimate
from .c_core import CIdentifier
from .engine import (
    MIN_SHARE,
    OUTLIER_RANGE,
    OUTLIER_SIGMAS,
    STATUSES,
    Identification,
    check_record,
)
from .options import ENGINES, ONLINE_METHODS, check_options, default_options
from .refine import OdeSimulator, canonical_from_public, fit_initial_state, refine, stretches, upsample

__all__ = [
    "identify", "run_estimator", "ENGINES", "ASSESSMENT_UNCERTAINTY", "STATUSES", "SAMPLES_PER_PERIOD", "SIMULATION_TOLERANCE", "MIN_SHARE", "REPLICATES",
    "Assessment", "assess", "noise_level", "content_frequency", "samples_per_period", "upsampling_factor",
    "upsampling_needed", "upsampled", "natural_frequency", "term_shares", "isolated_outliers",
    "OFFSETS", "DISPLACEMENT_OFFSET", "displacement_offset_values",
]

#: Samples per period of the highest frequency in the displacement that identification
#: works at: a record with fewer is upsampled to this many (the Silverbox rule). Measured
#: (noise-free 10 Hz plant, multisine to 25 Hz): the damping is biased by 7 % at 8 samples
#: per period of the highest frequency, 0.3 % at 20, 0.02 % at 40 and 3e-6 at 120.
SAMPLES_PER_PERIOD = 50.0
#: Below this many samples per period no value is published (the integrals are biased).
MIN_SAMPLES_PER_PERIOD = 20.0
#: Largest normalised RMS simulation error beyond the noise for a model that explains the record.
SIMULATION_TOLERANCE = 0.05
#: A simulation of the identified model that misses the record by more than this beyond the
#: noise (normalised RMS; and by more than a quarter of the noise level) has its published
#: values cross-checked by the output-error estimate, and a value the two estimates disagree on
#: beyond their stated errors gets their difference as its stated error. Measured on
#: noise-free records: a record the model describes is missed by less than 3e-4 (robust
#: method); the buffered methods' truncation bias of 0.2-3 % in the values shows as 3e-3 to 2.4e-2.
CONSISTENCY_EXCESS = 1e-3
#: Noisy replicates of the record behind each standard error.
REPLICATES = 8
#: Records of at least this many samples show a progress bar while their replicates run
#: (about two seconds on the C core).
PROGRESS_SAMPLES = 50_000
#: The relative standard error is never stated below this (rounding).
UNCERTAINTY_FLOOR = 1e-5
#: Quadrature and interpolation errors of the integrated force balance, as a fraction of it:
#: ``BALANCE_FLOOR + QUADRATURE_BIAS / spp**4`` (spp: samples per period of the highest
#: frequency). A parameter's stated error is at least that divided by its term's share
#: (measured on noise-free records: 3e-6 of the balance at 80 samples per period, 1.3e-5 at
#: 40, 2e-4 at 20).
BALANCE_FLOOR = 1e-5
QUADRATURE_BIAS = 50.0
#: Sensor offsets :func:`identify` can model (``offsets=``, CLI ``--offset KIND``), with the
#: words the CLI's help shows; see the module documentation.
OFFSETS: dict[str, str] = {
    "force": "a constant force bias per DOF (c1, c2, ...; the default of a bare --offset)",
    "displacement": "a displacement-sensor offset x0, x_meas = x + x0 (one DOF with a cubic spring: "
                    "duffing1, circuit, chain --n-dof 1 --orders 1,3)",
    "both": "a force bias and a displacement-sensor offset",
}
#: Name of the displacement sensor's offset among the parameters (``x_meas = x + x0``).
DISPLACEMENT_OFFSET = "x0"


@dataclass
class Assessment:
    """What the record supports, per parameter and for the whole model.

    Attributes
    ----------
    status : dict
        Parameter name -> one of :data:`STATUSES`.
    uncertainty : dict
        Parameter name -> relative standard error (NaN where it could not be determined).
    share : dict
        Parameter name -> share of its term in the force balance (NaN where unknown).
    fit : dict
        ``simulation_nrmse`` (normalised RMS error of the simulated displacement, the largest
        over the DOFs), ``noise_nrmse`` (the part the measurement noise explains),
        ``explained`` (bool), ``samples_per_period``, ``content_hz`` (highest frequency in
        the displacement), ``natural_hz`` (identified), ``upsampled`` (factor applied
        before identification, 1 if none), ``noise`` (displacement noise level per DOF),
        and when offsets are modelled ``offsets``: per offset (``c1``, ..., ``x0``) its
        ``value`` (None unless published), ``standard_error`` (absolute, in the parameter's
        unit) and ``status``.
        When the algebraic estimate left excited values undetermined and the output-error
        refinement was run, ``refinement``: its ``values``, stated ``uncertainty``,
        ``half_rate_change``, ``rms``, ``stretches``, ``evaluations`` and whether it was
        ``accepted``.
    notes : list of str
        What was found, in plain words (what is missing when a value is not published).
    values : dict
        The values assessed (public names): the estimator's, or the refinement's when it
        was accepted; ``uncertainty`` and ``status`` are theirs.
    """

    status: dict[str, str]
    uncertainty: dict[str, float]
    share: dict[str, float]
    fit: dict[str, Any]
    notes: list[str] = field(default_factory=list)
    values: dict[str, float] = field(default_factory=dict)

    @property
    def identified(self) -> bool:
        """True when every parameter is published."""
        return bool(self.status) and all(s == "published" for s in self.status.values())

    def published(self, values: Mapping[str, float]) -> dict[str, float]:
        """``values`` with NaN for every parameter that is not published."""
        return {k: (float(v) if self.status.get(k) == "published" else math.nan) for k, v in values.items()}

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready ``status``, ``uncertainty``, ``share``, ``fit`` and ``notes``."""
        def clean(v: Any) -> Any:
            if isinstance(v, (bool, np.bool_)):
                return bool(v)
            if isinstance(v, (int, np.integer)):
                return int(v)
            if isinstance(v, (float, np.floating)):
                return float(v) if np.isfinite(v) else None
            if isinstance(v, (list, tuple, np.ndarray)):
                return [clean(u) for u in v]
            if isinstance(v, Mapping):
                return {k: clean(u) for k, u in v.items()}
            return v
        return {
            "status": dict(self.status),
            "uncertainty": {k: clean(v) for k, v in self.uncertainty.items()},
            "share": {k: clean(v) for k, v in self.share.items()},
            "fit": {k: clean(v) for k, v in self.fit.items()},
            "notes": list(self.notes),
        }


# ---------------------------------------------------------------------- record figures
def _quantisation_step(column: np.ndarray) -> float:
    """Step of the grid the values lie on (an encoder's resolution), 0 if there is none."""
    steps = np.abs(np.diff(column))
    steps = steps[steps > 0]
    if len(steps) < 10:
        return 0.0
    q = float(np.min(steps))
    ratio = steps / q
    return q if np.all(np.abs(ratio - np.round(ratio)) <= 1e-6 * np.maximum(ratio, 1.0)) else 0.0


def noise_level(x: np.ndarray) -> np.ndarray:
    """Standard deviation of the white measurement noise on each column of ``x``.

    From the fourth differences (which remove a smooth signal up to ``(omega dt)^4``),
    robustly (median absolute deviation), combined with the quantisation noise ``q/sqrt(12)``
    of values on a grid of step ``q``. A smooth signal sampled coarsely leaks into the figure,
    which then overstates the noise (the safe side).
    """
    x = np.asarray(x, dtype=float).reshape(len(x), -1)
    out = np.zeros(x.shape[1])
    for j in range(x.shape[1]):
        d = np.diff(x[:, j], n=4)
        mad = float(np.median(np.abs(d - np.median(d)))) if len(d) else 0.0
        sigma = 1.4826 * mad / math.sqrt(70.0)
        q = _quantisation_step(x[:, j])
        out[j] = math.hypot(sigma, q / math.sqrt(12.0))
    return out


#: Periodogram bins below this multiple of the white-noise floor count as noise.
NOISE_BINS = 5.0


def content_frequency(x: np.ndarray, dt: float, *, fraction: float = 0.99,
                      noise: np.ndarray | None = None) -> float:
    """Highest frequency [Hz] below which ``fraction`` of the displacement's signal power lies.

    The displacement (each column, linear trend removed, Hann window) is transformed; the
    flat power of white noise of level ``noise`` (default :func:`noise_level`) is removed
    before the cumulative power is taken. The largest figure over the columns.
    """
    x = np.asarray(x, dtype=float).reshape(len(x), -1)
    n = x.shape[0]
    if n < 8:
        return math.nan
    sigma = noise_level(x) if noise is None else np.asarray(noise, dtype=float)
    w = np.hanning(n)
    freqs = np.fft.rfftfreq(n, dt)
    t = np.arange(n)
    best = 0.0
    for j in range(x.shape[1]):
        y = x[:, j] - np.polyval(np.polyfit(t, x[:, j], 1), t)
        power = np.abs(np.fft.rfft(y * w)) ** 2
        floor = sigma[j] ** 2 * np.sum(w**2)
        # a bin is signal only above NOISE_BINS x the mean noise power: white noise's
        # periodogram scatters (exponentially) around its mean, and the positive scatter of
        # thousands of noise bins would otherwise pass for high-frequency content
        signal = np.where(power > NOISE_BINS * floor, power - floor, 0.0)
        signal[0] = 0.0
        total = signal.sum()
        if total <= 0:
            continue
        k = int(np.searchsorted(np.cumsum(signal), fraction * total))
        best = max(best, float(freqs[min(k, len(freqs) - 1)]))
    return best if best > 0 else math.nan


def samples_per_period(fs: float, *frequencies: float) -> float:
    """``fs`` divided by the highest finite positive frequency given (inf if none)."""
    finite = [f for f in frequencies if f is not None and np.isfinite(f) and f > 0]
    return fs / max(finite) if finite else math.inf


def upsampling_factor(natural_frequency: float, fs: float,
                      samples_per_period: float = SAMPLES_PER_PERIOD) -> int:
    """Smallest integer ``q >= 1`` giving ``samples_per_period`` samples per resonance period."""
    if not (natural_frequency > 0 and fs > 0 and samples_per_period > 0):
        raise InputError("natural_frequency, fs and samples_per_period must be positive")
    return max(1, math.ceil(samples_per_period * natural_frequency / fs - 1e-9))


def upsampling_needed(record: Record, estimates: Mapping[str, float] | None = None,
                      model: Chain | None = None, *, content: float | None = None) -> int:
    """Upsampling factor the record needs before identification (1: none).

    When the record has fewer than :data:`SAMPLES_PER_PERIOD` samples per period of the
    highest frequency its displacement carries (or of the natural frequency identified from
    it, when ``estimates`` and ``model`` are given), the factor that brings it to
    :data:`SAMPLES_PER_PERIOD` (the Silverbox rule).
    """
    if content is None:
        content = content_frequency(record.x, record.dt)
    natural = math.nan
    if estimates is not None and model is not None:
        canonical = _canonical(model, estimates)
        natural = natural_frequency(model, canonical) if canonical is not None else math.nan
    spp = samples_per_period(record.fs, content, natural)
    if spp >= SAMPLES_PER_PERIOD or not np.isfinite(spp):
        return 1
    highest = max(f for f in (content, natural) if np.isfinite(f))
    return upsampling_factor(highest, record.fs, SAMPLES_PER_PERIOD)


def upsampled(record: Record, factor: int) -> Record:
    """The record on a grid ``factor`` times finer (band-limited interpolation of x and f)."""

    if factor == 1:
        return record
    x = upsample(record.x, factor)
    f = upsample(record.f, factor)
    t = record.t[0] + np.arange(len(x)) * (record.dt / factor)
    return Record(t, f, x, source=f"{record.source} (upsampled x{factor})", sampling_rtol=record.sampling_rtol)


def natural_frequency(model: Chain, canonical: Mapping[str, float], *, lowest: bool = False) -> float:
    """Highest (or ``lowest``) linearised natural frequency [Hz] of ``model`` with ``canonical``
    values (NaN if undefined)."""
    try:
        values = {k: float(v) for k, v in canonical.items()}
        if not all(np.isfinite(v) for v in values.values()):
            return math.nan
        omegas = model.linear_natural_frequencies(values)
    except (ValueError, ZeroDivisionError, np.linalg.LinAlgError, KeyError):
        return math.nan
    omegas = np.asarray(omegas, dtype=float)
    omegas = omegas[np.isfinite(omegas) & (omegas > 0)]
    if not omegas.size:
        return math.nan
    return float(omegas.min() if lowest else omegas.max()) / (2.0 * math.pi)


# A displacement sample further than OUTLIER_SIGMAS robust standard deviations (never below
# OUTLIER_RANGE of the column's range) from the cubic through its four neighbours is an
# isolated outlier (a spike, a dropout to 0, a wrapped encoder count): the online
# estimators' rule (duffid.identification.engine), with both neighbours known.
#: More outliers than this share of the samples are not isolated glitches: none is removed.
MAX_OUTLIER_SHARE = 0.001


def isolated_outliers(x: np.ndarray) -> list[tuple[int, int, float]]:
    """Isolated outliers of the displacement columns: (sample, column, value the neighbours give).

    Each interior sample is compared with the cubic through its two neighbours on each side,
    ``(-x[i-2] + 4 x[i-1] + 4 x[i+1] - x[i+2]) / 6``; a sample further from it than
    :data:`OUTLIER_SIGMAS` robust standard deviations of those differences (never less than
    the quantisation step nor :data:`OUTLIER_RANGE` of the column's range) is an outlier; of a run of neighbouring candidates (a spike also
    moves its neighbours' predictions) the largest is taken. Empty when more than
    :data:`MAX_OUTLIER_SHARE` of the samples qualify (then they are not isolated glitches).
    """
    x = np.asarray(x, dtype=float).reshape(len(x), -1)
    found: list[tuple[int, int, float]] = []
    if len(x) < 8:
        return found
    for j in range(x.shape[1]):
        c = x[:, j]
        prediction = (-c[:-4] + 4.0 * c[1:-3] + 4.0 * c[3:-1] - c[4:]) / 6.0
        r = c[2:-2] - prediction
        # never below the quantisation step, nor 1e-4 of the column's range: a noise-free record's
        # own smooth differences would otherwise pass for glitches where it moves fastest
        scale = max(1.4826 * float(np.median(np.abs(r - np.median(r)))), _quantisation_step(c),
                    OUTLIER_RANGE * float(np.ptp(c)), 1e-300)
        candidates = np.flatnonzero(np.abs(r) > OUTLIER_SIGMAS * scale)
        if not len(candidates):
            continue
        runs = np.split(candidates, np.flatnonzero(np.diff(candidates) > 1) + 1)
        for run in runs:
            k = int(run[np.argmax(np.abs(r[run]))])
            found.append((k + 2, j, float(prediction[k])))
    if len(found) > MAX_OUTLIER_SHARE * x.size:
        return []
    return found


# ---------------------------------------------------------------------- force balance
def term_shares(model: Any, canonical: Mapping[str, float], x: np.ndarray, f: np.ndarray,
                dt: float) -> dict[str, float]:
    """Share of each canonical parameter's term in the force balance of the equations it acts
    in, on a smooth displacement ``x`` (:meth:`~duffid.models.chain.Chain.term_shares`)."""
    return model.term_shares(canonical, x, f, dt)


# ---------------------------------------------------------------------- assessment
#: The simulation check restarts from the measured state every this many natural periods:
#: a lightly damped nonlinear plant's free-run simulation drifts onto another branch under
#: parameter errors far below any tolerance (measured: 0.1 % errors, 100 % NRMSE over 80
#: periods of a hardening plant at 1.6 % damping), which says nothing about the model.
SEGMENT_PERIODS = 2.0
#: Share of those segments (the worst) left out of the figure: a noisy initial state near a
#: softening spring's escape or a jump can send one stretch onto another branch.
MAX_ESCAPED = 0.1


def _segment_samples(record: Record, natural: float) -> tuple[int, int]:
    """Samples of a stretch's initial-state window and of a stretch (:data:`SEGMENT_PERIODS`
    natural periods, at least four windows)."""
    n = record.n_samples
    period = record.fs / natural if np.isfinite(natural) and natural > 0 else n
    init = int(max(period / 2, 10))
    return init, int(min(n, max(SEGMENT_PERIODS * period, 4 * init)))


def _simulation_fit(record: Record, model: Chain, canonical: Mapping[str, float], natural: float,
                    noise: np.ndarray) -> tuple[dict[str, Any], np.ndarray | None, str | None]:
    """Simulate the identified model under the measured force, in segments of
    :data:`SEGMENT_PERIODS` natural periods each started from a state fitted to its first
    half period; the NRMSE of the simulated displacement against the record."""

    spread = np.std(record.x, axis=0)
    fit: dict[str, Any] = {"simulation_nrmse": math.nan, "noise_nrmse": math.nan, "explained": False}
    noise_nrmse = float(np.max(noise / spread))
    fit["noise_nrmse"] = noise_nrmse
    n = record.n_samples
    init, length = _segment_samples(record, natural)
    try:
        simulator = OdeSimulator(model, record.dt, free=())
        simulated = np.empty_like(record.x)
        pieces: list[tuple[float, float, int]] = []  # (mean square error / variance, sum, samples)
        with np.errstate(all="ignore"):  # a trial initial state may make the simulation overflow
            for start, stop in stretches(n, length):
                segment = Record(record.t[start:stop], record.f[start:stop], record.x[start:stop],
                                 source=record.source)
                response = _segment_response(simulator, canonical, segment, min(init, len(segment.t) // 4))
                scaled = ((response[init:] - segment.x[init:]) / spread) ** 2
                worst = float(np.max(np.mean(scaled, axis=0))) if np.all(np.isfinite(scaled)) else math.inf
                pieces.append((worst, float(np.max(np.sum(scaled, axis=0))), len(scaled)))
                simulated[start:stop] = response if np.all(np.isfinite(response)) else segment.x
    except (RecordError, ValueError, ArithmeticError) as exc:
        return fit, None, f"the identified model cannot be simulated under the measured force ({exc})"
    # near a softening spring's escape or a lightly damped jump, a noisy initial state can
    # send one stretch onto another branch: the worst MAX_ESCAPED of the stretches are left out
    pieces.sort()
    kept = pieces[:max(1, len(pieces) - int(MAX_ESCAPED * len(pieces)))]
    escaped = sum(1 for p in pieces if not np.isfinite(p[0]))
    fit["segments"] = len(pieces)
    fit["segments_escaped"] = escaped
    if not all(np.isfinite(p[0]) for p in kept):
        return fit, None, (f"the identified model escapes (its simulation diverges) under the measured force in "
                           f"{escaped} of {len(pieces)} stretches of the record: it does not describe the plant")
    nrmse = math.sqrt(sum(p[1] for p in kept) / sum(p[2] for p in kept))
    fit["simulation_nrmse"] = nrmse
    excess = math.sqrt(max(nrmse**2 - noise_nrmse**2, 0.0))
    fit["explained"] = bool(np.isfinite(nrmse) and excess <= SIMULATION_TOLERANCE)
    if not fit["explained"]:
        return fit, simulated, (
            f"the identified model does not reproduce the record: driven by the measured force it "
            f"misses the measured displacement by {100 * nrmse:.3g} % RMS (noise explains "
            f"{100 * noise_nrmse:.2g} %, {100 * SIMULATION_TOLERANCE:.0f} % more is allowed); check the "
            f"columns (force and displacement swapped?), units, sensor offsets (--offset), and that "
            f"the model fits the plant (friction, other nonlinearities)")
    return fit, simulated, None


def _segment_response(simulator: Any, canonical: Mapping[str, float], segment: Record, init: int) -> np.ndarray:
    """The simulated displacement over one segment, from the initial state that best fits its
    first ``init`` samples, or, when that state makes the model escape, from the measured
    state (a local quadratic fit of the first samples)."""

    x0, v0 = fit_initial_state(simulator, canonical, segment, window=max(init, 3))
    out = simulator.simulate(canonical, segment.f, x0, v0)
    if np.all(np.isfinite(out)):
        return out
    k = max(min(init, len(segment.t)), 3)
    tau = segment.t[:k] - segment.t[0]
    coefficients = np.polyfit(tau, segment.x[:k], 2)  # rows: tau^2, tau, 1
    return simulator.simulate(canonical, segment.f, coefficients[2], coefficients[1])


def _bootstrap_uncertainty(record: Record, estimates: Mapping[str, float], noise: np.ndarray,
                           rerun: Callable[[Record], Mapping[str, float]], replicates: int,
                           seed: int, progress: bool | None = None) -> dict[str, float]:
    """Relative standard error of each estimate from ``replicates`` noisy copies of the record.

    ``progress``: a progress bar on stderr (None: when stderr is a terminal and the record is
    long enough, :data:`PROGRESS_SAMPLES`, for the replicates to take more than a couple of
    seconds)."""
    from tqdm import tqdm

    if progress is None:
        progress = sys.stderr.isatty() and record.n_samples >= PROGRESS_SAMPLES
    rng = np.random.default_rng(seed)
    deviations: dict[str, list[float]] = {k: [] for k in estimates}
    for _ in tqdm(range(replicates), desc="uncertainty (noisy replicates)", disable=not progress,
                  file=sys.stderr, leave=False):
        noisy = Record(record.t, record.f, record.x + rng.standard_normal(record.x.shape) * noise,
                       source=record.source, sampling_rtol=record.sampling_rtol)
        values = rerun(noisy)
        for k, v in estimates.items():
            deviations[k].append(float(values.get(k, math.nan)) - float(v))
    out = {}
    for k, v in estimates.items():
        d = np.array(deviations[k])
        if not np.all(np.isfinite(d)) or not np.isfinite(v) or v == 0:
            out[k] = math.inf
        else:
            out[k] = max(math.sqrt(float(np.mean(d**2))) / abs(float(v)), UNCERTAINTY_FLOOR)
    return out


#: A force whose standard deviation is below this fraction of its mean magnitude "hardly varies".
FORCE_VARIATION = 0.05


def _force_varies(record: Record) -> bool:
    """Whether the force varies enough to separate a constant offset from the stiffness."""
    f = record.f
    return bool(np.all(np.std(f, axis=0) > FORCE_VARIATION * np.abs(np.mean(f, axis=0))) and np.any(np.std(f, axis=0) > 0))


def _refusal(record: Record, model: Chain, values: Mapping[str, float], spp: float, highest: float) -> str | None:
    """Why the record cannot support any value before the model is even simulated (None: it may)."""
    still = [i + 1 for i in range(record.n_dof) if not np.std(record.x[:, i]) > 0]
    if still:
        return (f"the displacement (column{'s' if len(still) > 1 else ''} x{', x'.join(map(str, still))}) "
                f"does not vary over the record: check the column order (force and displacement "
                f"swapped?) and that the sensor was recording")
    if model.needs_force() and not np.any(np.abs(record.f) > 0):
        return ("the force is zero throughout the record (a free decay): only ratios such as b/m, k/m "
                "and kp/m are determined by such a record, not the parameters themselves; record the "
                "force, or identify a model whose equations are divided by the mass")
    missing = [k for k, v in values.items() if not np.isfinite(v)]
    if missing:
        return (f"the estimator never reached a well-conditioned solution for {', '.join(missing)}: "
                f"the record does not excite the model enough (a longer record, more force, or a "
                f"richer excitation such as a sweep or random force)")
    if spp < MIN_SAMPLES_PER_PERIOD:
        return (f"{spp:.3g} samples per period of the highest frequency ({highest:.4g} Hz) "
                f"is too few for the integrals (at least {MIN_SAMPLES_PER_PERIOD:.0f}): the values "
                f"would be biased; record faster or upsample")
    return None


def _offset_check(values: Mapping[str, float], uncertainty: Mapping[str, float],
                  with_offsets: Callable[[], Mapping[str, float]] | None, notes: list[str],
                  fit: dict[str, Any], max_uncertainty: float) -> set[str]:
    """Parameters whose value moves by more than 3 standard errors and ``max_uncertainty``
    when offsets are allowed."""
    if with_offsets is None:
        return set()
    alternative = with_offsets()
    offsets = {k: float(v) for k, v in alternative.items() if k not in values}
    fit["offsets_if_allowed"] = offsets
    changes = {k: (float(alternative.get(k, math.nan)) - v) / abs(v) for k, v in values.items() if v != 0}
    if not all(np.isfinite(c) for c in changes.values()):
        notes.append("with a constant offset allowed in the model the record no longer determines the "
                     "parameters: it cannot rule out a sensor offset, so the values assume there is none")
        return set()
    # the alternative has one more unknown per DOF, so its own scatter is larger: a change is a
    # finding when it exceeds both 3 standard errors and the publication tolerance
    moved = {k for k, c in changes.items() if abs(c) > max(3.0 * uncertainty[k], max_uncertainty)}
    if moved:
        shown = ", ".join(f"{k} {100 * changes[k]:+.3g} %" for k in sorted(moved, key=list(values).index))
        found = ", ".join(f"{k} = {v:.4g}" for k, v in offsets.items())
        hint = ("--offset displacement (or --offset both)" if DISPLACEMENT_OFFSET in offsets
                else "--offset KIND (" + ", ".join(OFFSETS) + ")")
        notes.append(f"with a constant offset allowed in the model the values change beyond their uncertainty "
                     f"({shown}; offsets {found}): the record shows a sensor offset or a bias; identify "
                     f"with {hint}")
    return moved


def _unphysical(model: Chain, canonical: Mapping[str, float]) -> str | None:
    """What is not physical about the identified values (None: nothing): a mass or inertia
    that is not positive, a damping that is negative (the model's own rules,
    ``model.is_physical``)."""
    bad = {public: v for public, v in model.from_canonical(canonical).items()
           if np.isfinite(v) and not model.is_physical(model.canonical_name(public), canonical[model.canonical_name(public)])}
    if not bad:
        return None
    found = ", ".join(f"{k} = {v:.4g}" for k, v in bad.items())
    return (f"the estimator found {found}, which is not physical (a mass or inertia must be positive and a "
            f"damping must not be negative in a passive plant): nothing is published; check the sign "
            f"conventions of force and displacement, the columns, and that the model fits the plant")


def _public_shares(model: Chain, shares: Mapping[str, float]) -> dict[str, float]:
    return {public: shares.get(model.canonical_name(public), math.nan) for public in model.parameters}


#: Engines of the online methods: the C core when it supports the model (Duffing1, Duffing2)
#: and a C compiler is available, else Python ("auto"); or one of them.
#: Largest relative uncertainty of a published value, unless the call gives ``max_uncertainty``:
#: the robust method's default (the options schema), for every method's assessment.
ASSESSMENT_UNCERTAINTY = default_options("robust")["max_uncertainty"]


def run_estimator(record: Record, model: Chain, method: str = "robust", *, engine: str = "auto",
                  **options: Any) -> Identification:
    """The estimator's run over ``record`` (unchecked), on the C core or in Python.

    The C core (:class:`~duffid.identification.c_core.CIdentifier`, one batch call) gives the answers
    of the Python identifier to rounding, many times faster; ``engine="auto"`` uses it for
    every model with the online methods when a C compiler is available, and Python otherwise
    (or for a model beyond the C core's limits): :class:`~duffid.models.chain.Duffing1`,
    :class:`~duffid.models.chain.Duffing2` and chains of their structure on the core's own
    description, any other chain or equation model on its generated description (the
    generic engine; one cached library per model, compiled on first use).
    """
    if engine not in ENGINES:
        raise InputError(f"engine must be one of {', '.join(ENGINES)}, got {engine!r}")
    if engine != "python" and method in ONLINE_METHODS:
        core = _c_model(model)
        try:
            if core is None:
                raise InputError(f"the C core does not run the model {model.name}")
            identifier = CIdentifier(core, record.dt, method, **options)
        except (BuildError, ValueError, OSError):
            # no compiler (BuildError), no C sources (AssetError, an OSError) (an installed wheel without them), or a model or
            # option the C core does not take: the Python identifier gives the same answers
            if engine == "c":
                raise
        else:
            with identifier:
                result = identifier.identify_record(record)
            return result if core is model else _renamed(result, model)
    elif engine == "c":
        raise InputError(f"the C core runs the methods {', '.join(ONLINE_METHODS)}, not {method!r}")
    return estimate(record, model, method, **options)


def _data_window(record: Record, frequency: float, periods: float) -> float:
    """Window [s] of the robust method for a record whose main frequency is ``frequency`` Hz:
    the whole record when it spans at most ``2 * periods`` periods (integrated from its
    first sample, as the paper does), else ``periods`` periods."""
    if record.duration * frequency <= 2.0 * periods:
        return float(record.duration + record.dt)
    return float(periods / frequency)


def _c_model(model: Any) -> Any:
    """The model the C core runs for ``model``: the core's own Duffing1 or Duffing2 with
    ``model``'s values for those and for chains of their structure; ``model`` itself (its
    generated description) for any other model with equations; None otherwise."""

    if isinstance(model, (Duffing1, Duffing2)):
        return model
    if isinstance(model, Chain):
        structure = (model.n_dof, model.coulomb is None, tuple(model.forced), tuple(model.orders or ()))
        if structure in ((1, True, (0,), (1, 3)), (2, True, (0,), (1, 3))):
            core = Duffing1 if model.n_dof == 1 else Duffing2
            return _chain_like(core(offset=model.offset), model.canonical_parameters())
    return model if isinstance(model, IdentifiableModel) else None


def _chain_like(template: Chain, canonical: Mapping[str, float]) -> Chain:
    try:
        return template.with_parameters(**{k: v for k, v in canonical.items() if not k.startswith("c")})
    except ValueError:
        return template


def _renamed(result: Identification, model: Chain) -> Identification:
    """A C-core result (Duffing1/Duffing2 names) under ``model``'s public names."""
    core = _c_model(model)
    assert core is not None

    def public(values: Mapping[str, float]) -> dict[str, float]:
        canonical = {core.canonical_name(k): float(v) for k, v in values.items()}
        return model.from_canonical(canonical)

    names = list(result.history)
    rows = [public({k: result.history[k][i] for k in names}) for i in range(len(result.t))]
    result.history = {k: np.array([row[k] for row in rows]) for k in model.parameters}
    result.parameters = public(result.parameters)
    result.estimates = public(result.estimates)
    by_canonical = {core.canonical_name(k): v for k, v in result.online_status.items()}
    result.online_status = {k: by_canonical[model.canonical_name(k)] for k in model.parameters}
    result.model = model.name
    return result


def identify(record: Record, model: Chain, method: str = "robust", *, offsets: str | None = None,
             check: bool = True, engine: str = "auto", progress: bool | None = None,
             refine: bool = True, **options: Any) -> Identification:
    """Identify ``model``'s parameters from a record, publishing only what the record supports.

    The estimator (:func:`duffid.identification.engine.estimate`: the online methods sample by
    sample, or a buffered basis) runs on the record; with ``check`` (the default) around it:

    - a record with fewer than :data:`SAMPLES_PER_PERIOD` samples per period of its highest
      frequency is upsampled (band-limited) first;
    - the robust method's automatic window is set from the data, in periods, and the record
      identified again with it, so that the result depends neither on when the online
      estimator first trusted itself nor on default seconds: the whole record when it spans
      at most ``2 window_periods`` periods, else ``window_periods`` periods of the
      displacement's main frequency, then of the identified natural frequency;
    - :func:`assess` checks the result against the record.

    ``parameters`` then holds only published values (NaN otherwise), ``estimates`` the
    estimator's final values and ``assessment`` the status, uncertainty and fit of each
    parameter and what is missing, in words.

    Parameters
    ----------
    record : Record
        Forces and displacements, evenly sampled.
    model : Chain
        Model structure.
    method : str
        ``robust`` (default), ``paper`` or a buffered basis (see
        :data:`duffid.identification.engine.METHODS`).
    offsets : {None, "force", "displacement", "both"}
        Sensor offsets to identify (:data:`OFFSETS`, see the module documentation).
        None: those of ``model`` (a model built with ``offset=True`` has a force bias,
        ``"force"``). ``"force"`` adds an unknown constant force per DOF (``c1``, ...);
        ``"displacement"`` a displacement-sensor offset ``x0`` (``x_meas = x + x0``, one-DOF
        models with a cubic spring), reported as the parameter ``x0``; ``"both"`` both, the
        force bias reported as ``c1``. The offsets found, with their standard errors, are in
        ``assessment.fit["offsets"]``. Without a visibly excited cubic term a displacement
        offset cannot be told from a force bias: ``x0`` is then not published and the notes
        say so.
    check : bool
        False: the estimator's run alone (:func:`run_estimator`, with the offsets mapped as
        above), for comparing estimators; its values are not checked and must not be
        published.
    engine : {"auto", "c", "python"}
        Where the online methods run (:func:`run_estimator`; a displacement offset needs the
        x^2 term, which only the Python identifier runs).
    progress : bool or None
        Progress bar on stderr while the checks run (None: for long records on a terminal).
    refine : bool
        Refine by output-error least squares when the algebraic estimate leaves excited
        values undetermined (see :func:`assess`; CLI ``--no-refine`` turns it off).
    **options
        Method options (see :class:`~duffid.identification.engine.OnlineIdentifier`).

    Raises
    ------
    ValueError
        An unknown ``offsets`` kind, or a displacement offset for a model that cannot carry
        it (the message names the models that can).
    """
    kind = _offset_kind(model, offsets)
    physical = _with_offsets(model) if kind is not None else model
    # a displacement offset: the chain of orders (1, 2, 3) with a constant is identified and
    # mapped back; `shifted` is cleared when the record cannot separate x0 from a force bias
    mode = {"shifted": kind in ("displacement", "both")}
    extended = _displacement_chain(physical) if mode["shifted"] else None
    if extended is not None and engine == "c" and method in ONLINE_METHODS:
        raise InputError("the C core runs stiffness orders 1 and 3 only; a displacement offset needs the x^2 "
                         "term: use engine 'auto' or 'python'")

    measured_coordinate: dict[str, float] = {}  # the last run's values of `extended`

    def run(rec: Record, opts: Mapping[str, Any]) -> Identification:
        if mode["shifted"] and extended is not None:
            raw = run_estimator(rec, extended, method, engine="python", **opts)
            measured_coordinate.clear()
            measured_coordinate.update(raw.estimates)
            return _mapped(raw, physical)
        return run_estimator(rec, physical, method, engine=engine, **opts)

    if not check:
        return run(record, options)
    check_record(record, model)
    outliers = isolated_outliers(record.x)
    if outliers:  # excluded: replaced by what their neighbours give, and reported
        x = record.x.copy()
        for i, j, value in outliers:
            x[i, j] = value
        measured, record = record, Record(record.t, record.f, x, source=record.source,
                                          sampling_rtol=record.sampling_rtol)
    opts = dict(options)
    # the robust method's window from the data, in natural periods (never the default
    # seconds, which belong to the paper's 3.6 Hz plant): first from the displacement's
    # main frequency, then from the identified natural frequency
    auto = method == "robust" and check_options(method, opts)["window"] == "auto"
    periods = check_options(method, opts)["window_periods"] if auto else math.nan
    content = content_frequency(record.x, record.dt)
    if auto and np.isfinite(content) and content > 0:
        opts["window"] = _data_window(record, content, periods)
    if auto and "min_time" not in options:  # 10 ms is 20 periods of a 2 kHz resonator
        opts["min_time"] = min(check_options(method, {})["min_time"], 0.5 * record.duration,
                               0.5 * periods / content if np.isfinite(content) and content > 0 else math.inf)
    factor = upsampling_needed(record, content=content)
    result = run(upsampled(record, factor), opts)
    slowest = natural_frequency(physical, _canonical(physical, result.estimates) or {}, lowest=True)
    again = upsampling_needed(record, result.estimates, physical, content=content)
    window = opts.get("window")
    if auto and np.isfinite(slowest) and slowest > 0:  # periods of the slowest mode
        window = _data_window(record, slowest, periods)
    if again > factor or window != opts.get("window"):
        factor = max(factor, again)
        if window is not None:
            opts["window"] = window
        result = run(upsampled(record, factor), opts)
    cubic_share = math.nan
    if mode["shifted"] and extended is not None:
        cubic_share = _cubic_share(record, measured_coordinate)
        if not cubic_share >= MIN_SHARE:  # x0 is a constant force like a force bias: not separable
            mode["shifted"] = False
            result = run(upsampled(record, factor), opts)
    max_uncertainty = float(opts.get("max_uncertainty", ASSESSMENT_UNCERTAINTY))

    def rerun(noisy: Record) -> Mapping[str, float]:
        return run(upsampled(noisy, factor), opts).estimates

    with_offsets = None
    if not physical.offset:
        offset_model = _with_offsets(model)

        def with_offsets() -> Mapping[str, float]:
            return run_estimator(upsampled(record, factor), offset_model, method, engine=engine, **opts).estimates
    elif kind == "force" and _carries_displacement_offset(physical):
        # a force bias is modelled: check that a displacement offset would not move the values
        def with_offsets() -> Mapping[str, float]:
            raw = run_estimator(upsampled(record, factor), _displacement_chain(physical), method,
                                engine="python", **opts).estimates
            if not _cubic_share(record, raw) >= MIN_SHARE:
                return dict(result.estimates)  # without the cubic, x0 is the force bias already modelled
            return displacement_offset_values(physical, raw)

    def at_half_rate() -> Mapping[str, float]:
        return run(_every_second(upsampled(record, factor)), opts).estimates

    result.assessment = assess(record, physical, result.estimates, rerun, max_uncertainty=max_uncertainty,
                               upsampled=factor, with_offsets=with_offsets, at_half_rate=at_half_rate,
                               progress=progress, displacement_offset=mode["shifted"], refine=refine)
    if kind in ("displacement", "both"):
        _report_displacement_offset(result, kind, separable=mode["shifted"], cubic_share=cubic_share)
    if outliers:
        listed = ", ".join(f"x{j + 1} = {measured.x[i, j]:.4g} at t = {measured.t[i]:.6g} s" for i, j, _ in outliers[:5])
        result.assessment.notes.insert(0, f"{len(outliers)} isolated outlier{'s' if len(outliers) > 1 else ''} in "
                                          f"the displacement excluded (replaced by the cubic through the "
                                          f"neighbouring samples): {listed}" + (" ..." if len(outliers) > 5 else ""))
        result.assessment.fit["outliers"] = [{"column": f"x{j + 1}", "t": float(measured.t[i]),
                                              "value": float(measured.x[i, j]), "replaced_by": value}
                                             for i, j, value in outliers]
    a = result.assessment
    result.parameters = a.published({k: a.values.get(k, v) for k, v in result.estimates.items()})
    if result.assessment.identified and result.t_identified is None:
        # the estimator integrated the whole record in one window: it needed all of it
        result.t_identified = float(result.t[-1])
    return result


def assess(record: Record, model: Chain, estimates: Mapping[str, float],
           rerun: Callable[[Record], Mapping[str, float]], *, max_uncertainty: float | None = None,
           replicates: int = REPLICATES, upsampled: int = 1, seed: int = 0,
           with_offsets: Callable[[], Mapping[str, float]] | None = None,
           at_half_rate: Callable[[], Mapping[str, float]] | None = None,
           progress: bool | None = None, displacement_offset: bool = False, refine: bool = True) -> Assessment:
    """Decide which of ``estimates`` (public names) the record supports.

    Parameters
    ----------
    record : Record
        The record as measured (before any upsampling).
    model : Chain
        Model structure.
    estimates : mapping
        Final estimates by public name (NaN where the estimator had none).
    rerun : callable
        Identifies a record (as measured) the way ``estimates`` were found (upsampling
        included) and returns its final estimates (public names): the bootstrap calls it
        on noisy copies of ``record``.
    max_uncertainty : float, optional
        Largest relative standard error of a published value (default
        :data:`ASSESSMENT_UNCERTAINTY`).
    replicates : int
        Noisy copies behind the standard errors.
    upsampled : int
        Factor by which the record was upsampled before identification.
    seed : int
        Seed of the replicates' noise.
    with_offsets : callable, optional
        For a model without offsets: identifies the record (as ``estimates`` were found)
        with the model's offset terms added and returns those estimates. A value that
        moves by more than its uncertainty when an offset is allowed is not published:
        the record cannot rule out a sensor offset.
    progress : bool or None
        Progress bar on stderr while the replicates run (None: for long records on a terminal).
    at_half_rate : callable, optional
        Identifies the record (as ``estimates`` were found) from every second sample. The
        difference to ``estimates`` bounds the quadrature's bias, which is of first order in
        the sampling period where the force jumps (a step between two samples): it enters
        each stated uncertainty (added in quadrature to the noise's share).
    displacement_offset : bool
        ``estimates`` (and ``rerun``'s values) also hold :data:`DISPLACEMENT_OFFSET`, the
        displacement sensor's offset (``x_meas = x + x0``): the model is simulated against
        the measured displacement minus ``x0``, and ``x0`` is assessed like the parameters
        (its share is that of the cubic term, the only one that separates it from a force
        bias).
    refine : bool
        When excited values are left undetermined by the algebraic estimate (and no offset
        check moved them), refine all values by output-error least squares
        (:func:`duffid.identification.refine.refine` in stretches of :data:`SEGMENT_PERIODS` periods),
        whose stated errors come from its covariance and its change at half the sampling
        rate; it is kept only when it agrees with the algebraic values within 3 combined
        standard errors (``fit["refinement"]``).

    Offsets (``c1``, ... of a model with ``offset``, and ``x0``) are published when their
    relative standard error is at most ``max_uncertainty`` or their standard error at most
    ``max_uncertainty`` of the signal's spread (displacement standard deviation, force RMS);
    ``fit["offsets"]`` lists them with their absolute standard errors.
    """
    names = list(model.parameters) + ([DISPLACEMENT_OFFSET] if displacement_offset else [])
    values = {k: float(estimates.get(k, math.nan)) for k in names}
    noise = noise_level(record.x)
    content = content_frequency(record.x, record.dt, noise=noise)
    canonical = _canonical(model, values)
    natural = natural_frequency(model, canonical) if canonical is not None else math.nan
    if max_uncertainty is None:
        max_uncertainty = ASSESSMENT_UNCERTAINTY
    spp = samples_per_period(record.fs * upsampled, content, natural)
    fit: dict[str, Any] = {"samples_per_period": spp, "content_hz": content, "natural_hz": natural,
                           "upsampled": int(upsampled), "noise": [float(s) for s in noise]}
    # the shares, the simulation and the noise are figures of the record as measured
    notes: list[str] = []
    if upsampled > 1:
        notes.append(f"the record was upsampled x{upsampled} (band-limited) before identification: "
                     f"its {record.fs:.4g} Hz sampling gives fewer than "
                     f"{SAMPLES_PER_PERIOD:.0f} samples per period of its highest frequency")
    status = {k: "uncertain" for k in names}
    uncertainty = {k: math.nan for k in names}
    share = {k: math.nan for k in names}
    refusal = _refusal(record, model, values, spp, max((v for v in (content, natural) if np.isfinite(v)), default=math.nan))
    if refusal is not None:
        notes.append(refusal)
        fit.update({"simulation_nrmse": math.nan, "noise_nrmse": math.nan, "explained": False})
        return Assessment(status, uncertainty, share, fit, notes, values)
    if canonical is None:
        notes.append("the identified values do not describe a physical " + model.name + " (" +
                     ", ".join(f"{k} = {v:.4g}" for k, v in values.items()) + "): the record does not "
                     "support this model (check the columns, units and the model)")
        fit.update({"simulation_nrmse": math.nan, "noise_nrmse": math.nan, "explained": False})
        return Assessment(status, uncertainty, share, fit, notes, values)
    shift = values.get(DISPLACEMENT_OFFSET, 0.0) if displacement_offset else 0.0
    physical = record if shift == 0.0 else Record(record.t, record.f, record.x - shift, source=record.source,
                                                  sampling_rtol=record.sampling_rtol)
    sim_fit, simulated, problem = _simulation_fit(physical, model, canonical, natural, noise)
    fit.update(sim_fit)
    if simulated is not None:
        shares = term_shares(model, canonical, simulated, record.f, record.dt)
        share = {**share, **_public_shares(model, shares)}
        if displacement_offset:  # only the cubic term tells x0 from a force bias
            share[DISPLACEMENT_OFFSET] = shares.get(f"k1_{max(model.orders)}", math.nan)
    unphysical = _unphysical(model, canonical)
    if problem is not None or unphysical is not None:
        notes.extend(n for n in (unphysical, problem) if n is not None)
        return Assessment(status, uncertainty, share, fit, notes, values)
    uncertainty = _bootstrap_uncertainty(record, values, noise, rerun, replicates, seed, progress)
    bias = BALANCE_FLOOR + QUADRATURE_BIAS / spp**4
    for k in names:  # the quadrature's share of the error, larger for a term that carries little
        if np.isfinite(share[k]) and share[k] > 0:
            uncertainty[k] = max(uncertainty[k], bias / share[k])
    if at_half_rate is not None:
        coarse = at_half_rate()
        for k in names:
            change = abs(float(coarse.get(k, math.nan)) - values[k]) / abs(values[k]) if values[k] else math.inf
            uncertainty[k] = _with_rate_bias(uncertainty[k], change)
        fit["half_rate_change"] = {k: (float(coarse.get(k, math.nan)) - values[k]) / values[k]
                                   for k in names if values[k]}
    varies = _force_varies(record)
    offset_moved = _offset_check(values, uncertainty, with_offsets if varies else None, notes, fit, max_uncertainty)
    if with_offsets is not None and not varies and model.offset:
        notes.append("the force hardly varies over the record (e.g. a step from the first sample): the record "
                     "cannot check for a displacement-sensor offset, so the values assume that the displacement "
                     "sensor reads zero at rest with no force")
    elif with_offsets is not None and not varies:
        notes.append("the force hardly varies over the record (e.g. a step from the first sample): the record "
                     "cannot separate a constant force or displacement offset from the stiffness, so the "
                     "values assume that the sensors read zero at rest with no force (a record with rest "
                     "before the step, or a varying force, lets duffid check it)")
    scales = _offset_scales(record, model, names)

    def determined(k: str) -> bool:
        return uncertainty[k] <= max_uncertainty or (
            k in scales and uncertainty[k] * abs(values[k]) <= max_uncertainty * scales[k])

    pending = [k for k in names if not determined(k) and not share[k] < MIN_SHARE]
    excess = math.sqrt(max(fit["simulation_nrmse"] ** 2 - fit["noise_nrmse"] ** 2, 0.0))
    if refine and not pending and not displacement_offset and \
            excess > max(CONSISTENCY_EXCESS, 0.25 * fit["noise_nrmse"]):
        # the model misses the record by more than its stated errors can explain: a bias of
        # the estimator (e.g. a buffered basis' truncation) shows as disagreement with the
        # output-error estimate, and their difference is then the value's uncertainty
        check = _refinement(record, model, values, uncertainty, natural, spp / upsampled, notes, [], check=True)
        if check is not None:
            fit["consistency"] = check
            _disagreement_as_uncertainty(check, uncertainty)
    if refine and pending and not offset_moved and not displacement_offset:
        # the equation error left excited values undetermined: the output error, an
        # efficient estimator for displacement noise, from the algebraic values
        refinement = _refinement(record, model, values, uncertainty, natural, spp / upsampled, notes, pending)
        if refinement is not None:
            fit["refinement"] = refinement
            if refinement["accepted"]:
                values = {**values, **refinement["values"]}
                uncertainty = {**uncertainty, **refinement["uncertainty"]}
            else:
                _disagreement_as_uncertainty(refinement, uncertainty)
    for k in names:
        if determined(k) and k not in offset_moved:
            status[k] = "published"
        elif np.isfinite(share[k]) and share[k] < MIN_SHARE and (k not in scales or k == DISPLACEMENT_OFFSET):
            status[k] = "not excited"
    weak = [k for k in names if status[k] == "not excited" and k != DISPLACEMENT_OFFSET]
    if weak:
        notes.append(f"{', '.join(weak)}: the term carries less than {100 * MIN_SHARE:.0f} % of the force "
                     f"balance in this record (" + ", ".join(f"{k} {100 * share[k]:.2g} %" for k in weak)
                     + "); a larger amplitude or a richer excitation would show it")
    if status.get(DISPLACEMENT_OFFSET) == "not excited":
        notes.append(_inseparable_note(share[DISPLACEMENT_OFFSET]))
    if scales:
        fit["offsets"] = {k: {"value": values[k] if status[k] == "published" else math.nan,
                              "standard_error": uncertainty[k] * abs(values[k]), "status": status[k]}
                          for k in scales}
    unsure = [k for k in names if status[k] == "uncertain" and k not in offset_moved]
    if unsure:
        notes.append(f"{', '.join(unsure)}: relative standard error "
                     + ", ".join(f"{k} {100 * uncertainty[k]:.2g} %" for k in unsure)
                     + f" above the {100 * max_uncertainty:.3g} % allowed (--max-uncertainty); more data, "
                       "less noise or a richer excitation would determine it")
    return Assessment(status, uncertainty, share, fit, notes, values)


#: The output-error refinement needs this many samples per period of the highest frequency
#: at half the sampling rate (its bias check) for the band-limited interpolation of the force.
REFINE_SAMPLES_PER_PERIOD = 4.0
#: Largest RK4 step of the refinement's simulation, in radians of the highest frequency.
REFINE_STEP = 0.1


def _every_second(record: Record) -> Record:
    """The record at half its sampling rate (every second sample)."""
    return Record(record.t[::2], record.f[::2], record.x[::2], source=record.source,
                  sampling_rtol=record.sampling_rtol)


def _with_rate_bias(standard_error: float, change: float) -> float:
    """A relative standard error combined with the bias that a value's relative ``change``
    at half the sampling rate shows beyond what the noise explains (half the samples: about
    one more standard error, so changes within 2 standard errors are noise)."""
    bias = math.sqrt(max(change**2 - (2.0 * standard_error) ** 2, 0.0)) if np.isfinite(change) else math.inf
    return math.hypot(standard_error, bias)


def _disagreement_as_uncertainty(refinement: Mapping[str, Any], uncertainty: dict[str, float]) -> None:
    """A value on which the algebraic and output-error estimates disagree beyond their
    stated errors is not known better than their difference: raise its stated error to it."""
    for k, apart in refinement["apart"].items():
        if not abs(apart) <= 3.0 * math.hypot(uncertainty[k], refinement["uncertainty"][k]):
            uncertainty[k] = max(uncertainty[k], abs(apart))


def _refinement(record: Record, model: Chain, values: Mapping[str, float], uncertainty: Mapping[str, float],
                natural: float, spp: float, notes: list[str], pending: list[str],
                check: bool = False) -> dict[str, Any] | None:
    """Output-error refinement of ``values`` (:func:`duffid.identification.refine.refine`, multiple
    shooting over stretches of :data:`SEGMENT_PERIODS` natural periods), with the
    stated errors of the Gauss-Newton covariance (inflated for correlated residuals) and the
    change at half the sampling rate beyond what the noise explains (the interpolation's
    bias, first order where the force jumps): ``fit["refinement"]``, not ``accepted`` (with a
    note) when it disagrees with the algebraic values by more than 3 combined standard errors;
    None (with a note) when it fails. ``check``: a cross-check of determined values (the
    caller takes the disagreement as their uncertainty; the notes say so)."""
    what = "output-error cross-check" if check else f"output-error refinement of {', '.join(pending)}"

    if not spp / 2 >= REFINE_SAMPLES_PER_PERIOD:
        return None
    _, length = _segment_samples(record, natural)
    canonical_names = {k: model.canonical_name(k) for k in model.parameters}

    def run(rec: Record, segment: int, samples_per_period: float) -> Any:
        substeps = max(4, math.ceil(2 * math.pi / (samples_per_period * REFINE_STEP)))
        return refine(rec, model, {k: values[k] for k in model.parameters}, segment=max(segment, 8),
                      substeps=substeps, progress=False)

    try:
        with np.errstate(all="ignore"):
            full = run(record, length, spp)
            half = run(_every_second(record), length // 2, spp / 2)
    except (ValueError, RecordError, ArithmeticError, np.linalg.LinAlgError) as exc:
        notes.append(f"the {what} failed ({exc}); the algebraic values stand")
        return None
    if not (full.success and half.success):
        notes.append(f"the {what} did not converge ({full.message if not full.success else half.message}); "
                     "the algebraic values stand")
        return None
    refined, stated, change = {}, {}, {}
    for k, c in canonical_names.items():
        v = full.parameters[k]
        sd = max(full.relative_std.get(c, math.inf), UNCERTAINTY_FLOOR)
        change[k] = (half.parameters[k] - v) / abs(v) if v else math.inf
        refined[k], stated[k] = v, _with_rate_bias(sd, change[k])
    apart = {k: (refined[k] - values[k]) / abs(values[k]) for k in canonical_names if values[k]}
    disagree = [k for k, d in apart.items()
                if not abs(d) <= 3.0 * math.hypot(uncertainty[k], stated[k])]
    info = {"values": refined, "uncertainty": stated, "half_rate_change": change,
            "rms": full.rms, "stretches": full.options["stretches"], "evaluations": full.nfev,
            "accepted": not disagree, "apart": apart}
    if check:
        if disagree:
            notes.append("the identified model misses the record by more than the noise explains, and the "
                         "output-error estimate disagrees with the algebraic one beyond their stated errors ("
                         + ", ".join(f"{k} {100 * apart[k]:+.3g} %" for k in disagree)
                         + "): the difference is taken as their uncertainty")
        return info
    if disagree:
        notes.append("the output-error refinement disagrees with the algebraic estimate beyond their "
                     "uncertainties (" + ", ".join(f"{k} {100 * apart[k]:+.3g} %" for k in disagree)
                     + "): the model may not describe the plant; the algebraic values stand, with the "
                       "difference as their uncertainty")
    else:
        notes.append(f"the algebraic estimate left {', '.join(pending)} undetermined: the values are refined by "
                     f"output-error least squares (the model simulated under the measured force in "
                     f"{full.options['stretches']} stretches of {SEGMENT_PERIODS:g} natural periods)")
    return info


def _with_offsets(model: Chain) -> Chain:
    """``model`` with an unknown constant force on each DOF (``c1``, ``c2``, ...)."""
    return model.with_offset()


def _canonical(model: Chain, public: Mapping[str, float]) -> dict[str, float] | None:
    """Canonical values from public ones (None if a needed value is missing)."""

    try:
        canonical = canonical_from_public(model, {k: v for k, v in public.items() if k != DISPLACEMENT_OFFSET})
    except (ValueError, KeyError, ZeroDivisionError):
        return None
    return canonical


# ---------------------------------------------------------------------- sensor offsets
def _offset_kind(model: Chain, offsets: str | None) -> str | None:
    """The offsets to identify: ``offsets`` checked, or those of ``model`` (None: none)."""
    if offsets is None:
        return "force" if model.offset else None
    if offsets not in OFFSETS:
        raise InputError(f"offsets must be one of {', '.join(OFFSETS)} (or None), got {offsets!r}")
    if offsets == "displacement" and model.offset:
        return "both"  # the model itself carries a force bias
    return offsets


def _carries_displacement_offset(model: Chain) -> bool:
    """Whether a displacement offset of ``model`` can be identified (a chain of one DOF, orders 1 and 3)."""
    return isinstance(model, Chain) and model.n_dof == 1 and tuple(model.orders or ()) == (1, 3)


def _displacement_chain(model: Chain) -> Chain:
    """The chain identified for a displacement offset: ``model``'s (one DOF, orders 1 and 3)
    with stiffness orders 1, 2, 3 and a constant force."""
    if not isinstance(model, Chain):
        raise InputError("a displacement-sensor offset of an equation model is written into the equation "
                         "(x - x0 in place of x makes it nonlinear in x0: write the polynomial in x with its own "
                         "coefficients, e.g. k1*x + k2*x^2 + k3*x^3 + c = f); --offset force adds a constant "
                         "force per equation")
    if not _carries_displacement_offset(model):
        raise InputError(f"a displacement-sensor offset is identified for one-DOF models with a linear and a "
                         f"cubic spring (duffing1, circuit, chain --n-dof 1 --orders 1,3), not {model.name} with "
                         f"{model.n_dof} DOF and stiffness orders {', '.join(map(str, model.orders or ()))}; "
                         f"use --offset force (a constant force per DOF)")
    canonical = model.canonical_parameters()
    return Chain(masses=(canonical["m1"],), damping=(canonical["b1"],),
                 stiffness=({1: canonical["k1_1"], 2: 0.0, 3: canonical["k1_3"]},),
                 coulomb=model.coulomb, forced=model.forced, offset=True, orders=(1, 2, 3))


def displacement_offset_values(model: Chain, extended: Mapping[str, float]) -> dict[str, float]:
    """``model``'s parameters and the displacement offset from the measured-coordinate chain.

    With ``x_meas = x + x0``, ``m x'' + b x' + k x + kp x^3 + c1 = f`` reads
    ``m x_meas'' + b x_meas' + a1 x_meas + a2 x_meas^2 + a3 x_meas^3 + a0 = f`` with
    ``a3 = kp``, ``a2 = -3 kp x0``, ``a1 = k + 3 kp x0^2`` and ``a0 = c1 - k x0 - kp x0^3``;
    inverted here: ``x0 = -a2 / (3 a3)``, ``kp = a3``, ``k = a1 - 3 a3 x0^2``,
    ``c1 = a0 + k x0 + kp x0^3``.

    Parameters
    ----------
    model : Chain
        The physical model (one DOF, stiffness orders 1 and 3, with ``offset``).
    extended : mapping
        Canonical values ``m1, b1, k1_1, k1_2, k1_3, c1`` (and ``fc1``) of the chain of
        orders 1, 2, 3 with a constant.

    Returns
    -------
    dict
        ``model``'s public parameters (``c1`` the force bias) and :data:`DISPLACEMENT_OFFSET`;
        all NaN when ``a3`` is zero or a value is not finite (then ``x0`` is undefined).
    """
    a1, a2, a3, a0 = (float(extended[k]) for k in ("k1_1", "k1_2", "k1_3", "c1"))
    names = list(model.parameters) + [DISPLACEMENT_OFFSET]
    if not (a3 != 0.0 and all(np.isfinite(v) for v in extended.values())):
        return {k: math.nan for k in names}
    x0 = -a2 / (3.0 * a3)
    k = a1 - 3.0 * a3 * x0**2
    canonical = {k_: float(v) for k_, v in extended.items() if k_ != "k1_2"}
    canonical.update({"k1_1": k, "k1_3": a3, "c1": a0 + k * x0 + a3 * x0**3})
    out = model.from_canonical(canonical)
    out[DISPLACEMENT_OFFSET] = x0
    return out


def _mapped(result: Identification, model: Chain) -> Identification:
    """A run of :func:`_displacement_chain`'s chain under ``model``'s public names and ``x0``."""
    names = list(result.history)
    with np.errstate(all="ignore"):
        rows = [displacement_offset_values(model, {k: result.history[k][i] for k in names})
                for i in range(len(result.t))]
        keys = list(model.parameters) + [DISPLACEMENT_OFFSET]
        result.history = {k: np.array([row[k] for row in rows]) for k in keys}
        raw = dict(result.estimates)
        result.parameters = displacement_offset_values(model, result.parameters)
        result.estimates = displacement_offset_values(model, raw)
    result.model = model.name
    return result


def _cubic_share(record: Record, extended: Mapping[str, float]) -> float:
    """Share of the cubic spring in the force balance, from the measured-coordinate chain's
    values (:func:`displacement_offset_values`), without derivatives of the measured
    displacement: the smaller of ``a3 x_meas^3`` and of ``kp (x_meas - x0)^3`` over the RMS of
    the balance, whose inertia and damping part is what the force leaves to them (``f``
    minus the spring and the constant). The first is small for a linear plant (whose ``x0``
    is noise), the second when ``x0`` dwarfs the motion; NaN if undefined."""
    try:
        a1, a2, a3, a0 = (float(extended[k]) for k in ("k1_1", "k1_2", "k1_3", "c1"))
    except KeyError:
        return math.nan
    if not (a3 != 0.0 and all(np.isfinite(v) for v in (a1, a2, a3, a0))):
        return math.nan
    xm, f = record.x[:, 0], record.f[:, 0]
    rest = f - (a1 * xm + a2 * xm**2 + a3 * xm**3 + a0)
    with np.errstate(all="ignore"):
        measured = [a1 * xm, a2 * xm**2, a3 * xm**3, np.full_like(xm, a0)]
        x0 = -a2 / (3.0 * a3)
        k = a1 - 3.0 * a3 * x0**2
        x = xm - x0
        physical = [k * x, a3 * x**3, np.full_like(xm, a0 + k * x0 + a3 * x0**3)]
        shares = []
        for terms, cubic in ((measured, 2), (physical, 1)):
            balance = float(np.mean(f**2) + np.mean(rest**2) + sum(np.mean(t**2) for t in terms))
            shares.append(math.sqrt(float(np.mean(terms[cubic] ** 2)) / balance) if balance > 0 else math.nan)
    return min(shares) if all(np.isfinite(shares)) else math.nan


def _inseparable_note(share: float) -> str:
    """Why ``x0`` is not published when the cubic spring is not excited."""
    carries = (f"the cubic spring carries {100 * share:.2g} % of the force balance (less than "
               f"{100 * MIN_SHARE:.0f} %)" if np.isfinite(share) else "the cubic spring's part of the force balance "
               "could not be determined")
    return (f"{DISPLACEMENT_OFFSET} is not published: {carries}; without a visibly nonlinear spring a "
            f"displacement-sensor offset acts as a constant force k*{DISPLACEMENT_OFFSET}, like a force bias, and "
            f"the record cannot separate the two: only their combined constant force c1 (= force bias - "
            f"k*{DISPLACEMENT_OFFSET}) is determined (an amplitude large enough to show the cubic spring would "
            f"separate them)")


def _offset_scales(record: Record, model: Chain, names: list[str]) -> dict[str, float]:
    """Spread of the signal each offset among ``names`` is judged against: the force's RMS
    for ``c1``, ..., the displacement's standard deviation for ``x0``."""
    out = {}
    rms = float(np.sqrt(np.mean(record.f**2))) if record.f.size else 0.0
    out.update({k: rms for k in model.offset_parameters() if k in names})
    if DISPLACEMENT_OFFSET in names:
        out[DISPLACEMENT_OFFSET] = float(np.std(record.x[:, 0]))
    return out


def _report_displacement_offset(result: Identification, kind: str, *, separable: bool, cubic_share: float) -> None:
    """Complete ``result`` of an identification with a displacement offset: ``x0`` not
    published (and why) when the record could not separate it from a force bias; with
    ``kind="displacement"`` the force bias leaves the parameters for ``fit["offsets"]``."""
    a = result.assessment
    offsets = a.fit.setdefault("offsets", {})
    if not separable:
        result.estimates[DISPLACEMENT_OFFSET] = math.nan
        a.status[DISPLACEMENT_OFFSET] = "not excited"
        a.uncertainty[DISPLACEMENT_OFFSET] = math.nan
        a.share[DISPLACEMENT_OFFSET] = cubic_share
        offsets[DISPLACEMENT_OFFSET] = {"value": math.nan, "standard_error": math.nan, "status": "not excited"}
        a.notes.append(_inseparable_note(cubic_share))
    if kind != "displacement":
        return
    for table in (result.estimates, a.status, a.uncertainty, a.share):
        table.pop("c1", None)
    bias = offsets.get("c1")
    if separable and bias is not None and bias["status"] == "published" \
            and abs(bias["value"]) > 3.0 * bias["standard_error"]:
        a.notes.append(f"the record also shows a constant force c1 = {bias['value']:.4g} "
                       f"(standard error {bias['standard_error']:.2g}; the force sensor reads it at zero force): the "
                       f"values above account for it; --offset both lists it among the parameters")
