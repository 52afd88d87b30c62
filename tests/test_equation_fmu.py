"""The estimator FMU of the user's own equations (duffid build-estimator): C (FMI 2 and 3, the
generic estimator core) and pythonfmu. Its units follow from the signals', it passes fmpy
validate, and through fmpy it gives at every sample what the online identifier gives on the
same record: the pythonfmu FMU exactly (it runs that identifier), the C FMU within the
identifier's own one-ulp spread on the record (tests/rounding.py, as tests/test_fmu_estimator.py).
"""
from __future__ import annotations

import shutil
import zipfile

import fmpy
import numpy as np
import pytest
from fmpy.fmi1 import FMICallException
from fmpy.validation import validate_fmu
from fmu_helpers import simulate_record, start_fmi2
from rounding import identifier_spread

from duffid import Chirp, Step, measure, simulate
from duffid.cli import main
from duffid.errors import CompilerNotFoundError, EquationError, InputError
from duffid.fmu import estimator as c_fmus
from duffid.fmu.estimator_table import variable_types
from duffid.fmu.python_estimator import build_equation_fmu
from duffid.identification.engine import STATUSES, OnlineIdentifier
from duffid.identification.trust import identify
from duffid.models.equation_model import EquationModel
from duffid.models.units import format_unit, parameter_units, parse_unit, si_exponents

needs_cc = pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None, reason="no C compiler")

DAMPING = "m*der(x,2) + b*der(x) + c*x^2*der(x) + k*x + kp*x^3 = f"
TRUTH = {"m": 1.2, "b": 3.0, "c": 4e4, "k": 1700.0, "kp": 5e5}


@pytest.mark.parametrize("equation, columns, units, expected", [
    (DAMPING, ("t", "f", "x"), {"x": "m", "f": "N"},
     {"m": "kg", "b": "N.s/m", "c": "N.s/m3", "k": "N/m", "kp": "N/m3"}),
    ("der(x,2) + c*der(x) + w*x = 0", ("t", "x"), {"x": "m"}, {"c": "1/s", "w": "1/s2"}),
    ("L*der(x,2) + R*der(x) + a*x + a3*x^3 = f", ("t", "f", "x"), {"x": "C", "f": "V"},
     {"L": "H", "R": "Ohm", "a": "1/F", "a3": "V/C3"}),
    ("m*der(x,2) + b*der(x) + k1*x + k2*x^2 + k3*x^3 + c = f", ("t", "f", "x"), {"x": "m", "f": "N"},
     {"m": "kg", "b": "N.s/m", "k1": "N/m", "k2": "N/m2", "k3": "N/m3", "c": "N"}),
    ("m*der(x,2) + b*der(x) + fc*sign(der(x)) + k*x = f", ("t", "f", "x"), {"x": "counts", "f": "N"},
     {"m": "N.s2/counts", "b": "N.s/counts", "fc": "N", "k": "N/counts"}),
    ("m1*der(x1,2) + b1*der(x1) + k1*x1 + k2*(x1-x2) + kc*(x1-x2)^3 = f; "
     "m2*der(x2,2) + k2*(x2-x1) + kc*(x2-x1)^3 + b2*der(x2) = 0", ("t", "f", "x1", "x2"),
     {"x1": "m", "x2": "m", "f": "N"},
     {"m1": "kg", "b1": "N.s/m", "k1": "N/m", "k2": "N/m", "kc": "N/m3", "m2": "kg", "b2": "N.s/m"}),
])
def test_parameter_units_follow_from_the_signals(equation, columns, units, expected):
    """Including an unforced equation whose scale comes from a shared parameter (2 DOF), a
    force-free ratio form and units duffid does not know (counts)."""
    assert parameter_units(EquationModel(equation, columns), units) == expected


def test_units_that_do_not_follow_must_be_declared():
    model = EquationModel("m*der(x,2) + b*der(x) + k*sin(x) = f")
    with pytest.raises(InputError, match=r"unit of k does not follow .* --units k="):
        parameter_units(model, {"x": "rad", "f": "N.m"})
    assert parameter_units(model, {"x": "rad", "f": "N.m"}, {"k": "N.m"})["k"] == "N.m"
    with pytest.raises(InputError, match="no unit for the signal f"):
        parameter_units(model, {"x": "m"})
    with pytest.raises(InputError, match="'v' is not a signal"):
        parameter_units(model, {"x": "m", "f": "N", "v": "m/s"})
    with pytest.raises(InputError, match="not a symbol"):
        parse_unit("N*s^2")


