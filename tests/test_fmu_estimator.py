"""The C estimator FMUs (duffid.fmu.estimator) on the shared FMI glue, through fmpy.

C (FMU) against Python (identify / OnlineIdentifier) is compared at a multiple of the Python
identifier's one-ulp spread on the same record (tests/rounding.py): ~1e-12 relative for the
1-DOF records, up to ~2e-9 for the 2-DOF chain's kp2 at the end of the record. The C FMU and
the Python FMU (which runs OnlineIdentifier) compare the same way.
"""
from __future__ import annotations

import shutil
import subprocess
import xml.etree.ElementTree as ET
import zipfile

import numpy as np
import pytest

fmpy = pytest.importorskip("fmpy")

from fmpy.fmi1 import FMICallException  # noqa: E402
from fmpy.validation import validate_fmu  # noqa: E402
from fmu_helpers import simulate_record, start_fmi2  # noqa: E402
from rounding import identifier_spread  # noqa: E402

from duffid import Duffing1, Duffing2, DuffingCircuit, Multisine, Record, measure, simulate  # noqa: E402
from duffid.fmu.estimator import build_estimator_fmu, build_estimator_fmus  # noqa: E402
from duffid.fmu.fmi_xml import declares_sampled_inputs  # noqa: E402
from duffid.fmu.estimator_table import TYPES  # noqa: E402
from duffid.identification.batch import estimate  # noqa: E402
from duffid.identification.engine import (
    STATUSES,  # noqa: E402
    OnlineIdentifier,  # noqa: E402
)

if shutil.which("gcc") is None:
    pytest.skip("gcc is needed to build the C FMUs", allow_module_level=True)

INPUTS = {"duffing1": ["x", "f"], "duffing2": ["x1", "x2", "f1"]}
C_FILES = {("duffing1", 2): "DuffingEstimator1.fmu", ("duffing1", 3): "DuffingEstimator1_fmi3.fmu",
           ("duffing2", 2): "DuffingEstimator2.fmu", ("duffing2", 3): "DuffingEstimator2_fmi3.fmu"}


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    out = tmp_path_factory.mktemp("estimator_fmus")
    try:
        import pythonfmu  # noqa: F401
        python = True
    except ImportError:
        python = False
    return {path.name: path for path in build_estimator_fmus(out, python=python)}


def test_files_and_validation(fmus):
    assert set(C_FILES.values()) <= set(fmus)
    for path in fmus.values():
        assert validate_fmu(str(path)) == [], path.name
        with zipfile.ZipFile(path) as z:  # x and f are samples of one instant (Gauss-Seidel orders)
            assert declares_sampled_inputs(ET.fromstring(z.read("modelDescription.xml"))), path.name
    for (model_name, version), name in C_FILES.items():
        with zipfile.ZipFile(fmus[name]) as z:
            names = z.namelist()
        assert "sources/duffid_estimator.c" in names and "sources/fmu_model_estimator.c" in names
        assert "sources/fmu_instance.c" in names and "sources/estimator_fmu_config.h" in names
        assert ("sources/buildDescription.xml" in names) == (version == 3)


def test_archives_are_deterministic(fmus, tmp_path):
    again = build_estimator_fmu("duffing1", tmp_path, 2)
    assert again.read_bytes() == fmus["DuffingEstimator1.fmu"].read_bytes()


@pytest.mark.parametrize("model_name, version", sorted(C_FILES))
def test_interface(fmus, model_name, version):
    md = fmpy.read_model_description(str(fmus[C_FILES[model_name, version]]))
    assert md.fmiVersion == f"{version}.0" and md.coSimulation is not None and md.modelExchange is None
    model = Duffing1() if model_name == "duffing1" else Duffing2()
    variables = {v.name: v for v in md.modelVariables}
    assert [v.name for v in md.modelVariables if v.causality == "input"] == INPUTS[model_name] + ["enable", "reset"]
    assert variables["enable"].type == variables["reset"].type == "Boolean"
    assert variables["enable"].start in ("true", "1", True) and variables["reset"].start in ("false", "0", False)
    outputs = [v.name for v in md.modelVariables if v.causality == "output"]
    assert outputs == [f"{n}_hat" for n in model.parameters] + ["identified", "condition", "uncertainty",
                                                                   "window_length"] + [
        f"{n}_status" for n in model.parameters] + ["outliers"] + [
        f"{n}_std_error" for n in model.parameters] + ["residual"]
    assert variables["k_std_error" if model_name == "duffing1" else "k1_std_error"].unit == "N/m"
    assert len(md.outputs) == len(outputs)
    for name in model.parameters:
        assert float(variables[f"{name}_nominal"].start) == 0.0  # no prior: the data give the scale
        assert variables[f"{name}_status"].type == ("Integer" if version == 2 else "Int32")
        assert "1 published" in variables[f"{name}_status"].description
        assert "4 changed" in variables[f"{name}_status"].description
    assert float(variables["method"].start) == 0.0 and float(variables["window"].start) == 0.0
    assert float(variables["gamma"].start) == 20.0 and float(variables["forgetting"].start) == 0.0
    assert variables["k_hat" if model_name == "duffing1" else "k1_hat"].unit == "N/m"
    assert md.defaultExperiment is not None and float(md.defaultExperiment.stepSize) == 1e-3
    integer = "Integer" if version == 2 else "Int32"
    assert variables["identified"].type == "Boolean" and variables["sign_in_numerator"].type == "Boolean"
    assert variables["method"].type == integer and variables["n_rows"].type == integer
    assert variables["gamma"].type == ("Real" if version == 2 else "Float64")


