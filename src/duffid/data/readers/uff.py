"""Universal File Format data sets 58 and 58b (modal-test software) through pyuff.

Each data set 58 is a channel named by its first ID line (``id1``; its number selects it too).
Only time responses (function type 1) with an evenly spaced time abscissa and real ordinates
make a record; the rate is ``1 / abscissa increment``, the start the abscissa minimum. The unit
is the ordinate's unit label or, without one, the SI unit of its specific data type
(displacement, velocity, acceleration, force); the label must agree with the ordinate's
length and force exponents.

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
#: Ordinate specific data types -> SI unit, for data sets without a unit label.
_DATA_TYPE_UNITS = {8: "m", 9: "N", 11: "m/s", 12: "m/s^2", 13: "N"}
#: Quantity -> (length exponent, force exponent) of its SI unit in a UFF 58 ordinate.
_EXPONENTS = {"displacement": (1, 0), "velocity": (1, 0), "acceleration": (1, 0), "force": (0, 1)}
_TIME = 17


def _label(value: Any) -> str:
    text = str(value or "").strip()
    return "" if text.upper() == "NONE" else text


def _channel(path: str, uff: Any, index: int, number: int, head: dict[str, Any]) -> Channel:
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
    unit = _label(head.get("ordinate_axis_units_lab")) or \
        _DATA_TYPE_UNITS.get(int(head.get("ordinate_spec_data_type", 0)))
    exponents = (int(head.get("ordinate_len_unit_exp", 0)), int(head.get("ordinate_force_unit_exp", 0)))
    known = lookup(unit)
    if not problem and known is not None and exponents != (0, 0) and \
            _EXPONENTS.get(known.quantity, exponents) != exponents:
        problem = (f"names the unit {unit!r} ({known.quantity}) but its ordinate's length and force exponents are "
                   f"{exponents[0]} and {exponents[1]}")
    increment = float(head.get("abscissa_inc", 0.0) or 0.0)

    def read() -> np.ndarray:
        with reading(path, f"UFF data set {number} {name!r}"):
            return np.asarray(uff.read_sets(index)["data"], dtype=np.float64)

    kind = f"58{'b' if head.get('binary') else ''} {FUNCTION_TYPES.get(func, f'type {func}')}"
    return Channel(name, unit, int(head.get("num_pts", 0)), 1.0 / increment if increment > 0 else None,
                   float(head.get("abscissa_min", 0.0) or 0.0), kind,
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
        heads = {k: uff.read_sets(k, header_only=True) for k, t in enumerate(types) if t == 58}
    yield [_channel(path, uff, k, n + 1, head) for n, (k, head) in enumerate(heads.items())]
