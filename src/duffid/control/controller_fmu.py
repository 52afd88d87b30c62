"""The adaptive controller as C co-simulation FMUs (FMI 2.0 and 3.0) on the shared FMI glue.

:func:`build_controller_fmus` compiles the portable controller core
(``fmus/controller/duffid_controller.c``) with the discrete-time FMU model
``fmus/controller/fmu_model_controller.c`` and the glue of ``fmus/common`` into
``AdaptiveController1[_fmi3].fmu`` (1-DOF Duffing oscillator or circuit) and
``AdaptiveController2[_fmi3].fmu`` (two-mass chain, force on m1, tracks x1). The
algorithm and the timing are those of :class:`duffid.control.adaptive.AdaptiveController`, which
gives the same outputs to rounding.

Variables (1-DOF; 2-DOF in brackets):

- inputs: ``r`` (reference position), ``r_dot``, ``r_ddot`` (its derivatives, used by
  ``reference_model`` 1; samples at ``t_k``, start 0), ``x`` [``x1``, ``x2``], the
  estimates ``m_hat``,
  ``b_hat``, ``k_hat``, ``kp_hat`` [``m1_hat``, ``b1_hat``, ``k1_hat``, ``kp1_hat``,
  ``b2_hat``, ``k2_hat``, ``kp2_hat``, ``m2_hat``] (NaN accepted: not yet estimated)
  and ``identified`` (Boolean);
- outputs: ``f`` (force command), ``f_sample`` (the force as a sample for an identifier:
  the mean of the forces before and after the next communication point, which stands
  for the zero-order-hold staircase; connect it to the estimator's force input),
  ``phase`` (Integer: 0 excitation, 1 control),
  ``x_ref`` (desired position x_d), ``v_hat`` [``v1_hat``, ``v2_hat``] (observer),
  ``saturated`` (Boolean), ``switch_time`` (the time from which the law acts) and
  ``<name>_used`` (the law's parameters);
  NaN before the switch except ``f``, ``f_sample``, ``phase`` and ``saturated``;
- fixed parameters: those of :func:`duffid.control.adaptive.controller_parameters` (``mode``,
  ``excitation``, ``reference_model`` and ``differentiator_samples`` Integer, ``freeze``
  Boolean), start
  values from ``controller_parameters(design(1e-3))``; the fixed mode's switch time is
  the parameter ``fixed_switch_time`` (setting ``switch_time`` of ``controller_parameters``).

A step whose size differs from ``sample_period`` is discarded (logged); parameters that
:func:`duffid.control.adaptive.check_parameters` rejects (e.g. ``excitation_amplitude`` above
``force_limit``) make the initialisation fail (logged). The FMU state holds the whole
controller (buffers, observer, reference model, phase).
"""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

from ..assets import fmu_sources
from ..cbuild import Platform
from ..errors import InputError
from ..fmu.c_model import build_c_model_fmu
from ..fmu.estimator_table import parameter_unit
from ..fmu.variables import FmuVariable
from .adaptive import PARAMETER_NAMES, controller_parameters
from .design import design
from .settings import PARAMETERS

__all__ = ["build_controller_fmus", "build_controller_fmu", "controller_variables", "CONTROLLER_FMU_NAMES",
           "TYPES"]

#: DOFs -> model identifier (FMI 3 files get a ``_fmi3`` suffix).
CONTROLLER_FMU_NAMES = {1: "AdaptiveController1", 2: "AdaptiveController2"}
#: Variables that are not Float64.
TYPES = {"identified": "Boolean", "phase": "Integer", "saturated": "Boolean",
         **{p.name: "Boolean" if p.kind == "bool" else "Integer" for p in PARAMETERS if p.kind != "real"}}
_FILES = ("duffid_controller.c", "duffid_controller.h", "duffid_ctrl_params.h", "fmu_model_controller.c")
#: Parameters: (name, unit, description), in value-reference order (then the nominal values
#: and fixed_switch_time), from the schema of duffid.control.settings.
_PARAMETERS = tuple((p.name, p.unit, p.description) for p in PARAMETERS if p.name != "fixed_switch_time")
_SWITCH = next(p for p in PARAMETERS if p.name == "fixed_switch_time")


