"""The online identifier as an FMI 2.0 co-simulation FMU written in Python (pythonfmu).

A fallback to the C FMUs: :func:`build_python_fmu` packs duffid's
:class:`~duffid.identification.engine.OnlineIdentifier` into ``DuffingEstimator1_python.fmu``
(model ``duffing1``) or ``DuffingEstimator2_python.fmu`` (``duffing2``).

Interface
---------
Inputs (Real)
    ``x``, ``f`` (1-DOF) or ``x1``, ``x2``, ``f1`` (2-DOF): displacements [m] and force [N].
Outputs (initial exact)
    ``m_hat``, ``b_hat``, ``k_hat``, ``kp_hat`` (1-DOF) or ``m1_hat``, ``b1_hat``,
    ``k1_hat``, ``kp1_hat``, ``b2_hat``, ``k2_hat``, ``kp2_hat``, ``m2_hat`` (2-DOF):
    the estimates (Real); ``identified`` (Boolean); ``condition``, ``uncertainty`` and
    ``window_length`` [s] (Real), the fields of :class:`~duffid.identification.engine.Estimate`;
    ``<name>_status`` (Integer) per parameter, the index of its status in
    :data:`~duffid.identification.engine.STATUSES` (as the C FMUs); ``outliers`` (Integer), the
    isolated displacement outliers excluded so far.
Parameters (tunable; read at the first step)
    ``method`` (String, "robust" or "paper"); ``window`` [s] (0 = "auto"),
    ``window_periods``, ``max_window`` [s], ``forgetting`` [s] (0 = none), ``rows``
    (String), ``n_rows`` (Integer, 0 = default), ``max_condition``, ``max_uncertainty``,
    ``min_time`` [s], ``settle`` [s] (robust); ``gamma``, ``quadrature`` (String),
    ``sign_in_numerator`` (Boolean) (paper); optional prior sizes ``<name>_nominal``
    of every parameter (0: none, the default: the trust test's scale comes from the data);
    ``sample_period`` [s].
    Defaults are identify()'s, so a record run through the FMU gives the CLI's answer.

From a measured velocity or acceleration (``motion="v"`` or ``"a"`` of
:func:`build_equation_fmu` and :func:`build_chain_fmu`, ``duffid build-estimator --motion``):
the inputs are ``v..`` [m/s] or ``a..`` [m/s2] instead of the displacements, the FMU runs
:class:`~duffid.identification.motion_online.OnlineMotionIdentifier` (the output-error fit on a
receding horizon), its parameters are that identifier's options
(:data:`~duffid.identification.motion_online.OPTIONS`: ``horizon``, ``max_horizon``,
``interval`` [s], 0 = auto, ``max_uncertainty``) and ``sample_period``; ``condition`` is NaN,
``outliers`` 0 and ``residual`` the latest fit's or check's output error over the signal's RMS.

Semantics
---------
Each ``doStep(t, h)`` consumes one sample: the inputs set for time ``t`` (the step's
start). ``h`` must equal the parameter ``sample_period`` [s] (relative difference up to
1e-9), the record's sampling period (its start value is the default experiment's step
size); a step of several periods is refused too, since the samples in between are not
known to the FMU. The identifier is created at the first step; a step of another size, a
changed parameter, an invalid parameter or a non-finite input is an error: the reason is
logged (logStatusError) and the step fails with fmi2Discard and the terminated status
set (see :meth:`EstimatorSlave.do_step`). To identify a record of ``n`` samples, set
``sample_period`` to its ``dt`` and simulate from ``t[0]`` to ``t[-1] + dt`` with
communication step ``dt`` and the inputs on the grid ``t0 + k dt``: after the last step
the outputs are the estimate after the last sample. Units are those of the C FMUs.

The FMU's state can be got and set (``canGetAndSetFMUstate``; not serialised): it holds every
variable's value and a copy of the identifier (:meth:`EstimatorSlave.get_state`).

NaN convention: an estimate that is not (yet) published is NaN, exactly as in
:class:`~duffid.identification.engine.Estimate`; ``identified`` tells when all are valid.
FMI 2.0 Reals are IEEE 754 doubles and fmpy passes NaN through unchanged; a master
that rejects NaN should gate on ``identified``. Start values are written as the XML
Schema's ``NaN`` and ``INF`` (pythonfmu's own ``nan`` is not a valid xs:double).

Requirements
------------
The FMU does not link libpython: it only runs inside a Python process (e.g. fmpy) in
which ``duffid`` (with numpy and scipy) is importable; pythonfmu's Python files travel
inside the FMU. A C host fails to load it (``undefined symbol: _Py_NoneStruct``); the C
estimator core (``fmus/estimator``, :mod:`duffid.identification.c_core`) is the base for FMUs that
run anywhere.
"""
from __future__ import annotations

