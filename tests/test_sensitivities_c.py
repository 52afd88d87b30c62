"""The output-error refinement's simulations in C (duffid.identification.refine.SensitivitySimulator)
against the Python simulator they replace: the same outputs and sensitivities to rounding, and
the same refinement."""
from __future__ import annotations

import numpy as np
import pytest

from duffid import Duffing1, Duffing2, Multisine, Record, measure, simulate
from duffid.identification import refine as refine_module
from duffid.identification.refine import OdeSimulator, SensitivitySimulator, refine, stretches
from duffid.models.chain import Chain

EPS = np.finfo(float).eps

PLANTS = {
    "1-DOF with offset": Duffing1(offset=True),
    "2-DOF": Duffing2(),
    "2 forces, friction": Chain(masses=(1.0, 0.5), damping=(2.0, 1.0), stiffness=({1: 2000.0, 3: 3e6}, {1: 800.0}),
                                coulomb=(0.3, 0.0), forced=(0, 1)),
}


@pytest.mark.parametrize("output", ["x", "v", "a"])
@pytest.mark.parametrize("name", list(PLANTS))
def test_the_c_stretches_are_the_python_simulation(name, output):
    plant = PLANTS[name]
    simulator = OdeSimulator(plant, 1e-3, substeps=3, free=list(plant.canonical_parameters())[1:])
    rng = np.random.default_rng(3)
    f = 3.0 * rng.standard_normal((900, plant.n_forces))
    stages = simulator.stage_inputs(f)
    p = {k: float(v) for k, v in plant.canonical_parameters().items()}
    bounds = [(0, 250), (250, 251), (251, 600), (600, 899), (899, 900)]
    n, q, nf = plant.n_dof, simulator.substeps, plant.n_forces
    states = 1e-3 * rng.standard_normal((len(bounds), 2 * n))
    y, dy = SensitivitySimulator(simulator).run(p, np.ascontiguousarray(stages.T), bounds, states, output)
    for (a, b), z0 in zip(bounds, states):
        if b - a == 1:  # the state itself, or the accelerations at it (the force: the previous step's end)
            acc, d_state, d_free = (np.asarray(v) for v in simulator.acceleration(
                z0, stages[2 * nf:, q * a - 1], simulator.parameter_vector(p)))
            start = np.hstack([np.zeros((2 * n, len(simulator.free))), np.eye(2 * n)])  # d(state)/d(free, state)
            expected, expected_d = {"x": (z0[:n], start[:n]), "v": (z0[n:], start[n:]),
                                    "a": (acc.ravel(), np.hstack([d_free, d_state]))}[output]
            assert np.allclose(y[a], expected, rtol=0, atol=8 * EPS * np.max(np.abs(expected)))
            assert np.allclose(dy[a], expected_d, rtol=0, atol=8 * EPS * np.max(np.abs(expected_d)))
            continue
        ys, dys = simulator.simulate_stages(p, stages[:, q * a:q * (b - 1)], z0[:n], z0[n:], sensitivities=True,
                                            output=output)
        # the same generated expressions; the accelerations' chain rule sums 2 n_dof products
        # in another order: a few roundings of the largest term of each column
        scale = np.max(np.abs(dys), axis=(0, 1), keepdims=True) + np.max(np.abs(dy[a:b]), axis=(0, 1), keepdims=True)
        if output == "a":
            assert np.allclose(y[a:b], ys, rtol=0, atol=8 * EPS * np.max(np.abs(ys)))
        else:
            assert np.array_equal(y[a:b], ys)
        assert np.all(np.abs(dy[a:b] - dys) <= 4 * n * EPS * scale)


def test_the_c_stretches_refuse_what_they_cannot_run():
    plant = Duffing1()
    simulator = OdeSimulator(plant, 1e-3)
    stages = np.ascontiguousarray(simulator.stage_inputs(np.zeros(100)).T)
    fast = SensitivitySimulator(simulator)
    p = plant.canonical_parameters()
    with pytest.raises(ValueError, match="beyond the stage inputs"):
        fast.run(p, stages, [(50, 101)], np.zeros((1, 2)))
    with pytest.raises(ValueError, match="unknown output"):
        fast.run(p, stages, [(0, 10)], np.zeros((1, 2)), output="jerk")


@pytest.mark.parametrize("output", ["x", "v"])
def test_refine_in_c_finds_what_the_python_refinement_finds(output, monkeypatch):
    """Multiple shooting over 12 stretches of a noisy hardening record: the same iterates (the
    same arithmetic) and so the same parameters, errors and evaluations."""
    plant = Duffing1()
    record = measure(simulate(plant, Multisine(8.0, 0.5, 10.0, 2.0, phases="random", seed=1), 1.2, 1e-3),
                     pulses_per_cm=None, snr_db=50, seed=4)
    if output == "v":
        v = OdeSimulator(plant, record.dt).simulate(plant.canonical_parameters(), record.f, [0.0], [0.0], output="v")
        record = Record(record.t, record.f, v + 0.003 * np.std(v) * np.random.default_rng(1).standard_normal(v.shape),
                        motion="v")
    start = {k: 1.03 * v for k, v in plant.parameters.items()}
    fast = refine(record, plant, start, segment=100, output=output, progress=False)
    monkeypatch.setattr(refine_module, "_sensitivities_in_c", lambda simulator: None)
    slow = refine(record, plant, start, segment=100, output=output, progress=False)
    assert fast.options["stretches"] == len(stretches(record.n_samples, 100)) == 12
    assert fast.nfev == slow.nfev and fast.success and slow.success
    for k, v in slow.parameters.items():
        assert fast.parameters[k] == pytest.approx(v, rel=1e-9, abs=0), k
        assert abs(v - plant.parameters[k]) <= 4 * slow.relative_std[plant.canonical_name(k)] * abs(v), k
