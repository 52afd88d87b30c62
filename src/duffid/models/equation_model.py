"""A model given by the user's own equations, with the interface of a built-in chain.

:class:`EquationModel` wraps the integrated-by-parts regressor that
:mod:`duffid.models.equation` derives from the text with CasADi and answers what the
identification engine and the checks of :mod:`duffid.identification.trust` ask a model
(the questions :class:`~duffid.models.chain.Chain` answers for the built-in plants):
its equations as terms over channels, how per-block solutions combine, which values are
physical, its linearised natural frequencies, its accelerations for simulation and each
term's share of the force balance. So the robust method, the paper method, the buffered
bases and the publication checks all run on the user's equation.

Equations that share a parameter form a *block* solved together (their rows stacked in one
least-squares problem); an equation alone is its own block. Every block needs a term
without a parameter (a force, or ``der(x,2)`` in a ratio form) that fixes its scale.

What is physical: the parameter of an equation's inertia term (``der(x_i,2)``) must have
the sign that makes the inertia positive relative to the force in the same equation, and
a parameter of a dissipative term (``der(x_i)`` times an even, non-negative function of
``x_i``, e.g. ``b*der(x)`` or ``c*x^2*der(x)``) the sign that makes it dissipate energy,
wherever the equation's inertia sign is known (a forced equation, or a ratio form whose
``der(x_i,2)`` has no parameter).
"""
from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

import casadi as ca
import numpy as np

from ..errors import EquationError, InputError
from .chain import Channel, Equation, Term
from .equation import DerivedRegressor, derive
from .regression import Regression

__all__ = ["EquationModel"]

#: Points (multiples of the displacement's scale) at which a channel is probed for being an
#: odd, increasing function of one displacement (a dissipative term's antiderivative).
_PROBES = (0.25, 0.5, 1.0, 2.0, 3.0)

#: Samples per call of a CasADi map over a record (one map of this size is built per
#: function and reused; a map of a million samples takes seconds to build).
MAP_CHUNK = 8192


