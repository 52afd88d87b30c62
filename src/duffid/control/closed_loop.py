"""The closed loop plant <-> identifier <-> adaptive controller, run as co-simulation.

Four loops are defined (:func:`loop_cases`): the paper's 1-DOF oscillator
(``Oscillator1DOF``), the same with a payload added during control
(``Oscillator1DOFPayload``, :func:`with_payload`), the 2-DOF chain (``Oscillator2DOF``,
force on and tracking of mass 1) and the Duffing circuit (``DuffingCircuit``, charge
tracked by the source voltage). Each is a :class:`duffid.cosim.system.System` of three FMUs::

    plant.x ──> estimator.x, controller.x       controller.f ──> plant.f
    estimator.{m,b,k,kp}_hat, identified ──> controller
    controller.f_sample ──> estimator.f         r(t), r'(t), r''(t) ──> controller.r, r_dot, r_ddot

run by the Jacobi master (every FMU reads the others' outputs of the same communication
point; the controller compensates its one-sample computational delay by prediction, see
:mod:`duffid.control.adaptive`). The plant holds the force over each step; the estimator gets the
controller's ``f_sample``, the mean of the forces before and after the sampling instant,
which stands for that staircase as a sample to O(h^2) (the command itself would lag by
half a step: 0.3 % on m and 13 % on kp under a 6 N chirp). The controller excites the plant with a force step until the
estimator reports identified and the estimates have settled, then switches bumplessly to
the certainty-equivalence law. The baseline is the same law on nominal parameters that
are wrong by a set fraction (:func:`duffid.control.design.mismatched`), switching at the same
time, without an estimator.

:func:`run_loop` runs one case both ways and returns a :class:`LoopResult` with the
estimates the law uses, the tracking RMS of both runs over the same interval and the
force peak (with a payload, also a :class:`PayloadResult`: when the estimator flagged the
mass changed and re-published it, and the tracking RMS before the payload, in the
transient and after the recovery); :func:`build_closed_loop_fmu` writes the 1-DOF loop
as one container FMU (``ClosedLoop1DOF.fmu``, input ``r``; outputs ``x``, ``f`` and the
estimates).
:func:`ensure_fmus` builds the FMUs of the loops when missing or stale.
"""
from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from ..assets import asset_path
from ..cosim.system import Result, System
from ..errors import InputError
from ..identification.engine import STATUSES
from ..models.chain import PAPER_DUFFING1, PAPER_DUFFING2, Duffing2
from .adaptive import controller_parameters
from .design import design, mismatched
from .settings import PARAMETERS

__all__ = ["SineReference", "Payload", "LoopCase", "LoopResult", "PayloadResult", "loop_cases", "with_payload",
           "ensure_fmus", "loop_system", "run_loop", "summary_lines", "PAYLOAD_SPAN", "PAYLOAD_PLANTS",
           "PAYLOAD_SHARE", "PAYLOAD_TIME", "PAYLOAD_PHASES", "FALLBACKS", "mark_fmus_current", "closed_loop_case",
           "build_closed_loop_fmu", "CLOSED_LOOP_OUTPUTS", "FMUS"]


@dataclass(frozen=True)
class SineReference:
    """Reference position ``offset + sum_i a_i sin(2 pi f_i t)``, vectorised.

    Parameters
    ----------
    offset : float
        Constant part.
    amplitudes, frequencies : tuple of float
        Amplitude and frequency [Hz] of each sine.
    """

    offset: float
    amplitudes: tuple[float, ...] = ()
    frequencies: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        if len(self.amplitudes) != len(self.frequencies):
            raise InputError(f"SineReference: {len(self.amplitudes)} amplitudes but "
                             f"{len(self.frequencies)} frequencies")

    def __call__(self, t: Any) -> Any:
        return self.derivative(t, 0)

    def derivative(self, t: Any, order: int) -> Any:
        """The `order`-th time derivative at `t` (order 0 is the value)."""
        if order not in (0, 1, 2):
            raise InputError(f"derivative order must be 0, 1 or 2, got {order!r}")
        t = np.asarray(t, dtype=float)
        value = np.full(t.shape, self.offset if order == 0 else 0.0)
        for a, f in zip(self.amplitudes, self.frequencies):
            w = 2.0 * np.pi * f
            phase = w * t + order * np.pi / 2.0   # d/dt sin(wt) = w sin(wt + pi/2)
            value = value + a * w ** order * np.sin(phase)
        return float(value) if value.ndim == 0 else value

    @property
    def peak(self) -> float:
        """An upper bound of ``|r(t)|``."""
        return abs(self.offset) + sum(abs(a) for a in self.amplitudes)


