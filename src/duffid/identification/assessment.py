"""The assessment of an identification (:func:`assess`): which values the record supports
(bootstrap uncertainty, simulation fit, consistency, term shares, refinement), and in words why
the others are not published."""
from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from ..data.record import Record
from ..errors import BuildError, RecordError
from ..models.chain import Chain
from .dispatch import Pool
from .engine import MIN_SHARE
from .offsets import DISPLACEMENT_OFFSET, canonical_of, inseparable_note, offset_check, offset_scales
from .options import default_options
from .refine import OdeSimulator, SegmentSimulator, fit_initial_state, refine, stretches
from .sampling import (
    MIN_SAMPLES_PER_PERIOD,
    SAMPLES_PER_PERIOD,
    content_frequency,
    every_second,
    force_varies,
    natural_frequency,
    near_force_jumps,
    noise_is_white,
    noise_level,
    samples_per_period,
)

__all__ = [
    "SIMULATION_TOLERANCE",
    "CONSISTENCY_EXCESS",
    "SENSOR_OFFSET_SIGMAS",
    "TRADE_OFF_CORRELATION",
    "measured_force_noise",
    "REPLICATES",
    "BOOTSTRAP_ROWS_PER_WINDOW",
    "PROGRESS_SAMPLES",
    "UNCERTAINTY_FLOOR",
    "BALANCE_FLOOR",
    "QUADRATURE_BIAS",
    "Assessment",
    "json_ready",
    "term_shares",
    "SEGMENT_PERIODS",
    "MAX_ESCAPED",
    "ASSESSMENT_UNCERTAINTY",
    "assess",
    "REFINE_SAMPLES_PER_PERIOD",
    "REFINE_STEP",
]


#: Largest normalised RMS simulation error beyond the noise for a model that explains the record.
SIMULATION_TOLERANCE = 0.05

#: A simulation of the identified model that misses the record by more than this beyond the
#: noise (normalised RMS; and by more than a quarter of the noise level) has its published
#: values cross-checked by the output-error estimate, and a value the two estimates disagree on
#: beyond their stated errors gets their difference as its stated error. Measured on
#: noise-free records: a record the model describes is missed by less than 3e-4 (robust
#: method); the buffered methods' truncation bias of 0.2-3 % in the values shows as 3e-3 to 2.4e-2.
CONSISTENCY_EXCESS = 1e-3

#: The output-error cross-check and refinement fit a constant offset of the displacement
#: sensor (a model without a force bias); one beyond this many standard errors from zero is
#: named in the notes when the values disagree. Measured: a 0.5-3 % offset (of the RMS) on a
#: hardening plant moved m and k by 0.6-1 % at 24-53 stated errors and kp by 1.2-1.7 %, while
#: the simulation missed the record by 2-8 times the noise, inside SIMULATION_TOLERANCE.
SENSOR_OFFSET_SIGMAS = 4.0

#: A value whose noisy replicates move with those of an excited value the record leaves
#: undetermined at least this correlated is not published either: its stated error counts the
#: noise's share of the trade-off, not a bias of the undetermined one, which the record cannot
#: bound. Measured: a linear plant in steady state under one sine left m 17 % uncertain at 0.073
#: (truth 1) and published k at 670.6 +- 0.67 % (truth 1000), their correlation 0.999999.
TRADE_OFF_CORRELATION = 0.999

#: Noisy replicates of the record behind each standard error.
REPLICATES = 8

#: The noisy replicates' runs on the C core take the rows of at least this many windows per
#: window length (every ``window // BOOTSTRAP_ROWS_PER_WINDOW``-th sample's, not every
#: sample's): their spread is that of the full estimator (measured on every record of
#: ``benchmarks/trust.py`` with 32 common noise draws: each standard error within 0.99-1.005
#: of the full rows' at 128, 0.95-1.07 at 64, 0.91-1.49 at 32, the damping's growing first),
#: at a third to a half of the cost for windows of 400-700 samples.
BOOTSTRAP_ROWS_PER_WINDOW = 128

