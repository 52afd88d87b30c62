"""Online identification from an accelerometer (OnlineMotionIdentifier): accuracy, honesty,
a plant that changes, and the cost per second of data.

The plant: hardening, 10 Hz (2 kg, kp x^2 / k = 0.5 at 1 cm), band-limited random force
(1-30 Hz), simulated by SciPy's DOP853 (not duffid's simulator); the acceleration at 5 kHz
with a bias of 1 % of its RMS and white noise at ``--snr`` dB, the force at 60 dB; 8 s. Per
change type and SNR, over ``--seeds`` noise/force seeds (median / worst):

- ``published from``: the first published value [s];
- ``share``: the share of samples at which k was published;
- ``worst error``: the largest distance of any published value from the truth at its sample
  [%] (right after a step: the old plant's values until the check withdraws them);
- ``worst z``: ... in stated standard errors; ``beyond 3 SE``: the share of published
  parameter-samples further than 3 stated errors from the truth [%];
- ``withdrawn after`` / ``re-published after``: from the change (a drift: its start) to k's
  first ``changed`` status, and from there to its next published value [s];
- ``after``: the largest error of any value published from 1 s after the change (a drift: its
  end) on [%];
- ``s per s``: wall-clock seconds per second of data (load-dependent; median over the runs).

Changes: ``k +25 %`` and ``k +2 %`` and ``m +20 %`` (a payload) steps at 4 s, ``k drift
+20 %`` linear from 2 to 6 s.

Usage: ``python benchmarks/motion_online.py [--seeds N] [--snr 50 40] [--changes 'k drift +20 %' ...]``.
"""
from __future__ import annotations

import argparse
import math
import time

import numpy as np
from scipy.integrate import solve_ivp
from scipy.interpolate import CubicSpline
from tqdm import tqdm

from duffid import Duffing1, Multisine, OnlineMotionIdentifier
from duffid.identification.engine import STATUSES

DT, T_END, T_CHANGE = 2e-4, 8.0, 4.0
DRIFT = (2.0, 6.0)
M, FN, ZETA = 2.0, 10.0, 0.02
K = M * (2 * np.pi * FN) ** 2
B = 2 * ZETA * np.sqrt(K * M)
AMPLITUDE = 0.01
KP = 0.5 * K / AMPLITUDE**2
NAMES = ("m", "b", "k", "kp")
CHANGED = STATUSES[4]
CHANGES = ("constant", "k +25 %", "k +2 %", "m +20 %", "k drift +20 %")


def stiffness_of(change: str):
    """k(t) and m(t) of a change type."""
    def k(t: float) -> float:
        if change == "k +25 %":
            return K * (1.25 if t >= T_CHANGE else 1.0)
        if change == "k +2 %":
            return K * (1.02 if t >= T_CHANGE else 1.0)
        if change == "k drift +20 %":
            return K * (1 + 0.2 * min(max((t - DRIFT[0]) / (DRIFT[1] - DRIFT[0]), 0.0), 1.0))
        return K

    def m(t: float) -> float:
        return M * (1.2 if change == "m +20 %" and t >= T_CHANGE else 1.0)
    return k, m


