"""SSP import and export (duffid.cosim.ssp, duffid.cosim.ssp_xml, ``duffid cosim x.ssp``,
``--export-ssp``), checked against independent masters: FMPy's ``simulate_ssp`` and Ecos
(``ecospy``).

What each master does, and so what is compared:

* duffid (Jacobi): row 0 holds the outputs after initialisation; before the step from t_k
  every connected input gets its source's output at t_k.
* FMPy 0.3.32 ``simulate_ssp``: every connector starts at 0.0, so before its first step
  every connected input is 0 (not the source's initial output); after each step it copies
  outputs to inputs (Jacobi from then on); its row k is labelled t_k but holds the values
  after the step, at t_{k+1}; it accumulates the time (t += h); it ignores the SSD's parameter
  bindings (values go through its ``parameter_set`` argument, whose values it leaves as the
  strings of the .ssv: they are converted here by type) and linear transformations. So the
  systems compared have outputs of 0 at t_0 (the loop's excitation is a chirp, which starts at
  0), the step is 2^-10 s (accumulating it is exact), and FMPy's row k is compared with
  duffid's row k + 1.
* Ecos 0.7.2 (``ecospy``): reads component-level parameter bindings as parameter sets by
  name (duffid writes one, :data:`duffid.cosim.ssp.PARAMETER_SET`), initialises, then Jacobi
  steps like duffid's: its values after step k are compared with duffid's row k + 1, and its
  initial values with row 0. It accumulates the time too (t += h).

At the 2^-10 s step the trajectories agree bit for bit (0 difference); the tolerance asked of
the comparison is 1e-9 relative to the largest plant displacement. At the demo's own 1 ms step
(and its step excitation, 10 N at t_0) they do not: measured over 3 s, Ecos's accumulated
time is 1 ulp off k h from step 10 on (0.010000000000000002), the plant's x differs by 1 ulp
from row 11 and the adaptive loop amplifies it to 1.2e-3 relative; FMPy's zero first input
and its extra step (3001 rows: its accumulated time stays below the stop time) give 0.14.
"""
from __future__ import annotations

import json
import shutil
import zipfile
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

fmpy = pytest.importorskip("fmpy")

from lxml import etree  # noqa: E402

from duffid.cli import main  # noqa: E402
from duffid.cosim.config import ConfigError, load_config, load_ssp  # noqa: E402
from duffid.cosim.ssp import PARAMETER_SET, SspError, read_ssp  # noqa: E402
from duffid.cosim.ssp_xml import SspArchive, parse_xml  # noqa: E402
from duffid.cosim.system import System, WiringError  # noqa: E402
from duffid.modelica.export import export_fmu  # noqa: E402

if shutil.which("gcc") is None:
    pytest.skip("gcc is needed to build the test FMUs", allow_module_level=True)

HERE = Path(__file__).parent
MODELS = HERE / "cosim_models.mo"
SCHEMAS = Path(fmpy.__file__).parent / "ssp" / "schema"
#: The loop's step in the comparisons with other masters: a power of two, so that FMPy's
#: accumulated time equals duffid's t0 + k h exactly.
LOOP_STEP = 2.0 ** -10
TOLERANCE = 1e-9


@pytest.fixture(scope="module")
def fmus(tmp_path_factory) -> dict[str, Path]:
    out = tmp_path_factory.mktemp("ssp_fmus")
    paths = [export_fmu(MODELS, f"CosimTest.{name}", out, 2, "cs") for name in ("Ramp", "Integrator", "Gain")]
    paths.append(export_fmu(MODELS, "CosimTest.Gain", out, 3, "cs"))
    return {p.stem: p for p in paths}


def _pack(path: Path, files: dict[str, bytes | Path]) -> Path:
    with zipfile.ZipFile(path, "w") as archive:
        for member, content in files.items():
            archive.writestr(member, content.read_bytes() if isinstance(content, Path) else content)
    return path


def _folder(name: str) -> dict[str, Path]:
    root = HERE / "ssp" / name
    return {p.relative_to(root).as_posix(): p for p in root.rglob("*") if p.is_file()}


def _hand_written(tmp_path: Path, fmus: dict[str, Path], name: str) -> Path:
    files: dict[str, bytes | Path] = dict(_folder(name))
    files.update({f"resources/{stem}.fmu": fmus[stem] for stem in ("Ramp", "Integrator", "Gain")})
    return _pack(tmp_path / f"{name}.ssp", files)


def _schema(name: str) -> etree.XMLSchema:
    return etree.XMLSchema(etree.parse(str(SCHEMAS / name)))


def _validate(archive: Path) -> None:
    ssd, ssv = _schema("SystemStructureDescription.xsd"), _schema("SystemStructureParameterValues.xsd")
    with zipfile.ZipFile(archive) as z:
        for member in z.namelist():
            if member.endswith((".ssd", ".ssv")):
                schema = ssd if member.endswith(".ssd") else ssv
                document = etree.fromstring(z.read(member))
                assert schema.validate(document), (member, str(schema.error_log))


