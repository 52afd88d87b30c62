"""Modelica library and its translation: structure, equations, errors, export options.

Tolerances: right-hand sides evaluated by CasADi against duffid's models are a handful of
scalar operations: 1e-12 relative plus 1e-12 absolute covers the cancellation between terms
of size ~10 (force, k x) with hundreds of ulps to spare; no BLAS is involved.
"""
from __future__ import annotations

import argparse
import inspect
import re
from pathlib import Path

import numpy as np
import pytest

from duffid.cli import build_fmus
from duffid.modelica import export as modelica
from duffid.modelica.export import EXAMPLE_PLANTS, ModelicaExportError, library_path, translate
from duffid.models.chain import PAPER_DUFFING1, PAPER_DUFFING2, Chain, Duffing1, Duffing2, DuffingCircuit

LIB = library_path()


def evaluate(ode, x, u, params=None):
    """Derivatives and named values of a translated model at (t=0, x, u)."""
    p = [v.value for v in ode.parameters]
    if params:
        names = [v.name for v in ode.parameters]
        for k, val in params.items():
            p[names.index(k)] = val
    guess = np.zeros(len(ode.tears))
    dx, values, _, residuals = ode.function(0.0, np.asarray(x, float), np.asarray(u, float), p, guess)
    named = dict(zip([v.name for v in ode.computed], np.array(values).ravel()))
    return np.array(dx).ravel(), named, np.array(residuals).ravel()


def _quiet_callbacks():
    """fmi2 callbacks with a logger of our own (fmpy's default proxy can be left dangling)."""
    from fmpy.fmi2 import fmi2CallbackFunctions, fmi2CallbackLoggerTYPE

    callbacks = fmi2CallbackFunctions()
    callbacks.logger = fmi2CallbackLoggerTYPE(lambda *args: None)
    _quiet_callbacks.keep = callbacks  # keep the ctypes callback alive
    return callbacks


def write_model(tmp_path: Path, text: str, name: str = "Test.mo") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


# ---------------------------------------------------------------------------------- library
def test_library_has_the_components_of_the_issue():
    from duffid.modelica.source import ModelicaSource

    classes = ModelicaSource(LIB).classes
    for name in ["Translational." + c for c in ("Flange", "Fixed", "Mass", "LinearSpring", "PolynomialSpring",
                                               "CubicSpring", "Damper", "CoulombFriction", "Force")] + \
            ["Electrical." + c for c in ("Pin", "Ground", "Resistor", "Inductor", "Capacitor", "CubicCapacitor",
                                        "SaturatingInductor", "VoltageSource")] + \
            ["Examples." + c for c in EXAMPLE_PLANTS]:
        assert f"Duffid.{name}" in classes, name
    assert classes["Duffid.Translational.Flange"].kind == "connector"
    # every declaration of a component has a description string
    text = (LIB / "Translational.mo").read_text() + (LIB / "Electrical.mo").read_text()
    for line in text.splitlines():
        if re.match(r"\s*(parameter |flow |input )?(Units\.\w+|Real|Flange|Pin) \w+", line):
            assert '"' in line, line


@pytest.mark.parametrize("plant", EXAMPLE_PLANTS)
def test_examples_translate_with_inputs_outputs_and_units(plant):
    ode = translate(LIB, f"Duffid.Examples.{plant}")
    assert len(ode.inputs) == 1
    outputs = [v for v in ode.flat.variables if v.output]
    assert outputs and all(v.unit for v in outputs)
    assert all(v.description for v in ode.parameters + ode.inputs + outputs)
    assert ode.flat.experiment["StopTime"] > 0