def controller_variables(dofs: int) -> tuple[list[FmuVariable], dict[str, int]]:
    """The variable table of ``AdaptiveController<dofs>`` and the value references of its
    groups (the ``CONTROLLER_VR_*`` defines of the C model)."""
    if dofs not in CONTROLLER_FMU_NAMES:
        raise InputError(f"dofs must be 1 or 2, got {dofs!r}")
    names = PARAMETER_NAMES[dofs]
    start = controller_parameters(design(1e-3), dofs=dofs)
    table: list[FmuVariable] = []
    groups: dict[str, int] = {}

    def add(name: str, causality: str, value: float | None, unit: str | None, text: str,
            group: str | None = None) -> None:
        variability = {"independent": "continuous", "output": "discrete", "parameter": "fixed"}.get(
            causality, "discrete" if name in TYPES else "continuous")
        initial = {"output": "calculated", "parameter": "exact"}.get(causality)
        groups.setdefault(group or name.upper(), len(table))
        table.append(FmuVariable(name=name, vr=len(table), causality=causality, variability=variability,
                                 initial=initial, start=value, internal_start=float("nan") if value is None
                                 else float(value), unit=unit, description=text))

    x_names = ("x",) if dofs == 1 else ("x1", "x2")
    add("time", "independent", None, "s", "simulation time")
    of = "" if dofs == 1 else " of x1"
    add("r", "input", 0.0, "m", "reference position" + of)
    add("r_dot", "input", 0.0, "m/s", f"reference velocity{of} (reference_model 1)")
    add("r_ddot", "input", 0.0, "m/s2", f"reference acceleration{of} (reference_model 1)")
    for name in x_names:
        add(name, "input", 0.0, "m", f"measured position {name}", "X")
    for name in names:
        add(f"{name}_hat", "input", 0.0, parameter_unit(name), f"estimate of {name} (NaN: not yet estimated)", "EST")
    add("identified", "input", 0.0, None, "the estimates are trustworthy")
    add("f", "output", None, "N", "force command (applied from the next communication point)")
    add("f_sample", "output", None, "N", "the force as a sample for an identifier: mean of the forces "
        "before and after the next communication point (zero-order hold)")
    add("phase", "output", None, None, "0 excitation, 1 control")
    add("x_ref", "output", None, "m", "desired position x_d at the next communication point (NaN before the switch)")
    for name in x_names:
        add(f"v{name[1:]}_hat", "output", None, "m/s", f"observer velocity of {name} (NaN before the switch)",
            "V_HAT")
    add("saturated", "output", None, None, "the last command was limited to force_limit")
    add("switch_time", "output", None, "s", "time from which the law acts (NaN before the switch)")
    for name in names:
        add(f"{name}_used", "output", None, parameter_unit(name), f"{name} of the law (NaN before the switch)", "USED")
    for name, unit, text in _PARAMETERS:
        add(name, "parameter", float(start[name]), unit, text)
    for name in names:
        add(f"{name}_nominal", "parameter", start[f"{name}_nominal"], parameter_unit(name),
            f"{name} of the fixed mode and of fallback 1", "NOMINAL")
    add(_SWITCH.name, "parameter", start[_SWITCH.name], _SWITCH.unit, _SWITCH.description)
    return table, groups


def build_controller_fmu(dofs: int, out_dir: str | Path, fmi_version: int = 2, compiler: str | None = None,
                         platforms: Sequence[Platform] | None = None) -> Path:
    """Build ``AdaptiveController<dofs>.fmu`` (FMI 2) or ``..._fmi3.fmu`` (FMI 3) in ``out_dir``
    with binaries for ``platforms`` (default: this machine)."""
    table, groups = controller_variables(dofs)
    defines = {"DOFS": dofs, **{f"VR_{group}": vr for group, vr in groups.items()}}
    non_finite = [v.name for v in table if v.name.endswith("_hat") and v.causality == "input"]
    return build_c_model_fmu(out_dir, CONTROLLER_FMU_NAMES[dofs], fmi_version, table, prefix="controller",
                             model_dir=fmu_sources("controller"), model_files=_FILES,
                             description=f"duffid adaptive controller ({dofs} DOF): excitation, online "
                                         "estimates, feedback linearisation",
                             types=TYPES, defines=defines,
                             sample_period=next(v.start for v in table if v.name == "sample_period"),
                             non_finite=non_finite, compiler=compiler, platforms=platforms)


def build_controller_fmus(out_dir: str | Path = Path("build/fmus"),
                          platforms: Sequence[Platform] | None = None) -> list[Path]:
    """Build ``AdaptiveController1``, ``AdaptiveController2`` (FMI 2.0) and their
    ``_fmi3`` variants in ``out_dir`` (created), with binaries for ``platforms`` (default:
    this machine); return the paths."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    return [build_controller_fmu(dofs, out_dir, version, platforms=platforms)
            for dofs in CONTROLLER_FMU_NAMES for version in (2, 3)]
