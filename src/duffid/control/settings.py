"""The parameters of the adaptive controller: one declarative schema, everything else from it.

:data:`PARAMETERS` lists every scalar parameter of the controller once, in the FMUs'
value-reference order: its FMU name, its field in the C ``duffid_ctrl_config``, its type,
its valid range, its unit and what it means, and the setting of
:func:`~duffid.control.adaptive.controller_parameters` it comes from (with the setting's
default) or the design it comes from. From it come

- the settings and their defaults (:data:`SETTINGS`) and :func:`check_parameters`;
- the C header ``fmus/controller/duffid_ctrl_params.h`` (:func:`c_header`): an X-macro
  table from which ``duffid_ctrl_check`` checks the ranges and the FMU reads its
  parameters (tests/test_control_settings.py checks the file is current and runs the Python
  and C checks against each other);
- the FMU parameter table of :mod:`duffid.control.controller_fmu`.

The nominal parameters of the fixed mode (``<name>_nominal``, one per model parameter;
masses positive) and the rule ``|excitation_amplitude| <= force_limit`` relate several
values; they are written once per language, next to the generated checks.
"""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from typing import Any, Mapping

from ..errors import InputError

__all__ = ["Parameter", "PARAMETERS", "SETTINGS", "MAX_DIFFERENTIATOR_SAMPLES", "check_parameters", "c_header",
           "C_HEADER_NAME", "coded"]

#: Largest ``differentiator_samples`` (the C core's fixed buffer; keeps its sums exact).
MAX_DIFFERENTIATOR_SAMPLES = 64
#: File name of the generated C header (in ``fmus/controller``).
C_HEADER_NAME = "duffid_ctrl_params.h"


@dataclass(frozen=True)
class Parameter:
    """One scalar parameter of the adaptive controller.

    Parameters
    ----------
    name : str
        FMU parameter name (and key of :func:`~duffid.control.adaptive.controller_parameters`'
        result).
    kind : {"real", "code", "count", "bool"}
        ``real``: a number checked by ``rule``; ``code``: the index of one of ``choices``;
        ``count``: an integer in ``minimum .. maximum``; ``bool``.
    description : str
        What it means (FMU variable description).
    rule : {"finite", "positive", "non_negative"}
        The range of a real parameter (every real must be finite).
    unit : str, optional
        Its unit.
    choices : tuple of str
        The names of a code's values (0, 1, ...).
    minimum, maximum : int
        The range of a count.
    setting : str, optional
        The setting of ``controller_parameters`` it comes from (None: from the design).
    default : object
        The setting's default.
    field : str, optional
        Its field in the C ``duffid_ctrl_config`` (default: ``name``).
    """

    name: str
    kind: str
    description: str
    rule: str = "finite"
    unit: str | None = None
    choices: tuple[str, ...] = ()
    minimum: int = 0
    maximum: int = 0
    setting: str | None = None
    default: Any = None
    field: str | None = None

    @property
    def c_field(self) -> str:
        """The field of ``duffid_ctrl_config`` (``K[0]``, ``switch_time``, ...)."""
        return self.field or self.name

    @property
    def rule_text(self) -> str:
        """The rule in words, as both checks word it (``"must be positive"``)."""
        if self.kind == "code":
            return f"must be 0 or 1 ({'/'.join(self.choices)})" if len(self.choices) == 2 else \
                f"must be an integer in 0 .. {len(self.choices) - 1} ({'/'.join(self.choices)})"
        if self.kind == "count":
            return f"must be an integer in {self.minimum} .. {self.maximum}"
        if self.kind == "bool":
            return "must be true or false"
        return {"finite": "must be finite", "positive": "must be positive",
                "non_negative": "must not be negative"}[self.rule]


def _setting(name: str, kind: str, default: Any, description: str, **kw: Any) -> Parameter:
    return Parameter(name, kind, description, setting=kw.pop("setting", name), default=default, **kw)


def _design(name: str, description: str, **kw: Any) -> Parameter:
    return Parameter(name, "real", description, **kw)