#: Records of at least this many samples show a progress bar while they are identified and
#: checked (about a seventh of a second at the checked identification's 140,000 to 170,000
#: samples/s on one core, 1-DOF, docs/guide/identify.md; slower models take longer).
PROGRESS_SAMPLES = 20_000

#: The relative standard error is never stated below this (rounding).
UNCERTAINTY_FLOOR = 1e-5

#: Quadrature and interpolation errors of the integrated force balance, as a fraction of it:
#: ``BALANCE_FLOOR + QUADRATURE_BIAS / spp**4`` (spp: samples per period of the highest
#: frequency). A parameter's stated error is at least that divided by its term's share
#: (measured on noise-free records: 3e-6 of the balance at 80 samples per period, 1.3e-5 at
#: 40, 2e-4 at 20).
BALANCE_FLOOR = 1e-5

QUADRATURE_BIAS = 50.0

def json_ready(value: Any) -> Any:
    """``value`` (numbers, arrays, lists, mappings) as plain JSON types, non-finite numbers as None."""
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if np.isfinite(value) else None
    if isinstance(value, (list, tuple, np.ndarray)):
        return [json_ready(u) for u in value]
    if isinstance(value, Mapping):
        return {k: json_ready(u) for k, u in value.items()}
    return value


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
        clean = json_ready
        return {
            "status": dict(self.status),
            "uncertainty": {k: clean(v) for k, v in self.uncertainty.items()},
            "share": {k: clean(v) for k, v in self.share.items()},
            "fit": {k: clean(v) for k, v in self.fit.items()},
            "notes": list(self.notes),
        }

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
                    noise: np.ndarray, spp: float = 0.0) -> tuple[dict[str, Any], np.ndarray | None, str | None]:
    """Simulate the identified model under the measured force, in segments of
    :data:`SEGMENT_PERIODS` natural periods each started from a state fitted to its first
    half period; the NRMSE of the simulated displacement against the record. ``spp``: samples
    per period of the highest frequency at the record's rate, which sets the RK4 steps per
    sample (steps of at most :data:`REFINE_STEP` radians, at most four per sample)."""

    spread = np.std(record.x, axis=0)
    fit: dict[str, Any] = {"simulation_nrmse": math.nan, "noise_nrmse": math.nan, "explained": False}
    noise_nrmse = float(np.max(noise / spread))
    fit["noise_nrmse"] = noise_nrmse
    n = record.n_samples
    init, length = _segment_samples(record, natural)
    try:
        substeps = min(4, max(1, math.ceil(2 * math.pi / (spp * REFINE_STEP)))) if spp > 0 else 4
        simulator = OdeSimulator(model, record.dt, free=(), substeps=substeps)
        simulated = np.empty_like(record.x)
        pieces: list[tuple[float, float, int]] = []  # (mean square error / variance, sum, samples)
        bounds = stretches(n, length)
        with np.errstate(all="ignore"):  # a trial initial state may make the simulation overflow
            fast = _segments_in_c(simulator, canonical, record, bounds, init)
            for i, (start, stop) in enumerate(bounds):
                measured = record.x[start:stop]
                if fast is not None and not fast[1][i]:
                    response = fast[0][start:stop]
                else:  # the fitted state escapes (or no C compiler): the Python simulator decides
                    segment = Record(record.t[start:stop], record.f[start:stop], measured, source=record.source)
                    response = _segment_response(simulator, canonical, segment, min(init, len(segment.t) // 4))
                scaled = ((response[init:] - measured[init:]) / spread) ** 2
                worst = float(np.max(np.mean(scaled, axis=0))) if np.all(np.isfinite(scaled)) else math.inf
                pieces.append((worst, float(np.max(np.sum(scaled, axis=0))), len(scaled)))
                simulated[start:stop] = response if np.all(np.isfinite(response)) else measured
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
            f"the model fits the plant (friction, other nonlinearities: duffid discover finds the terms the record "
            f"asks for)")
    return fit, simulated, None

def _segments_in_c(simulator: OdeSimulator, canonical: Mapping[str, float], record: Record,
                   bounds: list[tuple[int, int]], init: int) -> tuple[np.ndarray, list[bool]] | None:
    """The segments simulated in C (:class:`~duffid.identification.refine.SegmentSimulator`),
    or None without a C compiler."""
    try:
        fast = SegmentSimulator(simulator)
    except (BuildError, OSError):
        return None
    return fast.record_segments(canonical, record, bounds, init)

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
                           seed: int, progress: Any = None, pool: Pool | None = None,
                           reference: Callable[[], Mapping[str, float]] | None = None,
                           force_noise: np.ndarray | None = None
                           ) -> tuple[dict[str, float], dict[str, np.ndarray]]:
    """Relative standard error of each estimate from ``replicates`` noisy copies of the record
    (white noise of the levels ``noise`` on the displacements and ``force_noise`` on the forces),
    and the replicates' deviations of each finite estimate (for :func:`_traded_off`).

    The copies' noise is drawn in order from one generator (seeded by ``seed``) and the
    replicates run on ``pool`` (:class:`~duffid.identification.dispatch.Pool`: at most its
    jobs at a time, so at most that many copies exist), their values taken in order: the
    result is the same for any number of jobs. ``progress``: called once per replicate done.
    ``reference``: ``rerun``'s values for the record itself when ``rerun`` is not the
    estimator that gave ``estimates`` (its rows strided, :data:`BOOTSTRAP_ROWS_PER_WINDOW`):
    the deviations are taken from them."""
    pool = pool if pool is not None else Pool(1)
    rng = np.random.default_rng(seed)
    replicate_values: list[Mapping[str, float]] = []
    reference_run = pool.submit(reference) if reference is not None else None

    # the force's noise from a stream of its own: a record without it draws the same copies
    force_rng = np.random.default_rng([seed, 1])
    forced = force_noise is not None and bool(np.any(force_noise > 0))

    def noisy() -> Record:
        x = record.x + rng.standard_normal(record.x.shape) * noise
        f = record.f + force_rng.standard_normal(record.f.shape) * force_noise if forced else record.f
        return Record(record.t, f, x, source=record.source, sampling_rtol=record.sampling_rtol)

    for values in pool.ordered(rerun, (noisy for _ in range(replicates)), progress):
        replicate_values.append(values)
    centre = reference_run.result() if reference_run is not None else estimates
    out, deviations = {}, {}
    for k, v in estimates.items():
        d = np.array([float(values.get(k, math.nan)) - float(centre.get(k, math.nan)) for values in replicate_values])
        if not np.all(np.isfinite(d)) or not np.isfinite(v) or v == 0:
            out[k] = math.inf
        else:
            out[k] = max(math.sqrt(float(np.mean(d**2))) / abs(float(v)), UNCERTAINTY_FLOOR)
            deviations[k] = d
    return out, deviations