@dataclass(frozen=True)
class Payload:
    """A mass added to the plant during control: the plant FMU's input ``payload``.

    The payload moves with the mass from the communication point at `time` on (to 1 ns):
    position and velocity continue, the plant is ``(m + mass) x'' + ... = f`` after it.

    Parameters
    ----------
    mass : float
        Added mass [kg] (positive).
    time : float
        When it is added [s] (positive).
    """

    mass: float
    time: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.mass) and self.mass > 0.0):
            raise InputError(f"the payload's mass must be a positive number of kg, got {self.mass!r}")
        if not (math.isfinite(self.time) and self.time > 0.0):
            raise InputError(f"the payload's time must be a positive number of s, got {self.time!r}")

    def __call__(self, t: float) -> float:
        """The plant's input ``payload`` at `t` [kg]."""
        return self.mass if t >= self.time - 1e-9 else 0.0


@dataclass(frozen=True)
class LoopCase:
    """One closed loop: the FMUs, how they are wired, the truth and the scenario.

    Parameters
    ----------
    name : str
        Short name (file names, JSON keys).
    title : str
        Human-readable description.
    plant, estimator, controller : str
        FMU model identifiers (files ``<identifier>.fmu`` in the FMU folder).
    truth : dict
        True parameters in the estimator's names (``m, b, k, kp`` or the 2-DOF set).
    plant_parameters : dict
        Parameters set on the plant FMU (its own names, e.g. ``L, R, C, a``).
    estimator_parameters : dict
        Parameters set on the estimator FMU (e.g. optional prior sizes ``<name>_nominal``).
    positions : dict
        Estimator/controller position input -> plant output (``{"x": "q"}``).
    force : str
        Plant input driven by the controller's ``f``.
    estimator_force : str
        Estimator input that receives ``f``.
    reference : SineReference
        Reference of the tracked position.
    excitation_amplitude, force_limit : float
        Step amplitude of the identification phase and the controller's force limit.
    t_end, dt : float
        Duration and communication step [s].
    settle_after : float
        Tracking errors are compared from ``switch_time + settle_after`` on [s].
    mismatch : float
        Relative error of the baseline's nominal parameters.
    position_unit, force_unit : tuple
        Plot labels and scales, e.g. ``("mm", 1e3)``, ``("N", 1.0)``.
    controller_options : dict
        Controller settings (:func:`duffid.control.adaptive.controller_parameters`); by default
        ``reference_model="derivatives"``: the loop tracks ``r`` itself, fed with its exact
        derivatives.
    labels : dict
        Display names of the parameters (the circuit's ``m`` is ``L``, ...).
    payload : Payload, optional
        A mass added to ``m`` during control (the plant needs the input ``payload``, see
        :func:`with_payload`).
    """

    name: str
    title: str
    plant: str
    estimator: str
    controller: str
    truth: dict[str, float]
    plant_parameters: dict[str, float]
    estimator_parameters: dict[str, float]
    positions: dict[str, str]
    force: str
    estimator_force: str
    reference: SineReference
    excitation_amplitude: float
    force_limit: float
    t_end: float = 4.0
    dt: float = 1e-3
    settle_after: float = 1.0
    mismatch: float = 0.3
    position_unit: tuple[str, float] = ("mm", 1e3)
    force_unit: tuple[str, float] = ("N", 1.0)
    controller_options: dict[str, Any] = field(default_factory=lambda: {"reference_model": "derivatives"})
    labels: dict[str, str] = field(default_factory=dict)
    payload: Payload | None = None

    def true_values(self, name: str, t: Any) -> np.ndarray:
        """The true value of parameter `name` at the times `t` (``m`` grows by the payload)."""
        t = np.asarray(t, dtype=float)
        value = np.full(t.shape, float(self.truth[name]))
        if self.payload is not None and name == "m":
            value = value + np.vectorize(self.payload, otypes=[float])(t)
        return value

    @property
    def mechanical(self) -> bool:
        """Whether the plant is in the estimator's and controller's units (m, N)."""
        return self.force_unit[0] == "N"

    @property
    def tracked(self) -> str:
        """The plant output the controller tracks (the first position)."""
        return next(iter(self.positions.values()))


