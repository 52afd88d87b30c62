"""The three kinds of campaign task, run where a worker picks them up.

:func:`run_task` takes a :class:`~duffid.campaign.spec.Task` and returns one row of the
results table: the task's id and factors, ``status`` (``"ok"`` or ``"failed"``), ``error``
(the exception, in one line, when it failed), ``seconds`` and ``worker`` (host and process),
then the task's figures:

- ``identification``: per parameter ``estimate_<p>`` (the estimator's value; with the
  checks, the value assessed), ``error_<p>`` (relative error against the truth [%]) and,
  checked, ``status_<p>`` (:data:`duffid.identification.engine.STATUSES`) and
  ``uncertainty_<p>`` (relative standard error), ``published`` (how many parameters are);
- ``nonlinearity``: ``eta``, ``eta_uncorrected``, ``distortion_db``, ``verdict``,
  ``band_low``, ``band_high``; a plant that escapes its potential well gives ``eta`` NaN
  and the reason in ``note`` (as :func:`duffid.analysis.nonlinearity.amplitude_sweep`);
- ``cosim``: one column per metric (``<metric>.<name>`` for a metric returning a mapping),
  ``rows`` (communication points) and ``note`` (why the run ended early, if it did).

A failing task never raises: its error is in its row and the campaign goes on. Each process
keeps what tasks share: the exact simulation of an identification study (simulated once,
measured with each seed) and the co-simulation configurations
(:func:`duffid.campaign.systems.configured_system`).
"""
from __future__ import annotations

import math
import os
import socket
import time
from functools import lru_cache
from typing import TYPE_CHECKING, Any, Mapping

from ..analysis.nonlinearity import analyse, sweep_record
from ..data.record import Record
from ..data.signals import from_spec
from ..errors import InputError, SimulationError
from ..identification.trust import identify
from ..models.equation_model import EquationModel
from ..models.simulation import measure, simulate
from .metrics import resolve_metric
from .plants import plant_model
from .systems import configured_system

if TYPE_CHECKING:
    from .spec import Task

__all__ = ["run_task"]

@lru_cache(maxsize=8)
def _exact(which: tuple[str, str], plant: tuple[tuple[str, float], ...], excitation: str, t_end: float,
           dt: float) -> Record:
    """The noise-free simulation shared by the seeds of one setting (simulated once per process);
    ``which``: ``("model", name)`` or ``("equation", text)``."""
    model = plant_model({which[0]: which[1], **{f"plant.{k}": v for k, v in plant}})
    return simulate(model, from_spec(excitation), t_end, dt)


def _identification(settings: Mapping[str, Any]) -> dict[str, Any]:
    plant = plant_model(settings)
    if "record" in settings:
        record = Record.read(settings["record"])  # any format duffid reads, by its extension
        truth = {k[len("plant."):]: float(v) for k, v in settings.items() if k.startswith("plant.")}
    else:
        key = tuple(sorted((k[len("plant."):], float(v)) for k, v in settings.items() if k.startswith("plant.")))
        which = ("equation", settings["equation"]) if "equation" in settings else ("model", settings["model"])
        exact = _exact(which, key, settings["excitation"], settings["t_end"], settings["dt"])
        record = exact
        if "snr_db" in settings or settings.get("quantise", True):
            options: dict[str, Any] = {"seed": settings.get("seed", 0), "snr_db": settings.get("snr_db")}
            if not settings.get("quantise", True):
                options["pulses_per_cm"] = None
            record = measure(exact, **options)
        truth = dict(plant.parameters)
    check = settings.get("check", True)
    options = {k[len("options."):]: v for k, v in settings.items() if k.startswith("options.")}
    identified = EquationModel(settings["equation"], record.column_names) if "equation" in settings else plant
    result = identify(record, identified, settings.get("method", "robust"), check=check,
                      engine=settings.get("engine", "auto"), progress=False, **options)
    values = dict(result.assessment.values) if check and result.assessment is not None and \
        result.assessment.values else dict(result.parameters)
    row: dict[str, Any] = {}
    for name, value in values.items():
        row[f"estimate_{name}"] = float(value)
        true = truth.get(name)
        row[f"error_{name}"] = (100.0 * (float(value) - true) / true) if true else math.nan
    if check and result.assessment is not None:
        for name, status in result.assessment.status.items():
            row[f"status_{name}"] = status
            row[f"uncertainty_{name}"] = float(result.assessment.uncertainty.get(name, math.nan))
        row["published"] = sum(s == "published" for s in result.assessment.status.values())
    return row


def _nonlinearity(settings: Mapping[str, Any]) -> dict[str, Any]:
    plant = plant_model(settings)
    sweep = {k: settings[k] for k in ("rate", "f_max", "dt", "ring_down") if k in settings}
    try:
        record = sweep_record(plant, float(settings["amplitude"]), **sweep)
    except SimulationError as exc:
        return {"eta": math.nan, "eta_uncorrected": math.nan, "distortion_db": math.nan,
                "verdict": "undetermined", "note": f"escaped: {exc}"}
    result = analyse(record, band=settings.get("band"), n_modes=settings.get("n_modes"))
    return {"eta": float(result.eta), "eta_uncorrected": float(result.eta_uncorrected),
            "distortion_db": float(result.distortion_db), "verdict": result.verdict,
            "band_low": float(result.band[0]), "band_high": float(result.band[1])}


def _cosim(settings: Mapping[str, Any], metrics: Mapping[str, Mapping[str, Any]]) -> dict[str, Any]:
    overrides = {k: v for k, v in settings.items() if k not in ("system", "seed")}
    config = configured_system(settings["system"], overrides)
    result = config.run()
    row: dict[str, Any] = {"rows": len(result)}
    if result.ended is not None:
        row["note"] = result.ended
    for name, entry in metrics.items():
        arguments = {k: v for k, v in entry.items() if k != "function"}
        value = resolve_metric(entry["function"])(result, **arguments)
        if isinstance(value, Mapping):
            row.update({f"{name}.{k}": float(v) for k, v in value.items()})
        else:
            row[name] = float(value)
    return row


def run_task(task: Task) -> dict[str, Any]:
    """Run one task; its row of the results table (see the module documentation).

    Never raises for a failure of the task itself: the row says ``status = "failed"`` and
    ``error`` what went wrong.
    """
    start = time.perf_counter()
    row: dict[str, Any] = {"task": task.id, "kind": task.kind, **task.factors, "status": "ok", "error": None}
    try:
        if task.kind == "identification":
            row.update(_identification(task.settings))
        elif task.kind == "nonlinearity":
            row.update(_nonlinearity(task.settings))
        elif task.kind == "cosim":
            row.update(_cosim(task.settings, task.metrics))
        else:
            raise InputError(f"unknown kind of task {task.kind!r}")
    except Exception as exc:  # recorded; the campaign goes on
        row["status"] = "failed"
        row["error"] = f"{type(exc).__name__}: {' '.join(str(exc).split())}"
    row["seconds"] = time.perf_counter() - start
    row["worker"] = f"{socket.gethostname()}:{os.getpid()}"
    return row
