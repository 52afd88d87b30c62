"""Models and simulation: conventions of eqs. (1)-(5), (10)-(11) and (20)-(21).

Tolerances: accelerations are a dozen scalar operations on terms of size up to ~50 (N)
with a result of the same order: rounding is a few ulps, compared at 1e-14 relative (~45 ulps).
"""
from __future__ import annotations

import numpy as np
import pytest

from duffid import Chain, Duffing1, Duffing2, DuffingCircuit, SimulationError, Step, measure, model_from_name, simulate
from duffid.models.simulation import quantize


def test_duffing2_equations_follow_eqs_20_21():
    eq1, eq2 = Duffing2().equations()
    assert eq1.unknowns == ("m1", "b1", "k1_1", "k1_3", "b2", "k2_1", "k2_3")
    assert eq2.unknowns == ("b2/m2", "k2_1/m2", "k2_3/m2")
    signs = {t.unknown: (t.channel.label, t.order, t.sign) for t in eq1.lhs}
    assert signs["b2"] == ("(x2-x1)", 1, -1.0)          # b2 (x1' - x2')
    assert signs["k2_3"] == ("(x2-x1)^3", 0, -1.0)     # -kp2 (x2 - x1)^3
    assert [(t.channel.label, t.order, t.sign) for t in eq2.rhs] == [("x2", 2, -1.0)]  # = -x2''


def test_acceleration_matches_hand_written_2dof():
    m = Duffing2()
    p = m.parameters
    x, v, f = np.array([0.01, 0.03]), np.array([0.2, -0.1]), np.array([3.0])
    y2, y2d = x[1] - x[0], v[1] - v[0]
    a1 = (f[0] - p["b1"] * v[0] - p["k1"] * x[0] - p["kp1"] * x[0] ** 3
          - p["b2"] * (v[0] - v[1]) - p["k2"] * (x[0] - x[1]) + p["kp2"] * y2**3) / p["m1"]
    a2 = -(p["b2"] * y2d + p["k2"] * y2 + p["kp2"] * y2**3) / p["m2"]
    np.testing.assert_allclose(m.acceleration(x, v, f), [a1, a2], rtol=1e-14)


def test_static_equilibrium_of_a_step():
    m = Duffing1(b=40.0)
    rec = simulate(m, Step(5.0), 3.0, 1e-3)
    x = rec.x[-1, 0]
    assert m.parameters["k"] * x + m.parameters["kp"] * x**3 == pytest.approx(5.0, rel=1e-6)


def test_14N_step_escapes_its_potential_well():
    with pytest.raises(SimulationError, match="potential well"):
        simulate(Duffing1(), Step(14.0), 0.5, 1e-3)


def test_measurement_model():
    rec = simulate(Duffing1(), Step(10.0), 0.2, 1e-3)
    q = measure(rec)
    step = 1.0 / 226600.0
    np.testing.assert_allclose(q.x / step, np.round(q.x / step), atol=1e-6)
    assert np.max(np.abs(q.x - rec.x)) <= step / 2 + 1e-15
    noisy = measure(rec, pulses_per_cm=None, snr_db=20, seed=3)
    snr = 10 * np.log10(np.mean(rec.x**2) / np.mean((noisy.x - rec.x) ** 2))
    assert snr == pytest.approx(20, abs=1.0)
    np.testing.assert_array_equal(measure(rec, snr_db=20, seed=3).x, measure(rec, snr_db=20, seed=3).x)
    assert quantize(0.0) == 0.0


def test_circuit_vocabulary():
    c = DuffingCircuit(L=0.2, R=3.0, C=2e-3, a=1e6)
    assert c.parameters == pytest.approx({"L": 0.2, "R": 3.0, "C": 2e-3, "a": 1e6})
    assert c.canonical_parameters()["k1_1"] == pytest.approx(500.0)


def test_model_validation_errors():
    with pytest.raises(ValueError, match="m1"):
        Duffing1(m=-1.0)
    with pytest.raises(ValueError, match="unknown model"):
        model_from_name("duffing3")
    with pytest.raises(ValueError, match="forced"):
        Chain(masses=(1.0,), damping=(1.0,), stiffness=({1: 1.0},), forced=(2,))


def test_linear_natural_frequency():
    m = Duffing1()
    assert m.linear_natural_frequencies()[0] == pytest.approx(np.sqrt(1272.1 / 2.53))


# ---------------------------------------------------------------------- the models as equations
def test_each_chain_states_its_equations_in_the_equation_syntax():
    from duffid.models.equation_model import EquationModel

    assert Duffing1().equation_text() == "m*der(x,2) + b*der(x) + k*x + kp*x^3 = f"
    assert Duffing1(offset=True).equation_text() == "m*der(x,2) + b*der(x) + k*x + kp*x^3 + c1 = f"
    assert Duffing2().equation_text() == (
        "m1*der(x1,2) + b1*der(x1) + k1*x1 + kp1*x1^3 - b2*(der(x2) - der(x1)) - k2*(x2 - x1) - kp2*(x2 - x1)^3 = f1; "
        "m2*der(x2,2) + b2*(der(x2) - der(x1)) + k2*(x2 - x1) + kp2*(x2 - x1)^3 = 0")
    with pytest.raises(Exception, match="enters the equation as 1/C"):
        DuffingCircuit().equation_text()
    # the text is the same model: same accelerations and natural frequencies, for chains with
    # quadratic stiffness, Coulomb friction and three masses too
    chain = Chain(masses=(2.0, 1.0, 0.5), damping=(3.0, 1.0, 0.5),
                  stiffness=({1: 4000.0, 2: 1e4, 3: 1e6}, {1: 2000.0, 3: -5e5}, {1: 800.0}),
                  coulomb=(0.5, 0.2, 0.1))
    for plant in (Duffing1(m=0.4, b=1.5, k=900.0, kp=2e7), Duffing2(), chain):
        columns = (["t", "f", "x"] if plant.n_dof == 1 else
                   ["t", *(f"f{k + 1}" for k in range(plant.n_forces)), *(f"x{i + 1}" for i in range(plant.n_dof))])
        model = EquationModel(plant.equation_text(), columns, values=plant.parameters)
        assert set(model.parameters) == set(plant.parameters)
        np.testing.assert_allclose(model.linear_natural_frequencies(), plant.linear_natural_frequencies(), rtol=1e-12)
        rng = np.random.default_rng(1)
        for _ in range(3):
            x, v = rng.normal(0, 0.01, plant.n_dof), rng.normal(0, 0.3, plant.n_dof)
            f = rng.normal(0, 5.0, plant.n_forces)
            np.testing.assert_allclose(model.acceleration(x, v, f), plant.acceleration(x, v, f), rtol=1e-12, atol=1e-12)
