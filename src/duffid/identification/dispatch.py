"""Engine dispatch: which implementation runs an estimator on a record (the C core where it
runs the model, else Python), and the robust window from the data."""
from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from ..data.record import Record
from ..errors import BuildError, InputError
from ..models.chain import Chain, Duffing1, Duffing2
from ..models.registry import IdentifiableModel
from .batch import estimate
from .c_core import CIdentifier
from .engine import Identification
from .options import ENGINES, ONLINE_METHODS

__all__ = [
    "run_estimator",
    "data_window",
]


def run_estimator(record: Record, model: Chain, method: str = "robust", *, engine: str = "auto",
                  **options: Any) -> Identification:
    """The estimator's run over ``record`` (unchecked), on the C core or in Python.

    The C core (:class:`~duffid.identification.c_core.CIdentifier`, one batch call) gives the answers
    of the Python identifier to rounding, many times faster; ``engine="auto"`` uses it for
    every model with the online methods when a C compiler is available, and Python otherwise
    (or for a model beyond the C core's limits): :class:`~duffid.models.chain.Duffing1`,
    :class:`~duffid.models.chain.Duffing2` and chains of their structure on the core's own
    description, any other chain or equation model on its generated description (the
    generic engine; one cached library per model, compiled on first use).
    """
    if engine not in ENGINES:
        raise InputError(f"engine must be one of {', '.join(ENGINES)}, got {engine!r}")
    if engine != "python" and method in ONLINE_METHODS:
        core = _c_model(model)
        try:
            if core is None:
                raise InputError(f"the C core does not run the model {model.name}")
            identifier = CIdentifier(core, record.dt, method, **options)
        except (BuildError, ValueError, OSError):
            # no compiler (BuildError), no C sources (AssetError, an OSError) (an installed wheel without them), or a model or
            # option the C core does not take: the Python identifier gives the same answers
            if engine == "c":
                raise
        else:
            with identifier:
                result = identifier.identify_record(record)
            return result if core is model else _renamed(result, model)
    elif engine == "c":
        raise InputError(f"the C core runs the methods {', '.join(ONLINE_METHODS)}, not {method!r}")
    return estimate(record, model, method, **options)

def data_window(record: Record, frequency: float, periods: float) -> float:
    """Window [s] of the robust method for a record whose main frequency is ``frequency`` Hz:
    the whole record when it spans at most ``2 * periods`` periods (integrated from its
    first sample, as the paper does), else ``periods`` periods."""
    if record.duration * frequency <= 2.0 * periods:
        return float(record.duration + record.dt)
    return float(periods / frequency)

def _c_model(model: Any) -> Any:
    """The model the C core runs for ``model``: the core's own Duffing1 or Duffing2 with
    ``model``'s values for those and for chains of their structure; ``model`` itself (its
    generated description) for any other model with equations; None otherwise."""

    if isinstance(model, (Duffing1, Duffing2)):
        return model
    if isinstance(model, Chain):
        structure = (model.n_dof, model.coulomb is None, tuple(model.forced), tuple(model.orders or ()))
        if structure in ((1, True, (0,), (1, 3)), (2, True, (0,), (1, 3))):
            core = Duffing1 if model.n_dof == 1 else Duffing2
            return _chain_like(core(offset=model.offset), model.canonical_parameters())
    return model if isinstance(model, IdentifiableModel) else None

def _chain_like(template: Chain, canonical: Mapping[str, float]) -> Chain:
    try:
        return template.with_parameters(**{k: v for k, v in canonical.items() if not k.startswith("c")})
    except ValueError:
        return template

def _renamed(result: Identification, model: Chain) -> Identification:
    """A C-core result (Duffing1/Duffing2 names) under ``model``'s public names."""
    core = _c_model(model)
    assert core is not None

    def public(values: Mapping[str, float]) -> dict[str, float]:
        canonical = {core.canonical_name(k): float(v) for k, v in values.items()}
        return model.from_canonical(canonical)

    names = list(result.history)
    rows = [public({k: result.history[k][i] for k in names}) for i in range(len(result.t))]
    result.history = {k: np.array([row[k] for row in rows]) for k in model.parameters}
    result.parameters = public(result.parameters)
    result.estimates = public(result.estimates)
    by_canonical = {core.canonical_name(k): v for k, v in result.online_status.items()}
    result.online_status = {k: by_canonical[model.canonical_name(k)] for k in model.parameters}
    result.model = model.name
    return result
