"""A battery of realistic records: is every published value right, and is what is right published?

Run: python benchmarks/trust.py [--only NAME] [--repeats 3]

Plants at four scales (a MEMS resonator, laboratory oscillators, a machine, a civil
structure), hardening and softening springs, light and heavy damping, the Duffing circuit
and the 2-DOF chain; random (random-phase multisine), swept-sine, hammer, step (with rest
before it) and free-decay excitation; 60, 40 and 30 dB of displacement noise; sampling from
200 Hz to 50 kHz; force and displacement offsets, swapped columns, an isolated spike and a
plant with unmodelled Coulomb friction. Every record is identified with ``duffid.identify``
and the model *class* with its default values (``Duffing1()``, ...): nothing may depend on them.

Table 1: per record, the error of every published value (others: their status), the fit
(simulation NRMSE against the noise), the upsampling factor and the time.
Table 3: the online estimator alone, as the estimator FMUs run it (default options, the
record fed sample by sample through the C core): status and error of each value published at
the end, the largest error of any value it published during the run, outliers excluded.
Table 2 (summary): false trust (published values more than 5 % off: must be 0); coverage on
the well-excited records (every parameter published within 1 %); calibration (share of
published values within 3 stated standard errors); the online estimator's false trust (at
the end, and at any sample of the run); samples/s of the estimator (C and Python)
and of the checked identify (medians of ``--repeats`` runs, ratio to Python in the same run).
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np
from tqdm import tqdm

from duffid import (
    Chain,
    Chirp,
    Duffing1,
    Duffing2,
    DuffingCircuit,
    Multisine,
    Record,
    Step,
    identify,
    measure,
    simulate,
)
from duffid.identification.trust import run_estimator


def hammer(amplitude: float, width: float, t0: float = 0.05) -> Callable[[np.ndarray], np.ndarray]:
    """A half-sine impact of ``width`` seconds at ``t0``."""
    def force(t):
        t = np.asarray(t, dtype=float)
        inside = (t >= t0) & (t < t0 + width)
        return np.where(inside, amplitude * np.sin(np.pi * (t - t0) / width), 0.0)
    return force


def zero(t):
    return 0.0 * np.asarray(t, dtype=float)


def duffing(m: float, f_n: float, zeta: float, nonlinearity: float, amplitude: float) -> Duffing1:
    """A 1-DOF plant: natural frequency ``f_n`` Hz, damping ratio ``zeta``, cubic spring
    changing the stiffness by ``nonlinearity`` (signed) at displacement ``amplitude``."""
    k = m * (2 * math.pi * f_n) ** 2
    return Duffing1(m=m, b=2 * zeta * math.sqrt(k * m), k=k, kp=nonlinearity * k / amplitude**2)


PLANTS: dict[str, tuple[Any, float, float]] = {
    # name: (plant, natural frequency [Hz], displacement scale [m])
    "mems": (duffing(1e-9, 2000.0, 0.01, 0.3, 1e-6), 2000.0, 1e-6),
    "lab softening": (Duffing1(), 3.57, 8e-3),
    "lab hardening": (duffing(1.0, 10.0, 0.016, 0.3, 1e-2), 10.0, 1e-2),
    "heavy damping": (duffing(1.0, 10.0, 0.45, 0.3, 1e-2), 10.0, 1e-2),
    "machine": (duffing(20.0, 30.0, 0.03, 0.2, 1e-3), 30.0, 1e-3),
    "structure": (duffing(450.0, 11.1, 0.02, 0.2, 5e-3), 11.1, 5e-3),
    "circuit": (DuffingCircuit(), 15.9, 5e-3),
    "2-DOF chain": (Duffing2(), 6.2, 5e-3),
}
CLASSES = {Duffing1: Duffing1(), DuffingCircuit: DuffingCircuit(), Duffing2: Duffing2()}


@dataclass
class Case:
    name: str
    plant: str
    excitation: str            # random, sweep, hammer, step, decay, random+step
    fs: float
    snr_db: float | None
    duration: float
    well_excited: bool = False
    modify: str = ""           # f-offset, x-offset, swapped, spike
    friction: float = 0.0
    options: dict[str, Any] = field(default_factory=dict)


CASES = [
    Case("mems random 40 dB 50 kHz", "mems", "random", 50e3, 40, 0.2, True),
    Case("mems sweep 60 dB 50 kHz", "mems", "sweep", 50e3, 60, 0.2, True),
    Case("lab softening step 40 dB", "lab softening", "step", 1e3, 40, 2.2),
    Case("lab softening step 30 dB", "lab softening", "step", 1e3, 30, 2.2),
    Case("lab softening random 40 dB", "lab softening", "random", 1e3, 40, 8.0),
    Case("lab softening random 30 dB", "lab softening", "random", 1e3, 30, 8.0),
    Case("lab softening sweep 60 dB", "lab softening", "sweep", 1e3, 60, 8.0, True),
    Case("lab softening hammer 40 dB", "lab softening", "hammer", 1e3, 40, 4.0),
    Case("lab hardening random 40 dB", "lab hardening", "random", 2e3, 40, 8.0, True),
    Case("lab hardening sweep 40 dB", "lab hardening", "sweep", 2e3, 40, 8.0, True),
    Case("lab hardening random 40 dB 200 Hz", "lab hardening", "random", 200.0, 40, 8.0, True),
    Case("lab hardening hammer 60 dB", "lab hardening", "hammer", 2e3, 60, 4.0),
    Case("lab hardening free decay 40 dB", "lab hardening", "decay", 2e3, 40, 4.0),
    Case("heavy damping random 40 dB", "heavy damping", "random", 2e3, 40, 8.0, True),
    Case("heavy damping step 40 dB", "heavy damping", "step", 2e3, 40, 2.0),
    Case("machine random 60 dB 5 kHz", "machine", "random", 5e3, 60, 4.0, True),
    Case("machine hammer 40 dB 5 kHz", "machine", "hammer", 5e3, 40, 2.0),
    Case("structure random+step 40 dB 200 Hz", "structure", "random+step", 200.0, 40, 8.0, True),
    Case("structure sweep 30 dB 500 Hz", "structure", "sweep", 500.0, 30, 8.0),
    Case("circuit random 50 dB", "circuit", "random", 2e3, 50, 4.0, True),
    Case("circuit sweep 40 dB", "circuit", "sweep", 2e3, 40, 4.0, True),
    Case("2-DOF step 60 dB", "2-DOF chain", "step", 1e3, 60, 2.2),
    Case("2-DOF random 40 dB", "2-DOF chain", "random", 1e3, 40, 8.0),
    Case("lab softening random, force offset 0.5 N", "lab softening", "random", 1e3, 40, 8.0, modify="f-offset"),
    Case("lab softening random, x offset 0.25 mm", "lab softening", "random", 1e3, 40, 8.0, modify="x-offset"),
    Case("lab hardening step, x offset 0.25 mm", "lab hardening", "step", 2e3, 40, 2.2, modify="x-offset"),
    Case("lab softening random, columns swapped", "lab softening", "random", 1e3, 40, 8.0, modify="swapped"),
    Case("lab softening random, one spike", "lab softening", "random", 1e3, 40, 8.0, modify="spike"),
    Case("lab hardening random, Coulomb friction", "lab hardening", "random", 2e3, 50, 8.0, friction=0.5),
]


def excitation(case: Case, plant: Any, f_n: float, scale: float) -> Any:
    """A force that drives the plant to about ``scale``."""
    k = plant.canonical_parameters()["k1_1"]
    if isinstance(plant, Duffing2):
        k = 1e3
    level = k * scale
    if case.excitation == "random":
        return Multisine(1.5 * level, 0.2 * f_n, 2.5 * f_n, case.duration / 2, phases="random", seed=7)
    if case.excitation == "random+step":
        return Step(0.5 * level, 0.5) + Multisine(level, 0.2 * f_n, 2.5 * f_n, case.duration / 2,
                                                   phases="random", seed=7)
    if case.excitation == "sweep":
        return Chirp(0.6 * level, 0.3 * f_n, 2.5 * f_n, case.duration)
    if case.excitation == "hammer":
        return hammer(3 * level, 0.2 / f_n)
    if case.excitation == "step":
        return Step(0.8 * level, 0.2)
    return zero


def make_record(case: Case) -> tuple[Record, Any, dict[str, float]]:
    plant, f_n, scale = PLANTS[case.plant]
    truth = dict(plant.parameters)
    sim_plant = plant
    if case.friction:
        canonical = plant.canonical_parameters()
        sim_plant = Chain(masses=(canonical["m1"],), damping=(canonical["b1"],),
                          stiffness=({1: canonical["k1_1"], 3: canonical["k1_3"]},),
                          coulomb=(case.friction * canonical["k1_1"] * scale,))
    x0 = [0.8 * scale] + [0.0] * (plant.n_dof - 1) if case.excitation == "decay" else None
    record = simulate(sim_plant, excitation(case, plant, f_n, scale), case.duration, 1.0 / case.fs, x0=x0)
    record = measure(record, pulses_per_cm=None, snr_db=case.snr_db, seed=11)
    t, f, x = record.t, record.f.copy(), record.x.copy()
    if case.modify == "f-offset":
        f += 0.05 * np.max(np.abs(f))
    elif case.modify == "x-offset":
        x += 0.03 * np.max(np.abs(x))
    elif case.modify == "swapped":
        f, x = x, f
    elif case.modify == "spike":
        x[len(x) // 2, 0] += 20 * np.max(np.abs(x))
    return Record(t, f, x, source=case.name), plant, truth


def run_case(case: Case) -> dict[str, Any]:
    record, plant, truth = make_record(case)
    model = CLASSES[type(plant)]
    start = time.perf_counter()
    result = identify(record, model, **case.options)
    seconds = time.perf_counter() - start
    a = result.assessment
    rows = {}
    for name, value in truth.items():
        published = a.status[name] == "published"
        error = (result.parameters[name] - value) / value if published else math.nan
        rows[name] = {"status": a.status[name], "error": error, "uncertainty": a.uncertainty[name]}
    return {"case": case, "rows": rows, "fit": a.fit, "notes": a.notes, "seconds": seconds,
            "samples": record.n_samples, "online": run_online(record, model, truth)}


def run_online(record: Record, model: Any, truth: dict[str, float]) -> dict[str, Any]:
    """The online estimator over the record (the FMUs' run): final status and error of each
    parameter, the worst error of any value published during the run, outliers excluded."""
    result = run_estimator(record, model)
    rows = {}
    for name, value in truth.items():
        history = result.history[name]
        published = np.isfinite(history)
        worst = float(np.max(np.abs(history[published] - value)) / abs(value)) if published.any() else math.nan
        final = float(history[-1])
        rows[name] = {"status": result.status[name], "worst": worst,
                      "error": (final - value) / value if np.isfinite(final) else math.nan}
    return {"rows": rows, "outliers": len(result.outliers)}


def _cell(row: dict[str, Any]) -> str:
    if row["status"] != "published":
        return {"not excited": "not exc.", "uncertain": "uncert.", "lost": "lost", "changed": "changed"}[row["status"]]
    return f"{100 * row['error']:+.2f}%"


def print_cases(results: list[dict[str, Any]]) -> None:
    print("1. Per record: error of each published value (else its status), fit, time")
    print(f"{'record':<44} {'values (published error or status)':<62} {'sim/noise NRMSE':>16} {'up':>3} {'s':>5}")
    for r in results:
        cells = " ".join(f"{k}:{_cell(v)}" for k, v in r["rows"].items())
        fit = r["fit"]
        sim, noise = fit.get("simulation_nrmse", math.nan), fit.get("noise_nrmse", math.nan)
        nrmse = f"{100 * sim:.2g}/{100 * noise:.2g} %" if sim is not None and np.isfinite(sim) else "-"
        print(f"{r['case'].name:<44} {cells:<62} {nrmse:>16} {fit.get('upsampled', 1):>3} {r['seconds']:>5.1f}")


def print_online(results: list[dict[str, Any]]) -> None:
    print("\n3. Online estimator (the FMUs' run, default options): final error or status; worst published error")
    print(f"{'record':<44} {'values at the end':<62} {'worst during run':>18} {'outl.':>5}")
    for r in results:
        rows = r["online"]["rows"]
        cells = " ".join(f"{k}:{_cell(v)}" for k, v in rows.items())
        worst = max((v["worst"] for v in rows.values() if np.isfinite(v["worst"])), default=math.nan)
        shown = f"{100 * worst:.2f} %" if np.isfinite(worst) else "-"
        print(f"{r['case'].name:<44} {cells:<62} {shown:>18} {r['online']['outliers']:>5}")


def throughput(repeats: int) -> list[tuple[str, float]]:
    plant = Duffing1()
    record = measure(simulate(plant, Multisine(8.0, 0.5, 10.0, 5.0, phases="random", seed=1), 10.0, 1e-3),
                     pulses_per_cm=None, snr_db=40, seed=2)
    out = []
    for label, call in [("estimator, Python", lambda: run_estimator(record, plant, engine="python")),
                        ("estimator, C (one batch call)", lambda: run_estimator(record, plant, engine="c")),
                        ("identify() checked (C)", lambda: identify(record, plant))]:
        times = []
        for _ in range(repeats):
            start = time.perf_counter()
            call()
            times.append(time.perf_counter() - start)
        out.append((label, record.n_samples / float(np.median(times))))
    return out


def print_summary(results: list[dict[str, Any]], speeds: list[tuple[str, float]]) -> None:
    published = [(r, k, v) for r in results for k, v in r["rows"].items() if v["status"] == "published"]
    false = [(r["case"].name, k, v["error"]) for r, k, v in published if abs(v["error"]) > 0.05]
    well = [r for r in results if r["case"].well_excited]
    covered = [r for r in well if all(v["status"] == "published" and abs(v["error"]) <= 0.01
                                      for v in r["rows"].values())]
    within = [abs(v["error"]) <= 3 * v["uncertainty"] for _, _, v in published]
    print("\n2. Summary")
    print(f"  records: {len(results)}; published values: {len(published)} of "
          f"{sum(len(r['rows']) for r in results)}")
    print(f"  false trust (published values more than 5 % off): {len(false)}"
          + ("".join(f"\n    {name}: {k} {100 * e:+.2f} %" for name, k, e in false)))
    print(f"  coverage on the {len(well)} well-excited records (every parameter published within 1 %): "
          f"{len(covered)} of {len(well)}")
    for r in well:
        if r not in covered:
            print(f"    not covered: {r['case'].name}: " + ", ".join(f"{k} {_cell(v)}" for k, v in r["rows"].items()))
    if within:
        print(f"  calibration: {100 * np.mean(within):.0f} % of published values within 3 stated standard errors "
              f"(target >= 90 %)")
    online = [(r["case"].name, k, v) for r in results for k, v in r["online"]["rows"].items()]
    at_end = [(name, k, v["error"]) for name, k, v in online if v["status"] == "published" and abs(v["error"]) > 0.05]
    during = [(name, k, v["worst"]) for name, k, v in online if np.isfinite(v["worst"]) and v["worst"] > 0.05]
    print(f"  online estimator: {sum(v['status'] == 'published' for _, _, v in online)} values published at the end, "
          f"{len(at_end)} of them more than 5 % off; {len(during)} parameters published more than 5 % off at "
          f"some sample of the run")
    for name, k, e in at_end:
        print(f"    at the end: {name}: {k} {100 * e:+.2f} %")
    base = speeds[0][1]
    for label, rate in speeds:
        print(f"  {label:<34} {rate:>12,.0f} samples/s  (x{rate / base:.1f} of Python)")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", default=None, help="run the records whose name contains this text")
    parser.add_argument("--repeats", type=int, default=3, help="runs per throughput figure (median)")
    args = parser.parse_args(argv)
    cases = [c for c in CASES if args.only is None or args.only in c.name]
    if not cases:
        parser.error(f"--only {args.only!r} matches no record")
    results = [run_case(c) for c in tqdm(cases, desc="records", file=sys.stderr)]
    print_cases(results)
    print_online(results)
    print_summary(results, throughput(args.repeats))
    return 0


if __name__ == "__main__":
    sys.exit(main())
