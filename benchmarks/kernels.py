"""Run the numerically sensitive tests under every OpenBLAS kernel and thread count.

numpy's OpenBLAS picks its kernels by CPU; ``OPENBLAS_CORETYPE`` forces one. Each kernel
rounds QR, SVD and products differently, so a tolerance that holds on one machine only fails
on another (tests/rounding.py says how the suite's tolerances follow from the problem
instead). This script is how a change is checked the same way on any one machine.

Run: python benchmarks/kernels.py [--all] [--kernels unset,Prescott,...] [--threads 1,2]
                                  [--jobs 2] [--calibrate]
 or: make test-kernels

Table 1 (always): kernel x OPENBLAS_NUM_THREADS -> passed / failed / skipped / errors and
wall time of the pytest run (the numerically sensitive files, or the whole suite with --all).
Table 2 (--calibrate): where the comparisons' tolerances come from. For each record of the
estimator tests: the largest C-vs-Python relative difference under each kernel, divided by
the Python identifier's one-ulp spread on that record (tests/rounding.py; the tests allow
SAFETY times that spread), over the history and at the end of the record.
"""
from __future__ import annotations

import argparse
import itertools
import os
import re
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
KERNELS = ("unset", "Prescott", "Sandybridge", "Haswell", "Zen", "SkylakeX")
THREADS = ("unset", "1", "2")
# files whose assertions compare floating-point results closely (estimates, designs, bases)
SENSITIVE = ("test_estimator_c.py", "test_fmu_estimator.py", "test_fmu_python.py", "test_identification.py",
             "test_symbolic.py", "test_buffered.py", "test_regressors.py", "test_orthogonal.py",
             "test_control.py", "test_fmu_controller.py", "test_models.py", "test_modelica.py",
             "test_nonlinearity.py", "test_refine.py", "test_signals.py", "test_estimator_generic_c.py",
             "test_equation_fmu.py", "test_equation_model.py")
SUMMARY = re.compile(r"(\d+) (passed|failed|skipped|errors?|deselected|xfailed|xpassed)")


def _environment(kernel: str, threads: str) -> dict[str, str]:
    env = dict(os.environ)
    for name, value in (("OPENBLAS_CORETYPE", kernel), ("OPENBLAS_NUM_THREADS", threads)):
        if value == "unset":
            env.pop(name, None)
        else:
            env[name] = value
    return env


def _counts(output: str) -> dict[str, int]:
    last = [line for line in output.splitlines() if " in " in line and SUMMARY.search(line)]
    counts = {"passed": 0, "failed": 0, "skipped": 0, "errors": 0}
    for number, word in SUMMARY.findall(last[-1] if last else ""):
        key = "errors" if word.startswith("error") else word
        if key in counts:
            counts[key] += int(number)
    return counts


def run_suite(kernel: str, threads: str, files: list[str], extra: list[str]) -> dict:
    """One pytest run under ``kernel`` and ``threads``; its counts, time and failed test ids."""
    with tempfile.TemporaryDirectory(prefix="duffid-kernels-") as tmp:
        cmd = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", f"--basetemp={tmp}/t",
               *files, *extra]
        start = time.perf_counter()
        proc = subprocess.run(cmd, cwd=ROOT, env=_environment(kernel, threads), capture_output=True, text=True)
        seconds = time.perf_counter() - start
    counts = _counts(proc.stdout)
    failed = [line.split(" ", 1)[1].split(" - ")[0] for line in proc.stdout.splitlines()
              if line.startswith(("FAILED ", "ERROR "))]
    ok = proc.returncode == 0 and counts["passed"] > 0
    return {"kernel": kernel, "threads": threads, "seconds": seconds, "ok": ok, "failed_ids": failed,
            "returncode": proc.returncode, "tail": proc.stdout[-2000:] + proc.stderr[-2000:], **counts}


def print_runs(rows: list[dict]) -> None:
    print(f"{'OPENBLAS_CORETYPE':<18} {'NUM_THREADS':<12} {'passed':>7} {'failed':>7} {'skipped':>8} "
          f"{'errors':>7} {'time s':>8}  result")
    for r in rows:
        print(f"{r['kernel']:<18} {r['threads']:<12} {r['passed']:>7} {r['failed']:>7} {r['skipped']:>8} "
              f"{r['errors']:>7} {r['seconds']:>8.0f}  {'ok' if r['ok'] else 'FAILED'}")
    for r in rows:
        for test_id in r["failed_ids"]:
            print(f"  {r['kernel']}/{r['threads']}: {test_id}")
        if not r["ok"] and not r["failed_ids"]:
            print(f"  {r['kernel']}/{r['threads']}: pytest exited {r['returncode']}:\n{r['tail']}")


# ---------------------------------------------------------------------- calibration
CALIBRATION_CASES = {
    # name: (model, step force [N], duration [s], 40 dB noise seed or None, method, options)
    "1-DOF 10 N 40 dB robust": ("duffing1", 10.0, 2.0, 3, "robust", {}),
    "1-DOF 10 N 40 dB paper": ("duffing1", 10.0, 2.0, 3, "paper", {}),
    "2-DOF 6 N robust": ("duffing2", 6.0, 1.0, None, "robust", {}),
    "2-DOF 6 N paper": ("duffing2", 6.0, 1.0, None, "paper", {}),
    "2-DOF 10 N robust": ("duffing2", 10.0, 1.0, None, "robust", {}),
    "2-DOF 10 N paper (sign in numerator)": ("duffing2", 10.0, 1.0, None, "paper", {"sign_in_numerator": True}),
}