def _chain_system(fmus: dict[str, Path]) -> System:
    return (System().add("ramp", fmus["Ramp"], parameters={"a": 1.5, "y0": 0.5})
            .add("integrator", fmus["Integrator"]).add("gain", fmus["Gain"], parameters={"k": -3.0})
            .add("gain2", fmus["Gain"]).connect("ramp.y", "integrator.u").connect("integrator.y", "gain.u")
            .set_input("gain2.u", 0.75))


def _config(fmus: dict[str, Path]) -> dict:
    return {"components": {"ramp": {"fmu": str(fmus["Ramp"]), "parameters": {"a": 1.5, "y0": 0.5}},
                           "integrator": {"fmu": str(fmus["Integrator"])},
                           "gain": {"fmu": str(fmus["Gain"]), "parameters": {"k": -3.0}},
                           "gain2": {"fmu": str(fmus["Gain"])}},
            "connections": [["ramp.y", "integrator.u"], ["integrator.y", "gain.u"]],
            "inputs": {"gain2.u": 0.75},
            "run": {"stop_time": 1.0, "step": 0.01, "ordering": "gauss-seidel"}}


def _members(archive: Path) -> dict[str, bytes]:
    with zipfile.ZipFile(archive) as z:
        return {name: z.read(name) for name in z.namelist()}


# ------------------------------------------------------------------------------ export, round trip
@pytest.mark.parametrize("suffix", [".json", ".toml"])
def test_round_trip_config_ssp_system_ssp_is_stable(fmus, tmp_path, suffix):
    """JSON/TOML -> SSP -> System -> SSP: the same archive (structure, values, FMUs), the
    same run; the export validates against FMPy's SSP schemas."""
    config = _config(fmus)
    path = tmp_path / f"loop{suffix}"
    if suffix == ".json":
        path.write_text(json.dumps(config))
    else:
        lines = []
        for name, spec in config["components"].items():
            lines += [f"[components.{name}]", f"fmu = {json.dumps(spec['fmu'])}"]
            if "parameters" in spec:
                lines.append("parameters = { " + ", ".join(f"{k} = {v}" for k, v in spec["parameters"].items()) + " }")
        lines.insert(0, "connections = " + json.dumps(config["connections"]))
        lines.insert(1, "inputs = { \"gain2.u\" = 0.75 }")
        lines += ["[run]", "stop_time = 1.0", "step = 0.01", "ordering = \"gauss-seidel\""]
        path.write_text("\n".join(lines) + "\n")
    loaded = load_config(path)
    first = loaded.export_ssp(tmp_path / "a" / "loop.ssp")
    _validate(first)
    run = read_ssp(first, System())
    assert (run.start_time, run.stop_time, run.step, run.ordering, run.order) == (0.0, 1.0, 0.01, "gauss-seidel", None)
    assert run.warnings == []
    second = run.system.to_ssp(tmp_path / "b" / "loop.ssp", stop_time=run.stop_time, step=run.step,
                               ordering=run.ordering)
    assert first.read_bytes() == second.read_bytes()  # the same archive, byte for byte
    assert set(_members(first)) == {"SystemStructure.ssd", "resources/Gain.fmu", "resources/Integrator.fmu",
                                    "resources/Ramp.fmu", "resources/gain.ssv", "resources/ramp.ssv",
                                    "resources/gain2.ssv"}
    assert run.system.components == ["ramp", "integrator", "gain", "gain2"]
    assert [str(c) for c in run.system.connections] == ["ramp.y -> integrator.u", "integrator.y -> gain.u"]
    assert run.system.parameter_values("ramp") == {"a": 1.5, "y0": 0.5}
    assert run.system.constant_inputs == {"gain2.u": 0.75}
    a, b = loaded.run(), run.system.run(1.0, 0.01, ordering="gauss-seidel")
    assert a.names == b.names
    for name in a.names:
        assert np.array_equal(a[name], b[name]), name


def test_export_carries_transformations_units_and_ordering(fmus, tmp_path):
    system = (System().add("ramp", fmus["Ramp"]).add("gain", fmus["Gain"])
              .connect("ramp.y", "gain.u", factor=0.5, offset=-1.0, check_units=False))
    path = system.to_ssp(tmp_path / "t.ssp", stop_time=0.5, step=0.125, ordering="gauss-seidel",
                         order=["gain", "ramp"])
    _validate(path)
    ssd = _members(path)["SystemStructure.ssd"].decode()
    assert 'suppressUnitConversion="true"' in ssd and '<ssc:LinearTransformation factor="0.5" offset="-1.0"/>' in ssd
    run = read_ssp(path, System())
    assert (run.ordering, run.order, run.step) == ("gauss-seidel", ["gain", "ramp"], 0.125)
    (connection,) = run.system.connections
    assert (connection.factor, connection.offset, connection.check_units) == (0.5, -1.0, False)


def test_export_refuses_signals(fmus, tmp_path):
    system = System().add("gain", fmus["Gain"]).set_input("gain.u", lambda t: t)
    with pytest.raises(WiringError, match="gain.u is driven by a function: an SSP carries constant inputs only"):
        system.to_ssp(tmp_path / "x.ssp", stop_time=1.0, step=0.1)


