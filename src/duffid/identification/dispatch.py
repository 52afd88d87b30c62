"""Engine dispatch: which implementation runs an estimator on a record (the C core where it
runs the model, else Python), in blocks of :data:`BLOCK_SAMPLES` (memory bounded by the
history kept, not by the C core's per-sample outputs), the final estimates alone for the
checks' re-runs (:func:`final_estimates`) on a :class:`Pool` of threads, and the robust
window from the data."""
from __future__ import annotations

import os
import threading
from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any, Callable, Iterable, Iterator, Mapping

import numpy as np

from ..data.record import Record
from ..errors import BuildError, InputError
from ..models.chain import Chain, Duffing1, Duffing2
from ..models.registry import IdentifiableModel
from .batch import estimate
from .c_core import CIdentifier, outliers_of
from .engine import STATUSES, Identification, check_record
from .options import ENGINES, ONLINE_METHODS

__all__ = [
    "run_estimator",
    "final_estimates",
    "on_c_core",
    "data_window",
    "BLOCK_SAMPLES",
    "HISTORY_BLOCK",
    "Cancelled",
    "Pool",
    "all_cores",
]

#: Samples handed to the C batch per call by a run that keeps only the final estimates (no
#: per-sample output is written): a cancelled run stops within a block.
BLOCK_SAMPLES = 1 << 16

#: Samples per call of a run that keeps the history: their per-sample outputs (1.2 kB each)
#: go to one 5 MB buffer reused from block to block (a fresh, zeroed buffer of 64 k samples
#: per block cost nearly as much as the estimator: 1-DOF, 100 k samples, 0.60 s with such
#: outputs against 0.33 s with none, on a loaded machine).
HISTORY_BLOCK = 1 << 12


class Cancelled(Exception):
    """A run stopped between two blocks because its ``cancel`` event was set (Ctrl-C)."""


