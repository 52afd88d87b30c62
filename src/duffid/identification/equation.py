"""Identification of the user's own equations (text): an
:class:`~duffid.models.equation_model.EquationModel` through the same estimators and the
same publication checks as the built-in models (:func:`duffid.identification.trust.identify`)."""
from __future__ import annotations

from typing import Any, Sequence

from ..data.record import Record
from ..errors import InputError
from ..models.equation_model import EquationModel
from .engine import METHODS, Identification
from .trust import identify

__all__ = ["identify_equation", "EQUATION_METHODS"]

#: Methods of :func:`identify_equation`: every method of the built-in models.
EQUATION_METHODS = METHODS


def identify_equation(record: Record, equation: str | Sequence[str], method: str = "robust", *,
                      check: bool = True, **options: Any) -> Identification:
    """Identify the parameters of equations given as text from a record.

    Parameters
    ----------
    record : Record
        Forces and displacements; its column names (``t, f, x`` or ``t, f1.., x1..``)
        are the signals of the equations.
    equation : str or sequence of str
        Equations, e.g. ``"m*der(x,2) + b*der(x) + c*x^2*der(x) + k*x + kp*x^3 = f"``;
        several separated by ``;`` (equations sharing a parameter are solved together).
    method : {"robust", "paper", "legendre", "chebyshev", "block-pulse", "haar"}
        The estimator, as for the built-in models (:func:`duffid.identify`); ``paper``
        solves each equation alone (eqs. 16-19).
    check : bool
        True (default): publish only what the record supports (the checks of
        :func:`duffid.identification.trust.identify`: sampling, simulation of the identified
        equations under the measured force, bootstrap uncertainties, physical signs);
        False: the estimator's run alone, unchecked.
    **options
        Method options (see :class:`~duffid.identification.engine.OnlineIdentifier` and
        :func:`duffid.identification.trust.identify`: ``offsets="force"`` adds a constant to
        each equation, ``refine``, ``engine``).

    Returns
    -------
    Identification
        ``model`` is ``"equation"``; the parameters carry the equation's names;
        ``options["equation"]`` the equations.
    """
    if method not in EQUATION_METHODS:
        raise InputError(f"unknown method {method!r} for equations; choose one of {', '.join(EQUATION_METHODS)}")
    model = EquationModel(equation, record.column_names)
    result = identify(record, model, method, check=check, **options)
    result.options["equation"] = "; ".join(model.texts)
    return result
