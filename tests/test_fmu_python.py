"""The pythonfmu fallback FMU (duffid.fmu.python_estimator) through fmpy.

The FMU runs OnlineIdentifier in this process on the very samples identify() sees, so its
outputs are compared for identity (bit for bit, whatever the CPU or BLAS kernel): any
difference is a bug in the FMU's plumbing, not rounding.
"""
from __future__ import annotations

import zipfile

import numpy as np
import pytest

fmpy = pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")

from fmpy.fmi1 import FMICallException  # noqa: E402
from fmpy.fmi2 import fmi2Terminated  # noqa: E402
from fmpy.validation import validate_fmu  # noqa: E402
from fmu_helpers import simulate_record, start_fmi2, step_samples  # noqa: E402

from duffid import Duffing1, Duffing2  # noqa: E402
from duffid.fmu.estimator_table import DEFAULT_SAMPLE_PERIOD, estimator_variables  # noqa: E402
from duffid.fmu.python_estimator import FMU_NAMES, build_python_fmu  # noqa: E402
from duffid.identification.batch import estimate  # noqa: E402


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    out = tmp_path_factory.mktemp("fmus")
    return {name: build_python_fmu(name, out) for name in FMU_NAMES}


def test_file_names_and_validation(fmus):
    assert fmus["duffing1"].name == "DuffingEstimator1_python.fmu"
    assert fmus["duffing2"].name == "DuffingEstimator2_python.fmu"
    for path in fmus.values():
        assert validate_fmu(str(path)) == []
        with zipfile.ZipFile(path) as z:
            assert "modelDescription.xml" in z.namelist()


@pytest.mark.parametrize("model_name, inputs, outputs", [
    ("duffing1", ["x", "f"], ["m_hat", "b_hat", "k_hat", "kp_hat"]),
    ("duffing2", ["x1", "x2", "f1"], ["m1_hat", "b1_hat", "k1_hat", "kp1_hat", "b2_hat", "k2_hat", "kp2_hat",
                                       "m2_hat"]),
])
def test_interface(fmus, model_name, inputs, outputs):
    md = fmpy.read_model_description(str(fmus[model_name]))
    assert md.coSimulation is not None and md.fmiVersion == "2.0"
    variables = {v.name: v for v in md.modelVariables}
    assert [v.name for v in md.modelVariables if v.causality == "input"] == inputs + ["enable", "reset"]
    assert variables["enable"].type == variables["reset"].type == "Boolean"
    out = [v.name for v in md.modelVariables if v.causality == "output"]
    assert out == outputs + ["identified", "condition", "uncertainty", "window_length"] + [
        f"{n[:-4]}_status" for n in outputs] + ["outliers"] + [f"{n[:-4]}_std_error" for n in outputs] + ["residual"]
    assert all(variables[name].initial == "exact" for name in out)
    assert variables["identified"].type == "Boolean"
    assert np.isnan(float(variables[outputs[0]].start))
    params = [v for v in md.modelVariables if v.causality == "parameter"]
    assert all(v.variability == "tunable" for v in params)
    names = {v.name for v in params}
    assert {"method", "gamma", "window", "forgetting"} <= names
    model = Duffing1() if model_name == "duffing1" else Duffing2()
    for name in model.parameters:
        assert float(variables[f"{name}_nominal"].start) == 0.0  # no prior: the data give the scale
        assert variables[f"{name}_status"].type == "Integer"
    assert variables["method"].start == "robust" and float(variables["window"].start) == 0.0
    assert float(variables["gamma"].start) == 20.0 and float(variables["forgetting"].start) == 0.0
    # the C FMU's table gives the units and the sample period: same values here
    table = {v.name: v for v in estimator_variables(model_name)}
    for v in md.modelVariables:
        if v.type == "Real":
            assert v.unit == table[v.name].unit, v.name
    assert {u.name for u in md.unitDefinitions} == {v.unit for v in md.modelVariables if v.unit}
    assert float(variables["sample_period"].start) == float(md.defaultExperiment.stepSize) == DEFAULT_SAMPLE_PERIOD
    assert md.coSimulation.canHandleVariableCommunicationStepSize is False


def test_case_a_gives_identify_answer(fmus, case_a):
    result = simulate_record(fmus["duffing1"], case_a, ["x", "f"])
    expected = estimate(case_a, Duffing1())
    assert len(result) == case_a.n_samples + 1  # the initial values, then one row per sample
    for name in expected.parameters:
        # the whole history, NaN until published
        np.testing.assert_array_equal(result[f"{name}_hat"][1:], expected.history[name])
    assert np.array_equal(result["identified"][1:], expected.identified)
    assert result["window_length"][-1] == pytest.approx(expected.window)
    assert not result["identified"][0] and np.isnan(result["m_hat"][0])


def test_options_and_nominal_parameters(fmus, case_a):
    start = {"method": "paper", "sign_in_numerator": True, "gamma": 10.0}
    result = simulate_record(fmus["duffing1"], case_a, ["x", "f"], start)
    expected = estimate(case_a, Duffing1(), "paper", sign_in_numerator=True, gamma=10.0)
    for name, value in expected.parameters.items():
        assert result[f"{name}_hat"][-1] == value
    result = simulate_record(fmus["duffing1"], case_a, ["x", "f"], {"window": 0.1, "m_nominal": 3.0})
    expected = estimate(case_a, Duffing1(), window=0.1, nominal={"m": 3.0})
    for name, value in expected.parameters.items():  # the same value, or both unpublished (NaN)
        got = result[f"{name}_hat"][-1]
        assert got == value or (np.isnan(got) and np.isnan(value)), name


