"""The variable table of an FMU exported from a causalised Modelica model: value
references in the order time, parameters, calculated parameters, inputs, states, state
derivatives, then every other variable in declaration order."""
from __future__ import annotations

import math

from ..fmu.variables import FmuVariable, derivative_unit
from .causalize import OdeModel

__all__ = ["variable_table"]


def variable_table(ode: OdeModel) -> list[FmuVariable]:
    """Value references in the order time, parameters, calculated parameters, inputs,
    states, state derivatives, then every other variable in declaration order."""
    table: list[FmuVariable] = []

    def add(**kw) -> FmuVariable:
        var = FmuVariable(vr=len(table), **kw)
        table.append(var)
        return var

    add(name="time", causality="independent", variability="continuous", initial=None, start=None,
        internal_start=0.0, unit="s", description="Simulation time")
    flat = ode.flat
    state_names = {s.name for s in ode.states}
    derivative_names = {d.name for d in ode.derivatives}
    tear_names = {t.name for t in ode.tears}
    vr_of: dict[str, int] = {}
    for v in flat.role("parameter"):
        vr_of[v.name] = add(name=v.name, causality="parameter", variability="fixed", initial="exact",
                            start=float(v.value), internal_start=float(v.value), unit=v.unit,  # type: ignore[arg-type]
                            description=v.description, minimum=v.minimum, maximum=v.maximum).vr
    for v in flat.role("calculated"):
        vr_of[v.name] = add(name=v.name, causality="calculatedParameter", variability="fixed",
                            initial="calculated", start=None, internal_start=0.0, unit=v.unit,
                            description=v.description).vr
    for v in flat.role("input"):
        start = v.start if v.start is not None else 0.0
        vr_of[v.name] = add(name=v.name, causality="input", variability="continuous", initial=None,
                            start=start, internal_start=start, unit=v.unit, description=v.description,
                            minimum=v.minimum, maximum=v.maximum).vr
    for v in ode.states:
        start = v.start if v.start is not None else 0.0
        vr_of[v.name] = add(name=v.name, causality="output" if v.output else "local",
                            variability="continuous", initial="exact", start=start, internal_start=start,
                            unit=v.unit, description=v.description, settable_start=True,
                            minimum=v.minimum, maximum=v.maximum).vr
    for d, s in zip(ode.derivatives, ode.states):
        vr_of[d.name] = add(name=d.name, causality="output" if d.output else "local",
                            variability="continuous", initial="calculated", start=None, internal_start=0.0,
                            unit=derivative_unit(s.unit), description=d.description,
                            derivative_of=vr_of[s.name]).vr
    for v in flat.variables:
        if v.name in vr_of or v.role in ("parameter", "calculated", "input") or v.name in state_names \
                or v.name in derivative_names:
            continue
        guess = v.start if v.name in tear_names and v.start is not None and math.isfinite(v.start) else 0.0
        vr_of[v.name] = add(name=v.name, causality="output" if v.output else "local",
                            variability="continuous", initial="calculated", start=None,
                            internal_start=guess, unit=v.unit, description=v.description).vr
    return table