def _traded_off(deviations: Mapping[str, np.ndarray], names: Sequence[str]) -> dict[str, set[str]]:
    """Per parameter, the others whose replicates move with it at a correlation of at least
    :data:`TRADE_OFF_CORRELATION` (about the replicates' own centre: the noise's trade-off)."""
    out: dict[str, set[str]] = {k: set() for k in names}
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            if a in deviations and b in deviations:
                da, db = deviations[a], deviations[b]
                norm = float(np.linalg.norm(da) * np.linalg.norm(db))
                if norm > 0 and abs(float(da @ db)) >= TRADE_OFF_CORRELATION * norm:
                    out[a].add(b)
                    out[b].add(a)
    return out

def measured_force_noise(f: np.ndarray) -> np.ndarray:
    """The white noise level of each force column that the noisy replicates add: the force
    sensor's noise enters every value's error as the displacement's does (measured: with the
    force at 30 dB and the displacement at 60 dB, b was published 1-2 % off at 9-29 of the
    errors the displacement's noise alone gave). 0 where :func:`noise_is_white` says the
    figure is the signal's, not noise (a clean force sampled coarsely, a force whose content
    reaches the upper band): no noise is added there, as before."""
    f = np.asarray(f, dtype=float).reshape(len(f), -1)
    level = noise_level(f)
    return np.array([level[j] if noise_is_white(f[:, j])[0] else 0.0 for j in range(f.shape[1])])

