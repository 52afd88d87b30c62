"""A plant that changes during an online identification: detected, withdrawn, re-identified.

The records are simulated with :func:`duffid.simulate`'s ``changes`` (a plant of another
scale than the paper's: 0.8 kg, 16 Hz, hardening), band-limited random force, 50 dB noise
on the displacement. The targets are the issue's: at every sample a published value lies
within 5 % of the truth at some instant of the last second, and after the change every
changed parameter is published again within 2 %.
"""
from __future__ import annotations

import shutil

import numpy as np
import pytest

from duffid import Chirp, Duffing1, DuffingCircuit, Multisine, OnlineIdentifier, measure, simulate
from duffid.errors import InputError
from duffid.identification.c_core import CIdentifier
from duffid.identification.engine import (CHANGE_ALONE_SHARE, STATUSES, DriftLine, _alone, recent_solution,
                                         solve_factor, triangular_factor)

pytestmark = pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None,
                                reason="no C compiler")

DT = 5e-4
M, K, B = 0.8, 0.8 * (2 * np.pi * 16.0) ** 2, 2 * 0.03 * np.sqrt(0.8 * 0.8 * (2 * np.pi * 16.0) ** 2)
AMPLITUDE = 2e-3  # m: kp x^2 / k = 0.5 there
KP = 0.5 * K / AMPLITUDE**2
NAMES = ("m", "b", "k", "kp")


def plant(**changed: float) -> Duffing1:
    return Duffing1(**{"m": M, "b": B, "k": K, "kp": KP, **changed})


def record_of(changes: list[tuple[float, Duffing1]], t_end: float = 4.0, seed: int = 3):
    force = Multisine(0.9 * K * AMPLITUDE, 2.0, 40.0, t_end, phases="random", seed=seed)
    exact = simulate(plant(), force, t_end, DT, changes=changes)
    return measure(exact, pulses_per_cm=None, snr_db=50, seed=seed + 1)


def truth_of(record, changes: list[tuple[float, Duffing1]]) -> np.ndarray:
    """Samples x parameters: the plant's true values at each sample."""
    t = record.t - record.t[0]
    out = np.tile([plant().parameters[n] for n in NAMES], (len(t), 1))
    for time, p in changes:
        out[t >= time - 1e-12] = [p.parameters[n] for n in NAMES]
    return out


def run_c(record, **options):
    ident = CIdentifier(Duffing1(), DT, **options)
    rows = ident.run(record.x, record.f)
    return rows["parameters"][:, :4], np.array([[STATUSES[c] for c in r[:4]] for r in rows["status"]])


def worst_against_last_second(values: np.ndarray, truth: np.ndarray) -> float:
    """The largest relative distance of a published value from the truth at any instant of the
    second before it (the issue's measure of a stale value)."""
    span = int(round(1.0 / DT))
    worst = 0.0
    for j in range(values.shape[1]):
        for i in np.flatnonzero(np.isfinite(values[:, j])):
            window = truth[max(0, i - span):i + 1, j]
            worst = max(worst, float(np.min(np.abs(values[i, j] - window) / np.abs(window))))
    return worst


@pytest.fixture(scope="module")
def stiffness_step():
    changes = [(2.0, plant(k=1.25 * K))]
    record = record_of(changes)
    return record, truth_of(record, changes)


@pytest.fixture(scope="module")
def payload():
    changes = [(2.0, plant(m=1.2 * M))]
    record = record_of(changes, seed=5)
    return record, truth_of(record, changes)


