"""The nonlinear share of the restoring force, from an identified model.

For a spring ``k x + kp x^3`` the share at the record's peak deflection ``x_peak`` is
``kp x_peak^3 / (k x_peak) = kp x_peak^2 / k`` (signed: positive hardening, negative
softening); a user can read off whether a linear model will do over the record's range.
The values come from :func:`duffid.identification.trust.identify`, which publishes a
parameter only when the record supports it; the share's relative standard error combines
those of ``kp`` and ``k``. When either is not published the share is not given, and the
reason says why.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..data.record import Record
from ..identification.trust import identify
from ..models.chain import Chain

__all__ = ["SpringShare", "nonlinear_shares"]


@dataclass
class SpringShare:
    """The nonlinear share of one spring.

    Attributes
    ----------
    spring : str
        Which spring (``"k, kp"``, ``"k2, kp2"``, ...).
    share : float
        ``kp x_peak^2 / k`` (NaN when not given).
    uncertainty : float
        Its standard error (absolute, NaN when not given).
    deflection : float
        Peak deflection of the spring in the record [m] (or [C] for a circuit).
    reason : str
        Why the share is not given (empty when it is).
    """

    spring: str
    share: float
    uncertainty: float
    deflection: float
    reason: str = ""
    notes: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (NaN as None)."""
        def clean(v: float) -> float | None:
            return float(v) if np.isfinite(v) else None
        return {"spring": self.spring, "share": clean(self.share), "uncertainty": clean(self.uncertainty),
                "deflection": clean(self.deflection), "reason": self.reason or None}


def _springs(names: list[str], n_dof: int) -> list[tuple[str, str, int, int, bool]]:
    """(linear name, cubic name, DOF, neighbour DOF or -1 for ground, linear is 1/C)."""
    if "kp" in names and "k" in names:
        return [("k", "kp", 0, -1, False)]
    if "a" in names and "C" in names:
        return [("C", "a", 0, -1, True)]
    out = []
    for i in range(1, n_dof + 1):
        if f"k{i}" in names and f"kp{i}" in names:            # duffing2
            out.append((f"k{i}", f"kp{i}", i - 1, i - 2, False))
        elif f"k{i}_1" in names and f"k{i}_3" in names:       # chain
            out.append((f"k{i}_1", f"k{i}_3", i - 1, i - 2, False))
    return out


def nonlinear_shares(record: Record, model: Chain, **identify_options: Any) -> list[SpringShare]:
    """Identify ``model`` on ``record`` and give each cubic spring's share at the record's peak.

    Parameters
    ----------
    record : Record
        The record (any excitation ``identify`` supports).
    model : Chain
        Model structure with cubic springs (duffing1, duffing2, a chain with orders 1 and 3,
        the circuit).
    identify_options
        Passed to :func:`duffid.identification.trust.identify`.

    Returns
    -------
    list of SpringShare
        One per cubic spring; empty when the model has none.
    """
    record.require_displacement("the springs' shares")
    result = identify(record, model, **identify_options)
    assessment = result.assessment
    names = list(result.parameters)
    springs = _springs(names, record.n_dof)
    shares = []
    for lin, cub, dof, other in ((s[0], s[1], s[2], s[3]) for s in springs):
        inverse = lin == "C" and cub == "a"
        x = record.x[:, dof] - (record.x[:, other] if other >= 0 else 0.0)
        peak = float(np.max(np.abs(x)))
        label = f"{lin}, {cub}"
        missing = [n for n in (lin, cub) if not np.isfinite(result.parameters.get(n, np.nan))]
        if missing:
            why = "; ".join(f"{n} is {assessment.status.get(n, 'not identified')}" for n in missing)
            notes = [n for n in assessment.notes if any(re.search(rf"\b{re.escape(m)}\b", n) for m in missing)][:2]
            shares.append(SpringShare(label, np.nan, np.nan, peak,
                                      f"the nonlinear share cannot be given: {why}", notes))
            continue
        linear = 1.0 / result.parameters[lin] if inverse else result.parameters[lin]
        value = result.parameters[cub] * peak**2 / linear
        rel = float(np.hypot(assessment.uncertainty.get(lin, np.nan), assessment.uncertainty.get(cub, np.nan)))
        shares.append(SpringShare(label, float(value), abs(value) * rel, peak))
    return shares
