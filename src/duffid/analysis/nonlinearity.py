"""Nonlinearity quantification with the Hilbert transform of the FRF (paper section 2.2).

For a causal linear system the real and imaginary parts of the frequency response
function ``F`` are a Hilbert pair (eqs. 6-7), so ``H{F} = F``; a nonlinear system
distorts ``H{F}``. With the impulse response ``h = IFFT(F)``::

    H{F} = FFT(sgn(t) h(t))        (sgn(t) = +1 for t >= 0, -1 for t < 0)

which leaves a causal ``h`` unchanged.

Band edges
    ``F`` is only known in the excited band. Setting it to zero outside (the
    *uncorrected* form, used for the paper's figures) makes ``h`` acausal by itself: a
    linear plant then gives ``eta`` around 0.95 (NOTES.md). The *corrected* form extends
    ``F`` outside the band with a linear modal model fitted to the in-band FRF (rational
    fit by Sanathanan-Koerner iterations, unstable poles reflected), so that a linear
    plant gives ``eta = 1`` to rounding.

Indices (over the band)
    ``eta = |X_HF(0)|^2`` with the normalised cross-correlation at zero lag (eqs. 8-9)::

        X_HF(0) = sum H{F} conj(F) / sqrt(sum |H{F}|^2 sum |F|^2)

    (the conjugate makes ``eta = 1`` exactly when ``H{F} = F``), and the more sensitive
    *Hilbert distortion*, a normalised mean square error in dB::

        D = 10 log10( sum |H{F} - F|^2 / sum |F|^2 )

    ``eta`` is insensitive to a change of scale of ``H{F}`` and responds only to the square
    of small distortions (``eta ~ 1 - d^2`` for a relative distortion ``d``); ``D`` responds
    to ``d`` itself: -60 dB is a 0.1 % distortion. The paper's criterion is
    ``eta >= 0.9``: "dominantly linear".

FRF estimation
    From a swept sine: ratio of the Fourier transforms of the whole record (sweep plus
    ring-down, zero-padded), which is exact for a linear system whose response has died
    out; a Welch-averaged H1 estimate on a single sweep is biased near resonance
    (NOTES.md). From stepped sines: the complex amplitudes at each excitation frequency
    over an integer number of periods of the steady state, interpolated onto a uniform
    grid for the transform.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import numpy as np

from ..data.record import Record
from ..data.signals import Chirp, Gated
from ..errors import InputError, RecordError, SimulationError
from ..models.chain import Chain
from ..models.simulation import simulate

__all__ = [
    "FRF",
    "RationalModel",
    "NonlinearityResult",
    "frf_from_sweep",
    "frf_from_stepped_sines",
    "excited_band",
    "fit_rational",
    "hilbert_transform",
    "nonlinearity_index",
    "hilbert_distortion",
    "analyse",
    "amplitude_sweep",
    "sweep_record",
    "LINEARITY_THRESHOLD",
]

#: The paper's criterion: eta >= 0.9 means "dominantly linear".
LINEARITY_THRESHOLD = 0.9
_MIN_SAMPLES = 64
_MIN_LINES = 8


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
    """

    frequency: np.ndarray
    response: np.ndarray
    band: tuple[float, float]
    amplitude: float = float("nan")
    source: str = ""
    measured: tuple[np.ndarray, np.ndarray] | None = None  # stepped sines: (frequencies, values)

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


