"""Nonlinear oscillator models: the chain of the paper's eqs. (1)-(5) and named shortcuts.

Conventions
-----------
A chain has ``n`` masses in series hanging from a fixed wall; the last mass is free.
Element ``i`` (1-based) joins mass ``i-1`` (the wall for ``i = 1``) to mass ``i``; with the
deflection ``y_i = x_i - x_{i-1}`` (``x_0 = 0``) it carries the force

    F_i = b_i * dy_i/dt + sum_j k_i_j * y_i**j

and each mass may rub on the ground with Coulomb friction ``fc_i * sgn(dx_i/dt)``.
Mass ``i`` then obeys (eq. 3 of the paper)

    m_i x_i'' + F_i + fc_i sgn(x_i') - F_{i+1} = f_i .

Canonical parameter names are ``m<i>``, ``b<i>``, ``k<i>_<j>`` (stiffness of order j of
element i) and ``fc<i>``. The named shortcuts rename them with the paper's symbols:
:class:`Duffing1` uses ``m, b, k, kp`` (eqs. 10-11), :class:`Duffing2` uses
``m1, b1, k1, kp1, m2, b2, k2, kp2`` (eqs. 20-21) and :class:`DuffingCircuit` is the
series circuit ``L q'' + R q' + q/C + a q**3 = u`` with parameters ``L, R, C, a``.

For identification, every model exposes :meth:`Chain.equations`: one
:class:`Equation` per degree of freedom, linear in its unknowns, written with
:class:`Term` objects (unknown, signal channel, derivative order, sign).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, ClassVar, Mapping, Sequence

import casadi as ca
import numpy as np

from ..errors import InputError

__all__ = [
    "Channel",
    "Term",
    "Equation",
    "Chain",
    "Duffing1",
    "Duffing2",
    "DuffingCircuit",
    "PAPER_DUFFING1",
    "PAPER_DUFFING2",
]

#: Paper Table 1 (with b = 12.47 N s/m, the paper's estimate, as the truth for simulation).
PAPER_DUFFING1: dict[str, float] = {"m": 2.53, "b": 12.47, "k": 1272.1, "kp": -1.237e6}
#: Paper Table 3 with m1 from Tables 1 and 4 (2.53 kg) and the damping the issue fixes.
PAPER_DUFFING2: dict[str, float] = {
    "m1": 2.53, "b1": 5.0, "k1": 1272.1, "kp1": -1.237e6,
    "m2": 2.754, "b2": 4.0, "k2": 1570.0, "kp2": -1.350e6,
}


@dataclass(frozen=True)
class Channel:
    """A scalar signal computed from one sample of displacements ``x`` and forces ``f``.

    Parameters
    ----------
    kind : {"x", "deflection", "force", "sign_velocity", "one", "expression"}
        ``x``: displacement of DOF ``index``; ``deflection``: ``(x_i - x_{i-1})**power``
        of element ``index``; ``force``: force input ``index``; ``sign_velocity``: sign of
        the velocity of DOF ``index`` (taken from position increments by the identifier);
        ``one``: the constant 1 (offset term); ``expression``: channel ``index`` of a
        model's own channel function (an equation model's, see
        :class:`~duffid.models.equation_model.EquationModel`).
    index : int
        0-based DOF, element, force or expression index.
    power : int
        Power of a deflection channel.
    text : str
        Readable name of an expression channel.
    """

    kind: str
    index: int = 0
    power: int = 1
    text: str = field(default="", compare=False)

    def evaluate(self, x: np.ndarray, f: np.ndarray) -> np.ndarray:
        """Evaluate the channel on samples ``x`` (..., nx) and ``f`` (..., nf)."""
        if self.kind == "x":
            return x[..., self.index]
        if self.kind == "deflection":
            y = x[..., self.index] - (x[..., self.index - 1] if self.index > 0 else 0.0)
            return y**self.power
        if self.kind == "force":
            return f[..., self.index]
        if self.kind == "one":
            return np.ones(np.shape(x)[:-1])
        raise InputError(f"channel {self.label} needs the identifier's state")

    @property
    def label(self) -> str:
        """Readable name of the channel, e.g. ``(x2-x1)^3``."""
        i = self.index + 1
        if self.kind == "x":
            return f"x{i}"
        if self.kind == "deflection":
            y = f"(x{i}-x{i - 1})" if i > 1 else f"x{i}"
            return y if self.power == 1 else f"{y}^{self.power}"
        if self.kind == "force":
            return f"f{i}"
        if self.kind == "sign_velocity":
            return f"sgn(v{i})"
        if self.kind == "expression":
            return self.text
        return "1"


@dataclass(frozen=True)
class Term:
    """``sign * unknown * d^order/dt^order channel`` in an equation (unknown None: known).

    ``part`` numbers the equations of a joint block (equations that share unknowns and are
    solved together: each part contributes its own rows); 0 for a single equation.
    """

    unknown: str | None
    channel: Channel
    order: int = 0
    sign: float = 1.0
    part: int = 0


@dataclass(frozen=True)
class Equation:
    """One degree-of-freedom equation ``sum(lhs terms) = sum(rhs terms)``.

    ``unknowns`` lists the names of the unknowns in column order. When the DOF has no
    force input the equation is divided by its mass: the unknowns are ratios such as
    ``b2/m2`` and the right-hand side is ``-x2''``.
    """

    dof: int
    unknowns: tuple[str, ...]
    lhs: tuple[Term, ...]
    rhs: tuple[Term, ...]

    @property
    def channels(self) -> tuple[Channel, ...]:
        """Distinct channels used by the equation, in first-use order."""
        seen: dict[Channel, None] = {}
        for term in self.lhs + self.rhs:
            seen.setdefault(term.channel, None)
        return tuple(seen)

    @property
    def max_order(self) -> int:
        """Highest derivative order of any term."""
        return max(t.order for t in self.lhs + self.rhs)

    @property
    def parts(self) -> int:
        """Equations in this block (1 unless several equations are solved together)."""
        return 1 + max(t.part for t in self.lhs + self.rhs)


def _positive(name: str, value: float) -> float:
    value = float(value)
    if not np.isfinite(value) or value <= 0.0:
        raise InputError(f"parameter {name} must be a finite positive number, got {value!r}")
    return value


def _finite(name: str, value: float) -> float:
    value = float(value)
    if not np.isfinite(value):
        raise InputError(f"parameter {name} must be finite, got {value!r}")
    return value


@dataclass(frozen=True)
class Chain:
    """Chain of ``n`` masses from a fixed wall (eqs. 1-5 of the paper).

    Parameters
    ----------
    masses : sequence of float
        ``m_1 .. m_n`` [kg], positive.
    damping : sequence of float
        Viscous damping ``b_i`` of element ``i`` [N s/m].
    stiffness : sequence of mapping
        Per element ``i``, ``{order j: k_i_j}`` [N/m^j]. The union of the orders over all
        elements is the polynomial structure used for identification (``orders``).
    coulomb : sequence of float, optional
        Coulomb friction force ``fc_i`` of each mass [N]; None: no friction terms.
    forced : sequence of int, optional
        0-based DOFs that carry a force input, default ``(0,)``. Force column ``k`` of a
        record acts on DOF ``forced[k]``.
    offset : bool
        Add an unknown constant force per equation (``c<i>``) to the identification
        structure (real data: multiplying by (t-t0)^2 removes initial conditions, not
        biases).
    orders : sequence of int, optional
        Stiffness orders in the identification structure; default: every order present in
        ``stiffness`` plus 1. A zero coefficient of a listed order is still identified.
    """

    masses: tuple[float, ...]
    damping: tuple[float, ...]
    stiffness: tuple[Mapping[int, float], ...]
    coulomb: tuple[float, ...] | None = None
    forced: tuple[int, ...] = (0,)
    offset: bool = False
    orders: tuple[int, ...] | None = None
    #: Public parameters whose value is one over their canonical one (the circuit's C = 1/k1_1).
    reciprocal: ClassVar[tuple[str, ...]] = ()

    def __post_init__(self) -> None:
        n = len(self.masses)
        if n < 1:
            raise InputError("a chain needs at least one mass")
        object.__setattr__(self, "masses", tuple(_positive(f"m{i + 1}", m) for i, m in enumerate(self.masses)))
        if len(self.damping) != n or len(self.stiffness) != n:
            raise InputError(
                f"chain with {n} masses needs {n} damping values and {n} stiffness maps, "
                f"got {len(self.damping)} and {len(self.stiffness)}"
            )
        object.__setattr__(self, "damping", tuple(_finite(f"b{i + 1}", b) for i, b in enumerate(self.damping)))
        stiff = []
        for i, s in enumerate(self.stiffness):
            entry = {}
            for order, value in dict(s).items():
                if int(order) != order or order < 1:
                    raise InputError(f"element {i + 1}: stiffness order must be an integer >= 1, got {order!r}")
                entry[int(order)] = _finite(f"k{i + 1}_{order}", value)
            stiff.append(entry)
        object.__setattr__(self, "stiffness", tuple(stiff))
        if self.orders is None:
            orders = sorted({o for s in stiff for o in s} | {1})
        else:
            orders = sorted(set(int(o) for o in self.orders))
            if not orders or orders[0] < 1:
                raise InputError(f"orders must be integers >= 1, got {self.orders!r}")
            missing = {o for s in stiff for o in s if s[o] != 0.0} - set(orders)
            if missing:
                raise InputError(f"stiffness has orders {sorted(missing)} not listed in orders {orders}")
        object.__setattr__(self, "orders", tuple(orders))
        if self.coulomb is not None:
            if len(self.coulomb) != n:
                raise InputError(f"coulomb needs {n} values, got {len(self.coulomb)}")
            object.__setattr__(self, "coulomb", tuple(_finite(f"fc{i + 1}", c) for i, c in enumerate(self.coulomb)))
        forced = tuple(int(i) for i in self.forced)
        if not forced or len(set(forced)) != len(forced) or any(not 0 <= i < n for i in forced):
            raise InputError(f"forced must list distinct DOF indices in 0..{n - 1}, got {self.forced!r}")
        object.__setattr__(self, "forced", forced)

    # ------------------------------------------------------------------ structure
    @property
    def n_dof(self) -> int:
        """Number of masses."""
        return len(self.masses)

    @property
    def n_forces(self) -> int:
        """Number of force inputs."""
        return len(self.forced)

    @property
    def name(self) -> str:
        """Model name used by the CLI and in JSON output."""
        return "chain"

    def canonical_parameters(self) -> dict[str, float]:
        """Parameter values under canonical names (``m1``, ``b1``, ``k1_3``, ``fc1``, ...)."""
        out: dict[str, float] = {}
        for i in range(self.n_dof):
            out[f"m{i + 1}"] = self.masses[i]
            out[f"b{i + 1}"] = self.damping[i]
            for j in self.orders:
                out[f"k{i + 1}_{j}"] = self.stiffness[i].get(j, 0.0)
            if self.coulomb is not None:
                out[f"fc{i + 1}"] = self.coulomb[i]
        if self.offset:
            out.update({f"c{i + 1}": 0.0 for i in range(self.n_dof)})
        return out

    @property
    def parameters(self) -> dict[str, float]:
        """Parameter values under the model's public names."""
        return self.canonical_parameters()

    def from_canonical(self, values: Mapping[str, float]) -> dict[str, float]:
        """Rename canonical parameter estimates to the model's public names."""
        return dict(values)

    def canonical_name(self, public: str) -> str:
        """Canonical name (``m1``, ``k1_3``, ...) of the public parameter ``public``."""
        if public not in self.parameters:
            raise KeyError(f"{self.name}: no parameter {public!r}; known: {', '.join(self.parameters)}")
        return public

    def equations(self) -> tuple[Equation, ...]:
        """Identification structure: one equation per DOF, linear in its unknowns."""
        eqs = []
        for i in range(self.n_dof):
            forced = i in self.forced
            scale = "" if forced else f"/m{i + 1}"
            lhs: list[Term] = []
            unknowns: list[str] = []

            def add(name: str, channel: Channel, order: int, sign: float = 1.0) -> None:
                unknowns.append(name + scale)
                lhs.append(Term(name + scale, channel, order, sign))

            if forced:
                add(f"m{i + 1}", Channel("x", i), 2)
            add(f"b{i + 1}", Channel("deflection", i, 1), 1)
            for j in self.orders:
                add(f"k{i + 1}_{j}", Channel("deflection", i, j), 0)
            if self.coulomb is not None:
                add(f"fc{i + 1}", Channel("sign_velocity", i), 0)
            if i + 1 < self.n_dof:
                add(f"b{i + 2}", Channel("deflection", i + 1, 1), 1, -1.0)
                for j in self.orders:
                    add(f"k{i + 2}_{j}", Channel("deflection", i + 1, j), 0, -1.0)
            if self.offset:
                add(f"c{i + 1}", Channel("one"), 0)
            if forced:
                rhs = (Term(None, Channel("force", self.forced.index(i)), 0),)
            else:
                rhs = (Term(None, Channel("x", i), 2, -1.0),)
            eqs.append(Equation(i, tuple(unknowns), tuple(lhs), tuple(rhs)))
        return tuple(eqs)


    def equation_text(self) -> str:
        """The model's equations in the syntax of :mod:`duffid.models.equation`.

        One equation per mass in its physical form (force-free masses ``= 0``), with the
        model's public parameter names and the record's column names (``x``, ``f`` for one
        mass and one force, else ``x1 ..``, ``f1 ..``), e.g. for :class:`Duffing1`
        ``m*der(x,2) + b*der(x) + k*x + kp*x^3 = f``. This is what ``--equation NAME``
        stands for. The text states the same model; with one mass it is also the same
        estimator (the same unknowns and rows). With several masses the equation route
        solves the equations that share a coupling as one block, while the named model
        solves each force-free equation for ratios (``b2/m2``, ...) and scales them by a
        coupling found in the forced one: the two are different estimators of the same
        parameters.

        Raises
        ------
        InputError
            For a model whose parameter enters as a reciprocal (the circuit's ``C``, as
            ``q/C``), which an equation linear in its parameters cannot state.
        """
        public = {}
        for name in self.parameters:
            if name in self.reciprocal:
                raise InputError(f"{self.name}: its parameter {name} enters the equation as 1/{name}, which an "
                                 f"equation linear in its parameters cannot state (write it with k = 1/{name})")
            public[self.canonical_name(name)] = name
        n = self.n_dof
        x = ["x"] if n == 1 and self.n_forces == 1 else [f"x{i + 1}" for i in range(n)]
        f = ["f"] if n == 1 and self.n_forces == 1 else [f"f{k + 1}" for k in range(self.n_forces)]

        def deflection(i: int, power: int) -> str:
            y = x[i] if i == 0 else f"({x[i]} - {x[i - 1]})"
            return y if power == 1 else f"{y}^{power}"

        def velocity(i: int) -> str:
            return f"der({x[i]})" if i == 0 else f"(der({x[i]}) - der({x[i - 1]}))"

        texts = []
        for i in range(n):
            terms = [f"{public[f'm{i + 1}']}*der({x[i]},2)", f"{public[f'b{i + 1}']}*{velocity(i)}"]
            terms += [f"{public[f'k{i + 1}_{j}']}*{deflection(i, j)}" for j in self.orders]
            if self.coulomb is not None:
                terms.append(f"{public[f'fc{i + 1}']}*sign(der({x[i]}))")
            if i + 1 < n:
                terms.append(f"- {public[f'b{i + 2}']}*{velocity(i + 1)}")
                terms += [f"- {public[f'k{i + 2}_{j}']}*{deflection(i + 1, j)}" for j in self.orders]
            if self.offset:
                terms.append(f"c{i + 1}")
            rhs = f[self.forced.index(i)] if i in self.forced else "0"
            texts.append(" ".join(t if t.startswith("- ") else f"+ {t}" for t in terms)[2:] + f" = {rhs}")
        return "; ".join(texts)



    # ------------------------------------------------------------------ identification
    # What the identifiers and the checks of duffid.identification need to know about a
    # model's structure; an equation model (duffid.models.equation_model) answers the same.
    def combine_solutions(self, solutions: list[dict[str, float]], errors: list[dict[str, float]] | None = None
                          ) -> tuple[dict[str, float], dict[str, float]]:
        """Canonical parameters (and their relative standard errors) from per-equation solutions.

        A forced DOF's equation gives absolute values; an unforced DOF's equation gives values
        divided by its mass ``m_i``, found from a linear stiffness known on an absolute scale in
        a neighbouring equation. Each element's parameters are taken from the lowest-index
        equation with a known scale. Relative errors of products add in quadrature.
        """
        n = self.n_dof
        errors = errors if errors is not None else [{k: np.nan for k in sol} for sol in solutions]
        # scale[i] = (m_i or 1 for a forced DOF, its relative error)
        scale: list[tuple[float, float] | None] = [(1.0, 0.0) if i in self.forced else None for i in range(n)]

        def lookup(j: int, name: str) -> tuple[float, float] | None:
            key = name if j in self.forced else f"{name}/m{j + 1}"
            if key not in solutions[j] or scale[j] is None:
                return None
            s, es = scale[j]
            return s * solutions[j][key], float(np.hypot(es, errors[j][key]))

        progress = True
        while progress and any(s is None for s in scale):
            progress = False
            for i in range(n):
                if scale[i] is not None:
                    continue
                for e in (i + 1, i + 2):  # left and right element of mass i (1-based elements)
                    key = f"k{e}_1/m{i + 1}"
                    if key not in solutions[i] or solutions[i][key] == 0:
                        continue
                    for j in (e - 2, e - 1):  # the equations that contain element e
                        absolute = lookup(j, f"k{e}_1") if j != i and 0 <= j < n else None
                        if absolute is not None:
                            scale[i] = (absolute[0] / solutions[i][key],
                                        float(np.hypot(absolute[1], errors[i][key])))
                            progress = True
                            break
                    if scale[i] is not None:
                        break
        values: dict[str, float] = {}
        rse: dict[str, float] = {}
        for name in self.canonical_parameters():
            found = None
            if name.startswith("m") and name[1:].isdigit():
                i = int(name[1:]) - 1
                found = (solutions[i][name], errors[i][name]) if i in self.forced else scale[i]
            else:
                for j in range(n):
                    found = lookup(j, name)
                    if found is not None:
                        break
            values[name], rse[name] = found if found is not None else (np.nan, np.inf)
        return values, rse

    def share_sources(self, name: str) -> list[tuple[int, str | None]]:
        """Where canonical parameter ``name`` shows in the equations: ``(equation, unknown)``
        pairs, the unknown None where it is the equation's right-hand side (an unforced
        DOF's mass)."""
        out: list[tuple[int, str | None]] = []
        for j, eq in enumerate(self.equations()):
            key = name if j in self.forced else f"{name}/m{j + 1}"
            if key in eq.unknowns:
                out.append((j, key))
            elif name == f"m{j + 1}" and j not in self.forced:
                out.append((j, None))
        return out

    def is_physical(self, name: str, value: float) -> bool:
        """A mass must be positive and a damping coefficient not negative (a passive plant)."""
        if name[0] == "m" and name[1:].isdigit():
            return value > 0
        if name[0] == "b" and name[1:].isdigit():
            return value >= 0
        return True

    def period_parameters(self) -> tuple[str, ...]:
        """The canonical parameters that set the natural periods (masses, linear stiffnesses)."""
        return tuple(k for k in self.canonical_parameters()
                     if (k[0] == "m" and k[1:].isdigit()) or (k[0] == "k" and k.endswith("_1")))

    def offset_parameters(self) -> dict[str, int]:
        """Constant-force offset parameters and the 0-based equation each acts in."""
        return {f"c{i + 1}": i for i in range(self.n_dof)} if self.offset else {}

    def with_offset(self) -> "Chain":
        """The same model with an unknown constant force per DOF (``c1``, ``c2``, ...)."""
        if self.offset:
            return self
        if type(self) is Chain:
            return dataclasses.replace(self, offset=True)
        return type(self)(**self.parameters, offset=True)  # type: ignore[call-arg]

    def needs_force(self) -> bool:
        """Whether the parameters' scale comes from the force (a record without force gives ratios only)."""
        return True

    def symbolic_acceleration(self, p: Mapping[str, Any], x: Sequence[Any], v: Sequence[Any],
                              f: Sequence[Any], friction_velocity: float) -> list[Any]:
        """Accelerations of a chain, written element by element (works on CasADi symbols).

        ``m_i x_i'' + F_i + fc_i tanh(x_i' / v_f) - F_{i+1} + c_i = f_i`` with the element
        force ``F_i = b_i y_i' + sum_j k_i_j y_i^j`` and deflection ``y_i = x_i - x_{i-1}``:
        the structure of :meth:`~duffid.models.chain.Chain.equations` (offsets included).
        """
        n = self.n_dof
        forces = []
        for i in range(n):
            y = x[i] - x[i - 1] if i else x[i]
            ydot = v[i] - v[i - 1] if i else v[i]
            element = p[f"b{i + 1}"] * ydot
            for j in self.orders:
                element = element + p[f"k{i + 1}_{j}"] * y**j
            forces.append(element)
        acc = []
        for i in range(n):
            net = -forces[i]
            if i + 1 < n:
                net = net + forces[i + 1]
            if i in self.forced:
                net = net + f[self.forced.index(i)]
            if self.coulomb is not None:
                net = net - p[f"fc{i + 1}"] * ca.tanh(v[i] / friction_velocity)
            if self.offset:
                net = net - p[f"c{i + 1}"]
            acc.append(net / p[f"m{i + 1}"])
        return acc

    def term_shares(self, canonical: Mapping[str, float], x: np.ndarray, f: np.ndarray,
                    dt: float) -> dict[str, float]:
        """Share of each canonical parameter's term in the force balance of the DOFs it acts on.

        The terms (``m x''``, ``b y'``, ``k_j y^j``, ``fc sgn(v)``, ``c``) are evaluated on a
        smooth displacement ``x`` (e.g. the identified model's simulation) with central
        differences for the derivatives; a term's share is its RMS over the RMS of the
        quadratic sum of all terms on that DOF (largest over the DOFs it acts on).
        """
        x = np.asarray(x, dtype=float).reshape(len(x), -1)
        n_dof = x.shape[1]
        v = np.gradient(x, dt, axis=0, edge_order=2)
        a = np.gradient(v, dt, axis=0, edge_order=2)
        zeros = np.zeros((len(x), 1))
        y = x - np.concatenate([zeros, x[:, :-1]], axis=1)
        yd = v - np.concatenate([zeros, v[:, :-1]], axis=1)
        terms: dict[str, tuple[np.ndarray, tuple[int, ...]]] = {}
        for i in range(n_dof):
            acts = (i,) if i == 0 else (i, i - 1)     # element i joins DOF i-1 and DOF i
            for name, value in canonical.items():
                if name == f"m{i + 1}":
                    terms[name] = (value * a[:, i], (i,))
                elif name == f"b{i + 1}":
                    terms[name] = (value * yd[:, i], acts)
                elif name.startswith(f"k{i + 1}_"):
                    power = int(name.split("_", 1)[1])
                    terms[name] = (value * y[:, i] ** power, acts)
                elif name == f"fc{i + 1}":
                    terms[name] = (value * np.sign(v[:, i]), (i,))
                elif name == f"c{i + 1}":
                    terms[name] = (np.full(len(x), value), (i,))
        balance = np.zeros(n_dof)
        for series, dofs in terms.values():
            for d in dofs:
                balance[d] += float(np.mean(series**2))
        force = np.asarray(f, dtype=float).reshape(len(f), -1)
        for j in range(min(force.shape[1], n_dof)):
            balance[j] += float(np.mean(force[:, j] ** 2))
        out = {}
        for name, (series, dofs) in terms.items():
            rms = math.sqrt(float(np.mean(series**2)))
            out[name] = max(rms / math.sqrt(balance[d]) if balance[d] > 0 else math.nan for d in dofs)
        return out

    # ------------------------------------------------------------------ dynamics
    def with_parameters(self, **values: float) -> "Chain":
        """A copy with some canonical parameters replaced."""
        current = self.canonical_parameters()
        unknown = set(values) - set(current)
        if unknown:
            raise InputError(f"unknown parameters {sorted(unknown)}; known: {sorted(current)}")
        current.update(values)
        return _chain_from_canonical(self, current)

    def element_forces(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Force carried by each element, shape (..., n)."""
        x = np.asarray(x, dtype=float)
        v = np.asarray(v, dtype=float)
        zeros = np.zeros_like(x[..., :1])
        y = x - np.concatenate([zeros, x[..., :-1]], axis=-1)
        ydot = v - np.concatenate([zeros, v[..., :-1]], axis=-1)
        force = np.asarray(self.damping) * ydot
        for j in self.orders:
            kj = np.array([s.get(j, 0.0) for s in self.stiffness])
            force = force + kj * y**j
        return force

    def acceleration(self, x: np.ndarray, v: np.ndarray, f: np.ndarray,
                     friction_velocity: float = 1e-4) -> np.ndarray:
        """Accelerations for displacements ``x``, velocities ``v`` and forces ``f``.

        Coulomb friction is smoothed as ``fc * tanh(v / friction_velocity)`` so that an
        adaptive ODE solver can integrate it (documented approximation of sgn).
        """
        element = self.element_forces(x, v)
        right = np.concatenate([element[..., 1:], np.zeros_like(element[..., :1])], axis=-1)
        applied = np.zeros_like(element)
        applied[..., list(self.forced)] = f
        net = applied - element + right
        if self.coulomb is not None:
            net = net - np.asarray(self.coulomb) * np.tanh(v / friction_velocity)
        return net / np.asarray(self.masses)

    def linear_matrices(self, parameters: Mapping[str, float] | None = None
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Mass, damping and stiffness matrices of the chain linearised about x = 0, from canonical
        ``parameters`` (default: the model's values); linear in the masses, dampings and linear
        stiffnesses (a missing damping or stiffness counts as 0)."""
        p = self.canonical_parameters() if parameters is None else parameters
        n = self.n_dof

        def chain_matrix(values: np.ndarray) -> np.ndarray:
            A = np.diag(values)
            A[:-1, :-1] += np.diag(values[1:])
            A[np.arange(n - 1), np.arange(1, n)] = -values[1:]
            A[np.arange(1, n), np.arange(n - 1)] = -values[1:]
            return A

        k = np.array([p.get(f"k{i + 1}_1", 0.0) for i in range(n)])
        b = np.array([p.get(f"b{i + 1}", 0.0) for i in range(n)])
        m = np.array([p[f"m{i + 1}"] for i in range(n)])
        return np.diag(m), chain_matrix(b), chain_matrix(k)

    def linear_natural_frequencies(self, parameters: Mapping[str, float] | None = None) -> np.ndarray:
        """Undamped natural frequencies [rad/s] of the linearised chain about x = 0."""
        M, _, K = self.linear_matrices(parameters)
        eig = np.linalg.eigvals(np.linalg.solve(M, K))
        return np.sqrt(np.sort(np.abs(eig.real)))

    def linear_poles(self, parameters: Mapping[str, float] | None = None) -> np.ndarray:
        """Poles [rad/s] of the chain linearised about x = 0 (viscous damping included)."""
        M, B, K = self.linear_matrices(parameters)
        n = self.n_dof
        A = np.block([[np.zeros((n, n)), np.eye(n)], [-np.linalg.solve(M, K), -np.linalg.solve(M, B)]])
        return np.linalg.eigvals(A)


def _chain_from_canonical(template: Chain, values: Mapping[str, float]) -> Chain:
    n = template.n_dof
    stiffness = [{j: values[f"k{i + 1}_{j}"] for j in template.orders} for i in range(n)]
    new = Chain(
        masses=tuple(values[f"m{i + 1}"] for i in range(n)),
        damping=tuple(values[f"b{i + 1}"] for i in range(n)),
        stiffness=tuple(stiffness),
        coulomb=None if template.coulomb is None else tuple(values[f"fc{i + 1}"] for i in range(n)),
        forced=template.forced,
        offset=template.offset,
        orders=template.orders,
    )
    if type(template) is Chain:
        return new
    return template._rebuild(new)  # type: ignore[attr-defined]


class _Named(Chain):
    """A chain whose parameters carry the paper's names."""

    _names: dict[str, str] = {}  # public name -> canonical name

    @property
    def parameters(self) -> dict[str, float]:
        return self.from_canonical(self.canonical_parameters())

    def _to_public(self, public: str, canonical: Mapping[str, float]) -> float:
        return canonical[self._names[public]]

    def canonical_name(self, public: str) -> str:
        if public in self._names:
            return self._names[public]
        return super().canonical_name(public)

    def from_canonical(self, values: Mapping[str, float]) -> dict[str, float]:
        out = {public: self._to_public(public, values) for public in self._names}
        if self.offset:  # offsets keep their canonical names c1, c2, ...
            out.update({f"c{i + 1}": values[f"c{i + 1}"] for i in range(self.n_dof)})
        return out

    def _rebuild(self, chain: Chain) -> "_Named":
        params = {public: self._to_public(public, chain.canonical_parameters()) for public in self._names}
        return type(self)(**params, offset=chain.offset)  # type: ignore[call-arg]


class Duffing1(_Named):
    """One-DOF Duffing oscillator ``m x'' + b x' + k x + kp x^3 = f`` (eqs. 10-11).

    Defaults are :data:`PAPER_DUFFING1` (the paper's Table 1 with ``b = 12.47`` N s/m).
    """

    _names = {"m": "m1", "b": "b1", "k": "k1_1", "kp": "k1_3"}

    def __init__(self, m: float = PAPER_DUFFING1["m"], b: float = PAPER_DUFFING1["b"], k: float = PAPER_DUFFING1["k"],
                 kp: float = PAPER_DUFFING1["kp"], *, offset: bool = False) -> None:
        super().__init__(masses=(m,), damping=(b,), stiffness=({1: k, 3: kp},), offset=offset,
                         orders=(1, 3))

    @property
    def name(self) -> str:
        return "duffing1"


class Duffing2(_Named):
    """Two-DOF chain wall-m1-m2 of Figure 9, force on m1 (eqs. 20-21).

    ``m1 x1'' + b1 x1' + k1 x1 + kp1 x1^3 + b2 (x1' - x2') + k2 (x1 - x2) - kp2 (x2 - x1)^3 = f1``
    and ``m2 x2'' + b2 (x2' - x1') + k2 (x2 - x1) + kp2 (x2 - x1)^3 = 0``.
    """

    _names = {"m1": "m1", "b1": "b1", "k1": "k1_1", "kp1": "k1_3",
              "b2": "b2", "k2": "k2_1", "kp2": "k2_3", "m2": "m2"}

    def __init__(self, m1: float = PAPER_DUFFING2["m1"], b1: float = PAPER_DUFFING2["b1"],
                 k1: float = PAPER_DUFFING2["k1"], kp1: float = PAPER_DUFFING2["kp1"],
                 m2: float = PAPER_DUFFING2["m2"], b2: float = PAPER_DUFFING2["b2"],
                 k2: float = PAPER_DUFFING2["k2"], kp2: float = PAPER_DUFFING2["kp2"],
                 *, offset: bool = False) -> None:
        super().__init__(masses=(m1, m2), damping=(b1, b2),
                         stiffness=({1: k1, 3: kp1}, {1: k2, 3: kp2}), offset=offset,
                         orders=(1, 3))

    @property
    def name(self) -> str:
        return "duffing2"


class DuffingCircuit(_Named):
    """Series circuit ``L q'' + R q' + q/C + a q^3 = u`` (charge q, source voltage u).

    The same equation as :class:`Duffing1` with ``m = L``, ``b = R``, ``k = 1/C`` and
    ``kp = a``; records hold ``q`` in the displacement column and ``u`` in the force column.
    """

    _names = {"L": "m1", "R": "b1", "C": "k1_1", "a": "k1_3"}
    reciprocal: ClassVar[tuple[str, ...]] = ("C",)

    def __init__(self, L: float = 0.1, R: float = 2.0, C: float = 1e-3, a: float = 5e6,
                 *, offset: bool = False) -> None:
        super().__init__(masses=(L,), damping=(R,), stiffness=({1: 1.0 / _positive("C", C), 3: a},),
                         offset=offset, orders=(1, 3))

    def _to_public(self, public: str, canonical: Mapping[str, float]) -> float:
        value = canonical[self._names[public]]
        if public in self.reciprocal:
            return 1.0 / value if value != 0.0 else float("inf")
        return value

    @property
    def name(self) -> str:
        return "circuit"
