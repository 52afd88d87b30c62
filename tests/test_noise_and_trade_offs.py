"""What the stated errors count: the force sensor's noise (the noisy replicates add it as they
add the displacement's) and a trade-off the record cannot resolve (a value that moves with an
undetermined one is not published). Records from our own simulator, plants of other scales
than the paper's."""
from __future__ import annotations

import math

import numpy as np
import pytest

from duffid import Duffing1, Multisine, Record, identify, measure, simulate
from duffid.identification.assessment import TRADE_OFF_CORRELATION, measured_force_noise
from duffid.models.equation_model import EquationModel


def _within_stated_errors(result, truth):
    a = result.assessment
    for name, value in result.parameters.items():
        if math.isfinite(value):
            assert abs(value - truth[name]) <= 3 * a.uncertainty[name] * abs(value), (
                name, value, truth[name], a.uncertainty[name], a.notes)


PLANT = Duffing1(m=1.0, b=1.0, k=1000.0, kp=2e6)  # 5 Hz, lightly damped, hardening


def _force_noise_record(seed: int) -> Record:
    """4 s at 250 Hz under a multisine (0.5-20 Hz, 5 N); the displacement at 60 dB, the force
    with white noise of 3 % of its RMS (30 dB)."""
    exact = simulate(PLANT, Multisine(5.0, 0.5, 20.0, 4.0, phases="random", seed=seed), 4.0, 1 / 250)
    measured = measure(exact, pulses_per_cm=None, snr_db=60, seed=seed + 100)
    f = np.asarray(measured.f, dtype=float)
    noisy = f + np.random.default_rng(seed + 200).standard_normal(f.shape) * 0.03 * np.sqrt(np.mean(f**2))
    return Record(measured.t, noisy, measured.x, source="force_noise.csv")


def test_the_force_noise_is_measured_and_a_clean_force_adds_none():
    record = _force_noise_record(3)
    sigma = 0.03 * np.sqrt(np.mean(np.asarray(record.f) ** 2))
    assert measured_force_noise(record.f)[0] == pytest.approx(sigma, rel=0.15)
    clean = simulate(PLANT, Multisine(5.0, 0.5, 20.0, 4.0, phases="random", seed=3), 4.0, 1 / 250)
    assert measured_force_noise(clean.f)[0] == 0.0


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_force_noise_widens_the_stated_errors(seed):
    """Before, the replicates added the displacement's noise only: on these three records m
    was published 0.12-0.16 % off at 5-7 of its stated errors (on a helper's records of the
    same plant, b 1-2 % off at 9-29)."""
    result = identify(_force_noise_record(seed), Duffing1())
    _within_stated_errors(result, PLANT.parameters)
    assert result.assessment.fit["force_noise"][0] > 0


def test_stiffness_known_only_with_an_undetermined_mass_is_not_published():
    """A linear plant in steady state under one sine: only k - m w^2 and b are in the record.
    The algebraic estimate put m at 0.073 (truth 1; 17 % uncertain) and published k at 670.6
    with a stated 0.67 % (truth 1000)."""
    plant = Duffing1(m=1.0, b=3.0, k=1000.0, kp=0.0)
    exact = simulate(plant, Multisine(5.0, 2.9, 3.1, 1.0), 12.0, 1e-3)  # one cosine of 3 Hz
    measured = measure(exact, pulses_per_cm=None, snr_db=60, seed=103)
    steady = slice(8000, None)  # the transient from rest has died out (8 s: 12 time constants 2m/b)
    record = Record(measured.t[steady] - measured.t[8000], measured.f[steady], measured.x[steady], source="sine.csv")
    result = identify(record, EquationModel("m*der(x,2) + b*der(x) + k*x = f"))
    a = result.assessment
    assert a.status["k"] != "published" and a.status["m"] != "published", (result.parameters, a.notes)
    assert a.status["b"] == "published"
    assert any("k moves with m" in n and f"{TRADE_OFF_CORRELATION:g}" in n for n in a.notes), a.notes
    _within_stated_errors(result, plant.parameters)
