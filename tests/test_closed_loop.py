"""The main job's closed loops: plant FMU <-> estimator FMU <-> controller FMU in co-simulation.

Tolerances: the container FMU runs the very binaries of the orchestrated loop (C built with
-ffp-contract=off, no BLAS), so the two runs agree to rounding: 1e-12 relative. The recorded
reference results (closed_loop_reference.json) are compared at 1e-6 relative: they come from
closed loops whose estimates pass through the Python-free C core only, but a reference must
survive compiler and libm changes. Times are sample times (k * dt): 1e-9 s absolute.
"""
from __future__ import annotations

import json
import math
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import fmpy
import numpy as np
import pytest

from duffid.control.closed_loop import (
    CLOSED_LOOP_OUTPUTS,
    LoopCase,
    SineReference,
    build_closed_loop_fmu,
    closed_loop_case,
    ensure_fmus,
    loop_cases,
    loop_system,
    run_loop,
)
from duffid.cosim.system import System


@pytest.fixture(scope="session")
def loop_1dof(loop_fmus):
    return run_loop(loop_cases()["oscillator1dof"], loop_fmus)


def test_sine_reference_is_vectorised_and_checked():
    ref = SineReference(1.0, (2.0,), (0.5,))
    assert ref(0.5) == pytest.approx(1.0 + 2.0)
    assert np.allclose(ref(np.array([0.0, 0.5])), [1.0, 3.0])
    assert ref.peak == 3.0
    with pytest.raises(ValueError, match="amplitudes"):
        SineReference(0.0, (1.0,), ())


def test_references_stay_inside_the_safe_range():
    cases = loop_cases()
    # the 1-DOF softening spring peaks at ~18.5 mm: the reference keeps well below it
    assert cases["oscillator1dof"].reference.peak <= 8.5e-3
    assert cases["oscillator2dof"].reference.peak <= 8.5e-3


REFERENCE = Path(__file__).with_name("closed_loop_reference.json")


@pytest.mark.parametrize("name", ["oscillator1dof", "oscillator2dof", "duffing_circuit"])
def test_loops_reproduce_their_reference_results(loop_fmus, name):
    """Regression guard: switch time, estimates, tracking and force peaks of each loop as
    recorded in closed_loop_reference.json (regenerate it deliberately when the estimator,
    the controller or the loops change)."""
    expected = json.loads(REFERENCE.read_text())[name]
    got = run_loop(loop_cases()[name], loop_fmus).to_dict()
    assert got["switch_time"] == pytest.approx(expected["switch_time"], abs=1e-9)
    for key in ("identified", "final_estimates", "tracking_rms", "force_peak"):
        for item, value in expected[key].items():
            assert got[key][item] == pytest.approx(value, rel=1e-6), (key, item)


def test_ensure_fmus_reuses_current_builds(loop_fmus):
    folder = next(iter(loop_fmus.values())).parent
    before = {name: path.stat().st_mtime_ns for name, path in loop_fmus.items()}
    again = ensure_fmus(folder)
    assert {name: path.stat().st_mtime_ns for name, path in again.items()} == before


def test_one_dof_loop_meets_the_targets(loop_1dof):
    """Estimates within 0.5 % before the switch; tracking >= 5x better than the 30 % baseline;
    force within its limit."""
    r = loop_1dof
    case = r.case
    assert 0.0 < r.switch_time < case.t_end - case.settle_after - 1.0
    for p in ("m", "k", "kp"):
        assert abs(r.errors_percent[p]) < 0.5, (p, r.errors_percent)
    assert abs(r.errors_percent["b"]) < 2.0
    assert r.improvement >= 5.0, r.tracking_rms
    assert r.force_peak["adaptive"] <= case.force_limit
    assert r.saturated_samples["adaptive"] == 0
    # the controller used the estimator's outputs of the switch (freeze)
    i = int(np.searchsorted(r.adaptive.time, r.switch_time))
    used = {p: r.adaptive[f"controller.{p}_used"][-1] for p in case.truth}
    assert all(np.isfinite(list(used.values())))
    assert np.all(np.isnan(r.adaptive["controller.m_used"][:max(i - 1, 0)]))


def test_identification_goes_on_during_control(loop_1dof):
    """The estimator keeps running in closed loop; fed the staircase's samples (f_sample) it
    stays on the truth (the raw command would lag half a step)."""
    for p, value in loop_1dof.final_estimates.items():
        assert value == pytest.approx(loop_1dof.case.truth[p], rel=1e-3), p
    a = loop_1dof.adaptive
    f, f_sample = a["controller.f"], a["controller.f_sample"]
    assert f_sample[0] == f[0]
    assert np.allclose(f_sample[1:], 0.5 * (f[:-1] + f[1:]), rtol=0, atol=1e-12)


