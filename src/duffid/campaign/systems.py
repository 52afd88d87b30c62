"""Co-simulation systems of a campaign: a ``duffid cosim`` file with parameter overrides,
and the per-process folder where workers keep their files.

Each worker process has one folder (:func:`worker_folder`): the configurations with
overrides are written there, and the worker's co-simulation runs extract each FMU once below
it and reuse their instances (:mod:`duffid.cosim.instances`, made active by
:class:`duffid.campaign.runner.WorkerFolder`). The folder is removed when the worker closes
or the process exits; the folders of killed processes are removed by the next worker on the
host.
"""
from __future__ import annotations

import atexit
import hashlib
import json
import os
import shutil
import tempfile
import tomllib
from pathlib import Path
from typing import Any, Mapping

from ..cosim.config import CosimConfig, load_config, load_ssp
from ..errors import ConfigError, WiringError

__all__ = ["worker_folder", "remove_worker_folder", "configured_system"]

_PREFIX = "duffid-campaign-"
_FOLDER: dict[str, Any] = {"path": None, "tempdir": None}
#: Configurations loaded in this process (model descriptions read once per FMU file version).
_LOADED: dict[tuple[Any, ...], CosimConfig] = {}


def worker_folder(*, temporary_files: bool = False) -> Path:
    """This process's folder, created on first use.

    Parameters
    ----------
    temporary_files : bool
        Also make it the process's folder for temporary files (:data:`tempfile.tempdir`),
        where the co-simulation runner extracts the FMUs of each run (a worker process).
    """
    if _FOLDER["path"] is None or not Path(_FOLDER["path"]).is_dir():
        _remove_stale()
        _FOLDER["path"] = tempfile.mkdtemp(prefix=f"{_PREFIX}{os.getpid()}-")
        atexit.register(remove_worker_folder)
    if temporary_files and tempfile.tempdir != _FOLDER["path"]:
        _FOLDER["tempdir"] = tempfile.tempdir
        tempfile.tempdir = _FOLDER["path"]
    return Path(_FOLDER["path"])


def _remove_stale() -> None:
    """Remove the folders of this host's worker processes that no longer exist (killed, so
    they could not clean up)."""
    for folder in Path(tempfile.gettempdir()).glob(f"{_PREFIX}*-*"):
        pid = folder.name[len(_PREFIX):].split("-", 1)[0]
        if not pid.isdigit():
            continue
        try:
            os.kill(int(pid), 0)
        except ProcessLookupError:
            shutil.rmtree(folder, ignore_errors=True)
        except OSError:  # another user's process: alive
            pass


def remove_worker_folder() -> None:
    """Remove this process's folder and everything in it (the extracted FMUs)."""
    path = _FOLDER["path"]
    if path is not None:
        if tempfile.tempdir == path:
            tempfile.tempdir = _FOLDER["tempdir"]
        shutil.rmtree(path, ignore_errors=True)
        _FOLDER["path"] = None


def _absolute(base: Path, data: dict[str, Any]) -> dict[str, Any]:
    data = json.loads(json.dumps(data))  # a deep copy, and only what JSON can hold
    for spec in data.get("components", {}).values():
        if isinstance(spec, dict) and isinstance(spec.get("fmu"), str):
            spec["fmu"] = str((base / spec["fmu"]).resolve())
    csv = data.get("input_csv")
    if isinstance(csv, dict) and isinstance(csv.get("file"), str):
        csv["file"] = str((base / csv["file"]).resolve())
    return data


def configured_system(system: str | os.PathLike[str], overrides: Mapping[str, Any]) -> CosimConfig:
    """The ``duffid cosim`` configuration ``system`` with overrides.

    Parameters
    ----------
    system : str or os.PathLike
        A JSON or TOML configuration (:func:`duffid.cosim.config.load_config`), or an SSP
        archive / SSD file (:func:`duffid.cosim.config.load_ssp`).
    overrides : mapping
        ``"component.parameter"`` -> value (FMU parameters, merged into the file's
        ``parameters``; an SSP's bindings are overridden), ``"stop_time"`` and ``"step"``
        (the file's ``run`` section, an SSP's default experiment and annotation), and for an
        SSP ``"parameter_set"`` (an ``.ssv`` file of values, below the overrides).

    Raises
    ------
    ConfigError, WiringError
        As :func:`~duffid.cosim.config.load_config`, naming the file and the entry (an
        unknown component or parameter).
    """
    path = Path(system)
    if path.suffix.lower() in (".ssp", ".ssd"):
        return _configured_ssp(path, overrides)
    if "parameter_set" in overrides:
        raise ConfigError(f"{path}: parameter_set (an .ssv file) applies to an SSP system, not to a "
                          f"{path.suffix or 'plain'} configuration: give the values as overrides")
    try:
        raw = path.read_bytes()
        data = tomllib.loads(raw.decode()) if path.suffix.lower() == ".toml" else json.loads(raw)
    except (tomllib.TOMLDecodeError, json.JSONDecodeError, UnicodeDecodeError):
        return load_config(path)  # its own message
    if not isinstance(data, dict):
        return load_config(path)
    data = _absolute(path.parent, data)
    components = data.get("components", {}) if isinstance(data.get("components"), dict) else {}
    for key, value in overrides.items():
        if key in ("stop_time", "step"):
            data.setdefault("run", {})[key] = value
            continue
        comp, _, parameter = key.partition(".")
        if comp not in components or not isinstance(components[comp], dict):
            raise ConfigError(f"{path}: no component {comp!r} for the override {key} (components: "
                              f"{', '.join(components)})")
        components[comp].setdefault("parameters", {})[parameter] = value
    text = json.dumps(data, sort_keys=True)
    digest = hashlib.sha256(raw + text.encode()).hexdigest()[:16]
    derived = worker_folder() / f"{path.stem}-{digest}.json"
    if not derived.is_file():
        temporary = derived.with_suffix(".tmp")
        temporary.write_text(text)
        temporary.replace(derived)
    key = (str(derived), tuple(_stamp(c.get("fmu")) for c in components.values() if isinstance(c, dict)))
    if key not in _LOADED:
        try:
            _LOADED[key] = load_config(derived)
        except (ConfigError, WiringError) as exc:
            raise type(exc)(str(exc).replace(str(derived), f"{path} (with {dict(overrides)})")) from None
    return _LOADED[key]


def _configured_ssp(path: Path, overrides: Mapping[str, Any]) -> CosimConfig:
    """An SSP system with a campaign's overrides: run settings, a parameter set, values."""
    values = {k: v for k, v in overrides.items() if k not in ("stop_time", "step", "parameter_set")}
    try:
        return load_ssp(path, overrides.get("step"), stop_time=overrides.get("stop_time"),
                        parameter_set=overrides.get("parameter_set"), parameters=values or None)
    except (ConfigError, WiringError) as exc:
        raise type(exc)(f"{exc} (with {dict(overrides)})") from None


def _stamp(fmu: Any) -> tuple[Any, ...]:
    try:
        info = os.stat(fmu)
    except (OSError, TypeError):
        return (fmu,)
    return (fmu, info.st_size, info.st_mtime_ns)
