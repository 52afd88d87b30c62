"""Identification from a measured velocity or acceleration (offline).

A vibration rig measures the force with a load cell and the motion with an accelerometer
(or a laser vibrometer: a velocity); the algebraic estimator needs the displacement, and a
cubic spring needs it absolutely, not up to a drift. Integrating the measured signal does not
give it: the sensor's noise and bias integrate into a slow drift that no check on the
record can tell from motion. Measured on a hardening plant of 10 Hz under random force
(1-30 Hz), acceleration at 5 kHz with a bias of 1 % of its RMS and 50 dB noise, 4 s: the
displacement integrated twice (bias and trend removed, high-pass at 0.25-1 Hz) misses the
true one by 1.5-2 % RMS, and the algebraic estimate from it is 2-9 % off *with small stated
uncertainties*; the checked ``identify`` published such values. So here the integration only
gives a starting point, never a published value:

1. the measured signal is integrated once (velocity) or twice (acceleration), its mean and
   a polynomial trend removed, and high-passed without phase (:func:`integrated_displacement`);
2. the algebraic estimator runs on that displacement (a constant force among its unknowns):
   its final solution is the start, or, when that is not physical (the integrated
   displacement's drift can spoil it: a swept sine, two DOFs), the chain's linear matrices
   fitted to the frequency response (a user's equation has no such start: it is refused
   with that reason);
3. the output-error fit of :func:`duffid.identification.refine.refine` then simulates the
   model under the measured force and matches the simulated velocity or acceleration to the
   measured one (no integration of the measurement enters the criterion, so its noise adds
   no drift), with a constant sensor bias per DOF and each stretch of
   :data:`SEGMENT_PERIODS` natural periods started from its own fitted state (multiple
   shooting: a lightly damped nonlinear plant does not follow a long record from one state);
4. a value is published only when the fit explains the measured signal down to its white
   noise (:func:`~duffid.identification.sampling.noise_level`; within :data:`FIT_TOLERANCE`;
   and only where that figure is white noise, not signal:
   :func:`~duffid.identification.sampling.noise_is_white`)
   and its stated relative standard error (inflated for the residual's autocorrelation) is
   at most ``max_uncertainty``.

On the record above the fit converges in 5-7 simulations from starts 20 % off and gives
every parameter within 0.03 % (its stated errors 0.005-0.011 %), the bias within 0.4 %.
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..data.channels import FAMILY_WORDS
from ..data.record import Record
from ..data.units import si_unit
from ..errors import InputError, RecordError
from ..models.chain import Chain
from ..models.equation_model import EquationModel
from ..models.registry import model_from_name
from .assessment import Assessment
from .dispatch import final_estimates
from .engine import STATUSES, Identification
from .offsets import with_force_offsets
from .options import default_options
from .refine import OUTPUTS, EscapingStart, Refinement, canonical_from_public, refine
from .sampling import natural_frequency, noise_is_white, noise_level

__all__ = ["displacement_columns", "measured_motion", "band_limited_motion", "MOTIONS", "SEGMENT_PERIODS", "FIT_TOLERANCE", "FIT_PARTS", "PART_SAMPLES", "MAX_UNCERTAINTY", "START_POWER", "START_NONLINEAR", "START_BINS", "TERM_SIGMAS", "TERM_MOVE_SIGMAS", "TERM_START", "probe_terms",
           "integrated_displacement", "identify_motion"]

#: Largest relative standard error of a published value, by default (the robust method's).
MAX_UNCERTAINTY = default_options("robust")["max_uncertainty"]
#: The measured motions this module identifies from (a displacement goes to ``identify``).
MOTIONS = {"v": "velocity", "a": "acceleration"}
#: Length of the output-error fit's stretches, in natural periods of the starting estimate
#: (measured: 2-4 periods converge from starts 20 % off; 10 periods did not from 30 %).
SEGMENT_PERIODS = 3.0
#: The fit explains the measured signal when its RMS error is at most this multiple of the
#: signal's white noise, over the whole record and over each of its :data:`FIT_PARTS`
#: (a plant that changed within the record is followed worse in one part: measured, a
#: stiffness 2 % higher in the second half of 2 s at 40 dB left the whole fit within 1.16
#: times the noise, the worst eighth at 1.32; 1 % higher: 1.04 and 1.09, not seen; on
#: constant plants every eighth was within 0.98-1.03 at 30-50 dB).
FIT_TOLERANCE = 1.2
#: ... in this many consecutive parts of equal length (fewer for a short record: each part
#: has at least :data:`PART_SAMPLES` samples, so that its noise's RMS is known to about 4 %).
FIT_PARTS = 8
PART_SAMPLES = 400
#: The integration's high-pass sits at half the frequency below which this share of the
#: force's power lies (the force's lowest content), never below two cycles per record.
START_POWER = 0.01

#: The fallback start (when the algebraic one is not physical): each nonlinear stiffness term
#: this share of its DOF's linear one at the displacement's RMS (hardening).
START_NONLINEAR = 0.05
#: ... fitted over the frequency bins with at least this share of the force's largest power.
START_BINS = 1e-3

#: A term the model lacks whose effect on the measured signal stays below its noise still moves
#: the fitted values (a weak ``x^5`` spring at 40 dB left the fit at the noise and kp 2-3 % off,
#: 30-40 of its stated errors; a Coulomb friction of 1 % of the force's RMS, b 4-5 % off). So the
#: fit of a chain is repeated with each of its next terms added (:func:`probe_terms`: the next
#: odd stiffness power, ``x^2`` unless the model has it, a Coulomb friction unless it has one),
#: from the fit's values: a term this many of its standard errors from zero is one the record
#: shows. Measured (see the notes): on the right model (48 records of 16 set-ups, and 73 runs of
#: a probing helper's, hammer blows apart) every probed term was within 2.35 standard errors of
#: zero; an ``x^5`` spring of 0.5-2 % of the restoring force at 40 dB was 4.3-34 from it, a
#: friction of 0.5-2 % of the force's RMS 9.7-36.
TERM_SIGMAS = 4.0
#: ... and then a value that moved with the term by more than this many of its own stated
#: errors is not published: its stated uncertainty does not hold what the model lacks (a
#: value that moved less is published).
TERM_MOVE_SIGMAS = 3.0
#: The probed term starts at this share of its DOF's linear restoring force at the
#: displacement's RMS (a start of 0 would also be its scale).
TERM_START = 0.01

_SUPPORTED = tuple(o for o in OUTPUTS if o != "x")
assert set(MOTIONS) == set(_SUPPORTED), "every measured motion but the displacement has a fit output"


def _lowest_force_frequency(f: np.ndarray, dt: float) -> float:
    """Frequency [Hz] below which :data:`START_POWER` of the force's power lies (its mean removed)."""
    f = np.asarray(f, dtype=float).reshape(len(f), -1)
    power = np.sum(np.abs(np.fft.rfft(f - f.mean(axis=0), axis=0)) ** 2, axis=1)
    freqs = np.fft.rfftfreq(len(f), dt)
    total = power[1:].sum()
    if not total > 0:
        return math.nan
    cumulative = np.cumsum(power[1:]) / total
    return float(freqs[1:][np.searchsorted(cumulative, START_POWER)])


