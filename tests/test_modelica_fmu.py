"""Example plant FMUs: validation, ME and CS simulation in fmpy, accuracy against solve_ivp,
the FMI glue's defensive behaviour, FMU state, deterministic archives, rebuild from sources."""
from __future__ import annotations

import argparse
import ctypes
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE
from fmpy.fmi3 import FMU3Slave
from fmpy.validation import validate_fmu
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from duffid.cbuild import HOST_PLATFORM
from duffid.cli import build_fmus
from duffid.data.signals import Chirp
from duffid.modelica.export import EXAMPLE_PLANTS, build_all
from duffid.models.chain import Chain, Duffing1, Duffing2, DuffingCircuit

T_END, H = 0.5, 1e-3


@pytest.fixture(scope="session")
def fmus(tmp_path_factory) -> dict[str, Path]:
    """Every example plant built once: ``{"Oscillator1DOF": ..., "Oscillator1DOF_fmi3": ...}``."""
    paths = build_all(tmp_path_factory.mktemp("fmus"))
    return {p.stem: p for p in paths}


# ---------------------------------------------------------------------------------- driver
class Slave:
    """A co-simulation instance driven step by step, collecting log messages."""

    def __init__(self, fmu: Path, version: int, tmp: Path, logging_on: bool = False) -> None:
        self.md = read_model_description(fmu)
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.version = version
        self.messages: list[tuple[int, str]] = []
        directory = extract(fmu, str(tmp / f"{fmu.stem}_{id(self)}"))
        ident = self.md.coSimulation.modelIdentifier
        if version == 2:
            self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=directory, modelIdentifier=ident,
                                 instanceName="plant")

            def logger(env, name, status, category, message):
                self.messages.append((status, message.decode()))

            self.callbacks = fmi2CallbackFunctions()
            self.callbacks.logger = fmi2CallbackLoggerTYPE(logger)
            self.fmu.instantiate(callbacks=self.callbacks, loggingOn=logging_on)
        else:
            self.fmu = FMU3Slave(guid=self.md.instantiationToken, unzipDirectory=directory,
                                 modelIdentifier=ident, instanceName="plant")

            def log3(env, status, category, message):
                self.messages.append((status, message.decode()))

            self.fmu.instantiate(loggingOn=logging_on, logMessage=log3)

    def set(self, values: dict[str, float]) -> None:
        refs, vals = [self.vr[k] for k in values], list(values.values())
        (self.fmu.setReal if self.version == 2 else self.fmu.setFloat64)(refs, vals)

    def get(self, names: list[str]) -> list[float]:
        refs = [self.vr[k] for k in names]
        return (self.fmu.getReal if self.version == 2 else self.fmu.getFloat64)(refs)

    def initialize(self, start: dict[str, float] | None = None, tolerance: float | None = None,
                   stop_time: float | None = None) -> None:
        if self.version == 2:
            self.fmu.setupExperiment(tolerance=tolerance, startTime=0.0, stopTime=stop_time)
            if start:
                self.set(start)
            self.fmu.enterInitializationMode()
        else:
            if start:
                self.set(start)
            self.fmu.enterInitializationMode(tolerance=tolerance, startTime=0.0, stopTime=stop_time)
        self.fmu.exitInitializationMode()

    def run(self, input_name: str, u, outputs: list[str], n: int, t0: float = 0.0, h: float = H) -> np.ndarray:
        """Input held at u(t_k) over [t_k, t_k + h]; outputs at t_0 .. t_n."""
        rows = [self.get(outputs)]
        for k in range(n):
            t = t0 + k * h
            self.set({input_name: u(t)})
            self.fmu.doStep(t, h)
            rows.append(self.get(outputs))
        return np.array(rows)

    def close(self) -> None:
        self.fmu.terminate()
        self.fmu.freeInstance()


# ---------------------------------------------------------------------------------- references
def _mechanical(model, n):
    def rhs(y, u):
        return np.concatenate([y[n:], model.acceleration(y[:n], y[n:], np.array([u]))])
    return rhs


