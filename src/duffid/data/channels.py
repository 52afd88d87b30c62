"""Channels of a record file, and how the selected ones become a record's time, forces and
displacements.

Every reader (:mod:`duffid.data.readers`) describes what a file holds as a list of
:class:`Channel` (name, unit, rate, start time, length) that read their values only when asked.
:func:`select` says which channel plays which role (``t``, ``f``, ``x``, ``v``, ``a``, numbered
``f1``, ``x2``, ... for several degrees of freedom), from the user's selection or, without one,
from the channels' units and names. :func:`assemble` reads the selected channels, converts them
to SI (:mod:`duffid.data.units`) and checks that they share one rate, one start time and one
length: duffid never resamples, aligns, clips or drops samples.
"""
from __future__ import annotations

import math
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from ..errors import RecordError
from .units import QUANTITY_OF_ROLE, ROLE_QUANTITIES, lookup, si_factor

__all__ = ["Channel", "READ_PART", "UNIT_IN_NAME", "unit_in_name", "unit_suffix", "ROLE_PATTERN", "MOTION_NOT_YET", "MOTION_FAMILIES",
           "FAMILY_WORDS", "numeric", "check_roles", "channel_table", "select", "motion_of", "assemble",
           "check_source_voltage"]

#: A role of the selection syntax: ``t``, ``f``, ``x``, ``v``, ``a`` or numbered ``f1``, ``x2``, ...
#: Samples a streaming reader delivers at a time (8 MB of float64).
READ_PART = 1 << 20
ROLE_PATTERN = re.compile(r"[tfxva]|[fxva][1-9][0-9]*", re.ASCII)
#: Where velocity and acceleration channels are read (elsewhere a displacement is needed).
MOTION_NOT_YET = ("velocity (v) and acceleration (a) channels are identified by duffid identify "
                  "(duffid.identification.motion.identify_motion); here a displacement is needed: select a "
                  "displacement channel as x")
#: The motion families a record's motion columns may measure.
MOTION_FAMILIES = ("x", "v", "a")
_NAME_HINTS = {
    "time": re.compile(r"t|time|times?tamp|zeit", re.I),
    "force": re.compile(r"f\d*|force\w*|load\w*|kraft", re.I),
    "displacement": re.compile(r"x\d*|disp\w*|displacement\w*|position\w*", re.I),
    "velocity": re.compile(r"v\d*|vel\w*|velocity\w*", re.I),
    "acceleration": re.compile(r"a\d*|acc\w*|accel\w*|acceleration\w*", re.I),
}
#: What a role family holds, in words (plural).
FAMILY_WORDS = {"f": "forces", "x": "displacements", "v": "velocities", "a": "accelerations"}
#: A unit at the end of a channel's name, ``force (kN)`` or ``x [mm]``: read as the channel's unit
#: when its metadata give none (a text with a letter; not an axis letter X, Y, Z, nor a MATLAB
#: column ``data(:,2)``).
UNIT_IN_NAME = re.compile(r"[(\[]\s*([^()\[\]:,]*[^\W\d_][^()\[\]:,]*?)\s*[)\]]\s*$")
_AXIS_LABELS = frozenset("xyzXYZ")


def unit_in_name(name: str) -> str | None:
    """The unit closing ``name`` in brackets (:data:`UNIT_IN_NAME`; None: none)."""
    found = UNIT_IN_NAME.search(name)
    return found.group(1) if found and found.group(1) not in _AXIS_LABELS else None


#: What separates a unit ending a channel's name from the rest (``load_kN``, ``acc.mm.s2``).
_NAME_SEPARATORS = re.compile(r"[_.\- ]+")


