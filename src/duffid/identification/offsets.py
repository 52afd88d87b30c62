"""Sensor offsets in identification: the models that carry them, the mapping of a displacement
offset back to the physical parameters, and what the record says about them (used by
:func:`duffid.identification.trust.identify`)."""
from __future__ import annotations

import math
from typing import Any, Callable, Mapping

import numpy as np

from ..data.record import Record
from ..errors import InputError
from ..models.chain import Chain
from .engine import MIN_SHARE, OFFSET_SIGMAS, Identification
from .refine import canonical_from_public

__all__ = [
    "OFFSETS",
    "DISPLACEMENT_OFFSET",
    "offset_check",
    "with_force_offsets",
    "canonical_of",
    "offset_kind",
    "carries_displacement_offset",
    "displacement_chain",
    "displacement_offset_values",
    "mapped_to",
    "cubic_share_of",
    "inseparable_note",
    "offset_scales",
    "report_displacement_offset",
]


#: Sensor offsets :func:`identify` can model (``offsets=``, CLI ``--offset KIND``), with the
#: words the CLI's help shows; see the module documentation.
OFFSETS: dict[str, str] = {
    "force": "a constant force bias per DOF (c1, c2, ...; the default of a bare --offset)",
    "displacement": "a displacement-sensor offset x0, x_meas = x + x0 (one DOF with a cubic spring: "
                    "duffing1, circuit, chain --n-dof 1 --orders 1,3)",
    "both": "a force bias and a displacement-sensor offset",
}

#: Name of the displacement sensor's offset among the parameters (``x_meas = x + x0``).
DISPLACEMENT_OFFSET = "x0"

def offset_check(values: Mapping[str, float], uncertainty: Mapping[str, float],
                  with_offsets: Callable[[], Mapping[str, float]] | None, notes: list[str],
                  fit: dict[str, Any], max_uncertainty: float) -> set[str]:
    """Parameters whose value moves by more than 3 standard errors and ``max_uncertainty``
    when offsets are allowed."""
    if with_offsets is None:
        return set()
    alternative = with_offsets()
    offsets = {k: float(v) for k, v in alternative.items() if k not in values}
    fit["offsets_if_allowed"] = offsets
    changes = {k: (float(alternative.get(k, math.nan)) - v) / abs(v) for k, v in values.items() if v != 0}
    if not all(np.isfinite(c) for c in changes.values()):
        notes.append("with a constant offset allowed in the model the record no longer determines the "
                     "parameters: it cannot rule out a sensor offset, so the values assume there is none")
        return set()
    # the alternative has one more unknown per DOF, so its own scatter is larger: a change is a
    # finding when it exceeds both OFFSET_SIGMAS standard errors and the publication tolerance
    moved = {k for k, c in changes.items() if abs(c) > max(OFFSET_SIGMAS * uncertainty[k], max_uncertainty)}
    if moved:
        shown = ", ".join(f"{k} {100 * changes[k]:+.3g} %" for k in sorted(moved, key=list(values).index))
        found = ", ".join(f"{k} = {v:.4g}" for k, v in offsets.items())
        hint = ("--offset displacement (or --offset both)" if DISPLACEMENT_OFFSET in offsets
                else "--offset KIND (" + ", ".join(OFFSETS) + ")")
        notes.append(f"with a constant offset allowed in the model the values change beyond their uncertainty "
                     f"({shown}; offsets {found}): the record shows a sensor offset or a bias; identify "
                     f"with {hint}")
    return moved

def with_force_offsets(model: Chain) -> Chain:
    """``model`` with an unknown constant force on each DOF (``c1``, ``c2``, ...)."""
    return model.with_offset()

def canonical_of(model: Chain, public: Mapping[str, float]) -> dict[str, float] | None:
    """Canonical values from public ones (None if a needed value is missing)."""

    try:
        canonical = canonical_from_public(model, {k: v for k, v in public.items() if k != DISPLACEMENT_OFFSET})
    except (ValueError, KeyError, ZeroDivisionError):
        return None
    return canonical

# ---------------------------------------------------------------------- sensor offsets
def offset_kind(model: Chain, offsets: str | None) -> str | None:
    """The offsets to identify: ``offsets`` checked, or those of ``model`` (None: none)."""
    if offsets is None:
        return "force" if model.offset else None
    if offsets not in OFFSETS:
        raise InputError(f"offsets must be one of {', '.join(OFFSETS)} (or None), got {offsets!r}")
    if offsets == "displacement" and model.offset:
        return "both"  # the model itself carries a force bias
    return offsets

