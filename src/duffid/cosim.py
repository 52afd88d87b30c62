"""Co-simulation of FMUs (FMI 2.0 and 3.0 Co-Simulation) connected by variable name.

A :class:`System` holds named components (FMUs), connections from outputs to inputs and
external input signals; :meth:`System.run` steps it at a fixed communication step and
returns a :class:`Result`::

    from duffid.cosim import System
    from duffid.signals import Step

    system = (System()
              .add("plant", "build/fmus/Oscillator1DOF.fmu", parameters={"m": 2.5})
              .add("estimator", "build/fmus/DuffingEstimator1.fmu")
              .connect("plant.x", "estimator.x")
              .set_input("plant.f", Step(10.0))
              .set_input("estimator.f", Step(10.0)))
    result = system.run(stop_time=1.0, step=1e-3)                # Jacobi
    result = system.run(1.0, 1e-3, ordering="gauss-seidel")      # Gauss-Seidel
    result.time, result["estimator.k_hat"], result.to_csv("run.csv")

Semantics
---------
Communication points are ``t_k = start_time + k * step`` (``k = 0 .. n``), computed from
``k``, never by accumulating the step. Every component is instantiated, set up and
initialised at ``t_0`` (parameters are set before initialisation, external inputs at
``t_0`` during it); row 0 of the result holds the values after initialisation. Inputs
that are neither connected nor driven by :meth:`System.set_input` keep their start
values for the whole run; connected inputs keep them during initialisation and get
their first value before the first ``doStep``.

Step ``k`` (from ``t_k`` to ``t_{k+1}``):

* ``ordering="jacobi"``: every connected input is set from its source's output at
  ``t_k`` and every external input to its value at ``t_k``; then every component does
  ``doStep(t_k, step)``, then every output is read (values at ``t_{k+1}``).
* ``ordering="gauss-seidel"``: the components are stepped one after another in an
  order derived from the connection graph (:meth:`System.gauss_seidel_order`). Before a
  component steps, its inputs are set: a connection from a component *earlier* in the
  order delivers the source's output at ``t_{k+1}`` (that component has already
  stepped), a connection from a *later* component (or from itself) delivers the output
  at ``t_k``, a one-step delay. These are the *delayed* connections. External inputs
  always deliver their value at ``t_k``. The order minimises the number of delayed
  connections; ties are broken by the order in which components were added.

Under Jacobi every connection delivers the value at ``t_k``, so
:attr:`Result.delayed` lists every connection.

Failures
--------
A status worse than Warning (Discard, Error, Fatal; FMI 2 Pending) from any FMI call,
an FMI 3 ``terminateSimulation`` request, or a Python exception (an error in an input
function, ``KeyboardInterrupt``) stops the run. Every instance is released
(``terminate`` where the state allows it, then ``freeInstance``; an instance that
returned Fatal is not called again), every extracted directory is deleted, and
:class:`CosimError` is raised; it names the component, its FMU file, the FMI function,
the status, the time and the component's last logged messages, and carries the partial
:class:`Result` (rows up to the last complete communication point) and the
:class:`Failure`.

Log messages of each FMU go to callbacks owned by the run (kept alive as long as the
instance); they are never routed through fmpy's native logger proxy.
"""
from __future__ import annotations

import csv
import difflib
import math
import numbers
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Sequence, Union

import numpy as np

__all__ = ["System", "Result", "Connection", "Failure", "CosimError", "WiringError", "ORDERINGS",
           "EXACT_ORDER_LIMIT", "VARIABLE_KINDS", "with_article"]

#: Accepted values of ``run(ordering=...)``.
ORDERINGS = ("jacobi", "gauss-seidel")
#: Up to this many components the Gauss-Seidel order is exact (every permutation is
#: considered, by dynamic programming over subsets); beyond, a greedy heuristic.
EXACT_ORDER_LIMIT = 12

#: Source of an external input: a constant, a function of time, or samples ``(t, values)``.
InputSource = Union[float, Callable[[float], float], tuple]

