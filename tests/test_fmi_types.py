"""Every FMI 2 and FMI 3 variable type and arrays in the co-simulation master (issue 36): set,
get, connect, record, constant and CSV inputs, structural parameters, in System (Python and
compiled loops), the configuration files and the CSV output; what the container and SSP export
cannot carry is refused by name. The FMUs are duffid's own typed test FMUs (tests/typed_fmus.py,
tests/fmus), Feedthrough-like and StateSpace-like; results are compared with fmpy's own runs of
the same FMUs."""
from __future__ import annotations

import json
import zipfile

import fmpy
import numpy as np
import pytest
from fmpy.fmi3 import FMU3Slave
from fmpy.validation import validate_fmu

import typed_fmus
from duffid.cosim.config import load_config
from duffid.cosim.system import System
from duffid.errors import CosimError, WiringError

FMI3 = typed_fmus.FMI3_TYPES
NUMERIC3 = tuple(t for t in FMI3 if t not in ("String", "Binary"))
#: A value of every FMI 3 type other than its start value, set from outside.
VALUES = {"Float32": 0.25, "Float64": -2.5, "Int8": -128, "UInt8": 255, "Int16": -32768, "UInt16": 65535,
          "Int32": -2**31, "UInt32": 2**32 - 1, "Int64": -2**63, "UInt64": 2**64 - 1, "Boolean": False,
          "String": "grüße, \"quoted\"", "Binary": b"\x00\xff\x10", "Enumeration": 3}


@pytest.fixture(scope="session")
def typed(tmp_path_factory):
    """The typed test FMUs, built once per session, and FMUs that only describe (no binary)."""
    folder = tmp_path_factory.mktemp("typed_fmus")
    fmus = {m.name: typed_fmus.build(m, folder) for m in
            (typed_fmus.feedthrough3(), typed_fmus.statespace3(), typed_fmus.feedthrough2())}
    fmus["Stair3"] = typed_fmus.build(typed_fmus.stair3(), folder, cosimulation_attributes=' hasEventMode="true"')
    clock = '<Clock name="tick" valueReference="900" causality="input" variability="discrete" intervalVariability="triggered"/>'
    assert all(validate_fmu(str(path)) == [] for path in fmus.values())  # every FMU duffid makes passes
    fmus["Clocked"] = typed_fmus.build(typed_fmus.feedthrough3(), folder / "clocked", description_only=True,
                                       extra_variables=clock)
    return fmus


def _fmpy_feedthrough(path, inputs, steps=2, h=1e-3):
    """fmpy's own run of the Feedthrough3 FMU: ``inputs`` (name -> value) set with FMU3Slave's
    setter of each type before each step; every output read with its getter after each step."""
    md = fmpy.read_model_description(str(path))
    variables = {v.name: v for v in md.modelVariables}
    unzipped = fmpy.extract(str(path))
    slave = FMU3Slave(guid=md.instantiationToken, unzipDirectory=unzipped, modelIdentifier="Feedthrough3",
                      instanceName="reference")
    slave.instantiate()
    slave.enterInitializationMode(startTime=0.0)
    slave.exitInitializationMode()
    rows = []
    for k in range(steps):
        for name, value in inputs.items():
            v = variables[name]
            kind = "Int64" if v.type == "Enumeration" else v.type
            getattr(slave, f"set{kind}")([v.valueReference], value if isinstance(value, list) else [value])
        slave.doStep(currentCommunicationPoint=k * h, communicationStepSize=h)
        row = {}
        for v in md.modelVariables:
            if v.causality == "output":
                kind = "Int64" if v.type == "Enumeration" else v.type
                n = int(np.prod(v.shape)) if v.shape else 1
                values = getattr(slave, f"get{kind}")([v.valueReference], nValues=n) if v.shape else \
                    getattr(slave, f"get{kind}")([v.valueReference])
                row[v.name] = values
        rows.append(row)
    slave.terminate()
    slave.freeInstance()
    return rows