def unit_suffix(name: str, role: str) -> str | None:
    """A unit of ``role``'s quantity ending ``name`` after a separator (``load_kN``: ``kN``,
    ``acc_mm_s2``: ``mm/s2``, ``time_ms``: ``ms``); None when no known unit does.

    Parameters
    ----------
    name : str
        The channel's name (a CSV column's header).
    role : str
        ``t``, ``f``, ``x``, ``v``, ``a`` or numbered (``f1``): only its quantity's units count
        (``f_in``, an input force, names no force unit).
    """
    parts = [p for p in _NAME_SEPARATORS.split(name.strip()) if p]
    for k in (2, 1):  # "mm_s2" before "s2"
        if len(parts) > k:
            text = "/".join(parts[-k:])
            unit = lookup(text)
            if unit is not None and unit.quantity in ROLE_QUANTITIES[role[0]]:
                return text
    return None


def numeric(dtype: np.dtype) -> bool:
    """Whether values of ``dtype`` are real numbers (not text, timestamps, compound, complex or boolean)."""
    return bool(np.issubdtype(dtype, np.integer) or np.issubdtype(dtype, np.floating))


@dataclass(frozen=True)
class Channel:
    """One signal of a file, described from its metadata; its values are read by :attr:`read`.

    Parameters
    ----------
    name : str
        How the user selects it: ``group/channel`` (TDMS), a dataset path (HDF5, MATLAB v7.3),
        a channel number (WAV), a data set's name (UFF), a column or variable name.
    unit : str or None
        The unit the file names (None: none; the values are then taken as SI). Without one, a
        unit closing the name in brackets (:data:`UNIT_IN_NAME`) is the channel's.
    length : int
        Number of samples.
    rate : float or None, optional
        Sampling rate [Hz] the metadata give (None: none; the time comes from a time channel
        or the user's sampling rate).
    start : float, optional
        Time of the first sample [s] (TDMS ``wf_start_offset``, UFF abscissa minimum).
    kind : str, optional
        How the values are stored, for listings (``float64``, ``PCM int16``, ...).
    needs_scale : str, optional
        Non-empty when the values mean nothing without the user's scale (integer PCM): why.
    problem : str, optional
        Non-empty when the channel cannot be part of a record (a frequency response, complex
        values, text): why.
    read : callable, optional
        Returns the values as a 1-D float64 array (the file must still be open).
    read_part : callable, optional
        ``read_part(start, stop)`` returns the values ``[start, stop)`` (streaming readers: a
        large channel is then read in parts of :data:`READ_PART` samples, never whole).
    """

    name: str
    unit: str | None
    length: int
    rate: float | None = None
    start: float = 0.0
    kind: str = "float64"
    needs_scale: str = ""
    problem: str = ""
    read: Callable[[], np.ndarray] = field(default=lambda: np.empty(0), repr=False, compare=False)
    read_part: Callable[[int, int], np.ndarray] | None = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.unit is None or not self.unit.strip():  # none in the metadata: one in the name?
            object.__setattr__(self, "unit", unit_in_name(self.name))

    @property
    def quantity(self) -> str | None:
        """What the channel measures, from its unit, else from its name (None: cannot tell)."""
        unit = lookup(self.unit)
        if unit is not None:
            return unit.quantity
        if self.unit and self.unit.strip():
            return None
        last = re.split(r"[/.:]", re.sub(r"\(.*\)$", "", self.name).strip("/"))[-1].strip()
        hits = [q for q, pattern in _NAME_HINTS.items() if pattern.fullmatch(last)]
        return hits[0] if len(hits) == 1 else None

    def describe(self) -> str:
        """``'name' [unit, rate Hz, n samples]``, as listings and messages show it."""
        rate = f"{self.rate:g} Hz" if self.rate else "no rate"
        start = f", starts at {self.start:g} s" if self.start else ""
        return f"{self.name!r} [{self.unit or 'no unit'}, {rate}{start}, {self.length} samples]"


def channel_table(channels: Sequence[Channel]) -> list[dict[str, object]]:
    """One row per channel (number, name, unit, quantity, rate, start, length, kind), for listings."""
    return [{"number": k + 1, "name": c.name, "unit": c.unit or "", "quantity": c.quantity or "",
             "rate": c.rate, "start": c.start, "length": c.length, "kind": c.kind,
             "note": c.problem or c.needs_scale}
            for k, c in enumerate(channels)]