P1 = {"m": 2.0, "b": 10.0, "k": 1500.0, "kp": -1.0e6}
P2 = {"m1": 2.6, "b1": 6.0, "k1": 1300.0, "kp1": -1.2e6, "m2": 2.8, "b2": 3.0, "k2": 1500.0, "kp2": -1.3e6}
PC = {"m[1]": 1.0, "m[2]": 1.5, "m[3]": 0.8, "b[1]": 1.0, "b[2]": 2.0, "b[3]": 1.5, "k[1]": 1000.0,
      "k[2]": 1200.0, "k[3]": 900.0, "kp[1]": -1e5, "kp[2]": 2e5, "kp[3]": 0.0, "fc[1]": 0.5, "fc[2]": 0.2,
      "fc[3]": 0.1}
CHAIN = Chain(masses=(1.0, 1.5, 0.8), damping=(1.0, 2.0, 1.5),
              stiffness=({1: 1000.0, 3: -1e5}, {1: 1200.0, 3: 2e5}, {1: 900.0, 3: 0.0}), coulomb=(0.5, 0.2, 0.1))
PD = {"L": 0.12, "R": 2.5, "C": 1.2e-3, "a": 4e6}
PS = {"R": 2.5, "L0": 0.12, "Linf": 0.015, "Isat": 0.8, "C": 1.2e-3}


def _saturating_current(psi: float) -> float:
    f = lambda i: PS["Linf"] * i + (PS["L0"] - PS["Linf"]) * PS["Isat"] * np.tanh(i / PS["Isat"]) - psi  # noqa: E731
    bound = abs(psi) / PS["Linf"] + 1.0
    return brentq(f, -bound, bound, xtol=1e-16, rtol=1e-15)


def _saturating_rhs(y, u):
    i = _saturating_current(y[0])
    return [u - PS["R"] * i - y[1], i / PS["C"]]


#: plant -> (parameters, input, outputs, rhs(y, u), y0, outputs(y))
CASES = {
    "Oscillator1DOF": (P1, "f", ["x", "v"], _mechanical(Duffing1(**P1), 1), [0.0] * 2, lambda y: y),
    "Oscillator2DOF": (P2, "f1", ["x1", "x2", "v1", "v2"], _mechanical(Duffing2(**P2), 2), [0.0] * 4,
                       lambda y: y),
    "ChainNDOF": (PC, "f", ["x[1]", "x[2]", "x[3]", "v[1]", "v[2]", "v[3]"], _mechanical(CHAIN, 3), [0.0] * 6,
                  lambda y: y),
    "DuffingCircuit": (PD, "u", ["q", "i"], _mechanical(DuffingCircuit(**PD), 1), [0.0] * 2, lambda y: y),
    "SaturatingCircuit": (PS, "u", ["i", "vC", "psi"], _saturating_rhs, [0.0] * 2,
                          lambda y: [_saturating_current(y[0]), y[1], y[0]]),
}
CHIRP = Chirp(10.0, 0.0, 30.0, T_END)
EXCITATIONS = {"step": lambda t: 10.0, "chirp": lambda t: float(CHIRP(t))}


def reference(plant: str, excitation: str, n: int, h: float = H) -> np.ndarray:
    """solve_ivp of the same equations, the input held over each communication step."""
    _, _, _, rhs, y0, out = CASES[plant]
    u_of = EXCITATIONS[excitation]
    y = np.array(y0, float)
    rows = [out(y)]
    for k in range(n):
        u = u_of(k * h)
        sol = solve_ivp(lambda t, yy: rhs(yy, u), (k * h, (k + 1) * h), y, method="DOP853", rtol=1e-12, atol=1e-16)
        y = sol.y[:, -1]
        rows.append(out(y))
    return np.array(rows)


def relative_error(result: np.ndarray, ref: np.ndarray) -> np.ndarray:
    return np.max(np.abs(result - ref), axis=0) / np.max(np.abs(ref), axis=0)


# ---------------------------------------------------------------------------------- FMUs
def test_build_all_writes_every_plant_in_both_versions(fmus):
    assert sorted(fmus) == sorted([p for p in EXAMPLE_PLANTS] + [f"{p}_fmi3" for p in EXAMPLE_PLANTS])
    for name, path in fmus.items():
        md = read_model_description(path)
        assert md.fmiVersion == ("3.0" if name.endswith("_fmi3") else "2.0")
        assert md.modelExchange is not None and md.coSimulation is not None
        assert float(md.defaultExperiment.tolerance) == pytest.approx(1e-8)
        with zipfile.ZipFile(path) as archive:
            names = archive.namelist()
        assert {"sources/model.c", "sources/model_casadi.c", "sources/fmu_instance.c"} <= set(names)
        if name.endswith("_fmi3"):
            assert "sources/buildDescription.xml" in names and "sources/fmi3_functions.c" in names
        assert set(md.buildConfigurations[0].sourceFileSets[0].sourceFiles) == {
            "fmi3_functions.c" if name.endswith("_fmi3") else "fmi2_functions.c", "fmu_instance.c", "model.c",
            "model_casadi.c"}