@dataclass
class NonlinearityResult:
    """Hilbert-transform nonlinearity figures of one FRF.

    Attributes
    ----------
    eta : float
        Index of eqs. (8)-(9) with the band-edge correction (or uncorrected if asked).
    eta_uncorrected : float
        Index with the FRF truncated to the band (the paper's figures).
    distortion_db : float
        Hilbert distortion ``10 log10(sum|H{F} - F|^2 / sum|F|^2)`` over the band.
    band : tuple of float
        Band [Hz].
    amplitude : float
        Peak input amplitude.
    corrected : bool
        Whether ``eta`` uses the band-edge correction.
    frf, transform, transform_uncorrected : optional
        Data for plots.
    """

    eta: float
    eta_uncorrected: float
    distortion_db: float
    band: tuple[float, float]
    amplitude: float
    corrected: bool = True
    source: str = ""
    frf: FRF | None = field(default=None, repr=False)
    transform: np.ndarray | None = field(default=None, repr=False)
    transform_uncorrected: np.ndarray | None = field(default=None, repr=False)

    @property
    def verdict(self) -> str:
        """``"dominantly linear"`` when ``eta >= 0.9`` (the paper's criterion), else ``"nonlinear"``."""
        if not np.isfinite(self.eta):
            return "undetermined"
        return "dominantly linear" if self.eta >= LINEARITY_THRESHOLD else "nonlinear"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary with at least ``eta`` and ``band``."""
        def clean(v: float) -> float | None:
            return float(v) if np.isfinite(v) else None
        return {
            "eta": clean(self.eta),
            "band": [float(self.band[0]), float(self.band[1])],
            "eta_uncorrected": clean(self.eta_uncorrected),
            "distortion_db": clean(self.distortion_db),
            "corrected": self.corrected,
            "amplitude": clean(self.amplitude),
            "verdict": self.verdict,
            "source": self.source,
        }


# ---------------------------------------------------------------------- FRF estimation
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


def _check_band(frf_freq: np.ndarray, band: tuple[float, float], power: np.ndarray, source: str) -> None:
    f1, f2 = band
    if not (np.isfinite(f1) and np.isfinite(f2) and 0 <= f1 < f2):
        raise InputError(f"{source}: band must satisfy 0 <= f1 < f2, got {band}")
    mask = (frf_freq >= f1) & (frf_freq <= f2)
    if mask.sum() < _MIN_LINES:
        raise InputError(f"{source}: the band {f1:g}-{f2:g} Hz holds {mask.sum()} frequency lines, "
                         f"at least {_MIN_LINES} are needed (longer record or wider band)")
    # compare the in-band power density with that of the band holding the input's energy
    e1, e2 = excited_band(frf_freq, power)
    reference = float(np.mean(power[(frf_freq >= e1) & (frf_freq <= e2)]))
    if not float(np.mean(power[mask])) >= 1e-3 * reference:
        raise InputError(f"{source}: the input has no excitation in the band {f1:g}-{f2:g} Hz "
                         f"(its energy lies in {e1:.3g}-{e2:.3g} Hz)")


def frf_from_sweep(record: Record, *, band: tuple[float, float] | None = None, output: int = 0,
                   input: int = 0, pad: int = 2) -> FRF:
    """FRF of a swept-sine record: ratio of the Fourier transforms of the whole record.

    Parameters
    ----------
    record : Record
        Sweep plus ring-down, starting from rest; the response should have died out at
        the end (otherwise leakage biases the FRF).
    band : (f1, f2), optional
        Excited band [Hz]; default: the central 99.5 % of the input's energy.
    output, input : int
        Displacement and force columns.
    pad : int
        Zero-padding factor (finer grid, longer impulse response window).
    """
    if record.n_samples < _MIN_SAMPLES:
        raise RecordError(f"{record.source}: the FRF needs at least {_MIN_SAMPLES} samples, "
                          f"the record has {record.n_samples}")
    if not 0 <= output < record.n_dof or not 0 <= input < record.n_forces:
        raise InputError(f"{record.source}: no displacement column {output} or force column {input}")
    tail = max(record.n_samples // 20, 1)
    residual = float(np.max(np.abs(record.x[-tail:, output])) / max(np.max(np.abs(record.x[:, output])), 1e-300))
    if residual > 1e-2 or np.max(np.abs(record.f[-tail:, input])) > 0:
        warnings.warn(f"{record.source}: the record does not end in a ring-down at rest (last 5 %: "
                      f"response {100 * residual:.2g} % of its peak, force "
                      f"{'non-zero' if np.max(np.abs(record.f[-tail:, input])) > 0 else 'zero'}); "
                      "the FRF is biased by leakage: record a longer ring-down", UserWarning, stacklevel=2)
    n = pad * record.n_samples
    u = np.fft.rfft(record.f[:, input], n)
    y = np.fft.rfft(record.x[:, output], n)
    freq = np.fft.rfftfreq(n, record.dt)
    power = np.abs(u) ** 2
    if band is None:
        band = excited_band(freq, power)
    _check_band(freq, band, power, record.source)
    with np.errstate(divide="ignore", invalid="ignore"):
        response = np.where(power > 0, y / u, 0.0)
    return FRF(freq, response, (float(band[0]), float(band[1])),
               float(np.max(np.abs(record.f[:, input]))), record.source)


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
    spline of the residual.

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
        if frequencies is not None:
            f0 = float(frequencies[k])
        else:
            f0 = _excitation_frequency(rec, input)
        if not f0 > 0:
            raise InputError(f"{rec.source}: no excitation frequency found")
        periods = int(settle_fraction * rec.duration * f0)
        if periods < 2:
            raise RecordError(f"{rec.source}: the steady state holds {periods} period(s) of {f0:g} Hz; "
                              "at least 2 are needed")
        n = int(round(periods / f0 / rec.dt))
        t, u, y = rec.t[-n:], rec.f[-n:, input], rec.x[-n:, output]
        points.append((f0, _complex_amplitude(y, t, f0) / _complex_amplitude(u, t, f0),
                       float(np.max(np.abs(rec.f[:, input])))))
    points.sort()
    f = np.array([p[0] for p in points])
    if np.any(np.diff(f) <= 0):
        raise InputError("stepped sines: two records share an excitation frequency")
    response = np.array([p[1] for p in points])
    step = df or float(np.min(np.diff(f))) / 10.0
    grid = np.arange(0.0, f[-1] * 4.0 + step, step)
    values = np.zeros(len(grid), dtype=complex)
    inside = (grid >= f[0]) & (grid <= f[-1])
    # model-based interpolation: the fitted linear model plus a spline of the residual, so
    # that sparse points across a resonance do not invent a distortion
    model = fit_rational(f, response, n_modes)
    residual = response - model(f)
    spline = CubicSpline(f, residual.real)(grid[inside]) + 1j * CubicSpline(f, residual.imag)(grid[inside])
    values[inside] = model(grid[inside]) + spline
    return FRF(grid, values, (float(f[0]), float(f[-1])), max(p[2] for p in points),
               f"{len(records)} stepped sines", measured=(f, response))


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


# ---------------------------------------------------------------------- transform and indices
def hilbert_transform(frf: FRF, *, corrected: bool = True, n_modes: int = 1) -> np.ndarray:
    """``H{F}`` on the FRF's grid: ``FFT(sgn(t) * IFFT(F))``.

    Parameters
    ----------
    frf : FRF
        FRF on a uniform grid starting at 0 Hz.
    corrected : bool
        Extend the FRF outside its band with a fitted linear model ``M`` (``n_modes``
        modes): ``H{F} = M + H{(F - M) 1_band}`` (``H{M} = M`` for the causal, stable
        model); otherwise set the FRF to zero outside the band (the uncorrected form).
    n_modes : int
        Modes of the linear model used for the extension.
    """
    inside = frf.in_band
    if not corrected:
        return _sign_transform(np.where(inside, frf.response, 0.0))
    # the fitted model M is causal and stable, so H{M} = M exactly; only the in-band
    # residual F - M goes through the FFT (no truncation of M's tail at Nyquist)
    model = fit_rational(frf.frequency[inside], frf.response[inside], n_modes)
    fitted = model(frf.frequency)
    return fitted + _sign_transform(np.where(inside, frf.response - fitted, 0.0))


def _sign_transform(spectrum: np.ndarray) -> np.ndarray:
    """``FFT(sgn(t) IFFT(spectrum))`` for a one-sided spectrum on ``0 .. Nyquist``."""
    n = 2 * (len(spectrum) - 1)
    h = np.fft.irfft(spectrum, n)
    sign = np.ones(n)
    sign[n // 2 + 1:] = -1.0   # the second half of the window holds negative times
    sign[n // 2] = 0.0         # the Nyquist lag belongs to neither side
    return np.fft.rfft(sign * h, n)


def nonlinearity_index(frf: np.ndarray, transform: np.ndarray) -> float:
    """``eta = |sum H conj(F)|^2 / (sum|H|^2 sum|F|^2)`` (eqs. 8-9), over the given samples."""
    num = np.abs(np.vdot(frf, transform)) ** 2
    den = float(np.sum(np.abs(transform) ** 2) * np.sum(np.abs(frf) ** 2))
    return float(num / den) if den > 0 else float("nan")


def hilbert_distortion(frf: np.ndarray, transform: np.ndarray) -> float:
    """``10 log10(sum |H - F|^2 / sum |F|^2)`` [dB] over the given samples."""
    err = float(np.sum(np.abs(transform - frf) ** 2))
    ref = float(np.sum(np.abs(frf) ** 2))
    if ref <= 0:
        return float("nan")
    return 10.0 * np.log10(max(err / ref, 1e-300))


def analyse(data: Record | FRF, *, band: tuple[float, float] | None = None, corrected: bool = True,
            n_modes: int | None = None, output: int = 0) -> NonlinearityResult:
    """Nonlinearity figures of a sweep record (or an FRF).

    Parameters
    ----------
    data : Record or FRF
        A swept-sine record with ring-down, or an FRF (e.g. from stepped sines).
    band : (f1, f2), optional
        Band [Hz]; default from the input's energy.
    corrected : bool
        ``eta`` with the band-edge correction (default) or uncorrected.
    n_modes : int, optional
        Modes of the linear extension; default: the record's number of DOFs (1 for an FRF).
    output : int
        Displacement column of a record.
    """
    if isinstance(data, Record):
        frf = frf_from_sweep(data, band=band, output=output)
        modes = n_modes or data.n_dof
    else:
        frf = data if band is None else FRF(data.frequency, data.response, band, data.amplitude, data.source,
                                            data.measured)
        modes = n_modes or 1
    inside = frf.in_band
    with_correction = hilbert_transform(frf, corrected=True, n_modes=modes)
    without = hilbert_transform(frf, corrected=False)
    F = frf.response[inside]
    main = with_correction if corrected else without
    return NonlinearityResult(
        eta=nonlinearity_index(F, main[inside]),
        eta_uncorrected=nonlinearity_index(F, without[inside]),
        distortion_db=hilbert_distortion(F, main[inside]),
        band=frf.band, amplitude=frf.amplitude, corrected=corrected, source=frf.source,
        frf=frf, transform=with_correction, transform_uncorrected=without,
    )


# ---------------------------------------------------------------------- amplitude sweeps
def sweep_record(plant: Chain, amplitude: float, *, rate: float = 2.5, f_max: float = 10.0,
                 ring_down: float | None = None, dt: float = 2e-3) -> Record:
    """Simulate the paper's sweep ``A sin(pi rate t^2)`` (instantaneous frequency ``rate t``)
    from 0 to ``f_max`` Hz on DOF 1 of ``plant``, followed by a ring-down at zero force.

    The default ring-down lasts 12 time constants of the plant's slowest linear mode
    (its response decays to about 6e-6), so that the FRF of the record is not biased.
    """
    duration = f_max / rate
    if ring_down is None:
        decay = -np.max(plant.linear_poles().real)
        if not decay > 0:
            raise InputError(f"{plant.name}: the linearised plant is not damped; give ring_down")
        ring_down = 12.0 / decay
    force = Gated(Chirp.paper_sweep(amplitude, rate, duration=duration), duration)
    return simulate(plant, force, duration + ring_down, dt)


def amplitude_sweep(amplitudes: Sequence[float], simulator: Callable[[float], Record] | Chain, *,
                    band: tuple[float, float] | None = None, n_modes: int | None = None,
                    progress: bool = False, **sweep_options: Any) -> list[NonlinearityResult]:
    """``eta`` at each excitation amplitude.

    Parameters
    ----------
    amplitudes : sequence of float
        Peak force amplitudes [N].
    simulator : Chain or callable
        A plant model (simulated with :func:`sweep_record` and ``sweep_options``) or any
        function ``amplitude -> Record`` (e.g. an FMU run, or reading recorded CSVs).
    band, n_modes
        See :func:`analyse`; the band defaults to the one found at the first amplitude so
        that every amplitude is compared on the same band.
    progress : bool
        Show a progress bar.

    Returns
    -------
    list of NonlinearityResult
        One per amplitude; a plant that escapes its potential well gives ``eta = NaN``
        (verdict "undetermined") with the reason in ``source``.
    """
    from tqdm import tqdm

    run = simulator if callable(simulator) and not isinstance(simulator, Chain) else (
        lambda a: sweep_record(simulator, a, **sweep_options))
    results = []
    for amplitude in tqdm(amplitudes, desc="amplitudes", disable=not progress, leave=False):
        try:
            record = run(float(amplitude))
        except SimulationError as exc:
            results.append(NonlinearityResult(np.nan, np.nan, np.nan, band or (np.nan, np.nan),
                                              float(amplitude), source=f"escaped: {exc}"))
            continue
        result = analyse(record, band=band, n_modes=n_modes)
        band = band or result.band
        results.append(result)
    return results