def motion_of(roles: Sequence[str]) -> str:
    """The motion family (``x``, ``v`` or ``a``) of checked roles (:func:`check_roles`)."""
    return next((r[0] for r in roles if r[0] in MOTION_FAMILIES), "x")


def check_roles(roles: Sequence[str], source: str, *, motion: bool = False
                ) -> tuple[str | None, list[str], list[str]]:
    """Validate the roles of a selection; return the time role and the force and motion roles.

    ``motion``: velocities (``v``) or accelerations (``a``) may take the displacements' place
    (one kind of motion for every DOF; :func:`motion_of` tells which).

    Raises
    ------
    RecordError
        An unknown role, ``f`` with ``f1``, numbering with gaps, no force or motion, more
        forces than motion channels, two kinds of motion, or a velocity or acceleration where
        ``motion`` is false.
    """
    for role in roles:
        if not ROLE_PATTERN.fullmatch(str(role)):
            raise RecordError(f"{source}: unknown role {role!r} (roles: t, f, x, v, a, or f1.., x1.., v1.., a1..)")
    families: dict[str, list[str]] = {}
    for fam in "fxva":
        plain = fam in roles
        numbered = sorted(int(r[1:]) for r in roles if r[0] == fam and len(r) > 1)
        if plain and numbered:
            raise RecordError(f"{source}: give either {fam} or {fam}1, {fam}2, ... for the channels, not both")
        if numbered and numbered != list(range(1, len(numbered) + 1)):
            raise RecordError(f"{source}: the {fam} channels must be numbered {fam}1..{fam}{len(numbered)} "
                              f"without gaps, got {', '.join(f'{fam}{j}' for j in numbered)}")
        families[fam] = [fam] if plain else [f"{fam}{j}" for j in numbered]
    kinds = [fam for fam in MOTION_FAMILIES if families[fam]]
    other = families["v"] + families["a"]
    if other and not motion:
        what = "a velocity" if families["v"] else "an acceleration"
        named = ", ".join(other)
        if families["x"]:
            raise RecordError(f"{source}: {named} selects {what} channel, which duffid would not use here: "
                              f"drop {named} from the selection")
        raise RecordError(f"{source}: {named} selects {what} channel and no displacement: {MOTION_NOT_YET}")
    if len(kinds) > 1:
        raise RecordError(f"{source}: the selection mixes {' and '.join(FAMILY_WORDS[k] for k in kinds)}; give one "
                          "kind of motion (x, v or a) for every DOF")
    fam = kinds[0] if kinds else "x"
    if not families["f"]:
        raise RecordError(f"{source}: no channel given for f (the forces)")
    if not families[fam]:
        raise RecordError(f"{source}: no channel given for x (the displacements"
                          + (", or v / a: velocities or accelerations)" if motion else ")"))
    if len(families["f"]) > len(families[fam]):
        raise RecordError(f"{source}: {len(families['f'])} force channels but {len(families[fam])} "
                          f"{FAMILY_WORDS[fam][:-1]} channels; force j acts on DOF j, so there may not be more forces "
                          "than motion channels")
    return ("t" if "t" in roles else None), families["f"], families[fam]


def _listing(channels: Sequence[Channel]) -> str:
    return "; ".join(f"{k + 1}: {c.describe()}" for k, c in enumerate(channels)) or "none"


def _find(spec: str | int, role: str, channels: Sequence[Channel], source: str) -> Channel:
    """The channel ``spec`` names (its name, or its 1-based number)."""
    if isinstance(spec, (int, np.integer)) and not isinstance(spec, bool) or str(spec).isdigit():
        number = int(spec)
        if not 1 <= number <= len(channels):
            raise RecordError(f"{source}: no channel {number} for {role}: the file has {len(channels)} "
                              f"(channels: {_listing(channels)})")
        return channels[number - 1]
    wanted = str(spec).strip().strip("/")
    hits = [c for c in channels if c.name.strip("/") == wanted]
    if not hits:
        raise RecordError(f"{source}: no channel {str(spec)!r} for {role} (channels: {_listing(channels)})")
    if len(hits) > 1:
        raise RecordError(f"{source}: {len(hits)} channels are named {str(spec)!r}; give the channel's number "
                          f"instead (channels: {_listing(channels)})")
    return hits[0]


