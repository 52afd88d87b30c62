"""The run of a :class:`duffid.cosim.system.System`: instantiation, the fixed-step master loops,
recording, failure handling and clean-up (private; see :mod:`duffid.cosim.system`).

The inner loop works on preallocated buffers: one value buffer per variable type holds
every needed output (each component's outputs contiguous, read with one raw FMI get call
per type straight into it) and the external input values; each component's inputs are
gathered from it with ``np.take(..., out=...)`` into a preallocated buffer and set with
one raw set call per type; recording copies the buffer into a preallocated row. The raw
ctypes functions that fmpy loaded are called directly and their status is checked here.
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
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from ..errors import CosimError
from . import compiled_loop, instances
from .compiled_loop import CompiledLoop
from .elements import (
    DTYPES,
    N_MESSAGES,
    N_REPORTED,
    STATUS_NAMES,
    VARIABLE_KINDS,
    Component,
    Connection,
    External,
    Failure,
    Result,
    WiredSystem,
    check_external_value,
)

__all__ = ["Runner", "signals_held"]

#: Macro steps per call of the compiled loop: signals (Ctrl-C, SIGTERM) are acted on between calls.
_COMPILED_CHUNK = 5000

_FUNCS = {  # kind -> (get, set, ctype) per FMI version
    2: {"Real": ("fmi2GetReal", "fmi2SetReal", ctypes.c_double),
        "Integer": ("fmi2GetInteger", "fmi2SetInteger", ctypes.c_int),
        "Boolean": ("fmi2GetBoolean", "fmi2SetBoolean", ctypes.c_int)},
    3: {"Real": ("fmi3GetFloat64", "fmi3SetFloat64", ctypes.c_double),
        "Integer": ("fmi3GetInt32", "fmi3SetInt32", ctypes.c_int32),
        "Boolean": ("fmi3GetBoolean", "fmi3SetBoolean", ctypes.c_bool)},
}
_NP = {ctypes.c_double: np.float64, ctypes.c_int: np.int32, ctypes.c_int32: np.int32, ctypes.c_bool: np.bool_}
_SETTERS = {2: {"Real": "setReal", "Float64": "setReal", "Integer": "setInteger", "Enumeration": "setInteger",
                "Boolean": "setBoolean", "String": "setString"}}


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
        """Slots of every needed value in the per-type buffers; no FMU is touched."""
        system = self.system
        externals = system.wiring.externals
        sources = {c.source for c in system.wiring.connections}
        wanted = set(sources) | {n for n in self.names if n not in externals}
        self.slots: dict[str, tuple[str, int]] = {}
        counts = {k: 0 for k in DTYPES}
        self.reads: list[dict[str, list[tuple[str, int]]]] = []   # per component: kind -> [(var, vr)]
        self.read_lo: list[dict[str, int]] = []
        for inst in self.instances:
            comp = inst.comp
            reads: dict[str, list[tuple[str, int]]] = {}
            lows: dict[str, int] = {}
            for v in comp.md.modelVariables:
                full = f"{comp.name}.{v.name}"
                if full in wanted:
                    kind = VARIABLE_KINDS[v.type]
                    lows.setdefault(kind, counts[kind])
                    reads.setdefault(kind, []).append((v.name, v.valueReference))
                    self.slots[full] = (kind, counts[kind])
                    counts[kind] += 1
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
        self.g = {k: np.zeros(max(counts[k], 1), dtype=DTYPES[k]) for k in DTYPES}
        for ext in externals.values():
            if ext.mode == "constant":
                kind, slot = self.slots[ext.target]
                self.g[kind][slot] = ext.value
        self.tables = {}
        for kind, exts in self.ext_sampled.items():
            if exts:
                lo = self.ext_lo[kind] + sum(1 for e in externals.values() if e.mode == "constant" and e.kind == kind)
                table = np.column_stack([self.sampled[e.target] for e in exts]).astype(DTYPES[kind])
                self.tables[kind] = (self.g[kind][lo:lo + len(exts)], table)
        # per component inputs: connected (every step), external (every step unless constant)
        # entries (value reference, slot, set every step, (factor, offset) of a transformed connection or None)
        self.inputs: list[dict[str, list[tuple[int, int, bool, tuple[float, float] | None]]]] = [
            dict() for _ in self.instances]
        for conn in system.wiring.connections:
            comp, var = system.wiring.lookup(conn.target, "target")
            kind, slot = self.slots[conn.source]
            affine = (conn.factor, conn.offset) if conn.transformed else None
            self.inputs[self.index[comp.name]].setdefault(kind, []).append((var.valueReference, slot, True, affine))
        for ext in externals.values():
            comp, var = system.wiring.lookup(ext.target, "target")
            kind, slot = self.slots[ext.target]
            self.inputs[self.index[comp.name]].setdefault(kind, []).append(
                (var.valueReference, slot, ext.mode != "constant", None))
        # recording
        self.records = {}
        self.columns: dict[str, tuple[str, int]] = {}
        by_kind: dict[str, list[int]] = {k: [] for k in DTYPES}
        for name in self.names:
            kind, slot = self.slots[name]
            self.columns[name] = (kind, len(by_kind[kind]))
            by_kind[kind].append(slot)
        for kind, slots in by_kind.items():
            if slots:
                idx = np.array(slots, dtype=np.intp)
                identity = len(slots) == len(self.g[kind]) and np.array_equal(idx, np.arange(len(slots)))
                self.records[kind] = (np.zeros((self.n + 1, len(slots)), dtype=DTYPES[kind]), idx, identity)

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
                inst.slave.instantiate(loggingOn=comp.logging, logMessage=log3)  # fmpy keeps the callback
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

    def _call(self, inst: _Instance, method: str, *args: Any, **kwargs: Any) -> Any:
        """A call through fmpy's high-level API (set-up only), status exceptions converted."""
        from fmpy.fmi1 import FMICallException

        try:
            return getattr(inst.slave, method)(*args, **kwargs)
        except FMICallException as exc:
            raise _StepFailure(inst.index, exc.function, exc.status, self.grid[0]) from None

    def _set_parameters(self, inst: _Instance) -> None:
        comp = inst.comp
        for name, value in comp.parameters.items():
            var = comp.variables[name]
            if comp.version == 2:
                method = _SETTERS[2][var.type]
            else:
                method = "set" + ("Int64" if var.type == "Enumeration" else var.type)
            self._call(inst, method, [var.valueReference], [value])

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
            for kind, entries in self.inputs[ci].items():
                _, set_name, ctype = _FUNCS[version][kind]
                setf = raw(set_name)
                g = self.g[kind]
                for subset, target in ((entries, inits), ([e for e in entries if e[2]], sets)):
                    # a transformed connection is gathered, scaled and shifted in its own buffer (one set call),
                    # every step; during initialisation its input keeps its start value (no output is read yet)
                    transformed = [e for e in subset if e[3] is not None] if target is sets else []
                    if transformed:
                        vrs = (ctypes.c_uint * len(transformed))(*[e[0] for e in transformed])
                        idx = np.array([e[1] for e in transformed], dtype=np.intp)
                        buf = np.zeros(len(transformed), dtype=_NP[ctype])
                        affine = (np.array([e[3][0] for e in transformed]), np.array([e[3][1] for e in transformed]))
                        ptr = buf.ctypes.data_as(ctypes.POINTER(ctype))
                        size = ctypes.c_size_t(len(transformed))
                        args = (handle, vrs, size, ptr) + ((size,) if version == 3 else ())
                        self._keep += [vrs, buf, ptr]
                        target.append((g, idx, buf, setf, args, ci, set_name, affine))
                    subset = sorted((e for e in subset if e[3] is None), key=lambda e: e[1])  # by source slot
                    runs: list[list[tuple[int, int, bool]]] = []
                    for e in subset:
                        if runs and runs[-1][-1][1] + 1 == e[1]:
                            runs[-1].append(e)
                        else:
                            runs.append([e])
                    if _NP[ctype] == g.dtype and len(runs) <= 2:
                        # the sources are contiguous in the value buffer: set straight from it
                        for run in runs:
                            vrs = (ctypes.c_uint * len(run))(*[e[0] for e in run])
                            ptr = ctypes.cast(g.ctypes.data + run[0][1] * g.itemsize, ctypes.POINTER(ctype))
                            size = ctypes.c_size_t(len(run))
                            args = (handle, vrs, size, ptr) + ((size,) if version == 3 else ())
                            self._keep += [vrs, ptr]
                            target.append((g, None, None, setf, args, ci, set_name, None))
                    elif subset:  # gather with np.take into a buffer, one set call
                        vrs = (ctypes.c_uint * len(subset))(*[e[0] for e in subset])
                        idx = np.array([e[1] for e in subset], dtype=np.intp)
                        buf = np.zeros(len(subset), dtype=_NP[ctype])
                        ptr = buf.ctypes.data_as(ctypes.POINTER(ctype))
                        size = ctypes.c_size_t(len(subset))
                        args = (handle, vrs, size, ptr) + ((size,) if version == 3 else ())
                        self._keep += [vrs, buf, ptr]
                        target.append((g, idx, buf, setf, args, ci, set_name, None))
            for kind, entries in self.reads[ci].items():
                get_name, _, ctype = _FUNCS[version][kind]
                g = self.g[kind]
                lo = self.read_lo[ci][kind]
                vrs = (ctypes.c_uint * len(entries))(*[e[1] for e in entries])
                if _NP[ctype] == g.dtype:
                    ptr = ctypes.cast(g.ctypes.data + lo * g.itemsize, ctypes.POINTER(ctype))
                else:  # FMI 3 Boolean (1 byte): read into staging, then copy
                    staging = np.zeros(len(entries), dtype=np.bool_)
                    ptr = staging.ctypes.data_as(ctypes.POINTER(ctype))
                    posts.append((g[lo:lo + len(entries)], staging))
                    self._keep.append(staging)
                size = ctypes.c_size_t(len(entries))
                args = (handle, vrs, size, ptr) + ((size,) if version == 3 else ())
                self._keep += [vrs, ptr]
                gets.append((raw(get_name), args, ci, get_name))
            if version == 2:
                term = ctypes.c_bool(False)
                args = (handle, self.t_arg, self.h_arg, ctypes.c_int(1))
                self.step_ops.append((raw("fmi2DoStep"), args, ci, "fmi2DoStep", term, None))
            else:
                flags = [ctypes.c_bool(False) for _ in range(3)] + [ctypes.c_double(0.0)]
                args = (handle, self.t_arg, self.h_arg, ctypes.c_bool(True)) + tuple(ctypes.pointer(f) for f in flags)
                self._keep.append(flags)
                self.step_ops.append((raw("fmi3DoStep"), args, ci, "fmi3DoStep", flags[1], flags))
            self.set_ops.append(sets)
            self.init_ops.append(inits)
            self.get_ops.append(gets)
            self.post_ops.append(posts)

    def _initialize(self) -> None:
        t0, t_end = float(self.grid[0]), float(self.grid[-1])
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
        self.ending: _Terminated | None = None
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
                        for stepf, step_args, ci, fname, term, flags in steps:
                            status = stepf(*step_args)
                            if status > 1 or term.value:
                                self._ended(ci, fname, status, flags, t)
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
                [inst.comp for inst in self.instances], self.system.wiring.externals.values(), self.system.wiring.connections):
            return None  # System.run refused loop="compiled" for these
        moves = [(view, table, None, 0, table.strides[0]) for view, table in self.tables.values()]
        moves += [(rec, self.g[kind], None if identity else idx, rec.strides[0], 0)
                  for kind, (rec, idx, identity) in self.records.items()]

        def on_step(op: int, status: int, k: int) -> bool:
            _, _, ci, fname, _, flags = loop.step_entries[op]
            self._ended(ci, fname, status, flags, float(self.grid[k]))  # raises unless the FMU ended the run
            return True

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
                      ended=ended, loop=self.loop_used)