def integrated_displacement(y: np.ndarray, dt: float, order: int, cutoff: float) -> np.ndarray:
    """The displacement from a velocity (``order`` 1) or acceleration (2), band-limited.

    Each column: mean removed, integrated ``order`` times (trapezoid), a polynomial of degree
    ``order`` removed (the unknown initial state and the integrated bias), then high-passed at
    ``cutoff`` Hz without phase (an eighth-order Butterworth magnitude applied to the
    spectrum of the record mirrored at its end). Only a starting point: the noise's drift
    within the pass band remains (see the module documentation).
    """
    from scipy.integrate import cumulative_trapezoid

    y = np.asarray(y, dtype=float).reshape(len(y), -1)
    t = np.arange(len(y)) * dt
    out = y - y.mean(axis=0)
    for _ in range(order):
        out = cumulative_trapezoid(out, dx=dt, axis=0, initial=0.0)
    trend = np.polynomial.polynomial.polyfit(t, out, order)
    out = out - np.polynomial.polynomial.polyval(t, trend).T
    mirrored = np.concatenate([out, out[::-1]])
    freqs = np.fft.rfftfreq(len(mirrored), dt)
    gain = np.zeros_like(freqs)
    gain[1:] = 1.0 / np.sqrt(1.0 + (cutoff / freqs[1:]) ** 8)
    return np.fft.irfft(np.fft.rfft(mirrored, axis=0) * gain[:, None], len(mirrored), axis=0)[:len(y)]