import copy
import json
import math
import sys
import tempfile
from pathlib import Path
from typing import Any, Mapping, Sequence
from xml.etree.ElementTree import Element, SubElement

from ..errors import InputError
from ..identification.engine import STATUSES, OnlineIdentifier, status_codes
from ..identification.motion_online import OPTIONS as MOTION_OPTIONS
from ..identification.motion_online import OnlineMotionIdentifier
from ..identification.options import fmu_parameters, from_c, to_c
from .estimator_table import (
    DEFAULT_SAMPLE_PERIOD,
    ENABLE_DESCRIPTION,
    MODELS,
    RESET_DESCRIPTION,
    SAMPLE_PERIOD_DESCRIPTION,
    EstimatorInterface,
    builtin_interface,
    chain_interface,
    chain_parameter_unit,
    equation_interface,
    interface_from_spec,
    variable_units,
    with_motion,
)
from .fmi_xml import add_sampled_inputs, unit_definitions

__all__ = ["build_python_fmu", "build_equation_fmu", "build_chain_fmu", "chain_parameter_unit", "FMU_NAMES",
           "EstimatorSlave"]

#: Model name -> FMU model name (and file stem).
FMU_NAMES = {"duffing1": "DuffingEstimator1_python", "duffing2": "DuffingEstimator2_python"}
_DT_RTOL = 1e-9

_SCRIPT = '''\
"""{model_name} estimator FMU (generated by duffid.fmu.python_estimator.build_python_fmu)."""
{imports}from pythonfmu import DefaultExperiment, Fmi2Slave

from duffid.fmu.python_estimator import EstimatorSlave


class {class_name}(Fmi2Slave):
    """duffid's online identifier of the {model_name} model (FMI 2.0 co-simulation)."""

    author = "duffid"
    description = {description!r}
    default_experiment = DefaultExperiment(start_time=0.0, stop_time=1.0, step_size={sample_period!r})

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._estimator = EstimatorSlave(self, "{model_name}"{slave_arguments})

    def to_xml(self, model_options=dict()):
        return self._estimator.describe(super().to_xml(model_options))

    def exit_initialization_mode(self):
        self._estimator.exit_initialization_mode()

    def do_step(self, current_time, step_size):
        return self._estimator.do_step(current_time, step_size)

    def _get_fmu_state(self):
        return self._estimator.get_state()

    def _set_fmu_state(self, state):
        self._estimator.set_state(state)
'''


def _xs_double(value: float) -> str:
    if math.isnan(value):
        return "NaN"
    if math.isinf(value):
        return "INF" if value > 0 else "-INF"
    return f"{value:.17g}"


def _variable_types():
    """pythonfmu's classes, plus a Real that writes NaN and INF as XML Schema does."""
    from pythonfmu import Boolean, Integer, Real, String
    from pythonfmu.enums import Fmi2Causality, Fmi2Initial, Fmi2Variability

    class XsReal(Real):
        def to_xml(self) -> Element:
            node = super(Real, self).to_xml()  # the ScalarVariable attributes only
            attrib = {} if self.start is None else {"start": _xs_double(float(self.start))}
            SubElement(node, "Real", attrib)
            return node

    return XsReal, Integer, Boolean, String, Fmi2Causality, Fmi2Initial, Fmi2Variability


_FMI_TYPES = {"real": "Real", "count": "Integer", "choice": "String", "bool": "Boolean"}


def _option_parameters() -> dict[str, tuple[str, Any, str]]:
    """FMU parameter name -> (type, default, description) of the identifier options, from the
    schema (identify()'s defaults): reals and counts coded as the C FMUs code them (0: unset),
    choices by name."""
    out = {}
    for o in fmu_parameters():
        default = o.default if o.kind in ("choice", "bool") else to_c(o, o.default)
        out[o.name] = (_FMI_TYPES[o.kind], default, o.coded_description)
    return out


