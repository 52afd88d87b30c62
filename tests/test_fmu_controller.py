"""The C controller FMUs (duffid.control.controller_fmu) against the Python reference
duffid.control.adaptive.AdaptiveController, through fmpy's low-level API with our own callbacks.

Tolerances: the controller is scalar arithmetic in both C (-ffp-contract=off) and
Python (float operations, no BLAS), so C equals Python to a few ulps of the largest value of
each output: ``assert_same`` compares at 1e-12 relative to that scale.
"""
from __future__ import annotations

import math
import shutil
import zipfile

import numpy as np
import pytest

fmpy = pytest.importorskip("fmpy")
pytest.importorskip("control")

from fmpy.fmi1 import FMICallException  # noqa: E402
from fmpy.validation import validate_fmu  # noqa: E402
from fmu_helpers import start_fmi2  # noqa: E402

from duffid import Duffing1, Duffing2, Step, simulate  # noqa: E402
from duffid.control.adaptive import AdaptiveController, controller_parameters  # noqa: E402
from duffid.control.controller_fmu import TYPES, build_controller_fmu, build_controller_fmus  # noqa: E402
from duffid.control.design import design, mismatched  # noqa: E402

if shutil.which("gcc") is None:
    pytest.skip("gcc is needed to build the C FMUs", allow_module_level=True)

H = 1e-3
FILES = {(1, 2): "AdaptiveController1.fmu", (1, 3): "AdaptiveController1_fmi3.fmu",
         (2, 2): "AdaptiveController2.fmu", (2, 3): "AdaptiveController2_fmi3.fmu"}


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    return {path.name: path for path in build_controller_fmus(tmp_path_factory.mktemp("controller_fmus"))}


@pytest.fixture(scope="module")
def records():
    """Open-loop positions of the plants (10 N step), 1.5 s."""
    return {1: simulate(Duffing1(), Step(10.0), 1.5, H), 2: simulate(Duffing2(), Step(10.0), 1.5, H)}


def input_sequence(dofs, record, seed=0, nan_until=150, toggle=(180, 230)):
    """Inputs of every sample: positions of the record, a smooth reference with its exact
    derivatives, estimates NaN until ``nan_until`` then the truth with 1e-4 jitter,
    ``identified`` off in ``toggle``."""
    rng = np.random.default_rng(seed)
    truth = (Duffing1() if dofs == 1 else Duffing2()).parameters
    rows = []
    for k in range(record.n_samples):
        t = k * H
        row = {"r": 4e-3 + 3e-3 * math.sin(2 * math.pi * t) + 1e-3 * math.sin(6 * math.pi * t),
               "r_dot": 3e-3 * 2 * math.pi * math.cos(2 * math.pi * t) + 1e-3 * 6 * math.pi * math.cos(6 * math.pi * t),
               "r_ddot": -3e-3 * (2 * math.pi) ** 2 * math.sin(2 * math.pi * t)
               - 1e-3 * (6 * math.pi) ** 2 * math.sin(6 * math.pi * t)}
        if dofs == 1:
            row["x"] = float(record.x[k, 0])
        else:
            row["x1"], row["x2"] = float(record.x[k, 0]), float(record.x[k, 1])
        for name, value in truth.items():
            row[f"{name}_hat"] = math.nan if k < nan_until else value * (1.0 + 1e-4 * rng.standard_normal())
        row["identified"] = nan_until <= k and not toggle[0] <= k < toggle[1]
        rows.append(row)
    return rows


def _float_outputs(controller):
    return [n for n in controller.output_names if n not in TYPES]


def _read2(fmu, vr, controller):
    names = _float_outputs(controller)
    out = dict(zip(names, fmu.getReal([vr[n] for n in names])))
    out["phase"] = fmu.getInteger([vr["phase"]])[0]
    out["saturated"] = fmu.getBoolean([vr["saturated"]])[0]
    return out


