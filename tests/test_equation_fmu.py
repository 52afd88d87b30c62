"""The estimator FMU of the user's own equations (duffid build-estimator, pythonfmu): its units
follow from the signals', it passes fmpy validate, and through fmpy it gives at every sample
what the online identifier gives on the same record."""
from __future__ import annotations

import fmpy
import numpy as np
import pytest
from fmpy.validation import validate_fmu
from fmu_helpers import simulate_record

from duffid import Chirp, measure, simulate
from duffid.cli import main
from duffid.errors import EquationError, InputError
from duffid.fmu.python_estimator import build_equation_fmu
from duffid.identification.engine import STATUSES, OnlineIdentifier
from duffid.models.equation_model import EquationModel
from duffid.models.units import format_unit, parameter_units, parse_unit, si_exponents

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
    """duffid build-estimator --chain 3: inputs x1..x3 [m], f1 [N], the chain's parameters with
    their units, at every sample what OnlineIdentifier of the same chain gives."""
    from duffid import Multisine, model_from_name

    assert main(["build-estimator", "--chain", "3", "-o", str(tmp_path / "ChainEstimator3.fmu")]) == 0
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