def band_limited_motion(record: Record, motion: str, cutoff: float | None = None
                        ) -> tuple[float, tuple[np.ndarray, np.ndarray]]:
    """The displacement and velocity integrated from a velocity or acceleration record,
    band-limited (:func:`integrated_displacement`; the fit's starting states), and the
    high-pass used [Hz] (default: half the force's lowest content, :data:`START_POWER`, never
    below two cycles per record).

    Raises
    ------
    RecordError
        When the force has no content to set the high-pass from (and no ``cutoff``).
    """
    lowest = _lowest_force_frequency(record.f, record.dt)
    floor = 2.0 / (record.n_samples * record.dt)
    cutoff = max(0.5 * lowest, floor) if cutoff is None else float(cutoff)
    if not (math.isfinite(cutoff) and cutoff > 0):
        raise RecordError(f"{record.source}: the force has no content to set the integration's high-pass from; "
                          "give cutoff= (Hz)")
    x = integrated_displacement(record.x, record.dt, 1 if motion == "v" else 2, cutoff)
    v = record.x - record.x.mean(axis=0) if motion == "v" else integrated_displacement(record.x, record.dt, 1, cutoff)
    return cutoff, (x, v)


def _start(record: Record, model: Chain, motion: str, cutoff: float | None, algebraic: bool = True
           ) -> tuple[dict[str, float], float, tuple[np.ndarray, np.ndarray]]:
    """The algebraic estimate on the band-limited displacement (the fit's start; NaN without
    ``algebraic``), the cutoff and the band-limited displacement and velocity (the
    stretches' starting states)."""
    cutoff, (x, v) = band_limited_motion(record, motion, cutoff)
    if not algebraic:
        return {k: math.nan for k in model.parameters}, cutoff, (x, v)
    displacement = Record(record.t, record.f, x, source=f"{record.source} (integrated {MOTIONS[motion]})",
                          sampling_rtol=record.sampling_rtol)
    # the estimator's final solution (a constant force among its unknowns), never published
    values = final_estimates(displacement, with_force_offsets(model))
    start = {k: float(values.get(k, math.nan)) for k in model.parameters}
    if not _physical(model, start) and isinstance(model, Chain):  # a chain's linear matrices give another
        start = _linear_start(record, model, x)
    return start, cutoff, (x, v)


def _physical(model: Chain, values: dict[str, float]) -> bool:
    """Every value finite and physical (a mass > 0, a damping >= 0, ...)."""
    if not all(map(math.isfinite, values.values())):
        return False
    try:
        canonical = canonical_from_public(model, values)
    except InputError:  # a value the model refuses (a negative mass)
        return False
    return all(model.is_physical(k, v) for k, v in canonical.items())


