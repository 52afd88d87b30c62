"""Hilbert-transform nonlinearity index (paper section 2.2).

Tolerances: eta of a linear FRF is 1 to 1e-10 (1e-9 with a synthetic stiffness profile):
eta is a ratio of sums over ~1e4 frequency lines of magnitudes, each rounded to ~1e-15 by the
FFT-based Hilbert transform; a real nonlinearity moves eta by 1e-3 and more.
"""
from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from duffid import Duffing1, Duffing2, Record, RecordError, simulate
from duffid.analysis.frf import (
    LEAKAGE_MAX,
    STATIONARITY_MAX,
    choose_estimator,
    frf_from_h1,
)
from duffid.analysis.nonlinearity import (
    FRF,
    amplitude_sweep,
    analyse,
    fit_rational,
    frf_from_stepped_sines,
    frf_from_sweep,
    hilbert_distortion,
    hilbert_transform,
    nonlinearity_index,
    sweep_record,
)
from duffid.analysis.share import nonlinear_shares
from duffid.analysis.verdict import (
    D_LINEAR_DB,
    D_NONLINEAR_DB,
    SHARE_LINEAR,
    decide_group,
    thresholds,
)
from duffid.cli import main
from duffid.data.signals import Gated, Multisine


def _frf_1dof(f, m=2.53, b=12.47, k=1272.1):
    w = 2 * np.pi * f
    return 1.0 / (k - m * w**2 + 1j * b * w)


def _frf_2dof(f, plant=Duffing2()):
    """x1/f1 of the linearised 2-DOF chain: (K - w^2 M + j w B)^-1 [0, 0]."""
    p = plant.parameters
    M = np.diag([p["m1"], p["m2"]])
    K = np.array([[p["k1"] + p["k2"], -p["k2"]], [-p["k2"], p["k2"]]])
    B = np.array([[p["b1"] + p["b2"], -p["b2"]], [-p["b2"], p["b2"]]])
    w = 2 * np.pi * np.asarray(f)
    return np.array([np.linalg.inv(K - wi**2 * M + 1j * wi * B)[0, 0] for wi in w])


@pytest.mark.parametrize("frf_of, n_modes", [(_frf_1dof, 1), (_frf_2dof, 2)])
def test_hilbert_transform_of_a_causal_frf_is_itself(frf_of, n_modes):
    df = 0.01
    # the FFT machinery alone: the whole grid is the band, the FRF is negligible at Nyquist
    f = np.arange(0, 2000 + df / 2, df)
    F = frf_of(f)
    H = hilbert_transform(FRF(f, F, (0.0, f[-1])), corrected=False)
    assert np.max(np.abs(H - F)) < 1e-6 * np.max(np.abs(F))
    # a narrow band with the correction (fitted linear extension)
    f = np.arange(0, 100 + df / 2, df)
    F = frf_of(f)
    frf = FRF(f, F, (0.5, 12.0))
    H = hilbert_transform(frf, corrected=True, n_modes=n_modes)
    inside = frf.in_band
    assert np.max(np.abs(H[inside] - F[inside])) < 1e-6 * np.max(np.abs(F))
    assert nonlinearity_index(F[inside], H[inside]) == pytest.approx(1.0, abs=1e-10)
    # truncating instead of extending distorts the transform (NOTES.md: band edges matter)
    U = hilbert_transform(frf, corrected=False)
    assert nonlinearity_index(F[inside], U[inside]) < 0.999


def test_rational_fit_recovers_the_modes():
    f = np.arange(0.2, 15, 0.01)
    model = fit_rational(f, _frf_2dof(f), 2)
    np.testing.assert_allclose(model(f), _frf_2dof(f), rtol=1e-8)
    assert np.all(model.poles_hz.real < 0)


def test_distortion_moves_the_indices_the_expected_way():
    """An FRF whose stiffness depends on frequency non-causally (a softening near resonance)."""
    f = np.arange(0, 100, 0.01)
    etas, distortions = [], []
    for eps in (0.0, 0.02, 0.05, 0.1, 0.2):
        k = 1272.1 * (1.0 - eps * np.exp(-(((f - 3.5) / 0.7) ** 2)))
        F = _frf_1dof(f, k=k)
        frf = FRF(f, F, (0.5, 10.0))
        H = hilbert_transform(frf)
        etas.append(nonlinearity_index(F[frf.in_band], H[frf.in_band]))
        distortions.append(hilbert_distortion(F[frf.in_band], H[frf.in_band]))
    assert etas[0] == pytest.approx(1.0, abs=1e-9)
    assert all(a > b for a, b in zip(etas, etas[1:]))
    assert all(a < b for a, b in zip(distortions, distortions[1:]))