@pytest.mark.parametrize("name", ["DuffingEstimator1.fmu", "DuffingEstimator1_fmi3.fmu"])
def test_case_a_gives_identify_answer(fmus, case_a, name):
    result = simulate_record(fmus[name], case_a, ["x", "f"])
    expected = estimate(case_a, Duffing1())
    assert len(result) == case_a.n_samples + 1
    assert np.isnan(result["m_hat"][0]) and result["identified"][0] == 0.0
    spread = identifier_spread(Duffing1(), case_a)
    spread.assert_final({p: result[f"{p}_hat"][-1] for p in expected.parameters}, expected.parameters)
    spread.assert_history({p: result[f"{p}_hat"][1:] for p in expected.parameters}, expected.history)
    assert np.array_equal(result["identified"][1:] == 1.0, expected.identified)


@pytest.mark.parametrize("case", ["A", "B"])
def test_c_fmu_equals_python_fmu_and_online_identifier(fmus, case_a, case_b_exact, case):
    """The paper's cases A (14 N, quantised) and B (10 N, 2 s, quantised + 40 dB noise)."""
    if "DuffingEstimator1_python.fmu" not in fmus:
        pytest.skip("pythonfmu not installed")
    record = case_a if case == "A" else measure(case_b_exact, snr_db=40, seed=3)
    c = simulate_record(fmus["DuffingEstimator1.fmu"], record, ["x", "f"])
    py = simulate_record(fmus["DuffingEstimator1_python.fmu"], record, ["x", "f"])
    ident = OnlineIdentifier(Duffing1(), dt=record.dt)
    x, f = np.asarray(record.x).reshape(record.n_samples, -1), np.asarray(record.f).reshape(record.n_samples, -1)
    estimates = [ident.update(x[i], f[i]) for i in range(record.n_samples)]
    names = list(Duffing1().parameters)
    spread = identifier_spread(Duffing1(), record)
    spread.assert_history({p: c[f"{p}_hat"][1:] for p in names}, {p: py[f"{p}_hat"][1:] for p in names})
    spread.assert_history({p: c[f"{p}_hat"][1:] for p in names},
                          {p: np.array([e.parameters[p] for e in estimates]) for p in names})
    assert all(np.isnan(c[f"{p}_hat"][0]) and np.isnan(py[f"{p}_hat"][0]) for p in names)
    assert np.array_equal(c["identified"] == 1.0, py["identified"].astype(bool))
    for p in names:  # the status of each parameter, sample by sample, as the identifier's
        codes = [STATUSES.index(e.status[p]) for e in estimates]
        assert c[f"{p}_status"][0] == py[f"{p}_status"][0] == 0
        np.testing.assert_array_equal(c[f"{p}_status"][1:], codes)
        np.testing.assert_array_equal(py[f"{p}_status"][1:], codes)
    assert any(STATUSES.index("published") in set(c[f"{p}_status"]) for p in names)


