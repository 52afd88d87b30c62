"""Online identification from a measured velocity or acceleration
(duffid.identification.motion_online): the receding-horizon output-error fit.

The records come from the simulator of ``test_motion`` (SciPy's DOP853, not duffid's), with
the sensor's bias and noise added.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from test_motion import (AMPLITUDE, K, TRUE, changed_plant, measured, plant_motion, quintic_accelerometer,
                         two_dof_accelerations)

from duffid import Duffing1, OnlineMotionIdentifier
from duffid.data.record import Record
from duffid.data.signals import Chirp, Multisine
from duffid.errors import InputError
from duffid.identification.engine import STATUSES
from duffid.identification.motion_online import CHECK_EVERY, MIN_PERIODS, run_motion_online

DT = 2e-4
PUBLISHED, CHANGED = STATUSES[1], STATUSES[4]


def track(ident: OnlineMotionIdentifier, y: np.ndarray, f: np.ndarray) -> dict[str, np.ndarray]:
    """Every sample's published values, standard errors and statuses."""
    out: dict[str, list] = {"status": []}
    for name in ident.names:
        out[name], out[name + "_std"] = [], []
    for yi, fi in zip(y, f):
        est = ident.update(yi, fi)
        out["status"].append(dict(est.status))
        for name in ident.names:
            out[name].append(est.parameters[name])
            out[name + "_std"].append(est.std_errors[name])
    return {k: np.asarray(v) if k != "status" else v for k, v in out.items()}


@pytest.fixture(scope="module")
def accelerometer():
    """The issue's target record: random force 1-30 Hz, acceleration at 5 kHz, bias 1 % of its
    RMS, 50 dB noise, 4 s."""
    force = Multisine(0.8 * K * AMPLITUDE, 1.0, 30.0, 4.0, phases="random", seed=3)
    t, f, _, _, a = plant_motion(force, 4.0, DT)
    return t, measured(f, 60, 1), measured(a, 50, 2, bias_share=0.01)


def test_an_accelerometer_online_publishes_within_one_percent_and_its_errors(accelerometer):
    t, f, a = accelerometer
    ident = OnlineMotionIdentifier(Duffing1(), DT, "a")
    run = track(ident, a, f)
    for name, truth in TRUE.items():
        values, std = run[name], run[name + "_std"]
        published = np.isfinite(values)
        assert published[-1], (name, ident.notes)
        assert published.mean() >= 0.7, name  # published from the first second on
        error = np.abs(values[published] - truth)
        assert np.all(error <= 0.01 * truth), (name, error.max() / truth)
        assert np.all(error <= 4 * std[published]), (name, np.max(error / std[published]))
    assert not any(CHANGED in s.values() for s in run["status"])  # a constant plant: no alarm
    assert ident.fits >= 8 and ident.checks >= 10
    est = ident.estimate()
    assert est.identified and est.window <= 4.0 and 0 < est.residual < 0.01


def test_a_stiffness_step_is_withdrawn_at_once_and_published_again_within_one_percent():
    """k 25 % higher from 4 s of 6 s: the values are withdrawn as "changed" within a check
    period, published again within a second, then within 1 % of the new plant."""
    force = Multisine(0.8 * K * AMPLITUDE, 1.0, 30.0, 6.0, phases="random", seed=3)
    t, f, a, k = changed_plant(force, 6.0, DT, 1.25, 4.0)
    ident = OnlineMotionIdentifier(Duffing1(), DT, "a")
    run = track(ident, measured(a, 50, 2, bias_share=0.01), measured(f, 60, 1))
    step = int(round(4.0 / DT))
    published = np.isfinite(run["k"])
    assert published[step - 1]  # right before the step
    gone = step + int(np.argmax(~published[step:]))
    assert (gone - step) * DT <= CHECK_EVERY / 10.0 + 0.02
    assert run["status"][gone]["k"] == CHANGED
    back = gone + int(np.argmax(published[gone:]))
    assert published[back] and (back - step) * DT <= 1.0
    assert np.all(np.abs(run["k"][back:][published[back:]] / k[back:][published[back:]] - 1) <= 0.01)
    # before the step: the old plant within 1 %; nothing else was published
    before = published[:step]
    assert np.all(np.abs(run["k"][:step][before] / K - 1) <= 0.01)