def test_two_dof_gives_identify_answer(fmus, two_dof_exact):
    result = simulate_record(fmus["duffing2"], two_dof_exact, ["x1", "x2", "f1"])
    expected = estimate(two_dof_exact, Duffing2())
    for name in expected.parameters:
        np.testing.assert_array_equal(result[f"{name}_hat"][1:], expected.history[name])
    assert bool(result["identified"][-1]) == bool(expected.identified[-1])


def _start(path, tmp_path, messages, start_strings=None):
    """Instantiate with our own callbacks and logging on, String parameters set."""
    strings = start_strings or {}
    return start_fmi2(path, tmp_path, messages, start=strings, types=dict.fromkeys(strings, "String"),
                      logging_on=True, name="est")


def test_bad_parameter_ends_the_simulation_with_a_logged_error(fmus, tmp_path):
    messages = []
    fmu, vr = _start(fmus["duffing1"], tmp_path, messages, {"method": "fast"})
    try:
        fmu.setReal([vr["x"], vr["f"]], [0.0, 10.0])
        with pytest.raises(FMICallException, match="status 2"):  # fmi2Discard, terminated
            fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=1e-3)
        assert fmu.getBooleanStatus(fmi2Terminated)
    finally:
        fmu.freeInstance()
    assert (3, "logStatusError", "parameter method must be 'robust' or 'paper', got 'fast'") in messages


@pytest.fixture
def instance(fmus, tmp_path):
    """A started instance of the 1-DOF FMU (fmpy's low-level API) and its value references."""
    fmu, vr = _start(fmus["duffing1"], tmp_path, [])
    yield fmu, vr
    fmu.freeInstance()


def test_changing_the_step_size_is_an_error(instance, capsys):
    fmu, vr = instance
    for k in range(20):
        fmu.setReal([vr["x"], vr["f"]], [1e-4 * k * k, 10.0])
        fmu.doStep(currentCommunicationPoint=k * 1e-3, communicationStepSize=1e-3)
    fmu.doStep(currentCommunicationPoint=20e-3, communicationStepSize=1e-3 * (1 + 1e-12))  # rounding: fine
    with pytest.raises(FMICallException, match="status 2"):  # fmi2Discard, terminated
        fmu.doStep(currentCommunicationPoint=21e-3, communicationStepSize=2e-3)
    assert fmu.getBooleanStatus(fmi2Terminated)
    assert "differs from the parameter sample_period 0.001" in capsys.readouterr().err  # said without a logger
    with pytest.raises(FMICallException, match="status 2"):  # and it stays so
        fmu.doStep(currentCommunicationPoint=21e-3, communicationStepSize=1e-3)


def test_changing_a_parameter_after_the_first_step_is_an_error(instance):
    fmu, vr = instance
    fmu.setReal([vr["x"], vr["f"]], [0.0, 10.0])
    fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=1e-3)
    fmu.setReal([vr["gamma"]], [20.0])  # unchanged value: fine
    fmu.doStep(currentCommunicationPoint=1e-3, communicationStepSize=1e-3)
    fmu.setReal([vr["window"]], [0.2])
    with pytest.raises(FMICallException, match="status 2"):
        fmu.doStep(currentCommunicationPoint=2e-3, communicationStepSize=1e-3)


def test_non_finite_input_is_an_error(instance):
    fmu, vr = instance
    fmu.setReal([vr["x"], vr["f"]], [0.0, 10.0])
    fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=1e-3)
    fmu.setReal([vr["x"]], [float("nan")])
    with pytest.raises(FMICallException, match="status 2"):
        fmu.doStep(currentCommunicationPoint=1e-3, communicationStepSize=1e-3)
    assert np.isnan(fmu.getReal([vr["m_hat"]])[0]) and not fmu.getBoolean([vr["identified"]])[0]


def test_unknown_model_is_rejected(tmp_path):
    with pytest.raises(ValueError, match="duffing1"):
        build_python_fmu("circuit", tmp_path)


def test_the_fmu_state_round_trip(fmus, case_a, tmp_path):
    """fmi2GetFMUstate (declared since the acceleration FMUs): back to a state, the same
    outputs again, bit for bit (the identifier's state is copied, not only the variables)."""
    messages: list = []
    fmu, vr = start_fmi2(fmus["duffing1"], tmp_path, messages, start={"sample_period": case_a.dt})
    outputs = ["m_hat", "b_hat", "k_hat", "kp_hat", "condition", "window_length"]

    def run(first, n):
        return step_samples(fmu, vr, case_a, ["x", "f"], outputs, first, n)

    split = case_a.n_samples // 3
    run(0, split)
    state = fmu.getFMUstate()
    once = run(split, split)
    assert np.isfinite(once[-1, 0])
    fmu.setFMUstate(state)
    np.testing.assert_array_equal(run(split, split), once)
    fmu.freeFMUstate(state)
    fmu.terminate()
    fmu.freeInstance()
    assert fmpy.read_model_description(str(fmus["duffing1"])).coSimulation.canGetAndSetFMUstate
