"""Campaign specs: a TOML file read into plain, picklable task descriptions.

A spec names one kind of task, the settings every task shares, the factors that vary
(a full factorial grid) and, for Monte-Carlo studies, the noise seeds::

    [campaign]
    kind = "identification"          # or "nonlinearity", "cosim"
    name = "case B"                  # optional, for tables and plots
    seeds = 50                       # 0 .. 49, or a list of seeds; optional

    [task]                           # shared by every task
    model = "duffing1"
    excitation = "step:10"
    t_end = 2.0
    dt = 1e-3
    snr_db = 40

    [factors]                        # each list is one factor
    method = ["paper", "robust"]
    amplitude = { from = 0.1, to = 6.0, count = 13 }   # evenly spaced values
    "plant.kp" = [-1.237e6, 0.0]     # a model parameter

    [metrics]                        # cosim only: name -> scoring function and its arguments
    x_final = { function = "final", variable = "plant.x" }

Keys of ``[task]`` and ``[factors]`` per kind (:data:`KEYS`); nested tables
(``plant = {kp = 0.0}``) and dotted keys (``"plant.kp" = 0.0``) are the same thing.

- ``identification``: ``model`` (``duffing1``, ``duffing2``, ``circuit``) or ``equation`` (a
  text in the syntax of ``duffid identify --equation``, e.g. the equation ``duffid discover``
  chose: simulated and identified as written, its parameters 0 unless given), ``plant.<p>`` (the
  true parameters of the simulated plant, the model's nominal values otherwise),
  ``excitation`` (a signal spec, :func:`duffid.data.signals.from_spec`), ``t_end``, ``dt``,
  ``snr_db`` (measurement noise; absent: none), ``quantise`` (the encoder, default true),
  or ``record`` (a measured record instead of a simulation, in any format ``Record.read`` reads
  by its extension: CSV, MATLAB, TDMS, UFF, HDF5, WAV; the truth is then ``plant.<p>``);
  ``method``, ``options.<o>`` (method options), ``check`` (default true: the checked
  :func:`duffid.identify` with trust statuses; false: the bare estimator), ``engine``.
- ``nonlinearity``: ``model``, ``plant.<p>``, ``amplitude`` [N], ``rate`` [Hz/s], ``f_max``
  [Hz], ``dt``, ``ring_down`` [s], ``band`` ([f1, f2] Hz), ``n_modes``
  (:func:`duffid.analysis.nonlinearity.sweep_record` and ``analyse``).
- ``cosim``: ``system`` (a ``duffid cosim`` configuration file), ``stop_time``, ``step``,
  and ``<component>.<parameter>`` overrides of the FMUs' parameters; the run is scored by
  the ``[metrics]`` functions (:mod:`duffid.campaign.metrics` names, or
  ``"package.module:function"``), each called as ``function(result, **arguments)``.

Relative file names are taken from the spec's folder. Every error names the file and the
key (:class:`~duffid.errors.ConfigError`).
"""
from __future__ import annotations

import itertools
import math
import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from ..data.signals import from_spec
from ..errors import ConfigError, DuffidError
from ..identification.engine import METHODS
from ..identification.options import ENGINES, ONLINE_METHODS, check_options
from .metrics import resolve_metric
from .systems import configured_system
from ..models.equation_model import EquationModel
from .plants import PLANTS, RESERVED, equation_columns, plant_model

__all__ = ["KINDS", "KEYS", "MODELS", "Task", "CampaignSpec", "load_spec"]

#: The kinds of task.
KINDS = ("identification", "nonlinearity", "cosim")
#: Models a simulated plant can be (``model`` key).
MODELS = tuple(PLANTS)
#: Settings per kind: key -> what its value must be. ``plant.*``, ``options.*`` and (cosim)
#: ``<component>.<parameter>`` keys are checked separately.
KEYS: dict[str, dict[str, str]] = {
    "identification": {"model": "model name", "equation": "equation", "excitation": "signal spec", "t_end": "positive number",
                       "dt": "positive number", "snr_db": "number", "quantise": "boolean",
                       "record": "record file", "method": "method", "check": "boolean", "engine": "engine"},
    "nonlinearity": {"model": "model name", "amplitude": "positive number", "rate": "positive number",
                     "f_max": "positive number", "dt": "positive number", "ring_down": "positive number",
                     "band": "band", "n_modes": "positive integer"},
    "cosim": {"system": "cosim file", "stop_time": "number", "step": "positive number",
              "parameter_set": "SSV file"},
}
_REQUIRED = {"identification": (), "nonlinearity": ("model", "amplitude"), "cosim": ("system",)}
_PREFIXED = {"identification": ("plant", "options"), "nonlinearity": ("plant",), "cosim": ()}
_TOP = {"campaign", "task", "factors", "metrics"}
_RANGE = ("from", "to", "count")