def run_fmi2(path, tmp_path, params, rows, messages=None):
    messages = [] if messages is None else messages
    controller = AdaptiveController(1 if "x" in rows[0] else 2, parameters=params)
    fmu, vr = start_fmi2(path, tmp_path, messages, params, TYPES, name="ctrl")
    try:
        outputs = [_read2(fmu, vr, controller)]
        reals = [n for n in controller.input_names if n != "identified"]
        for k, row in enumerate(rows):
            fmu.setReal([vr[n] for n in reals], [row[n] for n in reals])
            fmu.setBoolean([vr["identified"]], [bool(row["identified"])])
            fmu.doStep(currentCommunicationPoint=k * H, communicationStepSize=H)
            outputs.append(_read2(fmu, vr, controller))
    finally:
        fmu.terminate()
        fmu.freeInstance()
    return outputs


def run_python(params, rows):
    controller = AdaptiveController(1 if "x" in rows[0] else 2, parameters=params)
    outputs = [controller.initialize(0.0)]
    for k, row in enumerate(rows):
        outputs.append(controller.step(k * H, H, row))
    return outputs


def assert_same(a, b, rtol=1e-12):
    assert len(a) == len(b)
    for name in a[0]:
        x = np.array([row[name] for row in a], dtype=float)
        y = np.array([row[name] for row in b], dtype=float)
        np.testing.assert_array_equal(np.isnan(x), np.isnan(y), err_msg=name)
        scale = np.nanmax(np.abs(x)) if np.any(np.isfinite(x)) else 0.0
        np.testing.assert_allclose(x, y, rtol=rtol, atol=rtol * scale, equal_nan=True, err_msg=name)


# ---------------------------------------------------------------------- building
def test_files_validation_and_sources(fmus):
    assert set(FILES.values()) == set(fmus)
    for (dofs, version), name in FILES.items():
        assert validate_fmu(str(fmus[name])) == [], name
        with zipfile.ZipFile(fmus[name]) as z:
            names = z.namelist()
        for source in ("duffid_controller.c", "duffid_controller.h", "fmu_model_controller.c",
                       "controller_fmu_config.h", "fmu_instance.c"):
            assert f"sources/{source}" in names
        assert ("sources/buildDescription.xml" in names) == (version == 3)


def test_archives_are_deterministic(fmus, tmp_path):
    assert build_controller_fmu(1, tmp_path, 2).read_bytes() == fmus["AdaptiveController1.fmu"].read_bytes()


@pytest.mark.parametrize("dofs, version", sorted(FILES))
def test_interface(fmus, dofs, version):
    md = fmpy.read_model_description(str(fmus[FILES[dofs, version]]))
    assert md.coSimulation is not None and md.modelExchange is None
    controller = AdaptiveController(dofs)
    variables = {v.name: v for v in md.modelVariables}
    assert tuple(v.name for v in md.modelVariables if v.causality == "input") == controller.input_names
    assert tuple(v.name for v in md.modelVariables if v.causality == "output") == controller.output_names
    params = controller_parameters(design(H), dofs=dofs)
    assert [v.name for v in md.modelVariables if v.causality == "parameter"] == list(params)
    for name, value in params.items():
        start = variables[name].start
        assert (start in ("true", "false") and (start == "true") == value) or float(start) == float(value), name
    integer = "Integer" if version == 2 else "Int32"
    assert variables["phase"].type == integer and variables["differentiator_samples"].type == integer
    assert variables["identified"].type == "Boolean" and variables["freeze"].type == "Boolean"
    assert variables["saturated"].type == "Boolean"


