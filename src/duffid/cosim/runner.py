"""The run of a :class:`duffid.cosim.system.System`: instantiation, the fixed-step master loops,
recording, failure handling and clean-up (private; see :mod:`duffid.cosim.system`).

The inner loop works on preallocated buffers: one value buffer per kind of value
(:mod:`duffid.cosim.value_types`) holds every needed output (each component's outputs
contiguous, an array's values one slot each, read with one raw FMI get call per kind straight
into it) and the external input values; each component's inputs are gathered from it with
``np.take(..., out=...)`` into a preallocated buffer and set with one raw set call per kind;
recording copies the buffer into a preallocated row. The raw ctypes functions that fmpy loaded
are called directly and their status is checked here. String and Binary values are Python
objects, got and set by :mod:`duffid.cosim.object_io`. An FMI 3 FMU with Event Mode has its
events handled between steps (:meth:`Runner._event`).
"""
from __future__ import annotations

import contextlib
import ctypes
import os
import shutil
import signal
import tempfile
import threading
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from ..errors import CosimError
from . import compiled_loop, instances
from .compiled_loop import CompiledLoop
from .elements import (
    N_MESSAGES,
    N_REPORTED,
    STATUS_NAMES,
    Component,
    Connection,
    External,
    Failure,
    Result,
    WiredSystem,
    check_external_value,
)
from .object_io import object_getter, object_setter
from .value_types import DTYPES, FMI_FUNCTIONS, OBJECT_KINDS, VARIABLE_KINDS, parse_start

__all__ = ["Runner", "signals_held"]

#: Most fmi3UpdateDiscreteStates calls of one event iteration (an FMU still asking is a failure).
_EVENT_ITERATIONS = 100
#: Macro steps per call of the compiled loop: signals (Ctrl-C, SIGTERM) are acted on between calls.
_COMPILED_CHUNK = 5000

@dataclass(eq=False)
class _Input:
    """An input variable a run sets: the buffer slot of each of its values (a connection's
    source, an external input, or a slot holding the start value of an element nothing
    drives), each value's (factor, offset) of a transformed connection or None, and whether it
    is set every step (connected or driven by a non-constant) or at initialisation only."""

    variable: Any
    kind: str
    size: int
    slots: list = field(default_factory=list)
    affine: list = field(default_factory=list)
    every_step: bool = False

    def __post_init__(self) -> None:
        self.slots = [None] * self.size
        self.affine = [None] * self.size

    @property
    def transformed(self) -> bool:
        return any(a is not None for a in self.affine)

    @property
    def contiguous(self) -> bool:
        """Whether its values' slots follow each other in the buffer."""
        return self.slots == list(range(self.slots[0], self.slots[0] + self.size))


class _StepFailure(Exception):
    """An FMI call returned a status worse than Warning."""

    def __init__(self, ci: int, function: str, status: int | str, t: float) -> None:
        super().__init__(function)
        self.ci, self.function, self.status, self.t = ci, function, status, t


class _Terminated(Exception):
    """A component asked to end the simulation (FMI 2 Discard + fmi2Terminated, FMI 3
    terminateSimulation); ``full``: it completed the step (a final row is recorded)."""

    def __init__(self, ci: int, t_last: float, full: bool) -> None:
        super().__init__(ci)
        self.ci, self.t_last, self.full = ci, t_last, full


class _Interrupted(Exception):
    """SIGTERM during a run (handled as Ctrl-C is)."""


def _succeeds(call: Any) -> bool:
    """Whether an fmpy binding's call returned OK or Warning (fmpy raises on the others)."""
    try:
        call()
    except Exception:  # fmpy's FMICallException, or a crash reported as an error
        return False
    return True


@contextlib.contextmanager
def signals_held() -> Iterator[None]:
    """A block that Ctrl-C (SIGINT) and SIGTERM cannot interrupt (in the main thread; they
    are ignored meanwhile): the release of FMU instances, the writing of the rows so far."""
    main = threading.current_thread() is threading.main_thread()
    held = [(sig, signal.signal(sig, signal.SIG_IGN)) for sig in (signal.SIGINT, signal.SIGTERM)] if main else []
    try:
        yield
    finally:
        for sig, handler in held:
            signal.signal(sig, handler)


def _interrupt(signum: int, frame: Any) -> None:
    raise _Interrupted(f"interrupted by {signal.Signals(signum).name}")


class _InputFailure(Exception):
    """A user input function raised (or returned something unusable)."""

    def __init__(self, ext: External, ci: int, t: float, exc: BaseException) -> None:
        super().__init__(ext.target)
        self.ext, self.ci, self.t, self.exc = ext, ci, t, exc


class _Instance:
    """One component's instance during a run: the fmpy slave, its callbacks and log."""

    def __init__(self, comp: Component, index: int) -> None:
        self.comp, self.index = comp, index
        self.slave: Any = None
        self.state = "new"   # new, instantiated, initializing, stepping, failed (status), freed
        self.failed_status = 0
        self.messages: deque[str] = deque(maxlen=N_MESSAGES)
        self.callbacks: Any = None
        self.holder: list = [self]     # the run the FMU's log callback reports to (a reused instance moves)
        self.pool_key: tuple | None = None  # set when the instance may be kept in the active pool

    def log(self, status: int, category: bytes | None, message: bytes | None) -> None:
        cat = category.decode("utf-8", "replace") if category else ""
        text = message.decode("utf-8", "replace") if message else ""
        self.messages.append(f"[{STATUS_NAMES.get(status, status)}] {cat + ': ' if cat else ''}{text}")


