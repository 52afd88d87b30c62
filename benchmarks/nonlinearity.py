"""Nonlinearity verdicts: a detection study, and the Hilbert index vs amplitude (paper Figures 6 and 11).

Run: python benchmarks/nonlinearity.py [--quick] [--seeds N] [--out DIR] [--amplitude-table]

Detection study (the table that sets the thresholds of duffid.analysis.verdict and
duffid.analysis.frf). Plants: the paper's 1-DOF oscillator without its cubic spring
(linear), and with a hardening or softening cubic spring whose share ``kp x^2 / k`` at
the peak of the linear response to each excitation is 3 % (weak), 10 % (moderate) or
25 % (strong); the true share is
measured on each exact record. Excitations at 1 N peak (and at 1/3 N for the
homogeneity test): a sweep 0-10 Hz at 1 Hz/s followed by a ring-down (ratio of
transforms), a random-phase multisine 0.5-10 Hz of 64 s without ring-down (averaged H1,
a stationary random force), stepped sines at 12 frequencies 1-8 Hz, 5 s each. White noise
at 60, 40 and 30 dB SNR is added to both the displacement and the force, with ``--seeds``
noise draws per case. A verdict is wrong when it calls the linear plant "nonlinear", or a
plant whose share is at least SHARE_LINEAR (10 %) "dominantly linear"; a weak plant may be
called either. ``--quick`` runs the strong and linear plants at 40 dB with one seed.

``--amplitude-table`` adds the earlier study: eta vs amplitude for the paper's sweep and
a 10x slower one on the paper's 1-DOF and 2-DOF plants.
"""
from __future__ import annotations

import argparse
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from duffid import Duffing1, Duffing2, simulate
from duffid.analysis.frf import (
    LEAKAGE_MAX,
    SETTLING_MAX,
    STATIONARITY_MAX,
    frf_from_stepped_sines,
)
from duffid.analysis.nonlinearity import (
    LINEARITY_THRESHOLD,
    amplitude_sweep,
    analyse,
    sweep_record,
)
from duffid.analysis.verdict import SHARE_LINEAR, decide_group, thresholds
from duffid.apps.plots import plot_eta_vs_amplitude
from duffid.data.record import Record
from duffid.data.signals import Multisine
from duffid.errors import SimulationError

DT = 2e-3
AMPLITUDE = 1.0
LOW = 1.0 / 3.0
PLANTS = {"linear": 0.0, "weak hardening": 0.03, "moderate hardening": 0.1, "strong hardening": 0.25,
          "weak softening": -0.03, "moderate softening": -0.1, "strong softening": -0.25}
EXCITATIONS = ("sweep + ring-down", "random", "stepped sine")
SNRS = (60.0, 40.0, 30.0)
STEPPED = np.linspace(1.0, 8.0, 12)
RANDOM_SECONDS = 64.0


@dataclass
class Case:
    """The exact records of one plant and excitation at one amplitude."""

    records: list[Record]
    share: float          # true kp x_peak^2 / k (signed)


def excite(plant: Duffing1, excitation: str, amplitude: float) -> list[Record]:
    """The exact record(s) of one excitation."""
    if excitation == "sweep + ring-down":
        return [sweep_record(plant, amplitude, rate=1.0, f_max=10.0, dt=DT)]
    if excitation == "random":
        force = Multisine(amplitude, 0.5, 10.0, RANDOM_SECONDS, phases="random", seed=3)
        return [simulate(plant, force, RANDOM_SECONDS, DT, rtol=1e-8, atol=1e-12)]
    return [simulate(plant, lambda t, f0=f0: amplitude * np.sin(2 * np.pi * f0 * t), 5.0, DT,
                     rtol=1e-8, atol=1e-12) for f0 in STEPPED]


def noisy(record: Record, snr_db: float, rng: np.random.Generator) -> Record:
    """White noise at ``snr_db`` (on each column's mean square) on displacement and force."""
    def add(a: np.ndarray) -> np.ndarray:
        sigma = np.sqrt(np.mean(a**2, axis=0) / 10.0 ** (snr_db / 10.0))
        return a + rng.standard_normal(a.shape) * sigma
    return Record(t=record.t, f=add(record.f), x=add(record.x), source=record.source)


def analyse_case(records: list[Record]):
    """The verdict of one (noisy) case: a record, or the stepped sines together."""
    if len(records) > 1:
        return analyse(frf_from_stepped_sines(records))
    return analyse(records[0])