def test_chirp_excitation(loop_fmus):
    """A chirp instead of the step: identified within 0.5 %, then the same tracking gain."""
    case = replace(loop_cases()["oscillator1dof"], excitation_amplitude=6.0,
                   controller_options={"reference_model": "derivatives", "excitation": "chirp", "chirp_f0": 1.0,
                                       "chirp_f1": 8.0, "chirp_duration": 2.0})
    r = run_loop(case, loop_fmus)
    phase = r.adaptive["controller.phase"]
    assert np.any(np.diff(r.adaptive["controller.f"][phase == 0]) != 0.0)  # it really chirped
    for p in ("m", "k", "kp"):
        assert abs(r.errors_percent[p]) < 0.5, r.errors_percent
    assert r.improvement >= 5.0, r.tracking_rms


def test_switch_is_bumpless(loop_1dof):
    """The force just after the switch continues the excitation step."""
    a = loop_1dof.adaptive
    f = a["controller.f"]
    phase = a["controller.phase"]
    k = int(np.argmax(phase == 1))
    assert k > 0 and phase[k - 1] == 0
    jumps = np.abs(np.diff(f[k - 3:k + 3]))
    assert jumps.max() < 0.05 * loop_1dof.case.excitation_amplitude


def test_baseline_switches_at_the_same_time(loop_1dof):
    b = loop_1dof.baseline
    k = int(np.argmax(b["controller.phase"] == 1))
    assert b.time[k] == pytest.approx(loop_1dof.switch_time, abs=1.5 * loop_1dof.case.dt)


def test_loop_without_identification_is_reported(loop_fmus):
    """A plant the estimator cannot identify in time: run_loop says so (no silent baseline)."""
    base = loop_cases()["oscillator1dof"]
    short = LoopCase(**{**base.__dict__, "t_end": 0.05})
    with pytest.raises(RuntimeError, match="never switched"):
        run_loop(short, loop_fmus)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["oscillator2dof", "duffing_circuit"])
def test_other_loops_identify_and_track(loop_fmus, name):
    r = run_loop(loop_cases()[name], loop_fmus)
    assert max(abs(e) for e in r.errors_percent.values()) < 2.0, r.errors_percent
    assert r.improvement >= 5.0, r.tracking_rms
    assert r.force_peak["adaptive"] <= r.case.force_limit


@pytest.mark.slow
def test_closed_loop_container_equals_orchestrator(loop_fmus, tmp_path):
    """ClosedLoop1DOF.fmu passes fmpy validate and reproduces the orchestrator's Jacobi run."""
    case = closed_loop_case()
    fmu = build_closed_loop_fmu(tmp_path, loop_fmus)
    assert fmpy.validation.validate_fmu(str(fmu)) == []
    md = fmpy.read_model_description(str(fmu))
    names = {v.name: v for v in md.modelVariables}
    assert all(names[name].causality == "input" for name in ("r", "r_dot", "r_ddot"))
    assert names["controller.reference_model"].causality == "parameter"
    for out in ("x", "f", "m_hat", "b_hat", "k_hat", "kp_hat"):
        assert names[out].causality == "output"
    t_end = 1.5
    direct = loop_system(case, loop_fmus).run(t_end, case.dt)
    container = System().add("loop", fmu).set_input("loop.r", case.reference).run(t_end, case.dt)
    for out, source in CLOSED_LOOP_OUTPUTS.items():
        a, b = container[f"loop.{out}"], direct[source]
        assert np.array_equal(np.isnan(a), np.isnan(b)), out
        finite = np.isfinite(b)
        assert np.allclose(a[finite], b[finite], rtol=1e-12, atol=1e-15), out


@pytest.mark.slow
def test_demo_json(tmp_path, loop_fmus):
    fmu_dir = next(iter(loop_fmus.values())).parent
    proc = subprocess.run([sys.executable, "-m", "duffid", "demo", "--out", str(tmp_path / "out"),
                           "--fmu-dir", str(fmu_dir), "--json"], capture_output=True, text=True, check=True)
    data = json.loads(proc.stdout)
    assert set(data["identified"]) == {"m", "b", "k", "kp"} == set(data["truth"])
    rms = data["tracking_rms"]
    assert rms["baseline"] >= 5.0 * rms["adaptive"] > 0.0
    assert set(data["cases"]) == {"oscillator1dof", "oscillator1dof_payload", "oscillator2dof", "duffing_circuit"}
    for name in data["cases"]:
        assert (tmp_path / "out" / f"{name}_closed_loop.png").exists()
        assert (tmp_path / "out" / f"{name}_adaptive.csv").exists()
    assert "payload" in data["cases"]["oscillator1dof_payload"] and "payload" not in data
    assert (tmp_path / "out" / "oscillator1dof_payload_payload.png").exists()
    assert all(math.isfinite(v) for v in data["identified"].values())
