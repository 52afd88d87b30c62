"""The FMU's variable table: value references, causality, variability, initial, start.

One table serves the generated C code and both modelDescription.xml writers, so that
value references and attributes cannot disagree.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["FmuVariable", "CAUSALITY_CODES", "VARIABILITY_CODES", "derivative_unit", "c_literal"]

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


_DERIVATIVE_UNITS = {"m": "m/s", "m/s": "m/s2", "C": "A", "A": "A/s", "Wb": "V", "V": "V/s", "rad": "rad/s",
                     "rad/s": "rad/s2"}


def derivative_unit(unit: str | None) -> str | None:
    """Unit of the time derivative of a quantity with ``unit`` (None when unknown)."""
    return _DERIVATIVE_UNITS.get(unit) if unit else None


def c_literal(value: float) -> str:
    """``value`` as a C double literal (``NAN`` for NaN)."""
    if math.isnan(value):
        return "NAN"
    return repr(float(value))
