"""Identify a series R-L-cubic-capacitor circuit in its own vocabulary (L, R, C, a).
=================================================================================

``L q'' + R q' + q/C + a q^3 = u``: the charge q is the "displacement" column and the
source voltage u the "force" column; the user never translates parameters by hand.

Run: python examples/duffing_circuit.py
"""
from __future__ import annotations

from duffid import Chirp, DuffingCircuit, identify, measure, simulate


def main() -> None:
    circuit = DuffingCircuit(L=0.1, R=2.0, C=1e-3, a=5e6)
    record = measure(simulate(circuit, Chirp(1.0, 0.0, 30.0, 2.0), t_end=2.0, dt=1e-4),
                     pulses_per_cm=None, snr_db=60, seed=1)
    result = identify(record, DuffingCircuit())
    for name, value in result.parameters.items():
        print(f"{name} = {value:.6g} (truth {circuit.parameters[name]:.6g})")


if __name__ == "__main__":
    main()
