"""Few samples per period: the rows' quadrature and the damping the online estimator publishes.

Run: python benchmarks/quadrature.py [--rates 180,200,250,300,360] [--dampings 0.008,0.02,0.05]

A 10 Hz hardening plant (``kp x^2 / k = 0.5`` at 1 cm) under a swept sine from 3 to 25 Hz
over 8 s, noise-free, sampled at each rate; the Python online estimator (default options,
the same code as the C core) is fed the record sample by sample. Printed per rate and
damping ratio: the worst published error of every parameter at any sample, with the standard
error stated then, for Gregory's rule with :data:`~duffid.identification.regressors.GREGORY_POINTS`
corrected end samples (the estimator's rule) and with three (the classical fourth-order
rule, for comparison), both with the half-rate check of :data:`~duffid.identification.engine.RATE_NOISE`.
The figures depend only on the arithmetic, not on the machine.
"""
from __future__ import annotations

import argparse
import math
from contextlib import contextmanager
from typing import Iterator

import numpy as np

from duffid import Chirp, Duffing1, OnlineIdentifier, simulate
from duffid.identification import regressors

NATURAL_HZ = 10.0
AMPLITUDE_M = 0.01        # the amplitude at which kp x^2 / k = HARDENING
HARDENING = 0.5
SWEEP_HZ = (3.0, 25.0)
DURATION_S = 8.0


@contextmanager
def gregory_points(points: int) -> Iterator[None]:
    """Run with ``points`` corrected samples at each end (the Python engine reads the
    module's value whenever a window length is new)."""
    kept = regressors.GREGORY_POINTS
    regressors.GREGORY_POINTS = points
    try:
        yield
    finally:
        regressors.GREGORY_POINTS = kept


def plant(damping_ratio: float) -> dict[str, float]:
    """The plant's parameters (SI units)."""
    k = (2 * math.pi * NATURAL_HZ) ** 2
    return {"m": 1.0, "b": 2 * damping_ratio * math.sqrt(k), "k": k, "kp": HARDENING * k / AMPLITUDE_M**2}


def worst_published(rate: float, damping_ratio: float) -> dict[str, tuple[float, float]]:
    """Per parameter: (worst relative error published at any sample, its stated relative
    standard error then); parameters never published are left out."""
    truth = plant(damping_ratio)
    force = Chirp(truth["k"] * AMPLITUDE_M * 6 * damping_ratio, SWEEP_HZ[0], SWEEP_HZ[1], DURATION_S)
    record = simulate(Duffing1(**truth), force, t_end=DURATION_S, dt=1.0 / rate)
    ident = OnlineIdentifier(Duffing1(), record.dt)
    worst: dict[str, tuple[float, float]] = {}
    for x, f in zip(record.x[:, 0], record.f[:, 0]):
        estimate = ident.update(x, f)
        for name, value in estimate.parameters.items():
            if np.isfinite(value):
                error = abs(value / truth[name] - 1.0)
                if error > worst.get(name, (-1.0, 0.0))[0]:
                    worst[name] = (error, estimate.std_errors[name] / abs(truth[name]))
    return worst


def _cell(worst: dict[str, tuple[float, float]], name: str) -> str:
    if name not in worst:
        return "never"
    error, stated = worst[name]
    return f"{100 * error:.2f} ({100 * stated:.2f})"


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rates", default="180,200,250,300,360", help="sample rates [Hz], comma-separated")
    parser.add_argument("--dampings", default="0.008,0.02,0.05", help="damping ratios, comma-separated")
    args = parser.parse_args(argv)
    rates = [float(r) for r in args.rates.split(",")]
    dampings = [float(z) for z in args.dampings.split(",")]
    rules = {f"order {regressors.GREGORY_POINTS + 1} (now)": regressors.GREGORY_POINTS, "order 4": 3}
    names = ("m", "b", "k", "kp")
    print(f"Worst published error at any sample, % (stated standard error then, %); {NATURAL_HZ:g} Hz plant, "
          f"swept sine {SWEEP_HZ[0]:g}-{SWEEP_HZ[1]:g} Hz, noise-free")
    header = f"{'rate (per period at ' + format(SWEEP_HZ[1], 'g') + ' Hz)':<28}{'zeta':>7}  {'rule':<15}" + "".join(
        f"{n:>18}" for n in names)
    print(header)
    for rate in rates:
        for zeta in dampings:
            for label, points in rules.items():
                with gregory_points(points):
                    worst = worst_published(rate, zeta)
                where = f"{rate:g} Hz ({rate / SWEEP_HZ[1]:.1f})"
                print(f"{where:<28}{100 * zeta:>6.1f}%  {label:<15}" + "".join(f"{_cell(worst, n):>18}" for n in names),
                      flush=True)


if __name__ == "__main__":
    main()
