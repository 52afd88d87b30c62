"""Equations linear in their unknowns over channels computed from the samples: the
structure every identification method works on (a model is data: channels and terms)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

__all__ = ["LinearTerm", "Regression"]


@dataclass(frozen=True)
class LinearTerm:
    """``coef * unknown * d^order/dt^order g[channel]`` in one equation.

    ``unknown`` indexes the equation's unknowns; None marks a known term, which belongs to
    the right-hand side of ``A theta = D``.
    """

    unknown: int | None
    channel: int
    order: int
    coef: float = 1.0


@dataclass(frozen=True)
class Regression:
    """Equations linear in their unknowns, over channels computed from the samples.

    Attributes
    ----------
    name : str
        Model name for results ("duffing1", "equation", ...).
    unknowns : tuple of tuple of str
        Unknown names of each equation.
    terms : tuple of tuple of LinearTerm
        Terms of each equation: ``sum(lhs terms) = sum(known terms)``.
    channel_labels : tuple of str
        Readable name of each channel.
    evaluate : callable
        ``evaluate(x, f, t, sgn) -> G``: channel values (n, channels) from displacements
        (n, nx), forces (n, nf), times (n,) and signs of velocity (n, nx).
    finish : callable
        Maps the per-equation solutions (list of dicts) to the public parameters.
    parameter_names : tuple of str
        Public parameter names, in output order.
    n_dof, n_forces : int
        Displacement and force columns a record must have.
    joint : bool
        Solve equations that share unknown names together (symbolic equations); False:
        every equation alone (the model's per-DOF form).
    """

    name: str
    unknowns: tuple[tuple[str, ...], ...]
    terms: tuple[tuple[LinearTerm, ...], ...]
    channel_labels: tuple[str, ...]
    evaluate: Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], np.ndarray]
    finish: Callable[[list[dict[str, float]]], dict[str, float]]
    parameter_names: tuple[str, ...]
    n_dof: int
    n_forces: int
    joint: bool = False
    matrices: Callable[[list[dict[str, float]]], dict[str, np.ndarray]] | None = None

    @property
    def max_order(self) -> int:
        """Highest derivative order of any term."""
        return max(t.order for eq in self.terms for t in eq)

    def assembly(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Per equation, maps from entries ``E[order, channel]`` (flattened) to ``A`` and ``D``."""
        n_ch = len(self.channel_labels)
        size = (self.max_order + 1) * n_ch
        maps = []
        for unknowns, terms in zip(self.unknowns, self.terms):
            lhs, rhs = np.zeros((size, len(unknowns))), np.zeros(size)
            for t in terms:
                row = t.order * n_ch + t.channel
                if t.unknown is None:
                    rhs[row] += t.coef
                else:
                    lhs[row, t.unknown] += t.coef
            maps.append((lhs, rhs))
        return maps