@pytest.mark.parametrize("case, changed", [("stiffness_step", "k"), ("payload", "m")])
def test_a_step_is_flagged_withdrawn_and_re_identified(request, case, changed):
    record, truth = request.getfixturevalue(case)
    values, status = run_c(record)
    t = record.t - record.t[0]
    j = NAMES.index(changed)
    assert (status[t < 2.0] != "changed").all()  # before the change: nothing flagged
    flagged = np.flatnonzero(status[:, j] == "changed")
    assert flagged.size and 2.0 <= t[flagged[0]] <= 2.6, "the change is flagged within 0.6 s"
    # the parameters that did not change are never called changed (they are re-identified)
    others = [i for i, name in enumerate(NAMES) if name != changed]
    assert (status[:, others] != "changed").all()
    assert worst_against_last_second(values, truth) <= 0.05
    end = t >= t[-1] - 0.5  # the last half second: the new value published within 2 %
    assert (status[end, j] == "published").all()
    assert np.max(np.abs(values[end, j] - truth[end, j]) / truth[end, j]) <= 0.02


def test_without_the_change_test_the_old_value_is_never_published_again(stiffness_step):
    """Without the test the estimate over every window since the start blends both plants:
    the moved estimate withdraws the old value (lost) and nothing after the step is published
    near the old stiffness either (the blend is never steady enough to publish)."""
    record, truth = stiffness_step
    values, status = run_c(record, change_threshold=None)
    t = record.t - record.t[0]
    j = NAMES.index("k")
    assert not (status[:, j] == "changed").any()
    late = (t > 2.6) & np.isfinite(values[:, j])
    assert np.all(np.abs(values[late, j] - K) > 0.05 * K) or not late.any()


def test_a_constant_plant_raises_no_change(stiffness_step):
    changes: list = []
    record = record_of(changes, seed=9)
    values, status = run_c(record)
    assert (status != "changed").all()
    assert worst_against_last_second(values, truth_of(record, changes)) <= 0.05
    assert (status[-1, [0, 2, 3]] == "published").all()


def test_a_swept_sine_on_a_constant_plant_raises_no_change():
    """The Duffing circuit of benchmarks/trust.py under a sine swept from 0.3 to 2.5 times its
    resonance, 40 dB: above the resonance the recent rows' band is narrow, the mass and the
    stiffness almost collinear, and the recent solution slides along that pair (m -24 %,
    1/C -97 %, 5 combined standard errors from the accumulated one) while either alone
    barely improves the prediction. Before the confirmation (CHANGE_ALONE_SHARE) the C core
    flagged this record at 3.37 s."""
    plant_ = DuffingCircuit()
    k = plant_.canonical_parameters()["k1_1"]
    dt, t_end, f_n = 5e-4, 4.0, 15.9
    exact = simulate(plant_, Chirp(0.6 * k * 5e-3, 0.3 * f_n, 2.5 * f_n, t_end), t_end, dt)
    record = measure(exact, pulses_per_cm=None, snr_db=40, seed=11)
    rows = CIdentifier(DuffingCircuit(), dt).run(record.x, record.f)
    status = rows["status"][:, :4]
    assert not (status == STATUSES.index("changed")).any()
    assert (status[-1] == STATUSES.index("published")).sum() >= 3  # the record does identify the plant


def test_the_confirmation_tells_one_changed_unknown_from_a_joint_slide():
    """engine._alone on rows whose first two columns are almost collinear: a misfit in the
    third unknown alone is confirmed for it; a slide along the collinear pair (as large in
    parameters) is confirmed for none, though the rows' own solution removes it."""
    rng = np.random.default_rng(1)
    x1 = rng.standard_normal(400)
    A = np.column_stack([x1, -x1 + 0.02 * rng.standard_normal(400), rng.standard_normal(400)])
    theta = np.array([1.0, 1.0, 1.0])
    D = A @ theta + 1e-3 * rng.standard_normal(400)
    R = triangular_factor(np.column_stack([A, D]), 4)
    changed = _alone(R, theta + [0.0, 0.0, 0.1], CHANGE_ALONE_SHARE)
    assert changed.tolist() == [False, False, True]
    slid = theta + [0.1, 0.1, 0.0]
    assert np.linalg.norm(R @ np.append(slid, -1.0)) > 2 * abs(R[3, 3])  # a misfit the joint fit removes
    assert not _alone(R, slid, CHANGE_ALONE_SHARE).any()
    assert not _alone(R, np.array([np.nan, 1.0, 1.0]), CHANGE_ALONE_SHARE).any()


