"""The elements of a co-simulated system: components (FMUs) and their variables (of every
FMI type, arrays by element: :mod:`duffid.cosim.value_types`), connections, external inputs, and
what a run returns (results, failures, errors)."""
from __future__ import annotations

import csv
import difflib
import numbers
import os
import re
import xml.etree.ElementTree as ET
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Protocol, Sequence, Union, runtime_checkable

import numpy as np

from ..errors import CosimError, InputError, WiringError
from ..fmu.fmi_xml import declares_sampled_inputs
from .value_types import DTYPES, VARIABLE_KINDS, check_value, csv_text, element_names, flat_index, split_element

__all__ = ["InputSource", "VARIABLE_KINDS", "STATUS_NAMES", "NAME_RE", "N_MESSAGES", "N_REPORTED", "DTYPES",
           "WiringError", "Connection", "Failure", "CosimError", "Result", "with_article", "suggest", "unit_of",
           "Component", "typed_parameter", "typed_parameter_values", "External", "check_external_value",
           "sampled_on_grid", "INTERPOLATIONS", "ORDERINGS", "Wiring", "WiredSystem", "SystemLike"]

#: Source of an external input: a constant (of the input's type: a number, bool, str, bytes, or a
#: nested sequence for an array), a function of time, or samples ``(t, values)``.
InputSource = Union[float, int, bool, str, bytes, Sequence, Callable[[float], Any], tuple]

STATUS_NAMES = {0: "OK", 1: "Warning", 2: "Discard", 3: "Error", 4: "Fatal", 5: "Pending"}
#: Accepted values of ``System.run(ordering=...)``.
ORDERINGS = ("jacobi", "gauss-seidel")
NAME_RE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
N_MESSAGES = 200      # log messages kept per component
N_REPORTED = 8        # log messages quoted in a CosimError




@dataclass(frozen=True)
class Connection:
    """A connection from ``source`` (an output, ``"component.variable"``) to ``target``
    (an input).

    Attributes
    ----------
    source, target : str
        ``"component.output"`` and ``"component.input"``.
    factor, offset : float
        The target receives ``factor * source + offset`` (1 and 0: the value itself; an SSP
        linear transformation or unit conversion). Real connections only.
    check_units : bool
        Whether the declared units were required to agree (False: a unit-generic FMU).
    """

    source: str
    target: str
    factor: float = 1.0
    offset: float = 0.0
    check_units: bool = True

    @property
    def transformed(self) -> bool:
        """Whether the connection changes the value (a factor other than 1 or an offset)."""
        return self.factor != 1.0 or self.offset != 0.0

    def __str__(self) -> str:
        if not self.transformed:
            return f"{self.source} -> {self.target}"
        return f"{self.source} -> {self.target} (x {self.factor!r} + {self.offset!r})"


@dataclass(frozen=True)
class Failure:
    """Why a run stopped.

    Attributes
    ----------
    component : str or None
        Component name (None for an interruption outside any component).
    fmu : Path or None
        Its FMU file.
    time : float
        Communication point at which the failing call was made (``t_k`` for a ``doStep``
        from ``t_k``), or the time an input function was evaluated at.
    function : str
        The FMI function (``"fmi2DoStep"``, ``"fmi3SetFloat64"``, ...), or
        ``"input function of plant.f"`` / ``"run"`` for Python exceptions.
    status : str
        ``"Discard"``, ``"Error"``, ``"Fatal"``, ``"Pending"``, ``"terminateSimulation"``,
        or the Python exception (``"ZeroDivisionError: ..."``).
    messages : tuple of str
        The component's last logged messages (``"[Error] category: text"``).
    """

    component: str | None
    fmu: Path | None
    time: float
    function: str
    status: str
    messages: tuple[str, ...] = ()

    def __str__(self) -> str:
        where = f"component {self.component!r} ({self.fmu})" if self.component else "the run"
        text = f"{where}: {self.function} returned {self.status} at t = {self.time!r}" if \
            self.function.startswith("fmi") else f"{where}: {self.function} failed at t = {self.time!r}: {self.status}"
        if self.messages:
            text += "\n  last logged messages:\n" + "\n".join(f"    {m}" for m in self.messages)
        elif self.function.startswith("fmi"):  # a silent FMU call (not a Python input function)
            text += (" (nothing was logged; some FMUs, e.g. pythonfmu ones, log only with logging on: "
                     "System.add(..., logging=True))")
        return text