# ------------------------------------------------------------------------------ hand-written SSPs
def test_hand_written_ssp_runs_as_fmpy_runs_it(fmus, tmp_path):
    """The standard-style chain: duffid's run equals FMPy's (and the stored reference)."""
    from fmpy.ssp.simulation import simulate_ssp
    from fmpy.ssp.ssd import read_ssv

    path = _hand_written(tmp_path, fmus, "chain")
    _validate(path)
    config = load_ssp(path, step=0.0625)
    assert (config.stop_time, config.step) == (2.0, 0.0625)
    with pytest.raises(ConfigError, match="an SSP file, not a JSON or TOML configuration: read it with"):
        load_config(path)  # whose callers may edit parameters: they must not be dropped silently
    result = config.run()
    parameters = read_ssv(str(path), resource="resources/Chain.ssv")
    for p in parameters.parameters:
        p.value = float(p.value)
    theirs = simulate_ssp(str(path), stop_time=2.0, step_size=0.0625, parameter_set=parameters)
    assert len(theirs) == len(result) - 1 == 32
    for name in ("ramp.y", "integrator.y", "gain.y"):
        assert np.array_equal(theirs[name], result[name][1:]), name
    reference = np.loadtxt(HERE / "ssp" / "chain_reference.csv", delimiter=",", skiprows=2)
    assert np.allclose(reference[:, 1:], np.column_stack([result[n] for n in ("ramp.y", "integrator.y", "gain.y")]),
                       rtol=1e-12, atol=1e-15)
    # the integrator holds the ramp's value at t_k over each step: y(t_n) = sum 1.5 t_k h = 0.75 t_n (t_n - h)
    t = result.time
    assert np.allclose(result["integrator.y"], 0.75 * t * (t - 0.0625), rtol=0, atol=1e-12)


def test_hand_written_features(fmus, tmp_path, capsys):
    """Bindings inline / .ssv with prefix / .ssm mapping, a system parameter connector, a linear
    transformation after a unit conversion; the step from --step; another tool's annotation
    reported."""
    path = _hand_written(tmp_path, fmus, "features")
    _validate(path)
    with pytest.raises(SspError, match="no communication step"):
        load_ssp(path)
    run = read_ssp(path, System())
    assert len(run.warnings) == 1 and "com.example.editor" in run.warnings[0] and "line" in run.warnings[0]
    system = run.system
    assert system.parameter_values("ramp") == {"a": 2.0}
    assert system.parameter_values("gain") == {"k": 6.0}          # 3 through the mapping's factor 2
    assert system.constant_inputs == {"integrator.u": 0.5}          # bias 0.25 through factor 2
    (connection,) = system.connections
    assert connection.factor == pytest.approx(0.004, rel=1e-15) and connection.offset == 0.5  # mm -> m, then x4 + 0.5
    result = system.run(1.0, 0.125)
    assert result.loop == "python"  # a transformed connection
    t = result.time
    expected = 6.0 * (0.004 * 2.0 * t[:-1] + 0.5)   # Jacobi: the input of the step from t_k
    assert result["gain.y"][0] == 0.0 and np.allclose(result["gain.y"][1:], expected, rtol=1e-14)
    assert np.allclose(result["integrator.y"], 0.5 * t, rtol=1e-14)
    with pytest.raises(WiringError, match="loop='compiled' cannot run this system.*factor or offset"):
        system.run(1.0, 0.125, loop="compiled")
    with pytest.raises(WiringError, match="which the container runtime cannot apply"):
        system.export_container(tmp_path / "c.fmu", step=0.125)
    assert main(["cosim", str(path), "--step", "0.125", "-o", str(tmp_path / "out.csv")]) == 0
    captured = capsys.readouterr()
    assert "warning" in captured.err and "com.example.editor" in captured.err
    assert "9 communication points" in captured.out


def test_ssp2_with_an_fmi3_component(fmus, tmp_path):
    ssd = f"""<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription" version="2.0" name="Two">
  <ssd:System name="Two">
    <ssd:Elements>
      <ssd:Component name="ramp" source="resources/Ramp.fmu">
        <ssd:Connectors><ssd:Connector name="y" kind="output"><ssc:Real/></ssd:Connector></ssd:Connectors>
      </ssd:Component>
      <ssd:Component name="gain" source="resources/Gain3.fmu">
        <ssd:Connectors><ssd:Connector name="u" kind="input"><ssc:Float64/></ssd:Connector></ssd:Connectors>
      </ssd:Component>
    </ssd:Elements>
    <ssd:Connections>
      <ssd:Connection startElement="ramp" startConnector="y" endElement="gain" endConnector="u"/>
    </ssd:Connections>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0" stopTime="1">
    <ssd:Annotations><ssc:Annotation type="io.github.duffid.cosim">
      <duffid:Run xmlns:duffid="https://duffid.github.io/ssp/1.0" step="0.25"/>
    </ssc:Annotation></ssd:Annotations>
  </ssd:DefaultExperiment>
</ssd:SystemStructureDescription>"""
    path = _pack(tmp_path / "two.ssp", {"SystemStructure.ssd": ssd, "resources/Ramp.fmu": fmus["Ramp"],
                                        "resources/Gain3.fmu": fmus["Gain_fmi3"]})
    config = load_ssp(path)
    result = config.run()
    assert config.step == 0.25 and np.allclose(result["gain.y"][1:], 2.0 * result.time[:-1])


