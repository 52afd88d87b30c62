"""The C test FMU that asks to end the simulation (tests/c/stopper_model.c on the shared glue),
FMI 2 (``CStopper.fmu``) and FMI 3 (``CStopper_fmi3.fmu``): y = the time reached, s = the
integral of its held input u; the step that passes the parameter ``t_end`` stops there and asks
to end the simulation (FMI 2 Discard + fmi2Terminated, FMI 3 terminateSimulation, with
earlyReturn when it stopped inside the step)."""
from __future__ import annotations

import math
from pathlib import Path

from duffid.fmu.c_model import build_c_model_fmu
from duffid.fmu.variables import FmuVariable

__all__ = ["STOPPER_SOURCE", "build_stopper_fmu"]

#: The model's C source.
STOPPER_SOURCE = Path(__file__).parent / "c" / "stopper_model.c"


def _variable(name: str, vr: int, causality: str, start: float | None, text: str) -> FmuVariable:
    variability = {"independent": "continuous", "parameter": "fixed", "input": "continuous"}.get(causality,
                                                                                                "discrete")
    initial = {"output": "calculated", "parameter": "exact"}.get(causality)
    return FmuVariable(name=name, vr=vr, causality=causality, variability=variability, initial=initial,
                       start=start, internal_start=math.nan if start is None else start,
                       unit="s" if name in ("time", "y", "t_end", "sample_period") else None, description=text)


def build_stopper_fmu(out_dir: str | Path, fmi_version: int = 2, t_end: float = 0.35) -> Path:
    """Build ``CStopper.fmu`` (FMI 2) or ``CStopper_fmi3.fmu`` (FMI 3) in ``out_dir``."""
    table = [_variable("time", 0, "independent", None, "simulation time"),
             _variable("u", 1, "input", 0.0, "input, integrated into s"),
             _variable("y", 2, "output", None, "the time reached"),
             _variable("s", 3, "output", None, "integral of u"),
             _variable("t_end", 4, "parameter", t_end, "time at which it asks to end the simulation"),
             _variable("sample_period", 5, "parameter", 0.01, "the default experiment's step (unused)")]
    return build_c_model_fmu(out_dir, "CStopper", fmi_version, table, prefix="stopper",
                             model_dir=STOPPER_SOURCE.parent, model_files=(STOPPER_SOURCE.name,),
                             description="asks to end the simulation at t_end", types={}, defines={},
                             sample_period=0.01)