# ------------------------------------------------------------------ every FMI 3 type
def test_every_fmi3_type_is_set_connected_and_recorded_as_fmpy_reads_it(typed):
    """Constants of every type into a, a's outputs connected to b's inputs of the same type
    (arrays whole): b's outputs are what fmpy's getters return after fmpy set the same values
    with its setters, type for type."""
    system = System().add("a", typed["Feedthrough3"]).add("b", typed["Feedthrough3"]).add("c", typed["Feedthrough2"])
    for t in FMI3:
        system.set_input(f"a.{t}_input", VALUES[t]).connect(f"a.{t}_output", f"b.{t}_input")
    system.connect("b.String_output", "c.String_input").connect("b.Enumeration_output", "c.Enumeration_input")
    system.set_input("a.Float64_array_input", [[9, 8, 7], [6, 5, 4]]).set_input("a.Int32_array_input", [-1, 0, 1])
    system.connect("a.Float64_array_output", "b.Float64_array_input")
    system.connect("a.Int32_array_output", "b.Int32_array_input")
    result = system.run(0.003, 1e-3, loop="python")
    compiled = system.run(0.003, 1e-3, loop="compiled")  # String and Binary calls called back from C
    for name in result.names:
        assert np.array_equal(result[name], compiled[name]), name
    reference = _fmpy_feedthrough(typed["Feedthrough3"], {
        **{f"{t}_input": VALUES[t] for t in FMI3},
        "Float64_array_input": [9, 8, 7, 6, 5, 4], "Int32_array_input": [-1, 0, 1]})
    for t in FMI3:
        assert result[f"b.{t}_output"][-1] == reference[-1][f"{t}_output"][0], t
        assert result[f"b.{t}_output"][-1] == VALUES[t], t
    assert [result[f"b.Float64_array_output[{i},{j}]"][-1] for i in (1, 2) for j in (1, 2, 3)] == \
        reference[-1]["Float64_array_output"] == [9, 8, 7, 6, 5, 4]
    assert [result[f"b.Int32_array_output[{i}]"][-1] for i in (1, 2, 3)] == reference[-1]["Int32_array_output"]
    assert result["c.String_output"][-1] == VALUES["String"] and result["c.Enumeration_output"][-1] == 3  # FMI 3 -> 2
    dtypes = {"Float32": np.float32, "UInt64": np.uint64, "Int8": np.int8, "Boolean": np.bool_,
              "Enumeration": np.int64, "String": object, "Binary": object}
    for t, dtype in dtypes.items():
        assert result[f"b.{t}_output"].dtype == dtype, t


def test_nothing_is_dropped_from_the_default_record_and_fmpy_agrees_on_every_column(typed):
    """Every output of the FMU is recorded by default (arrays as name[i,j]), with no warning;
    the columns fmpy records for the same FMU (its numeric types and arrays) are equal."""
    path = typed["Feedthrough3"]
    result = System().add("f", path).run(0.003, 1e-3)
    md = fmpy.read_model_description(str(path))
    outputs = [v for v in md.modelVariables if v.causality == "output"]
    expected = []
    for v in outputs:
        expected += [f"f.{v.name}"] if not v.shape else \
            [f"f.{v.name}[{','.join(str(i + 1) for i in ix)}]" for ix in np.ndindex(*v.shape)]
    assert result.names == expected and result.warnings == []
    reference = fmpy.simulate_fmu(str(path), stop_time=0.003, output_interval=1e-3)
    assert set(reference.dtype.names) - {"time"} == {v.name for v in outputs if v.type not in ("String", "Binary")}
    for name in reference.dtype.names[1:]:
        ours = np.array([[result[n][k] for n in expected if n.split("[")[0] == f"f.{name}"]
                         for k in range(len(result))])
        assert np.array_equal(ours.reshape(reference[name].shape), reference[name]), name
    assert result["f.String_parameter_output"][0] == "hello" and result["f.Binary_parameter_output"][0] == b"\n\x0b"