def test_ssd_beside_its_fmus_and_fmus_beside_the_archive(fmus, tmp_path):
    """A bare .ssd resolves sources against its folder; an archive's ../x against its own."""
    for stem in ("Ramp", "Integrator", "Gain"):
        (tmp_path / "resources").mkdir(exist_ok=True)
        shutil.copy(fmus[stem], tmp_path / "resources" / f"{stem}.fmu")
    files = _folder("chain")
    for member, source in files.items():
        (tmp_path / member).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(source, tmp_path / member)
    system = System.from_ssp(tmp_path / "SystemStructure.ssd")
    assert system.components == ["ramp", "integrator", "gain"] and system.parameter_values("gain") == {"k": -3.0}
    ssd = files["SystemStructure.ssd"].read_text().replace('source="resources/', 'source="../resources/')
    outside = _pack(tmp_path / "outside.ssp", {"SystemStructure.ssd": ssd,
                                               "resources/Chain.ssv": files["resources/Chain.ssv"]})
    assert System.from_ssp(outside).fmu("ramp") == tmp_path / "resources" / "Ramp.fmu"


# ------------------------------------------------------------------------------ what is refused
def _minimal(fmus, tmp_path, system_inner="", component_inner="", root_extra="", component_attrs="", name="m.ssp"):
    ssd = f"""<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues" version="1.0" name="M">
  <ssd:System name="M">
    <ssd:Elements>
      <ssd:Component name="gain" source="resources/Gain.fmu"{component_attrs}>
{component_inner}
      </ssd:Component>
    </ssd:Elements>
{system_inner}
  </ssd:System>
{root_extra}
</ssd:SystemStructureDescription>"""
    return _pack(tmp_path / name, {"SystemStructure.ssd": ssd, "resources/Gain.fmu": fmus["Gain"]})


@pytest.mark.parametrize("where, text, message", [
    ("system_inner", '<ssd:SignalDictionaries><ssd:SignalDictionary name="d"/></ssd:SignalDictionaries>',
     r"m.ssp!SystemStructure.ssd, line 11, <SignalDictionaries>: signal dictionaries are not supported"),
    ("component_attrs", ' implementation="ModelExchange"',
     r"line 7, <Component name='gain'>: implementation='ModelExchange'.*Model Exchange components are not supported"),
    ("component_attrs", ' type="application/x-ssp-package"', r"line 7, <Component name='gain'>: type="),
    ("component_inner", '<ssd:Connectors><ssd:Connector name="u" kind="output"/></ssd:Connectors>',
     r"line 8, <Connector name='u'>: kind='output', but u is 'input'"),
    ("component_inner", '<ssd:Connectors><ssd:Connector name="v" kind="input"/></ssd:Connectors>',
     r"line 8, <Connector name='v'>: the FMU Gain.fmu of component 'gain' has no variable 'v'"),
    ("component_inner", '<ssd:Frobnicate/>', r"line 8, <Frobnicate>: <Frobnicate> inside <Component> is not supported"),
    ("component_inner", """<ssd:ParameterBindings><ssd:ParameterBinding><ssd:ParameterValues>
        <ssv:ParameterSet version="1.0" name="p"><ssv:Parameters><ssv:Parameter name="kk"><ssv:Real value="1"/>
        </ssv:Parameter></ssv:Parameters></ssv:ParameterSet></ssd:ParameterValues></ssd:ParameterBinding>
        </ssd:ParameterBindings>""",
     r"line 9, <Parameter name='kk'>: component 'gain' \(Gain.fmu\) has no variable 'kk' \(SSP would ignore"),
    ("component_inner", """<ssd:ParameterBindings><ssd:ParameterBinding><ssd:ParameterValues>
        <ssv:ParameterSet version="1.0" name="p"><ssv:Parameters><ssv:Parameter name="y"><ssv:Real value="1"/>
        </ssv:Parameter></ssv:Parameters></ssv:ParameterSet></ssd:ParameterValues></ssd:ParameterBinding>
        </ssd:ParameterBindings>""", r"line 7, <Component name='gain'>: .*parameter y is an output"),
    ("system_inner", """<ssd:Connections><ssd:Connection startElement="gain" startConnector="y" endElement="gain"
        endConnector="u"><ssc:BooleanMappingTransformation/></ssd:Connection></ssd:Connections>""",
     r"line 12, <BooleanMappingTransformation>: BooleanMappingTransformation is not supported"),
    ("system_inner", """<ssd:Connections><ssd:Connection startElement="gain" startConnector="y" endElement="gain"
        endConnector="u"/></ssd:Connections>""",
     r"line 12, <Connection>: startConnector='y': component 'gain' declares no such connector"),
    ("root_extra", '<ssd:DefaultExperiment stopTime="x"/>', r"line 13, <DefaultExperiment>: stopTime='x' is not a finite"),
    ("root_extra", """<ssd:DefaultExperiment stopTime="1"><ssd:Annotations><ssc:Annotation type="io.github.duffid.cosim">
        <duffid:Run xmlns:duffid="https://duffid.github.io/ssp/1.0" stepp="1"/></ssc:Annotation></ssd:Annotations>
        </ssd:DefaultExperiment>""", r"line 14, <Run>: unknown attribute\(s\) \['stepp'\]"),
])
def test_unsupported_content_is_an_error_naming_file_line_and_element(fmus, tmp_path, where, text, message):
    path = _minimal(fmus, tmp_path, **{where: text})
    with pytest.raises((SspError, WiringError), match=message):
        System.from_ssp(path)