@pytest.mark.parametrize("name", ["DuffingCircuitEstimator.fmu", "DuffingCircuitEstimator_fmi3.fmu"])
def test_circuit_estimator_equals_the_online_identifier(fmus, name):
    """The series Duffing circuit (charge q [C], voltage u [V]): L, R, C and a with electrical
    units, at every sample as OnlineIdentifier(DuffingCircuit()) (C the reciprocal of the core's
    stiffness), statuses included; a prior size of C given as a capacitance."""
    md = fmpy.read_model_description(str(fmus[name]))
    units = {v.name: v.unit for v in md.modelVariables}
    assert (units["q"], units["u"], units["L_hat"], units["R_hat"], units["C_hat"], units["a_hat"]) == \
        ("C", "V", "H", "Ohm", "F", "V/C3")
    assert units["C_nominal"] == "F"
    plant = DuffingCircuit()
    record = measure(simulate(plant, Multisine(8.0, 2.0, 40.0, 2.0, phases="random", seed=4), 4.0, 5e-4),
                     snr_db=50, seed=1)
    for start, nominal in (({}, None), ({"C_nominal": 2e-3}, {"C": 2e-3})):
        result = simulate_record(fmus[name], record, ["q", "u"], start)
        ident = OnlineIdentifier(DuffingCircuit(), dt=record.dt, **({"nominal": nominal} if nominal else {}))
        estimates = [ident.update(record.x[i], record.f[i]) for i in range(record.n_samples)]
        names = list(plant.parameters)
        identifier_spread(DuffingCircuit(), record).assert_history(
            {p: result[f"{p}_hat"][1:] for p in names}, {p: np.array([e.parameters[p] for e in estimates]) for p in names})
        for p in names:
            np.testing.assert_array_equal(result[f"{p}_status"][1:], [STATUSES.index(e.status[p]) for e in estimates])
        assert estimates[-1].identified and bool(result["identified"][-1])
        for p, truth in plant.parameters.items():
            assert abs(result[f"{p}_hat"][-1] / truth - 1) < 0.02, p


@pytest.mark.parametrize("name", ["DuffingEstimator2.fmu", "DuffingEstimator2_fmi3.fmu"])
def test_two_dof_gives_identify_answer(fmus, two_dof_exact, name):
    result = simulate_record(fmus[name], two_dof_exact, ["x1", "x2", "f1"])
    expected = estimate(two_dof_exact, Duffing2())
    identifier_spread(Duffing2(), two_dof_exact).assert_final(
        {p: result[f"{p}_hat"][-1] for p in expected.parameters}, expected.parameters)
    assert bool(result["identified"][-1]) == bool(expected.identified[-1])


def test_options_and_nominal_parameters(fmus, case_a):
    fmu = fmus["DuffingEstimator1.fmu"]
    result = simulate_record(fmu, case_a, ["x", "f"], {"method": 1, "sign_in_numerator": True, "gamma": 10.0})
    expected = estimate(case_a, Duffing1(), "paper", sign_in_numerator=True, gamma=10.0)
    identifier_spread(Duffing1(), case_a, "paper", sign_in_numerator=True, gamma=10.0).assert_final(
        {p: result[f"{p}_hat"][-1] for p in expected.parameters}, expected.parameters)
    result = simulate_record(fmu, case_a, ["x", "f"], {"window": 0.1, "m_nominal": 3.0})
    expected = estimate(case_a, Duffing1(), window=0.1, nominal={"m": 3.0})
    identifier_spread(Duffing1(), case_a, window=0.1, nominal={"m": 3.0}).assert_final(
        {p: result[f"{p}_hat"][-1] for p in expected.parameters}, expected.parameters)


# ---------------------------------------------------------------------- low-level API
def _start(path, tmp_path, messages, start=None, logging_on=False):
    """Instantiate with our own callbacks (never fmpy's logger= proxy, see test_fmu_python)."""
    return start_fmi2(path, tmp_path, messages, start, TYPES, logging_on, name="est")


def _step(fmu, vr, k, x, f=10.0, dt=1e-3):
    fmu.setReal([vr["x"], vr["f"]], [float(np.ravel(x)[0]), float(np.ravel(f)[0])])
    fmu.doStep(currentCommunicationPoint=k * dt, communicationStepSize=dt)


def _outputs(fmu, vr):
    values = fmu.getReal([vr[n] for n in ("m_hat", "b_hat", "k_hat", "kp_hat", "condition")])
    return values + [float(fmu.getBoolean([vr["identified"]])[0])]


@pytest.fixture
def instance(fmus, tmp_path):
    messages = []
    fmu, vr = _start(fmus["DuffingEstimator1.fmu"], tmp_path, messages)
    yield fmu, vr, messages
    fmu.freeInstance()


