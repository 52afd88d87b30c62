"""The FMU's variable table: value references, causality, variability, initial, start.

One table serves the generated C code and both modelDescription.xml writers, so that
value references and attributes cannot disagree.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from .causalize import OdeModel

__all__ = ["FmuVariable", "variable_table", "CAUSALITY_CODES", "VARIABILITY_CODES"]

#: Causality codes of fmus/common/fmu_model.h.
CAUSALITY_CODES = {"parameter": 0, "calculatedParameter": 1, "input": 2, "output": 3, "local": 4,
                   "independent": 5}
#: Variability codes of fmus/common/fmu_model.h.
VARIABILITY_CODES = {"constant": 0, "fixed": 1, "tunable": 2, "discrete": 3, "continuous": 4}


@dataclass(frozen=True)
class FmuVariable:
    """One Float64 variable of the FMU.

    ``start`` is the start value written to modelDescription.xml (None: none);
    ``internal_start`` the value the C code starts from (e.g. the initial guess of a
    Newton iteration variable, which has no start attribute).
    """

    name: str
    vr: int
    causality: str
    variability: str
    initial: str | None
    start: float | None
    internal_start: float
    unit: str | None = None
    description: str = ""
    derivative_of: int | None = None
    settable_start: bool = False
    minimum: float | None = None
    maximum: float | None = None


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


_DERIVATIVE_UNITS = {"m": "m/s", "m/s": "m/s2", "C": "A", "A": "A/s", "Wb": "V", "V": "V/s", "rad": "rad/s",
                     "rad/s": "rad/s2"}


def derivative_unit(unit: str | None) -> str | None:
    """Unit of the time derivative of a quantity with ``unit`` (None when unknown)."""
    return _DERIVATIVE_UNITS.get(unit) if unit else None