@dataclass
class Result:
    """Values recorded on the communication grid.

    Attributes
    ----------
    time : numpy.ndarray
        ``t_0 .. t_m`` (``m = n`` for a complete run).
    names : list of str
        Recorded variables, ``"component.variable"``.
    order : list of str
        Components in stepping order (insertion order under Jacobi).
    delayed : list of Connection
        Connections that deliver the source's value at ``t_k`` to a step from ``t_k``
        (all of them under Jacobi; the feedback connections under Gauss-Seidel).
    ordering : str
        ``"jacobi"`` or ``"gauss-seidel"``.
    step : float
        Communication step [s].
    failure : Failure or None
        Why the run failed (None for a complete run or one a component ended).
    ended : str or None
        Which component ended the simulation before the stop time, and when (an FMU's
        request: FMI 2 Discard with fmi2Terminated, FMI 3 terminateSimulation); None when
        the run reached the stop time or failed.
    warnings : list of str
        What the run could not do as a user may expect, in plain words (FMI 3 aliases
        recorded once, a communication step shorter than an FMU's fixed internal step).
    loop : str
        The inner loop that ran: ``"compiled"`` (C) or ``"python"`` (see ``System.run(loop=)``).
    kinds : dict
        Recorded name -> the kind of its values (:data:`duffid.cosim.value_types.VARIABLE_KINDS`).
    """

    time: np.ndarray
    names: list[str]
    _columns: dict[str, np.ndarray] = field(repr=False)
    order: list[str] = field(default_factory=list)
    delayed: list[Connection] = field(default_factory=list)
    ordering: str = "jacobi"
    step: float = 0.0
    failure: Failure | None = None
    ended: str | None = None
    warnings: list[str] = field(default_factory=list)
    loop: str = "python"
    kinds: dict[str, str] = field(default_factory=dict)

    def __getitem__(self, name: str) -> np.ndarray:
        """The column of ``"component.variable"`` (an array element: ``"component.y[1,2]"``):
        float64 for Real, float32, int8 .. uint64 for the FMI 3 types of those names, int32
        for Integer, int64 for Enumeration, bool for Boolean, objects (str, bytes) for String
        and Binary."""
        try:
            return self._columns[name]
        except KeyError:
            raise KeyError(f"{name!r} was not recorded{suggest(name, self.names)}") from None

    def __contains__(self, name: object) -> bool:
        return name in self._columns

    def __len__(self) -> int:
        return len(self.time)

    def to_csv(self, path: str | os.PathLike[str]) -> None:
        """Write one header line (``time`` and :attr:`names`) and one row per
        communication point; floats in full precision (``repr``), integer types and
        Booleans as integers (Booleans as 0/1), Strings as text (quoted where CSV needs it),
        Binary values as hexadecimal (:func:`duffid.cosim.value_types.csv_text`)."""
        columns = [[repr(v) for v in self.time.tolist()]]
        for name in self.names:
            kind = self.kinds.get(name) or ("Boolean" if self._columns[name].dtype.kind == "b" else
                                            "Integer" if self._columns[name].dtype.kind in "iu" else "Real")
            columns.append([csv_text(kind, v) for v in self._columns[name].tolist()])
        with open(os.fspath(path), "w", newline="", encoding="utf-8") as fh:
            writer = csv.writer(fh, lineterminator="\n")
            writer.writerow(["time"] + self.names)
            writer.writerows(zip(*columns))


# --------------------------------------------------------------------------------- model info
def with_article(word: str) -> str:
    """``"an output"``, ``"a parameter"``."""
    return f"{'an' if word[:1] in 'aeiou' else 'a'} {word}"


def suggest(name: str, candidates: Iterable[str]) -> str:
    """"; did you mean ...?" with the candidates close to ``name`` (empty when none is)."""
    close = difflib.get_close_matches(name, list(candidates), n=3, cutoff=0.6)
    return f"; did you mean {' or '.join(repr(c) for c in close)}?" if close else ""


def unit_of(variable: Any) -> str | None:
    """The unit of an fmpy model variable, its declared type's when it has none of its own."""
    unit = getattr(variable, "unit", None)
    if unit is None and getattr(variable, "declaredType", None) is not None:
        unit = variable.declaredType.unit
    return unit or None


def _reads_sampled_inputs(path: Path) -> bool:
    """Whether the FMU at ``path`` declares that it reads its inputs as samples of one instant
    (duffid's annotation :data:`~duffid.fmu.fmi_xml.SAMPLED_INPUTS`: its estimators)."""
    with zipfile.ZipFile(path) as archive:  # fmpy has read it: a valid archive and XML
        return declares_sampled_inputs(ET.fromstring(archive.read("modelDescription.xml")))


