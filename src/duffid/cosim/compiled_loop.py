"""The orchestrator's inner loop in C (``fmus/cosim/duffid_cosim_loop.c``), private to
:mod:`duffid.cosim.runner`.

The runner prepares every macro step's operations (raw FMI set, doStep and get calls on
preallocated buffers, the input tables' rows and the recorded rows) for its Python loop;
:class:`CompiledLoop` hands the same operations, as flat C arrays, to
``duffid_cosim_run``, which executes them in the same order on the same buffers. Only
values are copied, so the trajectories equal the Python loop's bit for bit. A doStep that
does not simply succeed calls back into the runner, which decides (as in the Python loop)
whether the FMU ended the simulation or failed.

The library is compiled on first use with the one C build helper
(:func:`duffid.cbuild.cached_library`) and cached by source hash; without a C compiler
:func:`load` returns None and the runner uses its Python loop.
"""
from __future__ import annotations

import ctypes
from typing import Any, Callable, Iterable, Sequence

import numpy as np

from ..assets import fmu_sources
from ..cbuild import cached_library
from ..errors import CompilerNotFoundError

__all__ = ["CompiledLoop", "load", "obstacles", "LOOP_MODES", "DONE", "SET_FAILED", "GET_FAILED", "ABORTED", "ENDED",
           "STEP_ENDED", "STEP_ABORT", "EVENT_HANDLED"]

#: ``System.run(loop=...)``: ``"auto"`` (compiled where every component allows it, else
#: Python), ``"compiled"`` (an error where it cannot be used), ``"python"``.
LOOP_MODES = ("auto", "compiled", "python")

# duffid_cosim_run's return codes (DUFFID_LOOP_*)
DONE, SET_FAILED, GET_FAILED, ABORTED, ENDED = range(5)
# what on_step answers (DUFFID_STEP_*): the FMU ended the simulation (complete the macro step, then
# stop), abort now, or the FMU's Event Mode was handled (continue)
STEP_ENDED, STEP_ABORT, EVENT_HANDLED = range(3)
# value conversions (DUFFID_COPY, DUFFID_INT32_TO_BOOL, DUFFID_BOOL_TO_INT32, DUFFID_INT64_TO_INT32,
# DUFFID_INT32_TO_INT64), by (source, destination) bytes per value when they differ
_COPY, _INT32_TO_BOOL, _BOOL_TO_INT32, _INT64_TO_INT32, _INT32_TO_INT64 = range(5)
_CONVERSIONS = {(4, 1): _INT32_TO_BOOL, (1, 4): _BOOL_TO_INT32, (8, 4): _INT64_TO_INT32, (4, 8): _INT32_TO_INT64}

_P = ctypes.c_void_p


class _IoOp(ctypes.Structure):
    _fields_ = [("function", _P), ("instance", _P), ("vr", _P), ("n", ctypes.c_size_t), ("value", _P),
                ("fmi3", ctypes.c_int), ("convert", ctypes.c_int), ("gather_source", _P),
                ("gather_index", _P), ("itemsize", ctypes.c_size_t), ("n_values", ctypes.c_size_t), ("call", _P),
                ("context", _P)]


class _StepOp(ctypes.Structure):
    _fields_ = [("function", _P), ("instance", _P), ("fmi3", ctypes.c_int), ("event_handling_needed", _P),
                ("terminate", _P), ("early_return", _P), ("last_successful_time", _P), ("event_mode", ctypes.c_int)]


class _Move(ctypes.Structure):
    _fields_ = [("destination", _P), ("source", _P), ("index", _P), ("n", ctypes.c_size_t),
                ("itemsize", ctypes.c_size_t), ("destination_stride", ctypes.c_ssize_t),
                ("source_stride", ctypes.c_ssize_t), ("convert", ctypes.c_int), ("call", _P)]


class _Stage(ctypes.Structure):
    _fields_ = [(name, ctypes.c_int) for name in ("set_lo", "set_hi", "step_lo", "step_hi", "get_lo", "get_hi",
                                                  "post_lo", "post_hi")]


_CALLBACK = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_int, ctypes.c_int, ctypes.c_long)
_IO_CALL = ctypes.CFUNCTYPE(ctypes.c_int, _P)              # an own operation: (context) -> FMI status
_MOVE_CALL = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_long)  # an own copy: (row) -> 0
_LIBRARY: list[ctypes.CDLL | None] = []


