"""The plants a campaign simulates and the columns every results row has: what parsing a
spec needs, without the execution path (:mod:`duffid.campaign.tasks`)."""
from __future__ import annotations

from typing import Any, Mapping

from ..errors import InputError
from ..models.chain import Chain
from ..models.registry import PLANT_NAMES, REGISTRY

__all__ = ["plant_model", "RESERVED", "PLANTS"]

#: Columns every row has (a factor may not use these names).
RESERVED = ("task", "kind", "status", "error", "seconds", "worker")
#: Plants a task can simulate (``model`` key) -> their class (``plant.<p>``: its parameters): the
#: registry's models of fixed structure.
PLANTS = {name: REGISTRY[name].cls for name in PLANT_NAMES}


def plant_model(settings: Mapping[str, Any]) -> Chain:
    """The plant a task simulates: ``model`` with its ``plant.<p>`` parameter values.

    Raises
    ------
    InputError
        An unknown model or parameter (the message lists the model's parameters).
    """
    name = settings["model"]
    cls = PLANTS.get(name)
    if cls is None:
        raise InputError(f"model must be one of {', '.join(PLANTS)}, got {name!r}")
    values = {key[len("plant."):]: float(v) for key, v in settings.items() if key.startswith("plant.")}
    known = cls().parameters
    unknown = sorted(set(values) - set(known))
    if unknown:
        raise InputError(f"plant.{unknown[0]}: {name} has no parameter {unknown[0]!r}; "
                         f"its parameters: {', '.join(known)}")
    return cls(**values)
