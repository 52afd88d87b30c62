"""Identification of the user's own equations (text), from regressors derived by
:mod:`duffid.models.equation`: the paper method over the derived rows, or the buffered
methods over the derived regression structure."""
from __future__ import annotations

from typing import Any, Mapping, Sequence

import numpy as np

from ..data.record import Record
from ..errors import EquationError, InputError
from ..models.equation import DerivedRegressor, derive
from .buffered import identify_buffered, velocity_signs
from .engine import STATUSES, Identification, Integrators, equilibrated_condition, filtered_cramer
from .options import check_options
from .orthogonal import BASES

__all__ = ["identify_equation", "EQUATION_METHODS"]

#: Methods of :func:`identify_equation`.
EQUATION_METHODS = ("paper",) + BASES



def identify_equation(record: Record, equation: str | Sequence[str], method: str = "paper",
                      **options: Any) -> Identification:
    """Identify the parameters of equations given as text from a record.

    Parameters
    ----------
    record : Record
        Forces and displacements; its column names (``t, f, x`` or ``t, f1.., x1..``)
        are the signals of the equations.
    equation : str or sequence of str
        Equations, e.g. ``"m*der(x,2) + b*der(x) + c*x^2*der(x) + k*x + kp*x^3 = f"``;
        several separated by ``;``.
    method : {"paper", "legendre", "chebyshev", "block-pulse", "haar"}
        ``paper``: eqs. (16)-(19) with the derived rows (options ``gamma``, ``quadrature``,
        ``sign_in_numerator``, ``max_condition``, ``min_time``, ``deadband``, as
        :func:`duffid.identify`'s paper method); each equation needs a term without
        parameters and parameters of its own. The bases: the buffered estimator
        (:class:`~duffid.identification.buffered.BufferedIdentifier`; options ``window``, ``n_terms``,
        ``every``, ...), equations that share parameters solved together.

    Returns
    -------
    Identification
        ``model`` is ``"equation"``; the parameters carry the equation's names.
    """
    if method not in EQUATION_METHODS:
        raise InputError(f"unknown method {method!r} for equations; choose one of {', '.join(EQUATION_METHODS)}")
    regressor = derive(equation, record.column_names)
    _check_known_terms(regressor, joint=method != "paper")
    if method != "paper":
        result = identify_buffered(record, regressor.regression(), method, **options)
        result.options["equation"] = "; ".join(regressor.equations)
        return result
    return _identify_paper(record, regressor, options)


def _check_known_terms(reg: DerivedRegressor, joint: bool) -> None:
    owners: dict[str, list[int]] = {}
    for e, names in enumerate(reg.unknowns):
        for k in names:
            owners.setdefault(k, []).append(e)
    shared = {k: v for k, v in owners.items() if len(v) > 1}
    for e, eq in enumerate(reg.terms):
        if any(t.unknown is None for t in eq):
            continue
        if joint and any(e in v for v in shared.values()):
            continue
        raise EquationError(f"equation {reg.equations[e]!r} has no term without a parameter, so its "
                            "scale is free: name ratios instead (e.g. divide by the mass: der(x2,2) + c2*... = 0)"
                            + ("" if joint else ", or use a buffered method with parameters shared "
                               "with a forced equation"))
    if not joint and shared:
        k, v = next(iter(shared.items()))
        raise EquationError(f"parameter {k!r} appears in equations {', '.join(str(i + 1) for i in v)}: the paper "
                            "method solves each equation alone; use a buffered method (legendre, ...) to solve "
                            "them together")
    if joint:  # every group of equations sharing parameters needs a known term
        for k, v in shared.items():
            if not any(any(t.unknown is None for t in reg.terms[e]) for e in v):
                raise EquationError(f"equations {', '.join(str(i + 1) for i in v)} share {k!r} but none has a "
                                    "term without a parameter: their scale is free")


def _identify_paper(record: Record, reg: DerivedRegressor, options: Mapping[str, Any]) -> Identification:
    o = check_options("paper", options)  # the same options as identify()'s paper method
    record.require_samples(16, "identification of an equation")
    if any(r != len(u) for r, u in zip(reg.n_rows, reg.unknowns)):
        raise InputError("the paper method needs square systems (n_rows = unknowns)")
    dt = record.dt
    n = record.n_samples
    sgn = velocity_signs(record.x, o["deadband"])
    tau = np.arange(n) * dt  # as the online paper method
    U = np.asarray(reg.bank_function.map(n)(record.x.T, record.f.T, record.t[None, :], sgn.T, tau[None, :])).T
    bank = Integrators(U.shape[1], reg.depth, dt, o["quadrature"])
    filters = [Integrators(len(u) + 1, 2, dt, o["quadrature"]) for u in reg.unknowns]
    names = reg.parameters
    history = {k: np.full(n, np.nan) for k in names}
    condition = np.full(n, np.inf)
    flags = np.zeros(n, dtype=bool)
    for i in range(n):
        Y = bank.push(U[i])
        values: dict[str, float] = {}
        cond = 0.0
        for (A, D), filt, unknowns in zip(reg.rows(Y), filters, reg.unknowns):
            theta = filtered_cramer(A, D, filt, o["gamma"], tau[i], o["sign_in_numerator"])
            values.update(zip(unknowns, theta))
            cond = max(cond, equilibrated_condition(A))
        for k in names:
            history[k][i] = values[k]
        condition[i] = cond
        flags[i] = (cond <= o["max_condition"] and i * dt >= o["min_time"] - 1e-12 and i >= 8
                    and all(np.isfinite(v) for v in values.values()))
    return Identification(
        model="equation", method="paper", parameters={k: float(history[k][-1]) for k in names},
        t=record.t - record.t[0], history=history, condition=condition, identified=flags,
        t_identified=float(record.t[np.argmax(flags)] - record.t[0]) if flags.any() else None,
        window=float(record.duration),
        options={**o, "equation": "; ".join(reg.equations)}, source=record.source,
        status={k: STATUSES[1] if len(flags) and flags[-1] else STATUSES[0] for k in names})