def test_a_velocity_sensor_under_a_swept_sine_online_within_its_errors():
    """While the sweep has covered little of the band the stated errors are near the 1 % limit
    (measured: b 0.98 % off at 1.13 stated errors); every value is within 4 of them, and at
    the end within 1 %."""
    force = Chirp(0.8 * K * AMPLITUDE, 2.0, 25.0, 6.0)
    t, f, _, v, _ = plant_motion(force, 6.0, 5e-4)
    record = Record(t, measured(f, 60, 3), measured(v, 50, 4, bias_share=0.005), source="vibrometer", motion="v")
    assert run_motion_online(record, Duffing1()).method == "online output-error (velocity)"
    ident = OnlineMotionIdentifier(Duffing1(), record.dt, "v")
    run = track(ident, record.x, record.f)
    assert all(s == PUBLISHED for s in run["status"][-1].values())
    for name, truth in TRUE.items():
        values, std = run[name], run[name + "_std"]
        published = np.isfinite(values)
        assert published[int(2.0 / record.dt)], name  # from 2 s on
        assert np.all(np.abs(values[published] - truth) <= 4 * std[published]), name
        assert abs(values[-1] / truth - 1) <= 0.01, name


def test_an_impact_hammer_online_at_40_db():
    """A blow every second (a 3 ms half-sine), acceleration at 40 dB, 4 s: the first fits on a
    fraction of a blow's decay fail, and must not set the horizon (they once set it to 0.01 s
    from a nonsense fit, and nothing was ever published); every value published is within 4
    of its stated errors and 1 %."""
    def hammer(t):
        phase = np.mod(np.asarray(t, dtype=float) - 0.1, 1.0)
        return np.where(phase < 3e-3, 3.0 * K * AMPLITUDE * np.sin(np.pi * phase / 3e-3), 0.0)

    t, f, _, _, a = plant_motion(hammer, 4.0, DT)
    ident = OnlineMotionIdentifier(Duffing1(), DT, "a")
    run = track(ident, measured(a, 40, 6, bias_share=0.01), measured(f, 50, 5))
    assert ident.horizon == pytest.approx(4.0, rel=0.05)  # 40 natural periods
    for name, truth in TRUE.items():
        values, std = run[name], run[name + "_std"]
        published = np.isfinite(values)
        assert published[-1], (name, ident.notes)
        assert np.all(np.abs(values[published] - truth) <= np.minimum(4 * std[published], 0.01 * truth)), name


def test_a_plant_the_model_does_not_fit_is_never_published_online():
    force = Multisine(0.8 * K * AMPLITUDE, 1.0, 30.0, 3.0, phases="random", seed=7)
    t, f, _, _, a = plant_motion(force, 3.0, DT, quadratic=0.6 * K / AMPLITUDE)
    ident = OnlineMotionIdentifier(Duffing1(), DT, "a")
    run = track(ident, measured(a, 50, 8), measured(f, 60, 7))
    assert not any(np.isfinite(run[name]).any() for name in TRUE)
    assert any("misses the measured acceleration" in note for note in ident.notes), ident.notes


def test_a_term_the_model_lacks_keeps_the_values_it_moves_unpublished_online(monkeypatch):
    """The weak x^5 spring of test_motion at 40 dB: every fit that could publish k and kp is
    either probed (PROBE_EVERY, PROBE_GROWTH) or keeps the latest probe's finding, so neither is
    ever shown (before PROBE_GROWTH, kp was shown 1.4 % off at 16 stated errors for 2.5 s);
    what is shown stays near its stated errors (b within 3.5: it moves with the term by less
    than TERM_MOVE_SIGMAS)."""
    probed = []  # whether each horizon fit was probed
    apply_probe = OnlineMotionIdentifier._apply_probe

    def recording(self, result, probe, samples):
        probed.append(probe)
        apply_probe(self, result, probe, samples)

    monkeypatch.setattr(OnlineMotionIdentifier, "_apply_probe", recording)
    record = quintic_accelerometer(DT)
    ident = OnlineMotionIdentifier(Duffing1(), DT, "a")
    run = track(ident, record.x, record.f)
    assert not np.isfinite(run["k"]).any() and not np.isfinite(run["kp"]).any()
    assert np.isfinite(run["m"]).any()
    assert True in probed and False in probed  # ... so fits that were not probed kept the finding
    for name in ("m", "b"):
        shown = np.isfinite(run[name])
        assert np.all(np.abs(run[name][shown] - TRUE[name]) <= 3.6 * run[name + "_std"][shown]), name
    assert any("x^5 stiffness term the model lacks" in note for note in ident.notes), ident.notes


