"""duffid's container FMU runtime (fmus/container on the glue of fmus/common).

The container is exported from small Modelica FMUs (tests/cosim_models.mo), FMI 2 and FMI 3,
and driven through fmpy, the orchestrator and raw FMI calls (ctypes) for the faults a
container must survive: wrong arguments, wrong types, failing components, binaries that do
not load. Every error must reach the importer's logger (nothing on stdout) and leave the
process alive.

Tolerances: the container runs the orchestrator's algorithm on the same binaries with the
same operations, so states are compared at 1e-12 relative (a few ulps would do; the
margin covers libm differences between builds).
"""
from __future__ import annotations

import ctypes
import math
import re
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest

fmpy = pytest.importorskip("fmpy")

from fmpy.fmi2 import fmi2CallbackFunctions, fmi2CallbackLoggerTYPE
from fmpy.validation import validate_fmu

from duffid.cbuild import FMI2_PLATFORM, SHARED_LIBRARY_SUFFIX
from duffid.cosim.system import CosimError, System
from duffid.modelica.export import export_fmu

if shutil.which("gcc") is None:
    pytest.skip("gcc is needed to build the test FMUs", allow_module_level=True)

MODELS = Path(__file__).with_name("cosim_models.mo")
H = 0.01
#: A component that fails when time passes its parameter c (sqrt of a negative number).
FAILING = """package FailTest
  model Root "y = sqrt(c - time)"
    parameter Real c = 0.5 "Time at which y stops being a number";
    input Real u "Input";
    Real s(start = 0, fixed = true);
    output Real y "sqrt(c - time)";
  equation
    der(s) = u;
    y = sqrt(c - time) + s;
  end Root;
end FailTest;
"""
OK, WARNING, DISCARD, ERROR = 0, 1, 2, 3


@pytest.fixture(scope="module")
def fmus(tmp_path_factory) -> dict[str, Path]:
    """Ramp, Integrator, Gain (FMI 2: ``Name``, FMI 3: ``Name_fmi3``) and Root (FMI 2)."""
    out = tmp_path_factory.mktemp("container_fmus")
    paths = [export_fmu(MODELS, f"CosimTest.{name}", out, version, "cs")
             for name in ("Ramp", "Integrator", "Gain") for version in (2, 3)]
    source = out / "fail.mo"
    source.write_text(FAILING)
    paths.append(export_fmu(source, "FailTest.Root", out, 2, "cs"))
    return {p.stem: p for p in paths}


def _v(version: int) -> str:
    return "" if version == 2 else "_fmi3"


def _chain(fmus, versions) -> System:
    """ramp (a = 2) -> i1 (y0 = 0.5) -> gain (k = -4), each of its FMI version."""
    return (System().add("ramp", fmus[f"Ramp{_v(versions[0])}"], {"a": 2.0})
            .add("i1", fmus[f"Integrator{_v(versions[1])}"], {"y0": 0.5})
            .add("gain", fmus[f"Gain{_v(versions[2])}"], {"k": -4.0})
            .connect("ramp.y", "i1.u").connect("i1.y", "gain.u"))


@pytest.fixture(scope="module")
def chain_fmu(fmus, tmp_path_factory) -> Path:
    """The FMI 2 chain with an input ``u`` driving an integrator and outputs y, g, r, z."""
    system = _chain(fmus, (2, 2, 2)).add("i2", fmus["Integrator"])
    return system.export_container(tmp_path_factory.mktemp("chain") / "chain.fmu", inputs={"u": "i2.u"},
                                   outputs={"y": "i1.y", "g": "gain.y", "r": "ramp.y", "z": "i2.y"}, step=H)