def _progress(progress: bool | None | Callable[[str], Any], record: Record, replicates: int) -> tuple[Any, Any]:
    """The bootstrap's progress: the caller's callable, or a bar of its own (None: on a
    terminal for a record of at least :data:`PROGRESS_SAMPLES` samples); (step, bar to close)."""
    if callable(progress):
        return (lambda: progress("uncertainty")), None
    from tqdm import tqdm

    if progress is None:
        progress = sys.stderr.isatty() and record.n_samples >= PROGRESS_SAMPLES
    bar = tqdm(total=replicates, desc="uncertainty (noisy replicates)", disable=not progress, file=sys.stderr,
               leave=False)
    return bar.update, bar

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

def assess(record: Record, model: Chain, estimates: Mapping[str, float],
           rerun: Callable[[Record], Mapping[str, float]], *, max_uncertainty: float | None = None,
           replicates: int = REPLICATES, upsampled: int = 1, seed: int = 0,
           with_offsets: Callable[[], Mapping[str, float]] | None = None,
           at_half_rate: Callable[[], Mapping[str, float]] | None = None,
           progress: bool | None | Callable[[str], Any] = None, displacement_offset: bool = False,
           refine: bool = True, pool: Pool | None = None, noise: np.ndarray | None = None,
           content: float | None = None,
           rerun_reference: Callable[[], Mapping[str, float]] | None = None) -> Assessment:
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
    progress : bool, None or callable
        Progress bar on stderr while the replicates run (None: for long records on a terminal,
        :data:`PROGRESS_SAMPLES`); a callable is called with the stage's name after the
        simulation check, each replicate, the half-rate run and each simulation of an output-error
        fit (``"output-error fit"``) instead (the caller's bar).
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
    pool : Pool, optional
        Where the replicates, the half-rate run and the offset check run
        (:class:`~duffid.identification.dispatch.Pool`; default one job). The result is the same
        for any number of jobs.
    noise, content : optional
        :func:`noise_level` and :func:`content_frequency` of ``record`` when the caller has
        them already (computed once per record).
    rerun_reference : callable, optional
        ``rerun``'s values for the record itself, when ``rerun`` is a cheaper estimator than
        the one that gave ``estimates`` (the C core's rows of every few windows,
        :data:`BOOTSTRAP_ROWS_PER_WINDOW`): the replicates' deviations are taken from them.

    Offsets (``c1``, ... of a model with ``offset``, and ``x0``) are published when their
    relative standard error is at most ``max_uncertainty`` or their standard error at most
    ``max_uncertainty`` of the signal's spread (displacement standard deviation, force RMS);
    ``fit["offsets"]`` lists them with their absolute standard errors.
    """
    names = list(model.parameters) + ([DISPLACEMENT_OFFSET] if displacement_offset else [])
    values = {k: float(estimates.get(k, math.nan)) for k in names}
    noise = noise_level(record.x) if noise is None else np.asarray(noise, dtype=float)
    content = content_frequency(record.x, record.dt, noise=noise) if content is None else content
    canonical = canonical_of(model, values)
    natural = natural_frequency(model, canonical) if canonical is not None else math.nan
    if max_uncertainty is None:
        max_uncertainty = ASSESSMENT_UNCERTAINTY
    spp = samples_per_period(record.fs * upsampled, content, natural)
    force_noise = measured_force_noise(record.f)
    fit: dict[str, Any] = {"samples_per_period": spp, "content_hz": content, "natural_hz": natural,
                           "upsampled": int(upsampled), "noise": [float(s) for s in noise],
                           "force_noise": [float(s) for s in force_noise]}
    # the shares, the simulation and the noise are figures of the record as measured
    notes: list[str] = []
    if upsampled > 1:
        notes.append(f"the record was upsampled x{upsampled} (band-limited) before identification: "
                     f"its {record.fs:.4g} Hz sampling gives fewer than "
                     f"{SAMPLES_PER_PERIOD:.0f} samples per period of its highest frequency")
    elif spp < SAMPLES_PER_PERIOD and near_force_jumps(record.f).any():
        notes.append(f"the record was not upsampled although its {record.fs:.4g} Hz sampling gives fewer than "
                     f"{SAMPLES_PER_PERIOD:.0f} samples per period of its highest frequency: its force jumps "
                     f"between samples (a step), around which band-limited interpolation would ring")
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
    sim_fit, simulated, problem = _simulation_fit(physical, model, canonical, natural, noise, spp / upsampled)
    fit.update(sim_fit)
    if callable(progress):
        progress("simulation")
    if simulated is not None:
        shares = term_shares(model, canonical, simulated, record.f, record.dt)
        share = {**share, **_public_shares(model, shares)}
        if displacement_offset:  # only the cubic term tells x0 from a force bias
            share[DISPLACEMENT_OFFSET] = shares.get(f"k1_{max(model.orders)}", math.nan)
    unphysical = _unphysical(model, canonical)
    if problem is not None or unphysical is not None:
        notes.extend(n for n in (unphysical, problem) if n is not None)
        return Assessment(status, uncertainty, share, fit, notes, values)
    pool = pool if pool is not None else Pool(1)
    varies = force_varies(record)
    # the re-runs that do not depend on the bootstrap start first (with several jobs)
    coarse_run = pool.submit(at_half_rate) if at_half_rate is not None else None
    offset_run = pool.submit(with_offsets) if with_offsets is not None and varies else None
    step, bar = _progress(progress, record, replicates)
    try:
        uncertainty, deviations = _bootstrap_uncertainty(record, values, noise, rerun, replicates, seed, step,
                                                         pool, rerun_reference, force_noise)
    finally:
        if bar is not None:
            bar.close()
    bias = BALANCE_FLOOR + QUADRATURE_BIAS / spp**4
    for k in names:  # the quadrature's share of the error, larger for a term that carries little
        if np.isfinite(share[k]) and share[k] > 0:
            uncertainty[k] = max(uncertainty[k], bias / share[k])
    if coarse_run is not None:
        coarse = coarse_run.result()
        if callable(progress):
            progress("half rate")
        for k in names:
            change = abs(float(coarse.get(k, math.nan)) - values[k]) / abs(values[k]) if values[k] else math.inf
            uncertainty[k] = _with_rate_bias(uncertainty[k], change)
        fit["half_rate_change"] = {k: (float(coarse.get(k, math.nan)) - values[k]) / values[k]
                                   for k in names if values[k]}
    offset_moved = offset_check(values, uncertainty, offset_run.result if offset_run is not None else None, notes,
                                fit, max_uncertainty)
    if with_offsets is not None and not varies and model.offset:
        notes.append("the force hardly varies over the record (e.g. a step from the first sample): the record "
                     "cannot check for a displacement-sensor offset, so the values assume that the displacement "
                     "sensor reads zero at rest with no force")
    elif with_offsets is not None and not varies:
        notes.append("the force hardly varies over the record (e.g. a step from the first sample): the record "
                     "cannot separate a constant force or displacement offset from the stiffness, so the "
                     "values assume that the sensors read zero at rest with no force (a record with rest "
                     "before the step, or a varying force, lets duffid check it)")
    scales = offset_scales(record, model, names)

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
        # a value that can be published neither before nor after the check (undetermined, its
        # term not excited) stays at its algebraic value: free, it makes the fit ill-conditioned
        # (a 2-DOF record with cubic terms at 0.5 % of the force balance: 141 evaluations
        # against 5, the other values the same within 0.01 %)
        never = {k for k in names if not determined(k) and share[k] < MIN_SHARE}
        check = _refinement(record, model, values, uncertainty, natural, spp / upsampled, notes, [], check=True,
                            free=[model.canonical_name(k) for k in model.parameters if k not in never],
                            progress=progress if callable(progress) else None)
        if check is not None:
            fit["consistency"] = check
            _disagreement_as_uncertainty(check, uncertainty)
    if refine and pending and not offset_moved and not displacement_offset:
        # the equation error left excited values undetermined: the output error, an
        # efficient estimator for displacement noise, from the algebraic values
        refinement = _refinement(record, model, values, uncertainty, natural, spp / upsampled, notes, pending,
                                 progress=progress if callable(progress) else None)
        if refinement is not None:
            fit["refinement"] = refinement
            if refinement["accepted"]:
                values = {**values, **refinement["values"]}
                refined = refinement["uncertainty"]
                if np.any(force_noise > 0):
                    # its errors count the displacement's noise only: with a noisy force they are no
                    # smaller than the replicates' (measured: b 2.2 % off at a stated 0.7 %)
                    refined = {k: max(v, uncertainty[k]) for k, v in refined.items()}
                uncertainty = {**uncertainty, **refined}
            else:
                _disagreement_as_uncertainty(refinement, uncertainty)
    # a value known only together with an excited one the record leaves undetermined is no
    # better known than that one (TRADE_OFF_CORRELATION)
    paired = _traded_off(deviations, names)
    tied = {k: sorted(j for j in paired[k] if not determined(j) and not share[j] < MIN_SHARE)
            for k in names if determined(k)}
    tied = {k: v for k, v in tied.items() if v}
    if tied:
        notes.append("; ".join(f"{k} moves with {', '.join(v)} (correlation of their noisy replicates at least "
                               f"{TRADE_OFF_CORRELATION:g})" for k, v in tied.items())
                     + ": the record determines them only together (e.g. the motion has one frequency, where "
                       "inertia and stiffness act as k - m w^2), so neither is published; a richer excitation "
                       "or the transient from rest separates them")
    for k in names:
        if determined(k) and k not in offset_moved and k not in tied:
            status[k] = "published"
        elif np.isfinite(share[k]) and share[k] < MIN_SHARE and (k not in scales or k == DISPLACEMENT_OFFSET):
            status[k] = "not excited"
    weak = [k for k in names if status[k] == "not excited" and k != DISPLACEMENT_OFFSET]
    if weak:
        notes.append(f"{', '.join(weak)}: the term carries less than {100 * MIN_SHARE:.0f} % of the force "
                     f"balance in this record (" + ", ".join(f"{k} {100 * share[k]:.2g} %" for k in weak)
                     + "); a larger amplitude or a richer excitation would show it")
    if status.get(DISPLACEMENT_OFFSET) == "not excited":
        notes.append(inseparable_note(share[DISPLACEMENT_OFFSET]))
    if scales:
        fit["offsets"] = {k: {"value": values[k] if status[k] == "published" else math.nan,
                              "standard_error": uncertainty[k] * abs(values[k]), "status": status[k]}
                          for k in scales}
    unsure = [k for k in names if status[k] == "uncertain" and k not in offset_moved and k not in tied]
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

def _with_rate_bias(standard_error: float, change: float) -> float:
    """A relative standard error combined with the bias that a value's relative ``change``
    at half the sampling rate shows beyond what the noise explains (half the samples: about
    one more standard error, so changes within 2 standard errors are noise)."""
    bias = math.sqrt(max(change**2 - (2.0 * standard_error) ** 2, 0.0)) if np.isfinite(change) else math.inf
    return math.hypot(standard_error, bias)

def _disagreement_as_uncertainty(refinement: Mapping[str, Any], uncertainty: dict[str, float]) -> None:
    """A value on which the algebraic and output-error estimates disagree beyond their
    stated errors is not known better than their difference: raise its stated error to it.
    Where the output-error fit found a displacement-sensor offset (``offset_found``), which
    the algebraic estimate does not model, every value's difference counts: the offset biases
    them all (measured: kp 0.5 % off at 4 of its stated errors while within 3 combined errors
    of the output-error value)."""
    for k, apart in refinement["apart"].items():
        agrees = abs(apart) <= 3.0 * math.hypot(uncertainty[k], refinement["uncertainty"][k])
        if refinement.get("offset_found") or not agrees:
            uncertainty[k] = max(uncertainty[k], abs(apart))

def _refinement(record: Record, model: Chain, values: Mapping[str, float], uncertainty: Mapping[str, float],
                natural: float, spp: float, notes: list[str], pending: list[str],
                check: bool = False, free: Sequence[str] | None = None,
                progress: Callable[[str], Any] | None = None) -> dict[str, Any] | None:
    """Output-error refinement of ``values`` (:func:`duffid.identification.refine.refine`, multiple
    shooting over stretches of :data:`SEGMENT_PERIODS` natural periods), with the
    stated errors of the Gauss-Newton covariance (inflated for correlated residuals) and the
    change at half the sampling rate beyond what the noise explains (the interpolation's
    bias, first order where the force jumps): ``fit["refinement"]``, not ``accepted`` (with a
    note) when it disagrees with the algebraic values by more than 3 combined standard errors;
    None (with a note) when it fails. ``check``: a cross-check of determined values (the
    caller takes the disagreement as their uncertainty; the notes say so). ``free``: the canonical
    parameters refined (default: all); the others keep their values, with no stated error.
    ``progress("output-error fit")`` is called once per simulation of the fit."""
    what = "output-error cross-check" if check else f"output-error refinement of {', '.join(pending)}"

    if not spp / 2 >= REFINE_SAMPLES_PER_PERIOD:
        return None
    _, length = _segment_samples(record, natural)
    canonical_names = {k: model.canonical_name(k) for k in model.parameters}

    # a displacement sensor's offset moves a nonlinear spring's equilibrium: fitted as an output
    # offset unless the model carries a force bias (with which a linear spring confounds it)
    sensor_offset = not model.offset

    def run(rec: Record, segment: int, samples_per_period: float) -> Any:
        substeps = max(4, math.ceil(2 * math.pi / (samples_per_period * REFINE_STEP)))
        return refine(rec, model, {k: values[k] for k in model.parameters}, segment=max(segment, 8),
                      substeps=substeps, free=free, bias=sensor_offset,
                      progress=(lambda: progress("output-error fit")) if progress is not None else False)

    try:
        with np.errstate(all="ignore"):
            full = run(record, length, spp)
            half = run(every_second(record), length // 2, spp / 2)
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
            "accepted": not disagree, "apart": apart,
            "displacement_offset": list(full.bias), "displacement_offset_std": list(full.bias_std)}
    offsets = [j for j, (b, sd) in enumerate(zip(full.bias, full.bias_std)) if abs(b) > SENSOR_OFFSET_SIGMAS * sd]
    info["offset_found"] = bool(offsets)
    if offsets:
        named = "x" if len(full.bias) == 1 else "x{}"
        notes.append("the output-error fit finds a displacement-sensor offset ("
                     + ", ".join(f"{named.format(j + 1)} reads {full.bias[j]:.4g} at rest, "
                                 f"{abs(full.bias[j]) / full.bias_std[j]:.0f} standard errors from zero"
                                 for j in offsets)
                     + "): identify with --offset displacement (or --offset both) where the model allows it, or "
                       "remove the offset from the record")
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
