"""Running a campaign on Dask distributed: a local cluster of processes, or any cluster.

:func:`run_campaign` sends every task not yet done to the workers of a
:class:`distributed.Client` (a :class:`distributed.LocalCluster` of single-threaded worker
processes by default, an existing scheduler when its address is given), and writes each
row to the results (:class:`~duffid.campaign.store.ResultStore`) as it arrives, with a
progress bar. Tasks are plain descriptions (:class:`~duffid.campaign.spec.Task`); a task
that fails records its error in its row; a worker that dies takes its running tasks with it
and the scheduler runs them again on another worker (a task that kills
``distributed.scheduler.allowed-failures`` workers is recorded as failed). Each worker keeps
its files in one folder of its own (:class:`WorkerFolder`), removed when it closes.

The local cluster's workers run with :data:`WORKER_CONFIG`: a task runs in a thread of the
worker process while the worker's event loop runs in its main thread, and every time the
loop wakes up (by default: a sample of the task's stack every 10 ms, a health check of the
loop every 20 ms, ...) the task hands the GIL over and waits to get it back, most often when
numpy releases it (a LAPACK call) and cannot take it again at once. With Dask's defaults a
case-B run (0.28 s) took about 11 % longer in a worker than in the serial loop; with these
settings about 5 % (benchmarks/campaign.py, "per run"). Workers started for ``--scheduler``
have their own Dask configuration: :func:`worker_environment` gives the same settings as
environment variables for them.
"""
from __future__ import annotations

import logging
import os
import socket
import time
import uuid
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator
from urllib.parse import urlsplit

import dask
import pyarrow as pa
from distributed import Client, LocalCluster, as_completed
from distributed.diagnostics.plugin import WorkerPlugin
from tqdm import tqdm

from ..cosim.instances import InstancePool, activate, deactivate
from ..errors import InputError
from .spec import CampaignSpec, load_spec
from .store import ResultStore
from .systems import remove_worker_folder, worker_folder
from .tasks import run_task

__all__ = ["CampaignRun", "WorkerFolder", "run_campaign", "WORKER_CONFIG", "worker_environment"]

#: Dask settings of the local cluster (see the module documentation): what the worker's event
#: loop does while a task runs, only for the dashboard or for warnings, done less often.
WORKER_CONFIG: dict[str, Any] = {
    "distributed.worker.profile.enabled": False,       # the dashboard's profile: the task's stack every 10 ms
    "distributed.admin.tick.interval": "1s",           # the event loop's health check (a warning): every 20 ms
    "distributed.admin.system-monitor.interval": "2s",  # the dashboard's CPU/memory/network figures: every 0.5 s
    # the memory limits (spill, pause; the nanny's terminate) checked every second, not 0.1 s
    "distributed.worker.memory.monitor-interval": "1s",
}


def worker_environment() -> dict[str, str]:
    """:data:`WORKER_CONFIG` as the environment variables Dask reads (for workers started by
    hand, ``dask worker``): ``{"DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED": "False", ...}``."""
    return {"DASK_" + key.upper().replace(".", "__").replace("-", "_"): str(value)
            for key, value in WORKER_CONFIG.items()}


class WorkerFolder(WorkerPlugin):
    """Gives each worker process its own folder for the files of its tasks (the FMUs of
    co-simulation runs, extracted once, and their instances, reused; configurations with
    overrides) and frees and removes it all when the worker closes."""

    name = "duffid-campaign-folder"

    def setup(self, worker: Any) -> None:
        """Create the folder, make it the process's folder for temporary files, and extract
        FMUs there once and reuse their instances across runs
        (:mod:`duffid.cosim.instances`)."""
        activate(InstancePool(worker_folder(temporary_files=True) / "fmus"))

    def teardown(self, worker: Any) -> None:
        """Free the kept instances and remove the folder."""
        deactivate()
        remove_worker_folder()


@dataclass
class CampaignRun:
    """What a campaign run did.

    Attributes
    ----------
    spec : CampaignSpec
        The campaign.
    output : Path
        The results file.
    table : pyarrow.Table or None
        Every result so far (earlier runs included), one row per task.
    ran, skipped, failed : int
        Tasks run now, tasks skipped as already done (``resume``), tasks of this run that failed.
    workers : int
        Worker processes of the cluster when the run started.
    seconds : float
        Wall-clock time of the run (cluster start-up included).
    """

    spec: CampaignSpec
    output: Path
    table: pa.Table | None
    ran: int
    skipped: int
    failed: int
    workers: int
    seconds: float


def _probe(scheduler: str, timeout: float = 10.0) -> None:
    """Fail at once when nothing listens at a ``tcp://host:port`` scheduler address (Dask's own
    client retries a refused connection until its 30 s timeout); other addresses are left to Dask."""
    split = urlsplit(scheduler if "://" in scheduler else f"tcp://{scheduler}")
    if split.scheme != "tcp" or split.hostname is None:
        return
    try:
        port = split.port
    except ValueError:
        raise InputError(f"--scheduler {scheduler}: the port is not a number (e.g. tcp://host:8786)") from None
    try:
        socket.create_connection((split.hostname, port or 8786), timeout=timeout).close()
    except OSError as exc:
        reason = "nothing listens there" if isinstance(exc, ConnectionRefusedError) else (str(exc) or type(exc).__name__)
        raise InputError(f"cannot reach the Dask scheduler at {scheduler}: {reason} (start one with "
                         f"`dask scheduler`, or leave out --scheduler for a local cluster)") from None