def test_the_recent_solution_is_solve_factors_without_the_condition():
    """engine.recent_solution (the change test's recent estimate, no singular values) gives
    solve_factor's unknowns and standard errors to rounding, and refuses a singular factor."""
    rng = np.random.default_rng(2)
    for scales in ([1.0, 1.0, 1.0, 1.0], [1e-3, 10.0, 1e4, 1e8]):
        A = rng.standard_normal((300, 4)) * scales
        D = A @ [1.0, -2.0, 3.0, 0.5] + 0.1 * rng.standard_normal(300)
        R = triangular_factor(np.column_stack([A, D]), 5)
        theta, _, rse = solve_factor(R, 300.0, 50.0)[:3]
        got, got_rse = recent_solution(R, 300.0, 50.0)
        # to rounding: relative, or (a badly scaled column's unknown, which cancels) far below its error
        assert np.all(np.abs(got - theta) <= np.maximum(1e-12 * np.abs(theta), 1e-6 * rse * np.abs(theta)))
        # a relative error inherits the unknown's rounding: as large as that cancellation allows
        assert np.all(np.abs(got_rse - rse) <= np.maximum(1e-9, 1e-6 * rse) * rse)
    A[:, 1] = A[:, 0] * (scales[1] / scales[0])  # two proportional columns: singular
    R = triangular_factor(np.column_stack([A, D]), 5)
    assert np.isnan(recent_solution(R, 300.0, 50.0)[0]).all()
    assert np.isinf(recent_solution(R, 300.0, 50.0)[1]).all()


def drift_of(share: float, t_end: float = 4.0) -> list[tuple[float, Duffing1]]:
    """A linear drift of k by ``share`` over ``t_end`` s, as a staircase of 200 steps."""
    return [(t_end * i / 200, plant(k=K * (1 + share * i / 200))) for i in range(1, 200)]


@pytest.fixture(scope="module")
def stiffness_drift():
    changes = drift_of(-0.2)
    record = record_of(changes)
    return record, truth_of(record, changes)


@pytest.mark.parametrize("share, seed", [(-0.2, 3), (0.2, 4)])
def test_a_drift_is_flagged_and_no_published_value_goes_stale(share, seed):
    """A drift of 20 % over 4 s moves the recent estimate by less than the threshold's standard
    errors but beyond the band a value may move; lasting the recent memory, that is a change
    too (CHANGE_DRIFT_SHARE). Without that rule the second record published a stiffness 5.2 %
    from every true value of the second before it. The drift probe sees it sooner."""
    changes = drift_of(share)
    record = record_of(changes, seed=seed)
    values, status = run_c(record)
    flagged = np.flatnonzero(status[:, NAMES.index("k")] == "changed")
    # the drift probe (DRIFT_SIGMAS) sees it within 0.9 s (measured 0.67 and 0.80 s; the
    # recent estimate alone flagged it at 1.20 and 1.22 s)
    assert flagged.size and record.t[flagged[0]] - record.t[0] <= 0.9
    assert worst_against_last_second(values, truth_of(record, changes)) <= 0.05


def test_after_a_change_nothing_is_published_before_its_rows_span_a_window(stiffness_step):
    """The rows after a change begin a window later; until they span another window, they
    rest on one window's samples and their standard errors are not credible (measured on a
    drift: a stiffness published 6.2 % off with a stated error of 0.77 %)."""
    record, _ = stiffness_step
    rows = CIdentifier(Duffing1(), DT).run(record.x, record.f)
    status = rows["status"][:, :4]
    flag = int(np.flatnonzero((status == STATUSES.index("changed")).any(axis=1))[0])
    target = int(round(rows["window"][flag] / DT))
    for j, name in enumerate(NAMES):
        again = np.flatnonzero(status[flag:, j] == STATUSES.index("published"))
        assert again.size and again[0] >= 2 * target, name


