"""Feed samples one at a time to the online identifier, as a real-time loop would.
===============================================================================

A 2-DOF chain (paper Figure 9) is excited by a 6 N step on the first mass; the
identifier reports NaN until the estimate is trustworthy, then the parameters.

Run: python examples/online_loop.py
"""
from __future__ import annotations

import numpy as np

from duffid import Duffing2, OnlineIdentifier, Step, measure, simulate


def main() -> None:
    plant = Duffing2()
    record = measure(simulate(plant, Step(6.0), t_end=1.0, dt=1e-3))
    identifier = OnlineIdentifier(Duffing2(), dt=record.dt)
    for k, (x, f) in enumerate(zip(record.x, record.f)):
        estimate = identifier.update(x, f)          # O(1) work per sample
        if k % 200 == 0 or k == record.n_samples - 1:
            shown = {n: f"{v:.4g}" for n, v in estimate.parameters.items() if np.isfinite(v)}
            print(f"t={estimate.t:.3f}s identified={estimate.identified} cond={estimate.condition:.3g} {shown}")
    print("truth", plant.parameters)


if __name__ == "__main__":
    main()
