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
import threading
import time
from typing import Any, Callable, Mapping

import numpy as np
from tqdm import tqdm

from ..data.record import Record
from ..errors import InputError
from ..models.chain import Chain
from .assessment import ASSESSMENT_UNCERTAINTY, BOOTSTRAP_ROWS_PER_WINDOW, PROGRESS_SAMPLES, assess
from .c_facts import limit
from .dispatch import Pool, data_window, final_estimates, on_c_core, run_estimator
from .engine import MIN_SHARE, Identification, check_record
from .motion import identify_motion
from .offsets import (
    canonical_of,
    carries_displacement_offset,
    cubic_share_of,
    displacement_chain,
    displacement_offset_values,
    mapped_to,
    offset_kind,
    report_displacement_offset,
    with_force_offsets,
)
from .options import BUFFERED_METHODS, ONLINE_METHODS, check_options
from .sampling import (
    content_frequency,
    every_second,
    isolated_outliers,
    natural_frequency,
    upsampled,
    upsampling_needed,
)
# re-exported: the public names of the checked identification, wherever they live now
from .assessment import REPLICATES, SIMULATION_TOLERANCE, Assessment, term_shares  # noqa: F401
from .engine import STATUSES  # noqa: F401
from .offsets import DISPLACEMENT_OFFSET, OFFSETS  # noqa: F401
from .options import ENGINES  # noqa: F401
from .sampling import (  # noqa: F401
    MIN_SAMPLES_PER_PERIOD,
    SAMPLES_PER_PERIOD,
    noise_level,
    samples_per_period,
    upsampling_factor,
)

__all__ = [
    "identify",
    "run_estimator",
    "ENGINES",
    "ASSESSMENT_UNCERTAINTY",
    "STATUSES",
    "SAMPLES_PER_PERIOD",
    "SIMULATION_TOLERANCE",
    "MIN_SHARE",
    "REPLICATES",
    "Assessment",
    "assess",
    "noise_level",
    "content_frequency",
    "samples_per_period",
    "upsampling_factor",
    "upsampling_needed",
    "upsampled",
    "natural_frequency",
    "term_shares",
    "isolated_outliers",
    "OFFSETS",
    "DISPLACEMENT_OFFSET",
    "displacement_offset_values",
    "MIN_SAMPLES_PER_PERIOD",
]


def identify(record: Record, model: Chain, method: str = "robust", *, offsets: str | None = None,
             check: bool = True, engine: str = "auto", progress: bool | None = None,
             refine: bool = True, jobs: int | None = None, **options: Any) -> Identification:
    """Identify ``model``'s parameters from a record, publishing only what the record supports.

    The estimator (:func:`duffid.identification.batch.estimate`: the online methods sample by
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
        Forces and displacements, evenly sampled. A record of velocities or accelerations
        (:attr:`~duffid.data.record.Record.motion`) is identified by the output-error fit of
        :func:`~duffid.identification.motion.identify_motion` with its own checks (only
        ``max_uncertainty`` applies).
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
        Progress bar on stderr while the estimator and the checks run (None: on a terminal,
        for records of at least :data:`~duffid.identification.assessment.PROGRESS_SAMPLES`
        samples, about a second's work). Ctrl-C stops the runs under way and raises
        ``KeyboardInterrupt`` after a message on stderr.
    refine : bool
        Refine by output-error least squares when the algebraic estimate leaves excited
        values undetermined (see :func:`assess`; CLI ``--no-refine`` turns it off).
    jobs : int or None
        Threads for the independent re-runs of the checks (noisy replicates, half rate,
        offsets; None: every core, :func:`~duffid.identification.dispatch.all_cores`). The
        result is the same, bit for bit, for any number.
    **options
        Method options (see :class:`~duffid.identification.engine.OnlineIdentifier`). The
        record is taken as one plant: the online change test is off unless
        ``change_threshold`` is given (:func:`duffid.identification.changes.find_changes`
        tells where a record's plant changed; ``identify_segments`` identifies each stretch).

    Raises
    ------
    ValueError
        An unknown ``offsets`` kind, or a displacement offset for a model that cannot carry
        it (the message names the models that can).
    """
    if record.motion != "x":  # a velocity or acceleration: the output-error fit and its checks
        named = sorted(set(options) - {"max_uncertainty"}) + [
            flag for flag, given in (("method", method != "robust"), ("offsets", offsets is not None),
                                     ("check", not check), ("refine", not refine)) if given]
        if named:
            raise InputError(f"{record.source}: {', '.join(named)} do(es) not apply to a {record.motion} record: "
                             "it is identified by fitting the simulated motion to the measured one "
                             "(duffid.identification.motion.identify_motion); only max_uncertainty applies")
        return identify_motion(record, model, progress=progress, **options)
    kind = offset_kind(model, offsets)
    physical = with_force_offsets(model) if kind is not None else model
    estimation = _Estimation(model, physical, kind, method, engine)
    if not check:
        return estimation.run(record, options)
    check_record(record, model)
    if progress is None:
        progress = sys.stderr.isatty() and record.n_samples >= PROGRESS_SAMPLES
    bar = tqdm(total=REPLICATES + 4, desc="identify", unit="run", disable=not progress, file=sys.stderr, leave=False)
    started = time.perf_counter()

    def step(stage: str) -> None:
        """One run done; the output-error fit's simulations, when it runs, count as runs too."""
        if stage == "output-error fit" and bar.n >= bar.total:
            bar.total += 1
        bar.set_postfix_str(stage, refresh=False)
        bar.update(1)

    try:
        with Pool(jobs) as pool:
            estimation.cancel = pool.cancel
            return _checked(record, method, kind, physical, estimation, options, pool,
                            step, refine)
    except KeyboardInterrupt:
        bar.close()
        print(f"\nduffid identify: interrupted (Ctrl-C) after {time.perf_counter() - started:.1f} s; the runs under "
              "way were stopped and nothing was published", file=sys.stderr)
        raise
    finally:
        bar.close()


