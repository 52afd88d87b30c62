"""The simulation check's segments in C (duffid.identification.refine.SegmentSimulator) against the
Python simulator they replace: the same fitted states and simulated displacements, to the
fit's tolerance."""
from __future__ import annotations

import numpy as np
import pytest

from duffid import Duffing1, Duffing2, Multisine, measure, simulate
from duffid.identification import assessment
from duffid.identification.refine import OdeSimulator, SegmentSimulator, stretches
from duffid.identification.sampling import natural_frequency, noise_level


@pytest.mark.parametrize("plant", [Duffing1(), Duffing2()], ids=["1-DOF", "2-DOF"])
def test_segments_in_c_reproduce_the_python_simulation(plant, monkeypatch):
    record = measure(simulate(plant, Multisine(8.0, 0.5, 10.0, 2.0, phases="random", seed=1), 4.0, 1e-3),
                     pulses_per_cm=None, snr_db=40, seed=2)
    canonical = plant.canonical_parameters()
    natural = natural_frequency(plant, canonical)
    noise = noise_level(record.x)
    fast = assessment._simulation_fit(record, plant, canonical, natural, noise, 60.0)
    monkeypatch.setattr(assessment, "_segments_in_c", lambda *args: None)
    slow = assessment._simulation_fit(record, plant, canonical, natural, noise, 60.0)
    assert fast[0]["segments"] == slow[0]["segments"] > 4
    # the same minimum of the initial-state fit (Levenberg-Marquardt in C and MINPACK's),
    # the same RK4 steps: equal to the fit's tolerance, far below the measurement noise
    spread = np.std(record.x, axis=0)
    assert np.max(np.abs(fast[1] - slow[1]) / spread) < 1e-4
    assert fast[0]["simulation_nrmse"] == pytest.approx(slow[0]["simulation_nrmse"], rel=1e-4)


def test_an_escaping_segment_is_reported_not_hidden():
    plant = Duffing1()
    record = measure(simulate(plant, Multisine(8.0, 0.5, 10.0, 2.0, phases="random", seed=1), 2.0, 1e-3),
                     pulses_per_cm=None, snr_db=40, seed=2)
    wrong = {**plant.canonical_parameters(), "k1_3": -1e12}  # escapes at once
    simulator = OdeSimulator(plant, record.dt, free=())
    _, escaped = SegmentSimulator(simulator).record_segments(wrong, record, stretches(record.n_samples, 500), 100)
    assert all(escaped)
