"""Co-simulation of FMUs (FMI 2.0 and 3.0 Co-Simulation) connected by variable name.

A :class:`System` holds named components (FMUs), connections from outputs to inputs and
external input signals; :meth:`System.run` steps it at a fixed communication step and
returns a :class:`Result`::

    from duffid.cosim.system import System
    from duffid.data.signals import Step

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
  connections; ties are broken by the order in which components were added. An FMU that
  reads its inputs as samples of one instant (duffid's estimators declare it with the
  annotation :data:`duffid.fmu.fmi_xml.SAMPLED_INPUTS`) gets them all from one instant:
  it steps before all its sources or after all of them (in the closed loop: estimator,
  plant, controller; x and f at ``t_k``). Otherwise the estimator would read x at ``t_{k+1}`` with f at
  ``t_k``, a skew it takes for physics (measured on the 1-DOF loop: m, b and kp 2.5 % off).
  A given ``order=`` that breaks this is refused.

Under Jacobi every connection delivers the value at ``t_k``, so
:attr:`Result.delayed` lists every connection.

Variable types and arrays
-------------------------
Every FMI 2 and FMI 3 variable type is exchanged (:mod:`duffid.cosim.value_types`): FMI 2
Real, Integer, Boolean, String, Enumeration; FMI 3 Float32, Float64, Int8 .. UInt64, Boolean,
String, Binary, Enumeration. A connection joins variables of one kind: the same type, FMI 2
Real and FMI 3 Float64, FMI 2 Integer and FMI 3 Int32, or two Enumerations with the same items
(no other conversion is made; a factor or offset applies to Real connections only). Constants
and samples are checked against the input's type (range of an integer type, 0/1 of a Boolean).
String values are ``str``, Binary values ``bytes`` (the compiled loop calls back into Python for
their calls and copies). :meth:`Result.to_csv` writes Binary values as hexadecimal.

FMI 3 arrays (``<Dimension>``, fixed or given by a structural parameter) are recorded element by
element as ``"comp.y[i,j]"`` (indices from 1, row-major). An array output connects to an array
input of the same shape (element by element), and an element (``"comp.y[2]"``) to a scalar or to
an element; an array input of which only some elements are driven gets its start values in the
others (FMI sets an array whole). Structural parameters given to :meth:`add` are set in
Configuration Mode before the other parameters and give the shapes of the arrays.

An FMI 3 FMU that declares ``hasEventMode`` is instantiated with ``eventModeUsed``: after
initialisation and after every ``doStep`` that sets ``eventHandlingNeeded`` the master enters Event
Mode, calls ``updateDiscreteStates`` until the FMU needs no further update, and returns to Step
Mode (early returns are not allowed: events fall on the communication grid's next point). Clocks
(Scheduled Execution, clocked Co-Simulation) are refused when the FMU is added, naming the
variable; so is an FMU without a Co-Simulation interface.

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
import math
import numbers
import os
from types import MappingProxyType
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

__all__ = ["System", "Result", "Connection", "Failure", "CosimError", "WiringError", "ORDERINGS",
           "EXACT_ORDER_LIMIT", "VARIABLE_KINDS", "with_article"]

#: Up to this many components the Gauss-Seidel order is exact (every permutation is
#: considered, by dynamic programming over subsets); beyond, a greedy heuristic.
EXACT_ORDER_LIMIT = 12

from ..errors import CosimError, WiringError
from .compiled_loop import LOOP_MODES, obstacles
from .container import export_container
from .value_types import DTYPES, FLOAT_KINDS, INTEGER_KINDS, check_value
from .elements import (
    INTERPOLATIONS,
    ORDERINGS,
    NAME_RE,
    VARIABLE_KINDS,
    Component,
    Connection,
    External,
    Failure,
    InputSource,
    Result,
    check_external_value,
    sampled_on_grid,
    suggest,
    typed_parameter,
    typed_parameter_values,
    Wiring,
    unit_of,
    with_article,
)
from .runner import Runner
from .ssp import read_ssp, write_ssp


def _order_cost(order: Sequence[int], edges: Sequence[tuple[int, int]]) -> int:
    pos = {c: i for i, c in enumerate(order)}
    return sum(1 for s, d in edges if pos[s] >= pos[d])


def _one_instant(v: int, prefix: int, together: Mapping[int, tuple[int, bool]]) -> bool:
    """Whether component ``v``, stepped after the components of the bit set ``prefix``, gets all
    its inputs from one instant: ``together[v]`` is the bit set of its sources (itself
    excluded) and whether an input is delivered at t_k anyway (a time-varying external input or
    a connection from itself); components without an entry take any mix."""
    if v not in together:
        return True
    sources, at_tk = together[v]
    earlier = sources & prefix
    return earlier == 0 or (earlier == sources and not at_tk)


def _skewed(order: Sequence[int], together: Mapping[int, tuple[int, bool]]) -> int | None:
    """The first component of ``order`` that gets its inputs from two instants
    (:func:`_one_instant`), None when none does."""
    prefix = 0
    for v in order:
        if not _one_instant(v, prefix, together):
            return v
        prefix |= 1 << v
    return None


def _exact_order(n: int, edges: Sequence[tuple[int, int]],
                 together: Mapping[int, tuple[int, bool]] | None = None) -> list[int] | None:
    """The permutation with the fewest delayed edges, lexicographically smallest among
    those (dynamic programming over subsets, equivalent to trying every permutation), in
    which every component of ``together`` gets its inputs from one instant
    (:func:`_one_instant`); None when no permutation does."""
    together = together or {}
    self_loops = [0] * n
    out: list[dict[int, int]] = [dict() for _ in range(n)]
    for s, d in edges:
        if s == d:
            self_loops[s] += 1
        else:
            out[s][d] = out[s].get(d, 0) + 1
    out_items = [list(o.items()) for o in out]
    full = (1 << n) - 1

    def cost(prefix: int, v: int) -> float:  # edges from v to components already placed
        if not _one_instant(v, prefix, together):
            return math.inf
        return self_loops[v] + sum(w for u, w in out_items[v] if prefix >> u & 1)

    rest: list[float] = [0] * (1 << n)  # rest[S]: fewest delayed edges when the prefix is the set S
    for subset in range(full - 1, -1, -1):
        rest[subset] = min(cost(subset, v) + rest[subset | 1 << v] for v in range(n) if not subset >> v & 1)
    if math.isinf(rest[0]):
        return None
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


def _csv_value(kind: str, text: str, where: str) -> Any:
    """A CSV field as a sample of ``kind``: a finite number (integers exactly), a Boolean as
    0/1/true/false, a String as it is, a Binary as hexadecimal (WiringError naming ``where``)."""
    if kind == "String":
        return text
    text = text.strip()
    if kind in INTEGER_KINDS:
        try:
            return int(text)
        except ValueError:
            pass
    if kind == "Boolean" and text.lower() in ("true", "false"):
        return text.lower() == "true"
    if kind == "Binary":
        try:
            return bytes.fromhex(text)
        except ValueError:
            raise WiringError(f"{where}: {text!r} is not hexadecimal (a Binary input)") from None
    try:
        value = float(text)
    except ValueError:
        raise WiringError(f"{where}: {text!r} is not a number") from None
    if not math.isfinite(value):
        raise WiringError(f"{where}: {text!r} is not finite")
    return value


# --------------------------------------------------------------------------------- inputs
class System:
    """A set of co-simulation FMUs connected by variable name.

    Build it with the chainable :meth:`add`, :meth:`connect`, :meth:`set_input` and
    :meth:`inputs_from_csv`; run it with :meth:`run`; export it as one container FMU
    with :meth:`export_container`. See the module documentation for the exact
    semantics of a step.
    """

    def __init__(self) -> None:
        self._components: dict[str, Component] = {}
        self._connections: list[Connection] = []
        self._externals: dict[str, External] = {}
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
            Parameter values set before initialisation: Real and Float32 as float, the
            integer types and Enumeration as int (range checked), Boolean as bool, String as
            str, Binary as bytes (or hexadecimal text); an array as a nested sequence of its
            shape. FMI 3 structural parameters are set in Configuration Mode, before the
            others, and give the shapes of the arrays they dimension. Unknown names and wrong
            types are rejected.
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
        if not isinstance(name, str) or not NAME_RE.match(name):
            raise WiringError(f"component name {name!r} must be an identifier (letters, digits, _)")
        if name in self._components:
            raise WiringError(f"component {name!r} is already in the system")
        comp = Component(name, Path(path), logging)
        given = [(comp.variable(pname), value) for pname, value in (parameters or {}).items()]
        # structural parameters first: they give the shapes of the array parameters
        for variable, value in sorted(given, key=lambda item: item[0].causality != "structuralParameter"):
            comp.parameters[variable.name] = typed_parameter(comp, variable, value)
        self._components[name] = comp
        return self

    def _lookup(self, full: str, role: str) -> tuple[Component, Any]:
        if not isinstance(full, str) or "." not in full:
            raise WiringError(f"{role} {full!r} must be 'component.variable'")
        cname, var = full.split(".", 1)
        comp = self._components.get(cname)
        if comp is None:
            raise WiringError(f"{role} {full!r}: no component {cname!r} in the system"
                              f"{suggest(cname, self._components)}")
        return comp, comp.variable(var)

    def _channel(self, full: str, role: str) -> tuple[Component, Any, int | None]:
        """The component, variable and element position (None: the whole variable) of
        ``"comp.var"`` or ``"comp.var[i,j]"``."""
        comp, _ = self._lookup(full.split("[", 1)[0] if isinstance(full, str) else full, role)
        var, index = comp.channel(full.split(".", 1)[1])
        return comp, var, index

    def _channel_names(self, comp: Component, var: Any, index: int | None) -> list[str]:
        """The full names of the values a channel covers (normalised element names)."""
        names = comp.elements(var)
        return [f"{comp.name}.{names[index]}"] if index is not None else [f"{comp.name}.{n}" for n in names]

    def _claim_input(self, target: str, driver: str) -> tuple[Component, Any, int | None, list[str]]:
        comp, var, index = self._channel(target, "target")
        if var.causality != "input":
            raise WiringError(f"target {target!r}: {comp.where()}: {var.name} is {with_article(var.causality)}, not an input")
        keys = self._channel_names(comp, var, index)
        for key in keys:
            if key in self._drivers:
                raise WiringError(f"input {key!r} is already driven by {self._drivers[key]}; "
                                  f"it cannot also be driven by {driver}")
        return comp, var, index, keys

    def connect(self, source: str, target: str, *, check_units: bool = True, factor: float = 1.0,
                offset: float = 0.0) -> System:
        """Connect an output to an input (``"plant.x"``, ``"estimator.x"``).

        Checks that both exist, that the source is an output and the target an input,
        that the kinds match (:mod:`duffid.cosim.value_types`: Real/Float64, Integer/Int32,
        Enumeration with the same items, or the same FMI type), that the shapes match (an
        array to an array of its shape, element-wise; an element ``"comp.y[2]"`` to a scalar
        or an element), that the target has no other driver, and that the units agree when
        both declare one.

        Parameters
        ----------
        source, target : str
            ``"component.output"`` and ``"component.input"`` (or array elements,
            ``"component.y[1,2]"``, indices from 1).
        check_units : bool
            False connects variables whose declared units differ: a generic FMU used in
            another domain (the 1-DOF estimator and controller, declared in m and N, on
            the Duffing circuit's charge [C] and voltage [V]). Types are still checked.
        factor, offset : float
            The target receives ``factor * source + offset`` (an SSP linear transformation
            or unit conversion; Real connections only). A transformed connection runs in
            the Python loop (``run(loop="auto")`` takes it) and cannot be exported as a
            container FMU.

        Returns
        -------
        System
            self.
        """
        scomp, svar, sindex = self._channel(source, "source")
        if svar.causality != "output":
            raise WiringError(f"source {source!r}: {scomp.where()}: {svar.name} is {with_article(svar.causality)}, "
                              "not an output")
        tcomp, tvar, tindex, keys = self._claim_input(target, f"the connection from {source!r}")
        skind, tkind = scomp.kind(svar, "connected"), tcomp.kind(tvar, "connected")
        if skind != tkind:
            raise WiringError(f"cannot connect {source!r} ({svar.type}) to {target!r} ({tvar.type}): "
                              "types differ (duffid connects the same kind only: Real/Float64, Integer/Int32, "
                              "Enumeration, or one FMI 3 type to itself)")
        if skind == "Enumeration":
            items = [[(i.name, int(i.value)) for i in getattr(v.declaredType, "items", [])] for v in (svar, tvar)]
            if items[0] != items[1]:
                raise WiringError(f"cannot connect {source!r} to {target!r}: their enumerations have different "
                                  f"items ({items[0]} and {items[1]})")
        sshape = () if sindex is not None else scomp.shape(svar)
        tshape = () if tindex is not None else tcomp.shape(tvar)
        if sshape != tshape:
            raise WiringError(f"cannot connect {source!r} (shape {sshape}) to {target!r} (shape {tshape}): an "
                              "array connects to an array of the same shape, an element (name[i]) to a scalar "
                              "or an element")
        sunit, tunit = unit_of(svar), unit_of(tvar)
        if check_units and sunit and tunit and sunit != tunit:
            raise WiringError(f"cannot connect {source!r} [{sunit}] to {target!r} [{tunit}]: units differ "
                              "(connect(..., check_units=False) for a unit-generic FMU)")
        for value, label in ((factor, "factor"), (offset, "offset")):
            if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
                raise WiringError(f"connection {source!r} -> {target!r}: {label} must be a finite number, "
                                  f"got {value!r}")
        connection = Connection(source, target, float(factor), float(offset), bool(check_units))
        if connection.transformed and skind != "Real":
            raise WiringError(f"connection {source!r} -> {target!r}: a factor or offset applies to Real "
                              f"connections only, not {svar.type}")
        self._connections.append(connection)
        for key in keys:
            self._drivers[key] = f"the connection from {source!r}"
        return self

    def set_input(self, target: str, source: InputSource, interpolation: str | None = None) -> System:
        """Drive an input from outside the system.

        Parameters
        ----------
        target : str
            ``"component.input"``.
        source : constant, callable or (t, values)
            A constant of the input's type (a number, bool, str, bytes; for an array input
            a nested sequence of its shape); a function ``t -> value`` evaluated at every
            communication point (e.g. a :class:`duffid.data.signals.Signal`); or samples
            ``(t, values)``
            (finite, non-decreasing ``t``; a time given twice marks a step, the second
            value holding from that time on). Every communication point ``t_0 .. t_n``
            must lie within ``[t[0], t[-1]]``; nothing is extrapolated or clipped
            (:meth:`run` raises otherwise).
        interpolation : {"linear", "hold", "average", "sample-of-hold"}, optional
            How samples are read between sample times: "linear" interpolates, "hold" keeps
            the last sample (zero-order hold), "average" gives each step the mean of the
            linear interpolation over it, "sample-of-hold" the sample at each point of the
            staircase that "hold" makes (the mean of the held values before and after it;
            see :meth:`replay`). Default: "linear" for a Real or Float32 input of continuous
            variability, "hold" for a discrete-variability one and for inputs of the other
            types (as FMI hosts do), which can only hold their samples.

        Returns
        -------
        System
            self.
        """
        return self._set_input(target, source, "set_input", interpolation)

    def _set_input(self, target: str, source: Any, origin: str, interpolation: str | None = None) -> System:
        comp, var, index, keys = self._claim_input(target, origin)
        kind = comp.kind(var, "driven")
        if index is None and comp.shape(var):  # a whole array: a constant of its shape, element by element
            try:
                values = typed_parameter_values(comp, var, source, f"input {target!r} ({origin})")
            except ValueError as exc:
                raise WiringError(str(exc)) from None
            for key, value in zip(keys, values):
                self._externals[key] = External(key, kind, "constant", value, origin)
                self._drivers[key] = origin
            return self
        target = keys[0]
        continuous = kind in FLOAT_KINDS and var.variability == "continuous"
        if interpolation is None:
            interpolation = "linear" if continuous else "hold"
        elif interpolation not in INTERPOLATIONS:
            raise WiringError(f"input {target!r} ({origin}): interpolation must be one of "
                              f"{', '.join(INTERPOLATIONS)}, got {interpolation!r}")
        elif interpolation != "hold" and kind not in FLOAT_KINDS:
            raise WiringError(f"input {target!r} ({origin}) is {var.type}: it can only hold its samples")
        if isinstance(source, tuple) or isinstance(source, list):
            if len(source) != 2:
                raise WiringError(f"input {target!r}: samples must be a pair (t, values)")
            ts = np.asarray(source[0], dtype=np.float64)
            values = np.asarray(source[1], dtype=np.float64 if kind == "Real" else object)
            if ts.ndim != 1 or values.shape != ts.shape or len(ts) < 2:
                raise WiringError(f"input {target!r}: t and values must be 1-D of the same length >= 2, "
                                  f"got shapes {ts.shape} and {values.shape}")
            if not np.all(np.isfinite(ts)) or not np.all(np.diff(ts) >= 0):
                raise WiringError(f"input {target!r}: t must be finite and non-decreasing")
            if np.any((np.diff(ts[1:]) == 0) & (np.diff(ts[:-1]) == 0)):
                raise WiringError(f"input {target!r}: a time is given more than twice (twice marks a step)")
            if kind != "Real":
                try:
                    checked = [check_value(kind, v, f"input {target!r} ({origin}), sample {i}")
                               for i, v in enumerate(values.tolist())]
                except ValueError as exc:
                    raise WiringError(str(exc)) from None
                values = np.array(checked, dtype=DTYPES[kind] if kind not in FLOAT_KINDS else np.float64)
            ext = External(target, kind, "sampled", (ts, values), origin, interpolation)
        elif callable(source):
            ext = External(target, kind, "function", source, origin)
        else:
            if isinstance(source, numbers.Real) and not isinstance(source, (bool, np.bool_)) and kind == "Real":
                value: Any = float(source)
            else:
                try:
                    value = check_value(kind, source, f"input {target!r} ({origin})")
                except ValueError as exc:
                    what = {"String": "a text", "Binary": "bytes (or hexadecimal text)"}.get(kind, "a number")
                    raise WiringError(f"{exc}; the source must be {what}, a function of t or (t, values)") from None
            ext = External(target, kind, "constant", value, origin)
        self._externals[target] = ext
        self._drivers[target] = origin
        return self

    def replay(self, samples: tuple, held: str, sampled: Sequence[str]) -> System:
        """Replay a measured signal into a plant and into estimators, paired right.

        An FMU input holds its value over each communication step, so a plant driven by the
        samples ``f(t_k)`` responds to a staircase, which lags the samples by half a step; an
        estimator given the same samples would read that lag as physics (for a stiff plant,
        a half-step force lag looks like extra damping of about k h / 2). Here the plant's
        input ``held`` gets the samples held over each step, and every input of
        ``sampled`` gets the staircase's own sample at each communication point, the mean
        of the held values before and after it (as the adaptive controller's ``f_sample``),
        so that both see the same force.

        Parameters
        ----------
        samples : (t, values)
            The measured signal (see :meth:`set_input`).
        held : str
            The plant input (``"component.input"``).
        sampled : sequence of str
            The estimator inputs.

        Returns
        -------
        System
            self.
        """
        self._set_input(held, samples, "replay (held)", "hold")
        for target in ([sampled] if isinstance(sampled, str) else sampled):
            self._set_input(target, samples, "replay (sample of the held signal)", "sample-of-hold")
        return self

    def inputs_from_csv(self, path: str | os.PathLike[str], columns: Mapping[str, str],
                        interpolation: Mapping[str, str] | None = None) -> System:
        """Drive inputs from the columns of a CSV file.

        Parameters
        ----------
        path : str or os.PathLike
            CSV file: one header line with a time column ``t`` or ``time`` and named
            columns, then one row of numbers per sample (non-decreasing time; a time
            given on two rows marks a step, the second row holding from then on).
        columns : mapping
            CSV column -> ``"component.input"``.
        interpolation : mapping, optional
            CSV column -> "linear", "hold", "average" or "sample-of-hold" (default per
            input: see :meth:`set_input`).

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
                raise WiringError(f"{source}, line 1: no column {column!r}{suggest(column, header)}")
        wanted = [time_cols[0]] + list(columns)
        index = [header.index(c) for c in wanted]
        kinds = ["Real"] + [self._csv_kind(target) for target in columns.values()]
        data = np.empty((len(rows) - 1, len(wanted)), dtype=object)
        for i, row in enumerate(rows[1:]):
            line = i + 2
            if len(row) != len(header):
                raise WiringError(f"{source}, line {line}: {len(row)} fields, the header has {len(header)}")
            for j, (col, k) in enumerate(zip(wanted, index)):
                data[i, j] = _csv_value(kinds[j], row[k], f"{source}, line {line}, column {col!r}")
        if len(data) < 2:
            raise WiringError(f"{source}: needs at least 2 rows of samples, found {len(data)}")
        times = data[:, 0].astype(np.float64)
        steps = np.diff(times)
        bad = np.nonzero((steps < 0) | np.concatenate([[False], (steps[1:] == 0) & (steps[:-1] == 0)]))[0]
        if len(bad):
            raise WiringError(f"{source}, line {bad[0] + 3}, column {wanted[0]!r}: time "
                              f"{float(times[bad[0] + 1])!r} does not increase (previous {float(times[bad[0]])!r}"
                              "; a time may be given twice, to mark a step)")
        for column in interpolation or {}:
            if column not in columns:
                raise WiringError(f"{source}: interpolation given for {column!r}, which is not one of the columns "
                                  f"used ({', '.join(columns)})")
        for j, (column, target) in enumerate(columns.items(), start=1):
            self._set_input(target, (times, data[:, j].tolist()), f"column {column!r} of {source}",
                            (interpolation or {}).get(column))
        return self

    def _csv_kind(self, target: str) -> str:
        comp, var, _ = self._channel(target, "target")
        return comp.kind(var, "driven")

    # ---------------------------------------------------------------- inspection
    @property
    def components(self) -> list[str]:
        """Component names in insertion order."""
        return list(self._components)

    @property
    def connections(self) -> list[Connection]:
        """Connections in the order they were made."""
        return list(self._connections)

    def fmu(self, component: str) -> Path:
        """The FMU file of ``component``."""
        return self._component(component).path

    def parameter_values(self, component: str) -> dict[str, Any]:
        """The parameter values given to ``component`` (a copy, typed as they are set)."""
        return dict(self._component(component).parameters)

    def variable(self, full: str) -> Any:
        """The fmpy model variable of ``"component.variable"`` (read-only use)."""
        return self._lookup(full, "variable")[1]

    def model_description(self, component: str) -> Any:
        """fmpy's model description of ``component``'s FMU (read-only use)."""
        return self._component(component).md

    @property
    def wiring(self) -> Wiring:
        """A read-only view of the components, connections, external inputs and the variable
        lookup (what the runner and the container export read)."""
        return Wiring(MappingProxyType(self._components), tuple(self._connections),
                      MappingProxyType(self._externals), self._lookup, self._channel)

    @property
    def external_inputs(self) -> dict[str, str]:
        """Inputs driven from outside the system -> how: ``"constant"``, ``"function"``
        or ``"sampled"``."""
        return {target: ext.mode for target, ext in self._externals.items()}

    @property
    def constant_inputs(self) -> dict[str, float]:
        """Inputs driven by a constant -> its value."""
        return {target: ext.value for target, ext in self._externals.items() if ext.mode == "constant"}

    def _component(self, name: str) -> Component:
        try:
            return self._components[name]
        except KeyError:
            raise WiringError(f"no component {name!r} in the system{suggest(name, self._components)}") from None

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
        with the largest outgoing-minus-incoming count to the front. Every component whose
        FMU reads its inputs as samples of one instant gets them from one instant (the exact
        order among those that do; the greedy one must, else WiringError).

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
        edges, together = self._edges(), self._together()
        if n <= EXACT_ORDER_LIMIT:
            perm = _exact_order(n, edges, together)
        else:
            perm = _greedy_order(n, edges)
            perm = None if _skewed(perm, together) is not None else perm
        if perm is None:
            sampled = [names[v] for v in together]
            raise WiringError(f"no Gauss-Seidel order gives {', '.join(map(repr, sampled))} all inputs from one "
                              "instant (an FMU that reads its inputs as samples of one instant, such as an "
                              "estimator); give order=... or use ordering='jacobi'")
        return [names[i] for i in perm]

    def _together(self) -> dict[int, tuple[int, bool]]:
        """The components whose FMU reads its inputs as samples of one instant
        (:attr:`Component.sampled_inputs`), as index -> (bit set of the components that feed
        them, itself excluded; whether an input arrives at t_k anyway: a time-varying external
        input or a connection from itself)."""
        index = {name: i for i, name in enumerate(self._components)}
        out = {}
        for name, comp in self._components.items():
            if not comp.sampled_inputs:
                continue
            sources, at_tk = 0, any(ext.mode != "constant" and key.split(".", 1)[0] == name
                                    for key, ext in self._externals.items())
            for c in self._connections:
                if c.target.split(".", 1)[0] == name:
                    source = c.source.split(".", 1)[0]
                    at_tk = at_tk or source == name
                    sources |= 0 if source == name else 1 << index[source]
            out[index[name]] = (sources, at_tk)
        return out

    def _check_one_instant(self, order: Sequence[str]) -> None:
        """WiringError when a given Gauss-Seidel ``order`` feeds a component that reads its
        inputs as samples of one instant from two instants."""
        names = list(self._components)
        v = _skewed([names.index(name) for name in order], self._together())
        if v is None:
            return
        name = names[v]
        before = set(order[:list(order).index(name)])
        inputs = [c for c in self._connections if c.target.split(".", 1)[0] == name]
        earlier = [c.target for c in inputs if c.source.split(".", 1)[0] in before]
        later = [c.target for c in inputs if c.target not in earlier] + [
            key for key, ext in self._externals.items() if ext.mode != "constant" and key.split(".", 1)[0] == name]
        raise WiringError(f"order {list(order)}: {self._components[name].where()} reads its inputs as samples "
                          f"of one instant, but {', '.join(earlier)} would get values at t_k+1 and "
                          f"{', '.join(later)} at t_k (a skew it would read as physics); step it before "
                          "all its sources or after all of them, or use ordering='jacobi'")

    def _delayed(self, order: Sequence[str]) -> list[Connection]:
        pos = {c: i for i, c in enumerate(order)}
        return [c for c in self._connections
                if pos[c.source.split(".", 1)[0]] >= pos[c.target.split(".", 1)[0]]]

    # ---------------------------------------------------------------- running
    def run(self, stop_time: float, step: float, start_time: float = 0.0, ordering: str = "jacobi",
            order: Sequence[str] | None = None, record: Sequence[str] | None = None,
            progress: bool = False, loop: str = "auto") -> Result:
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
            Variables to record (``"component.variable"``, an array whole or one element
            ``"component.y[1,2]"``): outputs, local variables and externally driven inputs
            (connected inputs: record their source). Default: every output of every component
            (every type; arrays element by element) and every externally driven input.
        progress : bool
            Show a tqdm progress bar (updated in chunks of steps).
        loop : {"auto", "compiled", "python"}
            The inner loop: the macro steps in C over the FMUs' functions (``fmus/cosim``,
            compiled on first use), or in Python. The two give the same trajectories bit
            for bit; the C loop is faster. ``"auto"`` (default) takes the C loop unless a
            component is a Python FMU (pythonfmu), an input is a Python function, or no C
            compiler is found; ``"compiled"`` makes those cases an error (String and Binary
            values are copied by Python, called back from the C loop).
            ``Result.loop`` says which one ran.

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

        if ordering not in ORDERINGS:
            raise WiringError(f"ordering must be one of {ORDERINGS}, got {ordering!r}")
        if loop not in LOOP_MODES:
            raise WiringError(f"loop must be one of {LOOP_MODES}, got {loop!r}")
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
                                      f"{suggest(unknown[0], self._components)}")
                if sorted(sequence) != sorted(self._components):
                    missing = [c for c in self._components if c not in sequence]
                    raise WiringError(f"order must name every component exactly once; "
                                      f"missing {missing}, given {sequence}")
                self._check_one_instant(sequence)
            delayed = self._delayed(sequence)
        warnings: list[str] = []
        names = self._record_names(record, warnings)
        if loop == "compiled":
            reasons = obstacles(self._components.values(), self._externals.values(), self._connections)
            if reasons:
                raise WiringError("loop='compiled' cannot run this system: " + "; ".join(reasons))
        for comp in self._components.values():
            internal = getattr(comp.md.coSimulation, "fixedInternalStepSize", None)
            if internal is not None and float(step) < float(internal) * (1 - 1e-9):
                warnings.append(f"component {comp.name!r} ({comp.path}) computes with a fixed internal step of "
                                f"{float(internal)!r} s, longer than the communication step {float(step)!r} s: its "
                                "outputs change only every internal step (a staircase)")
        grid = float(start_time) + np.arange(n + 1) * float(step)
        sampled = {t: sampled_on_grid(e, grid) for t, e in self._externals.items() if e.mode == "sampled"}
        runner = Runner(self, grid, float(step), ordering, sequence, delayed, names, sampled, progress, loop)
        result = runner.execute()
        result.warnings = warnings
        return result

    def _record_names(self, record: Sequence[str] | None, warnings: list[str]) -> list[str]:
        """The recorded values' names (an array's elements ``comp.y[i,j]``), checked."""
        if record is None:
            names = []
            for comp in self._components.values():
                seen: dict[tuple[str, int], str] = {}
                for v in comp.md.modelVariables:
                    full = f"{comp.name}.{v.name}"
                    driven = [n for n in self._channel_names(comp, v, None) if n in self._externals]
                    if v.causality == "output":
                        key = (v.type, v.valueReference)
                        if key in seen and comp.version == 3:
                            warnings.append(f"{full} is an alias of {seen[key]} (the same value reference): "
                                            f"recorded once, as {seen[key]}")
                            continue
                        seen.setdefault(key, full)
                        names += self._channel_names(comp, v, None)
                    else:
                        names += driven
            return names
        if isinstance(record, str):
            raise WiringError("record must be a sequence of names, not a string")
        names = []
        for full in record:
            comp, var, index = self._channel(full, "recorded variable")
            comp.kind(var, "recorded")
            for name in self._channel_names(comp, var, index):
                if var.causality == "input" and name not in self._externals:
                    hint = next((f"; record its source {c.source!r}" for c in self._connections
                                 if c.target in (full, name)), "")
                    raise WiringError(f"recorded variable {name!r} is an input that no external source drives{hint}")
                if name in names:
                    raise WiringError(f"recorded variable {name!r} is listed twice")
                names.append(name)
        return names

    # ---------------------------------------------------------------- SSP
    @classmethod
    def from_ssp(cls, path: str | os.PathLike[str]) -> System:
        """The system of an SSP archive (``.ssp``) or of a bare ``.ssd`` file.

        The default experiment and duffid's run annotation are in
        :func:`duffid.cosim.ssp.read_ssp`'s result (and ``duffid cosim system.ssp`` uses
        them); this returns the system only. See :mod:`duffid.cosim.ssp` for what is
        supported and how SSP maps onto a system.

        Raises
        ------
        SspError
            What duffid cannot read or honour, naming the file, line and element.
        WiringError
            A wiring error, prefixed with the place in the file it comes from.
        """
        system = cls()
        read_ssp(path, system)
        return system

    def to_ssp(self, path: str | os.PathLike[str], *, stop_time: float, step: float, start_time: float = 0.0,
               ordering: str = "jacobi", order: Sequence[str] | None = None) -> Path:
        """Write the system as an SSP 1.0 archive: the FMUs, the connections, the parameter
        values and constant inputs (one ``.ssv`` per component), the default experiment and
        duffid's run annotation. See :func:`duffid.cosim.ssp.write_ssp` for the parameters
        and limits; returns the archive's path."""
        return write_ssp(self, path, stop_time=stop_time, step=step, start_time=start_time, ordering=ordering,
                         order=order)

    # ---------------------------------------------------------------- container
    def export_container(self, path: str | os.PathLike[str], inputs: Mapping[str, str | Sequence[str]] | None = None,
                         outputs: Mapping[str, str] | None = None, step: float = 1e-3,
                         parameters: Mapping[str, str | Sequence[str]] | None = None, fmi_version: int = 2) -> Path:
        """Write the system as one co-simulation container FMU, FMI 2.0 or 3.0 (duffid's
        container runtime).

        See :func:`duffid.cosim.container.export_container` for the parameters and
        limits.
        """
        return export_container(self, path, inputs=inputs, outputs=outputs, step=step, parameters=parameters,
                                fmi_version=fmi_version)