def loop_cases() -> dict[str, LoopCase]:
    """The loops of the main job: 1-DOF oscillator, the same with a payload (:func:`with_payload`
    with its defaults), 2-DOF chain, Duffing circuit."""
    one = dict(PAPER_DUFFING1)
    two = {name: PAPER_DUFFING2[name] for name in Duffing2().parameters}  # public order
    circuit = {"L": 0.1, "R": 2.0, "C": 1e-3, "a": 5e6}
    one_dof = LoopCase(
        name="oscillator1dof", title="Oscillator1DOF <-> DuffingEstimator1 <-> AdaptiveController1",
        plant="Oscillator1DOF", estimator="DuffingEstimator1", controller="AdaptiveController1",
        truth=one, plant_parameters=dict(one), estimator_parameters={},
        positions={"x": "x"}, force="f", estimator_force="f",
        # |x| <= 8 mm: well inside the softening spring's safe range (escape ~18.5 mm)
        reference=SineReference(4e-3, (3e-3, 1e-3), (1.0, 3.0)),
        excitation_amplitude=10.0, force_limit=30.0)
    return {
        "oscillator1dof": one_dof,
        "oscillator1dof_payload": with_payload(one_dof),
        "oscillator2dof": LoopCase(
            name="oscillator2dof", title="Oscillator2DOF <-> DuffingEstimator2 <-> AdaptiveController2",
            plant="Oscillator2DOF", estimator="DuffingEstimator2", controller="AdaptiveController2",
            truth=two, plant_parameters=dict(two),
            # the second cubic spring carries ~1e-6 of the force balance in this loop (it deflects
            # by a fraction of a millimetre): a prior size, an order of magnitude a user knows,
            # says how small is small enough to publish
            estimator_parameters={"kp2_nominal": 1e6},
            positions={"x1": "x1", "x2": "x2"}, force="f1", estimator_force="f1",
            reference=SineReference(3e-3, (2e-3, 1e-3), (1.0, 2.5)),
            # 8 N: x1 peaks at 12.7 mm during the step (10 N: 17 mm, close to the well's edge)
            excitation_amplitude=8.0, force_limit=40.0),
        "duffing_circuit": LoopCase(
            name="duffing_circuit", title="DuffingCircuit <-> DuffingEstimator1 <-> AdaptiveController1",
            plant="DuffingCircuit", estimator="DuffingEstimator1", controller="AdaptiveController1",
            truth={"m": circuit["L"], "b": circuit["R"], "k": 1.0 / circuit["C"], "kp": circuit["a"]},
            plant_parameters=circuit,
            # sizes of the trust test: orders of magnitude a user knows, not the truth
            estimator_parameters={"m_nominal": 0.1, "b_nominal": 1.0, "k_nominal": 1e3, "kp_nominal": 1e6},
            positions={"x": "q"}, force="u", estimator_force="f",
            reference=SineReference(5e-3, (4e-3, 1e-3), (2.0, 5.0)),
            excitation_amplitude=15.0, force_limit=60.0,
            position_unit=("mC", 1e3), force_unit=("V", 1.0),
            labels={"m": "L", "b": "R", "k": "1/C", "kp": "a"}),
    }


#: What the law may use while the estimates are withdrawn (the controller's ``fallback``).
FALLBACKS = next(p.choices for p in PARAMETERS if p.name == "fallback")
#: Plants that take a payload: the loop's plant -> the plant FMU with the input ``payload``.
PAYLOAD_PLANTS = {"Oscillator1DOF": "Oscillator1DOFPayload"}
#: A payload run lasts this long after the payload [s]: detection and re-identification
#: (about 1.3 s at the defaults), then ``settle_after`` and a second of recovered tracking.
PAYLOAD_SPAN = 3.5
#: The default payload: this share of ``m``, at this time [s] (after the switch and
#: ``settle_after``, with a second of tracking before it).
PAYLOAD_SHARE, PAYLOAD_TIME = 0.2, 2.5