def carries_displacement_offset(model: Chain) -> bool:
    """Whether a displacement offset of ``model`` can be identified (a chain of one DOF, orders 1 and 3)."""
    return isinstance(model, Chain) and model.n_dof == 1 and tuple(model.orders or ()) == (1, 3)

def displacement_chain(model: Chain) -> Chain:
    """The chain identified for a displacement offset: ``model``'s (one DOF, orders 1 and 3)
    with stiffness orders 1, 2, 3 and a constant force."""
    if not isinstance(model, Chain):
        raise InputError("a displacement-sensor offset of an equation model is written into the equation "
                         "(x - x0 in place of x makes it nonlinear in x0: write the polynomial in x with its own "
                         "coefficients, e.g. k1*x + k2*x^2 + k3*x^3 + c = f); --offset force adds a constant "
                         "force per equation")
    if not carries_displacement_offset(model):
        raise InputError(f"a displacement-sensor offset is identified for one-DOF models with a linear and a "
                         f"cubic spring (duffing1, circuit, chain --n-dof 1 --orders 1,3), not {model.name} with "
                         f"{model.n_dof} DOF and stiffness orders {', '.join(map(str, model.orders or ()))}; "
                         f"use --offset force (a constant force per DOF)")
    canonical = model.canonical_parameters()
    return Chain(masses=(canonical["m1"],), damping=(canonical["b1"],),
                 stiffness=({1: canonical["k1_1"], 2: 0.0, 3: canonical["k1_3"]},),
                 coulomb=model.coulomb, forced=model.forced, offset=True, orders=(1, 2, 3))

def displacement_offset_values(model: Chain, extended: Mapping[str, float]) -> dict[str, float]:
    """``model``'s parameters and the displacement offset from the measured-coordinate chain.

    With ``x_meas = x + x0``, ``m x'' + b x' + k x + kp x^3 + c1 = f`` reads
    ``m x_meas'' + b x_meas' + a1 x_meas + a2 x_meas^2 + a3 x_meas^3 + a0 = f`` with
    ``a3 = kp``, ``a2 = -3 kp x0``, ``a1 = k + 3 kp x0^2`` and ``a0 = c1 - k x0 - kp x0^3``;
    inverted here: ``x0 = -a2 / (3 a3)``, ``kp = a3``, ``k = a1 - 3 a3 x0^2``,
    ``c1 = a0 + k x0 + kp x0^3``.

    Parameters
    ----------
    model : Chain
        The physical model (one DOF, stiffness orders 1 and 3, with ``offset``).
    extended : mapping
        Canonical values ``m1, b1, k1_1, k1_2, k1_3, c1`` (and ``fc1``) of the chain of
        orders 1, 2, 3 with a constant.

    Returns
    -------
    dict
        ``model``'s public parameters (``c1`` the force bias) and :data:`DISPLACEMENT_OFFSET`;
        all NaN when ``a3`` is zero or a value is not finite (then ``x0`` is undefined).
    """
    a1, a2, a3, a0 = (float(extended[k]) for k in ("k1_1", "k1_2", "k1_3", "c1"))
    names = list(model.parameters) + [DISPLACEMENT_OFFSET]
    if not (a3 != 0.0 and all(np.isfinite(v) for v in extended.values())):
        return {k: math.nan for k in names}
    x0 = -a2 / (3.0 * a3)
    k = a1 - 3.0 * a3 * x0**2
    canonical = {k_: float(v) for k_, v in extended.items() if k_ != "k1_2"}
    canonical.update({"k1_1": k, "k1_3": a3, "c1": a0 + k * x0 + a3 * x0**3})
    out = model.from_canonical(canonical)
    out[DISPLACEMENT_OFFSET] = x0
    return out

def mapped_to(result: Identification, model: Chain) -> Identification:
    """A run of :func:`displacement_chain`'s chain under ``model``'s public names and ``x0``."""
    names = list(result.history)
    with np.errstate(all="ignore"):
        rows = [displacement_offset_values(model, {k: result.history[k][i] for k in names})
                for i in range(len(result.t))]
        keys = list(model.parameters) + [DISPLACEMENT_OFFSET]
        result.history = {k: np.array([row[k] for row in rows]) for k in keys}
        raw = dict(result.estimates)
        result.parameters = displacement_offset_values(model, result.parameters)
        result.estimates = displacement_offset_values(model, raw)
    result.model = model.name
    return result