def test_after_a_drift_is_flagged_the_drifting_stiffness_is_tracked():
    """Once flagged, the drifting stiffness is a line in time (engine.DriftLine): published at
    the line's newest value, within 2 % of the truth over the last second of the record (a
    constant over the samples since the flag lagged the drift by half of them: 2.7-5.4 %,
    or unpublished), and not flagged again while the drift stays linear."""
    changes = drift_of(0.2, t_end=6.0)
    record = record_of(changes, t_end=6.0, seed=4)
    values, status = run_c(record)
    truth = truth_of(record, changes)
    j = NAMES.index("k")
    flags = np.flatnonzero(np.diff((status[:, j] == "changed").astype(int)) == 1)
    assert len(flags) == 1
    last = record.t - record.t[0] >= 5.0
    assert np.isfinite(values[last, j]).all()
    assert np.max(np.abs(values[last, j] - truth[last, j]) / truth[last, j]) <= 0.02
    assert worst_against_last_second(values, truth) <= 0.05


def test_a_drifting_stiffness_and_the_others_are_published_within_their_stated_errors():
    """A line's rows weigh each sample's term by its own time (DriftLine, KernelBank.within):
    with every sample at the window's newest time instead, the line lagged by half a window
    (k's mean error over the last second 0.16 %, 40 of its stated errors) and the drift within
    each window went into the others (b published 1.7-3 % off with stated errors of 0.3-0.7 %
    for 70 % of the record, m 0.2 % off at 0.04 %). Before the drift probe restarts the
    equation, a published constant includes the probe's drift to now in its error
    (DRIFT_BIAS_SIGMAS): k's published samples further than 3 stated errors from the truth fell
    from 84 % to 7 % (the rest: before the probe's rates are significant)."""
    changes = drift_of(0.2, t_end=6.0)
    record = record_of(changes, t_end=6.0, seed=4)
    rows = CIdentifier(Duffing1(), DT).run(record.x, record.f)
    values, errors, truth = rows["parameters"][:, :4], rows["std_errors"][:, :4], truth_of(record, changes)
    shown = np.isfinite(values)
    beyond = shown & (np.abs(values - truth) > 3 * errors)
    j = NAMES.index("k")
    last = record.t - record.t[0] >= 5.0
    assert abs(np.mean((values[last, j] - truth[last, j]) / truth[last, j])) <= 0.001
    assert np.count_nonzero(beyond[:, j]) <= 0.15 * np.count_nonzero(shown[:, j])
    for name in ("m", "b"):  # measured: none (4,535 and 7,954 samples before)
        assert np.count_nonzero(beyond[:, NAMES.index(name)]) <= 0.01 * len(values), name


def test_a_drift_line_is_the_least_squares_line_with_its_standard_errors():
    """DriftLine's value and standard error at a time equal those of the explicit least squares
    with the rate columns (numpy's lstsq and covariance)."""
    rng = np.random.default_rng(7)
    t = np.repeat(np.linspace(0.0, 2.0, 100), 3)
    A = rng.normal(size=(300, 3)) * [1.0, 50.0, 3e3]
    truth = np.array([2.0, 0.1, 4e-3])
    D = A @ truth + 0.01 * A[:, 2] * t * truth[2] * 50 + rng.normal(scale=0.5, size=300)
    line = DriftLine(np.array([False, False, True]))
    rows = np.vstack([line.rows(A[i:i + 1], t[i]) for i in range(300)])
    R = triangular_factor(np.column_stack([rows, D]), line.size + 1)
    line.solve(R, 300.0, 1.0)
    theta, *_ = np.linalg.lstsq(rows, D, rcond=None)
    s2 = np.sum((D - rows @ theta) ** 2) / (300 - line.size)
    cov = s2 * np.linalg.inv(rows.T @ rows)
    for time in (0.0, 1.3, 2.0):
        value, rse = line.at(time)
        c = np.zeros(line.size)
        c[2], c[3] = 1.0, time
        assert np.allclose(value[:2], theta[:2], rtol=1e-10)
        assert value[2] == pytest.approx(c @ theta, rel=1e-10)
        assert rse[2] * abs(value[2]) == pytest.approx(np.sqrt(c @ cov @ c), rel=1e-8)
        assert rse[0] * abs(value[0]) == pytest.approx(np.sqrt(cov[0, 0]), rel=1e-8)


