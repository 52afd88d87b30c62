"""Hilbert-transform nonlinearity index (paper section 2.2).

Tolerances: eta of a linear FRF is 1 to 1e-10 (1e-9 with a synthetic stiffness profile):
eta is a ratio of sums over ~1e4 frequency lines of magnitudes, each rounded to ~1e-15 by the
FFT-based Hilbert transform; a real nonlinearity moves eta by 1e-3 and more.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from duffid import Duffing1, Duffing2, Record, RecordError, simulate
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
from duffid.cli import main


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
    with pytest.warns(UserWarning, match="longer ring-down"):
        frf_from_sweep(record)
    full = sweep_record(Duffing2(), 0.5, f_max=12.0)  # default: 12 time constants
    assert analyse(full).eta > 0.9999