def test_compiled_loop_equals_python_loop_for_every_type_arrays_and_elements(typed):
    """Every FMI 3 type recorded, FMI 2 types, a whole-array connection, element-to-scalar and
    scalar-to-element connections (the other elements keep their start), FMI 2 <-> FMI 3
    Enumeration, a sampled Enumeration input: the C loop gives the Python loop's values bit for bit."""
    f3, f2 = typed["Feedthrough3"], typed["Feedthrough2"]
    system = System().add("a", f3).add("b", f3).add("c", f2).add("d", f2)
    for t in NUMERIC3:
        system.connect(f"a.{t}_output", f"b.{t}_input")
    for t in ("Real", "Integer", "Boolean"):
        system.connect(f"c.{t}_output", f"d.{t}_input")
    system.connect("a.Float64_array_output", "b.Float64_array_input")
    system.connect("a.Enumeration_output", "c.Enumeration_input").connect("c.Enumeration_output", "d.Enumeration_input")
    system.connect("a.Float64_array_output[2,3]", "c.Real_input").connect("c.Integer_output", "b.Int32_array_input[2]")
    system.set_input("a.Float64_array_input", [[1, 2, 3], [4, 5, 6]]).set_input("a.UInt64_input", 2**64 - 1)
    system.set_input("a.Enumeration_input", (np.array([0, 1.5e-3, 1.5e-3, 1.0]), [1, 1, 3, 3]))
    runs = {loop: system.run(0.004, 1e-3, loop=loop) for loop in ("python", "compiled")}
    seidel = {loop: system.run(0.004, 1e-3, loop=loop, ordering="gauss-seidel") for loop in ("python", "compiled")}
    assert runs["compiled"].loop == seidel["compiled"].loop == "compiled"
    for name in runs["python"].names:
        assert np.array_equal(runs["python"][name], runs["compiled"][name]), name
        assert np.array_equal(seidel["python"][name], seidel["compiled"][name]), name
    r = runs["compiled"]
    assert list(r["d.Enumeration_output"]) == [0, 0, 1, 1, 1] and list(r["c.Enumeration_output"]) == [0, 1, 1, 1, 3]
    assert list(r["b.Int32_array_output[2]"][1:]) == [-32] * 4            # from c.Integer_output
    assert list(r["b.Int32_array_output[1]"]) == [1] * 5 and list(r["b.Int32_array_output[3]"]) == [3] * 5  # starts
    assert list(r["d.Real_output"][2:]) == [6.0] * 3                     # a's element [2,3], one step later
    assert r["b.UInt64_output"][-1] == 2**64 - 1


# ------------------------------------------------------------------ FMI 2 types
def test_every_fmi2_type_and_a_csv_input_of_each(typed, tmp_path):
    """Real, Integer, Boolean, String and Enumeration from a CSV file (each column read as its
    input's type) and as constants; parameters of every type; the CSV output writes them back."""
    path = typed["Feedthrough2"]
    csv = tmp_path / "in.csv"
    csv.write_text('t,r,i,b,s,e\n0,1.5,7,true,"a, b",2\n0.001,2.5,9,0,zwei,3\n0.002,2.5,9,0,zwei,3\n')
    system = System().add("f", path, parameters={"Real_parameter": 4.0, "Integer_parameter": -3,
                                                  "Boolean_parameter": False, "String_parameter": "p",
                                                  "Enumeration_parameter": 1})
    system.inputs_from_csv(csv, {"r": "f.Real_input", "i": "f.Integer_input", "b": "f.Boolean_input",
                                 "s": "f.String_input", "e": "f.Enumeration_input"})
    record = [f"f.{t}_{r}" for t in typed_fmus.FMI2_TYPES for r in ("output", "parameter_output")]
    result = system.run(0.002, 1e-3, record=record + ["f.String_input"], loop="python")
    compiled = system.run(0.002, 1e-3, record=record + ["f.String_input"], loop="compiled")  # sampled text in C
    assert all(np.array_equal(result[n], compiled[n]) for n in result.names) and compiled.loop == "compiled"
    assert list(result["f.Real_output"]) == [1.5, 1.5, 2.5]     # the input at t_k, held over the step
    assert list(result["f.Integer_output"]) == [7, 7, 9] and list(result["f.Boolean_output"]) == [True, True, False]
    assert list(result["f.String_output"]) == ["a, b", "a, b", "zwei"]
    assert list(result["f.Enumeration_output"]) == [2, 2, 3]
    assert [result[f"f.{t}_parameter_output"][0] for t in typed_fmus.FMI2_TYPES] == [4.0, -3, False, "p", 1]
    reference = fmpy.simulate_fmu(str(path), stop_time=0.002, output_interval=1e-3,
                                  start_values={"Real_parameter": 4.0, "Integer_parameter": -3,
                                                "Enumeration_parameter": 1, "Boolean_parameter": False})
    for t in ("Real", "Integer", "Boolean", "Enumeration"):
        assert reference[f"{t}_parameter_output"][0] == result[f"f.{t}_parameter_output"][0], t
    out = tmp_path / "out.csv"
    result.to_csv(out)
    lines = out.read_text().splitlines()
    assert lines[1].split(",")[:5] == ["0.0", "1.5", "4.0", "7", "-3"]
    assert '"a, b"' in lines[1] and lines[3].count("zwei") == 2   # String_output and String_input