def with_payload(case: LoopCase, mass: float | None = None, time: float | None = None,
                 fallback: str = "hold") -> LoopCase:
    """`case` with a payload added to its mass during control.

    The plant becomes its variant with the input ``payload`` (:data:`PAYLOAD_PLANTS`), the
    run lasts until :data:`PAYLOAD_SPAN` after the payload, and the controller follows the
    estimates (``freeze`` off): while the estimator has withdrawn them (the mass
    ``changed``, the others ``uncertain``) the law uses its `fallback`, and it takes the
    re-identified values once they are all published again.

    Parameters
    ----------
    case : LoopCase
        A loop without payload whose plant is in :data:`PAYLOAD_PLANTS`.
    mass : float, optional
        Added mass [kg] (default :data:`PAYLOAD_SHARE` of ``m``).
    time : float, optional
        When it is added [s] (default :data:`PAYLOAD_TIME`).
    fallback : {"hold", "nominal"}
        What the law uses meanwhile: the parameters it had (whose mass is the one before
        the payload), or the baseline's (``case.truth`` wrong by ``case.mismatch``). Hold
        is the default: the model it had is off in the mass only, the baseline's in every
        parameter (measured in docs/getting-started.md).
    """
    if fallback not in FALLBACKS:
        raise InputError(f"fallback must be one of {', '.join(FALLBACKS)}, got {fallback!r}")
    if case.payload is not None:
        raise InputError(f"{case.name} carries a payload already")
    if case.plant not in PAYLOAD_PLANTS:
        raise InputError(f"{case.name}: the plant {case.plant} takes no payload; plants that do: "
                         f"{', '.join(PAYLOAD_PLANTS)}")
    payload = Payload(PAYLOAD_SHARE * case.truth["m"] if mass is None else float(mass),
                      PAYLOAD_TIME if time is None else float(time))
    return replace(case, name=f"{case.name}_payload", plant=PAYLOAD_PLANTS[case.plant], payload=payload,
                   title=f"{PAYLOAD_PLANTS[case.plant]} (+{payload.mass:.4g} kg at {payload.time:g} s) <-> "
                         f"{case.estimator} <-> {case.controller}",
                   t_end=payload.time + PAYLOAD_SPAN,
                   controller_options={**case.controller_options, "freeze": False, "fallback": fallback,
                                       "nominal": mismatched(case.truth, case.mismatch)})


#: FMUs the loops need (model identifiers).
FMUS = ("Oscillator1DOF", *PAYLOAD_PLANTS.values(), "Oscillator2DOF", "DuffingCircuit", "DuffingEstimator1",
        "DuffingEstimator2", "AdaptiveController1", "AdaptiveController2")