def _calibration_record(model_name: str, step: float, duration: float, seed: int | None):
    from duffid import Duffing1, Duffing2, Step, measure, simulate

    model = Duffing1() if model_name == "duffing1" else Duffing2()
    record = simulate(model, Step(step), duration, 1e-3)
    return model, (record if seed is None else measure(record, snr_db=40, seed=seed))


def _histories(engine: str, out: str) -> None:
    """Child process: every calibration case's estimate history with ``engine`` to ``out`` (npz)."""
    import numpy as np

    from duffid import OnlineIdentifier
    from duffid.identification.c_core import CIdentifier

    cls = CIdentifier if engine == "C" else OnlineIdentifier
    arrays = {}
    for i, (name, (model_name, step, duration, seed, method, options)) in enumerate(CALIBRATION_CASES.items()):
        model, record = _calibration_record(model_name, step, duration, seed)
        ident = cls(model, record.dt, method, **options)
        arrays[f"case{i}"] = np.array([list(ident.update(x, f).parameters.values()) for x, f in zip(record.x, record.f)])
    np.savez(out, **arrays)


def calibrate(kernels: list[str]) -> None:
    import numpy as np

    sys.path.insert(0, str(ROOT / "tests"))
    from rounding import SAFETY, identifier_spread

    with tempfile.TemporaryDirectory(prefix="duffid-calibrate-") as tmp:
        engines = ["C", *kernels]
        paths = {e: f"{tmp}/{e}.npz" for e in engines}

        def child(engine: str) -> None:
            env = _environment("unset" if engine == "C" else engine, "unset")
            subprocess.run([sys.executable, __file__, "--histories", engine, paths[engine]], env=env, check=True)

        with ThreadPoolExecutor(2) as pool:
            list(pool.map(child, engines))
        data = {e: np.load(paths[e]) for e in engines}
        print(f"\nC-vs-Python difference / one-ulp spread of Python (tests allow {SAFETY:g}); "
              f"history over samples >= 100 | end of record")
        print(f"{'record':<38} " + " ".join(f"{k:>17}" for k in kernels) + f" {'spread (end, max)':>18}")
        for i, (name, (model_name, step, duration, seed, method, options)) in enumerate(CALIBRATION_CASES.items()):
            model, record = _calibration_record(model_name, step, duration, seed)
            spread = identifier_spread(model, record, method, **options)
            C = data["C"][f"case{i}"]
            cells = []
            for k in kernels:
                P = data[k][f"case{i}"]
                with np.errstate(all="ignore"):
                    rel = np.where(P == C, 0.0, np.abs(P - C) / np.abs(P))
                rel = np.where(np.isfinite(rel), rel, 0.0)
                hist = (rel[100:].max(axis=0) / np.maximum(spread.parameters[100:].max(axis=0), 1e-300)).max()
                end = (rel[-1] / np.maximum(spread.parameters[-1], 1e-300)).max()
                cells.append(f"{hist:8.2f} |{end:7.2f}")
            print(f"{name:<38} " + " ".join(f"{c:>17}" for c in cells) + f" {spread.parameters[-1].max():18.1e}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--all", action="store_true", help="run the whole suite, not only the sensitive files")
    parser.add_argument("--kernels", default="unset,Prescott,Sandybridge,Haswell,Zen",
                        help=f"comma-separated OPENBLAS_CORETYPE values (known: {', '.join(KERNELS)})")
    parser.add_argument("--threads", default="1,2", help="comma-separated OPENBLAS_NUM_THREADS values")
    parser.add_argument("--jobs", type=int, default=2, help="pytest runs at a time (default 2)")
    parser.add_argument("--calibrate", action="store_true",
                        help="also print the C-vs-Python difference per kernel against the one-ulp spread")
    parser.add_argument("--histories", nargs=2, metavar=("ENGINE", "OUT"), help=argparse.SUPPRESS)
    parser.add_argument("pytest_args", nargs="*", help="extra pytest arguments (after --)")
    args = parser.parse_args(argv)
    if args.histories:
        _histories(*args.histories)
        return 0
    kernels = [k.strip() for k in args.kernels.split(",") if k.strip()]
    threads = [t.strip() for t in args.threads.split(",") if t.strip()]
    unknown = [k for k in kernels if k not in KERNELS]
    if unknown:
        parser.error(f"--kernels: unknown kernel(s) {', '.join(unknown)}; known: {', '.join(KERNELS)}")
    if args.jobs < 1:
        parser.error("--jobs must be at least 1")
    files = [] if args.all else [f"tests/{name}" for name in SENSITIVE]
    combos = list(itertools.product(kernels, threads))
    print(f"{'whole suite' if args.all else f'{len(files)} numerically sensitive test files'} under "
          f"{len(combos)} kernel/thread settings, {args.jobs} at a time", flush=True)
    with ThreadPoolExecutor(args.jobs) as pool:
        rows = list(pool.map(lambda kt: run_suite(*kt, files, args.pytest_args), combos))
    print_runs(rows)
    if args.calibrate:
        calibrate([k for k in kernels if k != "unset"])
    return 0 if all(r["ok"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