# ---------------------------------------------------------------------- C = Python
CASES = {
    "adaptive": {},
    "adaptive-follow": {"freeze": False, "settle_time": 0.02},
    "adaptive-follow-fallback": {"freeze": False, "settle_time": 0.02, "fallback": "nominal"},
    "adaptive-chirp-limited": {"excitation": "chirp", "excitation_amplitude": 8.0, "chirp_f0": 2.0,
                               "chirp_f1": 10.0, "chirp_duration": 0.3, "force_limit": 10.5,
                               "differentiator_samples": 17},
    "fixed": {"mode": "fixed", "switch_time": 0.5},
    "derivatives": {"reference_model": "derivatives"},
    "derivatives-follow-limited": {"reference_model": "derivatives", "freeze": False, "settle_time": 0.02,
                                   "force_limit": 10.5},
    "fixed-derivatives": {"mode": "fixed", "switch_time": 0.5, "reference_model": 1},
}


@pytest.mark.parametrize("dofs", [1, 2])
@pytest.mark.parametrize("case", sorted(CASES))
def test_c_fmu_equals_python_reference(fmus, records, tmp_path, dofs, case):
    settings = dict(CASES[case])
    if case == "fixed" or "fallback" in case:
        settings["nominal"] = mismatched((Duffing1() if dofs == 1 else Duffing2()).parameters, 0.3)
    params = controller_parameters(design(H), dofs=dofs, **settings)
    rows = input_sequence(dofs, records[dofs])
    withdrawn = range(900, 1000)  # during control: the estimator withdraws its estimates
    if "fallback" in case:
        for k in withdrawn:
            rows[k]["identified"] = False
    c = run_fmi2(fmus[FILES[dofs, 2]], tmp_path, params, rows)
    py = run_python(params, rows)
    assert_same(c, py)
    phases = [row["phase"] for row in py]
    assert phases[0] == 0 and phases[-1] == 1  # both phases covered
    if not case.startswith("fixed"):
        assert py[-1]["switch_time"] >= 0.25  # after identified came back and settled
    if case in ("adaptive-chirp-limited", "derivatives-follow-limited"):
        assert any(row["saturated"] for row in py)
    if "follow" in case:
        assert py[-1]["m_used" if dofs == 1 else "m1_used"] != py[phases.index(1)]["m_used" if dofs == 1
                                                                                     else "m1_used"]
    if "fallback" in case:  # row k + 1 holds the outputs of the step at sample k
        mass = "m" if dofs == 1 else "m1"
        assert phases[withdrawn[0]] == 1
        assert {py[k + 1][f"{mass}_used"] for k in withdrawn} == {settings["nominal"][mass]}
        assert py[withdrawn[-1] + 2][f"{mass}_used"] == rows[withdrawn[-1] + 1][f"{mass}_hat"]
    if "derivatives" in case:  # the transient has decayed: x_d = r (Taylor-predicted to t_{k+1})
        t_end = len(rows) * H
        r_end = 4e-3 + 3e-3 * math.sin(2 * math.pi * t_end) + 1e-3 * math.sin(6 * math.pi * t_end)
        assert py[-1]["x_ref"] == pytest.approx(r_end, abs=1e-8)


def test_fmi3_equals_python_reference(fmus, records, tmp_path):
    from fmpy.fmi3 import FMU3Slave

    params = controller_parameters(design(H), dofs=2, freeze=False, reference_model="derivatives")
    rows = input_sequence(2, records[2], seed=1)
    path = fmus[FILES[2, 3]]
    md = fmpy.read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    controller = AdaptiveController(2, parameters=params)
    messages = []

    def log(env, status, category, message):
        messages.append((status, category.decode(), message.decode()))

    fmu = FMU3Slave(guid=md.guid, unzipDirectory=fmpy.extract(str(path), str(tmp_path / "u3")),
                    modelIdentifier=md.coSimulation.modelIdentifier, instanceName="ctrl3")
    fmu.instantiate(loggingOn=False, logMessage=log)
    floats = _float_outputs(controller)

    def read():
        out = dict(zip(floats, fmu.getFloat64([vr[n] for n in floats])))
        out["phase"] = fmu.getInt32([vr["phase"]])[0]
        out["saturated"] = fmu.getBoolean([vr["saturated"]])[0]
        return out

    try:
        fmu.enterInitializationMode(startTime=0.0)
        fmu.setBoolean([vr["freeze"]], [False])
        fmu.setInt32([vr["reference_model"]], [1])
        fmu.exitInitializationMode()
        outputs = [read()]
        reals = [n for n in controller.input_names if n != "identified"]
        for k, row in enumerate(rows):
            fmu.setFloat64([vr[n] for n in reals], [row[n] for n in reals])
            fmu.setBoolean([vr["identified"]], [bool(row["identified"])])
            fmu.doStep(currentCommunicationPoint=k * H, communicationStepSize=H)
            outputs.append(read())
    finally:
        fmu.freeInstance()
    assert_same(outputs, run_python(params, rows))
    assert messages == []