@pytest.mark.parametrize("case, span", [("stiffness_step", (0.6, 3.6)), ("stiffness_drift", (0.0, 3.5))])
def test_python_and_c_agree_across_a_change(request, case, span):
    record, _ = request.getfixturevalue(case)
    part = record.slice(*span)
    py = OnlineIdentifier(Duffing1(), DT)
    estimates = [py.update(x, f) for x, f in zip(part.x, part.f)]
    values, status = run_c(part)
    py_values = np.array([[e.parameters[n] for n in NAMES] for e in estimates])
    py_status = np.array([[e.status[n] for n in NAMES] for e in estimates])
    assert (py_status == status).all()
    assert (py_status == "changed").any()
    both = np.isfinite(py_values)
    assert np.array_equal(both, np.isfinite(values))
    assert np.max(np.abs(values[both] - py_values[both]) / np.abs(py_values[both])) < 1e-8


def test_standard_errors_and_residual_are_reported(payload):
    record, truth = payload
    ident = CIdentifier(Duffing1(), DT)
    estimates = [ident.update(x, f) for x, f in zip(record.x[:3000], record.f[:3000])]
    last = estimates[-1]
    for name in NAMES:
        if last.status[name] == "published":
            se = last.std_errors[name]
            assert 0 < se < 0.01 * abs(last.parameters[name])  # within max_uncertainty
        else:
            assert np.isnan(last.std_errors[name])
    assert 0 < last.residual < 1
    # the window that first holds the heavier mass predicts its forces badly
    t = record.t - record.t[0]
    after = ident.run(record.x[3000:], record.f[3000:])
    before_change = [e.residual for e, ti in zip(estimates, t) if 1.0 < ti < 2.0]
    at_change = after["residual"][(t[3000:] > 2.0) & (t[3000:] < 2.1)]
    assert np.nanmax(at_change) > 5 * np.nanmax(before_change)


@pytest.mark.parametrize("options, message", [
    ({"change_threshold": -1.0}, "change_threshold"),
    ({"change_memory": 0.0}, "change_memory"),
    ({"change_memory": "soon"}, "change_memory"),
])
def test_bad_change_options_are_refused(options, message):
    with pytest.raises(InputError, match=message):
        OnlineIdentifier(Duffing1(), DT, **options)


@pytest.mark.parametrize("engine", ["python", "c"])
def test_hold_keeps_the_estimates_over_a_gap(payload, engine):
    """Samples 1.2-1.5 s are not given (the FMUs' enable input false): the published values
    are reported unchanged while the window grows again, and identification goes on."""
    record, truth = payload
    part = record.slice(0.0, 1.9)
    t = part.t - part.t[0]
    ident = OnlineIdentifier(Duffing1(), DT) if engine == "python" else CIdentifier(Duffing1(), DT)
    before = after = estimate = None
    for i, (x, f) in enumerate(zip(part.x, part.f)):
        if 1.2 <= t[i] < 1.5:
            if before is None:
                ident.hold()
                before = estimate
            continue
        estimate = ident.update(x, f)
        if before is not None and t[i] < 1.5 + 0.9 * 0.1:  # well within the window's regrowth
            assert estimate.parameters == before.parameters or all(
                np.isnan(a) and np.isnan(b) or a == b
                for a, b in zip(estimate.parameters.values(), before.parameters.values()))
            assert estimate.status == before.status
        after = estimate
    assert before.status["k"] == "published" and after.status["k"] == "published"
    assert abs(after.parameters["k"] - K) <= 0.02 * K