def test_unit_strings():
    assert parse_unit("N.s2/m") == {"N": 1, "s": 2, "m": -1} and parse_unit("1") == {}
    assert parse_unit("1/(m2.s2)") == {"m": -2, "s": -2}
    assert si_exponents("N.s2/m") == si_exponents("kg") and si_exponents("counts/s") is None
    assert format_unit({"N": 1, "s": 2, "m": -1}) == "kg" and format_unit({"counts": 1, "s": -1}) == "counts/s"
    assert format_unit({}) == "1"


@pytest.fixture(scope="module")
def record():
    model = EquationModel(DAMPING, values=TRUTH)
    return measure(simulate(model, Chirp(5.0, 1.0, 15.0, 4.0), 4.0, 1e-3), snr_db=45, seed=2)


@pytest.mark.slow
def test_equation_fmu_equals_the_online_identifier_at_every_sample(tmp_path, record):
    fmu = build_equation_fmu(DAMPING, tmp_path, name="NonlinearDamping", units={"x": "m", "f": "N"})
    assert validate_fmu(str(fmu)) == []
    md = fmpy.read_model_description(str(fmu))
    units = {v.name: v.unit for v in md.modelVariables}
    assert units["c_hat"] == "N.s/m3" and units["k_nominal"] == "N/m" and units["x"] == "m"
    assert md.coSimulation.canHandleVariableCommunicationStepSize is False
    result = simulate_record(fmu, record, ["x", "f"])
    ident = OnlineIdentifier(EquationModel(DAMPING), record.dt)
    names = list(TRUTH)
    for k in range(record.n_samples):
        estimate = ident.update(record.x[k], record.f[k])
        row = result[k + 1]  # the outputs after the step that consumed sample k
        for name in names:
            np.testing.assert_array_equal(row[f"{name}_hat"], estimate.parameters[name], err_msg=f"{name} at {k}")
            assert row[f"{name}_status"] == STATUSES.index(estimate.status[name])
        assert bool(row["identified"]) == estimate.identified
    assert estimate.identified  # the record determines every parameter: a meaningful comparison
    for name, truth in TRUTH.items():
        assert abs(estimate.parameters[name] / truth - 1) < 0.05