def _sources_digest() -> str:
    """Hash of every source an FMU of :data:`FMUS` is built from."""
    package = Path(__file__).resolve().parents[1]  # duffid
    named = [(f"assets/{path.relative_to(folder).as_posix()}", path)
             for folder in (asset_path("fmus"), asset_path("modelica"))
             for path in folder.rglob("*") if path.suffix in (".mo", ".c", ".h")]
    named += [(path.relative_to(package).as_posix(), path)
              for path in [*(package / "modelica").glob("*.py"), *(package / "fmu").glob("*.py"),
                           package / "cbuild.py", package / "control" / "controller_fmu.py",
                           package / "control" / "adaptive.py"]]
    digest = hashlib.sha256()
    for name, path in sorted(named):
        digest.update(name.encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def _stamp(folder: Path) -> Path:
    return folder / ".duffid-loop-sources"


def mark_fmus_current(folder: str | Path) -> None:
    """Record that the FMUs of :data:`FMUS` in `folder` were built from the current sources."""
    _stamp(Path(folder)).write_text(_sources_digest() + "\n")


def ensure_fmus(folder: str | Path, *, rebuild: bool = False, log: Callable[[str], None] | None = None
                ) -> dict[str, Path]:
    """Build the FMUs of the loops into `folder` unless they are there and up to date.

    A stamp file records a hash of the Modelica, C and generator sources; FMUs built from
    other sources are rebuilt.

    Parameters
    ----------
    folder : path
        FMU folder (created).
    rebuild : bool
        Build even if the FMUs are up to date.
    log : callable, optional
        Receives one line per FMU built.

    Returns
    -------
    dict
        Model identifier -> FMU path.
    """
    from ..fmu.estimator import build_estimator_fmu
    from ..modelica.export import export_fmu, library_path
    from .controller_fmu import build_controller_fmu

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    paths = {name: folder / f"{name}.fmu" for name in FMUS}
    stamp = _stamp(folder)
    digest = _sources_digest()
    current = stamp.exists() and stamp.read_text().strip() == digest
    if not rebuild and current and all(p.exists() for p in paths.values()):
        return paths
    stamp.unlink(missing_ok=True)
    for name, path in paths.items():
        if name.startswith("DuffingEstimator"):
            build_estimator_fmu(f"duffing{name[-1]}", folder, 2)
        elif name.startswith("AdaptiveController"):
            build_controller_fmu(int(name[-1]), folder, 2)
        else:
            export_fmu(library_path(), f"Duffid.Examples.{name}", path)
        if log is not None:
            log(f"built {path}")
    stamp.write_text(digest + "\n")
    return paths


def _controller_parameters(case: LoopCase, **settings: Any) -> dict[str, Any]:
    return controller_parameters(design(case.dt), dofs=len(case.positions),
                                 excitation_amplitude=case.excitation_amplitude, force_limit=case.force_limit,
                                 **{**case.controller_options, **settings})


def loop_system(case: LoopCase, fmus: Mapping[str, Path], *, baseline: bool = False,
                switch_time: float | None = None) -> System:
    """The co-simulation system of one loop.

    Parameters
    ----------
    case : LoopCase
        The loop.
    fmus : mapping
        Model identifier -> FMU path (:func:`ensure_fmus`).
    baseline : bool
        False: plant, estimator and adaptive controller. True: plant and the controller in
        its fixed mode on parameters wrong by ``case.mismatch``, switching at `switch_time`
        (no estimator).
    switch_time : float, optional
        Switch time of the baseline [s] (required with ``baseline=True``).
    """
    system = System()
    system.add("plant", fmus[case.plant], parameters=case.plant_parameters)
    if baseline:
        if switch_time is None:
            raise InputError("the baseline needs the switch time of the adaptive run")
        params = _controller_parameters(case, mode="fixed", switch_time=float(switch_time),
                                        nominal=mismatched(case.truth, case.mismatch))
    else:
        params = _controller_parameters(case)
        system.add("estimator", fmus[case.estimator],
                   parameters={**case.estimator_parameters, "sample_period": case.dt})
    system.add("controller", fmus[case.controller], parameters=params)
    # the 1-DOF estimator and controller are declared in m and N; the circuit feeds C and V
    generic = {"check_units": case.mechanical}
    for port, output in case.positions.items():
        system.connect(f"plant.{output}", f"controller.{port}", **generic)
        if not baseline:
            system.connect(f"plant.{output}", f"estimator.{port}", **generic)
    system.connect("controller.f", f"plant.{case.force}", **generic)
    if not baseline:
        # the plant holds f over each step; f_sample is that staircase as a sample at t_k
        system.connect("controller.f_sample", f"estimator.{case.estimator_force}", **generic)
        for p in case.truth:
            system.connect(f"estimator.{p}_hat", f"controller.{p}_hat")
        system.connect("estimator.identified", "controller.identified")
    if case.payload is not None:
        system.set_input("plant.payload", case.payload)
    system.set_input("controller.r", case.reference)
    if params["reference_model"] == 1:  # track r itself: feed its derivatives
        system.set_input("controller.r_dot", lambda t: case.reference.derivative(t, 1))
        system.set_input("controller.r_ddot", lambda t: case.reference.derivative(t, 2))
    return system


#: The phases of a payload run whose tracking is compared (see :class:`PayloadResult`).
PAYLOAD_PHASES = ("before", "transient", "recovered")


@dataclass
class PayloadResult:
    """How the adaptive loop met its payload, against the baseline.

    Every time is a communication point of the adaptive run (NaN: it did not happen).

    Attributes
    ----------
    payload : Payload
        The payload.
    fallback : str
        What the law used while the estimates were withdrawn (``hold`` or ``nominal``).
    detected : float
        When the estimator first reported the mass ``changed`` [s].
    republished : float
        When it next published the mass [s].
    mass, mass_std_error : float
        The mass it published then and its standard error [kg].
    true_mass : float
        The plant's mass with the payload [kg].
    readapted : float
        When the controller used the estimates again (the estimator's ``identified``) [s].
    final_mass : float
        The mass published at the end [kg].
    intervals : dict
        Phase -> ``(start, end)`` [s]: ``before`` from ``switch_time + settle_after`` to the
        payload, ``transient`` from the payload to ``readapted``, ``recovered`` from
        ``readapted + settle_after`` to the end.
    tracking_rms : dict
        ``"adaptive"`` and ``"baseline"`` -> phase -> RMS of ``x - r`` (NaN for a phase
        without samples).
    """

    payload: Payload
    fallback: str
    detected: float
    republished: float
    mass: float
    mass_std_error: float
    true_mass: float
    readapted: float
    final_mass: float
    intervals: dict[str, tuple[float, float]]
    tracking_rms: dict[str, dict[str, float]]

    @property
    def detection_delay(self) -> float:
        """From the payload to the ``changed`` flag [s]."""
        return self.detected - self.payload.time

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (times in s, masses in kg)."""
        return {"mass": self.payload.mass, "time": self.payload.time, "fallback": self.fallback,
                "detected": self.detected,
                "detection_delay": self.detection_delay, "republished": self.republished,
                "republished_mass": self.mass, "republished_std_error": self.mass_std_error,
                "true_mass": self.true_mass,
                "readapted": self.readapted, "final_mass": self.final_mass,
                "intervals": {k: list(v) for k, v in self.intervals.items()}, "tracking_rms": self.tracking_rms}


@dataclass
class LoopResult:
    """Outcome of one loop: adaptive and baseline runs and their figures of merit.

    Attributes
    ----------
    case : LoopCase
        The loop.
    adaptive, baseline : Result
        The co-simulation results (every output on the communication grid).
    switch_time : float
        When the adaptive controller switched to control [s].
    identified : dict
        The estimates the law uses (those of the switch).
    final_estimates : dict
        The estimator's outputs at the end of the run.
    tracking_rms : dict
        ``{"adaptive": ..., "baseline": ...}``: RMS of ``x - r`` from
        ``switch_time + settle_after`` to the end, same interval in both runs.
    force_peak : dict
        Largest ``|f|`` of each run.
    saturated_samples : dict
        Communication points at which each run's command was limited.
    payload : PayloadResult or None
        With a payload: detection, re-identification and tracking by phase.
    """

    case: LoopCase
    adaptive: Result
    baseline: Result
    switch_time: float
    identified: dict[str, float]
    final_estimates: dict[str, float]
    tracking_rms: dict[str, float]
    force_peak: dict[str, float]
    saturated_samples: dict[str, int]
    payload: PayloadResult | None = None

    @property
    def errors_percent(self) -> dict[str, float]:
        """Relative error of each identified parameter [%]."""
        return {p: 100.0 * (v - self.case.truth[p]) / self.case.truth[p] for p, v in self.identified.items()}

    @property
    def improvement(self) -> float:
        """Baseline tracking RMS divided by the adaptive one."""
        return self.tracking_rms["baseline"] / self.tracking_rms["adaptive"]

    def tracking_error(self, run: str) -> tuple[np.ndarray, np.ndarray]:
        """Time and tracking error ``x - r`` of ``"adaptive"`` or ``"baseline"``."""
        result = self.adaptive if run == "adaptive" else self.baseline
        return result.time, result[f"plant.{self.case.tracked}"] - self.case.reference(result.time)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary."""
        return {"identified": self.identified, "truth": dict(self.case.truth),
                "errors_percent": self.errors_percent, "final_estimates": self.final_estimates,
                "tracking_rms": self.tracking_rms, "improvement": self.improvement,
                "switch_time": self.switch_time, "tracking_from": self.switch_time + self.case.settle_after,
                "force_peak": self.force_peak, "force_limit": self.case.force_limit,
                "saturated_samples": self.saturated_samples, "mismatch": self.case.mismatch,
                "t_end": self.case.t_end, "dt": self.case.dt,
                **({} if self.payload is None else {"payload": self.payload.to_dict()})}


def _rms_between(result: Result, case: LoopCase, t_from: float, t_to: float = math.inf) -> float:
    """RMS of the tracking error over the communication points of ``[t_from, t_to)``; NaN if none."""
    t = result.time
    mask = (t >= t_from - 1e-12) & (t < t_to - 1e-12)
    if not mask.any():
        return math.nan
    error = result[f"plant.{case.tracked}"][mask] - case.reference(t[mask])
    return float(np.sqrt(np.mean(error ** 2)))


def _rms_after(result: Result, case: LoopCase, t_from: float) -> float:
    rms = _rms_between(result, case, t_from)
    if math.isnan(rms):
        raise InputError(f"{case.name}: no samples after t = {t_from:g} s (t_end {case.t_end:g} s)")
    return rms


def _first(t: np.ndarray, mask: np.ndarray) -> float:
    """The first time where `mask` holds (NaN: never)."""
    hits = np.flatnonzero(mask)
    return float(t[hits[0]]) if hits.size else math.nan


def _payload_result(case: LoopCase, adaptive: Result, baseline: Result, switch: float) -> PayloadResult:
    """Detection, re-publication and tracking by phase of a run with ``case.payload``."""
    payload = case.payload
    assert payload is not None
    t = adaptive.time
    status, mass = adaptive["estimator.m_status"], adaptive["estimator.m_hat"]
    after = t >= payload.time - 1e-9
    detected = _first(t, after & (status == STATUSES.index("changed")))
    since = t >= detected  # all False when never detected
    republished = _first(t, since & (status == STATUSES.index("published")))
    readapted = _first(t, since & (adaptive["estimator.identified"] != 0))
    k = np.flatnonzero(t == republished)
    published = k.size > 0
    intervals = {"before": (switch + case.settle_after, payload.time),
                 "transient": (payload.time, readapted if math.isfinite(readapted) else case.t_end),
                 "recovered": (readapted + case.settle_after, case.t_end) if math.isfinite(readapted)
                 else (math.nan, math.nan)}
    rms = {name: {phase: _rms_between(run, case, *intervals[phase]) if math.isfinite(intervals[phase][0])
                  else math.nan for phase in PAYLOAD_PHASES}
           for name, run in (("adaptive", adaptive), ("baseline", baseline))}
    end = status[-1] == STATUSES.index("published")
    return PayloadResult(payload=payload, fallback=str(case.controller_options.get("fallback", "hold")),
                         detected=detected, republished=republished,
                         mass=float(mass[k[0]]) if published else math.nan,
                         mass_std_error=float(adaptive["estimator.m_std_error"][k[0]]) if published else math.nan,
                         true_mass=float(case.true_values("m", case.t_end)),
                         readapted=readapted, final_mass=float(mass[-1]) if end else math.nan,
                         intervals=intervals, tracking_rms=rms)


def run_loop(case: LoopCase, fmus: Mapping[str, Path], *, progress: bool = False) -> LoopResult:
    """Run one loop adaptively and with the mismatched baseline.

    Raises
    ------
    RuntimeError
        If the adaptive controller never switched (the estimator never identified the
        plant within ``case.t_end``).
    InputError
        If the case's payload comes before ``switch_time + settle_after`` (it must meet a
        settled control).
    """
    adaptive = loop_system(case, fmus).run(case.t_end, case.dt, progress=progress)
    switch = adaptive["controller.switch_time"][-1]
    if not math.isfinite(switch):
        raise RuntimeError(f"{case.name}: the controller never switched to control within "
                           f"{case.t_end:g} s (the estimator did not identify the plant)")
    if case.payload is not None and case.payload.time < switch + case.settle_after:
        raise InputError(f"{case.name}: the payload at {case.payload.time:g} s comes before the control settled "
                         f"(switch at {switch:.3f} s + {case.settle_after:g} s); add it later")
    baseline = loop_system(case, fmus, baseline=True, switch_time=switch).run(case.t_end, case.dt,
                                                                                 progress=progress)
    t_from = switch + case.settle_after
    first = next(iter(case.truth))
    at_switch = int(np.argmax(np.isfinite(adaptive[f"controller.{first}_used"])))  # freeze off: they follow later
    identified = {p: float(adaptive[f"controller.{p}_used"][at_switch]) for p in case.truth}
    final = {p: float(adaptive[f"estimator.{p}_hat"][-1]) for p in case.truth}
    runs = {"adaptive": adaptive, "baseline": baseline}
    return LoopResult(
        case=case, adaptive=adaptive, baseline=baseline, switch_time=float(switch),
        identified=identified, final_estimates=final,
        tracking_rms={name: _rms_after(r, case, t_from) for name, r in runs.items()},
        force_peak={name: float(np.max(np.abs(r["controller.f"]))) for name, r in runs.items()},
        saturated_samples={name: int(np.sum(r["controller.saturated"] != 0)) for name, r in runs.items()},
        payload=None if case.payload is None else _payload_result(case, adaptive, baseline, float(switch)))


#: Outputs of ``ClosedLoop1DOF.fmu`` -> the component variable they expose.
CLOSED_LOOP_OUTPUTS = {"x": "plant.x", "f": "controller.f", "m_hat": "estimator.m_hat",
                       "b_hat": "estimator.b_hat", "k_hat": "estimator.k_hat", "kp_hat": "estimator.kp_hat",
                       "identified": "estimator.identified", "phase": "controller.phase",
                       "x_ref": "controller.x_ref"}


def closed_loop_case() -> LoopCase:
    """The loop inside ``ClosedLoop1DOF.fmu``: the 1-DOF case with the reference filter.

    A block with only ``r`` connected must not need its derivatives, so the controller's
    ``reference_model`` is ``"filter"`` (the triple-pole model smooths ``r``, whatever its
    shape); set the container parameter ``controller.reference_model`` to 1 and feed
    ``r_dot`` and ``r_ddot`` to track ``r`` itself.
    """
    return replace(loop_cases()["oscillator1dof"], controller_options={"reference_model": "filter"})


def build_closed_loop_fmu(out_dir: str | Path, fmus: Mapping[str, Path] | None = None,
                          case: LoopCase | None = None) -> Path:
    """Write the 1-DOF loop as one container FMU ``ClosedLoop1DOF.fmu``.

    Inputs ``r`` (reference position [m]) and ``r_dot``, ``r_ddot`` (its derivatives,
    used only with ``controller.reference_model`` = 1); outputs
    :data:`CLOSED_LOOP_OUTPUTS`; parameters ``plant.*``, ``estimator.*`` and
    ``controller.*`` (every value set on a component); the container's Jacobi master
    steps at ``case.dt`` (1 ms).

    Parameters
    ----------
    out_dir : path
        Output folder.
    fmus : mapping, optional
        Component FMUs (default: :func:`ensure_fmus` in `out_dir`).
    case : LoopCase, optional
        Default: :func:`closed_loop_case`.
    """
    out_dir = Path(out_dir)
    case = case or closed_loop_case()
    if fmus is None:
        fmus = ensure_fmus(out_dir)
    system = loop_system(case, fmus)
    inputs = {name: [f"controller.{name}"] for name in ("r", "r_dot", "r_ddot")}
    return system.export_container(out_dir / "ClosedLoop1DOF.fmu", inputs=inputs,
                                   outputs=CLOSED_LOOP_OUTPUTS, step=case.dt)


def summary_lines(result: LoopResult) -> Sequence[str]:
    """Printable summary of one loop."""
    case = result.case
    lines = [f"== {case.name}: {case.title} ==",
             f"identification: {case.excitation_amplitude:g} {case.force_unit[0]} step until identified "
             f"and settled; switched to control at {result.switch_time:.3f} s",
             f"{'parameter':>10} {'truth':>13} {'law at switch':>13} {'err %':>8} {'estimate at end':>16} "
             f"{'err %':>8}"]
    for p, true in case.truth.items():
        final, end = result.final_estimates[p], float(case.true_values(p, case.t_end))
        lines.append(f"{case.labels.get(p, p):>10} {true:>13.6g} {result.identified[p]:>13.6g} "
                     f"{result.errors_percent[p]:>8.3f} {final:>16.6g} {100.0 * (final - end) / end:>8.3f}")
    unit, scale = case.position_unit
    lines.append(f"tracking RMS of {case.tracked} - r from {result.switch_time + case.settle_after:.3f} s "
                 f"to {case.t_end:g} s: adaptive {result.tracking_rms['adaptive'] * scale:.4g} {unit}, "
                 f"baseline ({case.mismatch:.0%} mismatch) {result.tracking_rms['baseline'] * scale:.4g} {unit}"
                 f" -> {result.improvement:.1f}x better")
    lines.append(f"force peak: adaptive {result.force_peak['adaptive']:.2f}, baseline "
                 f"{result.force_peak['baseline']:.2f} (limit {case.force_limit:g} {case.force_unit[0]}); "
                 f"limited samples: adaptive {result.saturated_samples['adaptive']}, "
                 f"baseline {result.saturated_samples['baseline']}")
    if result.payload is not None:
        lines += _payload_lines(result)
    return lines


#: What each fallback does, in the summary's words.
_FALLBACK_WORDS = {"hold": "held its parameters (fallback hold)",
                  "nominal": "used the baseline's parameters (fallback nominal)"}


def _at(time: float) -> str:
    return f"{time:.3f} s" if math.isfinite(time) else "never"


def _payload_lines(result: LoopResult) -> list[str]:
    """The payload's part of :func:`summary_lines`."""
    case, r = result.case, result.payload
    assert r is not None
    unit, scale = case.position_unit
    m = case.truth["m"]
    line = f"payload: +{r.payload.mass:.4g} kg ({r.payload.mass / m:.0%} of m) at {r.payload.time:g} s; "
    if math.isnan(r.detected):
        final = f"{r.final_mass:.6g} kg" if math.isfinite(r.final_mass) else "none"
        line += (f"m never flagged changed (the mass published at the end: {final}, the true {r.true_mass:.6g} kg); "
                 "the law followed the published estimates")
    else:
        line += f"m flagged changed at {_at(r.detected)} ({r.detection_delay:.3f} s later), "
        line += (f"re-published at {_at(r.republished)}: {r.mass:.6g} kg, standard error {r.mass_std_error:.2g} kg, "
                 f"{100.0 * (r.mass - r.true_mass) / r.true_mass:+.4f} % off the true {r.true_mass:.6g} kg"
                 if math.isfinite(r.republished) else "never re-published")
        line += f"; meanwhile the law {_FALLBACK_WORDS[r.fallback]}; it re-adapted at {_at(r.readapted)}"
    lines = [line]
    spans = {phase: f"{phase} {a:.2f}-{b:.2f} s" if math.isfinite(a) else f"{phase} -"
             for phase, (a, b) in r.intervals.items()}
    lines.append(f"tracking RMS of {case.tracked} - r [{unit}]   " + "".join(f"{spans[p]:>24}"
                                                                         for p in PAYLOAD_PHASES))
    for run, label in (("adaptive", "adaptive"), ("baseline", f"baseline ({case.mismatch:.0%} mismatch)")):
        lines.append(f"{label:<34}" + "".join(f"{r.tracking_rms[run][p] * scale:>24.4g}" for p in PAYLOAD_PHASES))
    return lines