# ---------------------------------------------------------------------- behaviour
@pytest.mark.parametrize("reference_model", ["filter", "derivatives"])
def test_bumpless_switch_and_force_limit(reference_model):
    params = controller_parameters(design(H), force_limit=10.5, reference_model=reference_model)
    rows = input_sequence(1, simulate(Duffing1(), Step(10.0), 1.0, H))
    out = run_python(params, rows)
    f = np.array([row["f"] for row in out])
    phase = np.array([row["phase"] for row in out])
    k = int(np.argmax(phase == 1))
    assert f[k] == pytest.approx(f[k - 1], rel=1e-13, abs=1e-13)  # first law output = the excitation
    assert np.all(np.abs(f) <= 10.5)
    saturated = np.array([row["saturated"] for row in out], dtype=bool)
    assert saturated.any() and np.all(np.abs(f[saturated]) == 10.5)
    assert np.all(np.abs(f[~saturated]) < 10.5)
    # both reference models start x_d, x_d', x_d'' at the observer's prediction and the
    # model's acceleration: the same switch, then "derivatives" converges to r
    filtered = run_python(controller_parameters(design(H), force_limit=10.5), rows)
    assert [row["x_ref"] for row in filtered[:k + 1]] == [row["x_ref"] for row in out[:k + 1]]
    assert filtered[k]["f"] == f[k]
    r_end = rows[-1]["r"] + H * rows[-1]["r_dot"] + 0.5 * H * H * rows[-1]["r_ddot"]
    assert abs(filtered[-1]["x_ref"] - r_end) > 1e-3  # the filter's lag
    if reference_model == "derivatives":
        assert abs(out[-1]["x_ref"] - r_end) < 1e-8  # z decays like exp(-30 t)


@pytest.fixture
def instance(fmus, tmp_path):
    messages = []
    fmu, vr = start_fmi2(fmus["AdaptiveController1.fmu"], tmp_path, messages, types=TYPES, name="ctrl")
    yield fmu, vr, messages
    fmu.freeInstance()


def test_wrong_step_size_is_discarded_and_logged(instance):
    fmu, vr, messages = instance
    fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=H)
    with pytest.raises(FMICallException, match="status 2"):  # fmi2Discard
        fmu.doStep(currentCommunicationPoint=H, communicationStepSize=2 * H)
    assert any(status == 3 and "differs from the parameter sample_period" in text for status, _, text in messages)


def test_nan_accepted_on_estimates_rejected_on_positions(instance):
    fmu, vr, messages = instance
    fmu.setReal([vr["m_hat"], vr["kp_hat"]], [float("nan"), float("inf")])
    fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=H)
    assert messages == []
    for name in ("x", "r", "r_dot", "r_ddot"):
        with pytest.raises(FMICallException, match="status 3"):
            fmu.setReal([vr[name]], [float("nan")])
    assert any(status == 3 and "not finite" in text and "variable x " in text for status, _, text in messages)
    with pytest.raises(FMICallException, match="status 3"):
        fmu.setReal([vr["force_limit"]], [float("nan")])