def test_nested_systems_are_refused(fmus, tmp_path):
    with zipfile.ZipFile(_minimal(fmus, tmp_path)) as z:
        ssd = z.read("SystemStructure.ssd").decode().replace("</ssd:Elements>",
                                                              '<ssd:System name="inner"/></ssd:Elements>')
    path = _pack(tmp_path / "nested.ssp", {"SystemStructure.ssd": ssd, "resources/Gain.fmu": fmus["Gain"]})
    with pytest.raises(SspError, match=r"nested.ssp!SystemStructure.ssd, line 10, <System name='inner'>: nested systems"):
        System.from_ssp(path)


# ------------------------------------------------------------------------------ safe XML and archives
BILLION_LAUGHS = b"""<?xml version="1.0"?>
<!DOCTYPE lolz [
 <!ENTITY lol "lol">
 <!ENTITY lol1 "&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;">
 <!ENTITY lol2 "&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;">
 <!ENTITY lol3 "&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;">
]>
<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
  version="1.0" name="&lol3;"/>
"""
XXE = b"""<?xml version="1.0"?>
<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
  version="1.0" name="x">
<!DOCTYPE foo [ <!ENTITY xxe SYSTEM "file:///etc/passwd"> ]>
  <ssd:System name="&xxe;"/>
</ssd:SystemStructureDescription>
"""


@pytest.mark.parametrize("data, line", [(BILLION_LAUGHS, 2), (XXE, 4)])
def test_entity_expansion_and_external_entities_are_refused(tmp_path, data, line):
    path = _pack(tmp_path / "evil.ssp", {"SystemStructure.ssd": data})
    with pytest.raises(SspError, match=rf"evil.ssp!SystemStructure.ssd, line {line}: a <!DOCTYPE declaration is "
                                       r"refused.*billion laughs.*XXE"):
        System.from_ssp(path)


def test_a_dtd_hidden_by_the_encoding_is_refused_by_the_parser():
    data = BILLION_LAUGHS.replace(b'<?xml version="1.0"?>', b'<?xml version="1.0" encoding="UTF-16"?>')
    with pytest.raises(SspError, match="document type declaration is refused"):
        parse_xml(data.decode().encode("utf-16"), "utf16.ssd")


def test_malformed_xml_names_line_and_column():
    with pytest.raises(SspError, match=r"bad.ssd, line 2, column \d+: not well-formed XML"):
        parse_xml(b"<a>\n<b></a>", "bad.ssd")


@pytest.mark.parametrize("member", ["../evil.txt", "/abs/evil.txt", "a/../../evil.txt", "C:/evil.txt",
                                    "a\\..\\evil.txt"])
def test_archive_members_with_unsafe_paths_are_refused(tmp_path, member):
    path = tmp_path / "slip.ssp"
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("SystemStructure.ssd", b"<x/>")
        z.writestr(zipfile.ZipInfo(member), b"evil")
    with pytest.raises(SspError, match=r"slip.ssp: the archive member .* refused"):
        SspArchive(path)
    with pytest.raises(SspError, match="refused"):
        System.from_ssp(path)


def test_not_an_archive(tmp_path):
    path = tmp_path / "plain.ssp"
    path.write_text("not a zip")
    with pytest.raises(SspError, match="plain.ssp: not a readable ZIP archive"):
        System.from_ssp(path)


# ------------------------------------------------------------------------------ CLI
def test_cli_exports_and_runs_an_ssp(fmus, tmp_path, capsys):
    config = tmp_path / "loop.json"
    config.write_text(json.dumps(_config(fmus)))
    assert main(["cosim", str(config), "--export-ssp", str(tmp_path / "loop.ssp")]) == 0
    assert "wrote" in capsys.readouterr().out
    assert main(["cosim", str(config), "-o", str(tmp_path / "json.csv")]) == 0
    assert main(["cosim", str(tmp_path / "loop.ssp"), "-o", str(tmp_path / "ssp.csv")]) == 0
    assert (tmp_path / "json.csv").read_text() == (tmp_path / "ssp.csv").read_text()
    assert main(["cosim", str(tmp_path / "loop.ssp"), "--step", "0.02", "-o", str(tmp_path / "coarse.csv")]) == 0
    assert len((tmp_path / "coarse.csv").read_text().splitlines()) == 52


