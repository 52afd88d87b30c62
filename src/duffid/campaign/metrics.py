"""Scoring functions of co-simulation runs, named in a campaign spec's ``[metrics]``.

Each is called as ``function(result, **arguments)`` with the run's
:class:`~duffid.cosim.elements.Result` and the entry's other keys, and returns a float (or
a mapping of names to floats, each becoming a column ``<metric>.<name>``). A user's own
function is named ``"package.module:function"`` and follows the same rule.
"""
from __future__ import annotations

import importlib
from typing import Any, Callable

import numpy as np

from ..errors import ConfigError, InputError

__all__ = ["METRICS", "final", "peak", "rms", "mean", "resolve_metric"]


def _window(result: Any, variable: str, t_from: float) -> np.ndarray:
    values = np.asarray(result[variable], dtype=float)
    mask = result.time >= t_from - 1e-12
    if not mask.any():
        raise InputError(f"{variable}: no samples after t = {t_from:g} s (the run ends at {result.time[-1]:g} s)")
    return values[mask]


def final(result: Any, variable: str) -> float:
    """The variable's last recorded value."""
    return float(result[variable][-1])


def peak(result: Any, variable: str, t_from: float = 0.0) -> float:
    """The largest absolute value from ``t_from`` on."""
    return float(np.max(np.abs(_window(result, variable, t_from))))


def rms(result: Any, variable: str, reference: float = 0.0, t_from: float = 0.0) -> float:
    """The RMS of ``variable - reference`` from ``t_from`` on (e.g. a tracking error)."""
    return float(np.sqrt(np.mean((_window(result, variable, t_from) - reference) ** 2)))


def mean(result: Any, variable: str, t_from: float = 0.0) -> float:
    """The mean from ``t_from`` on."""
    return float(np.mean(_window(result, variable, t_from)))


#: Built-in metric functions by name.
METRICS: dict[str, Callable[..., Any]] = {"final": final, "peak": peak, "rms": rms, "mean": mean}


def resolve_metric(name: str) -> Callable[..., Any]:
    """The scoring function a ``[metrics]`` entry names: a :data:`~duffid.campaign.metrics.METRICS`
    name or ``"package.module:function"``.

    Raises
    ------
    ConfigError
        The module or function does not exist (the message says which).
    """
    if name in METRICS:
        return METRICS[name]
    module, _, function = name.partition(":")
    if not module or not function:
        raise ConfigError(f"metric function {name!r} is neither one of {', '.join(METRICS)} nor "
                          "\"package.module:function\"")
    try:
        found = getattr(importlib.import_module(module), function)
    except ImportError as exc:
        raise ConfigError(f"metric function {name!r}: cannot import {module}: {exc}") from None
    except AttributeError:
        raise ConfigError(f"metric function {name!r}: {module} has no {function!r}") from None
    if not callable(found):
        raise ConfigError(f"metric function {name!r} is not callable")
    return found