def select(channels: Sequence[Channel], columns: Mapping[str, str | int] | None, source: str, *,
           time: bool = True, motion: bool = False) -> dict[str, Channel]:
    """Which channel plays which role.

    Parameters
    ----------
    channels : sequence of Channel
        What the file holds.
    columns : mapping or None
        Role -> channel name or 1-based number (``{"f": "Data/force", "x": "Data/disp"}``).
        None: a file with exactly one force channel and one motion channel (by their units, else
        their names), besides time channels, is read as such.
    source : str
        The file, for messages.
    time : bool, optional
        Without ``columns``: whether a lone time channel may play ``t`` (False when the user gives
        the sampling rate).
    motion : bool, optional
        Whether a velocity or acceleration channel may take the displacement's place (the
        roles ``v``, ``a``; :func:`check_roles`).

    Returns
    -------
    dict
        Role -> channel, time first (when a time channel plays ``t``), then forces, then
        displacements.

    Raises
    ------
    RecordError
        A channel that is not there, a role that is not known, a velocity or acceleration, or a
        file whose channels do not say which is which (the message lists them with their units).
    """
    allow_motion = motion
    if columns is not None:
        t_role, f_roles, x_roles = check_roles(list(columns), source, motion=allow_motion)
        roles = ([t_role] if t_role else []) + f_roles + x_roles
        chosen = {role: _find(columns[role], role, channels, source) for role in roles}
        names = [c.name for c in chosen.values()]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise RecordError(f"{source}: channel {twice[0]!r} is selected for two roles "
                              f"({', '.join(r for r, c in chosen.items() if c.name == twice[0])})")
        return chosen
    kinds: dict[str, list[Channel]] = {}
    for channel in channels:
        kinds.setdefault(QUANTITY_OF_ROLE.get(channel.quantity or "", "?"), []).append(channel)
    forces, times = kinds.get("f", []), kinds.get("t", [])
    motion = [c for fam in "xva" for c in kinds.get(fam, [])]
    if len(forces) == 1 and len(motion) == 1 and "?" not in kinds:
        fam = QUANTITY_OF_ROLE[motion[0].quantity or ""]
        if fam != "x" and not allow_motion:
            raise RecordError(f"{source}: channel {motion[0].name!r} measures {motion[0].quantity} "
                              f"({motion[0].unit or 'by its name'}): {MOTION_NOT_YET}")
        chosen = {"f": forces[0], fam: motion[0]}
        if time and len(times) == 1 and not (forces[0].rate and motion[0].rate):
            chosen = {"t": times[0], **chosen}
        return chosen
    strange = [c for c in channels if c.unit and c.unit.strip() and lookup(c.unit) is None]
    unknown = (f"; unknown unit{'s' if len(strange) > 1 else ''}: "
               + ", ".join(f"{c.name!r} in {c.unit!r}" for c in strange)) if strange else ""
    raise RecordError(f"{source}: cannot tell which channel is the force and which the displacement "
                      f"({len(forces)} force and {len(motion)} motion channels found by unit or name{unknown}); "
                      f"select them, e.g. --columns f=NAME,x=NAME (channels: {_listing(channels)})")


def _quantity(unit: str | None) -> str | None:
    known = lookup(unit)
    return known.quantity if known is not None else None