# ------------------------------------------------------------------------------ raw FMI calls
class Raw:
    """The container's binary loaded with ctypes: FMI 2 calls with our own logger."""

    def __init__(self, path: Path, folder: Path) -> None:
        self.unzipdir = Path(fmpy.extract(str(path), str(folder)))
        self.md = fmpy.read_model_description(str(path))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        ident = self.md.coSimulation.modelIdentifier
        self.lib = ctypes.CDLL(str(self.unzipdir / "binaries" / FMI2_PLATFORM / f"{ident}{SHARED_LIBRARY_SUFFIX}"))
        self.messages: list[tuple[int, str, str]] = []

        def log(env, name, status, category, message):
            self.messages.append((status, category.decode(), message.decode().replace("%%", "%")))

        self.callbacks = fmi2CallbackFunctions()
        self.callbacks.logger = fmi2CallbackLoggerTYPE(log)
        self.uri = (self.unzipdir / "resources").as_uri().encode()
        self.c: int | None = None

    def instantiate(self, guid: bytes | None = b"", uri: bytes | None = b"", name: bytes = b"c") -> int | None:
        f = self.lib.fmi2Instantiate
        f.restype = ctypes.c_void_p
        f.argtypes = [ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_char_p,
                      ctypes.POINTER(fmi2CallbackFunctions), ctypes.c_int, ctypes.c_int]
        self.c = f(name, 1, self.md.guid.encode() if guid == b"" else guid, self.uri if uri == b"" else uri,
                   ctypes.byref(self.callbacks), 0, 0)
        return self.c

    def __call__(self, function: str, *args) -> int:
        f = getattr(self.lib, function)
        f.restype = ctypes.c_int
        return f(ctypes.c_void_p(self.c), *args)

    def start(self, t0: float = 0.0) -> None:
        assert self.instantiate()
        assert self("fmi2SetupExperiment", 0, ctypes.c_double(0), ctypes.c_double(t0), 0, ctypes.c_double(0)) == OK
        assert self("fmi2EnterInitializationMode") == OK
        assert self("fmi2ExitInitializationMode") == OK

    def get(self, *names: str) -> list[float]:
        vrs = (ctypes.c_uint * len(names))(*[self.vr[n] for n in names])
        values = (ctypes.c_double * len(names))()
        assert self("fmi2GetReal", vrs, ctypes.c_size_t(len(names)), values) == OK, self.messages
        return list(values)

    def set(self, values: dict[str, float]) -> int:
        vrs = (ctypes.c_uint * len(values))(*[self.vr[n] for n in values])
        array = (ctypes.c_double * len(values))(*values.values())
        return self("fmi2SetReal", vrs, ctypes.c_size_t(len(values)), array)

    def step(self, t: float, h: float) -> int:
        return self("fmi2DoStep", ctypes.c_double(t), ctypes.c_double(h), 1)

    def errors(self) -> list[str]:
        return [m for s, _, m in self.messages if s >= DISCARD]

    def free(self) -> None:
        if self.c:
            self.lib.fmi2FreeInstance.restype = None
            self.lib.fmi2FreeInstance(ctypes.c_void_p(self.c))
            self.c = None


@pytest.fixture
def raw(chain_fmu, tmp_path, capfd):
    """A Raw container of the chain; at the end nothing was printed on stdout or stderr."""
    made: list[Raw] = []

    def make(path: Path = chain_fmu) -> Raw:
        made.append(Raw(path, tmp_path / f"raw{len(made)}"))
        return made[-1]

    yield make
    for r in made:
        r.free()
    out, err = capfd.readouterr()
    assert out == "" and err == ""