def load() -> ctypes.CDLL | None:
    """The compiled loop (built on first use, once per process); None without a C compiler.

    Raises
    ------
    BuildError
        If the compiler fails on the loop's source (a bug: the source is duffid's).
    """
    if not _LIBRARY:
        try:
            path = cached_library("libduffid_cosim_loop", fmu_sources("cosim"), ("duffid_cosim_loop.c",),
                                  ("duffid_cosim_loop.h",))
        except CompilerNotFoundError:
            _LIBRARY.append(None)
        else:
            lib = ctypes.CDLL(str(path))
            lib.duffid_cosim_run.restype = ctypes.c_int
            lib.duffid_cosim_run.argtypes = [
                _P, ctypes.c_long, ctypes.c_long, ctypes.c_double, _P, ctypes.c_int, _P, _P, _P, _P, _P,
                ctypes.c_int, _CALLBACK, ctypes.POINTER(ctypes.c_long), ctypes.POINTER(ctypes.c_int),
                ctypes.POINTER(ctypes.c_int)]
            _LIBRARY.append(lib)
    return _LIBRARY[0]


def obstacles(components: Iterable[Any], externals: Iterable[Any], connections: Iterable[Any] = ()) -> list[str]:
    """Why the compiled loop cannot run a system, in words (empty: it can): a component that
    is a Python FMU (pythonfmu runs Python inside its FMI calls), an input that is a Python
    function (called every step), a connection with a factor or offset (an SSP linear
    transformation: the C loop only copies values), no C compiler (checked last, by building
    the loop). String and Binary values do not stop it: their calls and copies (into Python
    objects: an FMU owns the memory its getters return, valid until its next call) are called
    back from the C loop."""
    reasons = [f"component {c.name!r} is a Python FMU (pythonfmu)" for c in components
               if (c.md.generationTool or "").startswith("PythonFMU")]
    reasons += [f"the input {e.target} is a Python function" for e in externals if e.mode == "function"]
    reasons += [f"the connection {c} has a factor or offset" for c in connections if c.transformed]
    if not reasons and load() is None:
        reasons.append("no C compiler was found to build it")
    return reasons


def _address(obj: Any) -> int | None:
    """The address a ctypes pointer, array or scalar refers to (None for None)."""
    if obj is None:
        return None
    if isinstance(obj, ctypes._Pointer):
        return ctypes.cast(obj, ctypes.c_void_p).value
    return ctypes.addressof(obj)


def _function(f: Any) -> int:
    return ctypes.cast(f, ctypes.c_void_p).value


def _conversion(source: np.ndarray, target_itemsize: int) -> int:
    if source.itemsize == target_itemsize:
        return _COPY
    return _CONVERSIONS[(source.itemsize, target_itemsize)]