class Component:
    """A component of a system: FMU file, model description, parameter values.

    ``sampled_inputs``: the FMU reads its inputs as samples of one instant (duffid's
    estimators declare it); Gauss-Seidel delivers them all from one instant.

    Refused when it is read (:class:`WiringError` naming the component, its FMU, the variable
    and the reason): what the master cannot honour, so that nothing of the FMU is silently
    ignored: Clock variables and clocked variables (Scheduled Execution and clocked
    partitions), and variables of a type duffid does not know.
    """

    def __init__(self, name: str, path: Path, logging: bool) -> None:
        import fmpy

        self.name, self.path, self.logging = name, path, logging
        if not path.is_file():
            raise WiringError(f"component {name!r}: FMU file {path} does not exist")
        try:
            self.md = fmpy.read_model_description(str(path))
        except Exception as exc:  # fmpy raises plain Exceptions for bad archives / XML
            raise WiringError(f"component {name!r}: cannot read {path}: {exc}") from None
        if self.md.coSimulation is None:
            other = [label for attr, label in (("modelExchange", "Model Exchange"),
                                               ("scheduledExecution", "Scheduled Execution"))
                     if getattr(self.md, attr, None) is not None]
            raise WiringError(f"component {name!r}: {path.name} has no Co-Simulation interface"
                              + (f" (only {' and '.join(other)}, which duffid's master does not run)" if other else ""))
        self.version = self.md.fmiMajorVersion
        if self.version not in (2, 3):
            raise WiringError(f"component {name!r}: {path.name} is FMI {self.md.fmiVersion}; "
                              "only FMI 2.0 and 3.0 are supported")
        self.variables = {v.name: v for v in self.md.modelVariables}
        self.sampled_inputs = _reads_sampled_inputs(path)
        self.parameters: dict[str, Any] = {}
        for v in self.md.modelVariables:
            if v.type == "Clock" or v.clocks:
                what = "a Clock" if v.type == "Clock" else "clocked (it belongs to a clocked partition)"
                raise WiringError(f"{self.where()}: variable {v.name!r} is {what}; duffid's master does not "
                                  "support clocks (Scheduled Execution, clocked Co-Simulation)")
            if v.type not in VARIABLE_KINDS:
                raise WiringError(f"{self.where()}: variable {v.name!r} has type {v.type}, which duffid's master "
                                  "does not know")

    def where(self) -> str:
        return f"component {self.name!r} ({self.path.name})"

    @property
    def event_mode(self) -> bool:
        """Whether the master runs the FMU with Event Mode (FMI 3 ``hasEventMode``): it then
        instantiates it with eventModeUsed, and handles the events it asks for between steps."""
        return self.version == 3 and bool(getattr(self.md.coSimulation, "hasEventMode", False))

    def variable(self, var: str) -> Any:
        try:
            return self.variables[var]
        except KeyError:
            raise WiringError(f"{self.where()} has no variable {var!r}{suggest(var, self.variables)}") from None

    def channel(self, name: str) -> tuple[Any, int | None]:
        """The variable of ``name`` (``"y"`` or an array element ``"y[2,1]"``) and the
        element's row-major position (None for a whole variable)."""
        if name in self.variables:
            return self.variables[name], None
        base, index = split_element(name)
        if index is None:
            return self.variable(name), None
        var = self.variable(base)
        shape = self.shape(var)
        if not shape:
            raise WiringError(f"{self.where()}: {base} is a scalar; {name!r} names an element")
        try:
            return var, flat_index(index, shape, f"{self.where()}: {name}")
        except ValueError as exc:
            raise WiringError(str(exc)) from None

    def shape(self, variable: Any) -> tuple[int, ...]:
        """The dimensions of ``variable`` (empty for a scalar): fixed, or the value of the
        structural parameter that gives it (its value given to ``System.add``, else its start)."""
        dims = []
        for d in variable.dimensions:
            if d.start is not None and d.valueReference is None:
                dims.append(int(d.start))
                continue
            source = d.variable
            if source is None:
                raise WiringError(f"{self.where()}: a dimension of {variable.name} refers to value reference "
                                  f"{d.valueReference}, which no variable has")
            value = self.parameters.get(source.name, source.start)
            if value is None:
                raise WiringError(f"{self.where()}: the dimension of {variable.name} given by {source.name} "
                                  "has no value (set it with System.add(parameters=...))")
            dims.append(int(value))
        return tuple(dims)

    def size(self, variable: Any) -> int:
        """The number of values of ``variable`` (1 for a scalar)."""
        return int(np.prod(self.shape(variable), dtype=np.int64))

    def elements(self, variable: Any) -> list[str]:
        """The names of the variable's values: ``[name]`` for a scalar, ``name[i,j]`` elements."""
        return element_names(variable.name, self.shape(variable))

    def kind(self, variable: Any, purpose: str) -> str:
        """The kind of the variable's values (:data:`VARIABLE_KINDS`); ``purpose`` (e.g.
        "connected") names what was asked in the error for a type duffid does not exchange."""
        kind = VARIABLE_KINDS.get(variable.type)
        if kind is None:
            raise WiringError(f"{self.where()}: {variable.name} has type {variable.type}, which cannot be {purpose}")
        return kind

    def outputs(self) -> list[Any]:
        return [v for v in self.md.modelVariables if v.causality == "output"]