#: Every scalar parameter, in FMU value-reference order (the nominal values of the fixed
#: mode come after ``fallback``, then ``fixed_switch_time``).
PARAMETERS: tuple[Parameter, ...] = (
    _setting("mode", "code", "adaptive",
             "0 adaptive, 1 fixed (baseline on the nominal parameters from fixed_switch_time)",
             choices=("adaptive", "fixed")),
    _design("sample_period", "sampling period; every communication step must equal it", rule="positive", unit="s"),
    _setting("excitation", "code", "step", "0 step, 1 linear chirp", choices=("step", "chirp")),
    _setting("excitation_amplitude", "real", 10.0, "amplitude of the excitation (at most force_limit)", unit="N"),
    _setting("chirp_f0", "real", 1.0, "chirp start frequency", rule="non_negative", unit="Hz"),
    _setting("chirp_f1", "real", 20.0, "chirp end frequency (kept after chirp_duration)", rule="non_negative",
             unit="Hz"),
    _setting("chirp_duration", "real", 2.0, "chirp sweep duration", rule="positive", unit="s"),
    _setting("min_excitation", "real", 0.2, "shortest excitation before an adaptive switch", rule="non_negative",
             unit="s"),
    _setting("settle_time", "real", 0.05, "time the estimates must stay within settle_tolerance",
             rule="non_negative", unit="s"),
    _setting("settle_tolerance", "real", 0.002, "relative change that restarts settling", rule="positive",
             unit="1"),
    _design("K1", "feedback gain on the position error", unit="1/s2", field="K[0]"),
    _design("K2", "feedback gain on the velocity error", unit="1/s", field="K[1]"),
    _design("L1", "observer gain on the position", unit="1", field="L[0]"),
    _design("L2", "observer gain on the velocity", unit="1/s", field="L[1]"),
    _design("reference_bandwidth", "triple pole of the reference model", rule="positive", unit="rad/s"),
    _setting("reference_model", "code", "filter",
             "0 filter: track the triple-pole model driven by r; 1 derivatives: track r (with r_dot, r_ddot) "
             "after a triple-pole transient from the switch", choices=("filter", "derivatives")),
    _setting("force_limit", "real", 20.0, "largest force magnitude", rule="positive", unit="N"),
    _setting("differentiator_samples", "count", 10,
             f"samples of the least-squares quadratic differentiator (3 .. {MAX_DIFFERENTIATOR_SAMPLES})",
             minimum=3, maximum=MAX_DIFFERENTIATOR_SAMPLES),
    _setting("freeze", "bool", True,
             "true: keep the estimates of the switch; false: follow finite estimates while identified"),
    _setting("fallback", "code", "hold",
             "freeze false, estimates withdrawn (not identified): 0 hold the law's parameters, 1 take the nominal",
             choices=("hold", "nominal")),
    _setting("fixed_switch_time", "real", 1.0, "switch time of the fixed mode", unit="s", setting="switch_time",
             field="switch_time"),
)
_BY_NAME = {p.name: p for p in PARAMETERS}

#: Controller settings (keywords of ``controller_parameters``) and their defaults; ``nominal``
#: (the parameters of the fixed mode and of ``fallback`` "nominal"; default: the paper's plant)
#: is not a scalar.
SETTINGS: dict[str, Any] = {**{p.setting: p.default for p in PARAMETERS if p.setting is not None},
                            "nominal": None}


def coded(name: str, value: Any) -> Any:
    """A setting's value as the FMU codes it: a code's name -> its index (integers pass)."""
    p = _BY_NAME[name] if name in _BY_NAME else next(q for q in PARAMETERS if q.setting == name)
    if p.kind == "code" and isinstance(value, str):
        return p.choices.index(value) if value in p.choices else value
    return value


def _violates(p: Parameter, value: Any) -> bool:
    if p.kind == "code":
        return isinstance(value, bool) or value not in range(len(p.choices))
    if p.kind == "count":
        return (isinstance(value, bool) or not isinstance(value, numbers.Integral)
                or not p.minimum <= value <= p.maximum)
    if p.kind == "bool":
        return not isinstance(value, (bool, numbers.Integral))
    value = float(value)
    if not math.isfinite(value):
        return True
    return (p.rule == "positive" and not value > 0.0) or (p.rule == "non_negative" and not value >= 0.0)