def _linear_start(record: Record, model: Chain, x: np.ndarray) -> dict[str, float]:
    """A start from the frequency response: the masses, dampings and linear stiffnesses fitted
    to ``(K - w^2 M + i w B) X = F`` (:meth:`~duffid.models.chain.Chain.linear_matrices`, linear
    in them) over the bins that carry the force's power, with the band-limited displacements
    ``x``; every nonlinear stiffness term at :data:`START_NONLINEAR` of its DOF's linear one at
    the displacement's RMS (hardening), other terms (friction, offsets) 0."""
    n = model.n_dof
    spectrum_f = np.fft.rfft(record.f - record.f.mean(axis=0), axis=0)
    spectrum_x = np.fft.rfft(x, axis=0)
    w = 2 * np.pi * np.fft.rfftfreq(len(x), record.dt)
    power = np.sum(np.abs(spectrum_f) ** 2, axis=1)
    used = (power >= START_BINS * power[1:].max()) & (w > 0)
    names = [k for k in model.canonical_parameters() if k[0] in "mb" or (k[0] == "k" and k.endswith("_1"))]
    columns = []
    for name in names:  # each linear parameter's share of (K - w^2 M + i w B) X, every bin and DOF
        unit = {**{f"m{i + 1}": 0.0 for i in range(n)}, name: 1.0}  # every mass is needed, 0 but this one
        M, B, K = model.linear_matrices(unit)
        term = (np.einsum("ij,wj->wi", K, spectrum_x[used]) - w[used, None] ** 2 * np.einsum(
            "ij,wj->wi", M, spectrum_x[used]) + 1j * w[used, None] * np.einsum("ij,wj->wi", B, spectrum_x[used]))
        columns.append(term.ravel())
    forces = np.zeros((used.sum(), n), dtype=complex)
    forces[:, :record.n_forces] = spectrum_f[used]
    design = np.array(columns).T
    solution = np.linalg.lstsq(np.vstack([design.real, design.imag]),
                               np.concatenate([forces.ravel().real, forces.ravel().imag]), rcond=None)[0]
    canonical = dict(zip(names, solution))
    spread = np.std(x, axis=0)
    for name in model.canonical_parameters():
        if name in canonical:
            continue
        dof, _, order = name[1:].partition("_")
        if name[0] == "k" and order.isdigit() and dof.isdigit():
            i = int(dof) - 1
            canonical[name] = START_NONLINEAR * canonical[f"k{i + 1}_1"] / spread[i] ** (int(order) - 1)
        else:
            canonical[name] = 0.0
    return model.from_canonical(canonical)

def _probes(model: Chain, fit: Refinement, spread: np.ndarray) -> list[tuple[str, Chain, dict[str, float], str]]:
    """The terms :func:`probe_terms` adds to a chain, one at a time: for each, its words, the
    extended chain, the added parameters' starts (:data:`TERM_START`) and how to identify a
    model that has it."""
    restoring = [sum(abs(fit.canonical[f"k{i + 1}_{o}"]) * spread[i] ** o for o in model.orders)
                 for i in range(model.n_dof)]
    flags = ["--model chain"] + ([f"--n-dof {model.n_dof}"] if model.n_dof > 1 else [])
    friction = model.coulomb is not None
    odd = max(model.orders) + 1 + max(model.orders) % 2
    out = []
    for order in [odd] + ([2] if 2 not in model.orders else []):
        orders = tuple(sorted({*model.orders, order}))
        extended = model_from_name("chain", model.n_dof, orders=orders, coulomb=friction, forced=model.forced,
                                   offset=model.offset)
        starts = {f"k{i + 1}_{order}": TERM_START * restoring[i] / spread[i] ** order for i in range(model.n_dof)}
        out.append((f"an x^{order} stiffness term", extended, starts,
                    " ".join(flags + ["--orders " + ",".join(map(str, orders))] + (["--coulomb"] if friction else []))))
    if not friction:
        extended = model_from_name("chain", model.n_dof, orders=model.orders, coulomb=True, forced=model.forced,
                                   offset=model.offset)
        starts = {f"fc{i + 1}": TERM_START * restoring[i] for i in range(model.n_dof)}
        orders = "" if tuple(model.orders) == (1, 3) else " --orders " + ",".join(map(str, model.orders))
        out.append(("a Coulomb friction (or another nonlinear damping)", extended, starts,
                    " ".join(flags) + orders + " --coulomb for a Coulomb friction, --equation for another damping"))
    return out