def test_binary_is_written_as_hex_and_wide_integers_exactly(typed, tmp_path):
    path = typed["Feedthrough3"]
    system = System().add("f", path).set_input("f.Binary_input", "00ff").set_input("f.UInt64_input", 2**64 - 1)
    system.set_input("f.Int64_input", -2**63)
    result = system.run(0.001, 1e-3, record=["f.Binary_output", "f.UInt64_output", "f.Int64_output",
                                             "f.Float32_output", "f.String_output"])
    out = tmp_path / "out.csv"
    result.to_csv(out)
    assert out.read_text().splitlines()[1] == f"0.0,00ff,{2**64 - 1},{-2**63},0.5,hello"


# ------------------------------------------------------------------ arrays and structural parameters
def _fmpy_statespace(path, sizes, arrays, inputs, h):
    """fmpy's own run of StateSpace3: structural parameters in Configuration Mode, then the
    arrays, ``inputs[0]`` as u before initialisation and ``inputs[k]`` before the step from
    t_k; y after initialisation and after each step (FMU3Slave's getters and setters)."""
    md = fmpy.read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    slave = FMU3Slave(guid=md.instantiationToken, unzipDirectory=fmpy.extract(str(path)),
                      modelIdentifier="StateSpace3", instanceName="reference")
    slave.instantiate()
    slave.enterConfigurationMode()
    for name, value in sizes.items():
        slave.setUInt64([vr[name]], [value])
    slave.exitConfigurationMode()
    for name, value in arrays.items():
        slave.setFloat64([vr[name]], list(np.ravel(value)))
    slave.setFloat64([vr["u"]], list(inputs[0]))
    slave.enterInitializationMode(startTime=0.0)
    slave.exitInitializationMode()
    r = sizes.get("r", 2)
    ys = [slave.getFloat64([vr["y"]], nValues=r)]
    for k, u in enumerate(inputs[:-1]):
        slave.setFloat64([vr["u"]], list(u))
        slave.doStep(currentCommunicationPoint=k * h, communicationStepSize=h)
        ys.append(slave.getFloat64([vr["y"]], nValues=r))
    slave.terminate()
    slave.freeInstance()
    return np.array(ys)


def test_statespace_with_default_sizes_equals_fmpy_simulate(typed):
    path = typed["StateSpace3"]
    result = System().add("ss", path).run(0.3, 0.1)
    reference = fmpy.simulate_fmu(str(path), stop_time=0.3, output_interval=0.1, output=["y"])
    assert result.names == ["ss.y[1]", "ss.y[2]"]
    assert np.array_equal(np.column_stack([result["ss.y[1]"], result["ss.y[2]"]]), reference["y"])


@pytest.mark.parametrize("loop", ["python", "compiled"])
def test_structural_parameters_size_the_arrays_as_in_fmpy(typed, loop):
    """m = 2 inputs, n = 3 states, r = 1 output set in Configuration Mode, the arrays given as
    nested lists of those shapes; the input array driven whole and element-wise."""
    path = typed["StateSpace3"]
    sizes = {"m": 2, "n": 3, "r": 1}
    arrays = {"A": [[0, 1, 0], [0, 0, 1], [-1, -2, -0.5]], "B": [[0, 0], [0, 1], [1, 0]], "C": [[1, 0.5, 0]],
              "D": [[0, 0.25]], "x0": [1, 0, -1]}
    system = System().add("ss", path, parameters={**arrays, **sizes})
    system.set_input("ss.u[1]", 2.0).set_input("ss.u[2]", (np.array([0.0, 1.0]), np.array([0.0, 1.0])))
    result = system.run(0.05, 0.01, loop=loop)
    assert result.loop == loop and result.names == ["ss.u[1]", "ss.u[2]", "ss.y[1]"]
    # fmpy's run with the same inputs (u[2] sampled: its value at each communication point)
    reference = _fmpy_statespace(path, sizes, arrays, [[2.0, u2] for u2 in result["ss.u[2]"]], 0.01)
    assert list(result["ss.y[1]"]) == list(reference[:, 0])