#: FMI 2 and FMI 3 variable types -> the kind duffid exchanges them as.
VARIABLE_KINDS = {"Real": "Real", "Float64": "Real", "Integer": "Integer", "Int32": "Integer", "Boolean": "Boolean"}
_STATUS = {0: "OK", 1: "Warning", 2: "Discard", 3: "Error", 4: "Fatal", 5: "Pending"}
_NAME_RE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
_N_MESSAGES = 200      # log messages kept per component
_N_REPORTED = 8        # log messages quoted in a CosimError
_DTYPES = {"Real": np.float64, "Integer": np.int32, "Boolean": np.int32}


class WiringError(ValueError):
    """A system that cannot be built: unknown component or variable, wrong causality,
    type or unit mismatch, an input driven twice, a bad parameter or input source."""


@dataclass(frozen=True)
class Connection:
    """A connection from ``source`` (an output, ``"component.variable"``) to ``target``
    (an input)."""

    source: str
    target: str

    def __str__(self) -> str:
        return f"{self.source} -> {self.target}"


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
        else:
            text += (" (nothing was logged; some FMUs, e.g. pythonfmu ones, log only with logging on: "
                     "System.add(..., logging=True))")
        return text


class CosimError(RuntimeError):
    """A co-simulation run stopped by a failure.

    Attributes
    ----------
    result : Result
        What was recorded up to the last complete communication point.
    failure : Failure
        Component, FMU, time, function, status and logged messages.
    """

    def __init__(self, failure: Failure, result: Result | None) -> None:
        super().__init__(str(failure))
        self.failure = failure
        self.result = result


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
        Why the run stopped early (None for a complete run).
    """

    time: np.ndarray
    names: list[str]
    _columns: dict[str, np.ndarray] = field(repr=False)
    order: list[str] = field(default_factory=list)
    delayed: list[Connection] = field(default_factory=list)
    ordering: str = "jacobi"
    step: float = 0.0
    failure: Failure | None = None

    def __getitem__(self, name: str) -> np.ndarray:
        """The column of ``"component.variable"`` (float64; int32 for Integer, bool for
        Boolean variables)."""
        try:
            return self._columns[name]
        except KeyError:
            raise KeyError(f"{name!r} was not recorded{_suggest(name, self.names)}") from None

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


def _suggest(name: str, candidates: Iterable[str]) -> str:
    close = difflib.get_close_matches(name, list(candidates), n=3, cutoff=0.6)
    return f"; did you mean {' or '.join(repr(c) for c in close)}?" if close else ""


def _unit(variable: Any) -> str | None:
    unit = getattr(variable, "unit", None)
    if unit is None and getattr(variable, "declaredType", None) is not None:
        unit = variable.declaredType.unit
    return unit or None


class _Component:
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
            raise WiringError(f"{self.where()} has no variable {var!r}{_suggest(var, self.variables)}") from None

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


def _typed_parameter(comp: _Component, variable: Any, value: Any) -> Any:
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
def _order_cost(order: Sequence[int], edges: Sequence[tuple[int, int]]) -> int:
    pos = {c: i for i, c in enumerate(order)}
    return sum(1 for s, d in edges if pos[s] >= pos[d])


def _exact_order(n: int, edges: Sequence[tuple[int, int]]) -> list[int]:
    """The permutation with the fewest delayed edges, lexicographically smallest among
    those (dynamic programming over subsets, equivalent to trying every permutation)."""
    self_loops = [0] * n
    out: list[dict[int, int]] = [dict() for _ in range(n)]
    for s, d in edges:
        if s == d:
            self_loops[s] += 1
        else:
            out[s][d] = out[s].get(d, 0) + 1
    out_items = [list(o.items()) for o in out]
    full = (1 << n) - 1

    def cost(prefix: int, v: int) -> int:  # edges from v to components already placed
        return self_loops[v] + sum(w for u, w in out_items[v] if prefix >> u & 1)

    rest = [0] * (1 << n)  # rest[S]: fewest delayed edges when the prefix is the set S
    for subset in range(full - 1, -1, -1):
        rest[subset] = min(cost(subset, v) + rest[subset | 1 << v] for v in range(n) if not subset >> v & 1)
    order, prefix = [], 0
    for _ in range(n):
        for v in range(n):
            if not prefix >> v & 1 and cost(prefix, v) + rest[prefix | 1 << v] == rest[prefix]:
                order.append(v)
                prefix |= 1 << v
                break
    return order


def _greedy_order(n: int, edges: Sequence[tuple[int, int]]) -> list[int]:
    """Eades-Lin-Smyth heuristic: sinks go to the back and sources to the front (each
    batch in insertion order); otherwise the component with the largest (outgoing -
    incoming) connection count goes next (lowest insertion index on ties)."""
    remaining = list(range(n))
    front: list[int] = []
    back: list[int] = []
    while remaining:
        live = set(remaining)
        outd = {v: 0 for v in remaining}
        ind = {v: 0 for v in remaining}
        for s, d in edges:
            if s != d and s in live and d in live:
                outd[s] += 1
                ind[d] += 1
        sinks = [v for v in remaining if outd[v] == 0]
        if sinks:
            back = sinks + back
            remaining = [v for v in remaining if v not in sinks]
            continue
        sources = [v for v in remaining if ind[v] == 0]
        if sources:
            front += sources
            remaining = [v for v in remaining if v not in sources]
            continue
        best = max(remaining, key=lambda v: (outd[v] - ind[v], -v))
        front.append(best)
        remaining.remove(best)
    return front + back


# --------------------------------------------------------------------------------- inputs
@dataclass
class _External:
    target: str
    kind: str           # Real / Integer / Boolean
    mode: str           # "constant", "function", "sampled"
    value: Any          # float, callable, or (t, values) arrays
    origin: str         # for messages


def _check_external_value(ext: _External, v: Any, t: float) -> float:
    if ext.kind == "Real":
        return float(v)
    number = float(v)
    if number != int(number) or (ext.kind == "Boolean" and number not in (0.0, 1.0)):
        raise ValueError(f"{ext.target} is {ext.kind}; the input gave {v!r} at t = {t!r}")
    return number


def _sampled_on_grid(ext: _External, grid: np.ndarray) -> np.ndarray:
    ts, values = ext.value
    lo, hi = float(grid[0]), float(grid[-1])
    if lo < ts[0] or hi > ts[-1]:
        bad = lo if lo < ts[0] else hi
        raise WiringError(f"input {ext.target} ({ext.origin}): the communication point t = {bad!r} lies "
                          f"outside the sampled range [{float(ts[0])!r}, {float(ts[-1])!r}] (never extrapolated)")
    if ext.kind == "Real":
        return np.interp(grid, ts, values)
    return values[np.searchsorted(ts, grid, side="right") - 1]  # previous sample (held)


# --------------------------------------------------------------------------------- system
class System:
    """A set of co-simulation FMUs connected by variable name.

    Build it with the chainable :meth:`add`, :meth:`connect`, :meth:`set_input` and
    :meth:`inputs_from_csv`; run it with :meth:`run`; export it as one container FMU
    with :meth:`export_container`. See the module documentation for the exact
    semantics of a step.
    """

    def __init__(self) -> None:
        self._components: dict[str, _Component] = {}
        self._connections: list[Connection] = []
        self._externals: dict[str, _External] = {}
        self._drivers: dict[str, str] = {}   # input -> what drives it (for messages)

    # ---------------------------------------------------------------- building
    def add(self, name: str, path: str | os.PathLike[str], parameters: Mapping[str, Any] | None = None, *,
            logging: bool = False) -> System:
        """Add a component.

        Parameters
        ----------
        name : str
            Component name, an identifier (letters, digits, ``_``), unique in the system.
        path : str or os.PathLike
            FMU file with a Co-Simulation interface (FMI 2.0 or 3.0).
        parameters : mapping, optional
            Parameter values set before initialisation: Real as float, Integer as int,
            Boolean as bool, String as str. Unknown names and wrong types are rejected.
        logging : bool
            Instantiate with ``loggingOn`` (debug messages). Errors are logged anyway by
            FMUs that follow the standard.

        Returns
        -------
        System
            self.

        Raises
        ------
        WiringError
            Bad name, missing or unreadable FMU, unknown parameter, bad value.
        """
        if not isinstance(name, str) or not _NAME_RE.match(name):
            raise WiringError(f"component name {name!r} must be an identifier (letters, digits, _)")
        if name in self._components:
            raise WiringError(f"component {name!r} is already in the system")
        comp = _Component(name, Path(path), logging)
        for pname, value in (parameters or {}).items():
            comp.parameters[pname] = _typed_parameter(comp, comp.variable(pname), value)
        self._components[name] = comp
        return self

    def _lookup(self, full: str, role: str) -> tuple[_Component, Any]:
        if not isinstance(full, str) or "." not in full:
            raise WiringError(f"{role} {full!r} must be 'component.variable'")
        cname, var = full.split(".", 1)
        comp = self._components.get(cname)
        if comp is None:
            raise WiringError(f"{role} {full!r}: no component {cname!r} in the system"
                              f"{_suggest(cname, self._components)}")
        return comp, comp.variable(var)

    def _claim_input(self, target: str, driver: str) -> tuple[_Component, Any]:
        comp, var = self._lookup(target, "target")
        if var.causality != "input":
            raise WiringError(f"target {target!r}: {comp.where()}: {var.name} is {with_article(var.causality)}, not an input")
        if target in self._drivers:
            raise WiringError(f"input {target!r} is already driven by {self._drivers[target]}; "
                              f"it cannot also be driven by {driver}")
        return comp, var

    def connect(self, source: str, target: str, *, check_units: bool = True) -> System:
        """Connect an output to an input (``"plant.x"``, ``"estimator.x"``).

        Checks that both exist, that the source is an output and the target an input,
        that the types match (Real/Float64, Integer/Int32, Boolean), that the target has
        no other driver, and that the units agree when both declare one.

        Parameters
        ----------
        source, target : str
            ``"component.output"`` and ``"component.input"``.
        check_units : bool
            False connects variables whose declared units differ: a generic FMU used in
            another domain (the 1-DOF estimator and controller, declared in m and N, on
            the Duffing circuit's charge [C] and voltage [V]). Types are still checked.

        Returns
        -------
        System
            self.
        """
        scomp, svar = self._lookup(source, "source")
        if svar.causality != "output":
            raise WiringError(f"source {source!r}: {scomp.where()}: {svar.name} is {with_article(svar.causality)}, "
                              "not an output")
        tcomp, tvar = self._claim_input(target, f"the connection from {source!r}")
        skind, tkind = scomp.kind(svar, "connected"), tcomp.kind(tvar, "connected")
        if skind != tkind:
            raise WiringError(f"cannot connect {source!r} ({svar.type}) to {target!r} ({tvar.type}): "
                              "types differ")
        sunit, tunit = _unit(svar), _unit(tvar)
        if check_units and sunit and tunit and sunit != tunit:
            raise WiringError(f"cannot connect {source!r} [{sunit}] to {target!r} [{tunit}]: units differ "
                              "(connect(..., check_units=False) for a unit-generic FMU)")
        self._connections.append(Connection(source, target))
        self._drivers[target] = f"the connection from {source!r}"
        return self

    def set_input(self, target: str, source: InputSource) -> System:
        """Drive an input from outside the system.

        Parameters
        ----------
        target : str
            ``"component.input"``.
        source : float, callable or (t, values)
            A constant; a function ``t -> value`` evaluated at every communication
            point (e.g. a :class:`duffid.signals.Signal`); or samples ``(t, values)``
            (strictly increasing finite ``t``): Real inputs are interpolated linearly,
            Integer and Boolean inputs hold the previous sample. Every communication
            point ``t_0 .. t_n`` must lie within ``[t[0], t[-1]]``; nothing is
            extrapolated or clipped (:meth:`run` raises otherwise).

        Returns
        -------
        System
            self.
        """
        return self._set_input(target, source, "set_input")

    def _set_input(self, target: str, source: Any, origin: str) -> System:
        comp, var = self._claim_input(target, origin)
        kind = comp.kind(var, "driven")
        if isinstance(source, tuple) or isinstance(source, list):
            if len(source) != 2:
                raise WiringError(f"input {target!r}: samples must be a pair (t, values)")
            ts = np.asarray(source[0], dtype=np.float64)
            values = np.asarray(source[1], dtype=np.float64)
            if ts.ndim != 1 or values.shape != ts.shape or len(ts) < 2:
                raise WiringError(f"input {target!r}: t and values must be 1-D of the same length >= 2, "
                                  f"got shapes {ts.shape} and {values.shape}")
            if not np.all(np.isfinite(ts)) or not np.all(np.diff(ts) > 0):
                raise WiringError(f"input {target!r}: t must be finite and strictly increasing")
            if kind != "Real" and not np.all(values == np.round(values)):
                raise WiringError(f"input {target!r} is {var.type}; the samples must be integers")
            ext = _External(target, kind, "sampled", (ts, values), origin)
        elif callable(source):
            ext = _External(target, kind, "function", source, origin)
        elif isinstance(source, numbers.Real):
            ext = _External(target, kind, "constant", float(source), origin)
            try:
                _check_external_value(ext, source, 0.0)
            except ValueError as exc:
                raise WiringError(str(exc)) from None
        else:
            raise WiringError(f"input {target!r}: the source must be a number, a function of t or "
                              f"(t, values); got {type(source).__name__}")
        self._externals[target] = ext
        self._drivers[target] = origin
        return self

    def inputs_from_csv(self, path: str | os.PathLike[str], columns: Mapping[str, str]) -> System:
        """Drive inputs from the columns of a CSV file (linear interpolation in time).

        Parameters
        ----------
        path : str or os.PathLike
            CSV file: one header line with a time column ``t`` or ``time`` and named
            columns, then one row of numbers per sample (strictly increasing time).
        columns : mapping
            CSV column -> ``"component.input"``.

        Returns
        -------
        System
            self.

        Raises
        ------
        WiringError
            The message names the file, the line and the column: missing file, missing
            or duplicate column, a field that is not a finite number, non-increasing
            time, fewer than 2 rows; and the usual wiring errors for the targets.
        """
        source = os.fspath(path)
        try:
            with open(source, newline="", encoding="utf-8-sig") as fh:
                rows = list(csv.reader(fh))
        except (OSError, UnicodeDecodeError) as exc:
            raise WiringError(f"{source}: cannot read: {exc}") from None
        if not rows:
            raise WiringError(f"{source}: empty file (expected a header line)")
        header = [h.strip() for h in rows[0]]
        if len(set(header)) != len(header):
            dup = next(h for h in header if header.count(h) > 1)
            raise WiringError(f"{source}, line 1: duplicate column {dup!r}")
        time_cols = [h for h in ("t", "time") if h in header]
        if not time_cols:
            raise WiringError(f"{source}, line 1: no time column 't' or 'time' (columns: {', '.join(header)})")
        for column in columns:
            if column not in header:
                raise WiringError(f"{source}, line 1: no column {column!r}{_suggest(column, header)}")
        wanted = [time_cols[0]] + list(columns)
        index = [header.index(c) for c in wanted]
        data = np.empty((len(rows) - 1, len(wanted)))
        for i, row in enumerate(rows[1:]):
            line = i + 2
            if len(row) != len(header):
                raise WiringError(f"{source}, line {line}: {len(row)} fields, the header has {len(header)}")
            for j, (col, k) in enumerate(zip(wanted, index)):
                text = row[k].strip()
                try:
                    value = float(text)
                except ValueError:
                    raise WiringError(f"{source}, line {line}, column {col!r}: {text!r} is not a number") from None
                if not math.isfinite(value):
                    raise WiringError(f"{source}, line {line}, column {col!r}: {text!r} is not finite")
                data[i, j] = value
        if len(data) < 2:
            raise WiringError(f"{source}: needs at least 2 rows of samples, found {len(data)}")
        bad = np.nonzero(np.diff(data[:, 0]) <= 0)[0]
        if len(bad):
            raise WiringError(f"{source}, line {bad[0] + 3}, column {wanted[0]!r}: time "
                              f"{float(data[bad[0] + 1, 0])!r} does not increase (previous {float(data[bad[0], 0])!r})")
        for j, (column, target) in enumerate(columns.items(), start=1):
            self._set_input(target, (data[:, 0], data[:, j]), f"column {column!r} of {source}")
        return self

    # ---------------------------------------------------------------- inspection
    @property
    def components(self) -> list[str]:
        """Component names in insertion order."""
        return list(self._components)

    @property
    def connections(self) -> list[Connection]:
        """Connections in the order they were made."""
        return list(self._connections)

    def gauss_seidel_order(self) -> tuple[list[str], list[Connection]]:
        """The Gauss-Seidel stepping order and its delayed connections.

        The order minimises the number of delayed connections (a connection is delayed
        when its source steps after its target, or is the target itself). Up to
        :data:`EXACT_ORDER_LIMIT` components the minimum is exact (all permutations,
        by dynamic programming over subsets), and among equally good orders the one
        closest to insertion order (lexicographically smallest) is chosen. Beyond, a
        greedy heuristic (Eades, Lin and Smyth 1993): repeatedly move every component
        without outgoing connections to the back and every one without incoming
        connections to the front (each batch in insertion order), else the component
        with the largest outgoing-minus-incoming count to the front.

        Returns
        -------
        order : list of str
        delayed : list of Connection
        """
        order = self._derive_order()
        return order, self._delayed(order)

    def _edges(self) -> list[tuple[int, int]]:
        index = {n: i for i, n in enumerate(self._components)}
        return [(index[c.source.split(".", 1)[0]], index[c.target.split(".", 1)[0]]) for c in self._connections]

    def _derive_order(self) -> list[str]:
        names = list(self._components)
        n = len(names)
        if n == 0:
            return []
        edges = self._edges()
        perm = _exact_order(n, edges) if n <= EXACT_ORDER_LIMIT else _greedy_order(n, edges)
        return [names[i] for i in perm]

    def _delayed(self, order: Sequence[str]) -> list[Connection]:
        pos = {c: i for i, c in enumerate(order)}
        return [c for c in self._connections
                if pos[c.source.split(".", 1)[0]] >= pos[c.target.split(".", 1)[0]]]

    # ---------------------------------------------------------------- running
    def run(self, stop_time: float, step: float, start_time: float = 0.0, ordering: str = "jacobi",
            order: Sequence[str] | None = None, record: Sequence[str] | None = None,
            progress: bool = False) -> Result:
        """Co-simulate from ``start_time`` to ``stop_time`` at a fixed communication step.

        Parameters
        ----------
        stop_time : float
            End time; ``stop_time - start_time`` must be an integer multiple of ``step``
            (within 1e-9 relative).
        step : float
            Communication step ``h`` [s]; the grid is ``t_k = start_time + k h``.
        start_time : float
            Start time ``t_0``.
        ordering : {"jacobi", "gauss-seidel"}
            Master algorithm (see the module documentation).
        order : sequence of str, optional
            Gauss-Seidel only: the stepping order (every component exactly once),
            instead of the derived one.
        record : sequence of str, optional
            Variables to record (``"component.variable"``): outputs, local variables and
            externally driven inputs (connected inputs: record their source). Default:
            every output of every component (Real, Integer, Boolean) and every
            externally driven input.
        progress : bool
            Show a tqdm progress bar (updated in chunks of steps).

        Returns
        -------
        Result
            ``n + 1`` rows, ``t_0 .. t_n``.

        Raises
        ------
        WiringError
            Bad arguments, unknown recorded variables, sampled inputs that do not cover
            the grid (before anything is instantiated).
        CosimError
            A failure during the run (see the module documentation); carries the partial
            result.
        """
        from ._cosim_runner import Runner  # the hot loop lives in its own module

        if ordering not in ORDERINGS:
            raise WiringError(f"ordering must be one of {ORDERINGS}, got {ordering!r}")
        if not self._components:
            raise WiringError("the system has no components")
        for value, label in ((stop_time, "stop_time"), (step, "step"), (start_time, "start_time")):
            if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
                raise WiringError(f"{label} must be a finite number, got {value!r}")
        if not step > 0:
            raise WiringError(f"step must be positive, got {step!r}")
        span = float(stop_time) - float(start_time)
        n = round(span / step)
        if n < 1 or abs(n * step - span) > 1e-9 * max(abs(span), abs(step)):
            raise WiringError(f"stop_time - start_time = {span!r} is not a positive integer multiple of "
                              f"step = {step!r}")
        if ordering == "jacobi":
            if order is not None:
                raise WiringError("order= applies to ordering='gauss-seidel' only")
            sequence = list(self._components)
            delayed = list(self._connections)
        else:
            if order is None:
                sequence = self._derive_order()
            else:
                sequence = list(order)
                unknown = [c for c in sequence if c not in self._components]
                if unknown:
                    raise WiringError(f"order: unknown component {unknown[0]!r}"
                                      f"{_suggest(unknown[0], self._components)}")
                if sorted(sequence) != sorted(self._components):
                    missing = [c for c in self._components if c not in sequence]
                    raise WiringError(f"order must name every component exactly once; "
                                      f"missing {missing}, given {sequence}")
            delayed = self._delayed(sequence)
        names = self._record_names(record)
        grid = float(start_time) + np.arange(n + 1) * float(step)
        sampled = {t: _sampled_on_grid(e, grid) for t, e in self._externals.items() if e.mode == "sampled"}
        runner = Runner(self, grid, float(step), ordering, sequence, delayed, names, sampled, progress)
        return runner.execute()

    def _record_names(self, record: Sequence[str] | None) -> list[str]:
        if record is None:
            names = []
            for comp in self._components.values():
                for v in comp.md.modelVariables:
                    full = f"{comp.name}.{v.name}"
                    if (v.causality == "output" and v.type in VARIABLE_KINDS and not v.dimensions) or full in self._externals:
                        names.append(full)
            return names
        if isinstance(record, str):
            raise WiringError("record must be a sequence of names, not a string")
        names = []
        for full in record:
            comp, var = self._lookup(full, "recorded variable")
            comp.kind(var, "recorded")
            if var.causality == "input" and full not in self._externals:
                hint = next((f"; record its source {c.source!r}" for c in self._connections if c.target == full), "")
                raise WiringError(f"recorded variable {full!r} is an input that no external source drives{hint}")
            if full in names:
                raise WiringError(f"recorded variable {full!r} is listed twice")
            names.append(full)
        return names

    # ---------------------------------------------------------------- container
    def export_container(self, path: str | os.PathLike[str], inputs: Mapping[str, str | Sequence[str]] | None = None,
                         outputs: Mapping[str, str] | None = None, step: float = 1e-3,
                         parameters: Mapping[str, str | Sequence[str]] | None = None) -> Path:
        """Write the system as one FMI 2.0 co-simulation container FMU (fmpy's container).

        See :func:`duffid.cosim_container.export_container` for the parameters and
        limits.
        """
        from .cosim_container import export_container

        return export_container(self, path, inputs=inputs, outputs=outputs, step=step, parameters=parameters)
