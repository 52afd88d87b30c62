"""Hilbert-transform nonlinearity index vs excitation amplitude (paper Figures 6 and 11).

Run: python benchmarks/nonlinearity.py [--out DIR] [--amplitudes 13]

For each plant the paper's sweep f = A sin(pi rate t^2) (instantaneous frequency
rate*t Hz, rate 2.5 Hz/s) and a 10x slower one (0.25 Hz/s) are simulated from rest,
followed by a ring-down. The table shows eta with the band-edge correction and without
it, the Hilbert distortion in dB, and the verdict (eta >= 0.9: dominantly linear). The
band comes from the input's energy at the first amplitude and is kept for all
amplitudes. Plots of eta vs amplitude are written to DIR.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from duffid import Duffing1, Duffing2
from duffid.analysis.nonlinearity import LINEARITY_THRESHOLD, amplitude_sweep
from duffid.apps.plots import plot_eta_vs_amplitude

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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("out"))
    parser.add_argument("--amplitudes", type=int, default=13, help="amplitudes per case (default 13)")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    for name, (plant, f_max, (a_min, a_max)) in CASES.items():
        amplitudes = np.linspace(a_min, a_max, args.amplitudes)
        series = {}
        print(f"\n{name}: sweep 0-{f_max:g} Hz, then a ring-down of 12 time constants, dt 2 ms")
        print(f"{'amplitude [N]':>14}" + "".join(f" | {label:^44}" for label in RATES))
        print(f"{'':>14}" + "".join(f" | {'eta':>9} {'uncorr.':>9} {'D [dB]':>7} {'verdict':>16}" for _ in RATES))
        for label, rate in RATES.items():
            start = time.perf_counter()
            series[label] = amplitude_sweep(amplitudes, plant, rate=rate, f_max=f_max,
                                            progress=True)
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
        plot = args.out / f"eta_vs_amplitude_{name.split(' (')[0].replace(' ', '_').replace('-', '')}.png"
        plot_eta_vs_amplitude({label: series[label] for label in RATES}, plot, title=name)
        print(f"  plot: {plot}")


if __name__ == "__main__":
    main()
