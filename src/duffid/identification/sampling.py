"""Record checks and the sampling policy of the checked identification: noise level, the
displacement's content frequency, samples per period and upsampling, isolated outliers, the
force's variation (used by :func:`duffid.identification.trust.identify`)."""
from __future__ import annotations

import math
from typing import Mapping

import numpy as np

from ..data.record import Record
from ..errors import InputError
from ..models.chain import Chain
from .engine import FORCE_VARIATION, JUMP_FACTOR, JUMP_RANGE, OUTLIER_RANGE, OUTLIER_SIGMAS
from .offsets import canonical_of
from .refine import upsample

__all__ = [
    "SAMPLES_PER_PERIOD",
    "MIN_SAMPLES_PER_PERIOD",
    "noise_level",
    "NOISE_AGREEMENT",
    "NOISE_SCATTER",
    "noise_is_white",
    "NOISE_BINS",
    "content_frequency",
    "samples_per_period",
    "upsampling_factor",
    "upsampling_needed",
    "upsampled",
    "natural_frequency",
    "MAX_OUTLIER_SHARE",
    "REPLACEMENT_PASSES",
    "isolated_outliers",
    "FORCE_VARIATION",
    "force_varies",
    "every_second",
]


#: Samples per period of the highest frequency in the displacement that identification
#: works at: a record with fewer is upsampled to this many (the Silverbox rule). Measured
#: (noise-free 10 Hz plant, multisine to 25 Hz): the damping is biased by 7 % at 8 samples
#: per period of the highest frequency, 0.3 % at 20, 0.02 % at 40 and 3e-6 at 120.
SAMPLES_PER_PERIOD = 50.0

#: Below this many samples per period no value is published (the integrals are biased).
MIN_SAMPLES_PER_PERIOD = 20.0

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

def _difference_noise(column: np.ndarray, order: int) -> float:
    """The white-noise standard deviation that the ``order``-th differences of ``column`` give
    (median absolute deviation; white noise of variance s^2 gives them C(2 order, order) s^2)."""
    d = np.diff(column, n=order)
    mad = float(np.median(np.abs(d - np.median(d)))) if len(d) else 0.0
    return 1.4826 * mad / math.sqrt(math.comb(2 * order, order))


#: :func:`noise_is_white`: the 4th and 6th differences' noise figures of white noise agree to
#: this share, plus :data:`NOISE_SCATTER` ``/ sqrt(samples)`` (five standard deviations of their
#: ratio over white noise: 0.0434, 0.0197 and 0.0046 at 250, 1,000 and 20,000 samples). A signal
#: that reaches the upper part of the band (a broadband force on an accelerometer's plant) leaks
#: into both, into the 4th more: measured on records of a 10 Hz plant at 5 kHz with 0.3-1 % white
#: noise, the ratio was 0.99-1.005 (1.055 with a 0.3 ms sensor delay); with the force's band up to
#: 1.5 kHz (the acceleration follows it above resonance) 1.13-1.45, where the 4th differences
#: overstated the noise 80-fold, and 1.21 for a vibrometer at 250 Hz under a force to 100 Hz.
NOISE_AGREEMENT = 0.05
#: See :data:`NOISE_AGREEMENT`.
NOISE_SCATTER = 3.3


def noise_is_white(x: np.ndarray) -> tuple[bool, float, float]:
    """Whether :func:`noise_level` measures white noise on every column of ``x``, not signal:
    ``(agree, sigma4, sigma6)``, the figures of the 4th and 6th differences of the column where
    they disagree most (:data:`NOISE_AGREEMENT`). A quantised column without noise agrees."""
    x = np.asarray(x, dtype=float).reshape(len(x), -1)
    allowed = NOISE_AGREEMENT + NOISE_SCATTER / math.sqrt(max(len(x), 1))
    worst = (True, 0.0, 0.0)
    spread = 0.0
    for j in range(x.shape[1]):
        s4, s6 = _difference_noise(x[:, j], 4), _difference_noise(x[:, j], 6)
        ratio = s4 / s6 if s6 > 0 else (1.0 if s4 == 0 else math.inf)
        if abs(ratio - 1.0) >= spread:
            spread = abs(ratio - 1.0)
            worst = (spread <= allowed, s4, s6)
    return worst