def _checked(record: Record, method: str, kind: str | None, physical: Chain, estimation: "_Estimation",
             options: Mapping[str, Any], pool: Pool, step: Callable[[str], Any], refine: bool) -> Identification:
    """:func:`identify` with ``check``: the record checks, the estimator's runs at the
    sampling and window the record needs, and :func:`assess` (its re-runs on ``pool``)."""
    outliers = isolated_outliers(record.x, record.f)
    if outliers:  # excluded: replaced by what their neighbours give, and reported
        x = record.x.copy()
        for i, j, value in outliers:
            x[i, j] = value
        measured, record = record, Record(record.t, record.f, x, source=record.source,
                                          sampling_rtol=record.sampling_rtol)
    estimation.record = record
    opts = estimation.options = dict(options)
    if method == "robust":  # the whole record is one plant here (where it changed: changes.find_changes)
        opts.setdefault("change_threshold", None)
    # the robust method's window from the data, in natural periods (never the default
    # seconds, which belong to the paper's 3.6 Hz plant): first from the displacement's
    # main frequency, then from the identified natural frequency
    auto = method == "robust" and check_options(method, opts)["window"] == "auto"
    periods = check_options(method, opts)["window_periods"] if auto else math.nan
    noise = noise_level(record.x)  # the record checks, computed once
    content = content_frequency(record.x, record.dt, noise=noise)
    if auto and np.isfinite(content) and content > 0:
        opts["window"] = data_window(record, content, periods)
    if auto and "min_time" not in options:  # 10 ms is 20 periods of a 2 kHz resonator
        opts["min_time"] = min(check_options(method, {})["min_time"], 0.5 * record.duration,
                               0.5 * periods / content if np.isfinite(content) and content > 0 else math.inf)
    estimation.factor = upsampling_needed(record, content=content)
    # a window of periods of the content frequency is redone in periods of the slowest
    # identified mode (the same only by chance): its first run's final values suffice
    first_window = opts.get("window") if auto else None  # None, or "auto" without a content frequency
    provisional = isinstance(first_window, float) and first_window < record.duration and \
        estimation.final_is_cheaper()
    result = None if provisional else estimation.run(estimation.sampled(), opts)
    # (its rows strided as the replicates': it decides the window only)
    first = estimation.final(estimation.sampled(), estimation.row_stride()) if result is None else result.estimates
    step("estimator")
    slowest = natural_frequency(physical, canonical_of(physical, first) or {}, lowest=True)
    again = upsampling_needed(record, first, physical, content=content)
    window = opts.get("window")
    if auto and np.isfinite(slowest) and slowest > 0:  # periods of the slowest mode
        window = data_window(record, slowest, periods)
    if result is None or again > estimation.factor or window != opts.get("window"):
        estimation.factor = max(estimation.factor, again)
        if window is not None:
            opts["window"] = window
        result = estimation.run(estimation.sampled(), opts)
    step("estimator")
    cubic_share = math.nan
    if estimation.shifted:
        cubic_share = cubic_share_of(record, estimation.measured_coordinate)
        if not cubic_share >= MIN_SHARE:  # x0 is a constant force like a force bias: not separable
            estimation.shifted = False
            result = estimation.run(estimation.sampled(), opts)
    estimation.result = result
    max_uncertainty = float(opts.get("max_uncertainty", ASSESSMENT_UNCERTAINTY))
    result.assessment = assess(record, physical, result.estimates, estimation.estimates,
                               max_uncertainty=max_uncertainty, upsampled=estimation.factor,
                               with_offsets=estimation.offset_check(), at_half_rate=estimation.at_half_rate,
                               progress=step, displacement_offset=estimation.shifted, refine=refine, pool=pool,
                               noise=noise, content=content, rerun_reference=estimation.reference())
    if kind in ("displacement", "both"):
        report_displacement_offset(result, kind, separable=estimation.shifted, cubic_share=cubic_share)
    if method in BUFFERED_METHODS and not result.assessment.identified and \
            not check_options(method, opts)["accumulate"]:  # say what its values rest on
        window = float(check_options(method, opts)["window"])
        natural = result.assessment.fit.get("natural_hz", math.nan)
        held = f", {window * natural:.2g} natural periods of the estimate" if np.isfinite(natural) else ""
        result.assessment.notes.append(
            f"the {method} method without --accumulate identifies from its latest window alone "
            f"({window:.3g} s{held}): --accumulate takes every window's rows")
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


