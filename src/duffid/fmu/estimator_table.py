"""The interface of the estimator FMUs, C and pythonfmu: names, inputs, units, types,
parameters and their start values (one table, from which every estimator FMU is described).

A model's part of the interface is an :class:`EstimatorInterface`: the built-in models
(:func:`builtin_interface`: ``duffing1``, ``duffing2``, ``circuit``), a chain
(:func:`chain_interface`) or the user's own equations (:func:`equation_interface`, units
from :func:`duffid.models.units.parameter_units`). :func:`estimator_variables` turns any of
them into the variable table.

Value references follow the order of :func:`estimator_variables` (the C model
``fmus/estimator/fmu_model_estimator.c`` checks the count): time, the displacements and the
forces (inputs), the estimates ``<name>_hat``, ``identified``, ``condition``, ``uncertainty``,
``window_length``, ``<name>_status``, ``outliers`` (outputs), then the parameters: ``method``,
the options of :mod:`duffid.identification.options`, ``<name>_nominal`` and
``sample_period``.
"""
from __future__ import annotations

import keyword
import re
from dataclasses import dataclass, field, replace
from typing import Any, Mapping, Sequence

from ..errors import InputError
from ..identification.engine import status_codes
from ..identification.motion import MOTIONS
from ..identification.options import ONLINE_METHODS, fmu_parameters
from ..models.registry import GENERATED_MODEL_CODE, REGISTRY
from .variables import FmuVariable

__all__ = ["C_FMU_NAMES", "MODELS", "MODEL_CODES", "GENERATED_MODEL_CODE", "INPUTS", "PARAMETER_UNITS",
           "parameter_unit", "chain_parameter_unit", "OPTIONS", "DEFAULT_SAMPLE_PERIOD", "SAMPLE_PERIOD_DESCRIPTION",
           "ENABLE_DESCRIPTION", "RESET_DESCRIPTION",
           "TYPES", "EstimatorInterface", "builtin_interface", "equation_interface", "chain_interface",
           "interface_from_spec", "variable_types", "variable_units", "estimator_variables", "MOTION_INPUTS",
           "with_motion"]

# The named models with a C estimator FMU (duffid.models.registry), as this module's tables:
_NAMED = {name: e for name, e in REGISTRY.items() if e.fmu_name is not None}
#: Model name -> model identifier of the C FMUs (FMI 3 files get a ``_fmi3`` suffix).
C_FMU_NAMES = {name: e.fmu_name for name, e in _NAMED.items()}
#: Model name -> the model (a :class:`~duffid.models.chain.Chain`) estimated.
MODELS = {name: e.cls for name, e in _NAMED.items()}
#: Model name -> the C core's model code (the circuit is the Duffing1 equation with L = m,
#: R = b, 1/C = k, a = kp).
MODEL_CODES = {name: e.c_code for name, e in _NAMED.items()}
#: Model name -> the inputs (name, unit, description): displacements, then forces.
INPUTS = {name: tuple((s.name, s.unit, s.description) for s in e.signals) for name, e in _NAMED.items()}
#: Unit of a parameter by its name without the index.
PARAMETER_UNITS = {"m": "kg", "b": "N.s/m", "k": "N/m", "kp": "N/m3", "L": "H", "R": "Ohm", "C": "F", "a": "V/C3"}
#: Parameters in value-reference order (name, unit, description): the method, then the
#: options of the schema (duffid.identification.options), which also generates the C table.
OPTIONS = (("method", None, "identification method: " + ", ".join(f"{i} {m}" for i, m in enumerate(ONLINE_METHODS))),
           *((o.name, o.unit, o.coded_description) for o in fmu_parameters()))
#: Start value of the parameter ``sample_period`` [s] and the default experiment's step size.
DEFAULT_SAMPLE_PERIOD = 1e-3
SAMPLE_PERIOD_DESCRIPTION = ("sampling period of the record; each doStep consumes one sample, so its "
                             "communicationStepSize must equal this")
#: Variables that are not Float64 (and every ``<name>_status``: Integer).
#: The estimator FMUs' Boolean input ``enable`` (:meth:`~duffid.identification.engine.OnlineIdentifier.hold`).
ENABLE_DESCRIPTION = ("false: the plant is not excited or a sensor saturated: the sample is skipped and the estimates "
                      "hold; when true again the window restarts, the accumulated estimate kept")
#: ... and ``reset``.
RESET_DESCRIPTION = "true: forget every sample before this step's (a new identification starts with it)"
TYPES = {"method": "Integer", "identified": "Boolean", "enable": "Boolean", "reset": "Boolean",
         **{o.name: "Boolean" if o.kind == "bool" else "Integer" for o in fmu_parameters() if o.c_kind == "CODE"}}