@pytest.mark.slow
def test_a_two_dof_chain_online_from_accelerations():
    from duffid import Duffing2

    model, record = two_dof_accelerations()
    result = run_motion_online(record, Duffing2())
    assert all(s == PUBLISHED for s in result.online_status.values())
    for name, value in model.parameters.items():
        h = result.history[name]
        assert np.all(np.abs(h[np.isfinite(h)] / value - 1) <= 0.01), name


def test_a_gap_restarts_the_horizon_and_keeps_the_values(accelerometer):
    t, f, a = accelerometer
    ident = OnlineMotionIdentifier(Duffing1(), DT, "a", horizon=1.0)
    n = int(2.0 / DT)
    for i in range(n):
        est = ident.update(a[i], f[i])
    assert est.identified
    ident.hold()
    est = ident.update(a[n + 100], f[n + 100])  # 100 samples later
    assert est.identified and est.window == pytest.approx(DT)
    ident.reset()
    est = ident.update(a[0], f[0])
    assert not est.identified and all(math.isnan(v) for v in est.parameters.values())


def test_a_short_horizon_is_not_published_before_enough_periods(accelerometer):
    t, f, a = accelerometer
    ident = OnlineMotionIdentifier(Duffing1(), DT, "a", horizon=0.3, max_horizon=0.3)
    run = track(ident, a[:8000], f[:8000])
    assert not any(np.isfinite(run[name]).any() for name in TRUE)
    assert any(f"published from {MIN_PERIODS:g}" in note for note in ident.notes), ident.notes


def test_bad_arguments_and_samples_are_refused():
    with pytest.raises(InputError, match="motion must be one of v, a"):
        OnlineMotionIdentifier(Duffing1(), DT, "x")
    with pytest.raises(InputError, match="dt must be a positive"):
        OnlineMotionIdentifier(Duffing1(), 0.0)
    with pytest.raises(InputError, match="horizon must be 'auto' or a positive number"):
        OnlineMotionIdentifier(Duffing1(), DT, horizon=-1.0)
    with pytest.raises(InputError, match="max_uncertainty must be a positive"):
        OnlineMotionIdentifier(Duffing1(), DT, max_uncertainty=math.nan)
    ident = OnlineMotionIdentifier(Duffing1(), DT, "v")
    with pytest.raises(InputError, match="1 velocity"):
        ident.update([1.0, 2.0], 0.0)
    with pytest.raises(InputError, match="non-finite velocity or force"):
        ident.update(math.nan, 0.0)
    with pytest.raises(Exception, match="measures a displacement"):
        run_motion_online(Record(np.arange(10) * DT, np.zeros(10), np.zeros(10), source="r"), Duffing1())


def test_the_cli_plots_the_online_fit_of_an_accelerometer_record(accelerometer, tmp_path, capsys):
    from duffid.cli import main

    t, f, a = accelerometer
    path = tmp_path / "rig.csv"
    n = int(2.0 / DT)
    np.savetxt(path, np.column_stack([t[:n], f[:n], a[:n]]), delimiter=",", header="time,load,acc\ns,N,m/s^2",
               comments="", fmt="%.17g")
    plot = tmp_path / "online.png"
    assert main(["identify", str(path), "--columns", "t=time,f=load,a=acc", "--model", "duffing1",
                 "--plot", str(plot)]) == 0
    assert "published" in capsys.readouterr().out
    assert plot.stat().st_size > 10_000
