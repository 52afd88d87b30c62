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

FRF estimation and the verdict
    :mod:`duffid.analysis.frf` estimates the FRF the way the record allows (ratio of
    transforms for a sweep plus ring-down, averaged H1 for a stationary random force,
    stepped sines) and checks it; :mod:`duffid.analysis.verdict` turns ``eta``, ``D`` and
    those checks into "dominantly linear", "nonlinear" or "cannot tell" with the reasons.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import numpy as np

from ..data.record import Record
from ..data.signals import Chirp, Gated
from ..errors import InputError, OptionError, SimulationError
from ..models.chain import Chain
from ..models.simulation import simulate
from .frf import (
    ESTIMATORS,
    FRF,
    RationalModel,
    choose_estimator,
    excited_band,
    fit_rational,
    frf_from_h1,
    frf_from_stepped_sines,
    frf_from_sweep,
)
from .verdict import ETA_NONLINEAR, Decision, decide, distortion_floor

__all__ = [
    "FRF",
    "RationalModel",
    "NonlinearityResult",
    "frf_from_sweep",
    "frf_from_h1",
    "frf_from_stepped_sines",
    "excited_band",
    "fit_rational",
    "hilbert_transform",
    "nonlinearity_index",
    "hilbert_distortion",
    "estimate_frf",
    "analyse",
    "amplitude_sweep",
    "sweep_record",
    "LINEARITY_THRESHOLD",
]

#: The paper's criterion: eta >= 0.9 means "dominantly linear" (:data:`duffid.analysis.verdict.ETA_NONLINEAR`).
LINEARITY_THRESHOLD = ETA_NONLINEAR


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
    source : str
        Where the data came from.
    frf, transform, transform_uncorrected : optional
        Data for plots.
    decision : Decision, optional
        The verdict with its reasons (:func:`duffid.analysis.verdict.decide`).
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
    decision: Decision | None = None

    @property
    def verdict(self) -> str:
        """``"dominantly linear"``, ``"nonlinear"`` or ``"cannot tell"`` (see :attr:`decision`)."""
        return self.decision.verdict if self.decision is not None else "cannot tell"

    @property
    def reasons(self) -> list[str]:
        """What the verdict rests on, or why there is none, in words."""
        return list(self.decision.reasons) if self.decision is not None else []

    @property
    def estimator(self) -> str:
        """The FRF estimator: ``sweep``, ``h1``, ``stepped`` or ``given``."""
        return self.frf.estimator if self.frf is not None else ""

    @property
    def distortion_floor_db(self) -> float:
        """Noise floor of ``distortion_db`` (what the measurement noise alone gives) [dB]."""
        return distortion_floor(self.frf) if self.frf is not None else float("nan")

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary: ``eta``, ``band``, ``verdict``, ``reasons``, the estimator and the checks."""
        def clean(v: Any) -> Any:
            if isinstance(v, (float, np.floating)):
                return float(v) if np.isfinite(v) else None
            return v
        checks = {k: clean(v) for k, v in (self.frf.checks.items() if self.frf is not None else ())}
        return {
            "eta": clean(self.eta),
            "band": [float(self.band[0]), float(self.band[1])],
            "eta_uncorrected": clean(self.eta_uncorrected),
            "distortion_db": clean(self.distortion_db),
            "distortion_floor_db": clean(self.distortion_floor_db),
            "corrected": self.corrected,
            "amplitude": clean(self.amplitude),
            "peak_displacement": clean(self.frf.peak_displacement) if self.frf is not None else None,
            "estimator": self.estimator,
            "verdict": self.verdict,
            "reasons": self.reasons,
            "checks": checks,
            "source": self.source,
        }


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


def estimate_frf(record: Record, *, estimator: str = "auto", band: tuple[float, float] | None = None,
                 output: int = 0, segments: int = 8) -> FRF:
    """The FRF of a record by the estimator it supports.

    Parameters
    ----------
    record : Record
        The record.
    estimator : {"auto", "sweep", "h1"}
        ``sweep``: ratio of transforms (sweep or burst plus ring-down); ``h1``: averaged H1
        for a stationary random force; ``auto``: ``sweep`` when the record starts and ends
        at rest, else ``h1``.
    band, output
        See :func:`analyse`.
    segments : int
        ``h1``: see :func:`duffid.analysis.frf.frf_from_h1`.
    """
    record.require_displacement("the FRF of the nonlinearity index")
    if estimator not in ESTIMATORS:
        raise OptionError(f"estimator must be one of {', '.join(ESTIMATORS)}, got {estimator!r}")
    if estimator == "auto":
        estimator = choose_estimator(record, output=output)
    if estimator == "sweep":
        return frf_from_sweep(record, band=band, output=output)
    return frf_from_h1(record, band=band, output=output, segments=segments, n_modes=record.n_dof)


def analyse(data: Record | FRF, *, band: tuple[float, float] | None = None, corrected: bool = True,
            n_modes: int | None = None, output: int = 0, estimator: str = "auto",
            segments: int = 8) -> NonlinearityResult:
    """Nonlinearity figures and verdict of a record (or an FRF).

    Parameters
    ----------
    data : Record or FRF
        A record (sweep with ring-down, random force, ...) or an FRF (e.g. from stepped sines).
    band : (f1, f2), optional
        Band [Hz]; default from the input's energy.
    corrected : bool
        ``eta`` with the band-edge correction (default) or uncorrected.
    n_modes : int, optional
        Modes of the linear extension; default: the record's number of DOFs (1 for an FRF).
    output : int
        Displacement column of a record (0-based).
    estimator : {"auto", "sweep", "h1"}
        FRF estimator for a record (see :func:`estimate_frf`).
    segments : int
        ``h1``: Welch segments.

    Returns
    -------
    NonlinearityResult
        ``eta`` exactly as the paper defines it (eqs. 8-9), ``D``, and the verdict with its reasons.
    """
    if isinstance(data, Record):
        frf = estimate_frf(data, estimator=estimator, band=band, output=output, segments=segments)
        modes = n_modes or data.n_dof
    else:
        frf = data if band is None else FRF(data.frequency, data.response, band, data.amplitude, data.source,
                                            data.measured, data.estimator, data.variance, data.coherence,
                                            data.problems, data.checks, data.peak_displacement)
        modes = n_modes or 1
    inside = frf.in_band
    with_correction = hilbert_transform(frf, corrected=True, n_modes=modes)
    without = hilbert_transform(frf, corrected=False)
    F = frf.response[inside]
    main = with_correction if corrected else without
    eta = nonlinearity_index(F, main[inside])
    distortion = hilbert_distortion(F, main[inside])
    # the decision always rests on the corrected transform: uncorrected, a linear plant reads distorted
    decision = decide(nonlinearity_index(F, with_correction[inside]),
                      hilbert_distortion(F, with_correction[inside]), frf)
    return NonlinearityResult(
        eta=eta,
        eta_uncorrected=nonlinearity_index(F, without[inside]),
        distortion_db=distortion,
        band=frf.band, amplitude=frf.amplitude, corrected=corrected, source=frf.source,
        frf=frf, transform=with_correction, transform_uncorrected=without, decision=decision,
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
        (verdict "cannot tell") with the reason in ``source``.
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
                                              float(amplitude), source=f"escaped: {exc}",
                                              decision=Decision("cannot tell", [f"no record: {exc}"])))
            continue
        result = analyse(record, band=band, n_modes=n_modes)
        band = band or result.band
        results.append(result)
    return results