def all_cores() -> int:
    """The cores this process may run on (the default number of jobs)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


class _Deferred:
    """A call made when its result is first asked for (one job: runs in the caller's order)."""

    def __init__(self, call: Callable[[], Any]) -> None:
        self._call, self._done, self._value = call, False, None

    def result(self) -> Any:
        if not self._done:
            self._value, self._done = self._call(), True
        return self._value


class Pool:
    """Independent estimator runs on up to ``jobs`` threads (the C batch releases the GIL
    while it runs a block); with one job every call runs in the caller's thread when its
    result is asked for. Every result depends only on its inputs, never on the number of
    jobs or the order in which runs finish.

    Parameters
    ----------
    jobs : int or None
        Threads (None: :func:`all_cores`).

    Attributes
    ----------
    cancel : threading.Event
        Set when the pool is left by an exception (Ctrl-C): runs given it
        (:func:`run_estimator`'s ``cancel``) stop at their next block.
    """

    def __init__(self, jobs: int | None = None) -> None:
        jobs = all_cores() if jobs is None else int(jobs)
        if jobs < 1:
            raise InputError(f"jobs must be at least 1, got {jobs}")
        self.jobs = jobs
        self.cancel = threading.Event()
        self._executor = ThreadPoolExecutor(jobs, thread_name_prefix="duffid") if jobs > 1 else None

    def __enter__(self) -> "Pool":
        return self

    def __exit__(self, kind: Any, *rest: Any) -> None:
        self.close(cancel=kind is not None)

    def close(self, cancel: bool = False) -> None:
        """Wait for the runs (after setting :attr:`cancel` when ``cancel``) and stop the threads."""
        if cancel:
            self.cancel.set()
        if self._executor is not None:
            self._executor.shutdown(wait=True, cancel_futures=True)

    def submit(self, call: Callable[[], Any]) -> Future | _Deferred:
        """Start ``call`` (one job: defer it); ``.result()`` gives its value."""
        if self._executor is None:
            return _Deferred(call)
        return self._executor.submit(call)

    def ordered(self, call: Callable[[Any], Any], inputs: Iterable[Callable[[], Any]],
                done: Callable[[], Any] | None = None) -> Iterator[Any]:
        """``call(make())`` for each ``make`` of ``inputs``, in order. Each input is made in
        the caller's thread, in order, when a job is free (at most :attr:`jobs` inputs exist
        at once); ``done`` is called after each result."""
        running: deque[Future | _Deferred] = deque()
        for make in inputs:
            if len(running) >= self.jobs:
                yield self._finished(running.popleft(), done)
            value = make()
            running.append(self.submit(lambda value=value: call(value)))
        while running:
            yield self._finished(running.popleft(), done)

    @staticmethod
    def _finished(future: Future | _Deferred, done: Callable[[], Any] | None) -> Any:
        value = future.result()
        if done is not None:
            done()
        return value


def run_estimator(record: Record, model: Chain, method: str = "robust", *, engine: str = "auto",
                  cancel: Any = None, **options: Any) -> Identification:
    """The estimator's run over ``record`` (unchecked), on the C core or in Python.

    The C core (:class:`~duffid.identification.c_core.CIdentifier`, fed in blocks of
    :data:`BLOCK_SAMPLES`) gives the answers of the Python identifier to rounding, many times
    faster; ``engine="auto"`` uses it for every model with the online methods when a C
    compiler is available, and Python otherwise (or for a model beyond the C core's limits):
    :class:`~duffid.models.chain.Duffing1`, :class:`~duffid.models.chain.Duffing2` and chains of
    their structure on the core's own description, any other chain or equation model on its
    generated description (the generic engine; one cached library per model, compiled on
    first use). ``cancel``: an event (``threading.Event``) checked between blocks of the C
    batch; when it is set the run raises :class:`Cancelled`.
    """
    record.require_displacement("the algebraic estimator")
    identifier = _c_identifier(record, model, method, engine, options)
    if identifier is None:
        return estimate(record, model, method, **options)
    with identifier:
        result = _identified_in_blocks(identifier, record, cancel)
    return result if identifier.model is model else _renamed(result, model)

def final_estimates(record: Record, model: Chain, method: str = "robust", *, engine: str = "auto",
                    cancel: Any = None, row_stride: int = 1, **options: Any) -> dict[str, float]:
    """The estimator's final solution over ``record`` (public names), as
    ``run_estimator(...).estimates``, without the history: on the C core block by block,
    no per-sample output written, and with a fixed window and no change test one solve at
    the end instead of one per sample (``cancel`` as in :func:`run_estimator`).
    ``row_stride`` s > 1: the rows of every s-th window only (the C core's deferred run; the
    Python identifier ignores it and gives the full solution)."""
    record.require_displacement("the algebraic estimator")
    identifier = _c_identifier(record, model, method, engine, options)
    if identifier is None:
        return dict(estimate(record, model, method, **options).estimates)
    with identifier:
        check_record(record, identifier.model, identifier.dt)
        identifier.reset()
        identifier.defer_solutions(row_stride=row_stride)  # one solve at the end where the options allow it (flush)
        for start, stop in _blocks(record.n_samples, cancel):
            identifier.consume(record.x[start:stop], record.f[start:stop])
        flushed = identifier.flush()
        values = {k: float(v) for k, v in (flushed if flushed is not None else identifier.latest()).current.items()}
    if identifier.model is model:
        return values
    return model.from_canonical({identifier.model.canonical_name(k): v for k, v in values.items()})

def on_c_core(record: Record, model: Chain, method: str, engine: str, options: Mapping[str, Any]) -> bool:
    """Whether :func:`run_estimator` and :func:`final_estimates` run ``model`` on the C core
    for this record with these ``options`` (else the Python identifier runs it, which also
    judges options the C core refuses)."""
    identifier = _c_identifier(record, model, method, engine, options)
    if identifier is None:
        return False
    identifier.close()
    return True

def _blocks(n: int, cancel: Any, size: int = BLOCK_SAMPLES) -> Any:
    """``(start, stop)`` of the blocks of ``size`` samples of ``n``; :class:`Cancelled` once
    ``cancel`` is set."""
    for start in range(0, n, size):
        if cancel is not None and cancel.is_set():
            raise Cancelled()
        yield start, min(start + size, n)

def _c_identifier(record: Record, model: Chain, method: str, engine: str,
                  options: Mapping[str, Any]) -> CIdentifier | None:
    """The C core's identifier of ``model`` (its ``model`` is the core's), or None when the
    Python identifier runs it."""
    if engine not in ENGINES:
        raise InputError(f"engine must be one of {', '.join(ENGINES)}, got {engine!r}")
    if engine != "python" and method in ONLINE_METHODS:
        core = _c_model(model)
        try:
            if core is None:
                raise InputError(f"the C core does not run the model {model.name}")
            return CIdentifier(core, record.dt, method, **options)
        except (BuildError, ValueError, OSError):
            # no compiler (BuildError), no C sources (AssetError, an OSError) (an installed wheel without them), or a model or
            # option the C core does not take: the Python identifier gives the same answers
            if engine == "c":
                raise
            return None
    if engine == "c":
        raise InputError(f"the C core runs the methods {', '.join(ONLINE_METHODS)}, not {method!r}")
    return None

def _identified_in_blocks(identifier: CIdentifier, record: Record, cancel: Any) -> Identification:
    """:meth:`CIdentifier.identify_record`'s result with the record fed in blocks: of each
    block's outputs the parameters, condition, flags and outliers are kept, of the last its
    window, current values and statuses (the flushed sample's when one was held back)."""
    check_record(record, identifier.model, identifier.dt)
    identifier.reset()
    names = identifier.parameter_names
    n = record.n_samples
    parameters = np.empty((len(names), n))  # a row per parameter: the history's arrays are its rows
    condition = np.empty(n)
    flags = np.empty(n, dtype=bool)
    outliers: list[dict[str, Any]] = []
    count, last = 0, None
    buffer = np.empty(min(n, HISTORY_BLOCK), dtype=identifier.output_dtype)
    for start, stop in _blocks(n, cancel, HISTORY_BLOCK):
        rows = identifier.run(record.x[start:stop], record.f[start:stop], out=buffer)
        parameters[:, start:stop] = rows["parameters"][:, :len(names)].T
        condition[start:stop] = rows["condition"]
        flags[start:stop] = rows["identified"].astype(bool)
        outliers.extend(outliers_of(rows, count, record.dt))
        count, last = int(rows["outliers"][-1]), rows[-1]
    window = float(last["window"])
    current = {name: float(last["current"][i]) for i, name in enumerate(names)}
    online_status = {name: STATUSES[last["status"][i]] for i, name in enumerate(names)}
    flushed = identifier.flush()
    if flushed is not None:  # a sample held back at the end, processed as measured
        parameters[:, -1] = [flushed.parameters[name] for name in names]
        condition[-1], flags[-1], window = flushed.condition, flushed.identified, flushed.window
        current = {k: float(v) for k, v in flushed.current.items()}
        online_status = dict(flushed.status)
    history = {name: parameters[i] for i, name in enumerate(names)}
    return Identification(
        model=identifier.model.name, method=identifier.method,
        parameters={name: float(history[name][-1]) for name in names},
        t=record.t - record.t[0], history=history, condition=condition, identified=flags,
        t_identified=float(record.t[np.argmax(flags)] - record.t[0]) if flags.any() else None,
        window=window, options=dict(identifier.options), source=record.source,
        estimates=current, online_status=online_status, outliers=outliers)

def data_window(record: Record, frequency: float, periods: float) -> float:
    """Window [s] of the robust method for a record whose main frequency is ``frequency`` Hz:
    the whole record when it spans at most ``2 * periods`` periods (integrated from its
    first sample, as the paper does), else ``periods`` periods."""
    if record.duration * frequency <= 2.0 * periods:
        return float(record.duration + record.dt)
    return float(periods / frequency)

def _c_model(model: Any) -> Any:
    """The model the C core runs for ``model``: the core's own Duffing1 or Duffing2 with
    ``model``'s values for those and for chains of their structure; ``model`` itself (its
    generated description) for any other model with equations; None otherwise."""

    if isinstance(model, (Duffing1, Duffing2)):
        return model
    if isinstance(model, Chain):
        structure = (model.n_dof, model.coulomb is None, tuple(model.forced), tuple(model.orders or ()))
        if structure in ((1, True, (0,), (1, 3)), (2, True, (0,), (1, 3))):
            core = Duffing1 if model.n_dof == 1 else Duffing2
            return _chain_like(core(offset=model.offset), model.canonical_parameters())
    return model if isinstance(model, IdentifiableModel) else None

def _chain_like(template: Chain, canonical: Mapping[str, float]) -> Chain:
    try:
        return template.with_parameters(**{k: v for k, v in canonical.items() if not k.startswith("c")})
    except ValueError:
        return template

def _renamed(result: Identification, model: Chain) -> Identification:
    """A C-core result (Duffing1/Duffing2 names) under ``model``'s public names."""
    core = _c_model(model)
    assert core is not None

    def public(values: Mapping[str, float]) -> dict[str, float]:
        canonical = {core.canonical_name(k): float(v) for k, v in values.items()}
        return model.from_canonical(canonical)

    names = list(result.history)
    rows = [public({k: result.history[k][i] for k in names}) for i in range(len(result.t))]
    result.history = {k: np.array([row[k] for row in rows]) for k in model.parameters}
    result.parameters = public(result.parameters)
    result.estimates = public(result.estimates)
    by_canonical = {core.canonical_name(k): v for k, v in result.online_status.items()}
    result.online_status = {k: by_canonical[model.canonical_name(k)] for k in model.parameters}
    result.model = model.name
    return result
