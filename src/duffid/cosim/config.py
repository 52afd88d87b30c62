"""Co-simulation systems described in a JSON or TOML file (``duffid cosim``).

A configuration file lets a user wire and run FMUs without writing Python::

    {
      "components": {
        "plant":      {"fmu": "build/fmus/Oscillator1DOF.fmu", "parameters": {"m": 2.6}},
        "estimator":  {"fmu": "build/fmus/DuffingEstimator1.fmu"},
        "controller": {"fmu": "build/fmus/AdaptiveController1.fmu"}
      },
      "connections": [["plant.x", "estimator.x"], ["plant.x", "controller.x"],
                      ["controller.f", "plant.f"], ["controller.f_sample", "estimator.f"],
                      ["estimator.m_hat", "controller.m_hat"], ...],
      "inputs": {"controller.r": 0.005},
      "input_csv": {"file": "reference.csv", "columns": {"r": "controller.r"}},
      "run": {"stop_time": 4.0, "step": 0.001, "start_time": 0.0, "ordering": "jacobi",
              "record": ["plant.x", "controller.f"]},
      "container": {"inputs": {"r": ["controller.r"]}, "outputs": {"x": "plant.x"}}
    }

Relative paths (FMUs, CSV) are taken from the configuration file's folder. ``inputs`` are
constants of the input's type (a number, true/false, a text for a String or hexadecimal text
for a Binary, a nested list for an array input; ``"comp.u[2]"`` names one element);
time-varying inputs come from ``input_csv`` (time column ``t`` or ``time``; a time given
twice marks a step; fields as the input's type reads them: numbers, true/false or 0/1, text,
hexadecimal for Binary): continuous Real and Float32 inputs are interpolated linearly,
discrete ones and the other types hold the last sample, and ``"interpolation": {"r": "hold"}``
overrides per column. ``container`` describes the container FMU that ``duffid cosim
--export-container`` writes (its step is ``run.step``). Connections may carry a third
element ``{"check_units": false}``. Every error names the file and the entry that is
wrong (:class:`ConfigError`); wiring errors are those of :class:`duffid.cosim.system.System`.
"""
from __future__ import annotations

import json
import math
import os
import tomllib

import numpy as np
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

from ..errors import ConfigError, WiringError
from .compiled_loop import LOOP_MODES
from .ssp import ANNOTATION, SspError, read_ssp
from .system import ORDERINGS, Result, System

__all__ = ["ConfigError", "CosimConfig", "load_config", "load_ssp", "SSP_SUFFIXES"]

#: File suffixes read as SSP (:func:`load_ssp`).
SSP_SUFFIXES = (".ssp", ".ssd")
_TOP = {"components", "connections", "inputs", "input_csv", "run", "container"}
_RUN = {"stop_time", "step", "start_time", "ordering", "order", "record", "loop"}
_COMPONENT = {"fmu", "parameters"}
_CONTAINER = {"inputs", "outputs", "parameters"}




@dataclass
class CosimConfig:
    """A parsed configuration: the system and how to run it.

    Attributes
    ----------
    path : Path
        The configuration file.
    system : System
        Components, connections and inputs.
    stop_time, step, start_time : float
        The run's time grid.
    ordering : str
        ``"jacobi"`` or ``"gauss-seidel"``.
    order : list of str or None
        Gauss-Seidel order given in the file.
    record : list of str or None
        Variables to record (None: every output).
    container : dict
        The ``container`` section (inputs, outputs, parameters of an exported container); for
        an SSP, its system's input and output connectors (every output when it has none).
    loop : str
        The inner loop (``System.run(loop=)``): ``"auto"``, ``"compiled"`` or ``"python"``.
    warnings : list of str
        What the file holds that duffid did not apply (an SSP's annotations of other tools).
    """

    path: Path
    system: System
    stop_time: float
    step: float
    start_time: float = 0.0
    ordering: str = "jacobi"
    order: list[str] | None = None
    record: list[str] | None = None
    container: dict[str, Any] = field(default_factory=dict)
    loop: str = "auto"
    warnings: list[str] = field(default_factory=list)

    def export_ssp(self, path: str | os.PathLike[str]) -> Path:
        """Write the system and its run (grid, ordering) as an SSP archive
        (:meth:`duffid.cosim.system.System.to_ssp`)."""
        return self.system.to_ssp(path, stop_time=self.stop_time, step=self.step, start_time=self.start_time,
                                  ordering=self.ordering,
                                  order=self.order if self.ordering == "gauss-seidel" else None)

    def run(self, *, progress: bool = False, ordering: str | None = None, loop: str | None = None) -> Result:
        """Run the system as configured (``ordering`` and ``loop`` override the file's)."""
        ordering = ordering or self.ordering
        return self.system.run(self.stop_time, self.step, start_time=self.start_time, ordering=ordering,
                               order=self.order if ordering == "gauss-seidel" else None, record=self.record,
                               progress=progress, loop=loop or self.loop)

    def export_container(self, path: str | os.PathLike[str], fmi_version: int = 2) -> Path:
        """Write the system as one container FMU (FMI ``fmi_version``: 2 or 3) described by the
        ``container`` section.

        Raises
        ------
        ConfigError
            If the file has no ``container`` section (the container's interface).
        """
        if not self.container:
            raise ConfigError(f"{self.path}: --export-container needs a \"container\" section, the container's "
                              "interface: its inputs (e.g. {\"r\": [\"controller.r\"]}) and outputs "
                              "(e.g. {\"x\": \"plant.x\"}); without it the FMU would have no inputs")
        return self.system.export_container(path, inputs=self.container.get("inputs"),
                                            outputs=self.container.get("outputs"), step=self.step,
                                            parameters=self.container.get("parameters"), fmi_version=fmi_version)