def test_excitation_above_force_limit_is_an_initialisation_error(fmus, tmp_path):
    messages = []
    with pytest.raises(FMICallException, match="status 3"):
        start_fmi2(fmus["AdaptiveController1.fmu"], tmp_path, messages,
                   {"excitation_amplitude": 12.0, "force_limit": 10.0}, TYPES, name="ctrl")
    assert any(status == 3 and "excitation_amplitude 12 exceeds force_limit 10" in text
               for status, _, text in messages)
    with pytest.raises(ValueError, match="exceeds force_limit"):
        controller_parameters(design(H), excitation_amplitude=12.0, force_limit=10.0)


def test_get_set_and_serialized_fmu_state(fmus, records, tmp_path):
    """The state (buffer, settling, observer, reference model, phase) is part of the FMU state."""
    params = controller_parameters(design(H))
    rows = input_sequence(1, records[1])
    controller = AdaptiveController(1, parameters=params)
    reals = [n for n in controller.input_names if n != "identified"]

    def step(fmu, vr, k):
        fmu.setReal([vr[n] for n in reals], [rows[k][n] for n in reals])
        fmu.setBoolean([vr["identified"]], [bool(rows[k]["identified"])])
        fmu.doStep(currentCommunicationPoint=k * H, communicationStepSize=H)

    fmu, vr = start_fmi2(fmus["AdaptiveController1.fmu"], tmp_path, [], params, TYPES, name="a")
    other, vr2 = start_fmi2(fmus["AdaptiveController1.fmu"], tmp_path, [], params, TYPES, name="b")
    try:
        for k in range(390):  # just before the switch
            step(fmu, vr, k)
        state = fmu.getFMUstate()
        for k in range(390, 700):
            step(fmu, vr, k)
        reference = _read2(fmu, vr, controller)
        assert reference["phase"] == 1
        fmu.setFMUstate(state)
        for k in range(390, 700):
            step(fmu, vr, k)
        assert _read2(fmu, vr, controller) == reference
        restored = other.deSerializeFMUstate(fmu.serializeFMUstate(state))
        other.setFMUstate(restored)
        other.freeFMUstate(restored)
        fmu.freeFMUstate(state)
        for k in range(390, 700):
            step(other, vr2, k)
        assert _read2(other, vr2, controller) == reference
    finally:
        fmu.freeInstance()
        other.freeInstance()


def test_a_diverging_step_is_refused_like_the_python_controller(fmus, records, tmp_path):
    """A position so large that the observer overflows after the switch: the C FMU discards
    the step with a logged reason (FMI 2: the run ends there) and the Python controller raises
    ArithmeticError and stays as before, so its following steps equal a run that never saw it."""
    params = controller_parameters(design(H), mode="fixed", switch_time=0.05)
    rows = input_sequence(1, records[1])[:120]
    clean = run_python(params, rows)
    messages = []
    controller = AdaptiveController(1, parameters=params)
    fmu, vr = start_fmi2(fmus["AdaptiveController1.fmu"], tmp_path, messages, params, TYPES, name="ctrl")
    reals = [n for n in controller.input_names if n != "identified"]
    try:
        for k, row in enumerate(rows[:101]):
            row = {**row, "x": 1e308} if k == 100 else row
            fmu.setReal([vr[n] for n in reals], [row[n] for n in reals])
            fmu.setBoolean([vr["identified"]], [bool(row["identified"])])
            if k < 100:
                fmu.doStep(currentCommunicationPoint=k * H, communicationStepSize=H)
                assert_same([_read2(fmu, vr, controller)], [clean[k + 1]])
        with pytest.raises(FMICallException, match="status 2"):  # fmi2Discard
            fmu.doStep(currentCommunicationPoint=100 * H, communicationStepSize=H)
    finally:
        fmu.freeInstance()
    assert any("diverged at t = 0.1" in text for _, _, text in messages), messages
    python = AdaptiveController(1, parameters=params)
    python.initialize(0.0)
    for k, row in enumerate(rows):
        if k == 100:
            with pytest.raises(ArithmeticError, match="diverged"):
                python.step(k * H, H, {**row, "x": 1e308})
        assert_same([python.step(k * H, H, row)], [clean[k + 1]])