def test_changing_the_step_size_is_discarded_and_logged(instance, case_a):
    fmu, vr, messages = instance
    for k in range(20):
        _step(fmu, vr, k, case_a.x[k])
    fmu.doStep(currentCommunicationPoint=20e-3, communicationStepSize=1e-3 * (1 + 1e-12))  # rounding: fine
    with pytest.raises(FMICallException, match="status 2"):  # fmi2Discard
        fmu.doStep(currentCommunicationPoint=21e-3, communicationStepSize=2e-3)
    assert any(status == 3 and "differs from the parameter sample_period 0.001" in text and
               "a step of several periods is refused" in text for status, _, text in messages)


@pytest.mark.parametrize("name", ["DuffingEstimator1.fmu", "DuffingEstimator1_fmi3.fmu"])
def test_sample_period_is_a_parameter_and_the_default_experiment_step(fmus, name):
    md = fmpy.read_model_description(str(fmus[name]))
    period = next(v for v in md.modelVariables if v.name == "sample_period")
    assert (period.causality, period.variability, period.unit) == ("parameter", "fixed", "s")
    assert float(md.defaultExperiment.stepSize) == float(period.start) == 1e-3
    assert md.coSimulation.canHandleVariableCommunicationStepSize is False
    assert "pymoca" not in md.generationTool and "glue" in md.generationTool


def test_a_first_step_other_than_sample_period_is_refused_with_both_values(fmus, tmp_path):
    messages = []
    fmu, vr = _start(fmus["DuffingEstimator1.fmu"], tmp_path, messages, {"sample_period": 2e-4})
    try:
        fmu.setReal([vr["x"], vr["f"]], [0.0, 1.0])
        with pytest.raises(FMICallException, match="status 2"):
            fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=1e-3)
    finally:
        fmu.freeInstance()
    text = next(text for status, _, text in messages if status == 3)
    assert "communicationStepSize 0.001 at t = 0 differs from the parameter sample_period 0.0002" in text
    assert "several periods" in text  # 1 ms = 5 sample periods: the 4 samples between are unknown


def test_fmpy_simulate_feeds_a_measured_csv_as_the_readme_says(fmus, tmp_path):
    """The README's command: a 5 kHz record of a plant of another scale, through fmpy's CLI."""
    import sys
    from pathlib import Path

    from duffid import simulate
    from duffid.data.signals import Chirp
    from duffid.identification.engine import OnlineIdentifier

    truth = Duffing1(m=0.8, b=4.0, k=3.0e4, kp=2.0e8)
    record = measure(simulate(truth, Chirp(20.0, 5.0, 60.0, 1.0), 1.0, 2e-4), snr_db=50, seed=11)
    csv = tmp_path / "rec5k.csv"
    np.savetxt(csv, np.column_stack([record.t, record.x[:, 0], record.f[:, 0]]), delimiter=",",
               header="time,x,f", comments="", fmt="%.17g")
    out = tmp_path / "est.csv"
    stop = float(record.t[-1] + record.dt)
    done = subprocess.run([str(Path(sys.executable).with_name("fmpy")), "simulate", str(fmus["DuffingEstimator1.fmu"]),
                           "--input-file", str(csv), "--start-values", "sample_period", repr(record.dt),
                           "--output-interval", repr(record.dt), "--stop-time", repr(stop), "--output-file",
                           str(out)], capture_output=True, text=True)
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr
    rows = np.genfromtxt(out, delimiter=",", names=True)
    assert len(rows) == record.n_samples + 1  # the initial row, then one per sample
    ident = OnlineIdentifier(Duffing1(), record.dt)
    for k in range(record.n_samples):
        estimate = ident.update(record.x[k], record.f[k])
    assert estimate.identified and bool(rows["identified"][-1])
    # the C FMU through fmpy's CLI gives the Python identifier's values, to the rounding spread
    identifier_spread(Duffing1(), record).assert_final({p: rows[f"{p}_hat"][-1] for p in truth.parameters},
                                                       estimate.parameters)
    for p, value in truth.parameters.items():  # and, published, they are the plant's
        assert abs(rows[f"{p}_hat"][-1] - value) <= 4 * estimate.uncertainty * abs(value) + 1e-3 * abs(value), p


def test_non_finite_input_is_an_error_logged_with_logging_off(instance):
    fmu, vr, messages = instance
    _step(fmu, vr, 0, 0.0)
    with pytest.raises(FMICallException, match="status 3"):
        fmu.setReal([vr["x"]], [float("nan")])
    assert any(status == 3 and "not finite" in text for status, _, text in messages)
    fmu.doStep(currentCommunicationPoint=1e-3, communicationStepSize=1e-3)  # the old input is kept


