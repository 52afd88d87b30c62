"""Units: the strings of FMI and Modelica (``N.s/m``, ``V/C3``), their SI base exponents, and the
units of an equation's parameters derived from the units of its signals.

A unit string is a product of factors ``symbol[exponent]`` joined by ``.``, optionally
followed by ``/`` and the factors of the denominator (``N.s2/m``, ``1/F``); ``1`` is
dimensionless. :func:`si_exponents` knows the SI base units and the derived units of
:data:`SI_UNITS`; any other symbol is kept as the user wrote it (a logger's ``counts``, say).

:func:`parameter_units` answers "what is the unit of ``c`` in ``m*der(x,2) + b*der(x) +
c*x^2*der(x) + k*x + kp*x^3 = f`` when x is in m and f in N?" by dimensional homogeneity:
every term of an equation has the unit of its terms without a parameter, so a parameter's
unit is that unit divided by the unit of what it multiplies. The unit of a CasADi
expression is found by scaling: an expression homogeneous in the signals satisfies
``g(λ^{e} signals) = λ^p g(signals)``, and ``p`` (an integer, checked at two scales and two
points) is its exponent of the unit symbol whose exponents ``e`` the signals carry. A term
that is not homogeneous (``sin(x)``, ``exp(x)``) has no derivable unit: its parameter's unit
must be declared.
"""
from __future__ import annotations

import re
from typing import TYPE_CHECKING, Mapping

import numpy as np

from ..errors import InputError

if TYPE_CHECKING:
    from .equation_model import EquationModel

__all__ = ["SI_BASE", "SI_UNITS", "si_exponents", "parse_unit", "format_unit", "parameter_units", "signal_units",
           "PREFERRED_UNITS"]

#: The SI base units, in the order of FMI's ``BaseUnit`` attributes.
SI_BASE = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")
#: SI base-unit exponents of the symbols :func:`si_exponents` knows.
SI_UNITS = {
    "kg": (1, 0, 0, 0, 0, 0, 0, 0), "m": (0, 1, 0, 0, 0, 0, 0, 0), "s": (0, 0, 1, 0, 0, 0, 0, 0),
    "A": (0, 0, 0, 1, 0, 0, 0, 0), "K": (0, 0, 0, 0, 1, 0, 0, 0), "mol": (0, 0, 0, 0, 0, 1, 0, 0),
    "cd": (0, 0, 0, 0, 0, 0, 1, 0), "rad": (0, 0, 0, 0, 0, 0, 0, 1),
    "N": (1, 1, -2, 0, 0, 0, 0, 0), "J": (1, 2, -2, 0, 0, 0, 0, 0), "W": (1, 2, -3, 0, 0, 0, 0, 0),
    "Pa": (1, -1, -2, 0, 0, 0, 0, 0), "Hz": (0, 0, -1, 0, 0, 0, 0, 0), "C": (0, 0, 1, 1, 0, 0, 0, 0),
    "V": (1, 2, -3, -1, 0, 0, 0, 0), "Ohm": (1, 2, -3, -2, 0, 0, 0, 0), "Wb": (1, 2, -2, -1, 0, 0, 0, 0),
    "H": (1, 2, -2, -2, 0, 0, 0, 0), "F": (-1, -2, 4, 2, 0, 0, 0, 0), "S": (-1, -2, 3, 2, 0, 0, 0, 0),
    "T": (1, 0, -2, -1, 0, 0, 0, 0),
}
#: Names preferred for a derived unit with the same SI exponents (mechanical and electrical
#: oscillators' parameters), tried in this order.
PREFERRED_UNITS = ("kg", "N/m", "N.s/m", "N/m2", "N/m3", "N.s/m2", "N.s/m3", "N/m5", "N.s/m5", "H", "Ohm", "F",
                   "1/F", "V/C2", "V/C3", "V.s/C3", "1/s", "1/s2", "1/(m2.s2)")
_FACTOR = re.compile(r"^([A-Za-z]+)(-?\d+)?$")
_SCALES = (2.0, 3.0)


