"""Throughput of the checked ``identify`` against the bare C batch, and its peak memory.

Run: python benchmarks/speed.py [--sizes 1e4,1e5,1e6,1e7] [--other-sizes 1e4,1e5,1e6] [--runs 5]
[--max-runs-10m N] [--models 1-DOF,2-DOF,equation]

For each model (the paper's 1-DOF plant, the 2-DOF chain and a user's equation with
amplitude-dependent damping) and record size, a record of random-phase multisine force at
1 kHz with 40 dB displacement noise is built once with duffid's own RK4 simulator (the step of
:class:`duffid.identification.refine.OdeSimulator`, the force exact at every stage) and cached
under ``build/speed_records``. A fresh process then loads it and, ``--runs`` times in turn,
runs the bare C batch (``run_estimator``: the estimator alone, one core), the checked
``identify`` on one core (``jobs=1``) and on every core: throughputs are the medians of the
runs (with their spread, lowest-highest), and each ratio checked / bare is the median of the
ratios of the same run (so that other load on the machine cancels). The peak RSS is the
fresh process's own high-water mark (``VmHWM`` in ``/proc/self/status``; not ``ru_maxrss``,
which a child inherits from its parent across exec), measured after one checked ``identify``
on all cores, the record and the interpreter included. The issue's target: checked >= 100,000
samples/s on one core and >= 0.4 x the bare batch; peak RSS growing at most linearly.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CACHE = ROOT / "build" / "speed_records"
DT = 1e-3
#: Period of the multisine force [s]: its values are computed over one period and repeated.
PERIOD = 20.0
DAMPING = "m*der(x,2) + b*der(x) + c*x^2*der(x) + k*x + kp*x^3 = f"
DAMPING_TRUTH = {"m": 1.2, "b": 3.0, "c": 4e4, "k": 1784.0, "kp": 5e5}


def plant(name: str) -> tuple[Any, Any]:
    """The plant and its force: (model, Multisine)."""
    from duffid import Duffing1, Duffing2, Multisine
    from duffid.models.equation_model import EquationModel

    if name == "1-DOF":
        return Duffing1(), Multisine(8.0, 0.5, 10.0, PERIOD, phases="random", seed=1)
    if name == "2-DOF":
        return Duffing2(), Multisine(5.0, 0.5, 12.0, PERIOD, phases="random", seed=1)
    if name == "equation":
        return EquationModel(DAMPING, values=DAMPING_TRUTH), Multisine(15.0, 1.0, 15.0, PERIOD, phases="random", seed=1)
    raise SystemExit(f"unknown model {name!r}")


def build_record(name: str, n: int) -> Path:
    """The cached record of ``n`` samples (built with duffid's RK4 step in chunks)."""
    from duffid import Record, measure
    from duffid.identification.refine import OdeSimulator

    path = CACHE / f"{name}-{n}.npz"
    if path.is_file():
        return path
    model, force = plant(name)
    substeps = 2
    sim = OdeSimulator(model, DT, substeps=substeps, free=())
    p = np.array([float(model.canonical_parameters()[k]) for k in sim.names])
    h = DT / substeps
    # the force at every half step over one period, repeated (PERIOD / h is an integer)
    per_period = int(round(PERIOD / (h / 2)))
    table = np.asarray(force(np.arange(per_period) * (h / 2)), dtype=float)

    def at(k: np.ndarray) -> np.ndarray:  # the force at half step k
        return table[k % per_period]

    nd = model.n_dof
    x = np.empty((n, nd))
    x[0] = 0.0
    z = np.zeros(2 * nd)
    chunk, runners = 1 << 16, {}
    i = 0
    while i < n - 1:
        samples = min(chunk, n - 1 - i)
        steps = samples * substeps
        k = 2 * (i * substeps + np.arange(steps))
        U = np.vstack([at(k), at(k + 1), at(k + 2)])
        if steps not in runners:
            runners[steps] = sim.step.mapaccum("simulate", steps)
        states = np.asarray(runners[steps](z, U, p, h))
        x[i + 1:i + 1 + samples] = states[:nd, substeps - 1::substeps].T
        z = states[:, -1].copy()
        i += samples
    if not np.all(np.isfinite(x)):
        raise SystemExit(f"{name}: the simulation escaped")
    t = np.arange(n) * DT
    f = at(4 * np.arange(n))
    record = measure(Record(t, f, x), pulses_per_cm=None, snr_db=40, seed=2)
    CACHE.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.npz")
    np.savez(tmp, t=record.t, f=record.f, x=record.x)
    os.replace(tmp, path)
    return path


def peak_rss() -> float:
    """This process's peak resident memory [MB] (VmHWM)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024.0
    return math.nan


def worker(name: str, n: int, runs: int) -> dict[str, Any]:
    """In a fresh process: the runs on the cached record; times, statuses, peak RSS."""
    from duffid import Record, identify
    from duffid.identification.dispatch import all_cores, run_estimator

    data = np.load(build_record(name, n))
    record = Record(data["t"], data["f"], data["x"].reshape(n, -1), source=f"{name} {n}")
    model, _ = plant(name)
    cores = all_cores()
    calls: dict[str, Callable[[], Any]] = {
        "bare": lambda: run_estimator(record, model, engine="c"),
        "checked 1 core": lambda: identify(record, model, jobs=1, progress=False),
        f"checked {cores} cores": lambda: identify(record, model, jobs=cores, progress=False),
    }
    times: dict[str, list[float]] = {k: [] for k in calls}
    result = None
    for _ in range(runs):
        for label, call in calls.items():
            start = time.perf_counter()
            out = call()
            times[label].append(time.perf_counter() - start)
            if label != "bare":
                result = out
    a = result.assessment
    return {"model": name, "n": n, "times": times, "cores": cores, "rss_mb": peak_rss(),
            "status": dict(a.status), "parameters": {k: float(v) for k, v in result.parameters.items()}}


def measure_case(name: str, n: int, runs: int) -> dict[str, Any]:
    build_record(name, n)
    out = subprocess.run([sys.executable, __file__, "--worker", name, str(n), str(runs)], check=True,
                         capture_output=True, text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def spread(values: list[float]) -> str:
    return f"{min(values):,.0f}-{max(values):,.0f}"


def print_table(rows: list[dict[str, Any]]) -> None:
    print(f"{'model':<9} {'samples':>10} {'runs':>4} {'bare C [samples/s]':>24} {'checked, 1 core':>24} "
          f"{'checked, all cores':>24} {'ratio 1 core':>18} {'ratio all':>18} {'peak RSS':>9}  published")
    for r in rows:
        n, t = r["n"], r["times"]
        labels = list(t)
        rate = {k: [n / s for s in v] for k, v in t.items()}
        ratio = {k: [b / c for b, c in zip(t["bare"], v)] for k, v in t.items()}

        def cell(k: str) -> str:
            return f"{np.median(rate[k]):,.0f} ({spread(rate[k])})"

        def rcell(k: str) -> str:
            return f"{np.median(ratio[k]):.3f} ({min(ratio[k]):.3f}-{max(ratio[k]):.3f})"

        published = sum(s == "published" for s in r["status"].values())
        print(f"{r['model']:<9} {n:>10,} {len(t['bare']):>4} {cell('bare'):>24} {cell(labels[1]):>24} "
              f"{cell(labels[2]):>24} {rcell(labels[1]):>18} {rcell(labels[2]):>18} {r['rss_mb']:>7,.0f} MB  "
              f"{published}/{len(r['status'])}")
    if rows:
        print(f"(all cores: {rows[0]['cores']}; spreads are lowest-highest over the runs; ratios are checked/bare "
              f"of the same run)")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", default="1e4,1e5,1e6,1e7", help="record sizes of the 1-DOF plant, in samples")
    parser.add_argument("--other-sizes", default="1e4,1e5,1e6",
                        help="record sizes of the 2-DOF chain and the equation model")
    parser.add_argument("--runs", type=int, default=5, help="runs per figure (median)")
    parser.add_argument("--max-runs-10m", type=int, default=None,
                        help="runs for records of 10 M samples and more (default: --runs)")
    parser.add_argument("--models", default="1-DOF,2-DOF,equation")
    parser.add_argument("--worker", nargs=3, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        name, n, runs = args.worker
        print(json.dumps(worker(name, int(n), int(runs))))
        return 0
    rows = []
    for name in args.models.split(","):
        for size in (args.sizes if name == "1-DOF" else args.other_sizes).split(","):
            n = int(float(size))
            runs = args.runs if n < 10_000_000 or args.max_runs_10m is None else args.max_runs_10m
            print(f"{name} {n:,} samples ...", file=sys.stderr, flush=True)
            rows.append(measure_case(name, n, runs))
    print("Checked identify against the bare C batch (1 kHz multisine records, 40 dB noise)")
    print_table(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