def test_bad_parameter_is_discarded_and_logged(fmus, tmp_path):
    messages = []
    fmu, vr = _start(fmus["DuffingEstimator1.fmu"], tmp_path, messages, {"method": 5})
    try:
        fmu.setReal([vr["x"], vr["f"]], [0.0, 10.0])
        with pytest.raises(FMICallException, match="status 2"):
            fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=1e-3)
    finally:
        fmu.freeInstance()
    assert any(status == 3 and "parameter method must be an integer in 0 .. 1" in text
               for status, _, text in messages)


def test_parameters_are_fixed_after_initialisation(instance):
    fmu, vr, messages = instance
    with pytest.raises(FMICallException, match="status 3"):
        fmu.setReal([vr["gamma"]], [10.0])
    with pytest.raises(FMICallException, match="status 3"):
        fmu.setInteger([vr["method"]], [1])


def test_typed_access(instance):
    fmu, vr, messages = instance
    assert fmu.getInteger([vr["method"], vr["n_rows"]]) == [0, 0]
    assert fmu.getBoolean([vr["identified"], vr["sign_in_numerator"]]) == [False, False]
    with pytest.raises(FMICallException, match="status 3"):
        fmu.getReal([vr["method"]])
    with pytest.raises(FMICallException, match="status 3"):
        fmu.getInteger([vr["gamma"]])
    with pytest.raises(FMICallException, match="status 3"):
        fmu.setBoolean([vr["x"]], [True])
    assert any("is not a Float64 variable" in text for _, _, text in messages)
    assert any("is not an Integer variable" in text for _, _, text in messages)


def test_get_set_and_serialized_fmu_state(fmus, instance, case_a_exact, tmp_path):
    fmu, vr, _ = instance
    for k in range(100):
        _step(fmu, vr, k, case_a_exact.x[k], case_a_exact.f[k])
    state = fmu.getFMUstate()
    for k in range(100, 180):
        _step(fmu, vr, k, case_a_exact.x[k], case_a_exact.f[k])
    reference = _outputs(fmu, vr)
    assert np.all(np.isfinite(reference[:4]))
    fmu.setFMUstate(state)
    for k in range(100, 180):
        _step(fmu, vr, k, case_a_exact.x[k], case_a_exact.f[k])
    np.testing.assert_array_equal(_outputs(fmu, vr), reference)
    # the serialised state in a second instance (other memory: the estimator is relocated)
    data = fmu.serializeFMUstate(state)
    fmu.freeFMUstate(state)
    other, vr2 = _start(fmus["DuffingEstimator1.fmu"], tmp_path, [])
    try:
        restored = other.deSerializeFMUstate(data)
        other.setFMUstate(restored)
        other.freeFMUstate(restored)
        for k in range(100, 180):
            _step(other, vr2, k, case_a_exact.x[k], case_a_exact.f[k])
        np.testing.assert_array_equal(_outputs(other, vr2), reference)
    finally:
        other.freeInstance()


def test_reset_starts_a_new_identification(instance, case_a):
    fmu, vr, _ = instance
    for k in range(60):
        _step(fmu, vr, k, case_a.x[k], case_a.f[k])
    first = _outputs(fmu, vr)
    fmu.reset()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    assert np.isnan(_outputs(fmu, vr)[0])
    for k in range(60):
        _step(fmu, vr, k, case_a.x[k], case_a.f[k])
    np.testing.assert_array_equal(_outputs(fmu, vr), first)


def test_fmi3_fmu_state_and_step_size(fmus, case_a, tmp_path):
    from fmpy.fmi3 import FMU3Slave

    path = fmus["DuffingEstimator1_fmi3.fmu"]
    md = fmpy.read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    messages = []

    def log(env, status, category, message):
        messages.append((status, category.decode(), message.decode()))

    def start(name):
        unzipdir = fmpy.extract(str(path), str(tmp_path / name))
        fmu = FMU3Slave(guid=md.guid, unzipDirectory=unzipdir, modelIdentifier=md.coSimulation.modelIdentifier,
                        instanceName=name)
        fmu.instantiate(loggingOn=False, logMessage=log)
        fmu.enterInitializationMode(startTime=0.0)
        fmu.exitInitializationMode()
        return fmu

    def step(fmu, k):
        fmu.setFloat64([vr["x"], vr["f"]], [float(case_a.x[k, 0]), float(case_a.f[k, 0])])
        fmu.doStep(currentCommunicationPoint=k * 1e-3, communicationStepSize=1e-3)

    outputs = [vr[n] for n in ("m_hat", "b_hat", "k_hat", "kp_hat")]
    fmu, other = start("a"), start("b")
    try:
        for k in range(120):
            step(fmu, k)
        data = fmu.serializeFMUState(fmu.getFMUState())
        for k in range(120, 200):
            step(fmu, k)
        reference = fmu.getFloat64(outputs)
        other.setFMUState(other.deserializeFMUState(data))
        for k in range(120, 200):
            step(other, k)
        np.testing.assert_array_equal(other.getFloat64(outputs), reference)
        assert other.getBoolean([vr["identified"]]) == fmu.getBoolean([vr["identified"]])
        assert other.getInt32([vr["method"]]) == [0]
        with pytest.raises(FMICallException, match="status 2"):  # fmi3Discard
            other.doStep(currentCommunicationPoint=0.2, communicationStepSize=2e-3)
    finally:
        fmu.freeInstance()
        other.freeInstance()
    assert any(status == 3 and "differs from the parameter sample_period" in text for status, _, text in messages)