@pytest.mark.parametrize("name", [p + s for p in EXAMPLE_PLANTS for s in ("", "_fmi3")])
def test_fmpy_validate_finds_no_problems(fmus, name):
    assert validate_fmu(str(fmus[name])) == []


@pytest.mark.parametrize("name", [p + s for p in EXAMPLE_PLANTS for s in ("", "_fmi3")])
def test_fmpy_simulates_model_exchange_and_co_simulation(fmus, name):
    md = read_model_description(fmus[name])
    u = next(v.name for v in md.modelVariables if v.causality == "input")
    outputs = [v.name for v in md.modelVariables if v.causality == "output"]
    t = np.linspace(0.0, 0.3, 301)
    signal = np.zeros(len(t), dtype=[("time", float), (u, float)])
    signal["time"], signal[u] = t, 10.0
    results = [simulate_fmu(fmus[name], fmi_type=kind, stop_time=0.3, output_interval=1e-3, input=signal,
                            output=outputs) for kind in ("ModelExchange", "CoSimulation")]
    for out in outputs:
        me, cs = results[0][out], results[1][out]
        assert np.all(np.isfinite(cs)) and np.max(np.abs(cs)) > 0
        assert np.max(np.abs(me - cs)) <= 1e-4 * np.max(np.abs(cs)), out


@pytest.mark.parametrize("excitation", EXCITATIONS)
@pytest.mark.parametrize("plant", EXAMPLE_PLANTS)
def test_co_simulation_matches_solve_ivp(fmus, tmp_path, plant, excitation):
    """Default tolerance (1e-8), parameters overridden through start values, 1e-7 relative."""
    params, u, outputs, *_ = CASES[plant]
    n = int(round(T_END / H))
    slave = Slave(fmus[plant], 2, tmp_path)
    slave.initialize(start=params)
    result = slave.run(u, EXCITATIONS[excitation], outputs, n)
    slave.close()
    err = relative_error(result, reference(plant, excitation, n))
    assert np.all(err < 1e-7), dict(zip(outputs, err))


@pytest.mark.parametrize("plant", ["Oscillator2DOF", "SaturatingCircuit"])
def test_fmi3_co_simulation_matches_solve_ivp(fmus, tmp_path, plant):
    params, u, outputs, *_ = CASES[plant]
    n = int(round(T_END / H))
    slave = Slave(fmus[f"{plant}_fmi3"], 3, tmp_path)
    slave.initialize(start=params)
    result = slave.run(u, EXCITATIONS["chirp"], outputs, n)
    slave.close()
    assert np.all(relative_error(result, reference(plant, "chirp", n)) < 1e-7)


def test_co_simulation_tolerance_comes_from_setup_experiment(fmus, tmp_path):
    params, u, outputs, *_ = CASES["Oscillator1DOF"]
    h = 0.025  # long communication steps: the integrator's own step sizes decide the accuracy
    ref = reference("Oscillator1DOF", "chirp", 20, h)
    errors = []
    for tolerance in (1e-3, None, 1e-11):
        slave = Slave(fmus["Oscillator1DOF"], 2, tmp_path)
        slave.initialize(start=params, tolerance=tolerance)
        errors.append(relative_error(slave.run(u, EXCITATIONS["chirp"], outputs, 20, h=h), ref).max())
        slave.close()
    assert errors[0] > 1e-7 > errors[1] > errors[2]


def test_state_start_values_are_settable(fmus, tmp_path):
    slave = Slave(fmus["Oscillator1DOF"], 2, tmp_path)
    slave.initialize(start={"mass.s": 0.01, "mass.v": -0.1})
    result = slave.run("f", lambda t: 0.0, ["x", "v"], 200)
    slave.close()
    model = Duffing1()
    sol = solve_ivp(lambda t, y: [y[1], model.acceleration(y[:1], y[1:], np.zeros(1))[0]], (0, 0.2), [0.01, -0.1],
                    method="DOP853", rtol=1e-12, atol=1e-16, t_eval=np.arange(201) * H)
    assert np.all(relative_error(result, sol.y.T) < 1e-7)


