"""Output-error refinement: interpolation, the RK4 simulator (against solve_ivp), sensitivities, fits.

Tolerances: simulation accuracy is compared at the integrator's truncation error (RK4 at
4 steps per sample against DOP853 at rtol 1e-10); fitted parameters at their noise level.
"""
from __future__ import annotations

import numpy as np
import pytest

from duffid import Chain, Duffing1, Duffing2, DuffingCircuit, Multisine, Record, RecordError, Step, simulate
from duffid.identification.refine import (
    OdeSimulator,
    canonical_from_public,
    correlation_factor,
    fit_initial_state,
    refine,
    rms_error,
    simulate_record,
    stretches,
    upsample,
)

DT_SB = 1.0 / 610.35  # Silverbox sampling: 9 samples per period of the plant below
SB_PLANT = Chain(masses=(5.376e-6,), damping=(2.2525e-4,), stiffness=({1: 0.99071, 2: -0.0342, 3: 3.916},),
                 orders=(1, 2, 3))


@pytest.fixture(scope="module")
def sb_record():
    """Silverbox-like plant under a random-phase multisine up to 150 Hz, solved by DOP853."""
    source = Multisine(0.08, 1.0, 150.0, 0.5, phases="random", seed=3)
    return simulate(SB_PLANT, source, 0.8, DT_SB)


# ---------------------------------------------------------------------- upsample
def test_upsample_bandlimited_is_exact_inside_the_band():
    t = np.arange(2000) * DT_SB
    signal = lambda tt: 0.006 + 0.02 * np.sin(2 * np.pi * 150.0 * tt + 0.3) + 0.01 * np.cos(2 * np.pi * 37 * tt)
    fine = upsample(signal(t), 4)
    assert fine.shape == (4 * 1999 + 1,)
    np.testing.assert_array_equal(fine[::4], signal(t))  # samples kept
    tf = np.arange(len(fine)) * DT_SB / 4
    err = np.abs(fine - signal(tf))[200:-200]
    assert err.max() < 5e-5 * 0.03  # filter ripple ~1e-5


def test_upsample_linear_and_channels():
    x = np.column_stack([np.arange(5.0), 2.0 * np.arange(5.0)])
    fine = upsample(x, 3, method="linear")
    assert fine.shape == (13, 2)
    np.testing.assert_allclose(fine[:, 0], np.arange(13) / 3)
    np.testing.assert_allclose(fine[:, 1], 2 * np.arange(13) / 3)
    np.testing.assert_array_equal(upsample(x, 1), x)


@pytest.mark.parametrize("factor, method", [(0, "linear"), (1.5, "linear"), (2, "cubic")])
def test_upsample_rejects_bad_arguments(factor, method):
    with pytest.raises(ValueError):
        upsample(np.arange(10.0), factor, method=method)


# ---------------------------------------------------------------------- simulator accuracy
def test_rk4_matches_solve_ivp_at_nine_samples_per_period(sb_record):
    """Four RK4 steps per sample agree with DOP853 (rtol 1e-10) to 5e-4 of the output RMS."""
    sim = OdeSimulator(SB_PLANT, sb_record.dt)
    x = sim.simulate(SB_PLANT.canonical_parameters(), sb_record.f, [0.0], [0.0])
    assert x.shape == sb_record.x.shape
    size = np.sqrt(np.mean(sb_record.x**2))
    late = slice(100, None)  # the start: the input jumps at t = 0, not band-limited there
    assert np.sqrt(np.mean((x - sb_record.x)[late] ** 2)) < 5e-4 * size
    coarse = OdeSimulator(SB_PLANT, sb_record.dt, substeps=1).simulate(
        SB_PLANT.canonical_parameters(), sb_record.f, [0.0], [0.0])
    assert np.sqrt(np.mean((coarse - sb_record.x)[late] ** 2)) > 10 * np.sqrt(np.mean((x - sb_record.x)[late] ** 2))


def test_two_dof_chain_with_linear_input_matches_solve_ivp():
    plant = Duffing2()
    record = simulate(plant, Step(6.0), 0.5, 1e-3)
    sim = OdeSimulator(plant, record.dt, interpolation="linear", substeps=2)
    x = sim.simulate(plant.canonical_parameters(), record.f, [0.0, 0.0], [0.0, 0.0])
    assert np.max(np.abs(x - record.x)) < 1e-6 * np.max(np.abs(record.x))


