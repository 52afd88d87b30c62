"""Online identification from a measured velocity or acceleration.

An accelerometer or a vibrometer does not give the displacement a cubic spring needs, and no
causal filter gives it either (see :mod:`duffid.identification.motion` and the notes "A
velocity or acceleration instead of a displacement"). Online, the offline output-error fit of
:func:`~duffid.identification.motion.identify_motion` is therefore re-run on the latest
samples (a receding horizon): every ``interval`` seconds of data, the model is fitted to the
last ``horizon`` seconds of the measured motion under the measured force, from the previous
fit's values (from the algebraic start on the integrated signal when there is none, or when
the warm start does not explain the signal).

What is published follows the offline rules of that fit, on the horizon: a value is
published when the simulated motion follows the measured one down to its white noise over the
horizon and over each of its parts (:data:`~duffid.identification.motion.FIT_PARTS`) and its
stated relative standard error is at most ``max_uncertainty``, and once the horizon spans
:data:`MIN_PERIODS` natural periods of the fitted model. A fit that no longer explains the
signal after one that did withdraws every value ("changed": a plant that changed within the
horizon is followed worse in one part); so does a fit whose horizon's latest half, fitted from
its values, moved beyond :data:`MOVED_ERRORS` standard errors (a drifting plant), and the
horizon then halves. Between fits the published values are checked every natural period on
the latest periods (:data:`CHECK_PERIODS`) and withdrawn as "changed" when they no longer
follow the signal, so a value that went stale is shown for at most about a natural period
(plus the time the change needs to show in those periods).

The work per sample is not fixed: a sample is stored (O(1)); the fits cost what the
offline fit of ``horizon`` seconds costs, once per ``interval``. This runs in Python (and
the Python estimator FMUs); the C core needs a displacement.
"""
from __future__ import annotations

import contextlib
import math
import sys
import warnings
from collections.abc import Iterator
from typing import Any

import numpy as np
from tqdm import tqdm

from ..data.record import Record
from ..errors import InputError, RecordError
from ..models.chain import Chain
from ..models.equation_model import EquationModel
from .engine import STATUSES, Estimate, Identification
from .motion import FIT_TOLERANCE, MAX_UNCERTAINTY, MOTIONS, band_limited_motion, identify_motion
from .refine import canonical_from_public, refine
from .sampling import natural_frequency, noise_level

__all__ = ["OnlineMotionIdentifier", "HORIZON_PERIODS", "REFITS_PER_HORIZON", "MIN_PERIODS", "FIRST_FIT",
           "CHECK_PERIODS", "CHECK_EVERY", "MOVED_ERRORS", "PROBE_EVERY", "PROBE_GROWTH", "OPTIONS", "run_motion_online"]

#: The automatic horizon, in natural periods of the latest fit's lowest mode (capped by
#: ``max_horizon``).
HORIZON_PERIODS = 40.0
#: The automatic interval between fits: this many fits per horizon.
REFITS_PER_HORIZON = 8
#: A value is published only once the fitted samples span this many natural periods.
MIN_PERIODS = 5.0
#: Samples of the first fit; until a fit gives a natural frequency, the next is tried when the
#: samples have doubled.
FIRST_FIT = 256
#: A fit's values are published only if the fit of its horizon's latest half (from them) is
#: within this many standard errors of the difference of them (else the plant moved within the
#: horizon: measured without it, a stiffness drifting 5 %/s at 40 dB was published up to 3.6 %
#: off, 17 % of the published values beyond 3 stated errors). Tested when the half spans
#: :data:`MIN_PERIODS` natural periods (after a fit whose values moved, nothing is published
#: until a horizon that long passes). Not 3.5: on a constant plant a horizon of 7.5 periods gave
#: a damping 6.4 such errors from its latest half's (the stated errors of so few periods are
#: less sure).
MOVED_ERRORS = 4.0
#: Between fits, every :data:`CHECK_EVERY` natural periods, the published values are checked
#: on the latest :data:`CHECK_PERIODS` periods: the model with those values (only its state
#: and the sensor's bias fitted) must follow the measured signal there to
#: :data:`~duffid.identification.motion.FIT_TOLERANCE` times its noise, or every value is
#: withdrawn ("changed") and the horizon restarts with the next sample. Measured (hardening
#: plant of 10 Hz, 50 dB, 3 periods): with the right values 0.98-1.02 times the noise, with
#: a stiffness 2 % off 4.2-6.8 times; about 25 ms per check.
CHECK_PERIODS = 3.0
#: The fits probe the model's next terms (:func:`~duffid.identification.motion.probe_terms`,
#: three more fits each) once every this many fits that could publish (once a horizon), and the
#: fits between keep the latest probe's findings: a term the model lacks is the plant's, not
#: the horizon's. Measured (``benchmarks/motion_online.py``, 3 seeds, constant and k +25 %):
#: probing every fit took 2.2-3.7 s per second of data, this 1.3-1.75 (0.8-1.1 before the probes;
#: load-dependent), the other figures unchanged.
PROBE_EVERY = REFITS_PER_HORIZON
#: ... and whenever the horizon has grown to more than this many times the one last probed (a
#: short horizon's probe sees less: the first fits of the weak x^5 spring of
#: ``tests/test_motion.py``, over fewer than 5 periods, found no term, and kept for a horizon,
#: that finding let kp be shown 1.4 % off at 16 stated errors).
PROBE_GROWTH = 1.5
#: ... checked this often, in natural periods.
CHECK_EVERY = 1.0