def test_arrays_connect_whole_and_by_element_between_components(typed):
    """StateSpace3's y (r = 2) drives another StateSpace3's u (m = 2) whole; y[2] drives a
    Feedthrough3 scalar, and that scalar drives u[1] of a third (element): as fmpy's own run."""
    path = typed["StateSpace3"]
    system = (System().add("p", path).add("q", path, parameters={"m": 2, "B": [[1, 0], [0, 1]], "D": [[0, 0], [0, 0]]})
              .add("f", typed["Feedthrough3"]).add("s", path)
              .connect("p.y", "q.u").connect("p.y[2]", "f.Float64_input").connect("f.Float64_output", "s.u[1]"))
    result = system.run(0.3, 0.1, record=["p.y", "q.y", "f.Float64_output", "s.y"], loop="compiled")
    reference = _fmpy_statespace(path, {}, {}, [[0.0]] * 4, 0.1)   # p: no input
    assert np.array_equal(np.column_stack([result["p.y[1]"], result["p.y[2]"]]), reference)
    assert list(result["f.Float64_output"][1:]) == list(reference[:-1, 1])   # Jacobi: one step later
    with pytest.raises(WiringError, match=r"shape \(2,\).*shape \(2, 3\)"):
        System().add("p", path).add("f", typed["Feedthrough3"]).connect("p.y", "f.Float64_array_input")
    with pytest.raises(WiringError, match=r"index \[3, 1\] is outside the variable's shape \(2, 3\)"):
        System().add("f", typed["Feedthrough3"]).add("g", typed["Feedthrough3"]).connect(
            "f.Float64_array_output[3,1]", "g.Float64_input")
    with pytest.raises(WiringError, match=r"'q.u\[1\]' is already driven"):
        System().add("p", path).add("q", path).connect("p.y[1]", "q.u[1]").set_input("q.u", [1.0])


# ------------------------------------------------------------------ Event Mode
@pytest.mark.parametrize("loop", ["python", "compiled"])
def test_event_mode_is_used_where_the_fmu_declares_it(typed, loop):
    """Stair3 declares hasEventMode: the master instantiates it with eventModeUsed and updates
    its discrete states in Event Mode between steps (event_updates counts them); the counter is
    fmpy's, whose run lets the FMU handle its events inside doStep."""
    path = typed["Stair3"]
    result = System().add("s", path).run(1.0, 0.1, loop=loop)
    reference = fmpy.simulate_fmu(str(path), stop_time=1.0, output_interval=0.1)
    assert result.loop == loop
    assert list(result["s.counter"]) == list(reference["counter"]) == [0, 0, 1, 1, 2, 2, 3, 3, 4, 4, 5]
    assert list(result["s.event_updates"]) == list(result["s.counter"]) and not any(reference["event_updates"])


def test_the_container_runs_event_mode_as_the_orchestrator_does(typed, tmp_path):
    """Stair3 inside the container: its events handled in Event Mode between internal steps, the
    counter as System.run's."""
    system = System().add("s", typed["Stair3"])
    path = system.export_container(tmp_path / "stair.fmu", step=0.1, fmi_version=3,
                                   outputs={"counter": "s.counter", "updates": "s.event_updates"})
    assert validate_fmu(str(path)) == []
    reference = fmpy.simulate_fmu(str(path), stop_time=1.0, output_interval=0.2)   # two internal steps each
    result = system.run(1.0, 0.1)
    assert list(reference["counter"]) == list(result["s.counter"][::2]) == [0, 1, 2, 3, 4, 5]
    assert list(reference["updates"]) == list(reference["counter"])