def noise_level(x: np.ndarray) -> np.ndarray:
    """Standard deviation of the white measurement noise on each column of ``x``.

    From the fourth differences (which remove a smooth signal up to ``(omega dt)^4``),
    robustly (median absolute deviation), combined with the quantisation noise ``q/sqrt(12)``
    of values on a grid of step ``q``. A smooth signal sampled coarsely leaks into the figure,
    which then overstates the noise: the safe side where noise only widens an error, not where
    a fit is checked against it (:func:`noise_is_white` tells).
    """
    x = np.asarray(x, dtype=float).reshape(len(x), -1)
    out = np.zeros(x.shape[1])
    for j in range(x.shape[1]):
        sigma = _difference_noise(x[:, j], 4)
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
    :data:`SAMPLES_PER_PERIOD` (the Silverbox rule). Never for a force that jumps between
    two samples (:func:`near_force_jumps`: a step): band-limited interpolation rings around a
    jump that the plant never felt (a lightly damped plant's double step at 25 samples per
    period, upsampled x3: b published 213 % off, stated within 0.6 %); the record is
    identified at its own rate, where the half-rate check sees the quadrature's bias.
    """
    if near_force_jumps(record.f).any():
        return 1
    if content is None:
        content = content_frequency(record.x, record.dt)
    natural = math.nan
    if estimates is not None and model is not None:
        canonical = canonical_of(model, estimates)
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
#: Passes of the outlier search on the repaired column (glitches side by side would otherwise
#: hide each other).
REPLACEMENT_PASSES = 3

#: More outliers than this share of the samples are not isolated glitches: none is removed.
#: Measured: a record with 1 % isolated glitches (spikes of 0.2 to 3 times the displacement's
#: range) is identified within 0.3 % once they are replaced (at 0.1 % every value was refused),
#: as the online estimator, which excludes them sample by sample, does.
MAX_OUTLIER_SHARE = 0.02

def _neighbours(c: np.ndarray) -> np.ndarray:
    """The cubic through each interior sample's two neighbours on each side."""
    return (-c[:-4] + 4.0 * c[1:-3] + 4.0 * c[3:-1] - c[4:]) / 6.0

def _bridged(c: np.ndarray, where: np.ndarray) -> list[tuple[int, float]]:
    """Each sample of ``where`` replaced by the cubic through the two nearest good samples on
    each side of its group of neighbouring outliers (for a single one: the cubic through its
    neighbours)."""
    bad = np.zeros(len(c), dtype=bool)
    bad[where] = True
    good = np.flatnonzero(~bad)
    out: list[tuple[int, float]] = []
    for group in np.split(where, np.flatnonzero(np.diff(where) > 1) + 1):
        if not len(group):
            continue
        k = int(np.searchsorted(good, group[0]))
        support = good[max(k - 2, 0):k + 2]
        coefficients = np.polyfit(support - group[0], c[support], min(3, len(support) - 1))
        out.extend((int(i), float(np.polyval(coefficients, i - group[0]))) for i in group)
    return out

def _glitches_of_run(c: np.ndarray, first: int, last: int, limit: float) -> tuple[np.ndarray, np.ndarray]:
    """The glitches among the samples ``first..last`` (a run of samples whose differences from
    their neighbours' cubic exceed ``limit``) and the values that bridge them.

    A glitch moves the neighbours' cubic of the two samples on each side too, and two glitches
    side by side can make a good neighbour's difference the largest of the run. So the run is
    bridged as a whole, by the cubic through the two samples on each side of it, and the
    samples further than ``limit`` from that bridge are the glitches. A run of glitches spans
    the two neighbours on each side of them, so at least four of its samples agree with the
    bridge; where fewer do, the bridge itself is wrong (a signal with few samples per period
    is no cubic over that span). Empty then, when the run has no two samples on each side, or
    when the bridge finds none.
    """
    support = np.array([first - 2, first - 1, last + 1, last + 2])
    if support[0] < 0 or support[-1] >= len(c):
        return np.zeros(0, dtype=int), np.zeros(0)
    inside = np.arange(first, last + 1)
    bridge = np.polyval(np.polyfit(support - first, c[support], 3), inside - first)
    bad = np.abs(c[inside] - bridge) > limit
    if np.count_nonzero(~bad) < 4:
        return np.zeros(0, dtype=int), np.zeros(0)
    return inside[bad], bridge[bad]