def test_offset_enters_like_a_constant_force():
    base = Duffing1()
    record = simulate(base, Step(8.0), 0.3, 1e-3)
    with_offset = Duffing1(offset=True)
    params = {**with_offset.canonical_parameters(), "c1": 2.0}
    sim = OdeSimulator(with_offset, 1e-3, interpolation="linear")
    x = sim.simulate(params, record.f + 2.0, [0.0], [0.0])  # f + c - c: the same motion
    assert np.max(np.abs(x - record.x)) < 1e-6 * np.max(np.abs(record.x))


def test_sensitivities_match_finite_differences(sb_record):
    sim = OdeSimulator(SB_PLANT, sb_record.dt, substeps=2)
    p = SB_PLANT.canonical_parameters()
    x0, v0 = [1e-3], [0.5]
    x, dx = sim.simulate(p, sb_record.f, x0, v0, sensitivities=True)
    assert dx.shape == (sb_record.n_samples, 1, len(sim.free) + 2)
    for j, name in enumerate(sim.free):
        step = 1e-6 * abs(p[name])
        shifted = sim.simulate({**p, name: p[name] + step}, sb_record.f, x0, v0)
        fd = (shifted - x) / step
        assert np.max(np.abs(fd - dx[:, :, j])) < 1e-3 * np.max(np.abs(dx[:, :, j])), name
    shifted = sim.simulate(p, sb_record.f, [x0[0] + 1e-7], v0)
    fd = (shifted - x) / 1e-7
    assert np.max(np.abs(fd - dx[:, :, -2])) < 1e-4 * np.max(np.abs(dx[:, :, -2]))


def test_simulator_rejects_bad_arguments():
    with pytest.raises(ValueError, match="dt"):
        OdeSimulator(Duffing1(), 0.0)
    with pytest.raises(ValueError, match="substeps"):
        OdeSimulator(Duffing1(), 1e-3, substeps=0)
    with pytest.raises(ValueError, match="unknown free"):
        OdeSimulator(Duffing1(), 1e-3, free=["kp"])
    sim = OdeSimulator(Duffing1(), 1e-3)
    with pytest.raises(ValueError, match="missing"):
        sim.simulate({"m1": 1.0}, np.zeros(10), [0.0], [0.0])


# ---------------------------------------------------------------------- helpers
def test_canonical_from_public_names():
    d1 = Duffing1(offset=True)
    canon = canonical_from_public(d1, {"m": 2.0, "b": 1.0, "k": 1000.0, "kp": -1e6, "c1": 0.3})
    assert canon == {"m1": 2.0, "b1": 1.0, "k1_1": 1000.0, "k1_3": -1e6, "c1": 0.3}
    circuit = canonical_from_public(DuffingCircuit(), {"L": 0.2, "R": 3.0, "C": 1e-3, "a": 1e6})
    assert circuit["k1_1"] == pytest.approx(1000.0) and circuit["m1"] == 0.2
    assert canonical_from_public(d1, {"k1_1": 5.0})["k1_1"] == 5.0  # canonical names pass through
    with pytest.raises(ValueError, match="unknown parameter"):
        canonical_from_public(d1, {"mass": 1.0})


def test_rms_error():
    a = np.zeros(100)
    b = np.r_[np.full(50, 9.0), np.full(50, 2.0)]
    assert rms_error(a, b) == pytest.approx(2.0)
    assert rms_error(a, b, skip=0) == pytest.approx(np.sqrt((50 * 81 + 50 * 4) / 100))
    assert rms_error(a, np.r_[b[:-1], np.inf]) == np.inf
    with pytest.raises(ValueError, match="shape"):
        rms_error(a, b[:-1])
    with pytest.raises(ValueError, match="skipping"):
        rms_error(a[:10], b[:10])


def test_fit_initial_state_recovers_a_known_state(sb_record):
    sim = OdeSimulator(SB_PLANT, sb_record.dt)
    p = SB_PLANT.canonical_parameters()
    x = sim.simulate(p, sb_record.f, [0.02], [-9.0])
    record = Record(sb_record.t, sb_record.f, x)
    x0, v0 = fit_initial_state(sim, p, record, window=50)
    assert x0[0] == pytest.approx(0.02, rel=1e-6) and v0[0] == pytest.approx(-9.0, rel=1e-5)
    again = simulate_record(record, SB_PLANT, p)
    assert rms_error(record.x, again.x, skip=0) < 1e-8


def test_simulate_record_reports_an_escape():
    softening = Duffing1()  # escapes its potential well under 14 N (NOTES.md)
    record = Record(np.arange(400) * 1e-3, np.full(400, 14.0), np.zeros(400), source="step.csv")
    with pytest.raises(RecordError, match="step.csv.*escaped"):
        simulate_record(record, softening, softening.parameters, init_window=0)