def test_python_and_c_hold_alike(payload):
    record, _ = payload
    part = record.slice(0.0, 1.8)
    t = part.t - part.t[0]
    runs = []
    for ident in (OnlineIdentifier(Duffing1(), DT), CIdentifier(Duffing1(), DT)):
        out = []
        for i, (x, f) in enumerate(zip(part.x, part.f)):
            if 1.0 <= t[i] < 1.2:
                if t[i - 1] < 1.0:
                    ident.hold()
                continue
            e = ident.update(x, f)
            out.append([e.parameters[n] for n in NAMES] + [float(e.status[n] == "published") for n in NAMES])
        runs.append(np.array(out))
    py, c = runs
    assert np.array_equal(np.isnan(py), np.isnan(c))
    ok = np.isfinite(py)
    assert np.max(np.abs(py[ok] - c[ok]) / np.maximum(np.abs(py[ok]), 1e-300)) < 1e-8


# ---------------------------------------------------------------------- the estimator FMUs
@pytest.fixture(scope="module")
def estimator_fmus(tmp_path_factory):
    from duffid.fmu.estimator import build_estimator_fmu

    out = tmp_path_factory.mktemp("fmus")
    return {version: build_estimator_fmu("duffing1", out, fmi_version=version) for version in (2, 3)}


def _fmu_run(fmu, record, enable=None, reset=None):
    import fmpy

    fields = [("time", float), ("x", float), ("f", float), ("enable", bool), ("reset", bool)]
    sig = np.zeros(record.n_samples, dtype=fields)
    sig["time"] = np.arange(record.n_samples) * record.dt
    sig["x"], sig["f"] = record.x[:, 0], record.f[:, 0]
    sig["enable"] = True if enable is None else enable
    sig["reset"] = False if reset is None else reset
    return fmpy.simulate_fmu(str(fmu), start_time=0.0, stop_time=record.n_samples * record.dt,
                             output_interval=record.dt, input=sig, start_values={"sample_period": record.dt},
                             output=["k_hat", "k_status", "k_std_error", "m_hat", "residual"])


@pytest.mark.parametrize("version", [2, 3])
def test_the_fmus_flag_a_step_and_publish_the_new_stiffness(estimator_fmus, stiffness_step, version):
    from fmpy.validation import validate_fmu

    assert validate_fmu(str(estimator_fmus[version])) == []
    record, truth = stiffness_step
    result = _fmu_run(estimator_fmus[version], record)
    values, status = run_c(record)
    n = min(len(result), len(values))
    # the FMU outputs the core's estimate of each sample (one step late: outputs follow doStep)
    k_fmu, k_core = result["k_hat"][1:n], values[: n - 1, 2]
    assert np.array_equal(np.isnan(k_fmu), np.isnan(k_core))
    assert np.allclose(k_fmu[np.isfinite(k_fmu)], k_core[np.isfinite(k_core)], rtol=1e-12, atol=0)
    codes = result["k_status"]
    assert (codes == STATUSES.index("changed")).any()
    assert codes[-1] == STATUSES.index("published") and abs(result["k_hat"][-1] - 1.25 * K) <= 0.02 * 1.25 * K
    se = result["k_std_error"][-1]
    assert 0 < se < 0.01 * result["k_hat"][-1]
    assert np.nanmax(result["residual"]) > 0


def test_an_fmu_state_with_drift_lines_round_trips(estimator_fmus, stiffness_drift, tmp_path):
    """After a flag the stiffness is a line (more unknowns in the state block): a serialized
    state restored in another instance continues exactly as the original."""
    from fmu_helpers import start_fmi2

    from duffid.fmu.estimator_table import TYPES

    record, _ = stiffness_drift
    values, status = run_c(record)
    flag = int(np.flatnonzero(status[:, NAMES.index("k")] == "changed")[0])
    stop = min(flag + int(1.0 / DT), record.n_samples - 200)

    def step(fmu, vr, k):
        fmu.setReal([vr["x"], vr["f"]], [float(record.x[k, 0]), float(record.f[k, 0])])
        fmu.doStep(currentCommunicationPoint=k * DT, communicationStepSize=DT)
        return fmu.getReal([vr["k_hat"], vr["k_std_error"], vr["residual"]])

    fmu, vr = start_fmi2(estimator_fmus[2], tmp_path, [], {"sample_period": DT}, TYPES)
    other, vr2 = start_fmi2(estimator_fmus[2], tmp_path, [], {"sample_period": DT}, TYPES)
    try:
        for k in range(stop):
            step(fmu, vr, k)
        data = fmu.serializeFMUstate(fmu.getFMUstate())
        reference = np.array([step(fmu, vr, k) for k in range(stop, stop + 200)])
        assert np.isfinite(reference[:, 0]).any()
        other.setFMUstate(other.deSerializeFMUstate(data))
        again = np.array([step(other, vr2, k) for k in range(stop, stop + 200)])
        np.testing.assert_array_equal(again, reference)
    finally:
        fmu.freeInstance()
        other.freeInstance()