@dataclass(frozen=True)
class LackingTerm:
    """A term the record shows and the model lacks (:func:`probe_terms`).

    Attributes
    ----------
    term : str
        In words (``"an x^5 stiffness term"``, ``"a Coulomb friction (or another nonlinear
        damping)"``).
    sigmas : float
        How many of its standard errors the largest of its coefficients is from zero.
    moved : dict
        The model's parameters (public names) that moved with it by more than
        :data:`TERM_MOVE_SIGMAS` of their stated errors, and by how many.
    remedy : str
        How to identify a model that has it (CLI flags).
    """

    term: str
    sigmas: float
    moved: dict[str, float]
    remedy: str

    def describe(self) -> str:
        """In words, for the assessment's notes."""
        head = (f"the record shows {self.term} the model lacks ({self.sigmas:.3g} standard errors from zero when "
                "it is added)")
        if not self.moved:
            return head + "; no value moves beyond its stated errors with it"
        names = list(self.moved)
        moves = [f"{v:.2g}" for v in self.moved.values()]
        said = (f"{names[0]} moves by {moves[0]} of its stated errors" if len(names) == 1 else
                ", ".join(names[:-1]) + f" and {names[-1]} move by " + ", ".join(moves[:-1]) + f" and {moves[-1]} "
                "of their stated errors")
        return f"{head}; with it, {said}: not published; identify with {self.remedy}"


def probe_terms(record: Record, model: Chain, fit: Refinement, motion: str, spread: np.ndarray, *,
                segment: int | None, states: tuple[np.ndarray, np.ndarray] | None) -> list[LackingTerm]:
    """The terms next to a chain's that the record shows (see :data:`TERM_SIGMAS`): the next
    odd stiffness power, ``x^2`` unless the chain has it, and a Coulomb friction unless it has one.

    Parameters
    ----------
    record, motion
        The measured record and what its motion columns measure.
    model : Chain
        The fitted model (an :class:`~duffid.models.equation_model.EquationModel` is not probed:
        it has no next term).
    fit : Refinement
        Its output-error fit (values and stated errors).
    spread : ndarray
        Each DOF's displacement RMS (the probed term's starting scale, :data:`TERM_START`).
    segment, states
        The fit's stretches and their starting states.

    Returns
    -------
    list of LackingTerm
        The probed terms more than :data:`TERM_SIGMAS` standard errors from zero (a probe
        whose fit fails, or fits worse than the model's, finds nothing).
    """
    if not isinstance(model, Chain):
        return []
    found = []
    for term, extended, starts, remedy in _probes(model, fit, spread):
        try:
            probe = refine(record, extended, {**fit.canonical, **starts}, output=motion, segment=segment,
                           progress=False, state_guess=states)
        except (InputError, RecordError, EscapingStart):
            continue
        # a probe that ran out of simulations still counts once it fits better than the model
        # (a Coulomb friction of 1 % at 40 dB: 50 simulations, RMS 3 % lower, the friction 20
        # standard errors from zero, b moved by 26 of its own)
        if not (probe.rms <= fit.rms and all(map(math.isfinite, probe.canonical.values()))):
            continue
        sigmas = max(1.0 / probe.relative_std[name] if probe.relative_std[name] > 0 else math.inf for name in starts)
        if not sigmas > TERM_SIGMAS:
            continue
        moved = {}
        for name in model.parameters:
            key = model.canonical_name(name)
            error = fit.relative_std[key] * abs(fit.canonical[key])
            shift = abs(probe.canonical[key] - fit.canonical[key])
            if not shift <= TERM_MOVE_SIGMAS * error:
                moved[name] = float(shift / error) if error > 0 else math.inf
        found.append(LackingTerm(term, float(sigmas), moved, remedy))
    return found


