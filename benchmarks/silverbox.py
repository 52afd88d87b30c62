"""Benchmark on real data: the Silverbox electronic Duffing oscillator.

Run: python benchmarks/silverbox.py [PATH] [--no-ablation] [--rule-check]

PATH is the folder holding SNLS80mV.mat (default: ../shared/data/silverbox next to the
repository). Tables:
  1. Simulation RMS error [mV] (first 50 samples skipped) per test record of: the
     algebraic estimate alone, algebraic + output-error refinement, the best linear
     model (2nd-order linear ODE fitted by output error) and least squares on
     Savitzky-Golay derivatives, next to the published figures of PROVENANCE.md; plus
     (ablation) the algebraic estimator without upsampling.
  2. The identified parameters, natural frequency and damping ratio of each method.
  3. (--rule-check) Why 50 samples per period: the online estimator on a noise-free
     simulation of the refined Silverbox model under the measured input, for several
     upsampling factors: errors of the natural frequency and damping ratio.
Takes about two minutes (three with --rule-check) on one core.
"""
from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np

from duffid.analysis.silverbox import (
    PARAMETER_NAMES,
    PUBLISHED_MV,
    TEST_RECORDS,
    SilverboxData,
    best_linear_model,
    choose_settings,
    damping_ratio,
    errors_on_test_records,
    identify_algebraic,
    identify_silverbox,
    load_silverbox,
    natural_frequency,
    savgol_least_squares,
    silverbox_model,
    to_canonical,
    to_public,
)
from duffid.data.record import Record
from duffid.identification.refine import OdeSimulator

TARGETS_MV = {"algebraic": 0.5, "refined": 0.40}  # arrow (full), from the issue


def _cells(values, width: int = 13, fmt: str = ".3f") -> str:
    sign = "+" if fmt.startswith("+") else ""
    spec = f">{sign}{width}{fmt.lstrip('+')}"
    return "".join(format(v, spec) if isinstance(v, (float, np.floating)) and np.isfinite(v)
                   else f"{'-' if v is None else str(v):>{width}}" for v in values)


def no_upsampling(data: SilverboxData) -> tuple[dict[str, float], dict[str, float]]:
    """The algebraic estimator on the raw 9 samples per period (factor 1)."""
    settings = choose_settings(data.training)
    settings = dataclasses.replace(settings, factor=1,
                                   samples_per_period=data.training.fs / settings.linear.natural_frequency)
    params = to_public(identify_algebraic(data.training, settings).parameters)
    return params, errors_on_test_records(data, params)[0]


