"""Benchmark of the online algebraic identifier: accuracy on the paper's cases and cost.

Run: python benchmarks/identification.py [--seeds 50] [--repeats 5]

Tables (medians over noise seeds; costs are medians of several runs, with ratios to a
baseline measured in the same run):
  1. Case A: 1-DOF, 14 N step, 0.25 s, 1 ms, encoder-quantised: errors and the time
     after which each estimate stays within 5 % of the truth.
  2. Case B: 1-DOF, 10 N step, 2 s, quantised + 40 dB noise: median errors over seeds,
     next to the peer baselines of ../shared/paper/NOTES.md.
  3. 2-DOF (Table 3 with m1 2.53, b1 5, b2 4), 6 N step, 1 s, noise-free.
  4. Cost per sample of OnlineIdentifier.update, of the estimator's run over a record in
     Python and in C (one batch call), and of the checked identify().
  5. Buffered identification with orthogonal functions (section 4), each basis on cases A
     and B next to the online methods: errors and cost per window.
"""
from __future__ import annotations

import argparse
import time

import numpy as np
from tqdm import tqdm

from duffid import Duffing1, Duffing2, OnlineIdentifier, Step, identify, measure, simulate
from duffid.identification.batch import estimate
from duffid.identification.buffered import BufferedIdentifier, velocity_signs
from duffid.identification.orthogonal import projection_matrix
from duffid.identification.trust import run_estimator

TARGETS_A = {"paper": {"m": 0.3, "b": 1.0, "k": 0.3, "kp": 0.3},
             "robust": {"m": 0.05, "b": 0.15, "k": 0.05, "kp": 0.05}}
TARGET_TIMES = {"m": 0.06, "k": 0.06, "b": 0.15, "kp": 0.15}
TARGETS_B = {"m": 0.2, "b": 0.4, "k": 0.06, "kp": 0.6}
PEERS_B = {
    "paper filtered (NOTES, gamma 20)": [0.29, 1.8, 0.05, 0.46],
    "sliding window I2..I5 (NOTES)": [0.14, 0.26, 0.04, 0.50],
    "output-error grey box (NOTES)": [0.05, 0.08, 0.03, 0.25],
    "LS on Savitzky-Golay (NOTES)": [0.68, 0.58, 0.13, 1.5],
}
NAMES1 = ("m", "b", "k", "kp")


def _row(label: str, values, width: int = 10, fmt: str = ".3f") -> str:
    cells = "".join(f"{v:>{width}{fmt}}" if isinstance(v, (float, np.floating)) and np.isfinite(v)
                    else f"{str(v if v is not None else '-'):>{width}}" for v in values)
    return f"{label:<36}{cells}"


def case_a() -> None:
    plant = Duffing1()
    truth = plant.parameters
    record = measure(simulate(plant, Step(14.0), 0.25, 1e-3))
    print("\n1. Case A: 1-DOF, 14 N step, 0.25 s, 1 ms, encoder 2266 pulses/cm")
    print(_row("relative error [%]", NAMES1))
    for method in ("paper", "robust"):
        result = estimate(record, plant, method)
        err = result.errors(truth)
        print(_row(f"  {method}", [abs(err[p]) for p in NAMES1]))
        print(_row(f"  {method} target (|err| <)", [TARGETS_A[method][p] for p in NAMES1]))
    print(_row("time to stay within 5 % [s]", NAMES1))
    for method in ("paper", "robust"):
        times = estimate(record, plant, method).time_within(truth, 0.05)
        print(_row(f"  {method}", [times[p] for p in NAMES1]))
    print(_row("  target (robust)", [TARGET_TIMES[p] for p in NAMES1]))