def check_parameters(params: Mapping[str, Any], dofs: int, parameter_names: tuple[str, ...]) -> None:
    """Check a parameter set of ``AdaptiveController<dofs>``; ``duffid_ctrl_check`` applies the
    same table (``fmus/controller/duffid_ctrl_params.h``).

    Parameters
    ----------
    params : mapping
        FMU parameter name -> value (codes as integers).
    dofs : {1, 2}
        The plant's degrees of freedom.
    parameter_names : tuple of str
        The model parameters, whose ``<name>_nominal`` values are checked (finite; masses positive).

    Raises
    ------
    InputError
        Naming the parameter, its rule and its value.
    """
    for p in PARAMETERS:
        value = params[p.name]
        if p.kind == "real" and not (isinstance(value, numbers.Real) and not isinstance(value, bool)):
            raise InputError(f"parameter {p.name} must be a number, got {value!r}")
        if _violates(p, value):
            finite = p.kind != "real" or math.isfinite(float(value))
            raise InputError(f"parameter {p.name} {p.rule_text if finite else 'must be finite'}, got {value!r}")
    for name in parameter_names:
        value = params[f"{name}_nominal"]
        if not math.isfinite(float(value)):
            raise InputError(f"parameter {name}_nominal must be finite, got {value!r}")
        if name.startswith("m") and not value > 0.0:
            raise InputError(f"parameter {name}_nominal must be positive, got {value!r}")
    if abs(params["excitation_amplitude"]) > params["force_limit"]:
        raise InputError(f"excitation_amplitude {params['excitation_amplitude']!r} exceeds force_limit "
                         f"{params['force_limit']!r}")


def _c_kind(p: Parameter) -> str:
    return "REAL" if p.kind == "real" else "INT"


def c_header() -> str:
    """The text of ``fmus/controller/duffid_ctrl_params.h``, generated from :data:`PARAMETERS`."""
    lines = [
        "/* The scalar parameters of the adaptive controller: GENERATED by duffid.control.settings",
        " * from its PARAMETERS schema (the single source of every parameter); do not edit.",
        " * `make generated` rewrites it; tests/test_control_settings.py checks it is current.",
        " *",
        " * X(kind, field, NAME, name, rule, minimum, maximum, rule text)",
        " *   kind   REAL (a double; rule FINITE, POSITIVE or NON_NEGATIVE) or INT (an int in",
        " *          minimum .. maximum; rule RANGE) or BOOL (any value: nonzero is true)",
        " *   field  the member of duffid_ctrl_config; NAME the FMU's CONTROLLER_VR_ suffix",
        " *",
    ]
    for p in PARAMETERS:
        unit = f" [{p.unit}]" if p.unit else ""
        lines.append(f" *   {p.name}{unit}: {p.description}")
    lines += [" */", "#ifndef DUFFID_CTRL_PARAMS_H", "#define DUFFID_CTRL_PARAMS_H", "",
              "#define DUFFID_CTRL_PARAMETERS(X) \\"]
    for i, p in enumerate(PARAMETERS):
        if p.kind == "real":
            rule, lo, hi = p.rule.upper(), 0, 0
        elif p.kind == "code":
            rule, lo, hi = "RANGE", 0, len(p.choices) - 1
        elif p.kind == "count":
            rule, lo, hi = "RANGE", p.minimum, p.maximum
        else:
            rule, lo, hi = "ANY", 0, 1
        kind = {"real": "REAL", "code": "INT", "count": "INT", "bool": "BOOL"}[p.kind]
        end = " \\" if i < len(PARAMETERS) - 1 else ""
        lines.append(f"    X({kind}, {p.c_field}, {p.name.upper()}, {p.name}, {rule}, {lo}, {hi}, "
                     f"\"{p.rule_text}\"){end}")
    lines += ["", "#endif /* DUFFID_CTRL_PARAMS_H */", ""]
    return "\n".join(lines)