def test_the_fmu_holds_while_disabled_and_resets_on_request(estimator_fmus, payload):
    record, _ = payload
    part = record.slice(0.0, 1.9)
    t = np.arange(part.n_samples) * part.dt
    enable = ~((t >= 1.2) & (t < 1.4))
    result = _fmu_run(estimator_fmus[2], part, enable=enable)
    held = (result["time"] > 1.2 + 2 * part.dt) & (result["time"] < 1.4)
    k = result["k_hat"][held]
    assert np.isfinite(k).all() and np.all(k == k[0])  # the published value holds
    assert np.isfinite(result["k_hat"][-1]) and abs(result["k_hat"][-1] - K) <= 0.02 * K
    reset = np.zeros(part.n_samples, dtype=bool)
    reset[int(1.5 / part.dt)] = True
    again = _fmu_run(estimator_fmus[2], part, reset=reset)
    after = (again["time"] > 1.5 + 2 * part.dt) & (again["time"] < 1.55)
    assert np.isnan(again["k_hat"][after]).all()  # a new identification: nothing published yet


# ---------------------------------------------------------------------- offline: where and each stretch
def test_find_changes_names_the_parameter_and_brackets_the_time(stiffness_step):
    from duffid.identification.changes import find_changes

    record, _ = stiffness_step
    changes = find_changes(record, Duffing1())
    assert len(changes) == 1
    change = changes[0]
    assert change.parameters == ("k",)
    assert change.onset <= 2.0 <= change.flagged <= 2.6
    assert change.describe().startswith("k changed between")


def test_identify_segments_identifies_each_plant(stiffness_step):
    from duffid.identification.changes import identify_segments

    record, _ = stiffness_step
    segments = identify_segments(record, Duffing1())
    assert len(segments) == 2
    for segment, k in zip(segments, (K, 1.25 * K)):
        a = segment.result.assessment
        assert a.status["k"] == "published"
        assert abs(segment.result.parameters["k"] - k) <= 3 * a.uncertainty["k"] * k + 1e-3 * k


def test_the_cli_says_the_plant_changed_and_segments_it(stiffness_step, tmp_path, capsys):
    import json

    from duffid.cli import main

    record, _ = stiffness_step
    path = tmp_path / "step.csv"
    np.savetxt(path, np.column_stack([record.t, record.f[:, 0], record.x[:, 0]]), delimiter=",",
               header="t,f,x", comments="")
    assert main(["identify", str(path), "--model", "duffing1"]) == 0
    assert "the online change test flagged a change of the plant: k changed between" in capsys.readouterr().out
    assert main(["identify", str(path), "--model", "duffing1", "--segments", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert [c["parameters"] for c in out["changes"]] == [["k"]]
    assert len(out["segments"]) == 2 and all(s["result"] is not None for s in out["segments"])
    assert main(["identify", str(path), "--model", "duffing1", "--segments", "--method", "legendre"]) != 0
    assert "--segments: the change test is the robust method's; --method legendre has none" in capsys.readouterr().err
    assert main(["identify", str(path), "--model", "duffing1", "--segments", "--change-threshold", "none"]) != 0
    assert "--segments needs the change test" in capsys.readouterr().err