class _Estimation:
    """The estimator runs of one checked identification: the model with its offsets, the
    method, engine and options, at the sampling decided for the record (its upsampled copy is
    made once per factor). Its methods are what :func:`assess` re-runs: on noisy copies
    (:meth:`estimates`), with the offsets the model lacks (:meth:`offset_check`), at half the
    rate (:meth:`at_half_rate`)."""

    def __init__(self, model: Chain, physical: Chain, kind: str | None, method: str, engine: str) -> None:
        self.model, self.physical, self.kind = model, physical, kind
        self.method, self.engine = method, engine
        # a displacement offset: the chain of orders (1, 2, 3) with a constant is identified and
        # mapped back; `shifted` is cleared when the record cannot separate x0 from a force bias
        self.shifted = kind in ("displacement", "both")
        self.extended = displacement_chain(physical) if self.shifted else None
        if self.extended is not None and engine == "c" and method in ONLINE_METHODS:
            raise InputError("the C core runs stiffness orders 1 and 3 only; a displacement offset needs the x^2 "
                             "term: use engine 'auto' or 'python'")
        self.measured_coordinate: dict[str, float] = {}  # the last run's values of `extended`
        self.record: Record | None = None
        self.options: dict[str, Any] = {}
        self.factor = 1
        self.result: Identification | None = None
        self._sampled: tuple[int, Record] | None = None
        self._stride: tuple[Any, int] | None = None  # row_stride's, for the window, factor and offset it was for
        self._reference: tuple[Any, Mapping[str, float]] | None = None  # reference_values', likewise
        self._reference_lock = threading.Lock()
        self.cancel: Any = None  # the pool's event: runs stop at their next block once it is set

    def run(self, record: Record, options: Mapping[str, Any]) -> Identification:
        """The estimator on ``record`` (the displacement-offset chain mapped back when it applies)."""
        if self.shifted and self.extended is not None:
            raw = run_estimator(record, self.extended, self.method, engine="python", **options)
            self.measured_coordinate.clear()
            self.measured_coordinate.update(raw.estimates)
            return mapped_to(raw, self.physical)
        return run_estimator(record, self.physical, self.method, engine=self.engine, cancel=self.cancel, **options)

    def final(self, record: Record, row_stride: int = 1) -> Mapping[str, float]:
        """The final estimates of :meth:`run` on ``record`` with the decided options, without
        the history (a re-run of the checks; safe to call from several threads);
        ``row_stride`` as :func:`~duffid.identification.dispatch.final_estimates`'s."""
        if self.shifted and self.extended is not None:
            raw = run_estimator(record, self.extended, self.method, engine="python", **self.options)
            return mapped_to(raw, self.physical).estimates
        return final_estimates(record, self.physical, self.method, engine=self.engine, cancel=self.cancel,
                               row_stride=row_stride, **self.options)

    def row_stride(self) -> int:
        """Samples between the rows of the noisy replicates' runs: at least
        :data:`~duffid.identification.assessment.BOOTSTRAP_ROWS_PER_WINDOW` per window length
        where the C core runs them with a fixed window (1: every sample's)."""
        window = self.options.get("window")
        key = (window, self.factor, self.shifted, self.options.get("change_threshold"))
        if self._stride is None or self._stride[0] != key:
            stride = 1
            # only where the C core defers the solutions (a fixed window, no change test): else the
            # replicates keep every row, and a strided reference would be a wasted pass
            if isinstance(window, float) and self.method == "robust" and not self.options.get("change_threshold") \
                    and self.final_is_cheaper():
                samples = window * self.record.fs * self.factor
                stride = int(min(max(samples // BOOTSTRAP_ROWS_PER_WINDOW, 1), limit("max_row_stride")))
            self._stride = (key, stride)
        return self._stride[1]

    def reference(self) -> Callable[[], Mapping[str, float]] | None:
        """The noisy replicates' estimator on the record itself, when it is not :meth:`run`'s
        (rows strided, :meth:`row_stride`); else None."""
        return self.reference_values if self.row_stride() > 1 else None

    def reference_values(self) -> Mapping[str, float]:
        """The final estimates of the record with the rows of every :meth:`row_stride`-th
        window (computed once for the current window and factor; safe from several threads)."""
        with self._reference_lock:
            key = (self.options.get("window"), self.factor, self.row_stride())
            if self._reference is None or self._reference[0] != key:
                self._reference = (key, self.final(self.sampled(), key[2]))
            return self._reference[1]

    def final_is_cheaper(self) -> bool:
        """Whether :meth:`final` costs less than :meth:`run` on the record (the C core, which
        then writes no per-sample output; the Python identifier keeps its history either way)."""
        return not self.shifted and on_c_core(self.record, self.physical, self.method, self.engine, self.options)

    def sampled(self) -> Record:
        """The record upsampled by the current factor (made once per factor)."""
        if self._sampled is None or self._sampled[0] != self.factor:
            self._sampled = (self.factor, upsampled(self.record, self.factor))
        return self._sampled[1]

    def estimates(self, noisy: Record) -> Mapping[str, float]:
        """The final estimates from a noisy copy of the record, identified as the record was
        (the rows of every :meth:`row_stride`-th sample)."""
        return self.final(upsampled(noisy, self.factor), self.row_stride())

    def at_half_rate(self) -> Mapping[str, float]:
        """The final estimates from every second sample."""
        return self.final(every_second(self.sampled()))

    def offset_check(self) -> Callable[[], Mapping[str, float]] | None:
        """The run that checks the offsets the model lacks (None when none applies): a force
        bias added to a model without one; a displacement offset where a force bias is
        modelled and the model can carry one."""
        if not self.physical.offset:
            offset_model = with_force_offsets(self.model)

            def with_offsets() -> Mapping[str, float]:
                stride = self.row_stride()
                if stride > 1 and not on_c_core(self.sampled(), offset_model, self.method, self.engine, self.options):
                    stride = 1
                values = final_estimates(self.sampled(), offset_model, self.method, engine=self.engine,
                                         cancel=self.cancel, row_stride=stride, **self.options)
                if stride == 1:
                    return values
                # rows strided as the replicates': its change is the one from the same strided
                # estimator without the offsets (the reference), carried to the values
                base = self.reference_values()
                return {k: v - base[k] + self.result.estimates[k] if k in base else v for k, v in values.items()}
            return with_offsets
        if self.kind == "force" and carries_displacement_offset(self.physical):
            def with_displacement_offset() -> Mapping[str, float]:
                raw = run_estimator(self.sampled(), displacement_chain(self.physical), self.method,
                                    engine="python", **self.options).estimates
                if not cubic_share_of(self.record, raw) >= MIN_SHARE:
                    # without the cubic, x0 is the force bias already modelled
                    return dict(self.result.estimates)
                return displacement_offset_values(self.physical, raw)
            return with_displacement_offset
        return None
