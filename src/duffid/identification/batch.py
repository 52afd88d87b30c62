"""A whole record through any estimator: the online methods sample by sample, the
buffered methods window by window. Nothing is checked here; publication is
:mod:`duffid.identification.trust`'s job."""
from __future__ import annotations

from typing import Any

from ..data.record import Record
from ..errors import InputError
from ..models.chain import Chain
from ..models.equation_model import EquationModel
from .buffered import identify_buffered
from .engine import METHODS, Identification, OnlineIdentifier, check_record
from .options import ONLINE_METHODS

__all__ = ["estimate"]


def estimate(record: Record, model: Chain | EquationModel, method: str = "robust", **options: Any) -> Identification:
    """Run an estimator over a record and return what it reported (nothing is checked).

    The online methods feed the record sample by sample through
    :class:`~duffid.identification.engine.OnlineIdentifier` (the same O(1) update as online use), so the estimate
    history is exactly what an online identifier would have reported at each sample.
    The buffered methods (paper section 4, :mod:`duffid.identification.buffered`) re-identify every
    ``every`` samples over the last window with an orthogonal basis. Publishing values
    is :func:`duffid.identification.trust.identify`'s job (``duffid.identify``): it checks the record
    against the model and publishes only what the record supports.

    Parameters
    ----------
    record : Record
        Forces and displacements, evenly sampled.
    model : Chain or EquationModel
        Model structure.
    method : {"robust", "paper", "legendre", "chebyshev", "block-pulse", "haar"}
        Estimator: online (``robust``, ``paper``) or buffered with the named basis.
    **options
        Method options, see :class:`~duffid.identification.engine.OnlineIdentifier` (online methods) and
        :class:`~duffid.identification.buffered.BufferedIdentifier` (``window``, ``n_terms``, ``every``,
        ``quadrature``, ``form``, ``repeated``, ``accumulate``, ``max_condition``,
        ``max_uncertainty``, ``deadband``).

    Returns
    -------
    Identification
        ``parameters`` are the estimator's final (held) values, ``estimates`` its final
        solution; for the buffered methods a :class:`~duffid.identification.buffered.BufferedIdentification`.
    """
    record.require_displacement("the algebraic estimator")
    if method not in METHODS:
        raise InputError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
    check_record(record, model)
    if method in ONLINE_METHODS:
        return OnlineIdentifier(model, record.dt, method, **options).identify_record(record)
    structure = model.regression() if isinstance(model, EquationModel) else model
    result = identify_buffered(record, structure, method, **options)
    result.estimates = dict(result.parameters)
    return result