def _copied(ident: Any, attributes: Mapping[str, Any]) -> dict[str, Any]:
    """A deep copy of an identifier's ``attributes`` but its model (shared)."""
    return copy.deepcopy({k: v for k, v in attributes.items() if k != "model"}, memo={id(ident.model): ident.model})


class _StepError(ValueError):
    """A step the estimator refuses (already logged)."""


class EstimatorSlave:
    """The estimator behind a generated FMU class (kept outside it: pythonfmu's loader
    takes the class of the FMU script that subclasses ``Fmi2Slave`` directly).

    It registers the FMU's variables on ``slave`` (values live as attributes there) and
    runs one :meth:`OnlineIdentifier.update` per step.
    """

    def __init__(self, slave: Any, model_name: str, equation: dict[str, Any] | None = None,
                 chain: dict[str, Any] | None = None, motion: str = "x") -> None:
        Real, Integer, Boolean, String, causality, initial, variability = _variable_types()
        self.slave = slave
        self.model_name = model_name
        self.equation = equation
        self.chain = chain
        self.motion = motion
        if equation is None and chain is None and model_name not in MODELS:
            raise InputError(f"unknown model {model_name!r}; choose {', '.join(MODELS)}")
        self.interface = self._interface()
        model = self._model()
        self.names = list(model.parameters)
        self.fmu_name = model_name if equation is not None or chain is not None else FMU_NAMES[model_name]
        self.x_names = [name for name, _, _ in self.interface.x]
        self.f_names = [name for name, _, _ in self.interface.f]
        self.ident: OnlineIdentifier | OnlineMotionIdentifier | None = None
        self.used: dict[str, Any] = {}
        self.last_error: str | None = None
        types = {"Real": Real, "Integer": Integer, "Boolean": Boolean, "String": String}

        for name, _, text in self.interface.inputs:
            setattr(slave, name, 0.0)
            slave.register_variable(Real(name, causality=causality.input, variability=variability.continuous,
                                         description=f"{text} (one sample per doStep)"))
        for name, start, text in (("enable", True, ENABLE_DESCRIPTION), ("reset", False, RESET_DESCRIPTION)):
            setattr(slave, name, start)
            slave.register_variable(Boolean(name, causality=causality.input, variability=variability.discrete,
                                            description=text))
        self.outputs = [f"{name}_hat" for name in self.names]
        for name in self.outputs:
            setattr(slave, name, math.nan)
            slave.register_variable(Real(name, causality=causality.output, initial=initial.exact,
                                         description=f"estimate of {name[:-4]} (NaN unless published)"))
        slave.identified = False
        slave.register_variable(Boolean("identified", causality=causality.output, initial=initial.exact,
                                        variability=variability.discrete,
                                        description="every estimate is trustworthy"))
        fitted = motion != "x"  # the output-error fit's outputs say what they are
        for name, text, start in (("condition", "NaN: the output-error fit has no condition number" if fitted
                                   else "condition number of the equations", math.nan if fitted else math.inf),
                                  ("uncertainty", "largest relative standard error of the latest fit" if fitted
                                   else "largest relative standard error (robust)", math.nan),
                                  ("window_length", "the latest fit's horizon [s]" if fitted
                                   else "window length [s]", 0.0)):
            setattr(slave, name, start)
            slave.register_variable(Real(name, causality=causality.output, initial=initial.exact,
                                         description=text))
        for name in self.names:
            setattr(slave, f"{name}_status", 0)
            slave.register_variable(Integer(f"{name}_status", causality=causality.output, initial=initial.exact,
                                            variability=variability.discrete,
                                            description=f"status of {name}: {status_codes()}"))
        slave.outliers = 0
        slave.register_variable(Integer("outliers", causality=causality.output, initial=initial.exact,
                                        variability=variability.discrete,
                                        description="0: the output-error fit has no outlier test" if fitted
                                        else "isolated displacement outliers excluded so far"))
        for name in self.names:
            setattr(slave, f"{name}_std_error", math.nan)
            slave.register_variable(Real(f"{name}_std_error", causality=causality.output, initial=initial.exact,
                                         description=f"standard error of the estimate of {name} (NaN unless "
                                                     "published)"))
        slave.residual = math.nan
        slave.register_variable(Real("residual", causality=causality.output, initial=initial.exact,
                                     description="the latest fit's or check's output error relative to the "
                                                 "measured signal's RMS (it jumps when the plant changes)" if fitted
                                     else "the window's one-step prediction error relative to its force "
                                          "balance (it jumps when the plant changes)"))

        self.parameters: dict[str, Any] = {}
        if motion != "x":  # the options of the output-error fit (0: "auto")
            for name, (default, _, text) in MOTION_OPTIONS.items():
                value = 0.0 if default == "auto" else float(default)
                self.parameters[name] = value
                setattr(slave, name, value)
                slave.register_variable(Real(name, causality=causality.parameter, variability=variability.tunable,
                                             description=text.replace("(auto:", "(0: auto,")))
        else:
            self.parameters["method"] = "robust"
            slave.method = "robust"
            slave.register_variable(String("method", causality=causality.parameter,
                                           variability=variability.tunable, description="robust or paper"))
            for name, (kind, default, text) in _option_parameters().items():
                self.parameters[name] = default
                setattr(slave, name, default)
                slave.register_variable(types[kind](name, causality=causality.parameter,
                                                    variability=variability.tunable, description=text))
            for name in self.names:
                pname = f"{name}_nominal"
                self.parameters[pname] = 0.0
                setattr(slave, pname, 0.0)
                slave.register_variable(Real(pname, causality=causality.parameter, variability=variability.tunable,
                                             description=f"optional prior size of {name} for the trust test "
                                                         "(0: none, the scale comes from the data)"))
        self.parameters["sample_period"] = DEFAULT_SAMPLE_PERIOD
        slave.sample_period = DEFAULT_SAMPLE_PERIOD
        slave.register_variable(Real("sample_period", causality=causality.parameter, variability=variability.tunable,
                                     description=SAMPLE_PERIOD_DESCRIPTION))

    def _interface(self) -> EstimatorInterface:
        """The interface of the FMU (duffid.fmu.estimator_table: the C FMUs' table)."""
        if self.chain is not None:
            base = chain_interface(int(self.chain["n_dof"]), orders=self.chain["orders"],
                                   coulomb=bool(self.chain["coulomb"]), name=self.model_name)
        elif self.equation is not None:
            base = interface_from_spec({**self.equation, "kind": "equation", "name": self.model_name})
        else:
            base = builtin_interface(self.model_name)
        return with_motion(base, self.motion)

    def _model(self) -> Any:
        """A new instance of the model estimated (a built-in model, a chain or the FMU's equations)."""
        return self.interface.model()

    def _units(self) -> dict[str, str]:
        """Variable name -> unit: those of the estimator table (the C FMUs' units; for equations
        the signals' units and the parameters' derived ones), and the output-error fit's options'."""
        extra = {name: unit for name, (_, unit, _) in MOTION_OPTIONS.items()} if self.motion != "x" else {}
        return {**variable_units(self.interface), **extra}

    def describe(self, root: Element) -> Element:
        """Complete pythonfmu's modelDescription ``root``: the units of the C FMUs' table
        (:func:`~duffid.fmu.estimator_table.estimator_variables`; for equations, their
        signals' and parameters' units) on the variables of the same name, and their
        ``UnitDefinitions``; the annotation that its inputs are samples of one instant
        (:data:`~duffid.fmu.fmi_xml.SAMPLED_INPUTS`)."""
        units = self._units()
        used = []
        for sv in root.iter("ScalarVariable"):
            real = sv.find("Real")
            if real is not None and sv.get("name") in units:
                real.set("unit", units[sv.get("name")])
                used.append(units[sv.get("name")])
        holder = Element("holder")
        unit_definitions(holder, used)
        after = list(root).index(root.find("CoSimulation")) + 1
        for k, element in enumerate(holder):
            root.insert(after + k, element)
        add_sampled_inputs(root)
        return root

    # ------------------------------------------------------------------ FMI
    def exit_initialization_mode(self) -> None:
        """Nothing to do: the identifier needs the step size, known at the first step."""

    def get_state(self) -> dict[str, Any]:
        """The FMU's state (fmi2GetFMUstate): every variable's value and a copy of everything
        of the identifier that changes with the samples (its model is shared)."""
        values = {v.name: getattr(self.slave, v.name) for v in self.slave.vars.values()}
        return {"values": values, "ident": None if self.ident is None else _copied(self.ident, vars(self.ident)),
                "used": dict(self.used), "last_error": self.last_error}

    def set_state(self, state: dict[str, Any]) -> None:
        """Return to a :meth:`get_state` (fmi2SetFMUstate; the state stays usable)."""
        for name, value in state["values"].items():
            setattr(self.slave, name, value)
        if state["ident"] is None:
            self.ident = None
        else:
            if self.ident is None:
                self._create(float(state["values"]["sample_period"]))
            assert self.ident is not None
            vars(self.ident).update(_copied(self.ident, state["ident"]))
        self.used = dict(state["used"])
        self.last_error = state["last_error"]

    def _log(self, message: str) -> None:
        """Log an error (logStatusError) and also print it on stderr: pythonfmu 0.7 passes
        messages to the host's logger only with debug logging on, and a host such as
        ``fmpy simulate`` would otherwise end the run without saying why."""
        try:
            from pythonfmu.enums import Fmi2Status
            self.slave.log(message, Fmi2Status.error, "logStatusError")
        except Exception:  # pragma: no cover - logging must not hide the error
            pass
        if self.last_error is None:
            print(f"{self.fmu_name}: error: {message}", file=sys.stderr)
        self.last_error = message

    def _fail(self, message: str) -> None:
        self._log(message)
        raise _StepError(message)

    def _current_parameters(self) -> dict[str, Any]:
        return {name: getattr(self.slave, name) for name in self.parameters}

    def _options(self, values: dict[str, Any]) -> tuple[str, dict[str, Any]]:
        method = str(values["method"])
        if method not in ("robust", "paper"):
            self._fail(f"parameter method must be 'robust' or 'paper', got {method!r}")
        options: dict[str, Any] = {}
        for o in fmu_parameters():
            if method not in o.methods:
                continue
            value = values[o.name]
            try:
                options[o.name] = str(value) if o.kind == "choice" else from_c(o, value)
            except InputError as exc:
                self._fail(str(exc))
        return method, options

    def _create(self, period: float) -> None:
        values = self._current_parameters()
        if self.motion != "x":
            options = {name: ("auto" if values[name] == 0 and MOTION_OPTIONS[name][0] == "auto" else
                              float(values[name])) for name in MOTION_OPTIONS}
            try:
                self.ident = OnlineMotionIdentifier(self._model(), period, self.motion, **options)
            except InputError as exc:
                self._fail(f"{self.model_name} estimator: {exc}")
            self.used = values
            return
        method, options = self._options(values)
        prior = {name: float(values[f"{name}_nominal"]) for name in self.names if values[f"{name}_nominal"] != 0}
        if prior and method == "robust":
            options["nominal"] = prior
        try:
            self.ident = OnlineIdentifier(self._model(), period, method, **options)
        except (TypeError, ValueError) as exc:
            self._fail(f"{self.model_name} estimator: {exc}")
        self.used = values

    def do_step(self, current_time: float, step_size: float) -> bool:
        """Consume the inputs (values at ``current_time``) as one sample.

        A changed step size or parameter, an invalid parameter or a non-finite input is
        logged (category logStatusError) and the step fails: False, which pythonfmu
        reports as fmi2Discard with the terminated status set, so a master ends the
        simulation at the last good step (fmpy does so quietly: pass it a logger to see
        the reason). Nothing is raised: pythonfmu 0.7.0 turns a Python exception into
        fmi2Fatal on a path that leaves the host interpreter corrupted (later crashes
        in the garbage collector).
        """
        try:
            self._step(current_time, step_size)
        except Exception as exc:  # noqa: BLE001 - never let an exception reach pythonfmu
            if not isinstance(exc, _StepError):
                self._log(f"{self.model_name} estimator: {type(exc).__name__}: {exc}")
            return False
        return True

    def _step(self, current_time: float, step_size: float) -> None:
        if self.last_error is not None:
            raise _StepError(self.last_error)  # terminated: every later step fails too
        period = float(self.slave.sample_period)
        if not (math.isfinite(period) and period > 0):
            self._fail(f"parameter sample_period must be positive, got {period!r}")
        if not abs(step_size - period) <= _DT_RTOL * period:
            ratio = step_size / period
            several = ratio > 1.5 and abs(ratio - round(ratio)) <= _DT_RTOL * ratio
            self._fail(f"communicationStepSize {step_size!r} at t = {current_time!r} differs from the parameter "
                       f"sample_period {period!r}: each doStep consumes one sample; set sample_period to the "
                       "record's sampling period and step by it" +
                       (" (a step of several periods is refused: the samples in between are not known)"
                        if several else ""))
        if self.ident is None:
            self._create(period)
        else:
            if self._current_parameters() != self.used:
                changed = sorted(k for k, v in self._current_parameters().items() if self.used[k] != v)
                self._fail(f"parameters {changed} changed after the first step (they are read once)")
        assert self.ident is not None
        slave = self.slave
        if slave.reset:  # a new identification starts with this sample
            self.ident.reset()
            for name in self.names:
                setattr(slave, f"{name}_hat", math.nan)
                setattr(slave, f"{name}_status", 0)
                setattr(slave, f"{name}_std_error", math.nan)
            slave.identified = False
            slave.residual = math.nan
        if not slave.enable:  # skipped: the outputs hold, the window restarts after it
            self.ident.hold()
            return
        x = [float(getattr(slave, name)) for name in self.x_names]
        f = [float(getattr(slave, name)) for name in self.f_names]
        try:
            estimate = self.ident.update(x, f)
        except ValueError as exc:
            self._fail(str(exc))
        for name, value in estimate.parameters.items():
            setattr(slave, f"{name}_hat", float(value))
        slave.identified = bool(estimate.identified)
        slave.condition = float(estimate.condition)
        slave.uncertainty = float(estimate.uncertainty)
        slave.window_length = float(estimate.window)
        for name, status in (estimate.status or {}).items():
            setattr(slave, f"{name}_status", STATUSES.index(status))
        slave.outliers = int(estimate.outliers)
        for name, error in (estimate.std_errors or {}).items():
            setattr(slave, f"{name}_std_error", float(error))
        slave.residual = float(estimate.residual)