class Runner:
    """Runs a system once (see :meth:`duffid.cosim.system.System.run`)."""

    def __init__(self, system: WiredSystem, grid: np.ndarray, step: float, ordering: str, sequence: list[str],
                 delayed: list[Connection], names: list[str], sampled: dict[str, np.ndarray],
                 progress: bool, loop: str = "auto") -> None:
        self.system, self.grid, self.step = system, grid, step
        self.loop_mode, self.loop_used = loop, "python"
        self.n = len(grid) - 1
        self.ordering, self.sequence, self.delayed, self.names = ordering, sequence, delayed, names
        self.sampled, self.progress = sampled, progress
        comps = list(system.wiring.components.values())
        self.instances = [_Instance(c, i) for i, c in enumerate(comps)]
        self.index = {c.name: i for i, c in enumerate(comps)}
        self.rows = 0
        self.tmp: str | None = None
        self._layout()

    # ------------------------------------------------------------------ layout
    def _layout(self) -> None:
        """Slots of every needed value in the per-kind buffers; no FMU is touched. A variable
        read from an FMU takes one slot per value (an array's in row-major order), an external
        input one slot, and an element of an array input that nothing drives a slot holding its
        start value (FMI sets an array whole)."""
        wiring = self.system.wiring
        externals = wiring.externals
        channel = wiring.channel
        wanted = set()
        for full in [c.source for c in wiring.connections] + [n for n in self.names if n not in externals]:
            comp, var, _ = channel(full, "variable")
            wanted.add((comp.name, var.name))
        self.slots: dict[str, tuple[str, int]] = {}  # "comp.var" -> first slot; an external's target -> its slot
        counts = {k: 0 for k in DTYPES}
        self.reads: list[dict[str, list[tuple[str, int, int]]]] = []   # per component: kind -> [(var, vr, size)]
        self.read_lo: list[dict[str, int]] = []
        for inst in self.instances:
            comp = inst.comp
            reads: dict[str, list[tuple[str, int, int]]] = {}
            lows: dict[str, int] = {}
            for v in comp.md.modelVariables:
                if (comp.name, v.name) in wanted:
                    kind, size = VARIABLE_KINDS[v.type], comp.size(v)
                    lows.setdefault(kind, counts[kind])
                    reads.setdefault(kind, []).append((v.name, v.valueReference, size))
                    self.slots[f"{comp.name}.{v.name}"] = (kind, counts[kind])
                    counts[kind] += size
            self.reads.append(reads)
            self.read_lo.append(lows)
        # external inputs: constants, then sampled, then functions (per kind)
        self.ext_sampled: dict[str, list[External]] = {k: [] for k in DTYPES}
        self.ext_functions: list[tuple[str, int, External]] = []
        self.ext_lo = dict(counts)
        for mode in ("constant", "sampled", "function"):
            for ext in externals.values():
                if ext.mode == mode:
                    self.slots[ext.target] = (ext.kind, counts[ext.kind])
                    if mode == "sampled":
                        self.ext_sampled[ext.kind].append(ext)
                    elif mode == "function":
                        self.ext_functions.append((ext.kind, counts[ext.kind], ext))
                    counts[ext.kind] += 1
        # per component inputs: kind -> [_Input], set every step when connected or driven by a non-constant
        self.inputs: list[dict[str, list[_Input]]] = [dict() for _ in self.instances]
        plans: dict[tuple[str, str], _Input] = {}

        def plan(full: str) -> tuple[_Input, int | None]:
            comp, var, index = channel(full, "target")
            entry = plans.get((comp.name, var.name))
            if entry is None:
                entry = plans[(comp.name, var.name)] = _Input(var, VARIABLE_KINDS[var.type], comp.size(var))
                self.inputs[self.index[comp.name]].setdefault(entry.kind, []).append(entry)
            return entry, index

        for conn in wiring.connections:
            entry, index = plan(conn.target)
            scomp, svar, sindex = channel(conn.source, "source")
            first = self.slots[f"{scomp.name}.{svar.name}"][1] + (sindex or 0)
            positions = range(entry.size) if index is None and sindex is None else [index or 0]
            for i, p in enumerate(positions):
                entry.slots[p] = first + i
                if conn.transformed:
                    entry.affine[p] = (conn.factor, conn.offset)
            entry.every_step = True
        for ext in externals.values():
            entry, index = plan(ext.target)
            entry.slots[index or 0] = self.slots[ext.target][1]
            entry.every_step |= ext.mode != "constant"
        fills: list[tuple[str, int, Any]] = []
        for entry in plans.values():
            starts = parse_start(entry.kind, entry.variable.start, entry.size)
            for p, slot in enumerate(entry.slots):
                if slot is None:
                    entry.slots[p] = counts[entry.kind]
                    fills.append((entry.kind, counts[entry.kind], starts[p]))
                    counts[entry.kind] += 1
        # zero, and for String and Binary the empty value: what a connected input gets during initialisation
        self.g = {k: np.full(max(counts[k], 1), parse_start(k, None, 1)[0], dtype=DTYPES[k]) for k in DTYPES}
        for ext in externals.values():
            if ext.mode == "constant":
                kind, slot = self.slots[ext.target]
                self.g[kind][slot] = ext.value
        for kind, slot, value in fills:
            self.g[kind][slot] = value
        self.tables = {}
        for kind, exts in self.ext_sampled.items():
            if exts:
                lo = self.ext_lo[kind] + sum(1 for e in externals.values() if e.mode == "constant" and e.kind == kind)
                table = np.column_stack([self.sampled[e.target] for e in exts]).astype(DTYPES[kind])
                self.tables[kind] = (self.g[kind][lo:lo + len(exts)], table)
        # recording
        self.records = {}
        self.columns: dict[str, tuple[str, int]] = {}
        by_kind: dict[str, list[int]] = {k: [] for k in DTYPES}
        for name in self.names:
            kind, slot = self._slot(name)
            self.columns[name] = (kind, len(by_kind[kind]))
            by_kind[kind].append(slot)
        for kind, slots in by_kind.items():
            if slots:
                idx = np.array(slots, dtype=np.intp)
                identity = len(slots) == len(self.g[kind]) and np.array_equal(idx, np.arange(len(slots)))
                self.records[kind] = (np.zeros((self.n + 1, len(slots)), dtype=DTYPES[kind]), idx, identity)

    def _slot(self, name: str) -> tuple[str, int]:
        """The kind and slot of a recorded value (an external input, a variable or an element)."""
        if name in self.system.wiring.externals:
            return self.slots[name]
        comp, var, index = self.system.wiring.channel(name, "recorded variable")
        kind, first = self.slots[f"{comp.name}.{var.name}"]
        return kind, first + (index or 0)

    # ------------------------------------------------------------------ instances
    def _instantiate(self, inst: _Instance) -> None:
        import fmpy
        from fmpy.fmi2 import defaultCallbacks, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE

        comp = inst.comp
        assert self.tmp is not None
        pool = instances.active()
        if pool is None:
            unzipdir = fmpy.extract(str(comp.path), str(Path(self.tmp) / comp.name))
        else:
            unzipdir = pool.unzipdir(comp.path)
            if pool.reusable(comp.md.generationTool):
                inst.pool_key = (pool.file_key(comp.path), comp.name, comp.version, comp.logging)
                pooled = pool.take(inst.pool_key)
                if pooled is not None:  # reset at the end of an earlier run: as if just instantiated
                    inst.slave, inst.callbacks, inst.holder = pooled
                    inst.holder[0] = inst
                    inst.state = "instantiated"
                    return
            pool.count_instantiation()
        ident = comp.md.coSimulation.modelIdentifier
        inst.slave = self._load(inst, unzipdir, ident)
        holder = inst.holder
        if comp.version == 2:

            def logger(env: Any, name: Any, status: int, category: bytes, message: bytes) -> None:
                if holder[0] is not None:
                    holder[0].log(status, category, message.replace(b"%%", b"%") if message else message)

            callbacks = fmi2CallbackFunctions()
            callbacks.logger = fmi2CallbackLoggerTYPE(logger)
            callbacks.allocateMemory = defaultCallbacks.allocateMemory
            callbacks.freeMemory = defaultCallbacks.freeMemory
            inst.callbacks = callbacks  # alive as long as the instance
            try:
                inst.slave.instantiate(callbacks=callbacks, loggingOn=comp.logging)
            except Exception:
                self._unload(inst)
                raise _StepFailure(inst.index, "fmi2Instantiate", "NULL (instantiation failed)", self.grid[0])
        else:

            def log3(env: Any, status: int, category: bytes, message: bytes) -> None:
                if holder[0] is not None:
                    holder[0].log(status, category, message)

            try:
                inst.slave.instantiate(loggingOn=comp.logging, logMessage=log3,  # fmpy keeps the callback
                                       eventModeUsed=comp.event_mode)
                failed = not inst.slave.component
            except Exception:
                failed = True
            if failed:
                self._unload(inst)
                raise _StepFailure(inst.index, "fmi3InstantiateCoSimulation", "NULL (instantiation failed)",
                                   self.grid[0])
        inst.state = "instantiated"

    def _load(self, inst: _Instance, unzipdir: str, identifier: str) -> Any:
        """fmpy's slave object for the component: its binary loaded. fmpy changes the working
        directory while it loads a library; it is restored whatever happens, and a binary that
        cannot be loaded is a failure naming the component and its FMU."""
        from fmpy.fmi2 import FMU2Slave
        from fmpy.fmi3 import FMU3Slave

        comp = inst.comp
        cwd = os.getcwd()
        try:
            if comp.version == 2:
                return FMU2Slave(guid=comp.md.guid, unzipDirectory=unzipdir, modelIdentifier=identifier,
                                 instanceName=comp.name)
            return FMU3Slave(guid=comp.md.instantiationToken, unzipDirectory=unzipdir, modelIdentifier=identifier,
                             instanceName=comp.name)
        except Exception as exc:
            inst.log(3, b"load", f"{type(exc).__name__}: {exc}".encode())
            raise _StepFailure(inst.index, "loading the binary", "cannot be loaded", self.grid[0]) from None
        finally:
            os.chdir(cwd)

    @staticmethod
    def _unload(inst: _Instance) -> None:
        """Unload the binary of an instance that does not exist (no call may reach it again)."""
        try:
            inst.slave.freeLibrary()
        finally:
            inst.slave = None
            inst.state = "freed"

    def _call(self, inst: _Instance, method: str, *args: Any, at: float | None = None, **kwargs: Any) -> Any:
        """A call through fmpy's high-level API (set-up, Event Mode), status exceptions converted
        (``at``: the time a failure is reported at, default the start)."""
        from fmpy.fmi1 import FMICallException

        try:
            return getattr(inst.slave, method)(*args, **kwargs)
        except FMICallException as exc:
            raise _StepFailure(inst.index, exc.function, exc.status, self.grid[0] if at is None else at) from None

    def _event(self, ci: int, t: float, entered: bool = False) -> None:
        """Event Mode of an FMI 3 component that uses it (``hasEventMode``): after a doStep that set
        eventHandlingNeeded (and after initialisation, which ends in Event Mode), enter Event Mode,
        update the discrete states until the FMU needs no further update, return to Step Mode. A
        request to end the simulation ends the run after this macro step."""
        inst = self.instances[ci]
        if not entered:
            self._call(inst, "enterEventMode", at=t)
        for _ in range(_EVENT_ITERATIONS):
            again, terminate, *_ = self._call(inst, "updateDiscreteStates", at=t)
            if terminate:
                self.ending = _Terminated(ci, t, True)
            if not again:
                break
        else:
            inst.log(3, b"duffid", f"the discrete states still need an update after {_EVENT_ITERATIONS} "
                                   "iterations of fmi3UpdateDiscreteStates".encode())
            raise _StepFailure(ci, "fmi3UpdateDiscreteStates", "no fixed point", t)
        self._call(inst, "enterStepMode", at=t)

    def _set_parameters(self, inst: _Instance) -> None:
        """The parameter values given to ``System.add``, through fmpy's setters; FMI 3 structural
        parameters first, in Configuration Mode."""
        comp = inst.comp
        given = [(comp.variables[name], value) for name, value in comp.parameters.items()]
        structural = [(v, value) for v, value in given if v.causality == "structuralParameter"]
        if structural:
            self._call(inst, "enterConfigurationMode")
            for var, value in structural:
                self._set_value(inst, var, value)
            self._call(inst, "exitConfigurationMode")
        for var, value in given:
            if var.causality != "structuralParameter":
                self._set_value(inst, var, value)

    def _set_value(self, inst: _Instance, var: Any, value: Any) -> None:
        """Set ``var`` (an array: its values, flat) with fmpy's setter of its type."""
        if inst.comp.version == 2:
            method = {"Real": "setReal", "Enumeration": "setInteger"}.get(var.type, "set" + var.type)
        else:
            method = "set" + ("Int64" if var.type == "Enumeration" else var.type)
        self._call(inst, method, [var.valueReference], value if isinstance(value, list) else [value])

    def _build_ops(self) -> None:
        """ctypes arrays and bound raw functions of the inner loop."""
        self.set_ops: list[list[tuple]] = []      # per component: every-step input sets
        self.init_ops: list[list[tuple]] = []     # per component: external inputs at t0
        self.get_ops: list[list[tuple]] = []
        self.post_ops: list[list[tuple]] = []     # FMI 3 Boolean staging -> value buffer
        self.step_ops: list[tuple] = []
        self._keep: list[Any] = []
        self.t_arg, self.h_arg = ctypes.c_double(float(self.grid[0])), ctypes.c_double(self.step)
        for inst in self.instances:
            comp, slave, ci = inst.comp, inst.slave, inst.index
            version, handle = comp.version, ctypes.c_void_p(slave.component)

            def raw(name: str, slave: Any = slave) -> Any:
                # a fresh function object without argtypes: every argument below is already
                # a ctypes object, so no per-call conversion (fmpy's own objects keep theirs)
                function = slave.dll[name]
                function.restype, function.argtypes = ctypes.c_int, None
                return function

            self._keep.append(handle)
            sets, inits, gets, posts = [], [], [], []

            def call_args(vrs: Any, ptr: Any, n_values: int) -> tuple:
                size = ctypes.c_size_t(len(vrs))
                return (handle, vrs, size, ptr) + ((ctypes.c_size_t(n_values),) if version == 3 else ())

            for kind, entries in self.inputs[ci].items():
                _, set_name, ctype = FMI_FUNCTIONS[version][kind]
                setf = raw(set_name)
                g = self.g[kind]
                for subset, target in ((entries, inits), ([e for e in entries if e.every_step], sets)):
                    if kind in OBJECT_KINDS:
                        if subset:
                            vrs = (ctypes.c_uint * len(subset))(*[e.variable.valueReference for e in subset])
                            self._keep.append(vrs)
                            call = object_setter(setf, handle, vrs, kind, version, g,
                                                 [s for e in subset for s in e.slots])
                            target.append((g, None, None, call, (), ci, set_name, None))
                        continue
                    # a transformed connection is gathered, scaled and shifted in its own buffer (one set call),
                    # every step; during initialisation its input keeps its start value (no output is read yet)
                    transformed = [e for e in subset if e.transformed] if target is sets else []
                    if transformed:
                        vrs = (ctypes.c_uint * len(transformed))(*[e.variable.valueReference for e in transformed])
                        idx = np.array([s for e in transformed for s in e.slots], dtype=np.intp)
                        buf = np.zeros(len(idx), dtype=np.dtype(ctype))
                        pairs = [a or (1.0, 0.0) for e in transformed for a in e.affine]
                        affine = (np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs]))
                        ptr = buf.ctypes.data_as(ctypes.POINTER(ctype))
                        self._keep += [vrs, buf, ptr]
                        target.append((g, idx, buf, setf, call_args(vrs, ptr, len(idx)), ci, set_name, affine))
                    plain = sorted((e for e in subset if not e.transformed), key=lambda e: e.slots[0])
                    runs: list[list[_Input]] = []   # inputs whose sources follow each other in the buffer
                    for e in plain:
                        if runs and runs[-1][-1].contiguous and e.contiguous and \
                                runs[-1][-1].slots[-1] + 1 == e.slots[0]:
                            runs[-1].append(e)
                        else:
                            runs.append([e])
                    if np.dtype(ctype) == g.dtype and len(runs) <= 2 and all(e.contiguous for e in plain):
                        # the sources are contiguous in the value buffer: set straight from it
                        for run in runs:
                            vrs = (ctypes.c_uint * len(run))(*[e.variable.valueReference for e in run])
                            ptr = ctypes.cast(g.ctypes.data + run[0].slots[0] * g.itemsize, ctypes.POINTER(ctype))
                            self._keep += [vrs, ptr]
                            target.append((g, None, None, setf, call_args(vrs, ptr, sum(e.size for e in run)), ci,
                                           set_name, None))
                    elif plain:  # gather with np.take into a buffer, one set call
                        vrs = (ctypes.c_uint * len(plain))(*[e.variable.valueReference for e in plain])
                        idx = np.array([s for e in plain for s in e.slots], dtype=np.intp)
                        buf = np.zeros(len(idx), dtype=np.dtype(ctype))
                        ptr = buf.ctypes.data_as(ctypes.POINTER(ctype))
                        self._keep += [vrs, buf, ptr]
                        target.append((g, idx, buf, setf, call_args(vrs, ptr, len(idx)), ci, set_name, None))
            for kind, entries in self.reads[ci].items():
                get_name, _, ctype = FMI_FUNCTIONS[version][kind]
                g = self.g[kind]
                lo = self.read_lo[ci][kind]
                n_values = sum(e[2] for e in entries)
                vrs = (ctypes.c_uint * len(entries))(*[e[1] for e in entries])
                self._keep.append(vrs)
                if kind in OBJECT_KINDS:
                    gets.append((object_getter(raw(get_name), handle, vrs, n_values, kind, version, g, lo), (), ci,
                                 get_name))
                    continue
                if np.dtype(ctype) == g.dtype:
                    ptr = ctypes.cast(g.ctypes.data + lo * g.itemsize, ctypes.POINTER(ctype))
                else:  # FMI 3 Boolean (1 byte), FMI 2 Enumeration (4 bytes): read into staging, then copy
                    staging = np.zeros(n_values, dtype=np.dtype(ctype))
                    ptr = staging.ctypes.data_as(ctypes.POINTER(ctype))
                    posts.append((g[lo:lo + n_values], staging))
                    self._keep.append(staging)
                self._keep.append(ptr)
                gets.append((raw(get_name), call_args(vrs, ptr, n_values), ci, get_name))
            if version == 2:
                term = ctypes.c_bool(False)
                args = (handle, self.t_arg, self.h_arg, ctypes.c_int(1))
                self.step_ops.append((raw("fmi2DoStep"), args, ci, "fmi2DoStep", term, None, None))
            else:
                flags = [ctypes.c_bool(False) for _ in range(3)] + [ctypes.c_double(0.0)]
                args = (handle, self.t_arg, self.h_arg, ctypes.c_bool(True)) + tuple(ctypes.pointer(f) for f in flags)
                self._keep.append(flags)
                self.step_ops.append((raw("fmi3DoStep"), args, ci, "fmi3DoStep", flags[1], flags,
                                      flags[0] if comp.event_mode else None))
            self.set_ops.append(sets)
            self.init_ops.append(inits)
            self.get_ops.append(gets)
            self.post_ops.append(posts)

    def _initialize(self) -> None:
        t0, t_end = float(self.grid[0]), float(self.grid[-1])
        self.ending: _Terminated | None = None
        for kind, (view, table) in self.tables.items():
            view[...] = table[0]
        self._evaluate_functions(t0)
        for inst in self.instances:
            if inst.comp.version == 2:
                self._call(inst, "setupExperiment", startTime=t0, stopTime=t_end)
                self._set_parameters(inst)
                self._call(inst, "enterInitializationMode")
            else:
                self._set_parameters(inst)
                self._call(inst, "enterInitializationMode", startTime=t0, stopTime=t_end)
            inst.state = "initializing"
            for g, idx, buf, setf, args, ci, fname, affine in self.init_ops[inst.index]:
                if idx is not None:
                    np.take(g, idx, out=buf)
                if affine is not None:
                    buf *= affine[0]
                    buf += affine[1]
                status = setf(*args)
                if status > 1:
                    raise _StepFailure(ci, fname, status, t0)
            self._call(inst, "exitInitializationMode")
            if inst.comp.event_mode:  # FMI 3 Co-Simulation with Event Mode leaves initialisation in it
                self._event(inst.index, t0, entered=True)
            inst.state = "stepping"
        self._read_all(t0)
        self._record(0)
        self.rows = 1

    def _read_all(self, t: float) -> None:
        for gets, posts in zip(self.get_ops, self.post_ops):
            for getf, args, ci, fname in gets:
                status = getf(*args)
                if status > 1:
                    raise _StepFailure(ci, fname, status, t)
            for dst, src in posts:
                dst[...] = src

    def _evaluate_functions(self, t: float) -> None:
        for kind, slot, ext in self.ext_functions:
            try:
                self.g[kind][slot] = check_external_value(ext, ext.value(t), t)
            except Exception as exc:
                raise _InputFailure(ext, self.index[ext.target.split(".", 1)[0]], t, exc) from exc

    def _record(self, row: int) -> None:
        for kind, (rec, idx, identity) in self.records.items():
            if identity:
                rec[row] = self.g[kind]
            else:
                np.take(self.g[kind], idx, out=rec[row])

    # ------------------------------------------------------------------ loops
    def _chunks(self, largest: int | None = None) -> Any:
        n = self.n
        if not self.progress:
            size = largest or max(n, 1)
            for start in range(0, n, size):
                yield start, min(n, start + size)
            return
        from tqdm import tqdm

        size = max(1, min(n // 100, largest or n))
        with tqdm(total=n, unit="step", desc="co-simulation") as bar:
            for start in range(0, n, size):
                stop = min(n, start + size)
                yield start, stop
                bar.update(stop - start)

    def _loop(self) -> None:
        grid = self.grid.tolist()
        take = np.take
        records = [(rec, idx, identity, self.g[kind]) for kind, (rec, idx, identity) in self.records.items()]
        tables = [(view, table) for view, table in self.tables.values()]
        functions = [(self.g[kind], slot, ext, ext.value, ext.kind == "Real", self.index[ext.target.split(".")[0]])
                     for kind, slot, ext in self.ext_functions]
        posts = [p for ps in self.post_ops for p in ps]
        if self.ordering == "jacobi":
            stages = [([s for ss in self.set_ops for s in ss], self.step_ops,
                       [g for gs in self.get_ops for g in gs], posts)]
        else:
            stages = [(self.set_ops[self.index[c]], [self.step_ops[self.index[c]]], self.get_ops[self.index[c]],
                       self.post_ops[self.index[c]]) for c in self.sequence]
        if self.ending is not None:  # a component asked to end the simulation in its initial event iteration
            raise self.ending
        compiled = self._compiled_loop(stages)
        if compiled is not None:
            self._run_compiled(compiled)
            return
        k = 0
        t = grid[0]
        t_arg = self.t_arg
        try:
            for start, stop in self._chunks():
                for k in range(start, stop):
                    t = grid[k]
                    t_arg.value = t
                    for sets, steps, gets, stage_posts in stages:
                        for g, idx, buf, setf, args, ci, fname, affine in sets:
                            if idx is not None:
                                take(g, idx, out=buf)
                            if affine is not None:
                                buf *= affine[0]
                                buf += affine[1]
                            status = setf(*args)
                            if status > 1:
                                raise _StepFailure(ci, fname, status, t)
                        for stepf, step_args, ci, fname, term, flags, event in steps:
                            status = stepf(*step_args)
                            if status > 1 or term.value:
                                self._ended(ci, fname, status, flags, t)
                            elif event is not None and event.value:
                                self._event(ci, grid[k + 1])
                        for getf, args, ci, fname in gets:
                            status = getf(*args)
                            if status > 1:
                                raise _StepFailure(ci, fname, status, grid[k + 1])
                        for dst, src in stage_posts:
                            dst[...] = src
                    t1 = grid[k + 1]
                    for view, table in tables:
                        view[...] = table[k + 1]
                    for g, slot, ext, func, real, ci in functions:
                        try:
                            g[slot] = func(t1) if real else check_external_value(ext, func(t1), t1)
                        except Exception as exc:
                            raise _InputFailure(ext, ci, t1, exc) from exc
                    for rec, idx, identity, g in records:
                        if identity:
                            rec[k + 1] = g
                        else:
                            take(g, idx, out=rec[k + 1])
                    if self.ending is not None:  # the step completed: its row is recorded
                        raise self.ending
        except BaseException as exc:
            self.rows = k + 2 if isinstance(exc, _Terminated) and exc.full else k + 1
            self.t_fail = t
            raise
        self.rows = self.n + 1

    def _compiled_loop(self, stages: list[tuple]) -> CompiledLoop | None:
        """The C loop over this run's operations, where it can run them: every component a C
        FMU (not pythonfmu, which runs Python inside its calls), no input function to call in
        Python, and a C compiler (else None: the Python loop)."""
        if self.loop_mode == "python" or compiled_loop.obstacles(
                [inst.comp for inst in self.instances], self.system.wiring.externals.values(),
                self.system.wiring.connections):
            return None  # System.run refused loop="compiled" for these
        moves: list[tuple] = []
        for kind, (view, table) in self.tables.items():
            if kind in OBJECT_KINDS:  # Python objects: copied by Python, called back from the C loop
                moves.append((lambda row, view=view, table=table: view.__setitem__(Ellipsis, table[row]),))
            else:
                moves.append((view, table, None, 0, table.strides[0]))
        for kind, (rec, idx, identity) in self.records.items():
            if kind in OBJECT_KINDS:
                moves.append((lambda row, rec=rec, idx=idx, g=self.g[kind]: np.take(g, idx, out=rec[row]),))
            else:
                moves.append((rec, self.g[kind], None if identity else idx, rec.strides[0], 0))

        def on_step(op: int, status: int, k: int) -> int:
            _, _, ci, fname, term, flags, event = loop.step_entries[op]
            if status <= 1 and not term.value:  # an FMU in Event Mode asked for it
                self._event(ci, float(self.grid[k + 1]))
                return compiled_loop.EVENT_HANDLED
            self._ended(ci, fname, status, flags, float(self.grid[k]))  # raises unless the FMU ended the run
            return compiled_loop.STEP_ENDED

        loop = CompiledLoop(compiled_loop.load(), self.grid, self.step, stages, moves, on_step)
        return loop

    def _run_compiled(self, loop: CompiledLoop) -> None:
        """The macro steps in C, in chunks (Ctrl-C and SIGTERM act between them)."""
        self.loop_used = "compiled"
        try:
            for start, stop in self._chunks(_COMPILED_CHUNK):
                code = loop.run(start, stop)
                k = loop.failed_step.value
                if code == compiled_loop.SET_FAILED:
                    ci, fname = loop.set_entries[loop.failed_op.value][5:7]
                    raise _StepFailure(ci, fname, loop.failed_status.value, float(self.grid[k]))
                if code == compiled_loop.GET_FAILED:
                    _, _, ci, fname = loop.get_entries[loop.failed_op.value]
                    raise _StepFailure(ci, fname, loop.failed_status.value, float(self.grid[k + 1]))
                if code == compiled_loop.ENDED:
                    raise self.ending
        except BaseException as exc:
            k = loop.failed_step.value
            self.rows = k + 2 if isinstance(exc, _Terminated) and exc.full else k + 1
            self.t_fail = float(self.grid[min(k, self.n)])
            raise
        self.rows = self.n + 1

    def _ended(self, ci: int, function: str, status: int, flags: Any, t: float) -> None:
        """A doStep that did not simply succeed: a request to end the simulation (raises
        :class:`_Terminated` for a partial step, or records it in ``self.ending`` and returns
        so that the macro step completes and its row is recorded), else a failure."""
        inst = self.instances[ci]
        slave, h = inst.slave, self.step
        handle = ctypes.c_void_p(slave.component)
        if inst.comp.version == 2:
            terminated = ctypes.c_int(0)
            if status != 2 or slave.dll.fmi2GetBooleanStatus(handle, 3, ctypes.byref(terminated)) > 1 or \
                    not terminated.value or any(m.startswith(("[Error]", "[Fatal]")) for m in inst.messages):
                # 3: fmi2Terminated; a component that logged an error failed, whatever it asks
                raise _StepFailure(ci, function, status, t)
            last = ctypes.c_double(t)
            if slave.dll.fmi2GetRealStatus(handle, 2, ctypes.byref(last)) > 1:  # 2: fmi2LastSuccessfulTime
                last.value = t
            inst.state, inst.failed_status = "failed", 2  # terminate, then free
            t_last = last.value
        else:
            if status > 1:
                raise _StepFailure(ci, function, status, t)
            # lastSuccessfulTime is the time reached when the FMU returned early or asks to end (it may
            # stop inside the step without an early return, which this host does not allow); a value
            # outside the step (an FMU that does not set it) is not believed
            reached = flags[3].value
            inside = t - 1e-9 * h <= reached <= t + h * (1 + 1e-9)
            t_last = reached if (flags[2].value or flags[1].value) and inside else t + h
        full = abs(t_last - (t + h)) <= 1e-9 * h
        self.ending = _Terminated(ci, t_last, full)
        if not full:
            raise self.ending

    # ------------------------------------------------------------------ driver
    def execute(self) -> Result:
        """Instantiate, initialise, loop, release; a :class:`Result` or :class:`CosimError`.

        In the main thread, SIGTERM interrupts the run as Ctrl-C does (the rows so far are
        kept in the error's result), and neither signal can interrupt the release of the
        instances and the deletion of the extracted FMUs.
        """
        main = threading.current_thread() is threading.main_thread()
        previous = signal.signal(signal.SIGTERM, _interrupt) if main else None
        try:
            return self._execute()
        finally:
            if main:
                signal.signal(signal.SIGTERM, previous)

    def _execute(self) -> Result:
        self.tmp = tempfile.mkdtemp(prefix="duffid-cosim-")
        self.t_fail = float(self.grid[0])
        try:
            for inst in self.instances:
                self._instantiate(inst)
            self._build_ops()
            self._initialize()
            self._loop()
        except _Terminated as end:
            self._release(None)
            inst = self.instances[end.ci]
            t_k = float(self.grid[self.rows - 1])
            note = (f"component {inst.comp.name!r} ({inst.comp.path}) asked to end the simulation at "
                    f"t = {end.t_last!r}" + ("" if end.full else
                                             f", during the step from t = {t_k!r}: the last row is t = {t_k!r}")
                    + ("" if inst.comp.logging or inst.comp.version == 3 else
                       " (FMI 2 cannot tell a failure from a request to stop, and its logging is off: if it "
                       "failed, System.add(..., logging=True) shows why)"))
            return self._result(None, note)
        except BaseException as exc:
            with signals_held():  # a second Ctrl-C must not lose the clean-up or the rows
                failure = self._failure(exc)
                self._release(failure)
                partial = self._result(failure)
            raise CosimError(failure, partial) from (
                exc.exc if isinstance(exc, _InputFailure) else None if isinstance(exc, _StepFailure) else exc)
        self._release(None)
        return self._result(None)

    def _failure(self, exc: BaseException) -> Failure:
        if isinstance(exc, _StepFailure):
            inst = self.instances[exc.ci]
            status = STATUS_NAMES.get(exc.status, str(exc.status)) if isinstance(exc.status, int) else exc.status
            if inst.slave is not None:  # an instance that exists (not one that failed to load or instantiate)
                inst.state = "failed"
                inst.failed_status = exc.status if isinstance(exc.status, int) else 3
            return Failure(inst.comp.name, inst.comp.path, float(exc.t), exc.function, status,
                           tuple(list(inst.messages)[-N_REPORTED:]))
        if isinstance(exc, _InputFailure):
            inst = self.instances[exc.ci]
            return Failure(inst.comp.name, inst.comp.path, float(exc.t), f"input function of {exc.ext.target}",
                           f"{type(exc.exc).__name__}: {exc.exc}", tuple(list(inst.messages)[-N_REPORTED:]))
        return Failure(None, None, float(self.t_fail), "run", f"{type(exc).__name__}: {exc}".rstrip(": "))

    def _release(self, failure: Failure | None) -> None:
        """terminate (where allowed) and freeInstance every instance, or, after a run that did
        not fail, reset and keep it in the active pool (:mod:`duffid.cosim.instances`); delete
        the directory (Ctrl-C and SIGTERM wait until it is done)."""
        with signals_held():
            self._release_all(keep=failure is None)

    def _release_all(self, keep: bool = False) -> None:
        pool = instances.active()
        try:
            for inst in reversed(self.instances):
                slave = inst.slave
                if slave is None or inst.state in ("new", "freed"):
                    continue
                try:
                    if inst.state == "failed" and inst.failed_status >= 4:  # Fatal: no further calls
                        inst.state = "freed"
                        continue
                    healthy = inst.state == "stepping"
                    discarded = inst.state == "failed" and inst.failed_status == 2
                    if healthy or discarded:
                        terminated = _succeeds(slave.terminate)
                        if keep and healthy and pool is not None and inst.pool_key is not None and terminated and \
                                _succeeds(slave.reset):
                            pool.give(inst.pool_key, slave, inst.callbacks, inst.holder)
                            inst.state, inst.slave, inst.callbacks = "freed", None, None
                            continue
                    slave.freeInstance()
                except Exception:  # keep releasing the others
                    pass
                inst.state = "freed"
                inst.slave = None
                inst.callbacks = None
        finally:
            if self.tmp is not None:
                shutil.rmtree(self.tmp, ignore_errors=True)
                self.tmp = None

    def _result(self, failure: Failure | None, ended: str | None = None) -> Result:
        rows = self.rows
        columns: dict[str, np.ndarray] = {}
        for name in self.names:
            kind, j = self.columns[name]
            column = self.records[kind][0][:rows, j]
            columns[name] = column.astype(bool) if kind == "Boolean" else column.copy()
        order = list(self.sequence)
        return Result(time=self.grid[:rows].copy(), names=list(self.names), _columns=columns, order=order,
                      delayed=list(self.delayed), ordering=self.ordering, step=self.step, failure=failure,
                      ended=ended, loop=self.loop_used,
                      kinds={name: self.columns[name][0] for name in self.names})