def test_build_estimator_cli(tmp_path, capsys):
    out = tmp_path / "NLD.fmu"
    assert main(["build-estimator", "--equation", DAMPING, "--name", "NLD", "--units", "x=m,f=N", "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert str(out) in text and "kp_hat" in text and "N/m3" in text
    assert validate_fmu(str(out)) == []
    # binaries for every platform whose compiler is installed, as duffid build-fmus gives
    from duffid.cbuild import resolve_platforms
    with zipfile.ZipFile(out) as z:
        folders = {n.split("/")[1] for n in z.namelist() if n.startswith("binaries/")}
    assert folders == {p.fmi2 for p in resolve_platforms(["all"])[0]}
    # mistakes are named
    assert main(["build-estimator", "--equation", "m*der(x,2) + b*der(x) + k*x = F", "-o", str(tmp_path / "E.fmu"),
                 "--name", "E"]) == 2
    assert "'F' is not a column" in capsys.readouterr().err
    assert main(["build-estimator", "--equation", DAMPING, "--units", "x=m,f=N,q=V"]) == 2
    assert "'q' is neither a signal nor a parameter" in capsys.readouterr().err
    assert main(["build-estimator", "--equation", DAMPING, "--name", "A", "-o", str(tmp_path / "B.fmu")]) == 2
    assert "file stem is its model name" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["build-estimator", "--equation", DAMPING, "--units", "x:m"])
    assert "is not name=unit" in capsys.readouterr().err
    with pytest.raises(InputError, match="Python identifier"):
        build_equation_fmu(DAMPING, tmp_path, name="2fast")
    with pytest.raises(EquationError):
        build_equation_fmu("m*der(x,2) = ", tmp_path, name="Bad")


@pytest.mark.slow
def test_chain_estimator_fmu_equals_the_online_identifier(tmp_path):
    """duffid build-estimator --chain 3 --backend python: inputs x1..x3 [m], f1 [N], the chain's
    parameters with their units, at every sample exactly what OnlineIdentifier of the same chain
    gives (the pythonfmu FMU runs it)."""
    from duffid import Multisine, model_from_name

    assert main(["build-estimator", "--chain", "3", "--backend", "python",
                 "-o", str(tmp_path / "ChainEstimator3.fmu")]) == 0
    fmu = tmp_path / "ChainEstimator3.fmu"
    assert validate_fmu(str(fmu)) == []
    units = {v.name: v.unit for v in fmpy.read_model_description(str(fmu)).modelVariables}
    assert (units["x3"], units["f1"], units["m2_hat"], units["b3_hat"], units["k2_1_hat"], units["k3_3_hat"]) == \
        ("m", "N", "kg", "N.s/m", "N/m", "N/m3")
    plant = model_from_name("chain", 3)
    record = measure(simulate(plant, Multisine(5.0, 1.0, 30.0, 2.0, phases="random", seed=5), 2.0, 1e-3),
                     snr_db=60, seed=2)
    result = simulate_record(fmu, record, ["x1", "x2", "x3", "f1"])
    ident = OnlineIdentifier(model_from_name("chain", 3), record.dt)
    for k in range(record.n_samples):
        estimate = ident.update(record.x[k], record.f[k])
        for name in plant.parameters:
            np.testing.assert_array_equal(result[k + 1][f"{name}_hat"], estimate.parameters[name], err_msg=name)
            assert result[k + 1][f"{name}_status"] == STATUSES.index(estimate.status[name])
    assert any(s == "published" for s in estimate.status.values())


# ---------------------------------------------------------------------- the C equation FMU
#: A 2-DOF chain with a cubic coupling, a force on each mass (two force inputs).
TWO_FORCES = ("m1*der(x1,2) + b1*der(x1) + k1*x1 + k2*(x1-x2) + kc*(x1-x2)^3 = f1; "
              "m2*der(x2,2) + b2*der(x2) + k2*(x2-x1) + kc*(x2-x1)^3 = f2")
TWO_FORCES_COLUMNS = ("t", "f1", "f2", "x1", "x2")
TWO_FORCES_TRUTH = dict(m1=1.1, b1=2.0, k1=1500.0, k2=800.0, kc=2e6, m2=0.7, b2=1.0)


def _assert_fmu_equals_identifier(result, model, record, method="robust", **options):
    """Every estimate, status and identified flag of an FMU run (``result``, one row before the
    first step) equal the online identifier's at every sample: estimates within the one-ulp
    spread of the identifier on this record, statuses and flags exactly. The paper method's
    first estimates, while its equations are singular to rounding (condition above 1e8), are
    rounding noise and are not compared (as in tests/test_estimator_generic_c.py)."""
    ident = OnlineIdentifier(model, record.dt, method, **options)
    estimates = [ident.update(x, f) for x, f in zip(record.x, record.f)]
    names = list(model.parameters)
    assert all(np.isnan(result[f"{p}_hat"][0]) for p in names)
    noise = np.array([e.condition > 1e8 for e in estimates]) if method == "paper" else np.zeros(len(estimates), bool)
    identifier_spread(model, record, method, **options).assert_history(
        {p: np.where(noise, np.nan, result[f"{p}_hat"][1:]) for p in names},
        {p: np.where(noise, np.nan, [e.parameters[p] for e in estimates]) for p in names}, ~noise)
    for p in names:
        np.testing.assert_array_equal(result[f"{p}_status"][1:], [STATUSES.index(e.status[p]) for e in estimates],
                                      err_msg=p)
    np.testing.assert_array_equal(result["identified"][1:].astype(bool), [e.identified for e in estimates])
    return estimates


@needs_cc
@pytest.mark.parametrize("version", [2, 3])
def test_c_equation_fmu_equals_the_online_identifier_and_identify(tmp_path, record, version):
    """The C FMU (the generic core on the equation's generated description): fmpy validate, the
    units and interface of the pythonfmu FMU, its model's generated source in sources/, and at
    every sample the values of OnlineIdentifier and of identify(check=False) (the estimator run
    of identify with the same method and options)."""
    fmu = c_fmus.build_equation_fmu(DAMPING, tmp_path, name="NonlinearDamping", units={"x": "m", "f": "N"},
                                    fmi_version=version, backend="c")
    assert fmu.name == ("NonlinearDamping.fmu" if version == 2 else "NonlinearDamping_fmi3.fmu")
    assert validate_fmu(str(fmu)) == []
    md = fmpy.read_model_description(str(fmu))
    assert md.fmiVersion == f"{version}.0" and md.coSimulation.canHandleVariableCommunicationStepSize is False
    variables = {v.name: v for v in md.modelVariables}
    units = {v.name: v.unit for v in md.modelVariables}
    assert [v.name for v in md.modelVariables if v.causality == "input"] == ["x", "f", "enable", "reset"]
    assert (units["x"], units["f"], units["c_hat"], units["kp_hat"], units["k_nominal"]) == \
        ("m", "N", "N.s/m3", "N/m3", "N/m")
    assert variables["c_status"].type == ("Integer" if version == 2 else "Int32")
    assert variables["identified"].type == "Boolean"
    python = fmpy.read_model_description(str(build_equation_fmu(DAMPING, tmp_path / "py", name="NonlinearDamping",
                                                                units={"x": "m", "f": "N"})))
    assert {v.name: v.unit for v in python.modelVariables if v.name != "time"} == \
        {k: u for k, u in units.items() if k != "time"}  # the same variables and units as the pythonfmu FMU
    with zipfile.ZipFile(fmu) as z:
        names = z.namelist()
        build = z.read("sources/duffid_build.h").decode()
    assert "sources/estimator_model.c" in names and "sources/duffid_estimator.c" in names
    assert "#define DUFFID_GENERATED_MODEL" in build
    result = simulate_record(fmu, record, ["x", "f"])
    estimates = _assert_fmu_equals_identifier(result, EquationModel(DAMPING), record)
    assert estimates[-1].identified  # the record determines every parameter: a meaningful comparison
    for name, truth in TRUTH.items():
        assert abs(result[f"{name}_hat"][-1] / truth - 1) < 0.05, name
    run = identify(record, EquationModel(DAMPING), check=False, engine="python")
    identifier_spread(EquationModel(DAMPING), record).assert_history(
        {p: result[f"{p}_hat"][1:] for p in TRUTH}, run.history)


@needs_cc
def test_c_equation_fmu_with_two_forces_a_ring_down_and_the_paper_method(tmp_path, record):
    """Two displacement and two force inputs (in the order of the equation's columns); a
    force-free ring-down (ratios); the paper method through the Integer parameter ``method``."""
    model = EquationModel(TWO_FORCES, TWO_FORCES_COLUMNS, values=TWO_FORCES_TRUTH)
    two = measure(simulate(model, [Chirp(5.0, 2.0, 20.0, 1.0), Step(3.0) + Chirp(2.0, 3.0, 25.0, 1.0)], 1.0,
                           1e-3), snr_db=60, seed=4)
    fmu = c_fmus.build_equation_fmu(TWO_FORCES, tmp_path, name="TwoForces", columns=TWO_FORCES_COLUMNS,
                                    backend="c")
    md = fmpy.read_model_description(str(fmu))
    assert [v.name for v in md.modelVariables if v.causality == "input"] == ["x1", "x2", "f1", "f2", "enable",
                                                                              "reset"]
    estimates = _assert_fmu_equals_identifier(simulate_record(fmu, two, ["x1", "x2", "f1", "f2"]),
                                              EquationModel(TWO_FORCES, TWO_FORCES_COLUMNS), two)
    assert estimates[-1].identified
    ring = "der(x,2) + c*der(x) + w*x + a*x^3 = 0"
    ring_model = EquationModel(ring, values=dict(c=3.0, w=2000.0, a=5e6))
    ring_record = measure(simulate(ring_model, lambda t: 0.0 * t, 1.0, 1e-3, x0=[0.02]), snr_db=50, seed=6)
    fmu = c_fmus.build_equation_fmu(ring, tmp_path, name="RingDown", backend="c")
    inputs = [v.name for v in fmpy.read_model_description(str(fmu)).modelVariables if v.causality == "input"]
    sig = ring_model.regressor.signals
    assert inputs == list(sig.x_names) + list(sig.f_names) + ["enable", "reset"]
    inputs = inputs[:-2]
    assert _assert_fmu_equals_identifier(simulate_record(fmu, ring_record, inputs), EquationModel(ring),
                                         ring_record)[-1].identified
    fmu = c_fmus.build_equation_fmu(DAMPING, tmp_path, name="Damping", backend="c")
    _assert_fmu_equals_identifier(simulate_record(fmu, record, ["x", "f"], {"method": 1}), EquationModel(DAMPING),
                                  record, "paper")


@needs_cc
def test_c_chain_fmu_equals_the_online_identifier(tmp_path):
    """duffid build-estimator --chain 2 --coulomb --fmi 3 (C): x1, x2 [m], f1 [N], the chain's
    parameters with Coulomb friction, at every sample what OnlineIdentifier gives."""
    from duffid import Chain, model_from_name

    assert main(["build-estimator", "--chain", "2", "--coulomb", "--fmi", "3", "-o", str(tmp_path)]) == 0
    fmu = tmp_path / "ChainEstimator2_fmi3.fmu"
    assert validate_fmu(str(fmu)) == []
    units = {v.name: v.unit for v in fmpy.read_model_description(str(fmu)).modelVariables}
    assert (units["x2"], units["f1"], units["m2_hat"], units["fc1_hat"], units["k1_3_hat"]) == \
        ("m", "N", "kg", "N", "N/m3")
    plant = Chain(masses=(0.9, 0.6), damping=(1.5, 1.0), stiffness=({1: 1200.0, 3: 1e6}, {1: 700.0, 3: 0.0}),
                  coulomb=(0.3, 0.2), orders=(1, 3))
    record = measure(simulate(plant, Chirp(6.0, 2.0, 20.0, 1.0), 1.0, 1e-3), snr_db=60, seed=2)
    model = model_from_name("chain", 2, coulomb=True)
    assert list(model.parameters) == list(plant.parameters)
    _assert_fmu_equals_identifier(simulate_record(fmu, record, ["x1", "x2", "f1"]), model, record)


def _fnv1a(data: bytes) -> int:
    """fmus/common's fmu_state_checksum (FNV-1a, 64 bits) from its seed."""
    h = 14695981039346656037
    for byte in data:
        h = ((h ^ byte) * 1099511628211) & 0xFFFFFFFFFFFFFFFF
    return h


@needs_cc
def test_c_equation_fmu_state_round_trip_and_a_state_of_another_model(tmp_path, record):
    """get/set and serialised FMU states continue bit for bit; a state of another equation whose
    description has the same sizes (x^2 for x^3: the same variables, parameters and tables) is
    refused by the glue (another FMU), and, its identity forged and its checksum resealed, by the
    model's check_state (the generated model's signature), the instance left as it was."""
    other_equation = DAMPING.replace("kp*x^3", "kp*x^2")
    a = c_fmus.build_equation_fmu(DAMPING, tmp_path, name="Damping", backend="c")
    b = c_fmus.build_equation_fmu(other_equation, tmp_path, name="Damping2", backend="c")
    types = variable_types(c_fmus.equation_interface(DAMPING, name="Damping"))
    outputs = [f"{p}_hat" for p in TRUTH] + ["condition"]

    def step(fmu, vr, k):
        fmu.setReal([vr["x"], vr["f"]], [float(record.x[k, 0]), float(record.f[k, 0])])
        fmu.doStep(currentCommunicationPoint=k * record.dt, communicationStepSize=record.dt)

    messages = []
    fa, vra = start_fmi2(a, tmp_path, messages, None, types, name="a")
    fa2, _ = start_fmi2(a, tmp_path, messages, None, types, name="a2")
    fb, vrb = start_fmi2(b, tmp_path, messages, None, types, name="b")
    try:
        for k in range(3000):
            step(fa, vra, k)
            step(fb, vrb, k)
        state = fa.getFMUstate()
        data = bytes(fa.serializeFMUstate(state))
        for k in range(3000, 3600):
            step(fa, vra, k)
        reference = fa.getReal([vra[n] for n in outputs])
        assert np.all(np.isfinite(reference))
        fa.setFMUstate(state)
        fa.freeFMUstate(state)
        for k in range(3000, 3600):
            step(fa, vra, k)
        np.testing.assert_array_equal(fa.getReal([vra[n] for n in outputs]), reference)
        restored = fa2.deSerializeFMUstate(data)  # another instance: the estimator is relocated
        fa2.setFMUstate(restored)
        fa2.freeFMUstate(restored)
        for k in range(3000, 3600):
            step(fa2, vra, k)
        np.testing.assert_array_equal(fa2.getReal([vra[n] for n in outputs]), reference)

        before = fb.getReal([vrb[n] for n in outputs])
        own = bytes(fb.serializeFMUstate(fb.getFMUstate()))
        for forged, reason in ((data, "saved by another FMU or build"),
                               (data[:16] + own[16:24] + data[24:], "inconsistent (estimator field model ")):
            forged = forged[:8] + _fnv1a(forged[16:]).to_bytes(8, "little") + forged[16:]
            messages.clear()
            with pytest.raises(FMICallException):
                fb.setFMUstate(fb.deSerializeFMUstate(forged))
            assert any(reason in text for _, _, text in messages), messages
            np.testing.assert_array_equal(fb.getReal([vrb[n] for n in outputs]), before)
    finally:
        for fmu in (fa, fa2, fb):
            fmu.freeInstance()


@needs_cc
def test_build_estimator_cli_backends(tmp_path, capsys, monkeypatch):
    """--fmi 3 and -o a folder; invalid equations name the term with the C backend too; without
    a C compiler "auto" builds the pythonfmu FMU and says why in one line, and FMI 3 is refused."""
    assert main(["build-estimator", "--equation", DAMPING, "--name", "NLD", "--units", "x=m,f=N", "--fmi", "3",
                 "-o", str(tmp_path / "out")]) == 0
    fmu = tmp_path / "out" / "NLD_fmi3.fmu"
    assert str(fmu) in capsys.readouterr().out and validate_fmu(str(fmu)) == []
    assert main(["build-estimator", "--equation", DAMPING, "--name", "NLD", "--fmi", "3",
                 "-o", str(tmp_path / "NLD.fmu")]) == 2
    assert "NLD_fmi3.fmu" in capsys.readouterr().err
    with pytest.raises(EquationError, match="'F' is not a column"):
        c_fmus.build_equation_fmu("m*der(x,2) + b*der(x) + k*x = F", tmp_path, name="E", backend="c")
    with pytest.raises(EquationError, match="sin"):
        c_fmus.build_equation_fmu("m*der(x,2) + k*sin(der(x,3)) = f", tmp_path, name="E", backend="c")
    with pytest.raises(InputError, match="backend must be one of auto, c, python"):
        c_fmus.build_equation_fmu(DAMPING, tmp_path, name="E", backend="fortran")
    monkeypatch.setenv("CC", "no-such-cc")
    with pytest.raises(CompilerNotFoundError, match="FMI 3.0 estimator FMU needs the C backend"):
        c_fmus.build_equation_fmu(DAMPING, tmp_path, name="E", fmi_version=3)
    path = c_fmus.build_equation_fmu(DAMPING, tmp_path / "fallback", name="NLD", units={"x": "m", "f": "N"})
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "pythonfmu FMU" in err and "no C compiler found" in err
    assert fmpy.read_model_description(str(path)).generationTool.startswith("PythonFMU")


@needs_cc
@pytest.mark.slow
@pytest.mark.skipif(shutil.which("cmake") is None, reason="fmpy's rebuild needs cmake")
@pytest.mark.parametrize("version", [2, 3])
def test_c_equation_fmu_rebuilt_from_its_sources_by_fmpy_is_identical(tmp_path, record, version):
    """sources/ holds the generated model and the duffid_build.h that selects it: fmpy's own
    rebuild (the FMI 2 file list, the FMI 3 buildDescription.xml, no flags of duffid's) gives
    a binary whose results equal the shipped one's bit for bit."""
    from fmpy.build import build_platform_binary

    fmu = c_fmus.build_equation_fmu(DAMPING, tmp_path, name="NonlinearDamping", fmi_version=version, backend="c")
    directory = (tmp_path / "unzipped").resolve()
    fmpy.extract(str(fmu), str(directory))
    binary = next((directory / "binaries").glob("*/*.so"))
    binary.unlink()
    (tmp_path / "cmake").mkdir()
    build_platform_binary(directory, build_dir=tmp_path / "cmake")
    assert binary.exists()
    rebuilt = tmp_path / "rebuilt" / fmu.name
    rebuilt.parent.mkdir()
    shutil.make_archive(str(rebuilt.with_suffix("")), "zip", directory)
    rebuilt.with_suffix(".zip").rename(rebuilt)
    a = simulate_record(fmu, record, ["x", "f"])
    b = simulate_record(rebuilt, record, ["x", "f"])
    for name in TRUTH:
        np.testing.assert_array_equal(b[f"{name}_hat"], a[f"{name}_hat"], err_msg=name)