def case_b(seeds: int) -> None:
    plant = Duffing1()
    truth = plant.parameters
    exact = simulate(plant, Step(10.0), 2.0, 1e-3)
    errors = {"paper": [], "robust": []}
    for seed in tqdm(range(seeds), desc="case B seeds", leave=False):
        record = measure(exact, snr_db=40, seed=seed)
        for method in errors:
            err = estimate(record, plant, method).errors(truth)
            errors[method].append([abs(err[p]) for p in NAMES1])
    print(f"\n2. Case B: 1-DOF, 10 N step, 2 s, quantised + 40 dB noise, median |error| [%] over {seeds} seeds")
    print(_row("", NAMES1))
    for method, values in errors.items():
        print(_row(f"  duffid {method}", np.median(values, axis=0)))
    print(_row("  target (robust)", [TARGETS_B[p] for p in NAMES1]))
    for label, values in PEERS_B.items():
        print(_row(f"  {label}", values))


def two_dof() -> None:
    plant = Duffing2()
    truth = plant.parameters
    record = simulate(plant, Step(6.0), 1.0, 1e-3)
    ratios = {f"{p}/m2": truth[p] / truth["m2"] for p in ("b2", "k2", "kp2")}
    names = list(truth) + list(ratios)
    print("\n3. 2-DOF chain, 6 N step on DOF 1, 1 s, 1 ms, noise-free: |error| [%] (target < 0.1)")
    print(_row("", names, width=9))
    for method in ("paper", "robust"):
        result = estimate(record, plant, method)
        p = result.parameters
        est = {**p, **{f"{q}/m2": p[q] / p["m2"] for q in ("b2", "k2", "kp2")}}
        ref = {**truth, **ratios}
        print(_row(f"  {method}", [abs(100 * (est[n] - ref[n]) / ref[n]) for n in names], width=9))


