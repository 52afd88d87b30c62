"""The interface every identifier implements, and the input checks they share.

An identifier takes a model structure and a sampling period, consumes one sample of
displacements and forces per :meth:`Identifier.update` and reports an
:class:`~duffid.identification.engine.Estimate`; :meth:`Identifier.identify_record` runs
a whole record. The online engine (:class:`~duffid.identification.engine.OnlineIdentifier`),
the C core (:class:`~duffid.identification.c_core.CIdentifier`) and the buffered methods
(:class:`~duffid.identification.buffered.BufferedIdentifier`) implement it.
"""
from __future__ import annotations

import math
import numbers
from abc import ABC, abstractmethod
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import InputError

if TYPE_CHECKING:
    from ..data.record import Record

__all__ = ["Identifier"]


class Identifier(ABC):
    """An identifier of a model's parameters from samples of displacements and forces.

    Parameters
    ----------
    model : object
        The model structure (a :class:`~duffid.models.chain.Chain`, or a regression
        structure with ``name``, ``n_dof`` and ``n_forces``).
    dt : float
        Sampling period [s], finite and positive.
    method : str
        The method's name.
    options : dict
        The method's options, already checked against its schema by the subclass.

    Raises
    ------
    InputError
        If ``dt`` is not a finite positive number.
    """

    def __init__(self, model: Any, dt: float, method: str, options: dict[str, Any]) -> None:
        if isinstance(dt, bool) or not isinstance(dt, numbers.Real) or not (math.isfinite(dt) and dt > 0):
            raise InputError(f"dt must be a positive number of seconds, got {dt!r}")
        self.model = model
        self.dt = float(dt)
        self.method = method
        self.options = options

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """Public parameter names, in output order."""
        return tuple(self.model.parameters)

    def checked_sample(self, x: Any, f: Any) -> tuple[np.ndarray, np.ndarray]:
        """``x`` and ``f`` as 1-D float arrays of the model's sizes.

        Raises
        ------
        InputError
            If their sizes do not fit the model (the message names both).
        """
        xa = np.atleast_1d(np.asarray(x, dtype=float))
        fa = np.atleast_1d(np.asarray(f, dtype=float))
        if xa.shape != (self.model.n_dof,) or fa.shape != (self.model.n_forces,):
            raise InputError(f"{self.model.name}: update needs {self.model.n_dof} displacement(s) and "
                             f"{self.model.n_forces} force(s), got {xa.size} and {fa.size}")
        return xa, fa

    @abstractmethod
    def reset(self) -> None:
        """Forget all samples (start a new identification)."""

    @abstractmethod
    def update(self, x: Any, f: Any) -> Any:
        """Consume one sample of displacements ``x`` and forces ``f``; return the estimate."""

    @abstractmethod
    def identify_record(self, record: Record) -> Any:
        """Run a whole record through the identifier (after :meth:`reset`); return the
        :class:`~duffid.identification.engine.Identification`."""