@contextmanager
def _client(scheduler: str | None, workers: int | None) -> Iterator[Client]:
    if scheduler is not None:
        if workers is not None:
            raise InputError("--workers sets the size of the local cluster; with --scheduler the cluster has "
                             "the workers started for it")
        _probe(scheduler)
        try:
            client = Client(scheduler, timeout=30)
        except (OSError, TimeoutError) as exc:
            raise InputError(f"cannot reach the Dask scheduler at {scheduler}: {exc}") from None
        with client:
            yield client
        return
    if workers is not None and workers < 1:
        raise InputError(f"--workers must be at least 1, got {workers}")
    n = workers or os.cpu_count() or 1
    with dask.config.set(WORKER_CONFIG), \
            LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                         silence_logs=logging.ERROR) as cluster, Client(cluster) as client:
        yield client


@contextmanager
def _quiet_dask() -> Iterator[None]:
    """Dask's own log lines (a worker lost, a task rescheduled) are not the command's voice:
    the results and the summary say what happened."""
    loggers = [logging.getLogger(name) for name in ("distributed", "tornado")]
    levels = [lg.level for lg in loggers]
    for lg in loggers:
        lg.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        for lg, level in zip(loggers, levels):
            lg.setLevel(level)


def run_campaign(spec: CampaignSpec | str | os.PathLike[str], output: str | os.PathLike[str], *,
                 scheduler: str | None = None, workers: int | None = None, resume: bool = False,
                 progress: bool = True, log: Callable[[str], None] | None = None) -> CampaignRun:
    """Run a campaign's tasks on Dask workers, results streamed to a Parquet file.

    Parameters
    ----------
    spec : CampaignSpec or path
        The campaign (:func:`~duffid.campaign.spec.load_spec`).
    output : str or os.PathLike
        The results (Parquet), written as rows arrive.
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://host:8786``); default: a local
        cluster of worker processes started for the run and stopped after it (Dask
        configured with :data:`WORKER_CONFIG`).
    workers : int, optional
        Worker processes of the local cluster (default: one per core).
    resume : bool
        Keep the results already in ``output`` and run only the tasks not done yet
        (failed tasks run again).
    progress : bool
        Show a progress bar.
    log : callable, optional
        Receives one line about the cluster before the run.

    Returns
    -------
    CampaignRun

    Raises
    ------
    InputError
        Results already in ``output`` without ``resume``, results of another campaign
        there, a scheduler that cannot be reached, a bad number of workers.
    ConfigError
        A bad spec (naming the file and the key).
    """
    start = time.perf_counter()
    if not isinstance(spec, CampaignSpec):
        spec = load_spec(spec)
    store = ResultStore(output, resume=resume)
    if store.previous is not None:
        ids = {t.id for t in spec.tasks}
        foreign = [t for t in store.previous.column("task").to_pylist() if t not in ids]
        if foreign:
            raise InputError(f"{store.output}: holds results of another campaign (task {foreign[0]!r} is not "
                             f"in {spec.path}); choose another output file")
    todo = [t for t in spec.tasks if t.id not in store.done]
    ran = failed = n_workers = 0
    try:
        if todo:
            with _quiet_dask(), _client(scheduler, workers) as client:
                client.register_plugin(WorkerFolder(), name=WorkerFolder.name)
                n_workers = len(client.scheduler_info(n_workers=-1)["workers"])
                if log is not None:
                    log(f"{len(todo)} task(s) on {n_workers} worker(s) of {client.scheduler.address}"
                        + (f"; {len(spec.tasks) - len(todo)} already done" if len(todo) < len(spec.tasks) else ""))
                token = uuid.uuid4().hex[:12]
                futures = client.map(run_task, todo, key=[f"duffid-campaign-{token}-{i}" for i in range(len(todo))],
                                     pure=False)
                by_key = {f.key: task for f, task in zip(futures, todo)}
                try:
                    with tqdm(total=len(todo), desc=spec.name, unit="task", disable=not progress,
                              leave=False) as bar:
                        for future in as_completed(futures):
                            task = by_key[future.key]
                            try:
                                row = future.result()
                            except Exception as exc:  # the worker died under it too often, or a lost result
                                row = {"task": task.id, "kind": task.kind, **task.factors, "status": "failed",
                                       "error": f"{type(exc).__name__}: {' '.join(str(exc).split())}"}
                            future.release()
                            store.add(row)
                            ran += 1
                            failed += row["status"] != "ok"
                            bar.update()
                finally:
                    client.cancel(futures)
    finally:
        table = store.close([t.id for t in spec.tasks])
    return CampaignRun(spec=spec, output=store.output, table=table, ran=ran,
                       skipped=len(spec.tasks) - len(todo), failed=failed, workers=n_workers,
                       seconds=time.perf_counter() - start)