def test_linear_plant_eta_at_any_amplitude():
    results = amplitude_sweep([0.1, 3.0, 6.0], Duffing1(kp=0.0))
    for r in results:
        assert r.eta >= 0.9999 and r.verdict == "dominantly linear"
        assert r.eta_uncorrected < r.eta
    assert len({round(r.eta_uncorrected, 9) for r in results}) == 1  # linear: amplitude-free


def test_duffing_eta_decreases_with_amplitude():
    results = amplitude_sweep([0.5, 3.0, 6.0], Duffing1(), rate=2.5)
    etas = [r.eta for r in results]
    assert etas[0] > etas[1] > etas[2] and etas[0] > 0.9999
    assert [r.band for r in results] == [results[0].band] * 3  # compared on one band


@pytest.mark.slow
def test_slow_sweep_crosses_the_threshold_at_6N():
    result = amplitude_sweep([6.0], Duffing1(), rate=0.25)[0]
    assert result.eta < 0.9 and result.verdict == "nonlinear"


def test_stepped_sines_of_a_linear_plant():
    plant = Duffing1(kp=0.0)
    records = []
    for f0 in np.linspace(1.0, 8.0, 12):
        records.append(simulate(plant, lambda t, f0=f0: np.sin(2 * np.pi * f0 * t), 5.0, 2e-3))
    frf = frf_from_stepped_sines(records)
    f, measured = frf.measured
    np.testing.assert_allclose(f, np.linspace(1.0, 8.0, 12), rtol=1e-6)
    np.testing.assert_allclose(measured, _frf_1dof(f), rtol=1e-3)
    assert analyse(frf).eta > 0.9999


def test_errors(tmp_path):
    t = np.arange(40) * 1e-3
    with pytest.raises(RecordError, match="at least 64 samples"):
        frf_from_sweep(Record(t=t, f=np.ones(40), x=np.zeros(40), source="short.csv"))
    record = sweep_record(Duffing1(), 1.0, f_max=5.0)
    with pytest.raises(ValueError, match="no excitation in the band"):
        analyse(record, band=(40.0, 60.0))
    with pytest.raises(ValueError, match="frequency lines"):
        analyse(record, band=(1.0, 1.05))
    silent = Record(t=record.t, f=np.zeros(record.n_samples), x=record.x, source="silent.csv")
    with pytest.raises(ValueError, match="silent.csv.*no energy|no energy"):
        analyse(silent)


def test_cli_json_one_and_several(tmp_path, capsys):
    paths = []
    for a in (0.5, 4.0):
        path = tmp_path / f"sweep_{a}.csv"
        sweep_record(Duffing1(), a, f_max=10.0).to_csv(path)
        paths.append(str(path))
    assert main(["nonlinearity", paths[0], "--json"]) == 0
    one = json.loads(capsys.readouterr().out)
    assert set(one) >= {"eta", "band"} and len(one["band"]) == 2 and one["eta"] > 0.999
    png = tmp_path / "eta.png"
    assert main(["nonlinearity", *paths, "--json", "--uncorrected", "--plot", str(png)]) == 0
    several = json.loads(capsys.readouterr().out)
    assert isinstance(several, list) and len(several) == 2 and not several[0]["corrected"]
    assert png.stat().st_size > 1000
    bad = tmp_path / "bad.csv"
    bad.write_text("t,f,x\n0,1,0\n0.001,nan,0\n")
    assert main(["nonlinearity", str(bad)]) == 2
    assert "bad.csv" in capsys.readouterr().err


def test_gated_sweep_has_a_ring_down():
    record = sweep_record(Duffing1(), 1.0, f_max=5.0, ring_down=4.0)
    assert np.all(record.f[record.t >= 2.0] == 0.0) and np.any(record.f[record.t < 2.0] != 0.0)