# ------------------------------------------------------------------------------ independent masters
@pytest.fixture(scope="module")
def loop_ssp(loop_fmus, tmp_path_factory):
    """The demo's 1-DOF closed loop (plant <-> estimator <-> adaptive controller, FMI 2 C FMUs)
    with a chirp excitation (0 at t_0), a constant reference and a 2^-10 s step: exported as
    SSP, and duffid's Jacobi run of it."""
    from duffid.control.closed_loop import closed_loop_case, loop_system

    case = replace(closed_loop_case(), dt=LOOP_STEP,
                   controller_options={"reference_model": "filter", "excitation": "chirp", "chirp_f0": 1.0,
                                       "chirp_f1": 8.0, "chirp_duration": 2.0})
    source = loop_system(case, loop_fmus)
    system = System()
    for name in source.components:
        system.add(name, source.fmu(name), parameters=source.parameter_values(name))
    for connection in source.connections:
        system.connect(connection.source, connection.target, check_units=connection.check_units)
    system.set_input("controller.r", 0.004)
    stop = 3072 * LOOP_STEP
    path = system.to_ssp(tmp_path_factory.mktemp("loop_ssp") / "loop.ssp", stop_time=stop, step=LOOP_STEP)
    result = system.run(stop, LOOP_STEP)
    assert result["controller.f"][0] == 0.0 and result["plant.x"][0] == 0.0   # comparable with FMPy (see top)
    assert result["controller.phase"][-1] == 1  # it identified and switched to control
    return path, result, stop


def _close(theirs: np.ndarray, ours: np.ndarray) -> float:
    return float(np.max(np.abs(theirs - ours)) / np.max(np.abs(ours)))


def test_fmpy_runs_the_exported_loop_as_duffid(loop_ssp):
    from fmpy.ssp.simulation import simulate_ssp
    from fmpy.ssp.ssd import ParameterSet, read_ssv

    path, ours, stop = loop_ssp
    _validate(path)
    parameters = ParameterSet(name="all")
    convert = {"Real": float, "Integer": int, "Boolean": lambda s: s == "true", "String": str}
    for component in ("plant", "estimator", "controller"):
        for parameter in read_ssv(str(path), resource=f"resources/{component}.ssv").parameters:
            parameter.value = convert[parameter.type](parameter.value)  # FMPy keeps the .ssv strings
            parameter.name = f"{component}.{parameter.name}"            # its names are system-level
            parameters.parameters.append(parameter)
    theirs = simulate_ssp(str(path), stop_time=stop, step_size=LOOP_STEP, parameter_set=parameters)
    assert len(theirs) == len(ours) - 1
    assert _close(theirs["plant.x"], ours["plant.x"][1:]) <= TOLERANCE
    assert np.array_equal(theirs["plant.x"], ours["plant.x"][1:])   # in fact bit for bit


def test_ecos_runs_the_exported_loop_as_duffid(loop_ssp):
    try:
        from ecospy import EcosLib, EcosSimulation
    except ImportError:
        pytest.skip("ecospy is not installed (pip install ecospy; it needs Debian's libtbb12)")
    except OSError as exc:  # its native library does not load
        pytest.skip(f"ecospy cannot load its library (it needs Debian's libtbb12: apt-get install libtbb12): {exc}")
    path, ours, stop = loop_ssp
    simulation = EcosSimulation(ssp_path=str(path), step_size=LOOP_STEP)
    try:
        assert simulation.init(0.0, PARAMETER_SET), EcosLib.get_last_error()
        x = [simulation.get_real("plant::x")]
        for _ in range(len(ours) - 1):
            simulation.step()
            x.append(simulation.get_real("plant::x"))
        assert simulation.get_real("controller::r") == 0.004  # the constant input, bound as a start value
    finally:
        simulation.free()
    x = np.array(x)
    assert _close(x, ours["plant.x"]) <= TOLERANCE
    assert np.array_equal(x, ours["plant.x"])


# ------------------------------------------------------------------------------ container from an SSP
def test_the_system_connectors_are_the_interface_of_an_exported_container(fmus, tmp_path):
    ssd = """<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues" version="1.0" name="Box">
  <ssd:System name="Box">
    <ssd:Connectors>
      <ssd:Connector name="u" kind="input"><ssc:Real/></ssd:Connector>
      <ssd:Connector name="y" kind="output"><ssc:Real/></ssd:Connector>
    </ssd:Connectors>
    <ssd:Elements>
      <ssd:Component name="gain" source="resources/Gain.fmu">
        <ssd:Connectors>
          <ssd:Connector name="u" kind="input"/><ssd:Connector name="y" kind="output"/>
        </ssd:Connectors>
        <ssd:ParameterBindings><ssd:ParameterBinding><ssd:ParameterValues>
          <ssv:ParameterSet version="1.0" name="p"><ssv:Parameters>
            <ssv:Parameter name="k"><ssv:Real value="4"/></ssv:Parameter>
          </ssv:Parameters></ssv:ParameterSet>
        </ssd:ParameterValues></ssd:ParameterBinding></ssd:ParameterBindings>
      </ssd:Component>
    </ssd:Elements>
    <ssd:Connections>
      <ssd:Connection startConnector="u" endElement="gain" endConnector="u"/>
      <ssd:Connection startElement="gain" startConnector="y" endConnector="y"/>
    </ssd:Connections>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0" stopTime="1"/>
</ssd:SystemStructureDescription>"""
    path = _pack(tmp_path / "box.ssp", {"SystemStructure.ssd": ssd, "resources/Gain.fmu": fmus["Gain"]})
    config = load_ssp(path, step=0.25)
    assert config.container == {"inputs": {"u": ["gain.u"]}, "outputs": {"y": "gain.y"}}
    assert any("system input 'u' is given no value" in w for w in config.warnings)
    assert np.all(config.run()["gain.y"] == 0.0)  # the input keeps its start value
    fmu = config.export_container(tmp_path / "box.fmu")
    result = System().add("box", fmu).set_input("box.u", 2.5).run(1.0, 0.25)
    assert np.allclose(result["box.y"][1:], 10.0)


