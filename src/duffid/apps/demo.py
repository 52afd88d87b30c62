"""The main job: identify and control the paper's plants in co-simulation.

``make demo`` and ``duffid demo`` run :func:`run_demo`: the FMUs are built if they are
missing or stale (:func:`duffid.control.closed_loop.ensure_fmus`), then each loop of
:func:`duffid.control.closed_loop.loop_cases` (1-DOF oscillator, the same with a payload
added during control, 2-DOF chain, Duffing circuit) runs plant <-> estimator <-> adaptive
controller and the mismatched baseline; estimates vs truth and tracking errors are printed
(with a payload: when the mass was flagged changed and re-published, and the tracking
before, during and after), and plots (excitation and response, estimates vs time, control
force, tracking error; with a payload ``<name>_payload.png``) and the recorded outputs
(CSV) are written to the output folder.
"""
from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Any, Mapping, TextIO

from ..control.closed_loop import LoopCase, LoopResult, ensure_fmus, loop_cases, run_loop, summary_lines
from .plots import plot_closed_loop, plot_payload

__all__ = ["run_demo"]


def run_demo(out: str | os.PathLike[str] = "out", *, fmu_dir: str | os.PathLike[str] = "build/fmus",
             stream: TextIO | None = None, progress: bool = False,
             cases: Mapping[str, LoopCase] | None = None) -> dict[str, Any]:
    """Run the main job and write its plots and records.

    Parameters
    ----------
    out : path
        Output folder (created).
    fmu_dir : path
        Where the FMUs are (built there if missing or stale).
    stream : file, optional
        Where the tables are printed (default stdout).
    progress : bool
        Progress bars for the co-simulation runs.
    cases : mapping, optional
        The loops to run, by name (default :func:`~duffid.control.closed_loop.loop_cases`).

    Returns
    -------
    dict
        The 1-DOF loop's summary (else the first loop's) at the top level (``identified``,
        ``truth``, ``tracking_rms``, ...) and every loop's under ``cases``.
    """
    stream = stream or sys.stdout
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    print("duffid demo: plant <-> online identifier <-> adaptive controller (FMI co-simulation)", file=stream)
    fmus = ensure_fmus(fmu_dir, log=lambda line: print(line, file=stream))
    results: dict[str, LoopResult] = {}
    for name, case in (loop_cases() if cases is None else cases).items():
        result = run_loop(case, fmus, progress=progress)
        results[name] = result
        print("", *summary_lines(result), sep="\n", file=stream)
        result.adaptive.to_csv(out / f"{name}_adaptive.csv")
        result.baseline.to_csv(out / f"{name}_baseline.csv")
        plot_closed_loop(result, out / f"{name}_closed_loop.png")
        if result.payload is not None:
            plot_payload(result, out / f"{name}_payload.png")
    print(f"\nplots and recorded outputs written to {out}/", file=stream)
    summary = results.get("oscillator1dof", next(iter(results.values()))).to_dict()
    summary["cases"] = {name: r.to_dict() for name, r in results.items()}
    return summary