@dataclass(frozen=True, eq=False)
class EstimatorInterface:
    """The model's part of an estimator FMU's interface.

    Attributes
    ----------
    kind : {"builtin", "chain", "equation"}
        Where the model comes from.
    identifier : str
        Model identifier (and file stem) of the FMU.
    x, f : tuple of (name, unit or None, description)
        The displacement and force inputs, in the order the estimator takes them.
    parameters : tuple of str
        Public parameter names, in output order.
    parameter_units : mapping
        Parameter -> unit (a parameter without an entry has none).
    reciprocal : tuple of str
        Parameters output as the reciprocal of the C core's (the circuit's C).
    description : str
        One line for modelDescription.xml.
    spec : mapping
        JSON-able data that rebuilds the interface (:func:`interface_from_spec`).
    """

    kind: str
    identifier: str
    x: tuple[tuple[str, str | None, str], ...]
    f: tuple[tuple[str, str | None, str], ...]
    parameters: tuple[str, ...]
    parameter_units: Mapping[str, str]
    description: str
    spec: Mapping[str, Any] = field(repr=False)
    reciprocal: tuple[str, ...] = ()

    @property
    def inputs(self) -> tuple[tuple[str, str | None, str], ...]:
        """Displacements, then forces."""
        return self.x + self.f

    @property
    def model_code(self) -> int:
        """The C core's model code (DUFFID_DUFFING1/2 for the built-in models, else
        :data:`GENERATED_MODEL_CODE`)."""
        return MODEL_CODES[self.spec["model"]] if self.kind == "builtin" else GENERATED_MODEL_CODE

    def model(self) -> Any:
        """A new instance of the model estimated."""
        if self.kind == "builtin":
            return MODELS[self.spec["model"]]()
        if self.kind == "chain":
            from ..models.registry import model_from_name

            return model_from_name("chain", int(self.spec["n_dof"]), orders=self.spec["orders"],
                                   coulomb=bool(self.spec["coulomb"]))
        from ..models.equation_model import EquationModel

        return EquationModel(self.spec["equations"], self.spec["columns"])


#: What an estimator FMU's motion inputs measure: symbol -> (word, unit suffix); the inputs of
#: a velocity or acceleration FMU are named with its symbol (``a``, ``a1`` for ``x``, ``x1``)
#: and their units are the displacement's per second (squared).
MOTION_INPUTS = {"x": ("displacement", ""), **{m: (word, {"v": "/s", "a": "/s2"}[m]) for m, word in MOTIONS.items()}}


def with_motion(interface: EstimatorInterface, motion: str) -> EstimatorInterface:
    """The interface whose motion inputs measure ``motion`` (:data:`MOTION_INPUTS`) instead of
    the displacements: renamed (``x1`` -> ``a1``), their units per second (squared); the
    spec records it."""
    if motion not in MOTION_INPUTS:
        raise InputError(f"motion must be one of {', '.join(MOTION_INPUTS)}, got {motion!r}")
    if motion == "x":
        return interface
    word, suffix = MOTION_INPUTS[motion]
    renamed = []
    for name, unit, text in interface.x:
        if not name.startswith("x"):
            raise InputError(f"{interface.identifier}: the displacement {name!r} is not named x...; a "
                             f"{word} input is named after it ({motion}...): name the displacements x, x1, ...")
        renamed.append((motion + name[1:], None if unit is None else unit + suffix,
                        text.replace("displacement of", f"{word} of") if "displacement of" in text
                        else f"{word} of the {text}"))
    return replace(interface, x=tuple(renamed), spec={**interface.spec, "motion": motion},
                   description=interface.description.replace("online algebraic identification",
                                                             f"online output-error identification from {word}"))


def _check_identifier(name: str) -> None:
    if not name.isidentifier() or keyword.iskeyword(name):
        raise InputError(f"--name {name!r} must be a Python identifier (letters, digits, _; not starting with a digit)")


def builtin_interface(model_name: str) -> EstimatorInterface:
    """The interface of a built-in estimator FMU (a key of :data:`C_FMU_NAMES`)."""
    if model_name not in C_FMU_NAMES:
        raise InputError(f"unknown model {model_name!r}; choose {', '.join(C_FMU_NAMES)}")
    model = MODELS[model_name]()
    inputs = INPUTS[model_name]
    return EstimatorInterface("builtin", C_FMU_NAMES[model_name], inputs[:model.n_dof], inputs[model.n_dof:],
                              tuple(model.parameters), {p: parameter_unit(p) for p in model.parameters},
                              f"duffid online algebraic identification of {type(model).__name__}",
                              {"kind": "builtin", "model": model_name}, model.reciprocal)


