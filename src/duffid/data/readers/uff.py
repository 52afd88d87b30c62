"""Universal File Format data sets 58 and 58b (modal-test software) through pyuff.

Each data set 58 is a channel named by its first ID line (``id1``; its number selects it too).
Only time responses (function type 1) with an evenly spaced time abscissa and real ordinates
make a record; the rate is ``1 / abscissa increment``, the start the abscissa minimum. The unit
is the ordinate's unit label or, without one, the unit of its specific data type
(displacement, velocity, acceleration, force) in the unit system of the units data set 164 before
it (SI without one); the label must agree with the ordinate's length and force exponents. A 164
set's factors must agree with its units code: the format divides by them to get SI (mm: 1000),
some writers multiply (mm: 0.001); either is taken, any other factor, or a user-defined system,
refuses the unlabelled sets. The abscissa is in seconds or in the time unit its label names
(``ms``).

The format's header holds the abscissa increment to 6 significant digits (E13.5) and ASCII data
to 12: a rate such as 1024 Hz comes back within 5e-7. pyuff reads a data set whole, not in
slices: a selected channel is read once, the others not at all.
"""
from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np

from ..channels import Channel
from ..units import lookup
from . import optional_import, reading

__all__ = ["EXTENSIONS", "FUNCTION_TYPES", "open_channels"]

EXTENSIONS = (".uff", ".unv")
#: UFF 58 function types (record 6, field 1).
FUNCTION_TYPES = {0: "general or unknown", 1: "time response", 2: "auto spectrum", 3: "cross spectrum",
                  4: "frequency response function", 5: "transmissibility", 6: "coherence", 7: "auto correlation",
                  8: "cross correlation", 9: "power spectral density", 10: "energy spectral density",
                  11: "probability density function", 12: "spectrum", 13: "cumulative frequency distribution",
                  14: "peaks valley", 15: "stress/cycles", 16: "strain/cycles", 17: "orbit",
                  18: "mode indicator function", 19: "force pattern", 20: "partial power", 21: "partial coherence",
                  22: "eigenvalue", 23: "eigenvector", 24: "shock response spectrum",
                  25: "finite impulse response filter",
                  26: "multiple coherence", 27: "order function"}
#: Quantity -> (length exponent, force exponent) of its SI unit in a UFF 58 ordinate.
_EXPONENTS = {"displacement": (1, 0), "velocity": (1, 0), "acceleration": (1, 0), "force": (0, 1)}
_TIME = 17
#: UFF 164 units code -> (name, length unit, metres in one, force unit, newtons in one).
_SYSTEMS = {1: ("SI", "m", 1.0, "N", 1.0), 2: ("BG", "ft", 0.3048, "lbf", 4.4482216152605),
            3: ("MG", "m", 1.0, "kgf", 9.80665), 4: ("BA", "ft", 0.3048, "pdl", 0.138254954376),
            5: ("MM", "mm", 1e-3, "mN", 1e-3), 6: ("CM", "cm", 1e-2, "cN", 1e-2),
            7: ("IN", "in", 0.0254, "lbf", 4.4482216152605), 8: ("GM", "mm", 1e-3, "kgf", 9.80665)}
#: Ordinate specific data type -> its unit, for data sets without a unit label, from the length
#: ``L`` and force ``F`` units of the file's system (:data:`_SYSTEMS`).
_SYSTEM_UNITS = {8: "{L}", 9: "{F}", 11: "{L}/s", 12: "{L}/s^2", 13: "{F}"}


def _label(value: Any) -> str:
    text = str(value or "").strip()
    return "" if text.upper() == "NONE" else text


def _system(units: dict[str, Any] | None) -> tuple[str, str] | str:
    """The (length, force) units of a UFF 164 set (None: SI), or why they cannot be taken."""
    if units is None:
        return "m", "N"
    code = int(units.get("units_code", 0))
    factors = (float(units.get("length", 0.0)), float(units.get("force", 0.0)))
    said = (f"the units data set 164 (units code {code} {_label(units.get('units_description'))!r}, length "
            f"factor {factors[0]:g}, force factor {factors[1]:g})")
    if code not in _SYSTEMS:
        return f"names no unit and {said} is not a system duffid knows; label the data set's ordinate unit"
    name, length, metres, force, newtons = _SYSTEMS[code]
    for factor, si in zip(factors, (metres, newtons)):
        if not (np.isclose(factor, 1.0 / si, rtol=1e-5) or np.isclose(factor, si, rtol=1e-5)):
            return (f"names no unit and {said} contradicts itself ({name} is {length} and {force}); "
                    "label the data set's ordinate unit")
    return length, force