def parse_unit(unit: str) -> dict[str, int]:
    """Symbol -> exponent of a unit string (``"N.s2/m"`` -> ``{"N": 1, "s": 2, "m": -1}``).

    Raises
    ------
    InputError
        If the string is not a product of ``symbol[exponent]`` factors (naming the factor).
    """
    text = unit.strip()
    if text == "1":
        return {}
    numerator, _, denominator = text.partition("/")
    denominator = denominator.strip()
    if denominator.startswith("(") and denominator.endswith(")"):
        denominator = denominator[1:-1]
    out: dict[str, int] = {}
    for part, sign in ((numerator, 1), (denominator, -1)):
        part = part.strip()
        if not part or part == "1":
            if sign == 1 and not part:
                raise InputError(f"unit {unit!r}: nothing before '/' (write 1/s, say)")
            continue
        for factor in part.split("."):
            m = _FACTOR.match(factor.strip())
            if m is None:
                raise InputError(f"unit {unit!r}: {factor!r} is not a symbol with an optional integer exponent "
                                 "(write units as N.s/m or m/s2)")
            out[m.group(1)] = out.get(m.group(1), 0) + sign * (int(m.group(2)) if m.group(2) else 1)
    return {k: v for k, v in out.items() if v}


def si_exponents(unit: str) -> tuple[int, ...] | None:
    """SI base-unit exponents of a unit string such as ``N.s/m`` (None: a symbol outside
    :data:`SI_UNITS`, or not a unit string)."""
    try:
        factors = parse_unit(unit)
    except InputError:
        return None
    total = [0] * len(SI_BASE)
    for symbol, power in factors.items():
        if symbol not in SI_UNITS:
            return None
        for k, e in enumerate(SI_UNITS[symbol]):
            total[k] += power * e
    return tuple(total)


def format_unit(factors: Mapping[str, int]) -> str:
    """The unit string of symbol exponents: a name of :data:`PREFERRED_UNITS` with the same SI
    exponents where every symbol is an SI one, else ``num/den`` in the symbols given
    (``{"N": 1, "s": 2, "m": -1}`` -> ``"kg"``; ``{"counts": 1, "s": -1}`` -> ``"counts/s"``)."""
    factors = {k: v for k, v in factors.items() if v}
    if not factors:
        return "1"

    def side(items: list[tuple[str, int]]) -> str:
        return ".".join(f"{s}{abs(e) if abs(e) != 1 else ''}" for s, e in items)

    num = sorted((s, e) for s, e in factors.items() if e > 0)
    den = sorted((s, e) for s, e in factors.items() if e < 0)
    plain = (side(num) or "1") + (("/" + (side(den) if len(den) == 1 else f"({side(den)})")) if den else "")
    target = si_exponents(plain)
    if target is not None:
        for name in PREFERRED_UNITS:
            if si_exponents(name) == target:
                return name
    return plain


def signal_units(model: EquationModel, units: Mapping[str, str]) -> dict[str, dict[str, int]]:
    """The parsed unit of every signal of ``model`` (its displacements and forces) from
    ``units`` (signal name -> unit string).

    Raises
    ------
    InputError
        A unit for a name that is not a signal, or a signal without a unit (naming both).
    """
    sig = model.regressor.signals
    names = list(sig.x_names) + list(sig.f_names)
    unknown = [k for k in units if k not in names and k != "t"]
    if unknown:
        raise InputError(f"--units: {unknown[0]!r} is not a signal of the equation (its signals are "
                         f"{', '.join(names)})")
    missing = [k for k in names if k not in units]
    if missing:
        raise InputError(f"--units: no unit for the signal{'s' if len(missing) > 1 else ''} {', '.join(missing)} "
                         f"(give every signal's unit, e.g. {','.join(f'{n}=...' for n in names)})")
    return {name: parse_unit(units[name]) for name in names}