# ---------------------------------------------------------------------- refinement
def test_refine_recovers_the_truth_from_a_perturbed_start():
    plant = Duffing1(offset=True)
    truth = {**plant.canonical_parameters(), "c1": 0.4}
    source = Multisine(6.0, 1.0, 20.0, 1.0, phases="random", seed=2)
    exact = simulate(Duffing1(), source, 1.0, 1e-3)  # offset added below: f - c drives the plant
    rng = np.random.default_rng(0)
    noisy = exact.x + 1e-6 * rng.standard_normal(exact.x.shape)
    record = Record(exact.t, exact.f + 0.4, noisy, source="multisine")
    start = {k: v * f for (k, v), f in zip(truth.items(), (1.05, 0.9, 0.95, 1.1, 1.5))}
    result = refine(record, plant, start, interpolation="bandlimited", progress=False)
    assert result.success
    for name, value in truth.items():
        assert result.canonical[name] == pytest.approx(value, rel=2e-3), name
    assert set(result.parameters) == {"m", "b", "k", "kp", "c1"}
    assert result.rms < 2e-6 < result.rms_start
    assert all(0 < v < 0.01 for v in result.relative_std.values())
    assert result.to_dict()["success"] is True


def test_refine_keeps_fixed_parameters():
    plant = Duffing1()
    record = simulate(plant, Multisine(6.0, 1.0, 20.0, 1.0, phases="random", seed=2), 0.5, 1e-3)
    start = {**plant.parameters, "b": 11.0}
    result = refine(record, plant, start, free=["b1"], progress=False)
    assert result.parameters["b"] == pytest.approx(12.47, rel=1e-4)
    assert result.parameters["m"] == plant.parameters["m"]


def test_refine_rejects_bad_starts():
    plant = Duffing1()
    record = simulate(plant, Step(5.0), 0.2, 1e-3)
    with pytest.raises(ValueError, match="not finite"):
        refine(record, plant, {**plant.parameters, "kp": np.nan})
    with pytest.raises(RecordError, match="needs 2 output"):
        refine(record, Duffing2(), Duffing2().parameters)


# ---------------------------------------------------------------------- multiple shooting
def test_stretches_cover_the_record_and_absorb_a_short_remainder():
    assert stretches(10, 4) == [(0, 4), (4, 8), (8, 10)]
    assert stretches(9, 4) == [(0, 4), (4, 9)]
    assert stretches(5, 8) == [(0, 5)]


def test_the_correlation_factor_is_one_for_white_residuals_and_grows_with_colour():
    rng = np.random.default_rng(4)
    white = rng.standard_normal(20_000)
    assert 1.0 <= correlation_factor(white, 200) < 1.1
    coloured = np.empty_like(white)  # AR(1), phi = 0.8: (1 + phi) / (1 - phi) = 9
    coloured[0] = white[0]
    for i in range(1, len(white)):
        coloured[i] = 0.8 * coloured[i - 1] + white[i]
    assert 7.0 < correlation_factor(coloured, 200) < 11.0
    assert correlation_factor(np.column_stack([white, coloured]), 200) == pytest.approx(
        correlation_factor(coloured, 200), rel=1e-12)  # the worst column


def test_stretches_follow_a_plant_that_no_single_simulation_can():
    """A hardening plant at 1.6 % damping under random force drifts: even noise-free, the true
    parameters simulated over the whole record miss it completely after a few seconds. In
    stretches of two periods the refinement recovers the truth within its stated errors."""
    k = (2 * np.pi * 10.0) ** 2
    plant = Duffing1(m=1.0, b=2 * 0.016 * np.sqrt(k), k=k, kp=0.3 * k / 0.01**2)
    force = Multisine(1.5 * k * 0.01, 2.0, 25.0, 4.0, phases="random", seed=7)
    exact = simulate(plant, force, 8.0, 1 / 2000)
    drift = simulate_record(exact, plant, plant.parameters).x - exact.x
    assert np.sqrt(np.mean(drift[-4000:] ** 2)) > 0.3 * np.std(exact.x)
    rng = np.random.default_rng(5)
    record = Record(exact.t, exact.f, exact.x + 0.01 * np.std(exact.x) * rng.standard_normal(exact.x.shape))
    start = {name: 1.02 * value for name, value in plant.parameters.items()}
    result = refine(record, plant, start, segment=400, progress=False)
    assert result.success and result.options["stretches"] == 40
    for name, value in plant.parameters.items():
        u = result.relative_std[plant.canonical_name(name)]
        assert 0 < u < 0.005, name
        assert abs(result.parameters[name] - value) <= 3 * u * value, (name, result.parameters[name], u)
    with pytest.raises(ValueError, match="segment must be a whole number of samples >= 4"):
        refine(record, plant, start, segment=2)