# ------------------------------------------------------------------ refusals, named
def test_what_the_master_cannot_honour_is_refused_by_name(typed, tmp_path):
    with pytest.raises(WiringError, match=r"component 'c' \(Feedthrough3_description.fmu\): variable 'tick' is a "
                                          "Clock.*does not support clocks"):
        System().add("c", typed["Clocked"])
    f3 = typed["Feedthrough3"]
    system = System().add("a", f3).add("b", f3)
    with pytest.raises(WiringError, match=r"'a.Float32_output' \(Float32\) to 'b.Float64_input' \(Float64\): types "
                                          "differ"):
        system.connect("a.Float32_output", "b.Float64_input")
    other = tmp_path / "OtherItems.fmu"  # the same FMU whose enumeration has another third item
    with zipfile.ZipFile(f3) as source, zipfile.ZipFile(other, "w") as target:
        for item in source.infolist():
            data = source.read(item)
            if item.filename == "modelDescription.xml":
                data = data.replace(b'name="Option3" value="3"', b'name="Option4" value="4"')
            target.writestr(item, data)
    with pytest.raises(WiringError, match=r"their enumerations have different items .*\('Option3', 3\).*\('Option4', 4\)"):
        system.add("o", other).connect("a.Enumeration_output", "o.Enumeration_input")
    with pytest.raises(WiringError, match=r"UInt8; 256 is outside its range \[0, 255\]"):
        system.set_input("a.UInt8_input", 256)
    with pytest.raises(WiringError, match=r"Int16; got 1.5 \(not an integer\)"):
        system.set_input("a.Int16_input", 1.5)
    with pytest.raises(WiringError, match=r"Binary; 'xyz' is not hexadecimal"):
        system.set_input("a.Binary_input", "xyz")
    with pytest.raises(WiringError, match="parameter A: A is an array of shape"):
        System().add("s", typed["StateSpace3"], parameters={"A": [1.0, 2.0]})
    system.connect("a.String_output", "b.String_input")
    with pytest.raises(WiringError, match=r"component 'b' \(Feedthrough3.fmu\): String_output is String; the container "
                                          "runtime carries scalar Real/Float64, Integer/Int32 and Boolean values as "
                                          "its own variables"):
        system.export_container(tmp_path / "c.fmu", outputs={"text": "b.String_output"})
    arrays = System().add("s", typed["StateSpace3"])
    with pytest.raises(WiringError, match=r"y is an array of Float64; the container runtime carries scalar "
                                          "Real/Float64, Integer/Int32 and Boolean values as its own variables"):
        arrays.export_container(tmp_path / "c.fmu", outputs={"y": "s.y"})
    with pytest.raises(WiringError, match="SSP 1.0 has no arrays"):
        arrays.add("t", typed["StateSpace3"]).connect("s.y[1]", "t.u[1]").to_ssp(tmp_path / "s.ssp", stop_time=1.0,
                                                                              step=0.1)


def test_a_structural_parameter_the_fmu_refuses_is_a_failure_not_a_crash(typed):
    system = System().add("ss", typed["StateSpace3"], parameters={"n": 9, "A": np.zeros((9, 9)).tolist(),
                                                                  "B": np.zeros((9, 1)).tolist(),
                                                                  "C": np.zeros((2, 9)).tolist(),
                                                                  "x0": [0.0] * 9})
    with pytest.raises(CosimError) as info:
        system.run(0.1, 0.1)
    assert info.value.failure.function == "fmi3SetUInt64" and "n = 9 exceeds its maximum 4" in str(info.value)


def test_configuration_files_carry_typed_constants(typed, tmp_path):
    config = tmp_path / "system.json"
    config.write_text(json.dumps({
        "components": {"f": {"fmu": str(typed["Feedthrough3"]), "parameters": {"String_parameter": "from file",
                                                                               "UInt64_parameter": 2**64 - 1}}},
        "inputs": {"f.Boolean_input": False, "f.String_input": "text", "f.Binary_input": "cafe",
                   "f.Int32_array_input": [4, 5, 6], "f.Float64_array_input[2,2]": 0.5},
        "run": {"stop_time": 0.001, "step": 0.001}}))
    result = load_config(config).run()
    assert result["f.Boolean_output"][-1] == False and result["f.String_output"][-1] == "text"  # noqa: E712
    assert result["f.Binary_output"][-1] == b"\xca\xfe" and result["f.UInt64_parameter_output"][-1] == 2**64 - 1
    assert [result[f"f.Int32_array_output[{i}]"][-1] for i in (1, 2, 3)] == [4, 5, 6]
    assert [result[f"f.Float64_array_output[2,{j}]"][-1] for j in (1, 2, 3)] == [4.0, 0.5, 6.0]
    assert result["f.String_parameter_output"][-1] == "from file"


def test_the_command_line_runs_a_toml_system_of_every_type(typed, tmp_path, capsys):
    from duffid.cli import main

    config = tmp_path / "system.toml"
    config.write_text(f'''[components.f]
fmu = "{typed["Feedthrough3"].as_posix()}"
[components.s]
fmu = "{typed["StateSpace3"].as_posix()}"
parameters = {{ m = 2, B = [[0, 0], [0, 1]], D = [[0, 0], [0, 0]] }}
[inputs]
"f.Binary_input" = "beef"
"f.String_input" = "toml text"
"s.u" = [1.0, 2.0]
[run]
stop_time = 0.002
step = 0.001
''')
    assert main(["cosim", str(config), "-o", str(tmp_path / "out.csv")]) == 0
    shown = capsys.readouterr().out
    assert "f.String_output                  final 'toml text'" in shown
    assert "f.Binary_output                  final beef" in shown and "s.u[2]" in shown
    header, first = (tmp_path / "out.csv").read_text().splitlines()[:2]
    assert header.endswith(",s.u[1],s.u[2],s.y[1],s.y[2]") and '"f.Float64_array_output[2,3]"' in header
    assert ",beef," in first