def test_plant_interfaces_and_defaults_follow_duffid_models():
    one = translate(LIB, "Duffid.Examples.Oscillator1DOF")
    assert {v.name: v.value for v in one.parameters if "." not in v.name} == pytest.approx(PAPER_DUFFING1)
    assert [v.name for v in one.inputs] == ["f"]
    assert {v.name for v in one.flat.variables if v.output} == {"x", "v"}
    two = translate(LIB, "Duffid.Examples.Oscillator2DOF")
    assert {v.name: v.value for v in two.parameters if "." not in v.name} == pytest.approx(PAPER_DUFFING2)
    assert [v.name for v in two.inputs] == ["f1"]
    assert {"x1", "x2"} <= {v.name for v in two.flat.variables if v.output}
    circuit = translate(LIB, "Duffid.Examples.DuffingCircuit")
    assert {v.name: v.value for v in circuit.parameters if "." not in v.name} == \
        pytest.approx({"L": 0.1, "R": 2.0, "C": 1e-3, "a": 5e6})
    assert [v.name for v in circuit.inputs] == ["u"]
    assert {v.name for v in circuit.flat.variables if v.output} == {"q", "i"}
    chain = translate(LIB, "Duffid.Examples.ChainNDOF")
    assert [v.name for v in chain.states] == [f"mass[{i}].{s}" for i in (1, 2, 3) for s in "sv"]
    assert {f"x[{i}]" for i in (1, 2, 3)} <= {v.name for v in chain.flat.variables if v.output}


# ---------------------------------------------------------------------------------- equations
RNG = np.random.default_rng(7)


def test_oscillators_match_duffid_models():
    params = {"m": 2.0, "b": 10.0, "k": 1500.0, "kp": -1e6}
    ode = translate(LIB, "Duffid.Examples.Oscillator1DOF")
    for _ in range(5):
        x, v, f = RNG.normal(0, 0.01), RNG.normal(0, 0.2), RNG.normal(0, 5)
        dx, named, _ = evaluate(ode, [x, v], [f], params)
        a = Duffing1(**params).acceleration(np.array([x]), np.array([v]), np.array([f]))[0]
        np.testing.assert_allclose(dx, [v, a], rtol=1e-13, atol=1e-15)
        assert named["x"] == x and named["v"] == v
    ode = translate(LIB, "Duffid.Examples.Oscillator2DOF")
    model = Duffing2()
    for _ in range(5):
        x, v, f = RNG.normal(0, 0.01, 2), RNG.normal(0, 0.2, 2), RNG.normal(0, 5)
        dx, named, _ = evaluate(ode, [x[0], v[0], x[1], v[1]], [f])
        a = model.acceleration(x, v, np.array([f]))
        np.testing.assert_allclose(dx, [v[0], a[0], v[1], a[1]], rtol=1e-12, atol=1e-12)


