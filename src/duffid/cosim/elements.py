"""The elements of a co-simulated system: components (FMUs) and their variables,
connections, external inputs, and what a run returns (results, failures, errors)."""
from __future__ import annotations

import csv
import difflib
import numbers
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Protocol, Union, runtime_checkable

import numpy as np

from ..errors import CosimError, InputError, WiringError

__all__ = ["InputSource", "VARIABLE_KINDS", "STATUS_NAMES", "NAME_RE", "N_MESSAGES", "N_REPORTED", "DTYPES",
           "WiringError", "Connection", "Failure", "CosimError", "Result", "with_article", "suggest", "unit_of",
           "Component", "typed_parameter", "External", "check_external_value", "sampled_on_grid",
           "INTERPOLATIONS", "ORDERINGS", "Wiring", "WiredSystem", "SystemLike"]

#: Source of an external input: a constant, a function of time, or samples ``(t, values)``.
InputSource = Union[float, Callable[[float], float], tuple]

#: FMI 2 and FMI 3 variable types -> the kind duffid exchanges them as.
VARIABLE_KINDS = {"Real": "Real", "Float64": "Real", "Integer": "Integer", "Int32": "Integer", "Boolean": "Boolean"}
STATUS_NAMES = {0: "OK", 1: "Warning", 2: "Discard", 3: "Error", 4: "Fatal", 5: "Pending"}
#: Accepted values of ``System.run(ordering=...)``.
ORDERINGS = ("jacobi", "gauss-seidel")
NAME_RE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
N_MESSAGES = 200      # log messages kept per component
N_REPORTED = 8        # log messages quoted in a CosimError
DTYPES = {"Real": np.float64, "Integer": np.int32, "Boolean": np.int32}




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
        What the run could not do as a user may expect, in plain words (array outputs not
        recorded, FMI 3 aliases recorded once, a communication step shorter than an FMU's
        fixed internal step).
    loop : str
        The inner loop that ran: ``"compiled"`` (C) or ``"python"`` (see ``System.run(loop=)``).
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

    def __getitem__(self, name: str) -> np.ndarray:
        """The column of ``"component.variable"`` (float64; int32 for Integer, bool for
        Boolean variables)."""
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
        communication point; floats in full precision (``repr``), Integer and Boolean
        variables as integers (Booleans as 0/1)."""
        columns = [self.time] + [self._columns[n] for n in self.names]
        with open(os.fspath(path), "w", newline="", encoding="utf-8") as fh:
            writer = csv.writer(fh, lineterminator="\n")
            writer.writerow(["time"] + self.names)
            lists = [c.astype(np.int64).tolist() if c.dtype.kind in "bi" else c.tolist() for c in columns]
            writer.writerows(zip(*[[repr(v) for v in col] for col in lists]))


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


class Component:
    """A component of a system: FMU file, model description, parameter values."""

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
            raise WiringError(f"component {name!r}: {path.name} has no Co-Simulation interface")
        self.version = self.md.fmiMajorVersion
        if self.version not in (2, 3):
            raise WiringError(f"component {name!r}: {path.name} is FMI {self.md.fmiVersion}; "
                              "only FMI 2.0 and 3.0 are supported")
        self.variables = {v.name: v for v in self.md.modelVariables}
        self.parameters: dict[str, Any] = {}

    def where(self) -> str:
        return f"component {self.name!r} ({self.path.name})"

    def variable(self, var: str) -> Any:
        try:
            return self.variables[var]
        except KeyError:
            raise WiringError(f"{self.where()} has no variable {var!r}{suggest(var, self.variables)}") from None

    def kind(self, variable: Any, purpose: str) -> str:
        """Real, Integer or Boolean; other types cannot be connected, driven or recorded."""
        kind = VARIABLE_KINDS.get(variable.type)
        if kind is None or variable.shape or variable.dimensions:
            raise WiringError(f"{self.where()}: {variable.name} has type {variable.type}"
                              f"{' (array)' if variable.dimensions else ''}; only scalar Real/Float64, "
                              f"Integer/Int32 and Boolean variables can be {purpose}")
        return kind

    def outputs(self) -> list[Any]:
        return [v for v in self.md.modelVariables if v.causality == "output" and v.type in VARIABLE_KINDS
                and not v.dimensions]


def typed_parameter(comp: Component, variable: Any, value: Any) -> Any:
    """Check and convert a parameter value for ``variable``."""
    where = f"{comp.where()}: parameter {variable.name}"
    if variable.causality == "input":
        raise WiringError(f"{where} is an input; drive it with set_input or connect")
    if variable.causality != "parameter" or variable.variability not in ("fixed", "tunable") \
            or variable.initial == "calculated":
        raise WiringError(f"{where} is {with_article(variable.causality)} ({variable.variability}) variable, "
                          "not a settable parameter")
    kind = variable.type
    if kind in ("Real", "Float64", "Float32"):
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            raise WiringError(f"{where} is {kind}; got {value!r}")
        return float(value)
    if kind in ("Integer", "Enumeration") or kind.startswith(("Int", "UInt")):
        if isinstance(value, bool) or not isinstance(value, numbers.Real) or value != int(value):
            raise WiringError(f"{where} is {kind}; got {value!r} (not an integer)")
        return int(value)
    if kind == "Boolean":
        if isinstance(value, (bool, np.bool_)) or (isinstance(value, numbers.Integral) and value in (0, 1)):
            return bool(value)
        raise WiringError(f"{where} is Boolean; got {value!r}")
    if kind == "String":
        if not isinstance(value, str):
            raise WiringError(f"{where} is String; got {value!r}")
        return value
    raise WiringError(f"{where} has type {kind}, which cannot be set")


# --------------------------------------------------------------------------------- ordering
@dataclass
class External:
    target: str
    kind: str           # Real / Integer / Boolean
    mode: str           # "constant", "function", "sampled"
    value: Any          # float, callable, or (t, values) arrays
    origin: str         # for messages
    interpolation: str = "linear"  # sampled: "linear" or "hold" (the previous sample)


def check_external_value(ext: External, v: Any, t: float) -> float:
    """The value ``v`` of the external input ``ext`` at time ``t``, checked against the input's kind."""
    if ext.kind == "Real":
        return float(v)
    number = float(v)
    if number != int(number) or (ext.kind == "Boolean" and number not in (0.0, 1.0)):
        raise InputError(f"{ext.target} is {ext.kind}; the input gave {v!r} at t = {t!r}")
    return number


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