def parameter_units(model: EquationModel, units: Mapping[str, str],
                    declared: Mapping[str, str] | None = None) -> dict[str, str]:
    """The unit of every parameter of ``model`` from the units of its signals.

    Parameters
    ----------
    model : EquationModel
        The equations.
    units : mapping
        Signal name -> unit string, for every displacement and force (time is in ``s``).
    declared : mapping, optional
        Parameter name -> unit string, for parameters whose unit the equations do not
        determine (a term that is not a product of powers of the signals), or to override.

    Returns
    -------
    dict
        Parameter -> unit string (:func:`format_unit`).

    Raises
    ------
    InputError
        Bad units, or a parameter whose unit cannot be derived and is not declared (naming
        the parameter and its term).
    """
    declared = dict(declared or {})
    for name in declared:
        if name not in model.parameters:
            raise InputError(f"--units: {name!r} is neither a signal nor a parameter of the equation")
        parse_unit(declared[name])
    signals = signal_units(model, units)
    sig = model.regressor.signals
    symbols = sorted({s for u in signals.values() for s in u} | {"s"})
    rng = np.random.default_rng(20261125)
    n_x, n_f = len(sig.x_names), len(sig.f_names)

    def evaluate(point: np.ndarray, scale: Mapping[str, float]) -> tuple[np.ndarray, np.ndarray]:
        """Jacobian of the residuals w.r.t. the parameters, and the residuals without them,
        at ``point`` with every signal scaled by its unit's factors."""
        x, dx, ddx, f = (point[:n_x].copy(), point[n_x:2 * n_x].copy(), point[2 * n_x:3 * n_x].copy(),
                         point[3 * n_x:3 * n_x + n_f].copy())
        t = float(point[-1])
        for i, name in enumerate(sig.x_names):
            factor = float(np.prod([scale.get(s, 1.0) ** e for s, e in signals[name].items()]))
            per_s = scale.get("s", 1.0)
            x[i] *= factor
            dx[i] *= factor / per_s
            ddx[i] *= factor / per_s**2
        for k, name in enumerate(sig.f_names):
            f[k] *= float(np.prod([scale.get(s, 1.0) ** e for s, e in signals[name].items()]))
        return model.residual_terms(x, dx, ddx, f, np.sign(dx), t * scale.get("s", 1.0))

    def exponents(values: list[tuple[float, float]]) -> int | None:
        """The integer p with value(λ) = λ^p value(1) at every (ratio, λ) pair, else None."""
        found = set()
        for ratio, lam in values:
            if not (np.isfinite(ratio) and ratio > 0):
                return None
            p = np.log(ratio) / np.log(lam)
            if abs(p - round(p)) > 1e-6:
                return None
            found.add(int(round(p)))
        return found.pop() if len(found) == 1 else None

    points = [rng.uniform(0.3, 1.7, 3 * n_x + n_f + 1) * rng.choice([-1.0, 1.0], 3 * n_x + n_f + 1)
              for _ in range(2)]
    base = [evaluate(p, {}) for p in points]
    n_eq, n_par = base[0][0].shape
    term_units: dict[tuple[int, int], dict[str, int] | None] = {}
    eq_units: list[dict[str, int] | None] = []
    for e in range(n_eq):
        for j in range(n_par + 1):  # the parameters' columns, then the terms without a parameter
            if all((b[0][e, j] if j < n_par else b[1][e]) == 0.0 for b in base):
                if j == n_par:
                    eq_units.append(None)
                continue
            unit: dict[str, int] | None = {}
            for symbol in symbols:
                pairs = []
                for p, b in zip(points, base):
                    ref = b[0][e, j] if j < n_par else b[1][e]
                    for lam in _SCALES:
                        scaled = evaluate(p, {symbol: lam})
                        value = scaled[0][e, j] if j < n_par else scaled[1][e]
                        pairs.append((value / ref, lam))
                power = exponents(pairs)
                if power is None:
                    unit = None
                    break
                if power:
                    unit[symbol] = power
            if j == n_par:
                eq_units.append(unit)
            else:
                term_units[(e, j)] = unit
    names = list(model.regressor.parameters)
    known: dict[int, dict[str, int]] = {j: parse_unit(declared[n]) for j, n in enumerate(names) if n in declared}

    def combine(a: Mapping[str, int], b: Mapping[str, int], sign: int) -> dict[str, int]:
        return {s: a.get(s, 0) + sign * b.get(s, 0) for s in set(a) | set(b) if a.get(s, 0) + sign * b.get(s, 0)}

    changed = True
    while changed:  # an equation without a parameter-free term takes its unit from a shared parameter
        changed = False
        for e in range(n_eq):
            for j in range(n_par):
                term = term_units.get((e, j))
                if term is None:
                    continue
                if eq_units[e] is None and j in known:
                    eq_units[e] = combine(known[j], term, 1)
                    changed = True
                if eq_units[e] is not None and j not in known:
                    known[j] = combine(eq_units[e], term, -1)
                    changed = True
    out: dict[str, str] = {}
    for j, name in enumerate(names):
        if name in declared:
            out[name] = declared[name]
        elif j in known:
            out[name] = format_unit(known[j])
        else:
            raise InputError(f"the unit of {name} does not follow from the signals' units (its term is not a "
                             f"product of powers of the signals): declare it, e.g. --units {name}=...")
    return out