def test_a_record_without_ring_down_is_flagged():
    record = sweep_record(Duffing2(), 0.5, f_max=12.0, ring_down=1.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")          # a message in the verdict, not a Python warning
        frf = frf_from_sweep(record)
    assert frf.problems and "has not decayed at the end" in frf.problems[0]
    full = sweep_record(Duffing2(), 0.5, f_max=12.0)  # default: 12 time constants
    assert analyse(full).eta > 0.9999


# ---------------------------------------------------------------------- the verdict (issue 18)
LINEAR = Duffing1(kp=0.0)


def _strict(function, *args, **kwargs):
    """Run with every Python warning an error: the verdict speaks in messages, not warnings."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return function(*args, **kwargs)


def _noisy(record, snr_db, seed=0, force=True):
    rng = np.random.default_rng(seed)

    def add(a):
        return a + rng.standard_normal(a.shape) * np.sqrt(np.mean(a**2, axis=0) / 10 ** (snr_db / 10))
    return Record(t=record.t, f=add(record.f) if force else record.f, x=add(record.x), source=record.source)


def _hardening(share, amplitude=1.0):
    """A hardening plant whose cubic force is ``share`` of the linear one at the linear sweep's peak."""
    peak = np.max(np.abs(sweep_record(LINEAR, amplitude, rate=1.0).x))
    return Duffing1(kp=share * 1272.1 / peak**2)


@pytest.fixture(scope="module")
def random_linear():
    """A linear plant under a stationary random force (random-phase multisine), no ring-down."""
    force = Multisine(1.0, 0.5, 10.0, 32.0, phases="random", seed=1)
    return simulate(LINEAR, force, 32.0, 2e-3, rtol=1e-8, atol=1e-12)


def test_random_force_without_ring_down_is_not_called_nonlinear(random_linear):
    """The issue's case: eta 0.846 and "nonlinear" with a raw UserWarning; now h1 and cannot tell."""
    assert choose_estimator(random_linear) == "h1"
    result = _strict(analyse, random_linear)
    assert result.estimator == "h1" and result.verdict == "cannot tell"
    assert "random force linearises the plant" in result.reasons[0]
    assert "homogeneity test" in result.reasons[0]


def test_sweep_estimator_refuses_a_response_that_has_not_decayed(random_linear):
    result = _strict(analyse, random_linear, estimator="sweep")
    assert result.verdict == "cannot tell" and result.frf.checks["leakage_end"] > LEAKAGE_MAX
    assert "the response has not decayed at the end" in result.reasons[0]
    assert "append a ring-down or use --estimator h1" in result.reasons[0]
    assert np.isfinite(result.eta)   # eta is still reported, as the paper defines it


def test_random_force_with_ring_down_uses_the_ratio_of_transforms():
    force = Gated(Multisine(1.0, 0.5, 10.0, 16.0, phases="random", seed=2), 16.0)
    record = simulate(LINEAR, force, 21.0, 2e-3, rtol=1e-8, atol=1e-12)
    result = _strict(analyse, record)
    assert result.estimator == "sweep" and result.verdict == "dominantly linear" and result.eta > 0.9999


def test_h1_refuses_a_sweep():
    result = _strict(analyse, sweep_record(LINEAR, 1.0, rate=1.0), estimator="h1")
    assert result.frf.checks["stationarity"] > STATIONARITY_MAX
    assert result.verdict == "cannot tell" and "the force is not stationary" in result.reasons[0]


def test_hardening_sweep_at_1N_is_nonlinear():
    """The issue's case: a cubic force of 40 % at the peak read "dominantly linear" (eta 0.93)."""
    result = _strict(analyse, sweep_record(_hardening(0.4), 1.0, rate=1.0))
    assert result.verdict == "nonlinear"
    assert result.distortion_db > D_NONLINEAR_DB and "Hilbert distortion D" in result.reasons[0]


def test_noisy_force_does_not_trip_the_ring_down_check():
    """Noise on the force at the end of a ring-down is not a force left on."""
    record = _noisy(sweep_record(LINEAR, 1.0, rate=1.0), 40.0)
    result = _strict(analyse, record)
    assert result.estimator == "sweep" and not result.frf.problems
    assert result.verdict != "nonlinear"


@pytest.mark.parametrize("snr_db", [30.0, 40.0])
def test_noise_never_reads_nonlinear(snr_db):
    record = _noisy(sweep_record(LINEAR, 1.0, rate=1.0), snr_db, seed=int(snr_db))
    result = _strict(analyse, record)
    assert result.verdict in ("dominantly linear", "cannot tell")
    assert abs(result.distortion_db - result.distortion_floor_db) < 6.0   # the floor predicts D
    if result.verdict == "cannot tell":
        assert "measurement noise alone gives D" in result.reasons[0]


def test_stepped_sines_that_have_not_settled_are_refused():
    records = [simulate(LINEAR, lambda t, f0=f0: np.sin(2 * np.pi * f0 * t), 1.5, 2e-3)
               for f0 in np.linspace(3.0, 8.0, 10)]
    result = _strict(analyse, frf_from_stepped_sines(records))
    assert result.verdict == "cannot tell" and "has not settled" in result.reasons[0]


def test_group_verdicts_and_the_homogeneity_test():
    linear = [analyse(sweep_record(LINEAR, a, rate=1.0)) for a in (0.3, 1.0)]
    group = decide_group([r.decision for r in linear], [r.frf for r in linear])
    assert group.verdict == "dominantly linear" and "changes by" in group.reasons[-1]
    hard = _hardening(0.4)
    nonlinear = [analyse(sweep_record(hard, a, rate=1.0)) for a in (0.3, 1.0)]
    group = decide_group([r.decision for r in nonlinear], [r.frf for r in nonlinear])
    assert group.verdict == "nonlinear" and any("changes with amplitude" in r for r in group.reasons)


def test_random_records_need_several_amplitudes(random_linear):
    low = Record(t=random_linear.t, f=random_linear.f / 3, x=random_linear.x / 3, source="low")
    records = [_noisy(random_linear, 50.0, seed=1), _noisy(low, 50.0, seed=2)]
    results = [_strict(analyse, r) for r in records]
    assert [r.verdict for r in results] == ["cannot tell"] * 2
    group = decide_group([r.decision for r in results], [r.frf for r in results])
    assert group.verdict == "dominantly linear" and "3x amplitude range" in group.reasons[-1]
    same = decide_group([results[0].decision] * 2, [results[0].frf] * 2)   # one amplitude: no test
    assert same.verdict == "cannot tell" and "amplitudes at least" in same.reasons[-1]


def test_nonlinear_share_from_the_identified_model():
    hard = _hardening(0.25)
    record = sweep_record(hard, 1.0, rate=1.0)
    (share,) = nonlinear_shares(record, Duffing1())
    truth = hard.parameters["kp"] * np.max(np.abs(record.x)) ** 2 / hard.parameters["k"]
    assert not share.reason and abs(share.share - truth) <= max(3 * share.uncertainty, 1e-3 * truth)
    assert share.share > SHARE_LINEAR


def test_thresholds_are_named_in_one_place():
    names = thresholds()
    assert names["D_LINEAR_DB"] == D_LINEAR_DB and names["D_NONLINEAR_DB"] == D_NONLINEAR_DB
    assert {"ETA_NONLINEAR", "FLOOR_MARGIN_DB", "HOMOGENEITY_NONLINEAR_DB", "SHARE_LINEAR"} <= set(names)


def test_h1_needs_enough_samples(random_linear):
    short = random_linear.slice(0.0, 0.5)
    with pytest.raises(RecordError, match="segments of .* are too short for H1"):
        frf_from_h1(short, segments=8)


def test_an_frf_without_noise_estimate_is_never_called_nonlinear():
    f = np.arange(0, 100, 0.01)
    k = 1272.1 * (1.0 - 0.2 * np.exp(-(((f - 3.5) / 0.7) ** 2)))
    result = analyse(FRF(f, _frf_1dof(f, k=k), (0.5, 10.0)))
    assert result.distortion_db > D_NONLINEAR_DB
    assert result.verdict == "cannot tell" and "no estimate of its noise" in result.reasons[0]


def test_a_record_that_does_not_start_at_rest_is_refused():
    record = sweep_record(LINEAR, 1.0, rate=1.0)
    late = record.slice(0.5, None)        # cut into the motion: the response is not at rest at the start
    result = _strict(analyse, late, estimator="sweep")
    assert result.verdict == "cannot tell" and "not at rest at the start" in result.reasons[0]


def test_h1_incoherence_beyond_noise_and_resolution_reads_nonlinear(random_linear):
    """Response power not linearly related to the force (here an in-band disturbance): nonlinear."""
    from scipy.signal import butter, sosfiltfilt

    rng = np.random.default_rng(5)
    sos = butter(4, [1.0, 8.0], btype="band", fs=1 / random_linear.dt, output="sos")
    disturbance = sosfiltfilt(sos, rng.standard_normal(random_linear.n_samples))
    disturbance *= 0.5 * np.std(random_linear.x) / np.std(disturbance)
    record = Record(t=random_linear.t, f=random_linear.f, x=random_linear.x[:, 0] + disturbance, source="d")
    result = _strict(analyse, record)
    assert result.estimator == "h1" and result.verdict == "nonlinear"
    assert "is the plant's own distortion, unless an unmeasured force acts on it" in result.reasons[0]


def test_a_group_says_which_records_it_could_not_use():
    good = analyse(sweep_record(LINEAR, 1.0, rate=1.0))
    cut = analyse(sweep_record(LINEAR, 0.3, rate=1.0, ring_down=0.5))
    assert cut.frf.problems
    group = decide_group([good.decision, cut.decision], [good.frf, cut.frf])
    assert group.verdict == "dominantly linear"
    assert any("1 of 2 records cannot be used" in r for r in group.reasons)


def test_h1_on_a_step_force_says_what_to_use_and_warns_nothing():
    """A step force has no energy once Welch removes each segment's mean: a message naming the
    file and the estimator to use, and no RuntimeWarning from the coherence."""
    from duffid import Step

    record = simulate(Duffing1(), Step(10.0), 1.0, 1e-3)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(RecordError, match="no energy once each segment's mean is removed.*--estimator sweep"):
            analyse(record, estimator="h1")