# ---------------------------------------------------------------------------------- glue
@pytest.mark.parametrize("version", [2, 3])
def test_glue_rejects_calls_in_the_wrong_state_with_a_logged_error(fmus, tmp_path, version):
    suffix = "" if version == 2 else "_fmi3"
    slave = Slave(fmus["Oscillator1DOF" + suffix], version, tmp_path, logging_on=False)
    with pytest.raises(FMICallException, match="status 3"):
        slave.fmu.doStep(0.0, H)
    assert "DoStep must not be called in state Instantiated" in slave.messages[-1][1]
    slave.initialize()
    with pytest.raises(FMICallException):
        slave.set({"m": 3.0})  # a fixed parameter after initialisation
    assert "variable m (value reference 1) cannot be set in state Step Mode" in slave.messages[-1][1]
    with pytest.raises(FMICallException):
        slave.set({"x": 3.0})  # an output
    assert "cannot be set" in slave.messages[-1][1]
    slave.close()


@pytest.mark.parametrize("version", [2, 3])
def test_glue_rejects_non_finite_inputs_and_bad_steps(fmus, tmp_path, version):
    suffix = "" if version == 2 else "_fmi3"
    slave = Slave(fmus["Oscillator1DOF" + suffix], version, tmp_path, logging_on=False)
    slave.initialize()
    for bad in (np.nan, np.inf):
        with pytest.raises(FMICallException, match="status 3"):
            slave.set({"f": bad})
        status, message = slave.messages[-1]
        assert status == 3 and "value" in message and "of variable f" in message and "not finite" in message
    slave.set({"f": 10.0})
    slave.fmu.doStep(0.0, H)
    for t, h, text in ((0.0, H, "does not match the FMU's time"), (H, 0.0, "must be positive"),
                       (H, -H, "must be positive"), (H, np.nan, "must be positive")):
        with pytest.raises(FMICallException, match="status 3"):
            slave.fmu.doStep(t, h)
        assert text in slave.messages[-1][1]
    slave.fmu.doStep(H, H)  # still usable
    assert slave.get(["time"]) == [pytest.approx(2 * H)]
    slave.close()


def test_glue_null_arguments_and_interface_checks(fmus, tmp_path):
    slave = Slave(fmus["Oscillator1DOF"], 2, tmp_path)
    slave.initialize()
    dll, c = slave.fmu.dll, slave.fmu.component
    assert dll.fmi2GetReal(c, None, 1, None) == 3
    assert "argument valueReferences must not be NULL" in slave.messages[-1][1]
    assert dll.fmi2GetReal(c, None, 0, None) == 0  # nothing requested: fine
    dll.fmi2DoStep.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_int]
    assert dll.fmi2DoStep(None, 0.0, H, 1) == 3  # NULL instance: no crash
    dll.fmi2GetDerivatives.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_double), ctypes.c_size_t]
    dx = (ctypes.c_double * 2)()
    assert dll.fmi2GetDerivatives(c, dx, 2) == 3
    assert "fmi2GetDerivatives is a Model Exchange function" in slave.messages[-1][1]
    vr = (ctypes.c_uint * 1)(999)
    value = (ctypes.c_double * 1)()
    assert dll.fmi2GetReal(c, vr, 1, value) == 3 and "unknown value reference 999" in slave.messages[-1][1]
    slave.close()
    # own callbacks: fmpy's default logger proxy may point to a logger another test freed
    with pytest.raises(Exception, match="instantiate"):
        FMU2Slave(guid="{wrong}", unzipDirectory=slave.fmu.unzipDirectory, modelIdentifier="Oscillator1DOF",
                  instanceName="x").instantiate(callbacks=slave.callbacks)
    assert "instantiation token {wrong} does not match" in slave.messages[-1][1]


def test_failed_step_is_discarded_and_the_last_state_kept(fmus, tmp_path):
    slave = Slave(fmus["Oscillator1DOF"], 2, tmp_path)
    slave.initialize()
    t = 0.0
    with pytest.raises(FMICallException, match="status 2"):  # the softening spring lets x escape
        for k in range(2000):
            t = k * H
            slave.set({"f": 100.0})
            slave.fmu.doStep(t, H)
    assert any("discarded" in m for _, m in slave.messages)
    assert slave.fmu.getRealStatus(2) == pytest.approx(t)  # fmi2LastSuccessfulTime
    assert np.all(np.isfinite(slave.get(["x", "v"])))
    with pytest.raises(FMICallException):
        slave.fmu.doStep(t, H)
    assert "must not be called in state Step Failed" in slave.messages[-1][1]
    slave.close()