def plants(excitation: str) -> dict[str, Duffing1]:
    """The study's plants for one excitation: kp set from the linear plant's peak under it at 1 N."""
    base = Duffing1(kp=0.0)
    peak = max(float(np.max(np.abs(r.x))) for r in excite(base, excitation, AMPLITUDE))
    p = base.parameters
    return {name: Duffing1(m=p["m"], b=p["b"], k=p["k"], kp=s * p["k"] / peak**2) for name, s in PLANTS.items()}


def detection(quick: bool, seeds: int) -> None:
    """Print the detection table."""
    names = ["linear", "strong hardening", "strong softening"] if quick else list(PLANTS)
    snrs = (40.0,) if quick else SNRS
    seeds = 1 if quick else seeds
    amplitudes = (AMPLITUDE,) if quick else (AMPLITUDE, LOW)
    models = {excitation: plants(excitation) for excitation in EXCITATIONS}
    cases: dict[tuple[str, str, float], Case | None] = {}
    for name in tqdm(names, desc="simulating plants"):
        for excitation in EXCITATIONS:
            plant = models[excitation][name]
            for a in amplitudes:
                try:
                    recs = excite(plant, excitation, a)
                except SimulationError:
                    cases[name, excitation, a] = None
                    continue
                peak = max(float(np.max(np.abs(r.x))) for r in recs)
                cases[name, excitation, a] = Case(recs, plant.parameters["kp"] * peak**2 / plant.parameters["k"])
    print("\nDetection study: 1-DOF plant (m 2.53 kg, b 12.47 N s/m, k 1272.1 N/m), force 1 N"
          + ("" if quick else " (and 1/3 N for the group verdict)") + f", {seeds} noise draw(s) per case")
    print(f"{'plant':<19} {'share':>7} {'excitation':<18} {'SNR':>4} {'estimator':>9} {'eta':>8} {'D [dB]':>7} "
          f"{'floor':>6}  {'verdict (1 N)':<18} {'group (1 N + 1/3 N)':<18}")
    tally: dict[tuple[str, float], dict[str, int]] = {}
    smallest: dict[tuple[str, float], float] = {}
    for excitation in EXCITATIONS:
        for snr in snrs:
            t = tally.setdefault((excitation, snr), {"runs": 0, "wrong": 0, "cannot": 0, "group_wrong": 0,
                                                      "group_cannot": 0, "groups": 0})
            for name in names:
                case = cases[name, excitation, AMPLITUDE]
                if case is None:
                    print(f"{name:<19} {'':>7} {excitation:<18} {snr:>4.0f} left its potential well")
                    continue
                for seed in range(seeds):
                    rng = np.random.default_rng(1000 * seed + int(snr))
                    high = analyse_case([noisy(r, snr, rng) for r in case.records])
                    group = "-"
                    truth = "linear" if PLANTS[name] == 0 else ("nonlinear" if abs(case.share) >= SHARE_LINEAR else "weak")
                    t["runs"] += 1
                    t["wrong"] += _wrong(truth, high.verdict)
                    t["cannot"] += high.verdict == "cannot tell"
                    if high.verdict == "nonlinear" and truth != "linear":
                        key = (excitation, snr)
                        smallest[key] = min(smallest.get(key, np.inf), abs(case.share))
                    low_case = cases.get((name, excitation, LOW))
                    if len(amplitudes) > 1 and low_case is not None:
                        low = analyse_case([noisy(r, snr, rng) for r in low_case.records])
                        g = decide_group([high.decision, low.decision], [high.frf, low.frf])
                        group = g.verdict
                        t["groups"] += 1
                        t["group_wrong"] += _wrong(truth, g.verdict)
                        t["group_cannot"] += g.verdict == "cannot tell"
                    print(f"{name:<19} {100 * case.share:>6.1f}% {excitation:<18} {snr:>4.0f} {high.estimator:>9} "
                          f"{high.eta:>8.5f} {high.distortion_db:>7.1f} {high.distortion_floor_db:>6.0f}  "
                          f"{high.verdict:<18} {group:<18}" + ("  WRONG" if _wrong(truth, high.verdict) else ""))
    print("\nSummary (wrong: a confident verdict contradicting the truth; target 0)")
    print(f"{'excitation':<18} {'SNR':>4} {'runs':>5} {'wrong':>6} {'cannot tell':>12} {'smallest share detected':>24}"
          f" {'group wrong':>12} {'group cannot tell':>18}")
    for (excitation, snr), t in tally.items():
        s = smallest.get((excitation, snr))
        print(f"{excitation:<18} {snr:>4.0f} {t['runs']:>5} {t['wrong']:>6} {t['cannot']:>12} "
              f"{(f'{100 * s:.1f} %' if s is not None else 'none'):>24} "
              f"{(str(t['group_wrong']) if t['groups'] else '-'):>12} {(str(t['group_cannot']) if t['groups'] else '-'):>18}")
    print("\nThresholds (duffid.analysis.verdict and duffid.analysis.frf, set by this study):")
    for k, v in {**thresholds(), "LEAKAGE_MAX": LEAKAGE_MAX, "STATIONARITY_MAX": STATIONARITY_MAX,
                 "SETTLING_MAX": SETTLING_MAX}.items():
        print(f"  {k} = {v:g}")