def check_source_voltage(source: str, force: str, unit: str, motion: Mapping[str, str | None]) -> None:
    """A force role in volts is the circuit's source voltage: its motion must then be a charge (C).
    With a displacement, velocity, acceleration or no unit it is a sensor's output voltage, which
    needs its sensitivity: RecordError naming the channels (``motion``: name -> unit)."""
    others = {name: unit_ for name, unit_ in motion.items() if _quantity(unit_) != "charge"}
    if others:
        name, other = next(iter(others.items()))
        said = f"in {other!r}" if other else "without a unit"
        raise RecordError(f"{source}: channel {force!r} is in {unit!r} but {name!r} is {said}, not a charge (C): a "
                          "force in volts is a sensor's output; give its sensitivity as --scale f=FACTOR (N per V), "
                          "or, for the circuit, the charge's unit C")


def _same(a: float, b: float) -> bool:
    return math.isclose(a, b, rel_tol=1e-9, abs_tol=0.0)


def assemble(chosen: Mapping[str, Channel], source: str, *, scale: Mapping[str, float] | None = None,
             fs: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read the chosen channels into SI time, force and displacement arrays.

    Parameters
    ----------
    chosen : mapping
        Role -> channel, as :func:`select` returns it.
    source : str
        The file, for messages.
    scale : mapping, optional
        Role (or family ``f``, ``x``, ``t``) -> factor into SI; replaces the unit's factor.
    fs : float, optional
        Sampling rate [Hz] for channels whose metadata give none (and no time channel).

    Returns
    -------
    t, f, x : numpy.ndarray
        Read-only float64 arrays of shapes ``(N,)``, ``(N, nf)`` and ``(N, nx)``; ``x`` holds
        the motion the roles select (:func:`motion_of`: displacements, velocities or
        accelerations).

    Raises
    ------
    RecordError
        Channels of different lengths, rates or start times (naming both), no rate at all, a
        rate given twice, or a unit that cannot be brought into SI (naming channel and unit).
    """
    scale = dict(scale or {})
    roles = list(chosen)
    unknown = sorted(set(scale) - set(roles) - {r[0] for r in roles})
    if unknown:
        raise RecordError(f"{source}: a scale for {', '.join(unknown)}, which selects no channel")
    for role in roles:  # a channel that cannot be part of a record, before anything else about it
        if chosen[role].problem:
            raise RecordError(f"{source}, channel {chosen[role].name!r}: {chosen[role].problem}")
    first = chosen[roles[0]]
    for role in roles[1:]:
        other = chosen[role]
        if other.length != first.length:
            raise RecordError(f"{source}: channel {first.name!r} has {first.length} samples but {other.name!r} has "
                              f"{other.length}; duffid never clips: give channels of one length")
    data_roles = [r for r in roles if r != "t"]
    rated = [chosen[r] for r in data_roles if chosen[r].rate]
    for other in rated[1:]:
        if not _same(other.rate, rated[0].rate):  # type: ignore[arg-type]
            raise RecordError(f"{source}: channel {rated[0].name!r} is sampled at {rated[0].rate:.12g} Hz but "
                              f"{other.name!r} at {other.rate:.12g} Hz; duffid never resamples: resample them to "
                              "one rate first")
        dt = 1.0 / rated[0].rate  # type: ignore[operator]
        if abs(other.start - rated[0].start) > 1e-6 * dt:
            raise RecordError(f"{source}: channel {rated[0].name!r} starts at {rated[0].start:.12g} s but "
                              f"{other.name!r} at {other.start:.12g} s; duffid never shifts or clips: give "
                              "channels that start together")
    if rated and len(rated) != len(data_roles):
        bare = next(chosen[r] for r in data_roles if not chosen[r].rate)
        raise RecordError(f"{source}: channel {rated[0].name!r} has a sampling rate ({rated[0].rate:g} Hz) but "
                          f"{bare.name!r} has none; select channels of one kind")
    if "t" in chosen and fs is not None:
        raise RecordError(f"{source}: a time channel and a sampling rate were both given; give one of them")
    if rated and fs is not None and not _same(fs, rated[0].rate):  # type: ignore[arg-type]
        raise RecordError(f"{source}: the sampling rate given ({fs:g} Hz) differs from the file's "
                          f"({rated[0].rate:.12g} Hz of channel {rated[0].name!r})")
    if "t" not in chosen and not rated and fs is None:
        raise RecordError(f"{source}: no sampling rate: channels {', '.join(repr(chosen[r].name) for r in roles)} "
                          "carry none; give the sampling rate (--fs) or a time channel (t=)")

    factors = {}  # every unit and scale is checked before anything is read
    for role in roles:
        channel = chosen[role]
        where = f"{source}, channel {channel.name!r}"
        given = scale.get(role, scale.get(role[0]))
        if channel.needs_scale and given is None:
            raise RecordError(f"{where}: {channel.needs_scale}; give --scale {role}=FACTOR")
        factors[role] = si_factor(channel.unit, role, where, given)
    voltages = [r for r in data_roles if r[0] == "f" and scale.get(r, scale.get("f")) is None
                and _quantity(chosen[r].unit) == "voltage"]
    if voltages:  # the circuit's source voltage, never a force sensor's output
        check_source_voltage(source, chosen[voltages[0]].name, chosen[voltages[0]].unit or "V",
                             {chosen[r].name: chosen[r].unit for r in data_roles if r[0] != "f"})

    def values(role: str, out: np.ndarray | None = None) -> np.ndarray:
        channel = chosen[role]

        def checked(raw: np.ndarray, length: int, where: str = "") -> np.ndarray:
            if raw.shape != (length,):
                raise RecordError(f"{source}, channel {channel.name!r}: read {raw.shape} values{where}, the metadata "
                                  f"say {length}")
            return raw

        if channel.read_part is not None:  # streamed: at most READ_PART samples beyond the result
            if out is None:
                out = np.empty(channel.length, dtype=np.float64)
            for start in range(0, channel.length, READ_PART):
                stop = min(start + READ_PART, channel.length)
                out[start:stop] = checked(channel.read_part(start, stop), stop - start,
                                          f" from sample {start}")
        else:
            raw = checked(channel.read(), channel.length)
            if out is None:
                out = np.asarray(raw, dtype=np.float64)
                if out is raw and not (out.flags.owndata and out.flags.writeable):
                    out = out.copy()  # the reader's buffer (a memory map, a cache) is never written
            else:
                out[:] = raw
            del raw
        bad = np.flatnonzero(~np.isfinite(out))
        if bad.size:  # named here, where the channel is known (the record's own check knows its role only)
            many = f" ({bad.size} such samples)" if bad.size > 1 else ""
            raise RecordError(f"{source}, channel {channel.name!r}: sample {int(bad[0]) + 1} of {channel.length} is "
                              f"{float(out[bad[0]])}{many}; duffid never drops or fills samples: give a record without "
                              "gaps")
        if factors[role] != 1.0:
            out *= factors[role]
        return out

    n = first.length
    columns: dict[str, np.ndarray] = {}
    for fam in ("f", motion_of(data_roles)):  # the motion columns: displacements, velocities or accelerations
        members = [r for r in data_roles if r[0] == fam]
        block = np.empty((n, len(members)), dtype=np.float64)
        for j, role in enumerate(members):
            values(role, block[:, j])
        columns[fam] = block
    if "t" in chosen:
        t = values("t")
        step = (t[-1] - t[0]) / (n - 1) if n > 1 else math.nan
        if rated and not math.isclose(step * rated[0].rate, 1.0, rel_tol=1e-6):
            raise RecordError(f"{source}: the time channel {chosen['t'].name!r} steps by {step:.12g} s but channel "
                              f"{rated[0].name!r} is sampled at {rated[0].rate:.12g} Hz; give one of them")
    else:
        rate = rated[0].rate if rated else fs
        start = rated[0].start if rated else 0.0
        t = np.arange(n, dtype=np.float64)
        t /= rate
        if start:
            t += start
    motion = columns[motion_of(data_roles)]
    for arr in (t, columns["f"], motion):
        arr.setflags(write=False)
    return t, columns["f"], motion