def test_evaluation_failure_is_an_error(fmus, tmp_path):
    slave = Slave(fmus["SaturatingCircuit"], 2, tmp_path)
    slave.fmu.setupExperiment()
    slave.set({"Isat": 0.0})  # tanh(i/0): the model cannot be evaluated
    slave.fmu.enterInitializationMode()
    with pytest.raises(FMICallException, match="status 3"):
        slave.fmu.exitInitializationMode()
    assert any("not finite" in m or "could not be evaluated" in m for _, m in slave.messages)
    slave.fmu.freeInstance()


@pytest.mark.parametrize("version", [2, 3])
def test_fmu_state_get_set_and_serialize(fmus, tmp_path, version):
    suffix = "" if version == 2 else "_fmi3"
    slave = Slave(fmus["Oscillator2DOF" + suffix], version, tmp_path)
    slave.initialize()
    u = EXCITATIONS["chirp"]
    slave.run("f1", u, ["x1"], 100)
    state = slave.fmu.getFMUState() if version == 3 else slave.fmu.getFMUstate()
    first = slave.run("f1", u, ["x1", "x2"], 100, t0=100 * H)
    if version == 2:
        slave.fmu.setFMUstate(state)
        serialized = slave.fmu.serializeFMUstate(state)
        slave.fmu.freeFMUstate(state)
        state = slave.fmu.deSerializeFMUstate(serialized)
        slave.fmu.setFMUstate(state)
    else:
        slave.fmu.setFMUState(state)
        serialized = slave.fmu.serializeFMUState(state)
        slave.fmu.freeFMUState(state)
        state = slave.fmu.deserializeFMUState(serialized)
        slave.fmu.setFMUState(state)
    again = slave.run("f1", u, ["x1", "x2"], 100, t0=100 * H)
    np.testing.assert_array_equal(first, again)
    slave.close()


# ---------------------------------------------------------------------------------- archives
def test_cli_rebuild_is_byte_identical(fmus, tmp_path, capsys):
    parser = argparse.ArgumentParser()
    build_fmus.add_parser(parser.add_subparsers(dest="command"))
    # the fixture's FMUs carry this machine's binary only
    args = parser.parse_args(["build-fmus", "--out", str(tmp_path), "--plant", "DuffingCircuit",
                              "--platforms", HOST_PLATFORM.name])
    assert build_fmus.run(args) == 0
    printed = capsys.readouterr().out.split()
    assert printed == [str(tmp_path / "DuffingCircuit.fmu"), str(tmp_path / "DuffingCircuit_fmi3.fmu")]
    for name in ("DuffingCircuit", "DuffingCircuit_fmi3"):
        assert (tmp_path / f"{name}.fmu").read_bytes() == fmus[name].read_bytes()


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("cmake") is None, reason="fmpy's rebuild needs cmake")
@pytest.mark.parametrize("name", ["Oscillator1DOF", "SaturatingCircuit_fmi3"])
def test_rebuild_from_sources_with_fmpy_gives_the_same_results(fmus, tmp_path, name):
    from fmpy.build import build_platform_binary

    version = 3 if name.endswith("_fmi3") else 2
    plant = name.removesuffix("_fmi3")
    params, u, outputs, *_ = CASES[plant]
    directory = (tmp_path / "unzipped").resolve()
    extract(fmus[name], str(directory))
    binary = next((directory / "binaries").glob("*/*.so"))
    binary.unlink()
    (tmp_path / "cmake").mkdir()
    build_platform_binary(directory, build_dir=tmp_path / "cmake")
    assert binary.exists()
    rebuilt = tmp_path / f"{name}.fmu"
    shutil.make_archive(str(rebuilt.with_suffix("")), "zip", directory)
    rebuilt.with_suffix(".zip").rename(rebuilt)
    results = []
    for path in (fmus[name], rebuilt):
        slave = Slave(path, version, tmp_path)
        slave.initialize(start=params)
        results.append(slave.run(u, EXCITATIONS["chirp"], outputs, 200))
        slave.close()
    np.testing.assert_allclose(results[1], results[0], rtol=1e-12, atol=1e-15)