def chain_parameter_unit(name: str) -> str:
    """The unit of a chain parameter: ``m<i>`` kg, ``b<i>`` N.s/m, ``k<i>_<j>`` N/m^j,
    ``fc<i>`` and ``c<i>`` N."""
    match = re.fullmatch(r"k\d+_(\d+)", name)
    if match:
        power = int(match.group(1))
        return "N/m" if power == 1 else f"N/m{power}"
    units = {"m": "kg", "b": "N.s/m", "fc": "N", "c": "N"}
    return units[name.rstrip("0123456789")]


def chain_interface(n_dof: int, *, orders: Sequence[int] = (1, 3), coulomb: bool = False,
                    name: str | None = None) -> EstimatorInterface:
    """The interface of the estimator of a chain of ``n_dof`` masses from a wall
    (:func:`duffid.models.registry.model_from_name` ``"chain"``: springs of the stiffness
    ``orders``, optionally Coulomb friction per mass, force on mass 1): inputs ``x1 .. x<n>``
    [m] and ``f1`` [N]; parameters in kg, N.s/m, N/m^j and N (:func:`chain_parameter_unit`).

    Raises
    ------
    InputError
        A chain of fewer than 1 mass, no positive stiffness order, or a name that is not an identifier.
    """
    from ..models.registry import model_from_name

    try:
        orders = sorted({int(o) for o in orders})
    except (TypeError, ValueError):
        raise InputError(f"--orders must be integers, got {list(orders)!r}") from None
    if not orders or min(orders) < 1:
        raise InputError(f"--orders must be positive stiffness orders, got {orders}")
    model = model_from_name("chain", int(n_dof), orders=orders, coulomb=coulomb)  # checks n_dof
    name = name or f"ChainEstimator{int(n_dof)}"
    _check_identifier(name)
    spec = {"kind": "chain", "name": name, "n_dof": int(n_dof), "orders": orders, "coulomb": bool(coulomb)}
    return EstimatorInterface(
        "chain", name, tuple((f"x{i + 1}", "m", f"displacement of mass {i + 1}") for i in range(model.n_dof)),
        (("f1", "N", "force on mass 1"),), tuple(model.parameters),
        {p: chain_parameter_unit(p) for p in model.parameters},
        f"duffid online algebraic identification of a chain of {int(n_dof)} masses (stiffness orders {orders}"
        f"{', Coulomb friction' if coulomb else ''})", spec)


def equation_interface(equation: str | Sequence[str], columns: Sequence[str] = ("t", "f", "x"), *,
                       units: Mapping[str, str] | None = None, name: str = "EquationEstimator") -> EstimatorInterface:
    """The interface of the estimator of the user's own equations.

    Parameters
    ----------
    equation : str or sequence of str
        The equations, as for :func:`duffid.identification.equation.identify_equation`.
    columns : sequence of str
        The signals' names as record columns (``t, f, x`` or ``t, f1.., x1..``): the FMU's
        inputs are the displacements and forces among them.
    units : mapping, optional
        Unit strings of every displacement and force (``{"x": "m", "f": "N"}``), and of
        parameters whose unit the equations do not determine; the parameters' units follow
        (:func:`duffid.models.units.parameter_units`). None: no units.
    name : str
        Model identifier and file stem (a Python identifier).

    Raises
    ------
    EquationError, InputError
        An equation that cannot be identified (naming the term), a bad name or unit.
    """
    from ..models.equation_model import EquationModel
    from ..models.units import parameter_units

    _check_identifier(name)
    model = EquationModel(equation, columns)
    sig = model.regressor.signals
    signal_units: dict[str, str] = {}
    params: dict[str, str] = {}
    if units:
        signals = set(sig.x_names) | set(sig.f_names)
        signal_units = {k: v for k, v in units.items() if k in signals}
        params = parameter_units(model, signal_units, {k: v for k, v in units.items() if k not in signals})
    spec = {"kind": "equation", "name": name, "equations": list(model.texts), "columns": list(columns),
            "units": signal_units, "parameter_units": params}
    return interface_from_spec(spec)


def interface_from_spec(spec: Mapping[str, Any]) -> EstimatorInterface:
    """The interface that ``spec`` (:attr:`EstimatorInterface.spec`) describes; an equation's
    units are taken as they are (they were derived when the spec was made)."""
    kind = spec.get("kind")
    motion = spec.get("motion", "x")
    if kind == "builtin":
        return with_motion(builtin_interface(spec["model"]), motion)
    if kind == "chain":
        return with_motion(chain_interface(spec["n_dof"], orders=spec["orders"], coulomb=spec["coulomb"],
                                           name=spec["name"]), motion)
    if kind != "equation":
        raise InputError(f"unknown estimator interface kind {kind!r}; choose builtin, chain or equation")
    from ..models.equation_model import EquationModel

    model = EquationModel(spec["equations"], spec["columns"])
    sig = model.regressor.signals
    units = dict(spec.get("units") or {})
    return with_motion(EstimatorInterface(
        "equation", spec["name"], tuple((n, units.get(n), f"displacement {n}") for n in sig.x_names),
        tuple((n, units.get(n), f"force {n}") for n in sig.f_names), tuple(model.parameters),
        dict(spec.get("parameter_units") or {}),
        "duffid online algebraic identification of " + "; ".join(model.texts),
        {k: v for k, v in spec.items() if k != "motion"}), motion)


