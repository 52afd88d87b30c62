"""Frequency response functions from records, with what each estimate can be trusted for.

Three estimators, each valid for one kind of record:

``sweep``
    Ratio of the Fourier transforms of the whole record (zero-padded). Exact for a linear
    system when the record holds the whole transient: it starts at rest and the response
    has died out at the end (a sweep, an impact or a burst of random force followed by a
    ring-down). Otherwise leakage biases it (a random force without ring-down: a linear
    plant looks nonlinear).
``h1``
    Welch-averaged ``H1 = S_fx / S_ff`` with the coherence (:mod:`scipy.signal`), for a
    *stationary* random force. The coherence tells how much of the response is linearly
    related to the force; a single sweep is not stationary and biases ``H1`` near resonance.
``stepped``
    Steady-state complex amplitudes of stepped sines (one record per frequency).

Each FRF carries the variance of its lines (from the measurement noise, estimated from
the record itself) and the checks that decide whether the record supports the estimate
(:class:`FRF` ``problems``: the reasons, in words, why it does not).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ..data.record import Record
from ..errors import InputError, OptionError, RecordError

__all__ = [
    "ESTIMATORS",
    "FRF",
    "RationalModel",
    "excited_band",
    "fit_rational",
    "noise_variance",
    "leakage",
    "choose_estimator",
    "frf_from_sweep",
    "frf_from_h1",
    "frf_from_stepped_sines",
    "LEAKAGE_MAX",
    "STATIONARITY_MAX",
    "SETTLING_MAX",
]

#: FRF estimators: ``auto`` chooses ``sweep`` for a record ending at rest, else ``h1``.
ESTIMATORS = ("auto", "sweep", "h1")

# Thresholds of the record checks, set by the simulation study of benchmarks/nonlinearity.py
# (linear 1-DOF plant, sweeps with ring-downs cut short, random forces, SNR 60/40/30 dB):
#: Largest response left at the start or end of a record, relative to its peak, for the
#: ``sweep`` estimator: a sweep whose ring-down is cut at 2 % (6 %) left reads D = -70 dB
#: (-56 dB), well below D_LINEAR_DB; a random force without ring-down leaves 40 % (D = -14 dB).
LEAKAGE_MAX = 2e-2
#: Largest spread (standard deviation) of the force's spectral centroid between Welch
#: segments, relative to the band width, for ``h1``: random forces of the study read 0.07
#: (the periodograms' own scatter), sweeps 0.23 and more.
STATIONARITY_MAX = 0.15
#: Largest change of a stepped sine's response amplitude between the two halves of its
#: analysed steady state, beyond the noise (relative): the response has not settled.
SETTLING_MAX = 1e-2

_MIN_SAMPLES = 64
_MIN_LINES = 8
_EDGE = 0.05            # fraction of the record at its end checked for a residual response
_NOISE_FACTOR = 6.0     # noise is measured above this multiple of the band's top (odd harmonics below)


@dataclass(frozen=True)
class FRF:
    """A frequency response function on a uniform grid ``k * df``, ``k = 0 .. n``.

    Attributes
    ----------
    frequency : ndarray
        Frequencies [Hz] from 0 in steps of ``df``.
    response : ndarray of complex
        Output over input at each frequency (meaningful inside ``band`` only).
    band : tuple of float
        Excited band ``(f1, f2)`` [Hz].
    amplitude : float
        Peak input amplitude of the record(s).
    source : str
        Where the data came from.
    measured : (ndarray, ndarray), optional
        Stepped sines: the measured frequencies and values.
    estimator : str
        ``sweep``, ``h1``, ``stepped`` or ``given``.
    variance : ndarray, optional
        Variance of each line of ``response`` due to measurement noise (NaN: unknown).
    coherence : ndarray, optional
        ``h1``: the coherence of force and displacement on the grid.
    problems : tuple of str
        Why the record does not support this estimate (empty when it does), in words.
    checks : dict
        The figures of the checks (``leakage``, ``stationarity``, ``settling``,
        ``noise_x``, ``noise_f``, ``segments``, ...).
    peak_displacement : float
        Largest absolute displacement of the analysed column (for the nonlinear share).
    """

    frequency: np.ndarray
    response: np.ndarray
    band: tuple[float, float]
    amplitude: float = float("nan")
    source: str = ""
    measured: tuple[np.ndarray, np.ndarray] | None = None
    estimator: str = "given"
    variance: np.ndarray | None = field(default=None, repr=False)
    coherence: np.ndarray | None = field(default=None, repr=False)
    problems: tuple[str, ...] = ()
    checks: dict = field(default_factory=dict)
    peak_displacement: float = float("nan")

    @property
    def in_band(self) -> np.ndarray:
        """Boolean mask of the frequencies inside the band."""
        return (self.frequency >= self.band[0]) & (self.frequency <= self.band[1])

    @property
    def df(self) -> float:
        """Frequency step [Hz]."""
        return float(self.frequency[1] - self.frequency[0])


@dataclass(frozen=True)
class RationalModel:
    """``N(s)/D(s)`` with ``s = j 2 pi f / w_ref``, real coefficients in ascending powers."""

    numerator: np.ndarray
    denominator: np.ndarray
    w_ref: float

    def __call__(self, frequency: np.ndarray) -> np.ndarray:
        s = 2j * np.pi * np.asarray(frequency, dtype=float) / self.w_ref
        return np.polyval(self.numerator[::-1], s) / np.polyval(self.denominator[::-1], s)

    @property
    def poles_hz(self) -> np.ndarray:
        """Poles as complex frequencies [rad/s]."""
        return np.roots(self.denominator[::-1]) * self.w_ref


# ---------------------------------------------------------------------- helpers
def excited_band(frequency: np.ndarray, power: np.ndarray, fraction: float = 0.995) -> tuple[float, float]:
    """The band holding the central ``fraction`` of the input's energy.

    Parameters
    ----------
    frequency : ndarray
        Frequencies [Hz].
    power : ndarray
        Input power spectrum on those frequencies.
    fraction : float
        Energy fraction inside the band (default 99.5 %: 0.25 % cut at each side).
    """
    total = float(np.sum(power))
    if not total > 0:
        raise InputError("the input has no energy: nothing is excited")
    cumulative = np.cumsum(power) / total
    tail = (1.0 - fraction) / 2.0
    lo = int(np.searchsorted(cumulative, tail))
    hi = int(np.searchsorted(cumulative, 1.0 - tail))
    return float(frequency[lo]), float(frequency[min(hi, len(frequency) - 1)])


def noise_variance(signal: np.ndarray, dt: float, f_above: float) -> float:
    """Variance of the white measurement noise on ``signal``, from its spectrum above ``f_above``.

    The median of the periodogram over ``f_above .. 0.9 Nyquist`` (where the signal itself
    has no content) over ``n ln 2`` (the median of an exponential variable is ``ln 2``
    times its mean). Deterministic content there (harmonics, a force's roll-off) can only
    raise the estimate: the checks that use it err towards "cannot tell".

    Returns
    -------
    float
        The variance, or NaN when fewer than 16 lines lie above ``f_above``.
    """
    n = len(signal)
    spectrum = np.abs(np.fft.rfft(signal - np.mean(signal))) ** 2
    freq = np.fft.rfftfreq(n, dt)
    lines = (freq >= f_above) & (freq <= 0.9 * freq[-1])
    if lines.sum() < 16:
        return float("nan")
    return float(np.median(spectrum[lines]) / (n * np.log(2.0)))


def _noise_reference(record: Record, top: float) -> float:
    """The frequency above which a record's spectrum is taken as noise."""
    return min(_NOISE_FACTOR * top, 0.5 * 0.5 / record.dt)


def leakage(x: np.ndarray, noise_var: float) -> tuple[float, float]:
    """Response left at the start (first 10 samples) and end (last 5 %) of a record, relative to its peak.

    The RMS of each edge beyond what the noise explains (its variance plus three standard
    errors of the edge's mean square), times sqrt(2) (a sinusoid's peak), over the largest
    absolute value of ``x``.
    """
    peak = float(np.max(np.abs(x)))
    if not peak > 0:
        return 0.0, 0.0
    var = noise_var if np.isfinite(noise_var) else 0.0

    def residual(part: np.ndarray) -> float:
        allowed = var * (1.0 + 3.0 * np.sqrt(2.0 / len(part)))
        return float(np.sqrt(2.0 * max(np.mean(part**2) - allowed, 0.0)) / peak)

    n = len(x)
    return residual(x[:10]), residual(x[-max(int(n * _EDGE), 2):])


def _check_band(frf_freq: np.ndarray, band: tuple[float, float], power: np.ndarray, source: str) -> None:
    f1, f2 = band
    if not (np.isfinite(f1) and np.isfinite(f2) and 0 <= f1 < f2):
        raise InputError(f"{source}: band must satisfy 0 <= f1 < f2, got {band}")
    mask = (frf_freq >= f1) & (frf_freq <= f2)
    if mask.sum() < _MIN_LINES:
        raise InputError(f"{source}: the band {f1:g}-{f2:g} Hz holds {mask.sum()} frequency lines, "
                         f"at least {_MIN_LINES} are needed (longer record or wider band)")
    e1, e2 = excited_band(frf_freq, power)
    reference = float(np.mean(power[(frf_freq >= e1) & (frf_freq <= e2)]))
    if not float(np.mean(power[mask])) >= 1e-3 * reference:
        raise InputError(f"{source}: the input has no excitation in the band {f1:g}-{f2:g} Hz "
                         f"(its energy lies in {e1:.3g}-{e2:.3g} Hz)")


def _check_columns(record: Record, output: int, input: int) -> None:
    if record.n_samples < _MIN_SAMPLES:
        raise RecordError(f"{record.source}: the FRF needs at least {_MIN_SAMPLES} samples, "
                          f"the record has {record.n_samples}")
    if not 0 <= output < record.n_dof or not 0 <= input < record.n_forces:
        raise InputError(f"{record.source}: no displacement column {output + 1} or force column {input + 1}")


def _noises(record: Record, output: int, input: int, top: float) -> tuple[float, float]:
    ref = _noise_reference(record, top)
    return (noise_variance(record.x[:, output], record.dt, ref),
            noise_variance(record.f[:, input], record.dt, ref))


def _force_band(record: Record, input: int) -> tuple[float, float]:
    u = np.fft.rfft(record.f[:, input])
    return excited_band(np.fft.rfftfreq(record.n_samples, record.dt), np.abs(u) ** 2)


def choose_estimator(record: Record, *, output: int = 0, input: int = 0) -> str:
    """``sweep`` when the record starts and ends at rest (leakage under :data:`LEAKAGE_MAX`), else ``h1``."""
    _check_columns(record, output, input)
    _, top = _force_band(record, input)
    noise_x, _ = _noises(record, output, input, top)
    start, end = leakage(record.x[:, output], noise_x)
    return "sweep" if max(start, end) <= LEAKAGE_MAX else "h1"


# ---------------------------------------------------------------------- estimators
def frf_from_sweep(record: Record, *, band: tuple[float, float] | None = None, output: int = 0,
                   input: int = 0, pad: int = 2) -> FRF:
    """FRF of a transient record: ratio of the Fourier transforms of the whole record.

    Parameters
    ----------
    record : Record
        Sweep (or impact, or burst) plus ring-down, starting from rest; when the response
        has not died out at the end (or was moving at the start), ``problems`` says so.
    band : (f1, f2), optional
        Excited band [Hz]; default: the central 99.5 % of the input's energy.
    output, input : int
        Displacement and force columns (0-based).
    pad : int
        Zero-padding factor (finer grid, longer impulse response window).
    """
    record.require_displacement("this FRF (displacement over force)")
    _check_columns(record, output, input)
    n_orig = record.n_samples
    n = pad * n_orig
    u = np.fft.rfft(record.f[:, input], n)
    y = np.fft.rfft(record.x[:, output], n)
    freq = np.fft.rfftfreq(n, record.dt)
    power = np.abs(u) ** 2
    if band is None:
        band = excited_band(freq, power)
    _check_band(freq, band, power, record.source)
    with np.errstate(divide="ignore", invalid="ignore"):
        response = np.where(power > 0, y / u, 0.0)
        noise_x, noise_f = _noises(record, output, input, band[1])
        nx = noise_x if np.isfinite(noise_x) else 0.0
        nf = noise_f if np.isfinite(noise_f) else 0.0
        variance = np.where(power > 0, (nx + np.abs(response) ** 2 * nf) * n_orig / power, np.inf)
    start, end = leakage(record.x[:, output], noise_x)
    problems = []
    if end > LEAKAGE_MAX:
        problems.append(f"the response has not decayed at the end (last {100 * _EDGE:g} % of the record: "
                        f"{100 * end:.2g} % of its peak, at most {100 * LEAKAGE_MAX:g} % allowed): "
                        "append a ring-down or use --estimator h1")
    if start > LEAKAGE_MAX:
        problems.append(f"the response is not at rest at the start ({100 * start:.2g} % of its peak in the "
                        f"first 10 samples): start the record at rest")
    checks = {"leakage_start": start, "leakage_end": end, "noise_x": noise_x, "noise_f": noise_f}
    return FRF(freq, response, (float(band[0]), float(band[1])),
               float(np.max(np.abs(record.f[:, input]))), record.source, estimator="sweep",
               variance=variance, problems=tuple(problems), checks=checks,
               peak_displacement=float(np.max(np.abs(record.x[:, output]))))


def frf_from_h1(record: Record, *, band: tuple[float, float] | None = None, output: int = 0,
                input: int = 0, segments: int = 8, n_modes: int = 1) -> FRF:
    """Averaged ``H1 = S_fx / S_ff`` with the coherence, for a stationary random force.

    Welch's method with Hann windows and 50 % overlap (:func:`scipy.signal.csd`,
    :func:`scipy.signal.welch`, :func:`scipy.signal.coherence`); the variance of each line
    is ``(coh_lin - coh) / (2 n coh) |H1|^2`` for ``n`` averaged segments, where ``coh_lin``
    is the coherence that a linear model of H1 driven by the measured force has with the
    force: the loss that the segments' finite resolution causes is a bias, the same for
    every record of the plant, not a random error.

    Parameters
    ----------
    record : Record
        A record under a stationary random force (no ring-down needed).
    segments : int
        The record is cut into this many non-overlapping lengths; with 50 % overlap about
        ``2 segments - 1`` are averaged. Each must span several decay times of the plant.
    n_modes : int
        Modes of the linear model whose response to the measured force gives the coherence
        loss that the segments' resolution alone causes (``incoherent_resolution``).
    """
    record.require_displacement("this FRF (displacement over force)")
    from scipy.signal import coherence, csd, spectrogram, welch

    _check_columns(record, output, input)
    if segments < 2:
        raise OptionError(f"segments must be at least 2, got {segments}")
    fs = 1.0 / record.dt
    nperseg = record.n_samples // segments
    if nperseg < _MIN_SAMPLES:
        raise RecordError(f"{record.source}: {segments} segments of {nperseg} samples are too short for H1 "
                          f"(at least {_MIN_SAMPLES} each): a longer record or fewer segments")
    u, x = record.f[:, input], record.x[:, output]
    freq, s_ff = welch(u, fs, nperseg=nperseg)
    _, s_fx = csd(u, x, fs, nperseg=nperseg)
    _, s_xx = welch(x, fs, nperseg=nperseg)
    if not np.sum(s_ff) > 0:
        raise RecordError(f"{record.source}: the force has no energy once each segment's mean is removed (a "
                          "constant or a step): H1 needs a stationary broadband force; a transient that starts "
                          "and ends at rest takes the sweep estimator (--estimator sweep)")
    with np.errstate(divide="ignore", invalid="ignore"):
        _, coh = coherence(u, x, fs, nperseg=nperseg)
    if band is None:
        band = excited_band(freq, s_ff)
    _check_band(freq, band, s_ff, record.source)
    averages = max(2 * segments - 1, 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        response = np.where(s_ff > 0, s_fx / s_ff, 0.0)
    noise_x, noise_f = _noises(record, output, input, band[1])
    inside = (freq >= band[0]) & (freq <= band[1])
    # stationarity: the force's spectral centroid in the band, segment by segment
    _, _, spec = spectrogram(u, fs, nperseg=nperseg)
    sf = spec[inside]
    weights = sf.sum(axis=0)
    centroids = (freq[inside, None] * sf).sum(axis=0) / np.where(weights > 0, weights, np.inf)
    spread = float(np.std(centroids) / (band[1] - band[0])) if len(centroids) > 1 else 0.0
    # the share of the in-band response not linearly related to the force; the part of it
    # that the measurement noise explains (white noise: one-sided density 2 var / fs); and
    # the part that the segments' finite resolution explains (leakage of the resonances):
    # the same share for a linear model of H1 driven by the measured force
    total = float(np.sum(s_xx[inside]))
    incoherent = float(np.sum((1.0 - coh[inside]) * s_xx[inside]) / total) if total > 0 else float("nan")
    nx = noise_x if np.isfinite(noise_x) else 0.0
    nf = noise_f if np.isfinite(noise_f) else 0.0
    noise_part = float(np.sum(2.0 / fs * (nx + np.abs(response[inside]) ** 2 * nf)) / total) if total > 0 else 0.0
    resolution_part = float("nan")
    try:
        model = fit_rational(freq[inside], response[inside], n_modes)
        n = 2 * record.n_samples
        linear = np.fft.irfft(np.fft.rfft(u, n) * model(np.fft.rfftfreq(n, record.dt)), n)[: record.n_samples]
        _, s_ll = welch(linear, fs, nperseg=nperseg)
        _, coh_l = coherence(u, linear, fs, nperseg=nperseg)
        resolution_part = float(np.sum((1.0 - coh_l[inside]) * s_ll[inside]) / np.sum(s_ll[inside]))
        # the random part of the coherence loss: beyond what the resolution alone causes
        random_loss = np.maximum(coh_l - coh, 0.0)
    except (InputError, np.linalg.LinAlgError, ValueError):
        random_loss = 1.0 - coh
    with np.errstate(divide="ignore", invalid="ignore"):
        variance = np.where(coh > 0, random_loss / (2.0 * averages * coh) * np.abs(response) ** 2, np.inf)
    problems = []
    if spread > STATIONARITY_MAX:
        problems.append(f"the force is not stationary (its spectrum moves by {100 * spread:.2g} % of the band "
                        f"between segments, at most {100 * STATIONARITY_MAX:g} % allowed; a sweep?): "
                        "H1 needs a stationary random force; append a ring-down and use --estimator sweep")
    checks = {"stationarity": spread, "incoherent": incoherent, "incoherent_noise": noise_part,
              "incoherent_resolution": resolution_part,
              "segments": averages, "noise_x": noise_x, "noise_f": noise_f,
              "coherence_min": float(np.min(coh[inside]))}
    return FRF(freq, response, (float(band[0]), float(band[1])), float(np.max(np.abs(u))), record.source,
               estimator="h1", variance=variance, coherence=coh, problems=tuple(problems), checks=checks,
               peak_displacement=float(np.max(np.abs(x))))


def _complex_amplitude(signal: np.ndarray, t: np.ndarray, frequency: float) -> complex:
    phasor = np.exp(-2j * np.pi * frequency * t)
    return complex(2.0 * np.mean(signal * phasor))


def _excitation_frequency(record: Record, input: int) -> float:
    """Frequency of a sine input: the FFT peak refined by a least-squares sine fit
    (cos, sin and offset at the trial frequency, as in IEEE 1057), which, unlike a DFT
    correlation, is unbiased when the record is not a whole number of periods."""
    from scipy.optimize import minimize_scalar

    u = record.f[:, input]
    t = record.t - record.t[0]
    spectrum = np.abs(np.fft.rfft(u - u.mean()))
    bin_width = 1.0 / (record.n_samples * record.dt)
    peak = float(np.argmax(spectrum[1:]) + 1) * bin_width

    def residual(f: float) -> float:
        basis = np.column_stack([np.cos(2 * np.pi * f * t), np.sin(2 * np.pi * f * t), np.ones_like(t)])
        return float(np.linalg.lstsq(basis, u, rcond=None)[1].sum())

    found = minimize_scalar(residual, bounds=(max(peak - bin_width, 1e-9), peak + bin_width),
                            method="bounded", options={"xatol": 1e-10 * peak})
    return float(found.x)


def frf_from_stepped_sines(records: Sequence[Record], *, frequencies: Sequence[float] | None = None,
                           output: int = 0, input: int = 0, settle_fraction: float = 0.5,
                           df: float | None = None, n_modes: int = 1) -> FRF:
    """FRF from stepped-sine records (one excitation frequency per record).

    The complex amplitudes of input and output at the excitation frequency are taken
    over the largest integer number of periods in the last ``settle_fraction`` of each
    record (the steady state), then interpolated onto a uniform grid for the Hilbert
    transform: a linear model of ``n_modes`` modes fitted to the points plus a cubic
    spline of the residual. A response whose amplitude differs between the two halves of
    that steady state by more than :data:`SETTLING_MAX` (beyond the noise) has not settled:
    ``problems`` names the frequencies.

    Parameters
    ----------
    records : sequence of Record
        One record per frequency, at least ``8``.
    frequencies : sequence of float, optional
        Excitation frequencies [Hz]; default: the input's spectral peak of each record.
    df : float, optional
        Step of the uniform grid (default: a tenth of the smallest spacing).
    """
    from scipy.interpolate import CubicSpline

    if len(records) < _MIN_LINES:
        raise InputError(f"stepped sines need at least {_MIN_LINES} records, got {len(records)}")
    points = []
    for k, rec in enumerate(records):
        _check_columns(rec, output, input)
        f0 = float(frequencies[k]) if frequencies is not None else _excitation_frequency(rec, input)
        if not f0 > 0:
            raise InputError(f"{rec.source}: no excitation frequency found")
        periods = int(settle_fraction * rec.duration * f0)
        if periods < 2:
            raise RecordError(f"{rec.source}: the steady state holds {periods} period(s) of {f0:g} Hz; "
                              "at least 2 are needed")
        n = int(round(periods / f0 / rec.dt))
        t, u, y = rec.t[-n:], rec.f[-n:, input], rec.x[-n:, output]
        U, Y = _complex_amplitude(u, t, f0), _complex_amplitude(y, t, f0)
        noise_x, noise_f = _noises(rec, output, input, f0)
        nx = noise_x if np.isfinite(noise_x) else 0.0
        nf = noise_f if np.isfinite(noise_f) else 0.0
        F = Y / U
        variance = 4.0 * (nx + abs(F) ** 2 * nf) / n / abs(U) ** 2
        half = (periods // 2) * int(round(1.0 / f0 / rec.dt)) if periods >= 4 else 0
        settling = 0.0
        if half > 0:  # compare whole periods at the start and end of the steady state
            first = abs(_complex_amplitude(y[:half], t[:half], f0))
            last = abs(_complex_amplitude(y[-half:], t[-half:], f0))
            noise_amp = 2.0 * np.sqrt(4.0 * nx / half)
            settling = max(abs(last - first) - noise_amp, 0.0) / max(abs(Y), 1e-300)
        points.append((f0, F, float(np.max(np.abs(rec.f[:, input]))), variance, settling,
                       float(np.max(np.abs(rec.x[:, output])))))
    points.sort(key=lambda p: p[0])
    f = np.array([p[0] for p in points])
    if np.any(np.diff(f) <= 0):
        raise InputError("stepped sines: two records share an excitation frequency")
    response = np.array([p[1] for p in points])
    step = df or float(np.min(np.diff(f))) / 10.0
    grid = np.arange(0.0, f[-1] * 4.0 + step, step)
    values = np.zeros(len(grid), dtype=complex)
    inside = (grid >= f[0]) & (grid <= f[-1])
    model = fit_rational(f, response, n_modes)
    residual = response - model(f)
    spline = CubicSpline(f, residual.real)(grid[inside]) + 1j * CubicSpline(f, residual.imag)(grid[inside])
    values[inside] = model(grid[inside]) + spline
    point_var = np.array([p[3] for p in points])
    variance = np.interp(grid, f, point_var)  # held constant outside the measured range
    unsettled = [p[0] for p in points if p[4] > SETTLING_MAX]
    problems = []
    if unsettled:
        problems.append(f"the response has not settled at {', '.join(f'{v:.3g}' for v in unsettled)} Hz "
                        f"(its amplitude changes by more than {100 * SETTLING_MAX:g} % within the analysed "
                        "steady state): dwell longer at each frequency")
    checks = {"settling": max(p[4] for p in points)}
    return FRF(grid, values, (float(f[0]), float(f[-1])), max(p[2] for p in points),
               f"{len(records)} stepped sines", measured=(f, response), estimator="stepped",
               variance=variance, problems=tuple(problems), checks=checks,
               peak_displacement=max(p[5] for p in points))


# ---------------------------------------------------------------------- linear model fit
def fit_rational(frequency: np.ndarray, response: np.ndarray, n_modes: int, *,
                 iterations: int = 20) -> RationalModel:
    """Fit a linear modal model ``N(s)/D(s)`` (``n_modes`` modes) to FRF samples.

    The denominator has degree ``2 n_modes`` (monic), the numerator ``2 n_modes - 2``
    (a displacement over force FRF rolls off as ``1/w^2``). Sanathanan-Koerner
    iterations weight Levy's linearised least squares by ``1/|D|``; unstable poles are
    reflected into the left half-plane and the numerator refitted.
    """
    if n_modes < 1:
        raise InputError(f"n_modes must be >= 1, got {n_modes}")
    w = 2.0 * np.pi * np.asarray(frequency, dtype=float)
    if len(w) < 4 * n_modes:
        raise InputError(f"fitting {n_modes} mode(s) needs at least {4 * n_modes} frequency lines, got {len(w)}")
    w_ref = float(np.sqrt(max(w.min(), w.max() * 1e-3) * w.max()))
    s = 1j * w / w_ref
    na, nb = 2 * n_modes, 2 * n_modes - 2
    Sa = s[:, None] ** np.arange(na)       # D = s^na + sum a_i s^i
    Sb = s[:, None] ** np.arange(nb + 1)
    weight = np.ones(len(s))
    for _ in range(iterations):
        M = np.hstack([Sb, -response[:, None] * Sa]) * weight[:, None]
        rhs = response * s**na * weight
        coef = np.linalg.lstsq(np.vstack([M.real, M.imag]), np.concatenate([rhs.real, rhs.imag]), rcond=None)[0]
        den = np.concatenate([coef[nb + 1:], [1.0]])
        weight = 1.0 / np.maximum(np.abs(np.polyval(den[::-1], s)), 1e-300)
    poles = np.roots(den[::-1])
    if np.any(poles.real > 0):  # reflect unstable poles, refit the numerator
        poles = np.where(poles.real > 0, -poles.real + 1j * poles.imag, poles)
        den = np.real(np.poly(poles))[::-1]
        D = np.polyval(den[::-1], s)
        M = Sb / D[:, None]
        num = np.linalg.lstsq(np.vstack([M.real, M.imag]), np.concatenate([response.real, response.imag]), rcond=None)[0]
    else:
        num = coef[: nb + 1]
    return RationalModel(np.asarray(num, dtype=float), np.asarray(den, dtype=float), w_ref)