def _read(path: Path) -> dict[str, Any]:
    if not path.is_file():
        raise ConfigError(f"{path}: no such file")
    try:
        if path.suffix.lower() == ".toml":
            with path.open("rb") as handle:
                data = tomllib.load(handle)
        else:
            data = json.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None
    except json.JSONDecodeError as exc:
        raise ConfigError(f"{path}:{exc.lineno}:{exc.colno}: not valid JSON: {exc.msg}") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: the top level must be an object (a table)")
    return data


def _mapping(path: Path, where: str, value: Any, allowed: set[str] | None = None) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise ConfigError(f"{path}: {where} must be an object, got {type(value).__name__}")
    if allowed is not None:
        unknown = sorted(set(value) - allowed)
        if unknown:
            raise ConfigError(f"{path}: {where}: unknown key(s) {unknown}; allowed: {sorted(allowed)}")
    return value


def _number(path: Path, where: str, value: Any, positive: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(f"{path}: {where} must be a finite number, got {value!r}")
    if positive and value <= 0:
        raise ConfigError(f"{path}: {where} must be > 0, got {value!r}")
    return float(value)


def _constant(path: Path, where: str, value: Any) -> Any:
    """A constant input as the file gives it: a number (an integer stays exact), a Boolean, a
    text (String; Binary as hexadecimal), or a list (an array input, nested by its dimensions);
    the input's type is checked when it is set."""
    if isinstance(value, list):
        return np.asarray(value, dtype=object)
    if isinstance(value, (bool, str)) or (isinstance(value, int) and not isinstance(value, bool)):
        return value
    return _number(path, where, value)


def load_ssp(path: str | os.PathLike[str], step: float | None = None, *, stop_time: float | None = None,
             parameter_set: str | os.PathLike[str] | None = None,
             parameters: Mapping[str, Any] | None = None) -> CosimConfig:
    """Read an SSP archive (``.ssp``) or SSD file (``.ssd``) as a configuration
    (:func:`duffid.cosim.ssp.read_ssp`): its default experiment and duffid's run annotation.

    Parameters
    ----------
    path : str or os.PathLike
        The file.
    step : float, optional
        The communication step, overriding the file's annotation (required when the file
        has none).
    stop_time : float, optional
        Overrides the default experiment's stop time.
    parameter_set : str or os.PathLike, optional
        An ``.ssv`` file of values (``component.parameter``), with priority over the SSD's
        bindings (a campaign's parameter set).
    parameters : mapping, optional
        ``"component.parameter"`` -> value, with priority over everything (a campaign's
        overrides).

    Raises
    ------
    SspError
        What duffid cannot read or honour, no stop time, no step.
    """
    path = Path(path)
    run = read_ssp(path, System(), parameter_set=parameter_set, parameters=parameters)
    if step is not None:
        run.step = _number(path, "--step", step, positive=True)
    if stop_time is not None:
        run.stop_time = _number(path, "stop_time", stop_time)
    if run.step is None:
        raise SspError(f"{path}: no communication step: the SSD has no duffid annotation "
                       f"(<ssc:Annotation type=\"{ANNOTATION}\"> in <DefaultExperiment>); give one (duffid cosim "
                       "--step)")
    if run.stop_time is None:
        raise SspError(f"{path}: no stop time: the SSD has no <DefaultExperiment stopTime=...>")
    container = {"inputs": run.interface["inputs"]}
    if run.interface["outputs"]:
        container["outputs"] = run.interface["outputs"]
    return CosimConfig(path=path, system=run.system, stop_time=run.stop_time, step=run.step,
                       start_time=run.start_time, ordering=run.ordering, order=run.order, warnings=run.warnings,
                       container=container)


def load_config(path: str | os.PathLike[str], step: float | None = None) -> CosimConfig:
    """Read a JSON (``.json``) or TOML (``.toml``) configuration and build its system.

    An SSP archive (``.ssp``) or SSD file (``.ssd``) is refused: read it with
    :func:`load_ssp`, which takes its own overrides (a caller that edits a configuration's
    parameters must not have them dropped on an SSP).

    Parameters
    ----------
    path : str or os.PathLike
        The file.
    step : float, optional
        The communication step, overriding the file's.

    Raises
    ------
    ConfigError
        Unreadable file, unknown or missing entries, wrong types (the message names the
        file and the entry).
    WiringError
        Wiring the system failed (unknown FMU variable, type mismatch, ...): the message
        is prefixed with the file and the entry.
    """
    path = Path(path)
    if path.suffix.lower() in SSP_SUFFIXES:
        raise ConfigError(f"{path}: an SSP file, not a JSON or TOML configuration: read it with "
                          "duffid.cosim.config.load_ssp (duffid cosim does), which applies parameter sets and overrides")
    data = _read(path)
    _mapping(path, "the top level", data, _TOP)
    base = path.parent
    system = System()

    def wired(where: str, call: Any, *args: Any, **kwargs: Any) -> None:
        try:
            call(*args, **kwargs)
        except WiringError as exc:
            raise WiringError(f"{path}: {where}: {exc}") from None

    components = _mapping(path, "components", data.get("components"))
    if not components:
        raise ConfigError(f"{path}: components: at least one component is needed")
    for name, spec in components.items():
        spec = _mapping(path, f"components.{name}", spec, _COMPONENT)
        if not isinstance(spec.get("fmu"), str):
            raise ConfigError(f"{path}: components.{name}.fmu must be the FMU's file name")
        parameters = _mapping(path, f"components.{name}.parameters", spec.get("parameters", {}))
        wired(f"components.{name}", system.add, name, base / spec["fmu"], parameters=parameters)
    connections = data.get("connections", [])
    if not isinstance(connections, list):
        raise ConfigError(f"{path}: connections must be a list of [source, target] pairs")
    for i, item in enumerate(connections):
        where = f"connections[{i}]"
        if not (isinstance(item, list) and len(item) in (2, 3) and all(isinstance(s, str) for s in item[:2])):
            raise ConfigError(f"{path}: {where} must be [\"comp.output\", \"comp.input\"] with optional "
                              f"options, got {item!r}")
        options = _mapping(path, f"{where} options", item[2], {"check_units"}) if len(item) == 3 else {}
        wired(where, system.connect, item[0], item[1], **options)
    for target, value in _mapping(path, "inputs", data.get("inputs", {})).items():
        wired(f"inputs.{target}", system.set_input, target, _constant(path, f"inputs.{target}", value))
    if "input_csv" in data:
        csv_spec = _mapping(path, "input_csv", data["input_csv"], {"file", "columns", "interpolation"})
        if not isinstance(csv_spec.get("file"), str):
            raise ConfigError(f"{path}: input_csv.file must be the CSV file's name")
        columns = _mapping(path, "input_csv.columns", csv_spec.get("columns"))
        interpolation = _mapping(path, "input_csv.interpolation", csv_spec.get("interpolation", {}))
        wired("input_csv", system.inputs_from_csv, base / csv_spec["file"], columns, interpolation)
    run = _mapping(path, "run", data.get("run"), _RUN)
    for key in ("stop_time",) if step is not None else ("stop_time", "step"):
        if key not in run:
            raise ConfigError(f"{path}: run.{key} is missing")
    ordering = run.get("ordering", "jacobi")
    if ordering not in ORDERINGS:
        raise ConfigError(f"{path}: run.ordering must be one of {list(ORDERINGS)}, got {ordering!r}")
    loop = run.get("loop", "auto")
    if loop not in LOOP_MODES:
        raise ConfigError(f"{path}: run.loop must be one of {list(LOOP_MODES)}, got {loop!r}")
    for key in ("order", "record"):
        if key in run and not (isinstance(run[key], list) and all(isinstance(s, str) for s in run[key])):
            raise ConfigError(f"{path}: run.{key} must be a list of names")
    container = _mapping(path, "container", data.get("container", {}), _CONTAINER)
    return CosimConfig(path=path, system=system, stop_time=_number(path, "run.stop_time", run["stop_time"]),
                       step=_number(path, "--step" if step is not None else "run.step",
                                    run["step"] if step is None else step, positive=True),
                       start_time=_number(path, "run.start_time", run.get("start_time", 0.0)),
                       ordering=ordering, order=run.get("order"), record=run.get("record"),
                       container=container, loop=loop)