def _interface(model: str | EstimatorInterface) -> EstimatorInterface:
    return model if isinstance(model, EstimatorInterface) else builtin_interface(model)


def variable_types(model: str | EstimatorInterface) -> dict[str, str]:
    """:data:`TYPES` with the ``<name>_status`` outputs of the model (a built-in model's name or an interface)."""
    interface = _interface(model)
    return {**TYPES, "outliers": "Integer", **{f"{name}_status": "Integer" for name in interface.parameters}}


def parameter_unit(name: str) -> str:
    """The unit of parameter ``name`` of a built-in model (``"k2"`` -> ``"N/m"``)."""
    return PARAMETER_UNITS[name.rstrip("0123456789")]


def _defaults(interface: EstimatorInterface) -> dict[str, float]:
    """Parameter start values: the robust method and the schema's defaults as the C core codes them."""
    values = {"method": 0.0, **{o.name: float(o.c_default) for o in fmu_parameters()}}
    values.update({f"{name}_nominal": 0.0 for name in interface.parameters})
    return values


def variable_units(model: str | EstimatorInterface) -> dict[str, str]:
    """Variable name -> unit of every variable of :func:`estimator_variables` that has one."""
    return {v.name: v.unit for v in estimator_variables(model) if v.unit}


def estimator_variables(model: str | EstimatorInterface) -> list[FmuVariable]:
    """The variable table of an estimator FMU (value references 0, 1, ...) of a built-in model
    (its name) or any :class:`EstimatorInterface`."""
    interface = _interface(model)
    defaults = _defaults(interface)
    units = interface.parameter_units
    table: list[FmuVariable] = []

    def add(name: str, causality: str, variability: str, initial: str | None, start: float | None,
            unit: str | None, description: str) -> None:
        table.append(FmuVariable(name=name, vr=len(table), causality=causality, variability=variability,
                                 initial=initial, start=start, internal_start=start if start is not None
                                 else float("nan"), unit=unit, description=description))

    add("time", "independent", "continuous", None, None, "s", "simulation time")
    for name, unit, text in interface.inputs:
        add(name, "input", "continuous", None, 0.0, unit, f"{text} (one sample per doStep)")
    for name in interface.parameters:
        add(f"{name}_hat", "output", "discrete", "calculated", None, units.get(name),
            f"estimate of {name} (NaN unless published)")
    add("identified", "output", "discrete", "calculated", None, None, "1 when every estimate is trustworthy")
    add("condition", "output", "discrete", "calculated", None, "1", "largest condition number of the equations")
    add("uncertainty", "output", "discrete", "calculated", None, "1", "largest relative standard error (robust)")
    add("window_length", "output", "discrete", "calculated", None, "s", "window length")
    for name in interface.parameters:
        add(f"{name}_status", "output", "discrete", "calculated", None, None,
            f"status of {name}: {status_codes()}")
    add("outliers", "output", "discrete", "calculated", None, None,
        "isolated displacement outliers excluded so far (each one logged, category logStatusWarning)")
    for name, unit, text in OPTIONS:
        add(name, "parameter", "fixed", "exact", defaults[name], unit, text)
    for name in interface.parameters:
        add(f"{name}_nominal", "parameter", "fixed", "exact", defaults[f"{name}_nominal"], units.get(name),
            f"optional prior size of {name} for the trust test (0: none, the scale comes from the data)")
    add("sample_period", "parameter", "fixed", "exact", DEFAULT_SAMPLE_PERIOD, "s", SAMPLE_PERIOD_DESCRIPTION)
    for name in interface.parameters:
        add(f"{name}_std_error", "output", "discrete", "calculated", None, units.get(name),
            f"standard error of the estimate of {name} (NaN unless published)")
    add("residual", "output", "discrete", "calculated", None, "1",
        "the window's one-step prediction error relative to its force balance (it jumps when the plant changes)")
    add("enable", "input", "discrete", None, 1.0, None, ENABLE_DESCRIPTION)
    add("reset", "input", "discrete", None, 0.0, None, RESET_DESCRIPTION)
    return table