class CompiledLoop:
    """The runner's operations as C arrays (see :class:`duffid.cosim.runner.Runner`).

    Parameters
    ----------
    library : ctypes.CDLL
        From :func:`load`.
    grid : numpy.ndarray
        The communication grid (float64, kept alive here).
    step : float
        The communication step.
    stages : sequence of (sets, steps, gets, posts)
        The runner's per-stage operation lists, in the layout of its Python loop: set
        ``(g, idx, buf, setf, args, ci, name)``, step ``(stepf, args, ci, name, term, flags)``,
        get ``(getf, args, ci, name)``, post ``(destination view, staging array)``; a step's
        ``event`` flag (FMI 3 eventHandlingNeeded) is given for an FMU that uses Event Mode.
    moves : sequence of (destination, source, index, destination_stride, source_stride)
        Copies after every macro step for row ``k + 1``: the input tables' rows and the
        recorded rows (arrays; strides in bytes; index None or an intp array), or ``(copy,)``
        with a Python function ``copy(row)`` (String and Binary values, Python objects).
        A set or get with no arguments is a Python function too (``() -> status``, the
        runner's String and Binary calls), called back from C.
    on_step : callable
        ``on_step(step_op, status, k) -> int``: :data:`STEP_ENDED` when the FMU ended the
        simulation (complete the macro step, then stop), :data:`STEP_ABORT` to abort,
        :data:`EVENT_HANDLED` when it handled the FMU's Event Mode (continue).
    """

    def __init__(self, library: ctypes.CDLL, grid: np.ndarray, step: float,
                 stages: Sequence[tuple[list, list, list, list]],
                 moves: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray | None, int, int]],
                 on_step: Callable[[int, int, int], bool]) -> None:
        self.library, self.grid, self.step = library, np.ascontiguousarray(grid, dtype=np.float64), float(step)
        self._keep: list[Any] = []
        sets, steps, gets, posts, stage_bounds = [], [], [], [], []
        #: The runner's set, step and get entries in the order of the C arrays (failures name them by index).
        self.set_entries: list[tuple] = []
        self.step_entries: list[tuple] = []
        self.get_entries: list[tuple] = []
        for stage_sets, stage_steps, stage_gets, stage_posts in stages:
            lo = (len(sets), len(steps), len(gets), len(posts))
            self.set_entries += stage_sets
            self.step_entries += stage_steps
            self.get_entries += stage_gets
            sets += [self._io(op[3], op[4], op[0], op[1], op[2]) for op in stage_sets]
            steps += [self._step(entry) for entry in stage_steps]
            gets += [self._io(op[0], op[1], None, None, None) for op in stage_gets]
            posts += [self._move(dst, src, None, 0, 0) for dst, src in stage_posts]
            stage_bounds.append(_Stage(lo[0], len(sets), lo[1], len(steps), lo[2], len(gets), lo[3], len(posts)))
        self.sets = (_IoOp * max(len(sets), 1))(*sets)
        self.steps = (_StepOp * max(len(steps), 1))(*steps)
        self.gets = (_IoOp * max(len(gets), 1))(*gets)
        self.posts = (_Move * max(len(posts), 1))(*posts)
        self.stages = (_Stage * len(stage_bounds))(*stage_bounds)
        moved = [self._move(*m) for m in moves]
        self.moves = (_Move * max(len(moved), 1))(*moved)
        self.n_moves = len(moved)
        self.exception: BaseException | None = None

        def callback(op: int, status: int, k: int) -> int:
            try:
                return on_step(op, status, k)
            except BaseException as exc:  # noqa: BLE001 - re-raised by run() once the C loop has returned
                self.exception = exc
                return STEP_ABORT

        self.callback = _CALLBACK(callback)
        self.failed_step, self.failed_op, self.failed_status = ctypes.c_long(0), ctypes.c_int(0), ctypes.c_int(0)

    def _own(self, function: Callable[..., int], kind: Any, failed: int) -> int:
        """The address of a C callback running the Python ``function`` (an exception is kept for
        :meth:`run` to raise, and the callback returns ``failed``)."""
        def call(*args: Any) -> int:
            try:
                status = function(*args)
                return status if isinstance(status, int) else 0  # a copy returns no status
            except BaseException as exc:  # noqa: BLE001 - re-raised by run() once the C loop has returned
                self.exception = self.exception or exc
                return failed

        callback = kind(call)
        self._keep.append(callback)
        return ctypes.cast(callback, ctypes.c_void_p).value

    def _io(self, function: Any, args: tuple, source: np.ndarray | None, index: np.ndarray | None,
            buffer: np.ndarray | None) -> _IoOp:
        if not args:  # the runner's own operation (String and Binary values): called back
            op = _IoOp()
            op.call = self._own(lambda context: function(), _IO_CALL, 3)
            return op
        handle, vrs, size, ptr = args[:4]
        fmi3 = len(args) == 5
        op = _IoOp(_function(function), handle.value, _address(vrs), size.value, _address(ptr), int(fmi3))
        op.n_values = args[4].value if fmi3 else size.value
        if index is not None:
            index = np.ascontiguousarray(index, dtype=np.intp)
            self._keep.append(index)
            op.convert = _conversion(source, buffer.itemsize)
            op.gather_source, op.gather_index, op.itemsize = source.ctypes.data, index.ctypes.data, source.itemsize
        return op

    @staticmethod
    def _step(entry: tuple) -> _StepOp:
        function, args, _, name, _, flags, event = entry
        op = _StepOp(_function(function), args[0].value, int(name == "fmi3DoStep"))
        if flags is not None:
            op.event_handling_needed, op.terminate, op.early_return, op.last_successful_time = (
                ctypes.addressof(f) for f in flags)
        op.event_mode = int(event is not None)
        return op

    def _move(self, destination: np.ndarray | Callable[[int], Any], source: np.ndarray | None = None,
              index: np.ndarray | None = None, destination_stride: int = 0, source_stride: int = 0) -> _Move:
        if callable(destination):  # the runner's own copy of row k + 1 (Python objects): called back
            move = _Move()
            move.call = self._own(destination, _MOVE_CALL, 0)
            return move
        if index is not None:
            index = np.ascontiguousarray(index, dtype=np.intp)
            self._keep.append(index)
        n = len(index) if index is not None else source.size if source_stride == 0 else source.shape[-1]
        return _Move(destination.ctypes.data, source.ctypes.data, index.ctypes.data if index is not None else None, n,
                     source.itemsize, destination_stride, source_stride, _conversion(source, destination.itemsize))

    def run(self, start: int, stop: int) -> int:
        """Macro steps ``start .. stop - 1``; a return code (:data:`DONE`, ...). After a
        failure ``failed_step``, ``failed_op`` and ``failed_status`` say where; an exception
        raised by ``on_step`` is re-raised here."""
        code = self.library.duffid_cosim_run(
            self.grid.ctypes.data, start, stop, self.step, ctypes.addressof(self.stages), len(self.stages),
            ctypes.addressof(self.sets), ctypes.addressof(self.steps), ctypes.addressof(self.gets),
            ctypes.addressof(self.posts), ctypes.addressof(self.moves), self.n_moves, self.callback,
            ctypes.byref(self.failed_step), ctypes.byref(self.failed_op), ctypes.byref(self.failed_status))
        if self.exception is not None:
            exc, self.exception = self.exception, None
            raise exc
        return code