def _median_time(func, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        func()
        times.append(time.perf_counter() - start)
    return float(np.median(times))


def cost(repeats: int) -> None:
    print(f"\n4. Cost (median of {repeats} runs; ratio to the paper method measured in the same run)")
    print(_row("", ["us/sample", "ratio", "samples/s"], width=12))
    cases = {"1-DOF": (Duffing1(), simulate(Duffing1(), Step(10.0), 2.0, 1e-3)),
             "2-DOF": (Duffing2(), simulate(Duffing2(), Step(6.0), 1.0, 1e-3))}
    for label, (model, record) in cases.items():
        per_sample = {}
        for method, options in [("paper", {}), ("robust", {}), ("robust", {"window": 0.1}),
                                ("robust", {"window": 1.0})]:
            def run() -> None:
                ident = OnlineIdentifier(model, record.dt, method, **options)
                for x, f in zip(record.x, record.f):
                    ident.update(x, f)
            key = method + ("" if not options else f" window {options['window']} s")
            per_sample[key] = _median_time(run, repeats) / record.n_samples
        base = per_sample["paper"]
        for key, value in per_sample.items():
            print(_row(f"  {label} update, {key}", [1e6 * value, value / base, 1.0 / value], width=12, fmt=".2f"))
        for name, call in [("estimate() robust, Python", lambda: estimate(record, model)),
                           ("run_estimator() robust, C", lambda: run_estimator(record, model, engine="c")),
                           ("identify() checked, C", lambda: identify(record, model))]:
            t_call = _median_time(call, repeats)
            print(_row(f"  {label} {name}", [1e6 * t_call / record.n_samples, t_call / record.n_samples / base,
                                            record.n_samples / t_call], width=12, fmt=".2f"))


#: Buffered configurations: (label, method, options). Case A is one window of 0.25 s.
BUFFERED_A = [
    ("legendre 24", "legendre", {}),
    ("chebyshev 24", "chebyshev", {}),
    ("block-pulse 128", "block-pulse", {}),
    ("haar 128", "haar", {}),
    ("block-pulse 128, exact P_m", "block-pulse", {"repeated": "exact"}),
    ("legendre 64, trapezoid coef.", "legendre", {"n_terms": 64, "quadrature": "trapezoid"}),
]
#: Case B: 0.5 s windows back to back, the equations of all windows stacked.
_B = {"window": 0.5, "accumulate": True}
BUFFERED_B = [
    ("legendre 48", "legendre", {**_B, "n_terms": 48}),
    ("chebyshev 48", "chebyshev", {**_B, "n_terms": 48}),
    ("block-pulse 128", "block-pulse", dict(_B)),
    ("haar 128", "haar", dict(_B)),
    ("block-pulse 128, exact P_m", "block-pulse", {**_B, "repeated": "exact"}),
    ("legendre 48, last window only", "legendre", {"window": 0.5, "n_terms": 48}),
]


def _window_cost(model, record, method: str, options: dict, repeats: int) -> list[float]:
    """Median cost of one re-identification (solve_window: us per window and per sample of
    the record, re-identifying every `every` samples) and of building the identifier from
    scratch (ms: quadrature, basis and operational matrices)."""
    def build() -> None:
        projection_matrix.cache_clear()
        BufferedIdentifier(model, record.dt, method, **options)
    setup = _median_time(build, repeats)
    ident = BufferedIdentifier(model, record.dt, method, **options)
    G = ident.regression.evaluate(record.x, record.f, record.t, velocity_signs(record.x))
    N = ident.n_intervals
    windows = [G[end - N: end + 1] for end in range(N, record.n_samples, max(N // 4, 1))]

    def run() -> None:
        for w in windows:
            ident.solve_window(w)
    per_window = _median_time(run, repeats) / len(windows)
    return [1e6 * per_window, 1e6 * per_window / ident.every, 1e3 * setup]


def buffered(seeds: int, repeats: int) -> None:
    plant = Duffing1()
    truth = plant.parameters
    record_a = measure(simulate(plant, Step(14.0), 0.25, 1e-3))
    print("\n5. Buffered identification with orthogonal functions (section 4, Figure 15)")
    print("5a. Case A (one 0.25 s window, encoder-quantised): |error| [%]; cost per window, per sample "
          "(re-identifying every window) and to set up")
    cost_names = ["us/window", "us/sample", "setup ms"]
    print(_row("", list(NAMES1) + cost_names, width=10))
    for method in ("paper", "robust"):
        err = estimate(record_a, plant, method).errors(truth)
        print(_row(f"  online {method}", [abs(err[p]) for p in NAMES1]))
    for label, method, options in BUFFERED_A:
        err = estimate(record_a, plant, method, **options).errors(truth)
        costs = _window_cost(plant, record_a, method, options, repeats)
        print(_row(f"  {label}", [abs(err[p]) for p in NAMES1] + costs))
    exact = simulate(plant, Step(10.0), 2.0, 1e-3)
    records = [measure(exact, snr_db=40, seed=s) for s in range(seeds)]
    print(f"5b. Case B (0.5 s windows, quantised + 40 dB noise): median |error| [%] over {seeds} seeds")
    print(_row("", list(NAMES1) + cost_names, width=10))
    for method in ("paper", "robust"):
        errors = [[abs(v) for v in estimate(r, plant, method).errors(truth).values()]
                  for r in tqdm(records, desc=method, leave=False)]
        print(_row(f"  online {method}", np.median(errors, axis=0)))
    for label, method, options in BUFFERED_B:
        errors = [[abs(v) for v in estimate(r, plant, method, **options).errors(truth).values()]
                  for r in tqdm(records, desc=label, leave=False)]
        costs = _window_cost(plant, records[0], method, options, repeats)
        print(_row(f"  {label}", list(np.median(errors, axis=0)) + costs))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=50, help="noise seeds of case B (default 50)")
    parser.add_argument("--repeats", type=int, default=5, help="runs per cost figure (default 5)")
    args = parser.parse_args()
    case_a()
    case_b(args.seeds)
    two_dof()
    cost(args.repeats)
    buffered(args.seeds, args.repeats)


if __name__ == "__main__":
    main()