def _wrong(truth: str, verdict: str) -> int:
    return int((truth == "linear" and verdict == "nonlinear") or (truth == "nonlinear" and verdict == "dominantly linear"))


# ---------------------------------------------------------------------- eta vs amplitude (earlier study)
CASES = {
    # name: (plant, f_max [Hz], amplitude range [N])
    "linear 1-DOF (kp = 0)": (Duffing1(kp=0.0), 10.0, (0.1, 6.0)),
    "Duffing 1-DOF (paper Table 1)": (Duffing1(), 10.0, (0.1, 6.0)),
    "Duffing 2-DOF (paper Table 3)": (Duffing2(), 12.0, (0.1, 6.15)),
}
RATES = {"paper sweep 2.5 Hz/s": 2.5, "10x slower 0.25 Hz/s": 0.25}


def crossing(amplitudes: np.ndarray, etas: np.ndarray) -> str:
    """Where eta first falls below the threshold, by linear interpolation."""
    below = np.flatnonzero(~(etas >= LINEARITY_THRESHOLD))
    if not len(below):
        return f"stays above {LINEARITY_THRESHOLD} up to {amplitudes[-1]:g} N"
    i = below[0]
    if i == 0 or not np.isfinite(etas[i]):
        return f"below {LINEARITY_THRESHOLD} (or undetermined) from {amplitudes[i]:g} N"
    a0, a1, e0, e1 = amplitudes[i - 1], amplitudes[i], etas[i - 1], etas[i]
    return f"crosses {LINEARITY_THRESHOLD} near {a0 + (e0 - LINEARITY_THRESHOLD) / (e0 - e1) * (a1 - a0):.2f} N"


def amplitude_table(out: Path, n_amplitudes: int) -> None:
    """eta vs amplitude for two sweep rates (paper Figures 6 and 11), with plots in ``out``."""
    for name, (plant, f_max, (a_min, a_max)) in CASES.items():
        amplitudes = np.linspace(a_min, a_max, n_amplitudes)
        series = {}
        print(f"\n{name}: sweep 0-{f_max:g} Hz, then a ring-down of 12 time constants, dt 2 ms")
        print(f"{'amplitude [N]':>14}" + "".join(f" | {label:^44}" for label in RATES))
        print(f"{'':>14}" + "".join(f" | {'eta':>9} {'uncorr.':>9} {'D [dB]':>7} {'verdict':>16}" for _ in RATES))
        for label, rate in RATES.items():
            start = time.perf_counter()
            series[label] = amplitude_sweep(amplitudes, plant, rate=rate, f_max=f_max, progress=True)
            series[label + "_seconds"] = time.perf_counter() - start
        for k, a in enumerate(amplitudes):
            row = f"{a:>14.3f}"
            for label in RATES:
                r = series[label][k]
                row += (f" | {r.eta:>9.5f} {r.eta_uncorrected:>9.5f} {r.distortion_db:>7.1f} {r.verdict:>16}"
                        if np.isfinite(r.eta) else f" | {'escaped its potential well':>44}")
            print(row)
        for label in RATES:
            etas = np.array([r.eta for r in series[label]])
            print(f"  {label}: band {series[label][0].band[0]:.3g}-{series[label][0].band[1]:.3g} Hz, "
                  f"{crossing(amplitudes, etas)}; {series[label + '_seconds']:.1f} s")
        plot = out / f"eta_vs_amplitude_{name.split(' (')[0].replace(' ', '_').replace('-', '')}.png"
        plot_eta_vs_amplitude({label: series[label] for label in RATES}, plot, title=name)
        print(f"  plot: {plot}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("out"))
    parser.add_argument("--quick", action="store_true", help="strong and linear plants, 40 dB, one seed (< 2 min)")
    parser.add_argument("--seeds", type=int, default=3, help="noise draws per case (default 3)")
    parser.add_argument("--amplitude-table", action="store_true", help="also eta vs amplitude (slow)")
    parser.add_argument("--amplitudes", type=int, default=13, help="amplitudes per case of that table (default 13)")
    args = parser.parse_args()
    start = time.perf_counter()
    detection(args.quick, args.seeds)
    if args.amplitude_table:
        args.out.mkdir(parents=True, exist_ok=True)
        amplitude_table(args.out, args.amplitudes)
    print(f"\n{time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
