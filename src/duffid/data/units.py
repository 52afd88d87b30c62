"""The units a record file's metadata may name, what each measures and its factor into SI.

One table, :data:`UNITS`, answers "what is ``mm/s^2`` and how many ``m/s^2`` is one of it?"
for every reader (TDMS ``unit_string``, UFF ordinate labels, HDF5 ``unit`` attributes, SEP-005
``unit_str``, CSV units rows). A record's roles take these quantities (:data:`ROLE_QUANTITIES`):
time ``t`` in s, forces ``f`` in N (or V, the circuit's source voltage), displacements ``x`` in
m (or C, the circuit's charge), velocities ``v`` in m/s and accelerations ``a`` in m/s^2.

A sensor voltage (``mV``, or ``V`` on a motion channel) is not a physical quantity until its
sensitivity is known: the user gives it as a scale; :func:`si_factor` says so when it is
missing.
"""
from __future__ import annotations

from dataclasses import dataclass

from ..errors import RecordError

__all__ = ["Unit", "UNITS", "ROLE_QUANTITIES", "QUANTITY_OF_ROLE", "STANDARD_GRAVITY", "lookup", "si_factor",
           "si_unit"]

#: Standard acceleration of gravity [m/s^2] (the ``g`` of accelerometers).
STANDARD_GRAVITY = 9.80665


@dataclass(frozen=True)
class Unit:
    """A unit: the quantity it measures, the SI unit of that quantity and its factor into it.

    Parameters
    ----------
    quantity : str
        ``time``, ``force``, ``voltage``, ``displacement``, ``charge``, ``velocity`` or
        ``acceleration``.
    si : str
        The SI unit of the quantity (``s``, ``N``, ``V``, ``m``, ``C``, ``m/s``, ``m/s^2``).
    factor : float
        SI units per unit (``mm``: 1e-3).
    """

    quantity: str
    si: str
    factor: float


_SI = {"time": "s", "force": "N", "voltage": "V", "displacement": "m", "charge": "C", "velocity": "m/s",
       "acceleration": "m/s^2"}


def si_unit(quantity: str) -> str:
    """The SI unit duffid uses for ``quantity`` (``"acceleration"``: ``"m/s^2"``)."""
    return _SI[quantity]


def _table() -> dict[str, Unit]:
    entries = {
        "time": {"s": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6},
        "force": {"N": 1.0, "kN": 1e3, "mN": 1e-3},
        "voltage": {"V": 1.0, "mV": 1e-3, "kV": 1e3},
        "displacement": {"m": 1.0, "cm": 1e-2, "mm": 1e-3, "um": 1e-6, "µm": 1e-6, "nm": 1e-9},
        "charge": {"C": 1.0, "mC": 1e-3, "uC": 1e-6, "µC": 1e-6, "nC": 1e-9},
        "velocity": {"m/s": 1.0, "mm/s": 1e-3, "um/s": 1e-6, "µm/s": 1e-6},
        "acceleration": {"m/s^2": 1.0, "mm/s^2": 1e-3, "g": STANDARD_GRAVITY},
    }
    return {name: Unit(quantity, _SI[quantity], factor)
            for quantity, units in entries.items() for name, factor in units.items()}


#: Unit string (normalised by :func:`lookup`) -> :class:`Unit`.
UNITS: dict[str, Unit] = _table()
#: Record role family -> the quantities a channel in that role may measure (first: the usual one).
ROLE_QUANTITIES = {"t": ("time",), "f": ("force", "voltage"), "x": ("displacement", "charge"),
                   "v": ("velocity",), "a": ("acceleration",)}
#: Quantity -> the role family that holds it.
QUANTITY_OF_ROLE = {"time": "t", "force": "f", "voltage": "f", "displacement": "x", "charge": "x",
                    "velocity": "v", "acceleration": "a"}
#: Spellings metadata uses for the same unit (after removing spaces).
_ALIASES = {"μ": "µ", "²": "^2", "**2": "^2", "s2": "s^2", "/s/s": "/s^2", "sec": "s"}


def _normalise(unit: str) -> str:
    text = "".join(unit.split())
    for old, new in _ALIASES.items():
        text = text.replace(old, new)
    return {"gn": "g", "g0": "g", "G": "g"}.get(text, text)


def lookup(unit: str | None) -> Unit | None:
    """The :class:`Unit` a metadata string names, or None (no unit, or one duffid does not know).

    Parameters
    ----------
    unit : str or None
        As the file writes it: ``"mm/s^2"``, ``"mm/s²"``, ``"m/s2"``, ``"µm"``, ``"um"``,
        ``"μm"`` (Greek mu), ``"g"``, ``"kN"``, ...
    """
    if unit is None:
        return None
    return UNITS.get(_normalise(unit))


def si_factor(unit: str | None, role: str, where: str, scale: float | None = None) -> float:
    """The factor that brings a channel's values into SI for ``role``.

    Parameters
    ----------
    unit : str or None
        The channel's unit from the file (None: the file names none; the values are taken as SI).
    role : str
        ``t``, ``f``, ``x``, ``v``, ``a`` or numbered (``f1``, ``x2``).
    where : str
        The file and channel, for messages (``"rig.tdms, channel 'Data/force'"``).
    scale : float, optional
        The user's factor (``--scale``): it replaces the unit's factor (a sensitivity, a unit
        duffid does not know).

    Returns
    -------
    float

    Raises
    ------
    RecordError
        A unit duffid does not know, a unit of another quantity than the role's, or a sensor
        voltage without its sensitivity; the message names the channel, the unit and the
        ``--scale`` to give.
    """
    family = role[0]
    if scale is not None:
        return float(scale)
    if unit is None or not unit.strip():
        return 1.0
    known = lookup(unit)
    si = _SI[ROLE_QUANTITIES[family][0]]
    if known is None:
        raise RecordError(f"{where}: unit {unit!r} is not one duffid knows (known: {', '.join(UNITS)}); give the "
                          f"factor into {si} with --scale {role}=FACTOR")
    if known.quantity == "voltage" and not (family == "f" and known.factor == 1.0):
        raise RecordError(f"{where}: unit {unit!r} is a sensor voltage; give its sensitivity as --scale "
                          f"{role}=FACTOR ({si} per {unit.strip()}, i.e. 1 / the sensitivity in {unit.strip()}/{si})")
    if known.quantity not in ROLE_QUANTITIES[family]:
        raise RecordError(f"{where}: unit {unit!r} measures {known.quantity}, not the "
                          f"{ROLE_QUANTITIES[family][0]} that {role} needs (in {si})")
    return known.factor