def typed_parameter(comp: Component, variable: Any, value: Any) -> Any:
    """Check and convert a parameter value for ``variable`` (a structural parameter too): a
    value of its kind, or for an array a (nested) sequence of its shape, returned flat."""
    where = f"{comp.where()}: parameter {variable.name}"
    if variable.causality == "input":
        raise WiringError(f"{where} is an input; drive it with set_input or connect")
    if variable.causality not in ("parameter", "structuralParameter") or \
            variable.variability not in ("fixed", "tunable") or variable.initial == "calculated":
        raise WiringError(f"{where} is {with_article(variable.causality)} ({variable.variability}) variable, "
                          "not a settable parameter")
    try:
        if not comp.shape(variable):
            return check_value(comp.kind(variable, "set"), value, where)
        return typed_parameter_values(comp, variable, value, where)
    except ValueError as exc:
        raise WiringError(str(exc)) from None


def typed_parameter_values(comp: Component, variable: Any, value: Any, where: str) -> list[Any]:
    """The values of the array ``variable`` from a (nested) sequence of its shape, checked
    (:func:`duffid.cosim.value_types.check_value`) and flat in row-major order; ValueError
    naming ``where`` otherwise."""
    kind, shape = comp.kind(variable, "set"), comp.shape(variable)
    if isinstance(value, (str, bytes)) or not isinstance(value, (Sequence, np.ndarray)):
        raise ValueError(f"{where}: {variable.name} is an array of shape {shape}; got {value!r}")
    try:
        values = np.asarray(value, dtype=object)
    except ValueError:  # ragged nesting
        values = np.empty(0, dtype=object)
    if values.shape != shape:
        raise ValueError(f"{where}: {variable.name} is an array of shape {shape}; got {value!r}")
    return [check_value(kind, v, f"{where}: {n}") for v, n in zip(values.ravel().tolist(), comp.elements(variable))]


# --------------------------------------------------------------------------------- ordering
@dataclass
class External:
    target: str
    kind: str           # a kind of VARIABLE_KINDS
    mode: str           # "constant", "function", "sampled"
    value: Any          # float, callable, or (t, values) arrays
    origin: str         # for messages
    interpolation: str = "linear"  # sampled: "linear" or "hold" (the previous sample)


def check_external_value(ext: External, v: Any, t: float) -> Any:
    """The value ``v`` of the external input ``ext`` at time ``t``, checked against the input's
    kind (:func:`duffid.cosim.value_types.check_value`; InputError otherwise)."""
    if ext.kind == "Real":
        return float(v)
    try:
        return check_value(ext.kind, v, f"{ext.target} (at t = {t!r})")
    except ValueError as exc:
        raise InputError(str(exc)) from None


#: How a sampled input is read between its samples: "linear" (the interpolated value at the
#: communication point), "hold" (the last sample at or before it), "average" (the mean of the
#: linear interpolation over the step that starts there: what an FMU that holds its input
#: over the step must get to respond as to the continuous signal, to O(h^2)),
#: "sample-of-hold" (the sample at the communication point of the staircase that "hold" gives
#: an FMU: the mean of the held values before and after it; what an estimator must get while a
#: plant is driven by the held signal, as the adaptive controller's f_sample).
INTERPOLATIONS = ("linear", "hold", "average", "sample-of-hold")