def near_force_jumps(f: np.ndarray) -> np.ndarray:
    """The samples whose neighbours' cubic (two samples on each side) spans a force jump: a
    change more than :data:`~duffid.identification.engine.JUMP_FACTOR` times the median change
    of that force and more than :data:`~duffid.identification.engine.JUMP_RANGE` of its largest
    magnitude (a step, an impact's onset). The displacement's curvature jumps with the force,
    so no cubic through those samples tells a glitch."""
    f = np.asarray(f, dtype=float).reshape(len(f), -1)
    change = np.abs(np.diff(f, axis=0))
    jumps = np.any((change > JUMP_FACTOR * np.median(change, axis=0))
                   & (change > JUMP_RANGE * np.max(np.abs(f), axis=0)), axis=1)
    near = np.zeros(len(f), dtype=bool)
    for k in np.flatnonzero(jumps) + 1:  # the interval k-1..k
        near[max(k - 2, 0):k + 2] = True
    return near


def isolated_outliers(x: np.ndarray, f: np.ndarray | None = None) -> list[tuple[int, int, float]]:
    """Isolated outliers of the displacement columns: (sample, column, value the neighbours give).

    Each interior sample is compared with the cubic through its two neighbours on each side,
    ``(-x[i-2] + 4 x[i-1] + 4 x[i+1] - x[i+2]) / 6``; a sample further from it than
    :data:`OUTLIER_SIGMAS` robust standard deviations of those differences (never less than
    the quantisation step nor :data:`OUTLIER_RANGE` of the column's range) is an outlier; of a run of neighbouring candidates (a spike also
    moves its neighbours' predictions) the largest is taken; the search is repeated on the
    repaired column (a glitch next to another shows once that one is replaced,
    :data:`REPLACEMENT_PASSES` times) and each group of neighbouring outliers is bridged by the
    cubic through the two good samples on each side. Empty when more than
    :data:`MAX_OUTLIER_SHARE` of the samples qualify (then they are not isolated glitches).
    With the forces ``f``, a sample whose neighbours' cubic spans a force jump is never a
    candidate (:func:`near_force_jumps`: a clean double step at 25 samples per period lost its
    real sample before the second step, and b was published 217 % off).
    """
    x = np.asarray(x, dtype=float).reshape(len(x), -1)
    near = np.zeros(len(x), dtype=bool) if f is None else near_force_jumps(f)
    found: list[tuple[int, int, float]] = []
    if len(x) < 8:
        return found
    for j in range(x.shape[1]):
        c = x[:, j]
        r = c[2:-2] - _neighbours(c)
        # never below the quantisation step, nor 1e-4 of the column's range: a noise-free record's
        # own smooth differences would otherwise pass for glitches where it moves fastest
        scale = max(1.4826 * float(np.median(np.abs(r - np.median(r)))), _quantisation_step(c),
                    OUTLIER_RANGE * float(np.ptp(c)), 1e-300)
        work, where = c.copy(), np.zeros(0, dtype=int)
        for _ in range(REPLACEMENT_PASSES):  # a glitch next to another shows once that one is replaced
            prediction = _neighbours(work)
            r = work[2:-2] - prediction
            candidates = np.flatnonzero((np.abs(r) > OUTLIER_SIGMAS * scale) & ~near[2:-2])
            if not len(candidates):
                break
            runs = np.split(candidates, np.flatnonzero(np.diff(candidates) > 1) + 1)
            for run in runs:
                bad, bridge = _glitches_of_run(work, run[0] + 2, run[-1] + 2, OUTLIER_SIGMAS * scale)
                if not len(bad):  # no clean support around the run: its largest difference
                    bad = np.array([int(run[np.argmax(np.abs(r[run]))]) + 2])
                    bridge = prediction[bad - 2]
                work[bad] = bridge
                where = np.union1d(where, bad)
        found.extend((int(i), j, v) for i, v in _bridged(c, where))
    if len(found) > MAX_OUTLIER_SHARE * x.size:
        return []
    return found

def force_varies(record: Record) -> bool:
    """Whether the force varies enough to separate a constant offset from the stiffness."""
    f = record.f
    return bool(np.all(np.std(f, axis=0) > FORCE_VARIATION * np.abs(np.mean(f, axis=0))) and np.any(np.std(f, axis=0) > 0))

def every_second(record: Record) -> Record:
    """The record at half its sampling rate (every second sample)."""
    return Record(record.t[::2], record.f[::2], record.x[::2], source=record.source,
                  sampling_rtol=record.sampling_rtol)