def test_a_parameter_set_and_overrides_take_priority(fmus, tmp_path):
    """A campaign's .ssv parameter set and its overrides over the SSP's own bindings."""
    path = _hand_written(tmp_path, fmus, "chain")
    ssv = tmp_path / "other.ssv"
    ssv.write_text('''<?xml version="1.0" encoding="UTF-8"?>
<ssv:ParameterSet xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues" version="1.0" name="o">
  <ssv:Parameters>
    <ssv:Parameter name="ramp.a"><ssv:Real value="7"/></ssv:Parameter>
    <ssv:Parameter name="gain.k"><ssv:Real value="5"/></ssv:Parameter>
  </ssv:Parameters>
</ssv:ParameterSet>''')
    config = load_ssp(path, step=0.5, stop_time=1.0, parameter_set=ssv, parameters={"gain.k": 9.0})
    assert config.system.parameter_values("ramp") == {"a": 7.0} and config.system.parameter_values("gain") == {"k": 9.0}
    assert config.stop_time == 1.0
    with pytest.raises(SspError, match=r"parameters\['gain.kk'\]: 'gain.kk' names no variable"):
        load_ssp(path, step=0.5, parameters={"gain.kk": 1.0})
    assert main(["cosim", str(path), "--step", "0.5", "--parameter-set", str(ssv), "-o", str(tmp_path / "o.csv")]) == 0
    rows = (tmp_path / "o.csv").read_text().splitlines()
    assert rows[0] == "time,ramp.y,integrator.y,gain.y" and rows[2].split(",")[0] == "0.5" and abs(float(rows[2].split(",")[1]) - 3.5) < 1e-12


def test_an_fmu_in_the_archive_is_checked_as_the_archive_is(fmus, tmp_path):
    with zipfile.ZipFile(fmus["Gain"]) as z:
        members = {name: z.read(name) for name in z.namelist()}
    members["modelDescription.xml"] = members["modelDescription.xml"].replace(
        b"<fmiModelDescription", b'<!DOCTYPE x [<!ENTITY e SYSTEM "file:///etc/passwd">]>\n<fmiModelDescription', 1)
    evil = _pack(tmp_path / "Evil.fmu", members)
    path = _minimal(fmus, tmp_path)
    with zipfile.ZipFile(path) as z:
        ssd = z.read("SystemStructure.ssd")
    path = _pack(tmp_path / "evil.ssp", {"SystemStructure.ssd": ssd, "resources/Gain.fmu": evil})
    with pytest.raises(SspError, match=r"Gain.fmu!modelDescription.xml, line \d+: a <!DOCTYPE declaration is refused"):
        System.from_ssp(path)


@pytest.mark.parametrize("source, message", [
    ("http://example.com/Gain.fmu", "only relative URIs and file: URIs are supported"),
    ("resources/Missing.fmu", "the archive has no member 'resources/Missing.fmu'"),
])
def test_component_sources(fmus, tmp_path, source, message):
    with zipfile.ZipFile(_minimal(fmus, tmp_path)) as z:
        ssd = z.read("SystemStructure.ssd").decode().replace('source="resources/Gain.fmu"', f'source="{source}"')
    path = _pack(tmp_path / "s.ssp", {"SystemStructure.ssd": ssd})
    with pytest.raises(SspError, match=rf"line 7, <Component name='gain'>: source=.*{message}"):
        System.from_ssp(path)
    ssd = ssd.replace(f'source="{source}"', f'source="{fmus["Gain"].as_uri()}"')
    assert System.from_ssp(_pack(tmp_path / "f.ssp", {"SystemStructure.ssd": ssd})).fmu("gain") == fmus["Gain"]


def test_an_fmi3_component_round_trips(fmus, tmp_path):
    system = (System().add("ramp", fmus["Ramp"], parameters={"a": 0.5}).add("gain", fmus["Gain_fmi3"], parameters={"k": 3.0})
              .connect("ramp.y", "gain.u"))
    path = system.to_ssp(tmp_path / "mixed.ssp", stop_time=1.0, step=0.25)
    _validate(path)
    again = System.from_ssp(path)
    assert again.parameter_values("gain") == {"k": 3.0} and again.model_description("gain").fmiVersion == "3.0"
    a, b = system.run(1.0, 0.25), again.run(1.0, 0.25)
    assert np.array_equal(a["gain.y"], b["gain.y"]) and np.allclose(b["gain.y"][1:], 1.5 * b.time[:-1])