def test_chain_with_friction_matches_duffid_chain():
    ode = translate(LIB, "Duffid.Examples.ChainNDOF")
    params = {"m[2]": 1.5, "kp[1]": -1e5, "kp[3]": 2e5, "fc[1]": 0.5, "fc[2]": 0.2, "fc[3]": 0.1, "b[3]": 2.0}
    chain = Chain(masses=(1.0, 1.5, 1.0), damping=(1.0, 1.0, 2.0),
                  stiffness=({1: 1000.0, 3: -1e5}, {1: 1000.0}, {1: 1000.0, 3: 2e5}), coulomb=(0.5, 0.2, 0.1))
    for _ in range(5):
        x, v, f = RNG.normal(0, 0.01, 3), RNG.normal(0, 1e-3, 3), RNG.normal(0, 5)
        dx, _, _ = evaluate(ode, np.ravel(np.column_stack([x, v])), [f], params)
        np.testing.assert_allclose(dx[1::2], chain.acceleration(x, v, np.array([f])), rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(dx[0::2], v)


def test_duffing_circuit_matches_duffid_circuit():
    ode = translate(LIB, "Duffid.Examples.DuffingCircuit")
    params = {"L": 0.12, "R": 2.5, "C": 1.2e-3, "a": 4e6}
    for _ in range(5):
        q, i, u = RNG.normal(0, 1e-3), RNG.normal(0, 0.1), RNG.normal(0, 5)
        dx, named, _ = evaluate(ode, [i, q], [u], params)  # states inductor.i, capacitor.q
        qdd = DuffingCircuit(**params).acceleration(np.array([q]), np.array([i]), np.array([u]))[0]
        np.testing.assert_allclose(dx, [qdd, i], rtol=1e-12)
        assert named["q"] == q and named["i"] == i


def test_saturating_circuit_solves_its_algebraic_loop_with_newton():
    ode = translate(LIB, "Duffid.Examples.SaturatingCircuit")
    assert [v.name for v in ode.tears] == ["inductor.i"]
    assert [v.name for v in ode.states] == ["inductor.psi", "capacitor.v"]
    for psi in (0.0, 0.05, -0.3, 1.0):
        dx, named, residuals = evaluate(ode, [psi, 2.0], [10.0])
        i = named["i"]
        assert 0.01 * i + 0.09 * np.tanh(i) == pytest.approx(psi, abs=1e-13)
        assert np.all(np.abs(residuals) < 1e-12)
        np.testing.assert_allclose(dx, [10.0 - 2.0 * i - 2.0, i / 1e-3], rtol=1e-12, atol=1e-12)


def test_index_reduction_demotes_relative_states_not_masses():
    ode = translate(LIB, "Duffid.Examples.Oscillator1DOF")
    assert ode.demoted == ["damper.s_rel"]
    assert [v.name for v in ode.states] == ["mass.s", "mass.v"]
    _, named, _ = evaluate(ode, [0.01, 0.3], [0.0])
    assert named["damper.s_rel"] == pytest.approx(0.01) and named["der(damper.s_rel)"] == pytest.approx(0.3)
    chain = translate(LIB, "Duffid.Examples.ChainNDOF")
    assert sorted(chain.demoted) == sorted([f"friction[{i}].s" for i in (1, 2, 3)] +
                                          [f"damper[{i}].s_rel" for i in (1, 2, 3)])


LINEAR = """
model Linear "Linear components of the library"
  input Real u(unit = "V") "source voltage";
  output Real x(unit = "m") "mass position";
  output Real vC(unit = "V") "capacitor voltage";
  Duffid.Translational.Fixed wall;
  Duffid.Translational.LinearSpring spring(c = 200);
  Duffid.Translational.PolynomialSpring poly(r = 2, k = {50, 1e4});
  Duffid.Translational.Mass mass(m = 2, s(start = 0.1));
  Duffid.Electrical.VoltageSource source;
  Duffid.Electrical.Resistor resistor(R = 10);
  Duffid.Electrical.Capacitor capacitor(C = 1e-2);
  Duffid.Electrical.Ground ground;
equation
  connect(wall.flange, spring.flange_a);
  connect(wall.flange, poly.flange_a);
  connect(spring.flange_b, mass.flange_a);
  connect(poly.flange_b, mass.flange_a);
  connect(source.p, resistor.p);
  connect(resistor.n, capacitor.p);
  connect(capacitor.n, source.n);
  connect(source.n, ground.p);
  source.u = u;
  x = mass.s;
  vC = capacitor.v;
end Linear;
"""


def test_linear_and_polynomial_components(tmp_path):
    ode = translate([LIB, write_model(tmp_path, LINEAR)], "Linear")
    assert [v.name for v in ode.states] == ["mass.s", "mass.v", "capacitor.v"]
    assert ode.flat.variable("mass.s").start == 0.1
    x, v, vc, u = 0.02, 0.1, 1.0, 5.0
    dx, named, _ = evaluate(ode, [x, v, vc], [u])
    np.testing.assert_allclose(dx, [v, -(200 * x + 50 * x + 1e4 * x**2) / 2, (u - vc) / 10 / 1e-2], rtol=1e-13)
    assert named["poly.f_j[2]"] == pytest.approx(1e4 * x**2)


def test_noevent_relations_are_translated(tmp_path):
    text = """
model Smooth
  input Real u;
  output Real y;
  Real x(start = 0, fixed = true);
equation
  der(x) = noEvent(if x > 0 then -x else -2*x) + u;
  y = x;
end Smooth;
"""
    ode = translate(write_model(tmp_path, text), "Smooth")
    assert evaluate(ode, [1.0], [0.0])[0][0] == -1.0
    assert evaluate(ode, [-1.0], [0.0])[0][0] == 2.0


# ---------------------------------------------------------------------------------- errors
UNSUPPORTED = {
    "when-clause": ("  Real x(start = 1, fixed = true);\n  Real y;\nequation\n  der(x) = -x;\n"
                    "  when x < 0.5 then\n    reinit(x, 1);\n  end when;\n  y = x;\n", 8),
    "algorithm section": ("  Real x(start = 1);\n  Real y;\nequation\n  der(x) = -x;\nalgorithm\n  y := x;\n", 8),
    "relation '>'": ("  Real x(start = 1);\nequation\n  der(x) = if x > 0 then -x else x;\n", 6),
    "pre()": ("  Real x(start = 1);\nequation\n  der(x) = -pre(x);\n", 6),
    "initial equation": ("  Real x;\ninitial equation\n  x = 1;\nequation\n  der(x) = -x;\n", 5),
    "discrete variable": ("  discrete Real d;\n  Real x;\nequation\n  der(x) = -x;\n  d = 1;\n", 4),
}


@pytest.mark.parametrize("construct", UNSUPPORTED)
def test_unsupported_constructs_name_construct_class_and_line(tmp_path, construct):
    body, line = UNSUPPORTED[construct]
    path = write_model(tmp_path, f"package P\n  \"test package\"\nmodel Bad \"bad\"\n{body}end Bad;\nend P;\n")
    with pytest.raises(ModelicaExportError) as info:
        translate(path, "P.Bad")
    message = str(info.value)
    assert construct in message and "P.Bad" in message and f"{path}:{line}" in message, message


def test_unsupported_construct_in_a_used_component_is_found(tmp_path):
    text = """package Q
  model Comp "component with an event"
    Real x(start = 1);
  equation
    der(x) = -x;
    when x < 0.5 then
      terminate("done");
    end when;
  end Comp;
  model Top
    Comp c;
  end Top;
end Q;
"""
    path = write_model(tmp_path, text)
    with pytest.raises(ModelicaExportError, match=rf"when-clause .* class Q\.Comp \({re.escape(str(path))}:6\)"):
        translate(path, "Q.Top")


def test_integer_variable_and_component_arrays_outside_the_top_class(tmp_path):
    text = """package R
  model Counter
    Integer k;
    Real x(start = 1);
  equation
    der(x) = -x;
    k = 1;
  end Counter;
  model Inner
    Duffid.Translational.Mass mass[2];
  end Inner;
  model Outer
    Inner sub;
  end Outer;
end R;
"""
    path = write_model(tmp_path, text)
    with pytest.raises(ModelicaExportError, match=r"discrete \(Integer/Boolean\) variable k in class R\.Counter"):
        translate(path, "R.Counter")
    with pytest.raises(ModelicaExportError, match=r"component array mass in class R\.Inner .*:10\)"):
        translate([LIB, path], "R.Outer")


def test_structural_errors(tmp_path):
    text = """package S
  model Unbalanced
    Real x(start = 0);
    Real y;
  equation
    der(x) = -x;
  end Unbalanced;
  model InputConstraint "a state forced to follow an input needs its derivative"
    input Real u;
    Real x(start = 0);
    Real y;
  equation
    der(x) = y;
    x = u;
  end InputConstraint;
end S;
"""
    path = write_model(tmp_path, text)
    with pytest.raises(ModelicaExportError, match="not balanced: 1 equations for 2 unknowns"):
        translate(path, "S.Unbalanced")
    with pytest.raises(ModelicaExportError, match=r"constraint .* involves input\(s\) \['u'\]"):
        translate(path, "S.InputConstraint")
    with pytest.raises(ModelicaExportError, match="class S.Missing not found"):
        translate(path, "S.Missing")
    bad = write_model(tmp_path, "model Syntax\n  Real x\nequation\n  der(x) = 1;\nend Syntax;\n", "Syntax.mo")
    with pytest.raises(ModelicaExportError, match=r"syntax error in class Syntax at .*Syntax\.mo:3"):
        translate(bad, "Syntax")


# ---------------------------------------------------------------------------------- API
def test_public_api_and_arguments():
    assert set(modelica.__all__) <= set(dir(modelica))
    sig = inspect.signature(modelica.export_fmu)
    assert list(sig.parameters)[:5] == ["mo_path", "class_name", "out", "fmi_version", "kind"]
    with pytest.raises(ValueError, match="fmi_version"):
        modelica.export_fmu(LIB, "Duffid.Examples.Oscillator1DOF", "x.fmu", fmi_version=1)
    with pytest.raises(ValueError, match="kind"):
        modelica.export_fmu(LIB, "Duffid.Examples.Oscillator1DOF", "x.fmu", kind="model")
    with pytest.raises(TypeError):
        modelica.export_fmu(LIB, "Duffid.Examples.Oscillator1DOF", "x.fmu", fmi_verison=2)  # misspelt
    parser = argparse.ArgumentParser()
    build_fmus.add_parser(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["build-fmus"])
    assert args.out == Path("build/fmus") and args.plant is None
    args = parser.parse_args(["build-fmus", "--out", "o", "--plant", "DuffingCircuit"])
    assert args.out == Path("o") and args.plant == ["DuffingCircuit"]


def test_omc_export_is_optional():
    import shutil

    if shutil.which("omc") is None:
        with pytest.raises(ModelicaExportError, match="omc is not on PATH"):
            modelica.export_fmu_omc(LIB, "Duffid.Examples.Oscillator1DOF", "out")


def test_chain_size_is_a_structural_parameter():
    ode = translate(LIB, "Duffid.Examples.ChainNDOF", structural_parameters={"n": 5})
    assert len(ode.states) == 10 and [v.name for v in ode.parameters][:5] == [f"m[{i}]" for i in range(1, 6)]
    x, v = RNG.normal(0, 0.01, 5), RNG.normal(0, 0.1, 5)
    dx, _, _ = evaluate(ode, np.ravel(np.column_stack([x, v])), [3.0])
    chain = Chain(masses=(1.0,) * 5, damping=(1.0,) * 5, stiffness=({1: 1000.0},) * 5)
    np.testing.assert_allclose(dx[1::2], chain.acceleration(x, v, np.array([3.0])), rtol=1e-12, atol=1e-12)
    with pytest.raises(ModelicaExportError, match="'m' is not an Integer or Boolean parameter"):
        translate(LIB, "Duffid.Examples.ChainNDOF", structural_parameters={"m": 2})


def test_export_options_me_or_cs_only_and_structural_size(tmp_path):
    from fmpy import read_model_description, simulate_fmu
    from fmpy.validation import validate_fmu

    from duffid import Step, simulate

    path = modelica.export_fmu(LIB, "Duffid.Examples.ChainNDOF", tmp_path, fmi_version=3, kind="cs",
                               structural_parameters={"n": 5})
    assert path == tmp_path / "ChainNDOF_fmi3.fmu"
    assert validate_fmu(str(path)) == []
    md = read_model_description(path)
    assert md.modelExchange is None and md.coSimulation is not None
    t = np.arange(501) * 1e-3
    signal = np.zeros(len(t), dtype=[("time", float), ("f", float)])
    signal["time"], signal["f"] = t, 10.0
    result = simulate_fmu(path, stop_time=0.5, output_interval=1e-3, input=signal, output=["x[5]"])
    chain = Chain(masses=(1.0,) * 5, damping=(1.0,) * 5, stiffness=({1: 1000.0},) * 5)
    ref = simulate(chain, Step(10.0), 0.5, 1e-3).x[:, 4]
    assert np.max(np.abs(result["x[5]"] - ref)) < 1e-7 * np.max(np.abs(ref))
    me = modelica.export_fmu(LIB, "Duffid.Examples.Oscillator1DOF", tmp_path / "me.fmu", kind="me")
    md = read_model_description(me)
    assert md.coSimulation is None and md.modelExchange is not None and validate_fmu(str(me)) == []
    from fmpy import extract
    from fmpy.fmi2 import FMU2Slave

    with pytest.raises(Exception, match="instantiate"):  # the binary knows it has no Co-Simulation
        FMU2Slave(guid=md.guid, unzipDirectory=extract(me, str(tmp_path / "me")),
                  modelIdentifier="Oscillator1DOF", instanceName="cs").instantiate(callbacks=_quiet_callbacks())