def test_the_container_carries_every_type_and_arrays_in_its_connections(typed, tmp_path):
    """Inside the container runtime, connections of every FMI 3 type (whole arrays too, FMI 2 <->
    FMI 3 Enumeration and String), as fmpy runs the container; its own outputs are Float64, Int32
    and Boolean (the glue's types) and equal System.run's."""
    f3, f2 = typed["Feedthrough3"], typed["Feedthrough2"]
    system = System().add("a", f3).add("b", f3).add("c", f2)
    for t in FMI3:
        system.connect(f"a.{t}_output", f"b.{t}_input")
    system.connect("a.Float64_array_output", "b.Float64_array_input").connect("b.Enumeration_output", "c.Enumeration_input")
    system.connect("a.Float64_array_output[2,3]", "c.Real_input").connect("b.String_output", "c.String_input")
    outputs = {"x": "b.Float64_output", "i": "b.Int32_output", "flag": "b.Boolean_output", "y": "c.Real_output",
               "e": "c.Integer_output", "text": "b.String_input_length", "bytes": "b.Binary_input_length"}
    path = system.export_container(tmp_path / "typed.fmu", step=1e-3, fmi_version=3, outputs=outputs)
    assert validate_fmu(str(path)) == []
    reference = fmpy.simulate_fmu(str(path), stop_time=0.003, output_interval=1e-3)
    result = system.run(0.003, 1e-3, record=list(outputs.values()))
    for name, source in outputs.items():
        assert list(reference[name][1:]) == list(result[source][1:]), name
    assert list(reference["x"][1:]) == [1.5] * 3 and list(reference["y"][2:]) == [6.0] * 2
    # String and Binary values crossed inside: b's inputs have the lengths of a's ("hello", 0a0b)
    assert list(reference["text"][1:]) == [5] * 3 and list(reference["bytes"][1:]) == [2] * 3
    # the connections' values inside: b's outputs of every type equal a's (read through System.run)
    inside = system.run(0.003, 1e-3, record=[f"b.{t}_output" for t in NUMERIC3])
    assert [inside[f"b.{t}_output"][-1] for t in NUMERIC3] == [float(typed_fmus.STARTS[t]) if t.startswith("Float")
                                                              else typed_fmus.STARTS[t] == "true" if t == "Boolean"
                                                              else int(typed_fmus.STARTS[t]) for t in NUMERIC3]
    # structural parameters and arrays given to add() are fixed in the container (Configuration Mode)
    sized = (System().add("p", typed["StateSpace3"])
             .add("q", typed["StateSpace3"], parameters={"m": 2, "B": [[1, 0], [0, 1]], "D": [[0, 0], [0, 0.5]],
                                                         "x0": [0.5, 0.0]})
             .add("f", f3, parameters={"UInt64_parameter": 2**64 - 1, "String_parameter": "fixed"})
             .connect("p.y", "q.u").connect("q.y[2]", "f.Float64_input"))
    path = sized.export_container(tmp_path / "sized.fmu", step=0.1, fmi_version=2, outputs={"y2": "f.Float64_output"})
    assert validate_fmu(str(path)) == []
    reference = fmpy.simulate_fmu(str(path), stop_time=0.4, output_interval=0.1)
    result = sized.run(0.4, 0.1, record=["q.y"])
    # f feeds its input through: the container's output, read after its inputs are set, is q.y[2] now
    assert list(reference["y2"][1:]) == list(result["q.y[2]"][1:]) and len(set(reference["y2"])) > 2
    with pytest.raises(WiringError, match=r"container output source 'q.y\[2\]': component 'q' \(StateSpace3.fmu\): an "
                                          "element of the array y"):
        sized.export_container(tmp_path / "e.fmu", outputs={"y2": "q.y[2]"})
    with pytest.raises(WiringError, match="the container sets an array input whole"):
        System().add("s", typed["StateSpace3"]).add("t", typed["StateSpace3"]).connect(
            "s.y[1]", "t.u[1]").export_container(tmp_path / "e.fmu")