def record(change: str, seed: int, snr: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """t, measured force and acceleration, and the truth of every parameter at every sample."""
    t = np.arange(0.0, T_END + DT / 2, DT)
    f = Multisine(0.8 * K * AMPLITUDE, 1.0, 30.0, T_END, phases="random", seed=seed)(t)
    drive = CubicSpline(t, f)
    k, m = stiffness_of(change)

    def rhs(tt: float, y: np.ndarray) -> list[float]:
        return [y[1], (drive(tt) - B * y[1] - k(tt) * y[0] - KP * y[0] ** 3) / m(tt)]

    options = {"method": "DOP853", "rtol": 1e-10, "atol": 1e-13, "max_step": 2 * DT}
    if change.endswith("drift +20 %") or change == "constant":
        x, v = solve_ivp(rhs, (0.0, t[-1]), [0.0, 0.0], t_eval=t, **options).y
    else:  # a step: integrated in two pieces, the second from the first's end
        before = t < T_CHANGE
        first = solve_ivp(rhs, (0.0, t[before][-1]), [0.0, 0.0], t_eval=t[before], **options)
        second = solve_ivp(rhs, (t[before][-1], t[-1]), first.y[:, -1], t_eval=t[~before], **options)
        x, v = np.hstack([first.y, second.y])
    truth = {"m": np.array([m(ti) for ti in t]), "b": np.full(t.size, B), "k": np.array([k(ti) for ti in t]),
             "kp": np.full(t.size, KP)}
    a = (f - B * v - truth["k"] * x - KP * x**3) / truth["m"]
    rng = np.random.default_rng(1000 + seed)
    rms_a, rms_f = np.sqrt(np.mean(a**2)), np.sqrt(np.mean(f**2))
    a_meas = a + 0.01 * rms_a + rng.normal(0.0, rms_a / 10 ** (snr / 20), a.shape)
    return t, f + rng.normal(0.0, rms_f / 1000, f.shape), a_meas, truth


def run(change: str, seed: int, snr: float) -> dict[str, float]:
    t, f, a, truth = record(change, seed, snr)
    ident = OnlineMotionIdentifier(Duffing1(), DT, "a")
    values = {n: np.empty(t.size) for n in NAMES}
    std = {n: np.empty(t.size) for n in NAMES}
    changed = np.zeros(t.size, dtype=bool)
    start = time.perf_counter()
    for i in range(t.size):
        est = ident.update(a[i], f[i])
        for n in NAMES:
            values[n][i] = est.parameters[n]
            std[n][i] = est.std_errors[n]
        changed[i] = est.status["k"] == CHANGED
    elapsed = time.perf_counter() - start
    error = np.vstack([np.abs(values[n] / truth[n] - 1) for n in NAMES])
    z = np.vstack([np.abs(values[n] - truth[n]) / std[n] for n in NAMES])
    shown = np.isfinite(error)
    at = DRIFT[0] if "drift" in change else T_CHANGE
    settled = (DRIFT[1] if "drift" in change else T_CHANGE) + 1.0
    out = {"published from": float(t[np.argmax(shown.any(axis=0))]) if shown.any() else math.nan,
           "share": 100 * float(np.isfinite(values["k"]).mean()),
           "worst error": 100 * float(np.max(error[shown])) if shown.any() else math.nan,
           "worst z": float(np.max(z[shown])) if shown.any() else math.nan,
           "beyond 3 SE": 100 * float(np.mean(z[shown] > 3)) if shown.any() else math.nan,
           "after": 100 * float(np.max(error[:, t >= settled][shown[:, t >= settled]]))
           if change != "constant" and shown[:, t >= settled].any() else math.nan,
           "withdrawn after": math.nan, "re-published after": math.nan, "s per s": elapsed / T_END}
    if change != "constant":
        flagged = np.flatnonzero(changed & (t >= at))
        if flagged.size:
            first = flagged[0]
            out["withdrawn after"] = float(t[first] - at)
            back = np.flatnonzero(np.isfinite(values["k"][first:]))
            out["re-published after"] = float(t[first + back[0]] - t[first]) if back.size else math.nan
    if change == "constant":
        out["withdrawn after"] = float(changed.any())  # a false alarm
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.partition("\n")[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--snr", type=float, nargs="+", default=[50.0, 40.0])
    parser.add_argument("--changes", nargs="+", default=list(CHANGES), choices=CHANGES, metavar="CHANGE",
                        help=f"the change types (default all: {', '.join(CHANGES)})")
    args = parser.parse_args()
    changes = args.changes
    columns = ("published from", "share", "worst error", "worst z", "beyond 3 SE", "withdrawn after",
               "re-published after", "after", "s per s")
    rows = []
    with tqdm(total=len(changes) * len(args.snr) * args.seeds, desc="records", leave=False) as bar:
        for snr in args.snr:
            for change in changes:
                results = []
                for seed in range(args.seeds):
                    results.append(run(change, seed, snr))
                    bar.update(1)
                rows.append((f"{change}, {snr:g} dB", results))
    print(f"OnlineMotionIdentifier, hardening plant {FN:g} Hz, acceleration at {1 / DT:g} Hz (bias 1 %), {T_END:g} s; "
          f"median / worst over {args.seeds} seeds")
    print("| record | " + " | ".join(columns) + " |")
    print("|---" * (len(columns) + 1) + "|")
    for name, results in rows:
        cells = []
        for c in columns:
            data = np.array([r[c] for r in results], dtype=float)
            if name.startswith("constant") and c == "withdrawn after":
                cells.append(f"{int(np.nansum(data))} false alarms")
                continue
            if np.all(np.isnan(data)):
                cells.append("-")
                continue
            worst = np.nanmin(data) if c == "share" else np.nanmax(data)
            missing = int(np.isnan(data).sum())
            cells.append(f"{np.nanmedian(data):.3g} / {worst:.3g}" + (f" ({missing} none)" if missing else ""))
        print(f"| {name} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
