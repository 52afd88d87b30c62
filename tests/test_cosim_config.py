"""Co-simulation systems from JSON/TOML files (duffid.cosim.config, ``duffid cosim``)."""
from __future__ import annotations

import csv
import json

import fmpy
import numpy as np
import pytest

from duffid.cli import main
from duffid.cosim.config import ConfigError, load_config
from duffid.cosim.system import System, WiringError

ESTIMATES = ("m_hat", "b_hat", "k_hat", "kp_hat", "identified")


def _config(fmus, **overrides):
    config = {
        "components": {
            "plant": {"fmu": str(fmus["Oscillator1DOF"])},
            "estimator": {"fmu": str(fmus["DuffingEstimator1"])},
            "controller": {"fmu": str(fmus["AdaptiveController1"]), "parameters": {"force_limit": 25.0}},
        },
        "connections": [["plant.x", "estimator.x"], ["plant.x", "controller.x"], ["controller.f", "plant.f"],
                        ["controller.f_sample", "estimator.f"],
                        *[[f"estimator.{name}", f"controller.{name}"] for name in ESTIMATES]],
        "input_csv": {"file": "reference.csv", "columns": {"r": "controller.r"}},
        "run": {"stop_time": 1.0, "step": 0.001, "record": ["plant.x", "controller.f", "estimator.k_hat"]},
        "container": {"inputs": {"r": ["controller.r"]}, "outputs": {"x": "plant.x", "f": "controller.f"}},
    }
    config.update(overrides)
    return config


@pytest.fixture
def folder(tmp_path):
    (tmp_path / "reference.csv").write_text("t,r\n0,0.005\n0.5,0.005\n1,0.007\n")
    return tmp_path


def _write(folder, config, name="loop.json"):
    path = folder / name
    path.write_text(json.dumps(config))
    return path


def test_config_run_equals_the_python_system(loop_fmus, folder):
    config = load_config(_write(folder, _config(loop_fmus)))
    result = config.run()
    system = (System().add("plant", loop_fmus["Oscillator1DOF"]).add("estimator", loop_fmus["DuffingEstimator1"])
              .add("controller", loop_fmus["AdaptiveController1"], parameters={"force_limit": 25.0})
              .connect("plant.x", "estimator.x").connect("plant.x", "controller.x")
              .connect("controller.f", "plant.f").connect("controller.f_sample", "estimator.f"))
    for name in ESTIMATES:
        system.connect(f"estimator.{name}", f"controller.{name}")
    system.set_input("controller.r", (np.array([0.0, 0.5, 1.0]), np.array([0.005, 0.005, 0.007])))
    direct = system.run(1.0, 1e-3)
    assert result.names == ["plant.x", "controller.f", "estimator.k_hat"]
    for name in result.names:
        assert np.array_equal(result[name], direct[name], equal_nan=True), name


def test_toml_config_and_relative_paths(loop_fmus, folder):
    (folder / "fmus").mkdir()
    for name in ("Oscillator1DOF",):
        (folder / "fmus" / f"{name}.fmu").write_bytes(loop_fmus[name].read_bytes())
    (folder / "loop.toml").write_text(
        '[components.plant]\nfmu = "fmus/Oscillator1DOF.fmu"\nparameters = { m = 3.0 }\n'
        '[inputs]\n"plant.f" = 10.0\n[run]\nstop_time = 0.5\nstep = 0.001\nordering = "gauss-seidel"\n')
    result = load_config(folder / "loop.toml").run()
    assert result.ordering == "gauss-seidel"
    assert 0.0 < result["plant.x"][-1] < 0.02


@pytest.mark.parametrize("change, message", [
    (lambda c: c.update(extra=1), "unknown key(s) ['extra']"),
    (lambda c: c["run"].pop("step"), "run.step is missing"),
    (lambda c: c["run"].update(step=-1), "run.step must be > 0"),
    (lambda c: c["run"].update(ordering="newton"), "run.ordering must be one of"),
    (lambda c: c["connections"].append(["plant.x"]), "connections[9] must be"),
    (lambda c: c["components"]["plant"].update(fmu=3), "components.plant.fmu must be"),
    (lambda c: c["components"]["plant"].update(parameters={"mass": 1.0}), "components.plant"),
    (lambda c: c["connections"].__setitem__(0, ["plant.y", "estimator.x"]), "connections[0]: "),
    (lambda c: c.update(inputs={"controller.r": "fast"}),
     "inputs.controller.r: input 'controller.r' (set_input) is Real; got 'fast'"),
])
def test_bad_configs_name_file_and_entry(loop_fmus, folder, change, message):
    config = _config(loop_fmus)
    change(config)
    path = _write(folder, config)
    with pytest.raises((ConfigError, WiringError)) as info:
        load_config(path)
    assert str(path) in str(info.value) and message in str(info.value)


