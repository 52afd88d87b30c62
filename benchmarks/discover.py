"""``duffid discover`` on records of plants with known missing terms: found, false, missed, time.

Run: python benchmarks/discover.py [--cases NAME,...] [--snr 40,50,60] [--quick] [--refine] [--cost-runs N]

Each record is simulated by an independent simulator (scipy's DOP853 at tight tolerances; the
force a random-phase multisine evaluated exactly at every stage; Coulomb friction smoothed
as ``tanh(v / 1e-4 m/s)``), not duffid's, from the hardening plant below with zero, one or two
terms that the base equation (``duffing1``: ``m x'' + b x' + k x + kp x^3 = f``) lacks, each
term carrying roughly a tenth of the force balance. White noise of the stated SNR is added to
the displacement (and 60 dB to the force). For every case and SNR the table gives the true
added terms, those found, the false ones (found but absent), the missed ones (present but
not found) and the wall-clock time of the search (one run; it includes compiling each
candidate's C estimator the first time, about 1.4 s each, and depends on the machine's
load). The Silverbox row reads ../shared/data/silverbox (the real electronic Duffing
oscillator) when it is there.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Mapping

import numpy as np
from scipy.integrate import solve_ivp

ROOT = Path(__file__).resolve().parents[1]

#: The base plant: 1.5 kg, 8.2 Hz, 2 % damping, kp x^3 ≈ 0.2 k x at 5 mm.
BASE = {"m": 1.5, "b": 3.1, "k": 4000.0, "kp": 3.2e7}
#: Each library term with the coefficient that gives it about a tenth of the balance at 5 mm.
TERMS: dict[str, tuple[float, Callable[[np.ndarray, np.ndarray], np.ndarray]]] = {
    "x^2": (8e4, lambda x, v: x**2),
    "x^5": (6e11, lambda x, v: x**5),
    "abs(x)*x": (8e4, lambda x, v: np.abs(x) * x),
    "x^2*der(x)": (4e5, lambda x, v: x**2 * v),
    "sign(der(x))": (1.0, lambda x, v: np.tanh(v / 1e-4)),
    "1": (2.0, lambda x, v: np.ones_like(x)),
}
#: Cases: name -> added terms (a subset of :data:`TERMS`).
CASES: dict[str, tuple[str, ...]] = {
    "plain": (),
    **{f"+ {term}": (term,) for term in TERMS},
    "+ x^2 & sign(der(x))": ("x^2", "sign(der(x))"),
    "+ x^5 & x^2*der(x)": ("x^5", "x^2*der(x)"),
    "+ x^2 & 1": ("x^2", "1"),
}
DT = 1e-3
DURATION = 20.0
#: The cost case's library: the default and two more terms, nine in all (the issue's size).
COST_LIBRARY = ("x^2", "x^3", "x^5", "abs(x)*x", "x^2*der(x)", "sign(der(x))", "1", "x^4", "x*der(x)")


@dataclass
class Plant:
    """A simulated plant: base values and added terms (name -> coefficient)."""

    added: Mapping[str, float]

    def force_of_terms(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        out = BASE["b"] * v + BASE["k"] * x + BASE["kp"] * x**3
        for term, coefficient in self.added.items():
            out = out + coefficient * TERMS[term][1](x, v)
        return out


def multisine(seed: int, rms: float = 10.0, low: float = 1.0, high: float = 20.0) -> Callable[[np.ndarray], np.ndarray]:
    """A random-phase multisine force (lines every 0.05 Hz from ``low`` to ``high``), ``rms`` N."""
    rng = np.random.default_rng(seed)
    frequencies = np.arange(low, high + 1e-9, 0.05)
    phases = rng.uniform(0, 2 * np.pi, len(frequencies))
    amplitude = rms * math.sqrt(2.0 / len(frequencies))

    def force(t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        return amplitude * np.sum(np.sin(2 * np.pi * frequencies[:, None] * t.ravel()[None, :] + phases[:, None]),
                                  axis=0).reshape(t.shape)
    return force


def sweep(duration: float, rms: float = 10.0, low: float = 1.0, high: float = 20.0) -> Callable[[np.ndarray], np.ndarray]:
    """A linear swept sine from ``low`` to ``high`` Hz over ``duration``, ``rms`` N."""
    rate = (high - low) / duration

    def force(t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        return rms * math.sqrt(2.0) * np.sin(2 * np.pi * (low * t + 0.5 * rate * t**2))
    return force


#: Excitations: name -> force of (seed, duration).
EXCITATIONS: dict[str, Callable[[int, float], Callable[[np.ndarray], np.ndarray]]] = {
    "multisine": lambda seed, duration: multisine(seed),
    "sweep": lambda seed, duration: sweep(duration),
}


def simulate_record(terms: tuple[str, ...], snr_db: float, *, seed: int = 1, duration: float = DURATION,
                    dt: float = DT, excitation: str = "multisine"):
    """A record of the base plant with ``terms`` added, simulated by scipy (not duffid), under
    ``excitation`` (:data:`EXCITATIONS`), with ``snr_db`` displacement noise and 60 dB force
    noise: a :class:`duffid.Record`."""
    from duffid import Record

    plant = Plant({term: TERMS[term][0] for term in terms})
    force = EXCITATIONS[excitation](seed, duration)
    t = np.arange(0.0, duration + dt / 2, dt)

    def rhs(tt: float, y: np.ndarray) -> list[float]:
        x, v = y
        return [v, float((force(np.array(tt)) - plant.force_of_terms(np.array(x), np.array(v))) / BASE["m"])]

    solution = solve_ivp(rhs, (0.0, t[-1]), [0.0, 0.0], t_eval=t, method="DOP853", rtol=1e-9, atol=1e-12,
                         max_step=2 * dt)
    x = solution.y[0]
    f = force(t)
    rng = np.random.default_rng(seed + 100)
    x_noisy = x + rng.normal(0.0, np.std(x) / 10 ** (snr_db / 20), x.shape)
    f_noisy = f + rng.normal(0.0, np.std(f) / 10 ** 3, f.shape)
    return Record(t, f_noisy[:, None], x_noisy[:, None],
                  source=f"{'+'.join(terms) or 'plain'}, {excitation}, {snr_db:g} dB, dt {dt:g} s")


#: A Bouc–Wen hysteretic element (no library term describes it): force ``alpha * z`` with
#: ``z' = v - beta |v| z - gamma v |z|`` (n = 1), z of the order of the displacement.
BOUC_WEN = {"alpha": 3000.0, "beta": 300.0, "gamma": 100.0}


def bouc_wen_record(snr_db: float = 50.0, *, seed: int = 1, duration: float = DURATION, dt: float = DT):
    """A record of the base plant with a Bouc–Wen element added (scipy, not duffid)."""
    from duffid import Record

    force = multisine(seed)
    alpha, beta, gamma = BOUC_WEN["alpha"], BOUC_WEN["beta"], BOUC_WEN["gamma"]
    t = np.arange(0.0, duration + dt / 2, dt)

    def rhs(tt: float, y: np.ndarray) -> list[float]:
        x, v, z = y
        restoring = BASE["b"] * v + BASE["k"] * x + BASE["kp"] * x**3 + alpha * z
        return [v, float((force(np.array(tt)) - restoring) / BASE["m"]), v - beta * abs(v) * z - gamma * v * abs(z)]

    solution = solve_ivp(rhs, (0.0, t[-1]), [0.0, 0.0, 0.0], t_eval=t, method="DOP853", rtol=1e-9, atol=1e-12,
                         max_step=2 * dt)
    x = solution.y[0]
    rng = np.random.default_rng(seed + 100)
    x_noisy = x + rng.normal(0.0, np.std(x) / 10 ** (snr_db / 20), x.shape)
    f = force(t)
    return Record(t, (f + rng.normal(0.0, np.std(f) / 10 ** 3, f.shape))[:, None], x_noisy[:, None],
                  source=f"Bouc-Wen at {snr_db:g} dB")


def silverbox_record():
    """The Silverbox training record (``duffid silverbox``'s), or None without the data."""
    from duffid.analysis.silverbox import default_data_dir, load_silverbox

    if not (default_data_dir() / "SNLS80mV.mat").is_file():
        return None
    return load_silverbox().training


def run_case(record, truth: tuple[str, ...], refine: bool = False) -> dict:
    """One search: found, false, missed, time."""
    from duffid.identification.discover import discover

    started = time.perf_counter()
    found = discover(record, "duffing1", refine=refine, progress=False)
    seconds = time.perf_counter() - started
    added = set(found.best.added)
    return {"truth": truth, "found": tuple(sorted(added)), "false": tuple(sorted(added - set(truth))),
            "missed": tuple(sorted(set(truth) - added)), "seconds": seconds,
            "simulation": found.best.fit.get("simulation_nrmse"), "noise": found.best.fit.get("noise_nrmse")}


def cost(runs: int) -> tuple[list[float], float]:
    """The issue's cost case: the 4-term base, the 9-term :data:`COST_LIBRARY`, 20,000 samples of
    the plant with x^2 added at 50 dB. Returns the warm times (the candidates' C estimators
    already compiled, as on a second search) and one cold time (a fresh process with an empty
    build directory: every C library compiled on the way)."""
    import os
    import subprocess
    import tempfile

    from duffid.identification.discover import discover

    record = simulate_record(("x^2",), 50.0)
    warm = []
    discover(record, "duffing1", library=COST_LIBRARY, progress=False)  # compile once
    for _ in range(runs):
        started = time.perf_counter()
        discover(record, "duffing1", library=COST_LIBRARY, progress=False)
        warm.append(time.perf_counter() - started)
    with tempfile.TemporaryDirectory() as build:
        path = Path(build) / "record.csv"
        record.to_csv(path)
        env = dict(os.environ, DUFFID_BUILD_DIR=build)
        started = time.perf_counter()
        subprocess.run([sys.executable, "-m", "duffid", "discover", str(path), "--library", "; ".join(COST_LIBRARY)],
                       check=True, env=env, capture_output=True)
        cold = time.perf_counter() - started
    return warm, cold


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", default=",".join(CASES), help="comma-separated case names")
    parser.add_argument("--snr", default="40,50,60", help="displacement SNRs [dB]")
    parser.add_argument("--quick", action="store_true", help="50 dB only")
    parser.add_argument("--refine", action="store_true", help="discover with the output-error refinement")
    parser.add_argument("--cost-runs", type=int, default=5, help="warm runs of the cost case (0: skip it)")
    args = parser.parse_args()
    sys.path.insert(0, str(ROOT / "src"))
    names = [n.strip() for n in args.cases.split(",") if n.strip()]
    unknown = [n for n in names if n not in CASES]
    if unknown:
        raise SystemExit(f"unknown case(s) {unknown}; known: {', '.join(CASES)}")
    snrs = [50.0] if args.quick else [float(s) for s in args.snr.split(",")]
    print(f"{'case':<24} {'SNR':>4}  {'found':<26} {'false':<14} {'missed':<14} {'sim/noise':>10} {'time [s]':>8}")
    totals = {"false": 0, "missed": 0, "runs": 0}
    for name in names:
        for snr in snrs:
            row = run_case(simulate_record(CASES[name], snr), CASES[name], args.refine)
            totals["false"] += len(row["false"])
            totals["missed"] += len(row["missed"])
            totals["runs"] += 1
            ratio = row["simulation"] / row["noise"] if row["simulation"] is not None else math.nan
            print(f"{name:<24} {snr:>4g}  {', '.join(row['found']) or '-':<26} {', '.join(row['false']) or '-':<14} "
                  f"{', '.join(row['missed']) or '-':<14} {ratio:>10.3g} {row['seconds']:>8.1f}", flush=True)
    for excitation, dt in (("sweep", DT), ("multisine", 5e-3), ("sweep", 5e-3)):
        for name in ("plain", "+ x^2", "+ sign(der(x))"):
            row = run_case(simulate_record(CASES[name], 50.0, excitation=excitation, dt=dt), CASES[name], args.refine)
            totals["false"] += len(row["false"])
            totals["missed"] += len(row["missed"])
            totals["runs"] += 1
            label = f"{name}, {excitation}, {1 / dt:g} Hz"
            print(f"{label:<36} {', '.join(row['found']) or '-':<26} {', '.join(row['false']) or '-':<14} "
                  f"{', '.join(row['missed']) or '-':<14} {row['simulation'] / row['noise']:>10.3g} "
                  f"{row['seconds']:>8.1f}", flush=True)
    print(f"{totals['runs']} searches: {totals['false']} false terms, {totals['missed']} missed terms")
    record = bouc_wen_record()
    started = time.perf_counter()
    from duffid.identification.discover import discover

    found = discover(record, "duffing1", refine=args.refine, progress=False)
    print(f"Bouc-Wen hysteresis (in no library term), 50 dB: found {', '.join(found.best.added) or '-'} in "
          f"{time.perf_counter() - started:.1f} s; residual: {found.residual['shape'] if found.residual else 'none'}")
    record = silverbox_record()
    if record is not None:
        row = run_case(record, ("1", "x^2"), args.refine)
        print(f"Silverbox training record ({record.n_samples} samples): found {', '.join(row['found']) or '-'}; "
              f"simulation NRMSE {100 * row['simulation']:.3g} % (noise estimate {100 * row['noise']:.2g} %); "
              f"{row['seconds']:.1f} s")
    if args.cost_runs > 0:
        warm, cold = cost(args.cost_runs)
        print(f"cost: 4-term base, 9-term library, 20,000 samples: warm median {np.median(warm):.2f} s "
              f"(min {min(warm):.2f}, max {max(warm):.2f}, {len(warm)} runs); cold (fresh process, every C "
              f"library compiled) {cold:.1f} s; target < 10 s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