def cubic_share_of(record: Record, extended: Mapping[str, float]) -> float:
    """Share of the cubic spring in the force balance, from the measured-coordinate chain's
    values (:func:`displacement_offset_values`), without derivatives of the measured
    displacement: the smaller of ``a3 x_meas^3`` and of ``kp (x_meas - x0)^3`` over the RMS of
    the balance, whose inertia and damping part is what the force leaves to them (``f``
    minus the spring and the constant). The first is small for a linear plant (whose ``x0``
    is noise), the second when ``x0`` dwarfs the motion; NaN if undefined."""
    try:
        a1, a2, a3, a0 = (float(extended[k]) for k in ("k1_1", "k1_2", "k1_3", "c1"))
    except KeyError:
        return math.nan
    if not (a3 != 0.0 and all(np.isfinite(v) for v in (a1, a2, a3, a0))):
        return math.nan
    xm, f = record.x[:, 0], record.f[:, 0]
    rest = f - (a1 * xm + a2 * xm**2 + a3 * xm**3 + a0)
    with np.errstate(all="ignore"):
        measured = [a1 * xm, a2 * xm**2, a3 * xm**3, np.full_like(xm, a0)]
        x0 = -a2 / (3.0 * a3)
        k = a1 - 3.0 * a3 * x0**2
        x = xm - x0
        physical = [k * x, a3 * x**3, np.full_like(xm, a0 + k * x0 + a3 * x0**3)]
        shares = []
        for terms, cubic in ((measured, 2), (physical, 1)):
            balance = float(np.mean(f**2) + np.mean(rest**2) + sum(np.mean(t**2) for t in terms))
            shares.append(math.sqrt(float(np.mean(terms[cubic] ** 2)) / balance) if balance > 0 else math.nan)
    return min(shares) if all(np.isfinite(shares)) else math.nan

def inseparable_note(share: float) -> str:
    """Why ``x0`` is not published when the cubic spring is not excited."""
    carries = (f"the cubic spring carries {100 * share:.2g} % of the force balance (less than "
               f"{100 * MIN_SHARE:.0f} %)" if np.isfinite(share) else "the cubic spring's part of the force balance "
               "could not be determined")
    return (f"{DISPLACEMENT_OFFSET} is not published: {carries}; without a visibly nonlinear spring a "
            f"displacement-sensor offset acts as a constant force k*{DISPLACEMENT_OFFSET}, like a force bias, and "
            f"the record cannot separate the two: only their combined constant force c1 (= force bias - "
            f"k*{DISPLACEMENT_OFFSET}) is determined (an amplitude large enough to show the cubic spring would "
            f"separate them)")

def offset_scales(record: Record, model: Chain, names: list[str]) -> dict[str, float]:
    """Spread of the signal each offset among ``names`` is judged against: the force's RMS
    for ``c1``, ..., the displacement's standard deviation for ``x0``."""
    out = {}
    rms = float(np.sqrt(np.mean(record.f**2))) if record.f.size else 0.0
    out.update({k: rms for k in model.offset_parameters() if k in names})
    if DISPLACEMENT_OFFSET in names:
        out[DISPLACEMENT_OFFSET] = float(np.std(record.x[:, 0]))
    return out

def report_displacement_offset(result: Identification, kind: str, *, separable: bool, cubic_share: float) -> None:
    """Complete ``result`` of an identification with a displacement offset: ``x0`` not
    published (and why) when the record could not separate it from a force bias; with
    ``kind="displacement"`` the force bias leaves the parameters for ``fit["offsets"]``."""
    a = result.assessment
    offsets = a.fit.setdefault("offsets", {})
    if not separable:
        result.estimates[DISPLACEMENT_OFFSET] = math.nan
        a.status[DISPLACEMENT_OFFSET] = "not excited"
        a.uncertainty[DISPLACEMENT_OFFSET] = math.nan
        a.share[DISPLACEMENT_OFFSET] = cubic_share
        offsets[DISPLACEMENT_OFFSET] = {"value": math.nan, "standard_error": math.nan, "status": "not excited"}
        a.notes.append(inseparable_note(cubic_share))
    if kind != "displacement":
        return
    for table in (result.estimates, a.status, a.uncertainty, a.share):
        table.pop("c1", None)
    bias = offsets.get("c1")
    if separable and bias is not None and bias["status"] == "published" \
            and abs(bias["value"]) > 3.0 * bias["standard_error"]:
        a.notes.append(f"the record also shows a constant force c1 = {bias['value']:.4g} "
                       f"(standard error {bias['standard_error']:.2g}; the force sensor reads it at zero force): the "
                       f"values above account for it; --offset both lists it among the parameters")