def rule_check(data: SilverboxData, truth: dict[str, float], samples: int = 8192) -> None:
    """Estimator bias vs samples per period on a noise-free Silverbox-like simulation."""
    training = data.training
    u = training.f[:samples, 0]
    sim = OdeSimulator(silverbox_model(), training.dt, substeps=16)
    y = sim.simulate(to_canonical(truth), u, [0.0], [0.0])[:, 0]
    record = Record(training.t[:samples], u, y, source="noise-free simulation of the refined model")
    base = choose_settings(record)
    f_true, z_true = natural_frequency(truth), damping_ratio(truth)
    print(f"\n3. Rule check: online estimator on {samples} samples of a noise-free simulation of the refined "
          f"model\n   under the measured input (f_n {f_true:.3f} Hz, zeta {z_true:.5f}); error [%]")
    print(f"{'factor':>8}{'samples/period':>16}{'f_n':>12}{'zeta':>12}{'k3':>12}")
    for q in (1, 2, 3, 4, 6, 8):
        settings = dataclasses.replace(base, factor=q, samples_per_period=q * record.fs / f_true)
        est = to_public(identify_algebraic(record, settings).parameters)
        errors = [100 * (natural_frequency(est) / f_true - 1), 100 * (damping_ratio(est) / z_true - 1),
                  100 * (est["k3"] / truth["k3"] - 1)]
        print(f"{q:>8}{settings.samples_per_period:>16.1f}" + _cells(errors, 12, "+.3f"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("path", nargs="?", type=Path, default=None, help="folder holding SNLS80mV.mat")
    parser.add_argument("--no-ablation", action="store_true", help="skip the run without upsampling")
    parser.add_argument("--rule-check", action="store_true", help="add table 3 (samples per period)")
    args = parser.parse_args()

    data = load_silverbox(args.path)
    start = time.perf_counter()
    result = identify_silverbox(data.path)
    t_main = time.perf_counter() - start
    methods: dict[str, dict[str, float]] = {"algebraic": result.algebraic, "algebraic + refinement": result.refined}
    errors: dict[str, dict[str, float]] = {
        "algebraic": {r: result.rms_mV[r]["algebraic"] for r in TEST_RECORDS},
        "algebraic + refinement": {r: result.rms_mV[r]["refined"] for r in TEST_RECORDS},
    }
    start = time.perf_counter()
    methods["best linear model"] = best_linear_model(data.training, result.settings.linear)
    errors["best linear model"] = errors_on_test_records(data, methods["best linear model"])[0]
    t_linear = time.perf_counter() - start
    methods["LS on Savitzky-Golay"] = savgol_least_squares(data.training, result.settings)
    errors["LS on Savitzky-Golay"] = errors_on_test_records(data, methods["LS on Savitzky-Golay"])[0]
    if not args.no_ablation:
        methods["algebraic, no upsampling"], errors["algebraic, no upsampling"] = no_upsampling(data)

    s = result.settings
    print(f"Silverbox benchmark: {result.source}")
    print(f"training {data.training.n_samples} samples at {data.training.fs:.2f} Hz; ARX resonance "
          f"{s.linear.natural_frequency:.2f} Hz -> upsampling x{s.factor} ({s.samples_per_period:.1f} samples "
          f"per period), window {1e3 * s.window:.1f} ms (3 periods)")
    print(f"time: algebraic estimator {result.times['identification']:.0f} s, refinement "
          f"{result.times.get('refinement', 0):.0f} s, test simulations {result.times['simulation']:.0f} s "
          f"(total {t_main:.0f} s); best linear model {t_linear:.0f} s")

    print("\n1. Simulation RMS error [mV] on the test records (first 50 samples skipped)")
    print(f"{'method':<28}" + "".join(f"{r:>24}" for r in TEST_RECORDS))
    for method, e in errors.items():
        print(f"{method:<28}" + _cells([e[r] for r in TEST_RECORDS], 24))
    print(f"targets (arrow_full): algebraic <= {TARGETS_MV['algebraic']} mV, with refinement <= "
          f"{TARGETS_MV['refined']} mV")
    print("published (test record, PROVENANCE.md):")
    for name, value in PUBLISHED_MV.items():
        print(f"  {name:<40}{value:>8.2f}")

    print("\n2. Parameters (SI units, volts) and small-signal natural frequency / damping ratio")
    print(f"{'method':<28}" + "".join(f"{p:>13}" for p in PARAMETER_NAMES) + f"{'f_n [Hz]':>13}{'zeta':>13}")
    for method, p in methods.items():
        print(f"{method:<28}" + _cells([p[n] for n in PARAMETER_NAMES], 13, ".5g")
              + _cells([natural_frequency(p)], 13, ".3f") + _cells([damping_ratio(p)], 13, ".5f"))
    if result.refinement is not None:
        std = result.refinement.relative_std
        print(f"{'refined: rel. std error':<28}" + _cells([std[c] for c in PARAMETER_NAMES.values()], 13, ".1e"))
        print(f"  refinement: {result.refinement.nfev} simulations, {result.refinement.message.rstrip('.')}; training RMS "
              f"{1e3 * result.refinement.rms_start:.3f} -> {1e3 * result.refinement.rms:.3f} mV")

    if args.rule_check:
        rule_check(data, result.refined or result.algebraic)


if __name__ == "__main__":
    main()
