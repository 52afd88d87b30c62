"""The interface of the estimator FMUs, C and pythonfmu: names, inputs, units, types,
parameters and their start values (one table, from which both FMUs are described).

Value references follow the order of :func:`estimator_variables` (the C model
``fmus/estimator/fmu_model_estimator.c`` checks the count): time, the displacements and the
force (inputs), the estimates ``<name>_hat``, ``identified``, ``condition``, ``uncertainty``,
``window_length``, ``<name>_status``, ``outliers`` (outputs), then the parameters: ``method``,
the options of :mod:`duffid.identification.options`, ``<name>_nominal`` and
``sample_period``.
"""
from __future__ import annotations

from ..errors import InputError
from ..identification.engine import status_codes
from ..identification.options import ONLINE_METHODS, fmu_parameters
from ..models.chain import Duffing1, Duffing2, DuffingCircuit
from .variables import FmuVariable

__all__ = ["C_FMU_NAMES", "MODELS", "MODEL_CODES", "RECIPROCAL", "INPUTS", "PARAMETER_UNITS", "parameter_unit", "OPTIONS",
           "DEFAULT_SAMPLE_PERIOD", "SAMPLE_PERIOD_DESCRIPTION", "TYPES", "variable_types", "estimator_variables"]

#: Model name -> model identifier of the C FMUs (FMI 3 files get a ``_fmi3`` suffix).
C_FMU_NAMES = {"duffing1": "DuffingEstimator1", "duffing2": "DuffingEstimator2", "circuit": "DuffingCircuitEstimator"}
#: Model name -> the model (a :class:`~duffid.models.chain.Chain`) estimated.
MODELS = {"duffing1": Duffing1, "duffing2": Duffing2, "circuit": DuffingCircuit}
#: Model name -> the C core's model code (DUFFID_DUFFING1, DUFFID_DUFFING2; the circuit is the
#: Duffing1 equation with L = m, R = b, 1/C = k, a = kp).
MODEL_CODES = {"duffing1": 1, "duffing2": 2, "circuit": 1}
#: Model name -> its parameters that are the reciprocal of the core's (output as 1/value).
RECIPROCAL = {"circuit": ("C",)}
#: Model name -> the inputs (name, unit, description): displacements, then forces.
INPUTS = {"duffing1": (("x", "m", "displacement of the mass"), ("f", "N", "force on the mass")),
           "duffing2": (("x1", "m", "displacement of m1"), ("x2", "m", "displacement of m2"),
                        ("f1", "N", "force on m1")),
           "circuit": (("q", "C", "charge of the capacitor"), ("u", "V", "source voltage"))}
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
TYPES = {"method": "Integer", "identified": "Boolean",
         **{o.name: "Boolean" if o.kind == "bool" else "Integer" for o in fmu_parameters() if o.c_kind == "CODE"}}


def variable_types(model_name: str) -> dict[str, str]:
    """:data:`TYPES` with the ``<name>_status`` outputs of the model."""
    model = MODELS[model_name]()
    return {**TYPES, "outliers": "Integer", **{f"{name}_status": "Integer" for name in model.parameters}}


def parameter_unit(name: str) -> str:
    """The unit of parameter ``name`` (``"k2"`` -> ``"N/m"``)."""
    return PARAMETER_UNITS[name.rstrip("0123456789")]


def _defaults(model_name: str) -> dict[str, float]:
    """Parameter start values: the robust method and the schema's defaults as the C core codes them."""
    values = {"method": 0.0, **{o.name: float(o.c_default) for o in fmu_parameters()}}
    model = MODELS[model_name]()
    values.update({f"{name}_nominal": 0.0 for name in model.parameters})
    return values


def estimator_variables(model_name: str) -> list[FmuVariable]:
    """The variable table of an estimator FMU (value references 0, 1, ...)."""
    if model_name not in C_FMU_NAMES:
        raise InputError(f"unknown model {model_name!r}; choose {', '.join(C_FMU_NAMES)}")
    model = MODELS[model_name]()
    defaults = _defaults(model_name)
    table: list[FmuVariable] = []

    def add(name: str, causality: str, variability: str, initial: str | None, start: float | None,
            unit: str | None, description: str) -> None:
        table.append(FmuVariable(name=name, vr=len(table), causality=causality, variability=variability,
                                 initial=initial, start=start, internal_start=start if start is not None
                                 else float("nan"), unit=unit, description=description))

    add("time", "independent", "continuous", None, None, "s", "simulation time")
    for name, unit, text in INPUTS[model_name]:
        add(name, "input", "continuous", None, 0.0, unit, f"{text} (one sample per doStep)")
    for name in model.parameters:
        add(f"{name}_hat", "output", "discrete", "calculated", None, parameter_unit(name),
            f"estimate of {name} (NaN unless published)")
    add("identified", "output", "discrete", "calculated", None, None, "1 when every estimate is trustworthy")
    add("condition", "output", "discrete", "calculated", None, "1", "largest condition number of the equations")
    add("uncertainty", "output", "discrete", "calculated", None, "1", "largest relative standard error (robust)")
    add("window_length", "output", "discrete", "calculated", None, "s", "window length")
    for name in model.parameters:
        add(f"{name}_status", "output", "discrete", "calculated", None, None,
            f"status of {name}: {status_codes()}")
    add("outliers", "output", "discrete", "calculated", None, None,
        "isolated displacement outliers excluded so far (each one logged, category logStatusWarning)")
    for name, unit, text in OPTIONS:
        add(name, "parameter", "fixed", "exact", defaults[name], unit, text)
    for name in model.parameters:
        add(f"{name}_nominal", "parameter", "fixed", "exact", defaults[f"{name}_nominal"], parameter_unit(name),
            f"optional prior size of {name} for the trust test (0: none, the scale comes from the data)")
    add("sample_period", "parameter", "fixed", "exact", DEFAULT_SAMPLE_PERIOD, "s", SAMPLE_PERIOD_DESCRIPTION)
    return table