def _integral(ts: np.ndarray, values: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The integral from ``ts[0]`` to each ``t`` of the linear interpolation of the samples
    (a repeated time, a step, is a segment of length zero)."""
    lengths = np.diff(ts)
    cumulative = np.concatenate([[0.0], np.cumsum(0.5 * (values[1:] + values[:-1]) * lengths)])
    i = np.clip(np.searchsorted(ts, t, side="right") - 1, 0, len(ts) - 2)
    d = t - ts[i]
    slope = np.divide(values[i + 1] - values[i], lengths[i], out=np.zeros(len(t)), where=lengths[i] > 0)
    return cumulative[i] + values[i] * d + 0.5 * slope * d * d


def sampled_on_grid(ext: External, grid: np.ndarray) -> np.ndarray:
    """The samples of a sampled external input at the communication points ``grid``.

    ``ext.interpolation`` "linear" interpolates between neighbouring samples, "hold" takes
    the last sample at or before the point, "average" the mean of the linear interpolation
    over the step from the point (at the last point, the value there). A time given twice
    marks a step: at that time and after it the second value holds (the right limit),
    before it the first.
    """
    ts, values = ext.value
    lo, hi = float(grid[0]), float(grid[-1])
    rounding = 1e-9 * float(grid[1] - grid[0]) if len(grid) > 1 else 0.0  # of t0 + k h against the samples' times
    if lo < ts[0] - rounding or hi > ts[-1] + rounding:
        bad = lo if lo < ts[0] - rounding else hi
        raise WiringError(f"input {ext.target} ({ext.origin}): the communication point t = {bad!r} lies "
                          f"outside the sampled range [{float(ts[0])!r}, {float(ts[-1])!r}] (never extrapolated)")
    grid = np.clip(grid, ts[0], ts[-1])
    i = np.searchsorted(ts, grid, side="right") - 1  # the last sample at or before each point
    if ext.interpolation == "hold":
        return values[i]
    if ext.interpolation == "sample-of-hold":
        held = values[i]
        return np.concatenate([held[:1], 0.5 * (held[1:] + held[:-1])])
    if ext.interpolation == "average":
        area = _integral(ts, values, grid)
        out = np.empty(len(grid))
        out[:-1] = np.diff(area) / np.diff(grid)
        out[-1] = np.interp(grid[-1], ts, values) if np.all(np.diff(ts) > 0) else values[i[-1]]
        return out
    if np.all(np.diff(ts) > 0):
        return np.interp(grid, ts, values)
    j = np.minimum(i + 1, len(ts) - 1)
    span = ts[j] - ts[i]
    weight = np.divide(grid - ts[i], span, out=np.zeros(len(grid)), where=span > 0)
    return values[i] + weight * (values[j] - values[i])


# --------------------------------------------------------------------------------- system


@dataclass(frozen=True)
class Wiring:
    """A read-only view of a system's wiring, for the code that runs or exports it (the
    runner, the container export): its components by name, its connections in the order they
    were made, what drives each input from outside, and the lookup of ``"comp.var"``.

    The mappings are read-only views of the system's own (no copy: build it when needed).
    """

    components: Mapping[str, Component]
    connections: tuple[Connection, ...]
    externals: Mapping[str, External]
    lookup: Callable[[str, str], tuple[Component, Any]]
    #: ``(name, role) -> (component, variable, element position or None)`` for names that may
    #: be array elements (``"comp.y[2]"``).
    channel: Callable[[str, str], tuple[Component, Any, int | None]] | None = None


@runtime_checkable
class WiredSystem(Protocol):
    """What the runner and the container export need of a system: its :class:`Wiring`."""

    @property
    def wiring(self) -> Wiring: ...


@runtime_checkable
class SystemLike(WiredSystem, Protocol):
    """What the SSP reader and writer need of a system (:class:`duffid.cosim.system.System`
    follows it): building by name and reading its components back."""

    def add(self, name: str, path: str | os.PathLike[str], parameters: Mapping[str, Any] | None = None, *,
            logging: bool = False) -> Any: ...

    def connect(self, source: str, target: str, *, check_units: bool = True, factor: float = 1.0,
                offset: float = 0.0) -> Any: ...

    def set_input(self, target: str, source: Any, interpolation: str | None = None) -> Any: ...

    @property
    def components(self) -> list[str]: ...

    @property
    def connections(self) -> list[Connection]: ...

    @property
    def external_inputs(self) -> dict[str, str]: ...

    @property
    def constant_inputs(self) -> dict[str, float]: ...

    def fmu(self, component: str) -> Path: ...

    def parameter_values(self, component: str) -> dict[str, Any]: ...

    def variable(self, full: str) -> Any: ...

    def model_description(self, component: str) -> Any: ...