@dataclass(frozen=True)
class Task:
    """One run of a campaign: a plain, picklable description.

    Attributes
    ----------
    id : str
        Unique in the campaign and stable across runs of the same spec (``--resume``):
        the factor values and the seed, e.g. ``"method=paper seed=3"``.
    kind : str
        One of :data:`KINDS`.
    settings : dict
        Flat settings (dotted keys); file names absolute.
    factors : dict
        The values of the factors (and ``seed``) that make this task, for the results table.
    metrics : dict
        ``cosim``: metric name -> ``{"function": ..., arguments...}``.
    """

    id: str
    kind: str
    settings: dict[str, Any]
    factors: dict[str, Any]
    metrics: dict[str, dict[str, Any]] = field(default_factory=dict)


@dataclass(frozen=True)
class CampaignSpec:
    """A parsed spec (see the module documentation).

    Attributes
    ----------
    path : Path
        The spec file.
    name : str
        Title of tables and plots.
    kind : str
        One of :data:`KINDS`.
    factors : dict
        Factor name -> its values, in the file's order (``seed`` last when seeds are given).
    tasks : list of Task
        The full factorial grid times the seeds.
    """

    path: Path
    name: str
    kind: str
    factors: dict[str, list[Any]]
    tasks: list[Task]


def _flatten(path: Path, section: str, table: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in table.items():
        full = f"{prefix}{key}"
        if isinstance(value, dict) and section == "factors" and set(value) == set(_RANGE):
            out[full] = _range(path, f"factors.{full}", value)
        elif isinstance(value, dict):
            out.update(_flatten(path, section, value, full + "."))
        else:
            out[full] = value
    return out


def _range(path: Path, where: str, value: Mapping[str, Any]) -> list[float]:
    """``{from = a, to = b, count = n}``: n evenly spaced values from a to b (numpy.linspace)."""
    count = value["count"]
    if not (_is_number(value["from"]) and _is_number(value["to"]) and isinstance(count, int)
            and not isinstance(count, bool) and count >= 1):
        raise ConfigError(f"{path}: {where}: a range is {{from = <number>, to = <number>, count = <integer "
                          f">= 1>}}, got {dict(value)!r}")
    return [float(v) for v in np.linspace(value["from"], value["to"], count)]


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _check_value(path: Path, where: str, kind: str, key: str, value: Any) -> Any:
    """The value of one setting, checked (file names made absolute)."""
    def bad(expected: str) -> ConfigError:
        return ConfigError(f"{path}: {where}: must be {expected}, got {value!r}")

    head = key.split(".", 1)[0]
    if "." in key and (head in _PREFIXED[kind] or kind == "cosim"):
        if kind == "cosim" or head == "plant":
            if not (_is_number(value) or isinstance(value, (bool, str))):
                raise bad("a number, boolean or string")
            if head == "plant":
                if not _is_number(value):
                    raise bad("a finite number")
                return float(value)
        return value
    check = KEYS[kind].get(key)
    if check is None:
        allowed = sorted(KEYS[kind]) + [f"{p}.<name>" for p in _PREFIXED[kind]] + (
            ["<component>.<parameter>"] if kind == "cosim" else [])
        raise ConfigError(f"{path}: {where}: unknown key for {kind} tasks; allowed: {', '.join(allowed)}")
    if check in ("positive number", "number"):
        if not _is_number(value) or (check == "positive number" and value <= 0):
            raise bad(f"a finite{' positive' if check == 'positive number' else ''} number")
        return float(value)
    if check == "positive integer":
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise bad("a positive integer")
        return value
    if check == "boolean":
        if not isinstance(value, bool):
            raise bad("true or false")
        return value
    if check == "model name":
        if value not in MODELS:
            raise bad(f"one of {', '.join(MODELS)}")
        return value
    if check == "equation":
        if not isinstance(value, str):
            raise bad('an equation in the syntax of duffid identify --equation, e.g. "m*der(x,2) + k*x = f"')
        try:
            EquationModel(value, equation_columns(value))
        except DuffidError as exc:
            raise bad(f"an equation duffid can identify ({exc})") from None
        return value
    if check == "method":
        if value not in METHODS:
            raise bad(f"one of {', '.join(METHODS)}")
        return value
    if check == "engine":
        if value not in ENGINES:
            raise bad(f"one of {', '.join(ENGINES)}")
        return value
    if check == "signal spec":
        try:
            from_spec(value)
        except (DuffidError, ValueError, TypeError) as exc:
            raise ConfigError(f"{path}: {where}: {exc}") from None
        return value
    if check == "band":
        if not (isinstance(value, list) and len(value) == 2 and all(_is_number(v) for v in value)
                and 0 <= value[0] < value[1]):
            raise bad("[f1, f2] with 0 <= f1 < f2")
        return (float(value[0]), float(value[1]))
    # a file
    if not isinstance(value, str):
        raise bad("a file name")
    full = (path.parent / value).resolve()
    if not full.is_file():
        raise ConfigError(f"{path}: {where}: no such file {full}")
    return str(full)


def _seeds(path: Path, value: Any) -> list[int]:
    if isinstance(value, int) and not isinstance(value, bool) and value >= 1:
        return list(range(value))
    if (isinstance(value, list) and value and all(isinstance(s, int) and not isinstance(s, bool) and s >= 0
                                                  for s in value) and len(set(value)) == len(value)):
        return list(value)
    raise ConfigError(f"{path}: campaign.seeds: must be a count (>= 1) or a list of distinct seeds >= 0, "
                      f"got {value!r}")


def _label(value: Any) -> str:
    return repr(value) if isinstance(value, str) and (not value or " " in value or "=" in value) else (
        f"{value:g}" if isinstance(value, float) else str(value))


def _check_cosim(path: Path, settings: Mapping[str, Any], factors: Mapping[str, list[Any]]) -> None:
    """Load the system file with the fixed overrides and each factor's values, so that an
    unknown component or parameter is found before anything runs."""
    fixed = {k: v for k, v in settings.items() if k != "system"}
    variants = [{}] + [{key: value} for key, values in factors.items() for value in values]
    for variant in variants:
        try:
            configured_system(settings["system"], {**fixed, **variant})
        except DuffidError as exc:
            where = f"factors.\"{next(iter(variant))}\"" if variant else "task"
            raise ConfigError(f"{path}: {where}: {exc}") from None


def load_spec(path: str | os.PathLike[str], *, seeds: int | None = None) -> CampaignSpec:
    """Read a campaign spec (TOML) into its tasks.

    Parameters
    ----------
    path : str or os.PathLike
        The spec file.
    seeds : int, optional
        Run seeds ``0 .. seeds - 1`` instead of the file's ``campaign.seeds``.

    Returns
    -------
    CampaignSpec

    Raises
    ------
    ConfigError
        Unreadable file, unknown kind or key, wrong value (the message names the file and
        the key), a factor with no values, a duplicated setting.
    """
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"{path}: no such file")
    try:
        with path.open("rb") as handle:
            data = tomllib.load(handle)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None
    unknown = sorted(set(data) - _TOP)
    if unknown:
        raise ConfigError(f"{path}: unknown table(s) {unknown}; allowed: {sorted(_TOP)}")
    for section in _TOP & set(data):
        if not isinstance(data[section], dict):
            raise ConfigError(f"{path}: {section} must be a table")
    head = data.get("campaign", {})
    extra = sorted(set(head) - {"kind", "name", "seeds"})
    if extra:
        raise ConfigError(f"{path}: campaign: unknown key(s) {extra}; allowed: kind, name, seeds")
    kind = head.get("kind")
    if kind not in KINDS:
        raise ConfigError(f"{path}: campaign.kind: must be one of {', '.join(KINDS)}, got {kind!r}")
    name = head.get("name", path.stem)
    if not isinstance(name, str):
        raise ConfigError(f"{path}: campaign.name: must be a string, got {name!r}")
    seed_list = _seeds(path, seeds) if seeds is not None else (
        _seeds(path, head["seeds"]) if "seeds" in head else None)

    settings = {key: _check_value(path, f"task.{key}", kind, key, value)
                for key, value in _flatten(path, "task", data.get("task", {})).items()}
    factors: dict[str, list[Any]] = {}
    for key, values in _flatten(path, "factors", data.get("factors", {})).items():
        where = f"factors.{key}" if "." not in key else f"factors.\"{key}\""
        if not isinstance(values, list) or not values:
            raise ConfigError(f"{path}: {where}: must be a non-empty list of values, got {values!r}")
        if key in settings:
            raise ConfigError(f"{path}: {where}: also set in [task]; a key is either fixed or a factor")
        if key == "seed":
            raise ConfigError(f"{path}: {where}: seeds are campaign.seeds")
        if key in RESERVED:
            raise ConfigError(f"{path}: {where}: {key!r} names a column of the results; choose another name")
        checked = [_check_value(path, f"{where}[{i}]", kind, key, v) for i, v in enumerate(values)]
        if len(set(map(repr, checked))) != len(checked):
            raise ConfigError(f"{path}: {where}: a value is repeated")
        factors[key] = checked
    for key in _REQUIRED[kind]:
        if key not in settings and key not in factors:
            raise ConfigError(f"{path}: task.{key}: missing (needed by {kind} tasks)")
    if kind == "identification":
        given = [k for k in ("model", "equation") if k in settings or k in factors]
        if len(given) != 1:
            raise ConfigError(f"{path}: task: give the plant as model (a name) or equation (a text), "
                              + ("not both" if given else "neither is there"))
    if kind == "identification" and "record" in settings and ("excitation" in settings or "excitation" in factors):
        raise ConfigError(f"{path}: task.record: a record is read, not simulated: drop task.excitation")
    if kind == "identification" and "record" not in settings and "record" not in factors:
        for key in ("excitation", "t_end", "dt"):
            if key not in settings and key not in factors:
                raise ConfigError(f"{path}: task.{key}: missing (needed to simulate the record)")

    if kind == "identification":
        methods = factors.get("method", [settings.get("method", "robust")])
        options = {k[len("options."):]: v for k, v in settings.items() if k.startswith("options.")}
        for method in methods:
            if method in ONLINE_METHODS:
                try:
                    check_options(method, options)
                except (DuffidError, ValueError, TypeError) as exc:
                    raise ConfigError(f"{path}: task.options: {exc}") from None
    if kind in ("identification", "nonlinearity"):
        first = {k: v[0] for k, v in factors.items()}
        for key in [k for k in factors if k.startswith("plant.")] or [None]:
            for value in factors[key] if key is not None else [None]:
                try:
                    plant_model({**settings, **first, **({key: value} if key else {})})
                except (DuffidError, ValueError, TypeError) as exc:
                    where = f"factors.\"{key}\"" if key else "task"
                    raise ConfigError(f"{path}: {where}: {exc}") from None

    metrics: dict[str, dict[str, Any]] = {}
    for mname, entry in data.get("metrics", {}).items():
        if kind != "cosim":
            raise ConfigError(f"{path}: metrics: only cosim tasks are scored by metric functions")
        if not isinstance(entry, dict) or not isinstance(entry.get("function"), str):
            raise ConfigError(f"{path}: metrics.{mname}: must be a table with function = \"...\" and its "
                              "arguments")
        try:
            resolve_metric(entry["function"])
        except ConfigError as exc:
            raise ConfigError(f"{path}: metrics.{mname}: {exc}") from None
        metrics[mname] = dict(entry)
    if kind == "cosim":
        if not metrics:
            raise ConfigError(f"{path}: metrics: a cosim campaign needs at least one metric")
        if "system" in factors:
            raise ConfigError(f"{path}: factors.system: one system file per campaign")
        _check_cosim(path, settings, factors)

    grid = list(itertools.product(*factors.values())) if factors else [()]
    tasks = []
    for combo in grid:
        values = dict(zip(factors, combo))
        for seed in (seed_list if seed_list is not None else [None]):
            chosen = dict(values) if seed is None else {**values, "seed": seed}
            ident = " ".join(f"{k}={_label(v)}" for k, v in chosen.items()) or "run"
            tasks.append(Task(ident, kind, {**settings, **chosen}, chosen, metrics))
    all_factors = dict(factors)
    if seed_list is not None:
        all_factors["seed"] = seed_list
    return CampaignSpec(path=path, name=name, kind=kind, factors=all_factors, tasks=tasks)
