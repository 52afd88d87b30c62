"""Benchmark of campaigns on Dask: the case-B Monte-Carlo study on 1 and 2 worker processes.

Run: python benchmarks/campaign.py [--seeds 250]

The spec is examples/campaigns/case_b.toml (1-DOF, 10 N step, 2 s, quantised + 40 dB
noise; the paper and robust online methods, bare estimator in Python) with seeds
0 .. seeds-1, i.e. 2 x seeds runs (500 by default). Tables:
  1. Wall-clock time of the serial loop of benchmarks/identification.py (table 2) and of
     the campaign on a local cluster of 1 and of 2 worker processes (cluster start-up
     included), runs per second and the speed-up 1 worker / 2 workers measured in this run
     (on 2 cores expect close to 2x when nothing else runs), and the runs' own seconds
     summed over the workers (busy = that / wall-clock: the workers kept busy on average) and
     what a run costs more in a worker than in the serial loop (task s / the serial loop's
     seconds - 1; the worker's event loop takes the GIL from the task now and then, see
     duffid.campaign.runner.WORKER_CONFIG).
  2. Median |error| [%] over the seeds from the campaign (runs where the estimator gave no
     value, NaN, counted apart), and whether every value of every run equals the serial
     loop's (the same computation, bit for bit, NaN for NaN).
"""
from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from duffid import Duffing1, Step, measure, simulate
from duffid.campaign import load_spec, run_campaign
from duffid.identification.batch import estimate

SPEC = Path(__file__).resolve().parent.parent / "examples" / "campaigns" / "case_b.toml"
NAMES = ("m", "b", "k", "kp")


def serial(seeds: int) -> dict[tuple[str, int], dict[str, float]]:
    """benchmarks/identification.py's case-B loop: errors [%] per (method, seed)."""
    plant = Duffing1()
    truth = plant.parameters
    exact = simulate(plant, Step(10.0), 2.0, 1e-3)
    out = {}
    for seed in tqdm(range(seeds), desc="serial loop", leave=False):
        record = measure(exact, snr_db=40, seed=seed)
        for method in ("paper", "robust"):
            out[(method, seed)] = estimate(record, plant, method).errors(truth)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=250, help="noise seeds (runs = 2 x seeds; default 250)")
    args = parser.parse_args()
    spec = load_spec(SPEC, seeds=args.seeds)
    print(f"{spec.name}: {len(spec.tasks)} runs ({SPEC.name}, seeds 0..{args.seeds - 1}); "
          f"{os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f} at the start")

    start = time.perf_counter()
    reference = serial(args.seeds)
    seconds = {"serial loop (one process)": time.perf_counter() - start}
    busy = {"serial loop (one process)": seconds["serial loop (one process)"]}
    tables = {}
    with tempfile.TemporaryDirectory() as folder:
        for workers in (1, 2):
            done = run_campaign(spec, Path(folder) / f"case_b_{workers}.parquet", workers=workers)
            assert done.failed == 0, f"{done.failed} runs failed"
            label = f"campaign, {workers} worker process{'es' if workers > 1 else ''}"
            seconds[label] = done.seconds
            busy[label] = float(sum(done.table.column("seconds").to_pylist()))
            tables[workers] = done.table.to_pylist()

    print(f"\n1. Wall-clock time of {len(spec.tasks)} runs (campaigns: cluster start-up included)")
    print(f"{'':<40}{'seconds':>10}{'runs/s':>10}{'task s':>10}{'busy':>8}{'per run':>10}")
    serial_seconds = seconds["serial loop (one process)"]
    for label, value in seconds.items():
        print(f"{label:<40}{value:>10.1f}{len(spec.tasks) / value:>10.2f}{busy[label]:>10.1f}"
              f"{busy[label] / value:>8.2f}{100 * (busy[label] / serial_seconds - 1):>+8.1f} %")
    one, two = (seconds[k] for k in seconds if k.startswith("campaign"))
    print(f"{'speed-up, 1 -> 2 workers':<40}{one / two:>10.2f}x   (load average now "
          f"{os.getloadavg()[0]:.1f}; task s: the runs' own seconds summed, busy: task s / wall-clock, "
          f"per run: task s against the serial loop)")

    print(f"\n2. Median |error| [%] over {args.seeds} seeds (campaign, 2 workers) and agreement with the serial loop")
    print("   (runs with no value, NaN, are left out of the medians and counted)")
    print(f"{'':<24}" + "".join(f"{p:>10}" for p in NAMES) + f"{'no value':>10}{'equal':>12}")
    for method in ("paper", "robust"):
        rows = [r for r in tables[2] if r["method"] == method]
        medians = [np.nanmedian([abs(r[f"error_{p}"]) for r in rows]) for p in NAMES]
        missing = [r["seed"] for r in rows if not all(np.isfinite(r[f"error_{p}"]) for p in NAMES)]
        same = all(np.array_equal(r[f"error_{p}"], reference[(method, r["seed"])][p], equal_nan=True)
                   for workers in tables for r in tables[workers] if r["method"] == method for p in NAMES)
        print(f"{'  duffid ' + method:<24}" + "".join(f"{v:>10.3f}" for v in medians)
              + f"{len(missing):>10}{'bit for bit' if same else 'DIFFERENT':>12}"
              + (f"   (no value: seed{'s' if len(missing) > 1 else ''} {', '.join(map(str, missing))})"
                 if missing else ""))
        assert same, f"{method}: the campaign's errors differ from the serial loop's"


if __name__ == "__main__":
    main()
