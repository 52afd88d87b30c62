"""The plants a campaign simulates and the columns every results row has: what parsing a
spec needs, without the execution path (:mod:`duffid.campaign.tasks`)."""
from __future__ import annotations

import re
from typing import Any, Mapping

from ..errors import InputError
from ..models.chain import Chain
from ..models.equation_model import EquationModel
from ..models.registry import PLANT_NAMES, REGISTRY

__all__ = ["plant_model", "equation_columns", "RESERVED", "PLANTS"]

#: Columns every row has (a factor may not use these names).
RESERVED = ("task", "kind", "status", "error", "seconds", "worker")
#: Plants a task can simulate (``model`` key) -> their class (``plant.<p>``: its parameters): the
#: registry's models of fixed structure.
PLANTS = {name: REGISTRY[name].cls for name in PLANT_NAMES}


def equation_columns(text: str) -> tuple[str, ...]:
    """The record columns an equation names: ``t``, its forces and its displacements
    (``x``, ``f`` or ``x1 ..``, ``f1 ..``), in the order of a record."""
    names = set(re.findall(r"\b([xf]\d*)\b", text))
    forces = sorted((n for n in names if n.startswith("f")), key=lambda n: (len(n), n))
    displacements = sorted((n for n in names if n.startswith("x")), key=lambda n: (len(n), n))
    return ("t", *forces, *displacements)


def plant_model(settings: Mapping[str, Any]) -> Chain | EquationModel:
    """The plant a task simulates: ``model`` (or ``equation``) with its ``plant.<p>`` parameter
    values (an equation's parameters not given are 0).

    Raises
    ------
    InputError
        An unknown model or parameter (the message lists the model's parameters), both or
        neither of ``model`` and ``equation``.
    """
    values = {key[len("plant."):]: float(v) for key, v in settings.items() if key.startswith("plant.")}
    if "equation" in settings:
        if "model" in settings:
            raise InputError("give model or equation, not both")
        text = settings["equation"]
        model = EquationModel(text, equation_columns(text))
        unknown = sorted(set(values) - set(model.parameters))
        if unknown:
            raise InputError(f"plant.{unknown[0]}: the equation has no parameter {unknown[0]!r}; "
                             f"its parameters: {', '.join(model.parameters)}")
        return EquationModel(text, equation_columns(text), values=values)
    name = settings.get("model")
    if name is None:
        raise InputError("model or equation: missing (the plant to simulate and identify)")
    cls = PLANTS.get(name)
    if cls is None:
        raise InputError(f"model must be one of {', '.join(PLANTS)}, got {name!r}")
    known = cls().parameters
    unknown = sorted(set(values) - set(known))
    if unknown:
        raise InputError(f"plant.{unknown[0]}: {name} has no parameter {unknown[0]!r}; "
                         f"its parameters: {', '.join(known)}")
    return cls(**values)