def build_python_fmu(model_name: str, out_dir: str | Path, *, needs_execution_tool: bool = True) -> Path:
    """Build ``DuffingEstimator1_python.fmu`` or ``DuffingEstimator2_python.fmu``.

    Parameters
    ----------
    model_name : {"duffing1", "duffing2"}
        Model of the estimator.
    out_dir : path
        Folder for the FMU (created if needed).
    needs_execution_tool : bool
        Value of the ``needsExecutionTool`` capability flag (the FMU needs a Python
        host); False for tools that refuse such FMUs.

    Returns
    -------
    Path
        The FMU file.

    Notes
    -----
    Uses pythonfmu's builder API (no network). The FMU runs only in a Python host with
    duffid installed, see the module documentation.
    """
    if model_name not in FMU_NAMES:
        raise InputError(f"unknown model {model_name!r}; choose {', '.join(FMU_NAMES)}")
    class_name = FMU_NAMES[model_name]
    script = _SCRIPT.format(model_name=model_name, class_name=class_name, sample_period=DEFAULT_SAMPLE_PERIOD,
                            imports="", slave_arguments="",
                            description=f"Online algebraic identification of {model_name} (duffid OnlineIdentifier)")
    return _build(script, class_name, out_dir, needs_execution_tool)


def build_equation_fmu(equation: str | Sequence[str], out_dir: str | Path, *, name: str = "EquationEstimator",
                       columns: Sequence[str] = ("t", "f", "x"), units: Mapping[str, str] | None = None,
                       motion: str = "x", needs_execution_tool: bool = True) -> Path:
    """Build ``<name>.fmu``: duffid's online identifier of the user's own equations (pythonfmu,
    FMI 2.0 co-simulation, the interface of the module documentation).

    Parameters
    ----------
    equation : str or sequence of str
        The equations, as for :func:`duffid.identification.equation.identify_equation`.
    out_dir : path
        Folder for the FMU (created if needed).
    name : str
        Model name, class and file stem (a Python identifier).
    columns : sequence of str
        The signals' names as record columns (``t, f, x`` or ``t, f1.., x1..``): the FMU's
        inputs are the displacements and forces among them.
    units : mapping, optional
        Unit strings of every displacement and force (``{"x": "m", "f": "N"}``), and of
        parameters whose unit the equations do not determine; the parameters' units follow
        (:func:`duffid.models.units.parameter_units`). None: no units.
    motion : {"x", "v", "a"}
        What the motion inputs measure: the displacements (the online algebraic identifier),
        or their velocities or accelerations (inputs ``v..``/``a..``,
        :class:`~duffid.identification.motion_online.OnlineMotionIdentifier`, its options as
        parameters).
    needs_execution_tool : bool
        See :func:`build_python_fmu`.

    Returns
    -------
    Path
        The FMU file.

    Raises
    ------
    EquationError, InputError
        An equation that cannot be identified (naming the term), a bad name or unit.
    """
    interface = with_motion(equation_interface(equation, columns, units=units, name=name), motion)
    spec = {k: v for k, v in interface.spec.items() if k not in ("kind", "name", "motion")}
    script = _SCRIPT.format(model_name=name, class_name=name, sample_period=DEFAULT_SAMPLE_PERIOD,
                            imports="import json\n",
                            slave_arguments=f", equation=json.loads({json.dumps(spec)!r}), motion={motion!r}",
                            description=interface.description + f" (duffid {_identifier_class(motion)})")
    return _build(script, name, out_dir, needs_execution_tool)