# ------------------------------------------------------------------------------ equality
@pytest.mark.parametrize("container", [2, 3])
@pytest.mark.parametrize("versions", [(2, 2, 2), (3, 3, 3), (3, 2, 3)])
def test_container_equals_jacobi(fmus, tmp_path, versions, container):
    """FMI 2 and FMI 3 components in an FMI 2 or FMI 3 container: states equal the
    orchestrator's (Jacobi), the fed-through gain shows its input's newest value, fmpy validates
    and simulates the container."""
    system = _chain(fmus, versions)
    path = system.export_container(tmp_path / "chain.fmu", outputs={"y": "i1.y", "g": "gain.y", "r": "ramp.y"},
                                   step=H, fmi_version=container)
    assert validate_fmu(str(path)) == []
    md = fmpy.read_model_description(str(path))
    assert md.fmiVersion == f"{container}.0"
    assert md.coSimulation.canGetAndSetFMUstate is False and md.generationTool.startswith("duffid.cosim.container")
    variables = {v.name: v for v in md.modelVariables}
    assert variables["y"].description.startswith("output i1.y: ")  # the component's own description follows
    with zipfile.ZipFile(path) as z:
        names = z.namelist()
    assert "resources/i1/modelDescription.xml" in names and "sources/container_fmu_config.h" in names
    expected = system.run(1.0, H, ordering="jacobi")
    inner = System().add("c", path).run(1.0, H)
    for name, source in {"y": "i1.y", "r": "ramp.y"}.items():
        np.testing.assert_allclose(inner[f"c.{name}"], expected[source], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(inner["c.g"], -4.0 * expected["i1.y"], rtol=1e-12, atol=1e-15)
    by_fmpy = fmpy.simulate_fmu(str(path), stop_time=1.0, step_size=5 * H, output_interval=5 * H)
    np.testing.assert_allclose(by_fmpy["y"], expected["i1.y"][::5], rtol=1e-12, atol=1e-15)


@pytest.mark.slow
def test_closed_loop_with_fmi3_estimator_and_controller(loop_fmus, tmp_path):
    """The 1-DOF loop with the FMI 3 estimator and controller (Boolean `identified` read as
    a 1-byte fmi3Boolean and set as one) and the FMI 2 plant equals the orchestrator."""
    from duffid.control.closed_loop import (
        CLOSED_LOOP_OUTPUTS,
        build_closed_loop_fmu,
        closed_loop_case,
        loop_system,
    )
    from duffid.control.controller_fmu import build_controller_fmu
    from duffid.fmu.estimator import build_estimator_fmu

    mixed = dict(loop_fmus)
    mixed["DuffingEstimator1"] = build_estimator_fmu("duffing1", tmp_path, 3)
    mixed["AdaptiveController1"] = build_controller_fmu(1, tmp_path, 3)
    case = closed_loop_case()
    fmu = build_closed_loop_fmu(tmp_path, mixed, case)
    assert validate_fmu(str(fmu)) == []
    direct = loop_system(case, mixed).run(1.0, case.dt)
    inner = System().add("loop", fmu).set_input("loop.r", case.reference).run(1.0, case.dt)
    assert direct["estimator.identified"].any()
    for out, source in CLOSED_LOOP_OUTPUTS.items():
        a, b = inner[f"loop.{out}"], direct[source]
        assert np.array_equal(np.isnan(a), np.isnan(b)), out
        finite = np.isfinite(b)
        assert np.allclose(a[finite], b[finite], rtol=1e-12, atol=1e-15), out


def test_input_parameter_and_feedthrough_through_raw_calls(raw):
    r = raw()
    r.start()
    assert r.get("time", "y", "r", "z") == [0.0, 0.5, 0.0, 0.0]
    assert r.set({"u": 3.0}) == OK
    assert r.step(0.0, 4 * H) == OK  # four internal steps
    t, z, y = r.get("time", "z", "y")
    assert t == 4 * H and z == pytest.approx(3.0 * 4 * H, rel=1e-14)
    # y = 0.5 + sum of 2 t_k h over the internal steps (left Riemann sums)
    assert y == pytest.approx(0.5 + 2.0 * H * H * (0 + 1 + 2 + 3), rel=1e-14)
    assert r("fmi2Terminate") == OK
    assert r.errors() == []


# ------------------------------------------------------------------------------ faults
def test_wrong_calls_are_logged_errors(raw):
    r = raw()
    r.start()
    # fmi2GetString with a Real's value reference
    vrs = (ctypes.c_uint * 1)(r.vr["y"])
    strings = (ctypes.c_char_p * 1)()
    assert r("fmi2GetString", vrs, ctypes.c_size_t(1), strings) == ERROR
    assert "fmi2GetString: unknown value reference" in r.errors()[-1]
    # a Real's value reference read as a Boolean, an unknown one
    ints = (ctypes.c_int * 1)()
    assert r("fmi2GetBoolean", vrs, ctypes.c_size_t(1), ints) == ERROR
    assert "variable y" in r.errors()[-1] and "not a Boolean" in r.errors()[-1]
    vrs[0] = 999
    assert r("fmi2GetReal", vrs, ctypes.c_size_t(1), (ctypes.c_double * 1)()) == ERROR
    assert "unknown value reference 999" in r.errors()[-1]
    # a failing setReal applies nothing: u is not set although it comes first
    assert r.set({"u": 7.0, "i1.y0": 1.0}) == ERROR  # a fixed parameter, in Step Mode
    assert "i1.y0" in r.errors()[-1] and "cannot be set" in r.errors()[-1]
    assert r.set({"u": 7.0, "z": 1.0}) == ERROR  # an output
    assert r.set({"u": math.nan}) == ERROR and "not finite" in r.errors()[-1]
    assert r.step(0.0, H) == OK
    assert r.get("z") == [0.0]  # u kept its start value 0
    # FMU states are refused
    state = ctypes.c_void_p()
    assert r("fmi2GetFMUstate", ctypes.byref(state)) == ERROR
    assert "canGetAndSetFMUstate=false" in r.errors()[-1] and state.value is None
    # a step that is not a whole multiple of the internal step, a wrong communication point
    assert r.step(H, 1.5 * H) > WARNING
    assert any("not a whole multiple of the container's internal step" in m for m in r.errors())


@pytest.mark.parametrize("case", ["nan tolerance", "negative tolerance", "stop before start", "nan start"])
def test_setup_experiment_checks_its_arguments(raw, case):
    r = raw()
    assert r.instantiate()
    tol_defined, tol, start, stop_defined, stop = {
        "nan tolerance": (1, math.nan, 0.0, 0, 0.0), "negative tolerance": (1, -1e-6, 0.0, 0, 0.0),
        "stop before start": (0, 0.0, 1.0, 1, 0.5), "nan start": (0, 0.0, math.nan, 0, 0.0)}[case]
    assert r("fmi2SetupExperiment", tol_defined, ctypes.c_double(tol), ctypes.c_double(start), stop_defined,
             ctypes.c_double(stop)) == ERROR
    assert len(r.errors()) == 1


def test_null_arguments_at_instantiation(raw):
    r = raw()
    assert not r.instantiate(guid=None)
    assert "instantiation token (NULL) does not match" in r.errors()[-1]
    assert not r.instantiate(guid=b"{00000000-0000-0000-0000-000000000000}")
    assert not r.instantiate(uri=None)
    assert "resource location is NULL" in r.errors()[-1]
    assert not r.instantiate(uri=b"http://example.com/resources")
    assert "not a file: URI" in r.errors()[-1]
    assert not r.instantiate(name=b"")
    # and a container whose components are all fine after all that
    assert r.instantiate()
    assert r("fmi2SetupExperiment", 0, ctypes.c_double(0), ctypes.c_double(0), 0, ctypes.c_double(0)) == OK


def test_a_failing_component_discards_the_step_and_keeps_the_time(fmus, tmp_path, raw):
    system = (System().add("ramp", fmus["Ramp"]).add("root", fmus["Root"], {"c": 0.055})
              .connect("ramp.y", "root.u"))
    path = system.export_container(tmp_path / "fails.fmu", outputs={"y": "root.y", "r": "ramp.y"}, step=H)
    r = raw(path)
    r.start()
    for k in range(5):
        assert r.step(k * H, H) == OK
    y_before = r.get("y")
    assert r.step(5 * H, 2 * H) == DISCARD  # root's second internal step passes t = 0.055
    message = " ".join(r.errors())
    assert "component 'root' (Root.fmu, FMI 2)" in message and "fmi2DoStep returned Discard" in message
    assert "y is not finite" in message  # the component's own message, forwarded
    # the container's time and variables are those of the step's start
    value = ctypes.c_double()
    assert r("fmi2GetRealStatus", 2, ctypes.byref(value)) == OK  # fmi2LastSuccessfulTime
    assert value.value == 5 * H and r.get("time", "y") == [5 * H] + y_before
    status = ctypes.c_int()
    assert r("fmi2GetStatus", 0, ctypes.byref(status)) == OK and status.value == DISCARD
    assert r.step(5 * H, H) == ERROR and "must not be called in state Step Failed" in r.errors()[-1]
    assert r("fmi2Terminate") == OK
    # reset makes new components: the run can start again
    assert r("fmi2Reset") == OK
    assert r("fmi2SetupExperiment", 0, ctypes.c_double(0), ctypes.c_double(0), 0, ctypes.c_double(0)) == OK
    assert r("fmi2EnterInitializationMode") == OK and r("fmi2ExitInitializationMode") == OK
    assert r.step(0.0, 5 * H) == OK and r.get("y") == y_before
    # through the orchestrator: a CosimError naming the container, with the component's message
    with pytest.raises(CosimError, match="root"):
        System().add("box", path).run(0.2, H)


def _replace_in_zip(path: Path, out: Path, name: str, data: bytes) -> Path:
    with zipfile.ZipFile(path) as z, zipfile.ZipFile(out, "w") as w:
        for info in z.infolist():
            w.writestr(info, data if info.filename == name else z.read(info))
    return out


def test_component_that_fails_to_instantiate(fmus, tmp_path, raw):
    """A component whose GUID does not match its binary: the container does not instantiate
    and says which component and FMU."""
    with zipfile.ZipFile(fmus["Gain"]) as z:
        xml = z.read("modelDescription.xml").decode()
    guid = re.search(r'guid="([^"]+)"', xml).group(1)
    wrong = _replace_in_zip(fmus["Gain"], tmp_path / "Gain.fmu", "modelDescription.xml",
                            xml.replace(guid, "{12345678-1234-1234-1234-123456789abc}").encode())
    system = System().add("ramp", fmus["Ramp"]).add("gain", wrong).connect("ramp.y", "gain.u")
    path = system.export_container(tmp_path / "bad.fmu", outputs={"g": "gain.y"}, step=H)
    r = raw(path)
    assert not r.instantiate()
    message = " ".join(r.errors())
    assert "component 'gain' (Gain.fmu, FMI 2): fmi2Instantiate failed" in message
    assert "{12345678-1234-1234-1234-123456789abc} does not match" in message  # gain's own message
    with pytest.raises(CosimError, match="box"):
        System().add("box", path).run(0.1, H)


def test_component_binary_that_does_not_load(chain_fmu, tmp_path, raw):
    inside = f"resources/i1/binaries/{FMI2_PLATFORM}/Integrator{SHARED_LIBRARY_SUFFIX}"
    broken = _replace_in_zip(chain_fmu, tmp_path / "broken.fmu", inside, b"\x7fELF not really")
    r = raw(broken)
    assert not r.instantiate()
    message = " ".join(r.errors())
    assert "component 'i1' (Integrator.fmu, FMI 2): its binary" in message and "cannot be loaded" in message


def test_container_needs_binaries_of_every_component(fmus, tmp_path):
    from duffid.errors import WiringError

    with zipfile.ZipFile(fmus["Gain"]) as z, zipfile.ZipFile(tmp_path / "Gain.fmu", "w") as w:
        for info in z.infolist():
            if not info.filename.startswith("binaries/"):
                w.writestr(info, z.read(info))
    system = System().add("ramp", fmus["Ramp"]).add("gain", tmp_path / "Gain.fmu").connect("ramp.y", "gain.u")
    with pytest.raises(WiringError, match="no platform has binaries of every component.*gain: none"):
        system.export_container(tmp_path / "x.fmu", outputs={"g": "gain.y"}, step=H)
    assert not (tmp_path / "x.fmu").exists()


# ------------------------------------------------------------------------------ a component asks to end
@pytest.fixture(scope="module")
def stoppers(tmp_path_factory) -> dict[int, Path]:
    """The C test FMU that asks to end the simulation at t_end (tests/stopper_fmu.py), FMI 2 and 3."""
    from stopper_fmu import build_stopper_fmu

    out = tmp_path_factory.mktemp("stoppers")
    return {version: build_stopper_fmu(out, version) for version in (2, 3)}


def _stopping(fmus, stoppers, version: int, t_end: float) -> System:
    """ramp (a = 2) -> stop.u (the stopper integrates it) and ramp -> i1."""
    return (System().add("ramp", fmus["Ramp"], {"a": 2.0}).add("stop", stoppers[version], {"t_end": t_end})
            .add("i1", fmus["Integrator"]).connect("ramp.y", "stop.u").connect("ramp.y", "i1.u"))


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("reached, last_step, last_row", [(0.35, 6, 0.35), (0.32, 6, 0.30), (0.355, 7, 0.35)])
def test_a_component_asking_to_end_ends_the_container_there(fmus, stoppers, tmp_path, raw, capfd, version, reached,
                                                            last_step, last_row):
    """At the end of the container's step (0.35), of an internal step inside it (0.32) and inside
    an internal step (0.355): the container's doStep says Discard, fmi2Terminated is true,
    fmi2LastSuccessfulTime is the time reached and the outputs are those of that time (equal to
    the orchestrator's Jacobi run where it records that time); nothing is logged as an error."""
    system = _stopping(fmus, stoppers, version, reached)
    path = system.export_container(tmp_path / "stops.fmu", outputs={"y": "stop.y", "s": "stop.s", "z": "i1.y"},
                                   step=H)
    r = raw(path)
    r.start()
    steps = 0
    while (status := r.step(steps * 5 * H, 5 * H)) == OK:
        steps += 1
    assert status == DISCARD and steps == last_step  # the container's step across the time reached
    flag, last = ctypes.c_int(), ctypes.c_double()
    assert r("fmi2GetBooleanStatus", 3, ctypes.byref(flag)) == OK and flag.value == 1  # 3: fmi2Terminated
    assert r("fmi2GetRealStatus", 2, ctypes.byref(last)) == OK  # 2: fmi2LastSuccessfulTime
    assert last.value == pytest.approx(reached, abs=1e-12)
    t, y, s_ = r.get("time", "y", "s")
    assert t == last.value and y == pytest.approx(reached, abs=1e-12)
    # s integrates the ramp's values 2 t_k, held over each internal step, up to the time reached
    grid = np.arange(0.0, reached - 1e-12, H)
    assert s_ == pytest.approx(float(np.sum(2.0 * grid * np.diff(np.append(grid, reached)))), rel=1e-12)
    errors = [m for status_, _, m in r.messages if status_ >= ERROR]
    assert errors == []
    assert any(f"component 'stop' (CStopper{'' if version == 2 else '_fmi3'}.fmu, FMI {version}) asked to end the "
               "simulation" in m for m in r.errors())
    assert r.step(last.value, H) == ERROR and "asked to end the simulation" in r.errors()[-1]
    status_ = ctypes.c_int()
    assert r("fmi2GetStatus", 0, ctypes.byref(status_)) == OK and status_.value == DISCARD
    assert r("fmi2Terminate") == OK and len([m for st, _, m in r.messages if st >= ERROR]) == 1  # the doStep
    # through the orchestrator: a clean end, the last row that of the last completed step
    inner = System().add("c", path).run(1.0, 5 * H)
    assert inner.failure is None and "component 'c'" in inner.ended and f"t = {last.value!r}" in inner.ended
    direct = system.run(1.0, H, ordering="jacobi")
    assert direct.failure is None and direct.ended is not None
    np.testing.assert_allclose(inner.time[-1], last_row, rtol=0, atol=1e-12)  # a partial step is not recorded
    row = int(np.argmin(np.abs(direct.time - inner.time[-1])))
    assert direct.time[row] == pytest.approx(inner.time[-1], abs=1e-12)
    np.testing.assert_allclose(inner["c.s"][-1], direct["stop.s"][row], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(inner["c.z"][-1], direct["i1.y"][row], rtol=1e-12, atol=1e-15)
    # and fmpy records the time reached (its own logger prints the container's Discard messages)
    by_fmpy = fmpy.simulate_fmu(str(path), stop_time=1.0, step_size=5 * H, output_interval=5 * H)
    assert by_fmpy["time"][-1] == pytest.approx(reached, abs=1e-12) and by_fmpy["y"][-1] == pytest.approx(reached)
    assert "asked to end the simulation" in capfd.readouterr().out


def test_an_fmi3_container_ends_where_a_component_asks(fmus, stoppers, tmp_path):
    """The FMI 3 container's doStep reports terminateSimulation (and earlyReturn inside a step)
    at the time a component reached: the orchestrator and fmpy end there, as with FMI 2."""
    system = _stopping(fmus, stoppers, 3, 0.355)
    path = system.export_container(tmp_path / "stops3.fmu", outputs={"y": "stop.y", "z": "i1.y"}, step=H,
                                   fmi_version=3)
    assert validate_fmu(str(path)) == []
    inner = System().add("c", path).run(1.0, 5 * H)
    assert inner.failure is None and "component 'c'" in inner.ended and "t = 0.355" in inner.ended
    direct = system.run(1.0, H, ordering="jacobi")
    np.testing.assert_allclose(inner.time[-1], 0.35, rtol=0, atol=1e-12)
    row = int(np.argmin(np.abs(direct.time - inner.time[-1])))
    np.testing.assert_allclose(inner["c.z"][-1], direct["i1.y"][row], rtol=1e-12, atol=1e-15)
    # no FMU state, as declared: the call fails, the process lives
    from fmpy import extract
    from fmpy.fmi3 import FMU3Slave

    md = fmpy.read_model_description(str(path))
    assert md.coSimulation.canGetAndSetFMUstate is False
    slave = FMU3Slave(guid=md.instantiationToken, unzipDirectory=extract(str(path), str(tmp_path / "x")),
                      modelIdentifier=md.coSimulation.modelIdentifier)
    slave.instantiate()
    slave.enterInitializationMode(startTime=0.0)
    slave.exitInitializationMode()
    with pytest.raises(Exception):
        slave.getFMUState()
    slave.terminate()
    slave.freeInstance()


def test_export_is_reproducible(fmus, tmp_path):
    """Same system, same bytes (the token is derived from the content)."""
    a = _chain(fmus, (2, 3, 2)).export_container(tmp_path / "a.fmu", outputs={"y": "i1.y"}, step=H)
    b = _chain(fmus, (2, 3, 2)).export_container(tmp_path / "b" / "a.fmu", outputs={"y": "i1.y"}, step=H)
    assert a.read_bytes() == b.read_bytes()
