"""Estimator FMUs that take a measured acceleration or velocity (pythonfmu,
duffid.fmu.python_estimator with ``motion``) through fmpy.

The FMU runs OnlineMotionIdentifier in this process on the very samples given to it, so its
outputs are compared with the identifier's for identity (any difference is a bug in the
FMU's plumbing, not rounding). A pythonfmu FMU runs only in a Python host: no C host and no
FMU state here (see duffid.fmu.python_estimator).
"""
from __future__ import annotations

import numpy as np
import pytest

fmpy = pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")

from fmpy.validation import validate_fmu  # noqa: E402
from fmu_helpers import simulate_record  # noqa: E402
from test_motion import AMPLITUDE, K, TRUE, measured, plant_motion  # noqa: E402

from duffid.cli import main  # noqa: E402
from duffid.data.record import Record  # noqa: E402
from duffid.data.signals import Multisine  # noqa: E402
from duffid.errors import InputError  # noqa: E402
from duffid.fmu.estimator import build_chain_fmu, build_equation_fmu  # noqa: E402
from duffid.identification.motion_online import OPTIONS, run_motion_online  # noqa: E402
from duffid.models.registry import model_from_name  # noqa: E402

DT = 2e-4


@pytest.fixture(scope="module")
def accelerometer():
    """Random force 1-30 Hz, acceleration at 5 kHz with a bias of 1 % of its RMS and 50 dB
    noise, 2 s."""
    force = Multisine(0.8 * K * AMPLITUDE, 1.0, 30.0, 2.0, phases="random", seed=3)
    t, f, _, _, a = plant_motion(force, 2.0, DT)
    return Record(t, measured(f, 60, 1), measured(a, 50, 2, bias_share=0.01), source="rig", motion="a")


@pytest.fixture(scope="module")
def chain_fmu(tmp_path_factory):
    return build_chain_fmu(1, tmp_path_factory.mktemp("fmus"), motion="a", backend="python")


def test_the_interface_names_the_acceleration_and_the_fits_options(chain_fmu):
    assert validate_fmu(str(chain_fmu)) == []
    md = fmpy.read_model_description(str(chain_fmu))
    variables = {v.name: v for v in md.modelVariables}
    assert [v.name for v in md.modelVariables if v.causality == "input"] == ["a1", "f1", "enable", "reset"]
    assert variables["a1"].unit == "m/s2" and variables["f1"].unit == "N"
    assert "acceleration of mass 1" in variables["a1"].description
    params = {v.name: v for v in md.modelVariables if v.causality == "parameter"}
    assert set(params) == set(OPTIONS) | {"sample_period"}  # no algebraic options, no method
    assert float(params["horizon"].start) == 0.0 and params["horizon"].unit == "s"
    assert float(params["max_uncertainty"].start) == OPTIONS["max_uncertainty"][0]
    assert "output-error identification from acceleration" in md.description


def test_the_fmu_gives_the_online_identifiers_answer(chain_fmu, accelerometer):
    result = simulate_record(chain_fmu, accelerometer, ["a1", "f1"])  # sample_period: the record's dt
    expected = run_motion_online(accelerometer, model_from_name("chain", 1))
    for name, history in expected.history.items():
        np.testing.assert_array_equal(result[f"{name}_hat"][1:], history)
    assert np.array_equal(result["identified"][1:], expected.identified)
    assert result["identified"][-1]
    truth = {"m1": TRUE["m"], "b1": TRUE["b"], "k1_1": TRUE["k"], "k1_3": TRUE["kp"]}
    for name, value in truth.items():
        assert abs(result[f"{name}_hat"][-1] / value - 1) <= 0.01, name
        assert result[f"{name}_status"][-1] == 1
        assert 0 < result[f"{name}_std_error"][-1] <= 0.01 * value


def test_an_equation_fmu_from_a_velocity_column(tmp_path):
    """``--columns t,f,v``: the equation is written in x, the FMU takes its velocity v."""
    path = build_equation_fmu("m*der(x,2) + b*der(x) + k*x + kp*x^3 = f", tmp_path, name="RigVelocity",
                              units={"x": "m", "f": "N"}, motion="v", backend="python")
    assert validate_fmu(str(path)) == []
    md = fmpy.read_model_description(str(path))
    variables = {v.name: v for v in md.modelVariables}
    assert [v.name for v in md.modelVariables if v.causality == "input"] == ["v", "f", "enable", "reset"]
    assert variables["v"].unit == "m/s" and variables["kp_hat"].unit == "N/m3"


def test_the_c_engine_and_fmi3_are_refused_for_an_acceleration(tmp_path):
    for options in ({"backend": "c"}, {"fmi_version": 3}):
        with pytest.raises(InputError, match="the C estimator core needs a displacement"):
            build_chain_fmu(1, tmp_path, motion="a", **options)
    with pytest.raises(InputError, match="motion must be one of x, v, a"):
        build_chain_fmu(1, tmp_path, motion="j")


def test_the_cli_builds_an_acceleration_estimator(tmp_path, capsys):
    out = tmp_path / "RigAcc.fmu"
    assert main(["build-estimator", "--equation", "m*der(x,2) + b*der(x) + k*x + kp*x^3 = f",
                 "--columns", "t,f,a", "--units", "x=m,f=N", "--name", "RigAcc", "-o", str(out)]) == 0
    captured = capsys.readouterr()
    assert "the C estimator core needs a displacement, not an acceleration" in captured.err
    assert "input   a " in captured.out and "m/s2" in captured.out
    assert main(["build-estimator", "--chain", "2", "--motion", "v", "-o", str(tmp_path)]) == 0
    assert "input   v2 " in capsys.readouterr().out
    assert main(["build-estimator", "--chain", "1", "--motion", "a", "--engine", "c", "-o", str(tmp_path)]) == 2
    assert "needs a displacement" in capsys.readouterr().err
    assert main(["build-estimator", "--equation", "m*der(x,2) + k*x = f", "--columns", "t,f,a",
                 "--motion", "v", "-o", str(tmp_path)]) == 2
    assert "--columns t,f,a measure a, --motion v" in capsys.readouterr().err


def test_the_fmu_state_round_trip(chain_fmu, accelerometer, tmp_path):
    """fmi2GetFMUstate 0.3 s before the values are first published, then 0.6 s on; back to the
    state: the same 0.6 s again,
    output for output (the identifier, its horizon and its published values come back), and
    the state stays usable after it was set."""
    from fmu_helpers import start_fmi2, step_samples

    messages: list = []
    fmu, vr = start_fmi2(chain_fmu, tmp_path, messages, start={"sample_period": accelerometer.dt})
    outputs = [f"{n}_hat" for n in ("m1", "b1", "k1_1", "k1_3")] + ["window_length", "residual"]

    def run(first: int, n: int) -> np.ndarray:
        return step_samples(fmu, vr, accelerometer, ["a1", "f1"], outputs, first, n)

    first = int(np.argmax(run_motion_online(accelerometer, model_from_name("chain", 1)).identified))
    assert first > 0
    split, n = max(first - int(0.3 / DT), 1), int(0.6 / DT)
    run(0, split)
    state = fmu.getFMUstate()
    once = run(split, n)
    assert np.isfinite(once[-1, :4]).all() and not np.isfinite(once[0, :4]).any()  # published meanwhile
    for _ in range(2):
        fmu.setFMUstate(state)
        np.testing.assert_array_equal(run(split, n), once)
    fmu.freeFMUstate(state)
    fmu.terminate()
    fmu.freeInstance()
    assert not [m for m in messages if m[0] >= 3], messages