def test_unreadable_files(folder):
    with pytest.raises(ConfigError, match="no such file"):
        load_config(folder / "missing.json")
    (folder / "broken.json").write_text('{"components": {\n  "plant": }\n}')
    with pytest.raises(ConfigError, match=r"broken.json:2:\d+: not valid JSON"):
        load_config(folder / "broken.json")


def test_cli_runs_writes_csv_and_reports_failures(loop_fmus, folder, capsys):
    path = _write(folder, _config(loop_fmus))
    assert main(["cosim", str(path), "-o", str(folder / "out.csv")]) == 0
    with open(folder / "out.csv", newline="") as handle:
        rows = list(csv.reader(handle))
    assert rows[0] == ["time", "plant.x", "controller.f", "estimator.k_hat"] and len(rows) == 1002
    assert "1001 communication points" in capsys.readouterr().out
    bad = _config(loop_fmus)
    bad["components"]["controller"]["parameters"] = {"force_limit": 5.0}  # below the 10 N excitation
    assert main(["cosim", str(_write(folder, bad, "bad.json")), "-o", str(folder / "bad.csv")]) == 1
    err = capsys.readouterr().err
    assert "controller" in err and "fmi2ExitInitializationMode" in err
    assert main(["cosim", str(folder / "missing.json")]) == 2


def test_cli_exports_the_container(loop_fmus, folder, capsys):
    path = _write(folder, _config(loop_fmus))
    fmu = folder / "loop.fmu"
    assert main(["cosim", str(path), "--export-container", str(fmu)]) == 0
    said = capsys.readouterr().out
    assert said.startswith(f"wrote {fmu}: container FMU (FMI 2.0 co-simulation, step 0.001 s) of controller, "
                           "estimator, plant; 1 input(s)") and "binaries for " in said and "linux64" in said
    assert fmpy.validation.validate_fmu(str(fmu)) == []
    md = fmpy.read_model_description(str(fmu))
    names = {v.name: v.causality for v in md.modelVariables}
    assert names["r"] == "input" and names["x"] == names["f"] == "output"
    # the components' units travel with the container's variables, with their definitions
    units = {v.name: v.unit for v in md.modelVariables}
    assert (units["r"], units["x"], units["f"], units["controller.force_limit"]) == ("m", "m", "N", "N")
    assert {"m", "N"} <= {u.name for u in md.unitDefinitions}
    assert md.coSimulation.canHandleVariableCommunicationStepSize is False  # whole multiples of its step only
    # the same loop as an FMI 3 container, run by fmpy as the FMI 2 one
    fmu3 = folder / "loop3.fmu"
    assert main(["cosim", str(path), "--export-container", str(fmu3), "--fmi", "3"]) == 0
    assert capsys.readouterr().out.startswith(f"wrote {fmu3}: container FMU (FMI 3.0 co-simulation")
    assert fmpy.validation.validate_fmu(str(fmu3)) == []
    runs = [fmpy.simulate_fmu(str(f), stop_time=0.2, step_size=1e-3, output=["x", "f"], start_values={"r": 1e-3})
            for f in (fmu, fmu3)]
    assert np.array_equal(runs[0]["x"], runs[1]["x"]) and np.array_equal(runs[0]["f"], runs[1]["f"])


def test_export_container_needs_an_interface(loop_fmus, folder, capsys):
    config = _config(loop_fmus)
    del config["container"]
    path = _write(folder, config)
    assert main(["cosim", str(path), "--export-container", str(folder / "loop.fmu")]) == 2
    err = capsys.readouterr().err
    assert "loop.json" in err and 'needs a "container" section' in err
    assert not (folder / "loop.fmu").exists()
    # an input driven from the file's input_csv that the container does not expose is not dropped
    config = _config(loop_fmus, container={"outputs": {"x": "plant.x"}})
    assert main(["cosim", str(_write(folder, config)), "--export-container", str(folder / "loop.fmu")]) == 2
    assert "controller.r is driven by the system's external inputs" in capsys.readouterr().err
    assert not (folder / "loop.fmu").exists()