def _identifier_class(motion: str) -> str:
    return "OnlineIdentifier" if motion == "x" else "OnlineMotionIdentifier"


def build_chain_fmu(n_dof: int, out_dir: str | Path, *, orders: Sequence[int] = (1, 3), coulomb: bool = False,
                    name: str | None = None, motion: str = "x", needs_execution_tool: bool = True) -> Path:
    """Build ``ChainEstimator<n>.fmu``: the online identifier of a chain of ``n_dof`` masses
    from a wall (:func:`duffid.models.registry.model_from_name` ``"chain"``: springs of the
    stiffness ``orders`` and optionally Coulomb friction per mass, force on mass 1), pythonfmu,
    FMI 2.0 co-simulation, the interface of the module documentation: inputs ``x1 .. x<n>``
    [m] and ``f1`` [N]; outputs ``<param>_hat`` (``m<i>`` kg, ``b<i>`` N.s/m, ``k<i>_<j>``
    N/m^j, ``fc<i>`` N) with statuses. ``motion`` as for :func:`build_equation_fmu` (inputs
    ``a1 ..`` [m/s2] or ``v1 ..`` [m/s]).

    Raises
    ------
    InputError
        A chain of fewer than 1 mass, no stiffness order, or a name that is not an identifier.
    """
    interface = with_motion(chain_interface(n_dof, orders=orders, coulomb=coulomb, name=name), motion)
    spec = {k: v for k, v in interface.spec.items() if k not in ("kind", "name", "motion")}
    script = _SCRIPT.format(model_name=interface.identifier, class_name=interface.identifier,
                            sample_period=DEFAULT_SAMPLE_PERIOD, imports="import json\n",
                            slave_arguments=f", chain=json.loads({json.dumps(spec)!r}), motion={motion!r}",
                            description=interface.description + f" (duffid {_identifier_class(motion)})")
    name = interface.identifier
    return _build(script, name, out_dir, needs_execution_tool)


def _build(script_text: str, class_name: str, out_dir: str | Path, needs_execution_tool: bool) -> Path:
    """pythonfmu's builder on a generated script (no network); the FMU file (it declares
    canGetAndSetFMUstate: :meth:`EstimatorSlave.get_state`)."""
    from pythonfmu.builder import FmuBuilder

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="duffid_fmu_") as tmp:
        script = Path(tmp) / f"{class_name}.py"
        script.write_text(script_text)
        try:
            fmu = FmuBuilder.build_FMU(script, dest=out_dir, needsExecutionTool=needs_execution_tool,
                                       canHandleVariableCommunicationStepSize=False, canGetAndSetFMUstate=True)
        finally:
            # the builder imports the script from the temporary folder: forget both, so
            # that a host in this process imports the copy inside the FMU
            while tmp in sys.path:
                sys.path.remove(tmp)
            sys.modules.pop(class_name, None)
    return Path(fmu)