def displacement_columns(record: Record | Sequence[str]) -> list[str]:
    """The columns an equation for a velocity or acceleration record is written in: the
    record's (or these column names), with its motion columns named as the displacements they
    measure (``t, f, x`` for ``t, f, a``)."""
    names = record.column_names if isinstance(record, Record) else list(record)
    return [("x" + c[1:]) if c[:1] in MOTIONS else c for c in names]


def measured_motion(columns: Sequence[str]) -> str:
    """What the motion columns among ``columns`` measure: ``"x"`` (displacements, also when
    there are none), ``"v"`` or ``"a"`` (:data:`MOTIONS`).

    Raises
    ------
    InputError
        When they mix kinds (a record measures one kind of motion).
    """
    kinds = sorted({c[:1] for c in columns if c[:1] in ("x", *MOTIONS)})
    if len(kinds) > 1:
        raise InputError(f"columns {','.join(columns)} mix {' and '.join(kinds)}: a record measures one kind of "
                         "motion (displacements x, velocities v or accelerations a)")
    return kinds[0] if kinds else "x"


def identify_motion(record: Record, model: Chain | EquationModel, motion: str | None = None, *,
                    max_uncertainty: float = MAX_UNCERTAINTY,
                    cutoff: float | None = None, segment: int | None = None,
                    start: Mapping[str, float] | None = None, check_terms: bool = True,
                    progress: bool | None = None) -> Identification:
    """Identify ``model`` from the force and a measured velocity or acceleration (offline).

    Parameters
    ----------
    record : Record
        Forces, and in the motion columns (``record.x``) the measured ``motion`` of each DOF
        in the model's displacement unit per second (velocity) or per second squared
        (acceleration).
    model : Chain or EquationModel
        Model structure (its values are not used); an equation is written in the
        displacements (``x`` or ``x1 ..``, columns :func:`displacement_columns`), whose
        velocity or acceleration the record measures.
    motion : {"v", "a"}, optional
        What the motion columns measure (:data:`MOTIONS`; default: the record's
        :attr:`~duffid.data.record.Record.motion`, which must agree when given).
    max_uncertainty : float
        Largest relative standard error of a published value.
    cutoff : float, optional
        High-pass of the integration that gives the start [Hz] (default: half the force's
        lowest content, :data:`START_POWER`).
    segment : int, optional
        Samples per stretch of the output-error fit (default: :data:`SEGMENT_PERIODS`
        natural periods of the start).
    start : mapping, optional
        The fit's start by public name (e.g. a previous fit's values, as the online
        identifier gives them); default: the algebraic estimate on the integrated
        displacement. Never published as such: only the fit's values are.
    check_terms : bool
        Probe a chain's next terms (:func:`probe_terms`: a stiffness power, a Coulomb
        friction) when the fit publishes values: a value that moves beyond its stated errors
        with a term the record shows is not published.
    progress : bool, optional
        The fit's progress bar (None: on a terminal).

    Returns
    -------
    Identification
        ``parameters``: the published values (NaN otherwise); ``estimates``: the fitted
        values; ``assessment``: per parameter status and relative standard error, ``fit``
        (``signal``, ``simulation_nrmse`` and ``noise_nrmse`` of the measured motion, the
        worst of its parts (:data:`FIT_PARTS`) ``worst_part_nrmse``, ``explained``, ``bias`` and
        ``bias_std`` per DOF (in ``bias_unit``, SI), ``start`` and ``cutoff_hz``), and notes in words.
    """
    motion = record.motion if motion is None else motion
    if motion not in MOTIONS:
        raise InputError(f"motion must be one of {', '.join(MOTIONS)} (velocity, acceleration), got {motion!r}; "
                         "a displacement is identified by identify()")
    if record.motion not in ("x", motion):
        raise RecordError(f"{record.source}: the record measures {record.motion}, not {motion}")
    record = record if record.motion == motion else Record(record.t, record.f, record.x, source=record.source,
                                                           sampling_rtol=record.sampling_rtol, motion=motion)
    if not (math.isfinite(max_uncertainty) and max_uncertainty > 0):
        raise InputError(f"max_uncertainty must be a positive number, got {max_uncertainty!r}")
    for count, needed, what in ((record.n_dof, model.n_dof, FAMILY_WORDS[motion]), (record.n_forces, model.n_forces,
                                                                                      "forces")):
        if count != needed:
            raise RecordError(f"{record.source}: model {model.name} needs {needed} {what} (columns), the record has "
                              f"{count}")
    word = MOTIONS[motion]
    given = start
    start, cutoff, states = _start(record, model, motion, cutoff, algebraic=given is None)
    if given is not None:
        unknown = sorted(set(given) - set(model.parameters))
        if unknown:
            raise InputError(f"start: {', '.join(unknown)} not parameter(s) of {model.name} "
                             f"({', '.join(model.parameters)})")
        start = {k: float(given.get(k, math.nan)) for k in model.parameters}
    notes: list[str] = []
    if not _physical(model, start):
        shown = ", ".join(f"{k} = {v:.4g}" for k, v in start.items())
        if given is not None:
            raise InputError(f"start: not a physical start for {model.name} ({shown})")
        return _refused(record, model, motion, start, cutoff,
                        f"the displacement integrated from the {word} gave no physical start for the fit ({shown}); "
                        "a longer record, a force with more low-frequency content or cutoff= may help")
    if segment is None:
        hz = natural_frequency(model, canonical_from_public(model, start), lowest=True)
        segment = max(8, int(round(SEGMENT_PERIODS / hz / record.dt))) if math.isfinite(hz) and hz > 0 else None
    try:
        try:
            fit = refine(record, model, start, output=motion, segment=segment, progress=progress, state_guess=states)
        except EscapingStart:
            if given is not None or not isinstance(model, Chain):
                raise
            # the algebraic start (e.g. a softening kp on a hardening plant, from the integration's drift) does
            # not simulate: the chain's linear matrices from the frequency response give another
            start = _linear_start(record, model, states[0])
            notes.append("the algebraic start did not simulate (it escapes); the fit started from the frequency "
                         "response's linear matrices")
            fit = refine(record, model, start, output=motion, segment=segment, progress=progress, state_guess=states)
    except (InputError, RecordError) as exc:
        return _refused(record, model, motion, start, cutoff, f"the output-error fit of the {word} failed: {exc}")
    noise = float(np.max(noise_level(record.x)))
    white, sigma4, sigma6 = noise_is_white(record.x)
    spread = float(np.max(np.std(record.x, axis=0)))
    parts = max(1, min(FIT_PARTS, len(fit.residuals) // PART_SAMPLES))
    worst_part = max(float(np.sqrt(np.mean(part**2))) for part in np.array_split(fit.residuals, parts))
    explained = bool(fit.success and white and max(fit.rms, worst_part) <= FIT_TOLERANCE * noise)
    status, uncertainty = {}, {}
    for name in fit.parameters:
        canonical = model.canonical_name(name)
        relative = fit.relative_std.get(canonical, math.nan)
        uncertainty[name] = relative
        ok = explained and model.is_physical(canonical, fit.canonical[canonical]) and relative <= max_uncertainty
        status[name] = STATUSES[1] if ok else STATUSES[0]
    if not white:
        notes.append(f"the measured {word}'s noise cannot be told from its signal: its 4th and 6th differences give "
                     f"noise levels {sigma4:.3g} and {sigma6:.3g}, which white noise would make equal (the signal "
                     "reaches the upper part of the sampled band, e.g. a broadband force), so the fit cannot be "
                     "checked against the noise: nothing is published; a force band-limited well below the Nyquist "
                     "frequency, or a higher sampling rate, lets it be checked")
    elif explained:
        notes.append(f"the model simulated under the measured force follows the measured {word} to its noise "
                     f"({fit.rms:.3g} RMS against noise {noise:.3g})")
    elif fit.success and fit.rms <= FIT_TOLERANCE * noise:
        notes.append(f"the model simulated under the measured force follows the measured {word} to its noise "
                     f"overall, but misses it by {100 * worst_part / spread:.3g} % RMS in one of {parts} parts "
                     f"of the record where its noise explains {100 * noise / spread:.2g} %: nothing is published; "
                     "the plant may have changed within the record (identify its stretches apart)")
    else:
        notes.append(f"the model simulated under the measured force misses the measured {word} by "
                     f"{100 * fit.rms / spread:.3g} % RMS where its noise explains {100 * noise / spread:.2g} %"
                     + ("" if fit.success else f" (the fit did not converge: {fit.message})")
                     + ": nothing is published; check the columns, units and that the model fits the plant")
    lacking: list[LackingTerm] = []
    probed = bool(check_terms and isinstance(model, Chain) and STATUSES[1] in status.values())
    if probed:
        lacking = probe_terms(record, model, fit, motion, np.std(states[0], axis=0), segment=segment, states=states)
    for term in lacking:
        notes.append(term.describe())
        for name in term.moved:
            status[name] = STATUSES[0]
    for name, s in status.items():
        if s != STATUSES[1] and explained and not any(name in term.moved for term in lacking):
            notes.append(f"{name}: relative standard error {100 * uncertainty[name]:.2g} % exceeds "
                         f"max_uncertainty {100 * max_uncertainty:.2g} % (not published)")
    published = {k: (v if status[k] == STATUSES[1] else math.nan) for k, v in fit.parameters.items()}
    assessment = Assessment(
        status=status, uncertainty=uncertainty, share={k: math.nan for k in status},
        fit={"signal": word, "simulation_nrmse": fit.rms / spread, "noise_nrmse": noise / spread,
             "worst_part_nrmse": worst_part / spread,
             "explained": explained, "bias": list(fit.bias), "bias_std": list(fit.bias_std),
             "bias_unit": si_unit(word), "start": dict(start), "cutoff_hz": cutoff, "stretches": fit.options["stretches"],
             "evaluations": fit.nfev,
             "terms_probed": probed,
             "lacking_terms": [{"term": t.term, "sigmas": t.sigmas, "moved": dict(t.moved), "remedy": t.remedy,
                                "note": t.describe()} for t in lacking]},
        notes=notes, values=dict(fit.parameters))
    return _result(record, model, motion, published, dict(fit.parameters), assessment)


def _refused(record: Record, model: Chain, motion: str, start: dict[str, float], cutoff: float,
             note: str) -> Identification:
    assessment = Assessment(status={k: STATUSES[0] for k in start}, uncertainty={k: math.nan for k in start},
                            share={k: math.nan for k in start},
                            fit={"signal": MOTIONS[motion], "explained": False, "start": dict(start),
                                 "cutoff_hz": cutoff},
                            notes=[note], values={k: math.nan for k in start})
    return _result(record, model, motion, {k: math.nan for k in start}, {k: math.nan for k in start}, assessment)


def _result(record: Record, model: Chain, motion: str, published: dict[str, float], values: dict[str, float],
            assessment: Assessment) -> Identification:
    done = all(s == STATUSES[1] for s in assessment.status.values())
    end = float(record.t[-1])
    return Identification(
        model=model.name, method=f"output-error ({MOTIONS[motion]})", parameters=published,
        t=np.array([end]), history={k: np.array([v]) for k, v in published.items()},
        condition=np.array([math.nan]), identified=np.array([done]), t_identified=end if done else None,
        window=end - float(record.t[0]), options={"motion": motion}, source=record.source,
        estimates=values, assessment=assessment, samples=len(record.t))
