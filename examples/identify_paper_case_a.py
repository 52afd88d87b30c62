"""Identify the paper's 1-DOF plant (case A: 14 N step, 0.25 s, encoder-quantised).
================================================================================

Run: python examples/identify_paper_case_a.py [--out DIR]
"""
from __future__ import annotations

import argparse
from pathlib import Path

from duffid import Duffing1, Step, identify, measure, simulate
from duffid.apps.plots import plot_estimates


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.partition("\n")[0])
    parser.add_argument("--out", type=Path, default=Path("out"))
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    plant = Duffing1()                                   # paper Table 1, b = 12.47
    record = measure(simulate(plant, Step(14.0), t_end=0.25, dt=1e-3))
    for method in ("robust", "paper"):
        result = identify(record, plant, method)
        errors = result.errors(plant.parameters)
        print(method, {k: f"{v:.4g} ({errors[k]:+.3f} %)" for k, v in result.parameters.items()})
        plot_estimates(result, args.out / f"case_a_{method}.png", truth=plant.parameters)


if __name__ == "__main__":
    main()