# ---------------------------------------------------------------------- C host, rebuild
@pytest.mark.slow
@pytest.mark.skipif(shutil.which("cmake") is None, reason="fmpy's rebuild needs cmake")
@pytest.mark.parametrize("name", ["DuffingEstimator1.fmu", "DuffingEstimator1_fmi3.fmu"])
def test_rebuild_from_sources_with_fmpy_gives_identical_results(fmus, case_a, tmp_path, name):
    from fmpy.build import build_platform_binary

    directory = (tmp_path / "unzipped").resolve()
    fmpy.extract(str(fmus[name]), str(directory))
    binary = next((directory / "binaries").glob("*/*.so"))
    binary.unlink()
    (tmp_path / "cmake").mkdir()
    build_platform_binary(directory, build_dir=tmp_path / "cmake")
    assert binary.exists()
    rebuilt = tmp_path / name
    shutil.make_archive(str(rebuilt.with_suffix("")), "zip", directory)
    rebuilt.with_suffix(".zip").rename(rebuilt)
    a = simulate_record(fmus[name], case_a, ["x", "f"])
    b = simulate_record(rebuilt, case_a, ["x", "f"])
    for pname in Duffing1().parameters:
        np.testing.assert_array_equal(b[f"{pname}_hat"], a[f"{pname}_hat"])


def test_c_host_program_matches_python(fmus, case_a, tmp_path):
    """tests/c/fmi_host.c (the C host of tests/test_c_hosts.py) loads the FMU's binary itself
    and steps it, FMI 2 and FMI 3: every estimate at every step, bit for bit as fmpy."""
    import os

    from c_hosts import Case, Host, compile_host, run_host

    from duffid.cbuild import HOST_PLATFORM

    host = Host(HOST_PLATFORM, compile_host(HOST_PLATFORM, tmp_path), dict(os.environ))
    inputs = {"x": np.ravel(case_a.x), "f": np.ravel(case_a.f)}
    outputs = [f"{p}_hat" for p in Duffing1().parameters]
    for version in (2, 3):
        fmu = fmus[C_FILES["duffing1", version]]
        got = run_host(host, Case(fmu.name, fmu, case_a.dt, inputs, {"sample_period": case_a.dt}, outputs), tmp_path)
        expected = simulate_record(fmu, case_a, ["x", "f"])
        for name in ["time", *outputs]:
            np.testing.assert_array_equal(got[name], expected[name], err_msg=f"{fmu.name}: {name}")


def test_a_glitch_is_excluded_by_both_fmus(fmus, case_b_exact):
    clean = measure(case_b_exact, snr_db=40, seed=3)
    x = clean.x.copy()
    x[900, 0] = 1.0  # a spike of 1 m
    x[1400:1402, 0] = 0.0  # a dropout of two samples
    record = Record(clean.t, clean.f, x, source="glitched")
    expected = estimate(record, Duffing1())
    assert len(expected.outliers) == 3
    names = ["DuffingEstimator1.fmu"] + (["DuffingEstimator1_python.fmu"] if "DuffingEstimator1_python.fmu" in fmus else [])
    for name in names:
        result = simulate_record(fmus[name], record, ["x", "f"])
        assert list(result["outliers"][[900, 901, 902, 1401, 1402, 1403, -1]]) == [0, 0, 1, 1, 1, 3, 3], name
        identifier_spread(Duffing1(), record).assert_final(
            {p: result[f"{p}_hat"][-1] for p in expected.parameters}, expected.parameters)