def _mapped(fn: ca.Function, maps: dict[tuple[int, int], ca.Function], n: int, *args: np.ndarray) -> list[np.ndarray]:
    """``fn`` over ``n`` samples, each argument rows x ``n``: ``fn.map`` of at most
    :data:`MAP_CHUNK` samples (kept in ``maps``), its outputs' sample blocks side by side as
    ``fn.map(n)`` gives them."""
    size = min(n, MAP_CHUNK)
    key = (id(fn), size)
    if key not in maps:
        maps[key] = fn.map(size)
    mapped = maps[key]
    parts: list[list[np.ndarray]] = [[] for _ in range(fn.n_out())]
    for start in range(0, n, size):
        count = min(size, n - start)
        chunk = [np.asarray(a, dtype=float)[:, start:start + count] for a in args]
        if count < size:  # the last chunk, padded (the padding's values are dropped)
            chunk = [np.pad(c, ((0, 0), (0, size - count))) for c in chunk]
        out = mapped(*chunk)
        for i, value in enumerate(out if isinstance(out, (tuple, list)) else (out,)):
            value = np.asarray(value, dtype=float)
            parts[i].append(value[:, :value.shape[1] // size * count])
    return [np.concatenate(p, axis=1) for p in parts]


class EquationModel:
    """The user's equations as a model for identification.

    Parameters
    ----------
    equations : str or sequence of str
        ``"m*der(x,2) + b*der(x) + c*x^2*der(x) + k*x + kp*x^3 = f"``; several separated by
        ``;`` (see :mod:`duffid.models.equation` for the syntax).
    columns : sequence of str
        The record's columns (``Record.column_names``): ``t, f, x`` or ``t, f1.., x1..``.
    values : mapping, optional
        Parameter values (e.g. a truth for simulation); unknown ones are 0. Identification
        never uses them.
    name : str
        Model name in results ("equation").

    Raises
    ------
    EquationError
        An equation that cannot be identified, naming the term or the name at fault.
    """

    def __init__(self, equations: str | Sequence[str], columns: Sequence[str] = ("t", "f", "x"), *,
                 values: Mapping[str, float] | None = None, name: str = "equation") -> None:
        self.regressor: DerivedRegressor = derive(equations, columns)
        reg = self.regressor
        self.columns = tuple(columns)
        self.texts = reg.equations
        self._name = name
        sig = reg.signals
        self.n_dof = sig.n_dof
        self.n_forces = sig.n_forces
        values = dict(values or {})
        unknown = set(values) - set(reg.parameters)
        if unknown:
            raise InputError(f"values for {sorted(unknown)}, which the equations do not name; "
                             f"their parameters are {', '.join(reg.parameters)}")
        self._values = {k: float(values.get(k, 0.0)) for k in reg.parameters}
        self._blocks = _blocks(reg.unknowns)
        self._check_scales()
        self._block_of = {k: b for b, eqs in enumerate(self._blocks) for e in eqs for k in reg.unknowns[e]}
        self._equations = tuple(self._block_equation(b, eqs) for b, eqs in enumerate(self._blocks))
        theta = ca.vertcat(*[reg.symbols[k] for k in reg.parameters])
        res = ca.vertcat(*reg.residuals)
        self._signals = [ca.vertcat(*sig.x), ca.vertcat(*sig.dx), ca.vertcat(*sig.ddx),
                         ca.vertcat(*sig.f) if sig.f else ca.SX(0, 1), ca.vertcat(*sig.sgn), sig.t]
        self._theta = theta
        self._residual = ca.Function("residual", self._signals + [theta], [res])
        self._maps: dict[tuple[int, int], ca.Function] = {}  # _mapped's
        self._regressors = ca.Function("regressors", self._signals, [ca.jacobian(res, theta),
                                                                      ca.substitute(res, theta, ca.DM.zeros(theta.numel()))])
        self.uses_time = bool(ca.depends_on(res, sig.t))
        self._signs = self._physical_signs()

    # ------------------------------------------------------------------ names
    @property
    def name(self) -> str:
        """Model name used in results."""
        return self._name

    @property
    def parameters(self) -> dict[str, float]:
        """Parameter values by name (0 unless given)."""
        return dict(self._values)

    def canonical_parameters(self) -> dict[str, float]:
        """The parameters (an equation model's names are its canonical names)."""
        return dict(self._values)

    def from_canonical(self, values: Mapping[str, float]) -> dict[str, float]:
        """The values of the model's parameters, in its order."""
        return {k: values[k] for k in self._values}

    def canonical_name(self, public: str) -> str:
        """``public`` itself (KeyError for a name the equations do not have)."""
        if public not in self._values:
            raise KeyError(f"{self.name}: no parameter {public!r}; known: {', '.join(self._values)}")
        return public

    def __repr__(self) -> str:
        return f"EquationModel({'; '.join(self.texts)!r})"

    # ------------------------------------------------------------------ structure
    def equations(self) -> tuple[Equation, ...]:
        """One :class:`~duffid.models.chain.Equation` per block of equations sharing parameters."""
        return self._equations

    def regression(self) -> Regression:
        """The regression structure of the buffered methods (equations sharing parameters solved together)."""
        return self.regressor.regression(self.name)

    def channel_values(self, x: np.ndarray, f: np.ndarray, t: float, sgn: np.ndarray) -> np.ndarray:
        """The channels ``g`` at one sample (displacements, forces, time, signs of velocity)."""
        out = self.regressor.channel_function(x, f if self.n_forces else ca.DM(0, 1), t, sgn)
        return np.asarray(out, dtype=float).ravel()

    def combine_solutions(self, solutions: list[dict[str, float]], errors: list[dict[str, float]] | None = None
                          ) -> tuple[dict[str, float], dict[str, float]]:
        """Parameters (and relative standard errors) from the blocks' solutions."""
        values: dict[str, float] = {}
        rse: dict[str, float] = {}
        errors = errors if errors is not None else [{k: np.nan for k in sol} for sol in solutions]
        for sol, err in zip(solutions, errors):
            values.update(sol)
            rse.update(err)
        return ({k: float(values.get(k, np.nan)) for k in self._values},
                {k: float(rse.get(k, np.inf)) for k in self._values})

    def share_sources(self, name: str) -> list[tuple[int, str | None]]:
        """The block whose solution holds ``name``."""
        return [(self._block_of[name], name)]

    def is_physical(self, name: str, value: float) -> bool:
        """Whether ``value`` has the sign an inertia or a dissipative term needs (see the module docs)."""
        rule = self._signs.get(name)
        if rule is None:
            return True
        sign, strict = rule
        return sign * value > 0 if strict else sign * value >= 0

    def period_parameters(self) -> tuple[str, ...]:
        """The parameters of the linearised inertia and stiffness (they set the natural periods)."""
        zero = ca.DM.zeros
        sig = self._signals
        res = self._residual(*sig, self._theta)
        M = ca.jacobian(res, sig[2])
        K = ca.substitute(ca.jacobian(res, sig[0]), ca.vertcat(sig[0], sig[1], sig[2], sig[4]),
                          zero(4 * self.n_dof))
        return tuple(k for k in self._values
                     if ca.depends_on(ca.vertcat(ca.vec(M), ca.vec(K)), self.regressor.symbols[k]))

    def offset_parameters(self) -> dict[str, int]:
        """Parameters that only multiply a constant (an offset) and the equation they act in."""
        reg = self.regressor
        out: dict[str, int] = {}
        for e, (names, terms) in enumerate(zip(reg.unknowns, reg.terms)):
            for j, name in enumerate(names):
                own = [t for t in terms if t.unknown == j]
                if own and all(t.order == 0 and reg.channel_exprs[t.channel].is_constant() for t in own):
                    out.setdefault(name, e)
        return out

    @property
    def offset(self) -> bool:
        """Whether an equation carries a constant (offset) term."""
        return bool(self.offset_parameters())

    def with_offset(self) -> "EquationModel":
        """The equations with an unknown constant added to each (``c1``, ``c2``, ... or
        ``offset1``, ... where those names are taken); itself if one already has a constant."""
        if self.offset:
            return self
        taken = set(self._values)
        texts = []
        for i, text in enumerate(self.texts):
            name = f"c{i + 1}" if f"c{i + 1}" not in taken else f"offset{i + 1}"
            lhs, rhs = text.split("=", 1)
            texts.append(f"{lhs.rstrip()} + {name} = {rhs.lstrip()}")
        return EquationModel(texts, self.columns, values=self._values, name=self.name)

    def needs_force(self) -> bool:
        """Whether the scale of some block comes from the force alone (a record without force
        then determines nothing)."""
        reg = self.regressor
        forces = ca.vertcat(*reg.signals.f) if reg.signals.f else None
        for eqs in self._blocks:
            known = [reg.channel_exprs[t.channel] for e in eqs for t in reg.terms[e] if t.unknown is None]
            if forces is not None and known and all(ca.depends_on(g, forces) for g in known):
                return True
        return False

    def residual_terms(self, x: np.ndarray, dx: np.ndarray, ddx: np.ndarray, f: np.ndarray, sgn: np.ndarray,
                       t: float) -> tuple[np.ndarray, np.ndarray]:
        """At one point of the signals (displacements, their derivatives, forces, signs of
        velocity, time): the derivative of each equation's residual with respect to each
        parameter (n_equations x n_parameters, parameters in :attr:`parameters` order) and
        the residuals' terms without a parameter."""
        jac, rest = self._regressors(x, dx, ddx, f if self.n_forces else np.zeros((0, 1)), sgn, t)
        return np.asarray(jac, dtype=float), np.asarray(rest, dtype=float).ravel()

    # ------------------------------------------------------------------ dynamics
    def linear_natural_frequencies(self, parameters: Mapping[str, float] | None = None) -> np.ndarray:
        """Undamped natural frequencies [rad/s] of the equations linearised about rest.

        Raises
        ------
        InputError
            When the equations do not give one acceleration per displacement.
        """
        theta = self._theta_vector(parameters)
        M, K = self._linear_matrices(theta)
        eig = np.linalg.eigvals(np.linalg.solve(M, K))
        return np.sqrt(np.sort(np.abs(eig.real)))

    def _linear_matrices(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if len(self.texts) != self.n_dof:
            raise InputError(f"{len(self.texts)} equation(s) for {self.n_dof} displacement(s): the equations "
                             "do not give one acceleration per displacement")
        sig = self._signals
        res = self._residual(*sig, theta)
        zero = [ca.DM.zeros(s.numel()) for s in sig[:5]] + [0.0]
        jac = ca.Function("linear", sig, [ca.jacobian(res, sig[2]), ca.jacobian(res, sig[0])])
        M, K = (np.asarray(m, dtype=float) for m in jac(*zero))
        if not np.all(np.isfinite(M)) or abs(np.linalg.det(M)) == 0.0:
            raise InputError("the identified inertia matrix is singular")
        return M, K

    def _theta_vector(self, parameters: Mapping[str, float] | None) -> np.ndarray:
        p = self._values if parameters is None else parameters
        missing = [k for k in self._values if k not in p]
        if missing:
            raise KeyError(f"{self.name}: missing parameter(s) {missing}")
        return np.array([float(p[k]) for k in self._values])

    def symbolic_acceleration(self, p: Mapping[str, Any], x: Sequence[Any], v: Sequence[Any],
                              f: Sequence[Any], friction_velocity: float) -> list[Any]:
        """Accelerations solved from the equations (CasADi symbols), ``sign(der(x))`` smoothed
        as ``tanh(der(x) / friction_velocity)``.

        Raises
        ------
        InputError
            For equations that use the time ``t`` or do not give one acceleration per displacement.
        """
        if self.uses_time:
            raise InputError("the equations use the time t, which a simulation from a fitted state cannot "
                             "reproduce")
        if len(self.texts) != self.n_dof:
            raise InputError(f"{len(self.texts)} equation(s) for {self.n_dof} displacement(s): the equations "
                             "do not give one acceleration per displacement")
        xs, vs = ca.vertcat(*x), ca.vertcat(*v)
        fs = ca.vertcat(*f) if len(f) else ca.SX(0, 1)
        theta = ca.vertcat(*[p[k] for k in self._values])
        a = ca.SX.sym("a", self.n_dof)
        res = self._residual(xs, vs, a, fs, ca.tanh(vs / friction_velocity), 0.0, theta)
        M = ca.jacobian(res, a)
        r0 = ca.substitute(res, a, ca.DM.zeros(self.n_dof))
        acc = -r0 / M if self.n_dof == 1 else -ca.solve(M, r0)
        return [acc[i] for i in range(self.n_dof)]

    def acceleration(self, x: np.ndarray, v: np.ndarray, f: np.ndarray, friction_velocity: float = 1e-4
                     ) -> np.ndarray:
        """Accelerations at one state under forces ``f`` with the model's values (what
        :func:`duffid.simulate` integrates; ``sign(der(x))`` smoothed as in
        :meth:`symbolic_acceleration`)."""
        key = float(friction_velocity)
        if getattr(self, "_acceleration_key", None) != key:
            xs, vs = ca.SX.sym("x", self.n_dof), ca.SX.sym("v", self.n_dof)
            fs = ca.SX.sym("f", self.n_forces)
            acc = self.symbolic_acceleration(self._values, [xs[i] for i in range(self.n_dof)],
                                             [vs[i] for i in range(self.n_dof)],
                                             [fs[i] for i in range(self.n_forces)], key)
            self._acceleration_fn = ca.Function("acceleration", [xs, vs, fs], [ca.vertcat(*acc)])
            self._acceleration_key = key
        return np.asarray(self._acceleration_fn(x, v, f), dtype=float).ravel()

    def term_shares(self, canonical: Mapping[str, float], x: np.ndarray, f: np.ndarray,
                    dt: float) -> dict[str, float]:
        """Share of each parameter's term in the balance of the equations it appears in.

        The terms are evaluated on a smooth displacement ``x`` (e.g. the identified model's
        simulation) with central differences for the derivatives; a term's share is its RMS
        over the root of the sum of the mean squares of all terms of that equation, the
        terms without a parameter included (largest over the equations it appears in).
        """
        x = np.asarray(x, dtype=float).reshape(len(x), -1)
        f = np.asarray(f, dtype=float).reshape(len(x), -1)
        n = len(x)
        v = np.gradient(x, dt, axis=0, edge_order=2)
        a = np.gradient(v, dt, axis=0, edge_order=2)
        t = np.arange(n) * dt
        J, known = _mapped(self._regressors, self._maps, n, x.T, v.T, a.T,
                           f.T if self.n_forces else np.zeros((0, n)), np.sign(v).T, t[None, :])
        n_eq, n_p = len(self.texts), len(self._values)
        J = np.asarray(J, dtype=float).reshape(n_eq, n, n_p)  # the map puts the samples' blocks side by side
        known = np.asarray(known, dtype=float)                 # (equations, samples)
        theta = self._theta_vector(canonical)
        terms = J * theta[None, None, :]                 # (equations, samples, parameters)
        out = {}
        for j, name in enumerate(self._values):
            shares = []
            for e in range(n_eq):
                if not np.any(J[e, :, j]):
                    continue
                balance = float(np.sum(np.mean(terms[e] ** 2, axis=0)) + np.mean(known[e] ** 2))
                rms = math.sqrt(float(np.mean(terms[e, :, j] ** 2)))
                shares.append(rms / math.sqrt(balance) if balance > 0 else math.nan)
            out[name] = max(shares) if shares else math.nan
        return out

    def equation_residuals(self, values: Mapping[str, float], x: np.ndarray, v: np.ndarray, a: np.ndarray,
                           f: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Each equation's residual (left side minus right side, in the equation's own
        units, e.g. N) at every sample of given displacements, velocities, accelerations,
        forces and times (arrays of samples x DOFs or forces); the velocity's sign stands for
        ``sign(der(x))``. Returns samples x equations."""
        x = np.asarray(x, dtype=float).reshape(len(x), -1)
        n = len(x)
        v = np.asarray(v, dtype=float).reshape(n, -1)
        a = np.asarray(a, dtype=float).reshape(n, -1)
        f = np.asarray(f, dtype=float).reshape(n, -1)
        theta = self._theta_vector(values)
        out, = _mapped(self._residual, self._maps, n, x.T, v.T, a.T, f.T if self.n_forces else np.zeros((0, n)),
                       np.sign(v).T, np.asarray(t, dtype=float)[None, :], np.tile(theta[:, None], (1, n)))
        return out.T

    # ------------------------------------------------------------------ construction
    def _check_scales(self) -> None:
        reg = self.regressor
        for eqs in self._blocks:
            if any(t.unknown is None for e in eqs for t in reg.terms[e]):
                continue
            text = reg.equations[eqs[0]] if len(eqs) == 1 else "; ".join(reg.equations[e] for e in eqs)
            raise EquationError(f"equation {text!r} has no term without a parameter, so its scale is free: "
                                "name ratios instead (e.g. divide by the mass: der(x,2) + c*der(x) + w*x = 0), "
                                "or share a parameter with a forced equation")

    def _block_equation(self, index: int, eqs: list[int]) -> Equation:
        reg = self.regressor
        names: list[str] = []
        for e in eqs:
            names += [k for k in reg.unknowns[e] if k not in names]
        lhs, rhs = [], []
        for part, e in enumerate(eqs):
            for t in reg.terms[e]:
                channel = Channel("expression", t.channel, text=reg.channels[t.channel])
                if t.unknown is None:
                    rhs.append(Term(None, channel, t.order, t.coef, part))
                else:
                    lhs.append(Term(reg.unknowns[e][t.unknown], channel, t.order, t.coef, part))
        return Equation(index, tuple(names), tuple(lhs), tuple(rhs))

    def _physical_signs(self) -> dict[str, tuple[float, bool]]:
        """Parameter -> (required sign, strictly) for inertia and dissipative terms."""
        reg = self.regressor
        sig = reg.signals
        kinds = [_channel_kind(g, sig) for g in reg.channel_exprs]
        signs: dict[str, tuple[float, bool]] = {}
        for names, terms in zip(reg.unknowns, reg.terms):
            forcing = [t.coef for t in terms if t.unknown is None and t.order == 0 and kinds[t.channel][0] == "f"]
            s_force = float(np.sign(forcing[0])) if len(forcing) == 1 else 0.0
            inertia: dict[int, float] = {}  # displacement -> sign of its inertia on the left
            for t in terms:
                kind, i = kinds[t.channel]
                if t.order != 2 or kind != "x":
                    continue
                if t.unknown is None:
                    inertia[i] = -float(np.sign(t.coef))
                elif s_force:
                    inertia[i] = s_force
                    signs.setdefault(names[t.unknown], (float(np.sign(t.coef)) * s_force, True))
            for t in terms:
                kind, i = kinds[t.channel]
                if t.unknown is not None and t.order == 1 and kind in ("x", "dissipative") and i in inertia:
                    signs.setdefault(names[t.unknown], (float(np.sign(t.coef)) * inertia[i], False))
        return signs


def _blocks(unknowns: Sequence[Sequence[str]]) -> list[list[int]]:
    """Groups of equations connected by shared parameters, in order of first equation."""
    parent = list(range(len(unknowns)))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    owner: dict[str, int] = {}
    for e, names in enumerate(unknowns):
        for k in names:
            if k in owner:
                parent[root(e)] = root(owner[k])
            else:
                owner[k] = e
    groups: dict[int, list[int]] = {}
    for e in range(len(unknowns)):
        groups.setdefault(root(e), []).append(e)
    return sorted(groups.values(), key=lambda g: g[0])


def _channel_kind(g: ca.SX, sig: Any) -> tuple[str, int]:
    """("x", i) for displacement i itself, ("f", k) for force k, ("dissipative", i) for an odd,
    increasing function of displacement i alone (the antiderivative of an even,
    non-negative factor of der(x_i)), else ("other", -1)."""
    for i, s in enumerate(sig.x):
        if ca.is_equal(g, s):
            return "x", i
    for k, s in enumerate(sig.f):
        if ca.is_equal(g, s):
            return "f", k
    others = ca.vertcat(*(sig.dx + sig.ddx + sig.f + sig.sgn + [sig.t]))
    used = [i for i, s in enumerate(sig.x) if ca.depends_on(g, s)]
    if len(used) != 1 or (others.numel() and ca.depends_on(g, others)):
        return "other", -1
    i = used[0]
    fn = ca.Function("probe", [sig.x[i]], [ca.substitute(g, ca.vertcat(*[s for j, s in enumerate(sig.x) if j != i]),
                                                          ca.DM.zeros(len(sig.x) - 1)) if len(sig.x) > 1 else g])
    grid = np.array([-p for p in _PROBES[::-1]] + [0.0] + list(_PROBES))
    values = np.array([float(fn(p)) for p in grid])
    odd = np.allclose(values, -values[::-1], rtol=1e-9, atol=1e-12 * max(np.max(np.abs(values)), 1.0))
    return ("dissipative", i) if odd and np.all(np.diff(values) > 0) else ("other", -1)