#: The options of :class:`OnlineMotionIdentifier`: name -> (default, unit, description).
OPTIONS = {
    "horizon": ("auto", "s", f"seconds of the latest samples each fit uses (auto: {HORIZON_PERIODS:g} natural "
                              "periods of the latest fit, at most max_horizon)"),
    "max_horizon": (10.0, "s", "largest horizon: the seconds of samples kept"),
    "interval": ("auto", "s", f"seconds of data between fits (auto: the horizon / {REFITS_PER_HORIZON})"),
    "max_uncertainty": (MAX_UNCERTAINTY, "1", "largest relative standard error of a published value"),
}


class OnlineMotionIdentifier:
    """Online identifier from the force and a measured velocity or acceleration.

    The options and their defaults are :data:`OPTIONS`.

    Parameters
    ----------
    model : Chain or EquationModel
        Model structure (its values are not used); an equation is written in the
        displacements whose velocity or acceleration is measured.
    dt : float
        Sampling period [s].
    motion : {"a", "v"}
        What the motion samples measure: acceleration (default) or velocity, in the model's
        displacement unit per second squared or per second.
    horizon : float or "auto"
        Seconds of the latest samples each fit uses; "auto": :data:`HORIZON_PERIODS`
        natural periods of the latest fit, at most ``max_horizon``.
    max_horizon : float
        Largest horizon [s]: the samples kept (memory: this many seconds of samples).
    interval : float or "auto"
        Seconds of data between fits; "auto": the horizon over :data:`REFITS_PER_HORIZON`.
    max_uncertainty : float
        Largest relative standard error of a published value.

    Examples
    --------
    >>> ident = OnlineMotionIdentifier(Duffing1(), dt=2e-4, motion="a")  # doctest: +SKIP
    >>> for a, f in samples:                                            # doctest: +SKIP
    ...     est = ident.update(a, f)
    """

    def __init__(self, model: Chain | EquationModel, dt: float, motion: str = "a", *,
                 horizon: float | str = OPTIONS["horizon"][0], max_horizon: float = OPTIONS["max_horizon"][0],
                 interval: float | str = OPTIONS["interval"][0],
                 max_uncertainty: float = OPTIONS["max_uncertainty"][0]) -> None:
        if motion not in MOTIONS:
            raise InputError(f"motion must be one of {', '.join(MOTIONS)} (velocity, acceleration), got {motion!r}; "
                             "a displacement is identified by OnlineIdentifier")
        if not (math.isfinite(dt) and dt > 0):
            raise InputError(f"dt must be a positive number of seconds, got {dt!r}")
        for name, value in (("max_horizon", max_horizon), ("max_uncertainty", max_uncertainty)):
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise InputError(f"{name} must be a positive number, got {value!r}")
        for name, value in (("horizon", horizon), ("interval", interval)):
            if value != "auto" and not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise InputError(f"{name} must be 'auto' or a positive number of seconds, got {value!r}")
        if horizon != "auto" and horizon > max_horizon:
            max_horizon = float(horizon)
        self.model = model
        self.dt = float(dt)
        self.motion = motion
        self.options: dict[str, Any] = {"horizon": horizon, "max_horizon": float(max_horizon), "interval": interval,
                                        "max_uncertainty": float(max_uncertainty)}
        self.names = list(model.parameters)
        self.capacity = max(int(round(self.options["max_horizon"] / self.dt)), FIRST_FIT)
        self._y = np.empty((self.capacity, model.n_dof))
        self._f = np.empty((self.capacity, model.n_forces))
        self.reset()

    # ----------------------------------------------------------------- state
    def reset(self) -> None:
        """Forget all samples and published values (a new identification)."""
        self.n = 0                # samples received
        self._count = 0           # samples since the last gap
        self._stored = 0          # ... of which in the buffer
        self._head = 0            # next slot of the ring buffer
        self._next_fit = FIRST_FIT
        self._frequency = math.nan  # the latest fit's lowest natural frequency [Hz]
        self._values = {k: math.nan for k in self.names}      # the latest fit's values
        self._published = {k: math.nan for k in self.names}
        self._std = {k: math.nan for k in self.names}
        self._relative = {k: math.nan for k in self.names}
        self._status = {k: STATUSES[0] for k in self.names}
        self._explained = False
        self._moving = False  # the latest tested horizon's values moved (until one does not)
        self._residual = math.nan
        self._lacking: list[dict[str, Any]] = []  # the latest term probe's findings (PROBE_EVERY)
        self._probe_in = 0  # fits until the next term probe
        self._probed_samples = 0  # ... and the samples of the horizon it probed
        self.fits = 0
        self.checks = 0
        self._next_check = 0
        self.last: Identification | None = None  # the latest fit's result
        self.notes: list[str] = []

    def hold(self) -> None:
        """The next sample does not follow the previous one (the samples in between are not
        given): the horizon restarts with the next sample; the published values are kept
        until the next fit."""
        self._count = 0
        self._stored = 0
        self._next_fit = FIRST_FIT

    # -------------------------------------------------------------- sizes
    @property
    def horizon(self) -> float:
        """The current horizon [s]."""
        h = self.options["horizon"]
        if h != "auto":
            return float(h)
        if math.isfinite(self._frequency) and self._frequency > 0:
            return min(self.options["max_horizon"], HORIZON_PERIODS / self._frequency)
        return self.options["max_horizon"]

    @property
    def interval(self) -> float:
        """The current interval between fits [s]."""
        i = self.options["interval"]
        return float(i) if i != "auto" else self.horizon / REFITS_PER_HORIZON

    # ----------------------------------------------------------------- steps
    def update(self, motion: Any, f: Any) -> Estimate:
        """Take one sample of the measured motion (one value per DOF) and the force(s); fit
        when an interval of data is complete.

        Raises
        ------
        InputError
            On a sample of the wrong size or a non-finite value.
        """
        y = np.atleast_1d(np.asarray(motion, dtype=float)).ravel()
        force = np.atleast_1d(np.asarray(f, dtype=float)).ravel()
        word = MOTIONS[self.motion]
        if y.size != self.model.n_dof or force.size != self.model.n_forces:
            raise InputError(f"{self.model.name}: a sample has {self.model.n_dof} {word}(s) and "
                             f"{self.model.n_forces} force(s), got {y.size} and {force.size}")
        if not (np.all(np.isfinite(y)) and np.all(np.isfinite(force))):
            raise InputError(f"sample {self.n}: non-finite {word} or force ({y.tolist()}, {force.tolist()})")
        self._y[self._head] = y
        self._f[self._head] = force
        self._head = (self._head + 1) % self.capacity
        self._count += 1
        self._stored = min(self._count, self.capacity)
        self.n += 1
        if self._count >= self._next_fit:
            self._fit()
        elif self._count >= self._next_check and any(s == STATUSES[1] for s in self._status.values()):
            self._check()
        return self.estimate()

    def _periods(self, periods: float) -> int:
        """Samples in ``periods`` natural periods of the latest fit."""
        return max(int(round(periods / self._frequency / self.dt)), 8)

    def _check(self) -> None:
        """Do the published values still explain the latest periods? (:data:`CHECK_PERIODS`)"""
        self._next_check = self._count + self._periods(CHECK_EVERY)
        n = min(self._periods(CHECK_PERIODS), self._stored)
        y, f = self._horizon_samples()
        try:
            _, (x, v) = band_limited_motion(Record(np.arange(len(y)) * self.dt, f, y, source="the horizon",
                                                   motion=self.motion), self.motion)
            record = Record(np.arange(n) * self.dt, f[-n:], y[-n:], source="the latest periods", motion=self.motion)
            with _quiet():
                fit = refine(record, self.model, self._values, free=(), output=self.motion,
                             state_guess=(x[-n:], v[-n:]), progress=False)
            noise = float(np.max(noise_level(record.x)))
            followed = bool(fit.success and fit.rms <= FIT_TOLERANCE * noise)
            self._residual = fit.rms / float(np.max(np.std(record.x, axis=0)))
        except (InputError, RecordError, ValueError, np.linalg.LinAlgError) as exc:
            followed = False
            fit = None
            self.notes = [f"the check of the published values failed: {exc}"]
        self.checks += 1
        if followed:
            return
        if fit is not None:
            self.notes = [f"the published values no longer explain the measured {MOTIONS[self.motion]} of the latest "
                          f"{n * self.dt:.3g} s ({fit.rms:.3g} RMS against noise {noise:.3g}): withdrawn, the plant "
                          "may have changed; the horizon restarts"]
        for k in self.names:
            if self._status[k] == STATUSES[1]:
                self._status[k] = STATUSES[4]
                self._published[k] = math.nan
                self._std[k] = math.nan
        self._explained = False
        self._count = self._stored = 0  # the change lies in the latest periods: none are kept
        self._next_fit = self._periods(MIN_PERIODS)

    def _horizon_samples(self) -> tuple[np.ndarray, np.ndarray]:
        """The latest samples of the horizon, oldest first."""
        n = min(self._stored, max(int(round(self.horizon / self.dt)), FIRST_FIT))
        index = (self._head - n + np.arange(n)) % self.capacity
        return self._y[index], self._f[index]

    def _fit(self) -> None:
        """Fit the horizon, and its latest half from that fit (:data:`MOVED_ERRORS`); while
        the fit does not explain the signal, or the values moved within the horizon, and the
        horizon spans more than twice :data:`MIN_PERIODS`, drop its older half and fit again
        (a plant that changed or drifts is followed by a shorter horizon)."""
        while True:
            y, f = self._horizon_samples()
            result = self._fit_once(y, f)
            self.fits += 1
            explained = result is not None and bool(result.assessment.fit.get("explained", False))
            moved = self._moved(result, y, f) if explained else None
            periods = len(y) * self.dt * self._frequency if math.isfinite(self._frequency) else 0.0
            if (explained and moved is None) or periods <= 2 * MIN_PERIODS:
                break
            self._count = self._stored = len(y) // 2
        self._schedule()
        if math.isfinite(self._frequency):
            self._next_check = self._count + self._periods(CHECK_EVERY)
        self._take(result, len(y) * self.dt, moved)

    def _moved(self, result: Identification, y: np.ndarray, f: np.ndarray) -> str | None:
        """Why the values moved within the horizon (None: they did not): the fit of its latest
        half, from the horizon's values, differs from them by more than :data:`MOVED_ERRORS`
        standard errors of the difference (that of nested least squares, ``sqrt(s_half^2 -
        s_all^2)``), or does not explain its samples."""
        half = len(y) // 2
        if half < FIRST_FIT or not half * self.dt * self._frequency >= MIN_PERIODS:
            if self._moving:  # too short to test: not published before a horizon long enough is
                return ("the values moved within an earlier horizon, and this one is too short to show they "
                        f"settled (its half spans fewer than {MIN_PERIODS:g} natural periods)")
            return None
        record = Record(np.arange(half) * self.dt, f[-half:], y[-half:], source=f"the latest {half * self.dt:.3g} s",
                        motion=self.motion)
        try:
            with _quiet():
                latest = identify_motion(record, self.model, max_uncertainty=self.options["max_uncertainty"],
                                         start=result.estimates, check_terms=False, progress=False)
        except (InputError, RecordError, ValueError, np.linalg.LinAlgError) as exc:
            return f"the fit of the horizon's latest half failed ({exc})"
        self.fits += 1
        if not latest.assessment.fit.get("explained", False):
            return "the model with the horizon's values does not explain its latest half"
        for name in self.names:
            value, recent = result.estimates[name], latest.estimates[name]
            s_all = abs(value) * result.assessment.uncertainty[name]
            s_half = abs(recent) * latest.assessment.uncertainty[name]
            spread = math.sqrt(max(s_half**2 - s_all**2, 0.25 * s_half**2))
            if not abs(recent - value) <= MOVED_ERRORS * spread:
                self._moving = True
                return (f"{name} moved within the horizon: {recent:.6g} over its latest half against {value:.6g} "
                        f"over all of it ({abs(recent - value) / spread:.2g} standard errors of the difference); "
                        "the plant may be drifting")
        self._moving = False
        return None

    def _fit_once(self, y: np.ndarray, f: np.ndarray) -> Identification | None:
        """The fit of these samples from the previous values, or (when that does not explain
        the signal) from the algebraic start; None when neither could run."""
        record = Record(np.arange(len(y)) * self.dt, f, y, source=f"the latest {len(y) * self.dt:.3g} s",
                        motion=self.motion)
        max_u = self.options["max_uncertainty"]
        result = None
        starts: list[dict[str, float] | None] = [None]
        if all(map(math.isfinite, self._values.values())):
            starts.insert(0, dict(self._values))
        probe = self._probe_in <= 0 or len(y) > PROBE_GROWTH * self._probed_samples
        for start in starts:
            try:
                with _quiet():
                    result = identify_motion(record, self.model, max_uncertainty=max_u, start=start,
                                             check_terms=probe, progress=False)
            except (InputError, RecordError, ValueError, np.linalg.LinAlgError) as exc:
                self.notes = [f"the fit of {record.source} failed: {exc}"]
                continue
            if result.assessment.fit.get("explained", False):
                break
        if result is not None:
            self._apply_probe(result, probe, len(y))
        return result

    def _apply_probe(self, result: Identification, probed: bool, samples: int) -> None:
        """Keep a fit's term probe's findings (:data:`PROBE_EVERY`), or apply the latest ones
        to a fit that was not probed: the values that moved with a lacking term are not
        published."""
        fit = result.assessment.fit
        if fit.get("terms_probed", False):
            self._lacking = list(fit.get("lacking_terms", []))
            self._probe_in = PROBE_EVERY - 1
            self._probed_samples = samples
            return
        if not probed:
            self._probe_in -= 1
        status = result.assessment.status
        for term in self._lacking:
            if any(status.get(name) == STATUSES[1] for name in term["moved"]):
                result.assessment.notes.append(f"(the term probe of an earlier fit) {term['note']}")
            for name in term["moved"]:
                if status.get(name) == STATUSES[1]:
                    status[name] = STATUSES[0]

    def _schedule(self) -> None:
        """The next fit: an interval on; until a fit gives a natural frequency, when the
        samples have doubled (if that is sooner)."""
        step = max(int(round(self.interval / self.dt)), 1)
        self._next_fit = self._count + step
        if not math.isfinite(self._frequency):
            self._next_fit = min(2 * self._count, self._next_fit)

    def _take(self, result: Identification | None, span: float, moved: str | None = None) -> None:
        """Statuses and published values from a fit (None: it failed; ``moved``: why its values
        moved within the horizon, then nothing is published)."""
        was_explained = self._explained
        self.last = result
        if result is None:
            self._explained = False
            self._residual = math.nan
            values = {k: math.nan for k in self.names}
            status = {k: STATUSES[0] for k in self.names}
            relative = {k: math.nan for k in self.names}
        else:
            fit = result.assessment.fit
            self._explained = bool(fit.get("explained", False))
            self._residual = float(fit.get("worst_part_nrmse", math.nan))
            values = dict(result.estimates)
            status = dict(result.assessment.status)
            relative = dict(result.assessment.uncertainty)
            self.notes = list(result.assessment.notes)
            if self._explained and all(map(math.isfinite, values.values())):  # the horizon's scale
                try:
                    hz = natural_frequency(self.model, canonical_from_public(self.model, values), lowest=True)
                except (InputError, ValueError):
                    hz = math.nan
                if math.isfinite(hz) and hz > 0:
                    self._frequency = float(hz)
            periods = span * self._frequency if math.isfinite(self._frequency) else 0.0
            if periods < MIN_PERIODS and any(s == STATUSES[1] for s in status.values()):
                status = {k: STATUSES[0] for k in self.names}
                self.notes.append(f"the fitted samples span {periods:.2g} natural periods; values are published "
                                  f"from {MIN_PERIODS:g} on")
            if moved is not None:
                self._explained = False
                status = {k: STATUSES[0] for k in self.names}
                self.notes.append(moved + ": nothing is published")
        self._values = values
        self._relative = relative
        for k in self.names:
            if status[k] == STATUSES[1]:
                self._status[k] = STATUSES[1]
                self._published[k] = values[k]
                self._std[k] = abs(values[k]) * relative[k]
                continue
            if self._status[k] == STATUSES[1] or self._status[k] in STATUSES[3:]:
                # withdrawn: the signal no longer fits (changed) or the error grew (lost)
                self._status[k] = STATUSES[4] if (was_explained and not self._explained) else (
                    STATUSES[3] if self._status[k] == STATUSES[1] else self._status[k])
            else:
                self._status[k] = STATUSES[0]
            self._published[k] = math.nan
            self._std[k] = math.nan

    def estimate(self) -> Estimate:
        """The current published values and statuses (those of the latest fit)."""
        relative = [r for r in self._relative.values() if math.isfinite(r)]
        return Estimate(t=(self.n - 1) * self.dt, parameters=dict(self._published),
                        identified=all(s == STATUSES[1] for s in self._status.values()),
                        condition=math.nan, uncertainty=max(relative) if relative else math.nan,
                        window=min(self._stored, max(int(round(self.horizon / self.dt)), FIRST_FIT)) * self.dt,
                        current=dict(self._values), status=dict(self._status), outliers=0,
                        std_errors=dict(self._std), residual=self._residual)