def _abscissa(head: dict[str, Any]) -> tuple[float, str]:
    """Seconds per abscissa unit, or 0.0 and why the abscissa is not a time."""
    unit = _label(head.get("abscissa_axis_units_lab"))
    known = lookup(unit) if unit else None
    if not unit or (known is not None and known.quantity == "time"):
        return (known.factor if known else 1.0), ""
    return 0.0, f"has an abscissa in {unit!r}, not a time unit duffid knows (s, ms, us)"


def _channel(path: str, uff: Any, index: int, number: int, head: dict[str, Any],
             units: dict[str, Any] | None = None) -> Channel:
    name = _label(head.get("id1")) or f"set {number}"
    func = int(head.get("func_type", 0))
    problem = ""
    if func != 1:
        problem = (f"is a {FUNCTION_TYPES.get(func, 'function')} (function type {func}); duffid reads time "
                   "responses (type 1)")
    elif int(head.get("ord_data_type", 4)) in (5, 6):
        problem = "holds complex values; a time response is real"
    elif int(head.get("abscissa_spacing", 1)) != 1:
        problem = "has an uneven abscissa; duffid never resamples: write it evenly spaced"
    elif int(head.get("abscissa_spec_data_type", _TIME)) not in (0, _TIME):
        problem = f"has an abscissa of specific data type {head['abscissa_spec_data_type']}, not time (17)"
    seconds, why = _abscissa(head)
    problem = problem or why
    unit = _label(head.get("ordinate_axis_units_lab")) or None
    system = _system(units)
    if unit is None and isinstance(system, str):
        problem = problem or system
    elif unit is None and int(head.get("ordinate_spec_data_type", 0)) in _SYSTEM_UNITS:
        unit = _SYSTEM_UNITS[int(head["ordinate_spec_data_type"])].format(L=system[0], F=system[1])
    elif unit is None and system != ("m", "N"):
        problem = problem or (f"names no unit and is of specific data type {head.get('ordinate_spec_data_type')}, "
                              f"of no unit, in a file whose units data set 164 is in {system[0]} and {system[1]}; "
                              "label its ordinate unit")
    exponents = (int(head.get("ordinate_len_unit_exp", 0)), int(head.get("ordinate_force_unit_exp", 0)))
    known = lookup(unit)
    if not problem and known is not None and exponents != (0, 0) and \
            _EXPONENTS.get(known.quantity, exponents) != exponents:
        problem = (f"names the unit {unit!r} ({known.quantity}) but its ordinate's length and force exponents are "
                   f"{exponents[0]} and {exponents[1]}")
    increment = float(head.get("abscissa_inc", 0.0) or 0.0) * seconds

    def read() -> np.ndarray:
        with reading(path, f"UFF data set {number} {name!r}"):
            return np.asarray(uff.read_sets(index)["data"], dtype=np.float64)

    kind = f"58{'b' if head.get('binary') else ''} {FUNCTION_TYPES.get(func, f'type {func}')}"
    return Channel(name, unit, int(head.get("num_pts", 0)), 1.0 / increment if increment > 0 else None,
                   float(head.get("abscissa_min", 0.0) or 0.0) * seconds, kind,
                   problem=f"data set {number} {problem}" if problem else "",
                   read=read)


@contextmanager
def open_channels(path: str) -> Iterator[list[Channel]]:
    """The data sets 58 of the UFF file ``path`` as channels (headers only until one is read).

    Errors as :mod:`duffid.data.readers` says.
    """
    pyuff = optional_import("pyuff", "UFF files")
    with reading(path, "UFF file"):
        uff = pyuff.UFF(path)
        types = [int(t) for t in uff.get_set_types()]
        heads: dict[int, tuple[dict[str, Any], dict[str, Any] | None]] = {}
        units = None
        for k, kind in enumerate(types):  # a units set 164 holds for the data sets after it
            if kind == 164:
                units = uff.read_sets(k)
            elif kind == 58:
                heads[k] = (uff.read_sets(k, header_only=True), units)
    yield [_channel(path, uff, k, n + 1, head, units) for n, (k, (head, units)) in enumerate(heads.items())]