@pytest.mark.parametrize("units, expected", [
    ('<ssv:Units><ssc:Unit name="g"><ssc:BaseUnit kg="1" factor="0.001"/></ssc:Unit></ssv:Units>', 2.6),
    ("", r"cannot convert \[g\] to \[kg\]: the unit 'g' has no definition"),
    ('<ssv:Units><ssc:Unit name="g"><ssc:BaseUnit m="1"/></ssc:Unit></ssv:Units>',
     r"cannot convert \[g\] to \[kg\]: different base units"),
])
def test_parameter_values_are_converted_to_the_variables_unit(loop_fmus, tmp_path, units, expected):
    ssv = f"""<?xml version="1.0" encoding="UTF-8"?>
<ssv:ParameterSet xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon" version="1.0" name="mass">
  <ssv:Parameters><ssv:Parameter name="plant.m"><ssv:Real value="2600" unit="g"/></ssv:Parameter></ssv:Parameters>
  {units}
</ssv:ParameterSet>"""
    ssd = """<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    version="1.0" name="P">
  <ssd:System name="P">
    <ssd:ParameterBindings><ssd:ParameterBinding source="resources/mass.ssv"/></ssd:ParameterBindings>
    <ssd:Elements><ssd:Component name="plant" source="resources/Oscillator1DOF.fmu"/></ssd:Elements>
  </ssd:System>
</ssd:SystemStructureDescription>"""
    path = _pack(tmp_path / "p.ssp", {"SystemStructure.ssd": ssd, "resources/mass.ssv": ssv,
                                      "resources/Oscillator1DOF.fmu": loop_fmus["Oscillator1DOF"]})
    if isinstance(expected, float):
        assert System.from_ssp(path).parameter_values("plant")["m"] == pytest.approx(expected, rel=1e-15)
    else:
        with pytest.raises(SspError, match=r"p.ssp!resources/mass.ssv, line 4, <Parameter name='plant.m'> -> "
                                           r"plant.m: " + expected):
            System.from_ssp(path)


OMS_ANNOTATION = """<ssd:Annotations><ssc:Annotation type="org.openmodelica">
      <oms:Annotations xmlns:oms="https://raw.githubusercontent.com/OpenModelica/OMSimulator/master/schema/oms.xsd">
        <oms:SimulationInformation><oms:{master} description="oms-ma" stepSize="0.125"/></oms:SimulationInformation>
      </oms:Annotations></ssc:Annotation></ssd:Annotations>"""


def test_omsimulators_fixed_step_master_gives_the_step(fmus, tmp_path):
    path = _minimal(fmus, tmp_path, system_inner=OMS_ANNOTATION.format(master="FixedStepMaster"),
                    root_extra='<ssd:DefaultExperiment stopTime="1"/>')
    config = load_ssp(path)
    assert config.step == 0.125 and len(config.warnings) == 2
    assert "only its fixed-step master is understood" in config.warnings[0]
    assert "line 13, <FixedStepMaster>: the communication step 0.125 s is taken" in config.warnings[1]
    assert load_ssp(path, step=0.5).step == 0.5
    path = _minimal(fmus, tmp_path, system_inner=OMS_ANNOTATION.format(master="VariableStepMaster"), name="v.ssp")
    with pytest.raises(SspError, match=r"v.ssp!SystemStructure.ssd, line 13, <VariableStepMaster>: OMSimulator's"):
        load_ssp(path)


def test_a_campaign_runs_an_ssp_system_with_a_parameter_set(fmus, tmp_path):
    """A campaign's system may be an SSP, with an .ssv parameter set, run settings and a factor
    over a component parameter (issue 32 item 4)."""
    from duffid.campaign import load_spec
    from duffid.campaign.tasks import run_task

    path = _hand_written(tmp_path, fmus, "chain")
    ssv = tmp_path / "set.ssv"
    ssv.write_text('''<?xml version="1.0" encoding="UTF-8"?>
<ssv:ParameterSet xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues" version="1.0" name="s">
  <ssv:Parameters><ssv:Parameter name="ramp.a"><ssv:Real value="2"/></ssv:Parameter></ssv:Parameters>
</ssv:ParameterSet>''')
    spec = tmp_path / "campaign.toml"
    spec.write_text(f"""[campaign]
name = "ssp"
kind = "cosim"
[task]
system = "{path.name}"
parameter_set = "{ssv.name}"
step = 0.25
stop_time = 2.0
[factors]
"gain.k" = [1.0, -2.0]
[metrics.final]
function = "final"
variable = "gain.y"
""")
    loaded = load_spec(spec)
    rows = [run_task(task) for task in loaded.tasks]
    assert [row["status"] for row in rows] == ["ok", "ok"], [row["error"] for row in rows]
    finals = {row["gain.k"]: row["final"] for row in rows}
    assert finals[1.0] != 0.0 and finals[-2.0] == pytest.approx(-2.0 * finals[1.0])
    # the .ssv's ramp slope a = 2 counts: the same run with the SSP's own binding differs
    own = load_ssp(path, step=0.25, stop_time=2.0, parameters={"gain.k": 1.0}).run()
    assert own["gain.y"][-1] != pytest.approx(finals[1.0])
    bad = tmp_path / "bad.toml"
    bad.write_text(f"""[campaign]
name = "b"
kind = "cosim"
[task]
system = "{path.name}"
step = 0.5
"gain.kk" = 1.0
[metrics.final]
function = "final"
variable = "gain.y"
""")
    with pytest.raises(ConfigError, match="gain.kk"):
        load_spec(bad)