@contextlib.contextmanager
def _quiet() -> Iterator[None]:
    """Silence the floating-point warnings of a fit whose trial values escape (its result
    says so in words: the CLI's voice, not Python warnings)."""
    with warnings.catch_warnings(), np.errstate(all="ignore"):
        warnings.simplefilter("ignore", RuntimeWarning)
        yield


def run_motion_online(record: Record, model: Chain | EquationModel, *, progress: bool | None = None,
                      **options: Any) -> Identification:
    """Run :class:`OnlineMotionIdentifier` (``options``) over a velocity or acceleration record,
    with a progress bar (``progress``; None: on a terminal).

    Returns
    -------
    Identification
        The history of the published values at every sample (``t``, ``history``,
        ``identified``), the values published at the end (``parameters``, their
        ``online_status``) and the latest fit's values (``estimates``).
    """
    if record.motion not in MOTIONS:
        raise RecordError(f"{record.source}: the record measures a displacement; run the OnlineIdentifier")
    ident = OnlineMotionIdentifier(model, record.dt, record.motion, **options)
    history = {k: np.empty(record.n_samples) for k in ident.names}
    identified = np.zeros(record.n_samples, dtype=bool)
    disable = not sys.stderr.isatty() if progress is None else not progress
    with tqdm(total=record.n_samples, desc=f"online fit of {model.name}", unit="sample", disable=disable,
              leave=False, mininterval=0.5) as bar:
        for i in range(record.n_samples):
            est = ident.update(record.x[i], record.f[i])
            for k, v in est.parameters.items():
                history[k][i] = v
            identified[i] = est.identified
            if i % 1000 == 999:
                bar.update(1000)
    last = ident.estimate()
    t = record.t - record.t[0]
    return Identification(
        model=model.name, method=f"online output-error ({MOTIONS[record.motion]})", parameters=last.parameters,
        t=t, history=history, condition=np.full(record.n_samples, math.nan),
        identified=identified, t_identified=float(t[np.argmax(identified)]) if identified.any() else None,
        window=last.window, options={"motion": record.motion, **ident.options}, source=record.source,
        estimates=dict(last.current or {}), online_status=dict(last.status or {}))
