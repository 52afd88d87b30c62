"""Build the Modelica example plants as FMUs and check them against duffid's own simulation.
=========================================================================================

Every plant of modelica/Duffid/Examples becomes ``<Name>.fmu`` (FMI 2.0) and
``<Name>_fmi3.fmu`` (FMI 3.0), each with Model Exchange, Co-Simulation and its C sources.
The four plants that duffid.models.chain also knows are then co-simulated in fmpy under a 10 N
(10 V) step and compared with :func:`duffid.simulate`.

Run: python examples/modelica_plants.py [--out build/fmus]
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from fmpy import simulate_fmu

from duffid import Chain, Duffing1, Duffing2, DuffingCircuit, Step, simulate
from duffid.modelica.export import build_all

#: plant -> (duffid model with the Modelica defaults, input name, displacement outputs)
PLANTS = {
    "Oscillator1DOF": (Duffing1(), "f", ["x"]),
    "Oscillator2DOF": (Duffing2(), "f1", ["x1", "x2"]),
    "ChainNDOF": (Chain(masses=(1.0,) * 3, damping=(1.0,) * 3, stiffness=({1: 1000.0},) * 3), "f",
                  ["x[1]", "x[2]", "x[3]"]),
    "DuffingCircuit": (DuffingCircuit(), "u", ["q"]),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.partition("\n")[0])
    parser.add_argument("--out", type=Path, default=Path("build/fmus"), help="output folder")
    args = parser.parse_args()
    paths = build_all(args.out)
    print(f"built {len(paths)} FMUs in {args.out}")
    t_end, dt = 1.0, 1e-3
    t = np.arange(int(round(t_end / dt)) + 1) * dt
    print(f"{'plant':<16} {'output':<6} {'max |x|':>10} {'rel. error vs duffid.simulate':>30}")
    for name, (model, u, outputs) in PLANTS.items():
        signal = np.zeros(len(t), dtype=[("time", float), (u, float)])
        signal["time"], signal[u] = t, 10.0
        result = simulate_fmu(args.out / f"{name}.fmu", fmi_type="CoSimulation", stop_time=t_end,
                              output_interval=dt, input=signal, output=outputs)
        record = simulate(model, Step(10.0), t_end, dt)
        for k, out in enumerate(outputs):
            ref = record.x[:, k]
            err = np.max(np.abs(result[out] - ref)) / np.max(np.abs(ref))
            print(f"{name:<16} {out:<6} {np.max(np.abs(ref)):>10.4g} {err:>30.2e}")


if __name__ == "__main__":
    main()
