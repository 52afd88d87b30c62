"""DAE to ODE: causalisation, simple index reduction and tearing of a :class:`FlatModel`.

The residual equations ``0 = r(der(x), x, z, u, p, t)`` become an explicit ODE with all
dependent variables computed from time, states, inputs and parameters:

1. An equation with one unknown that appears linearly is solved for it and the
   solution substituted everywhere (this removes connection aliases, flow balances
   and all explicit component equations).
2. An equation left without unknowns that still depends on states is a constraint
   between states (an index-2 DAE such as ``s_rel = flange_b.s - flange_a.s`` of a
   damper on a mass): one of its states (one without ``fixed = true``) is demoted to
   an algebraic variable and the differentiated constraint ``d/dt g = 0`` (a
   directional derivative, ``jtimes``) is added. Constraints involving inputs are
   rejected (they would need input derivatives).
3. When no equation has a single linear unknown, the rest is sorted into strongly
   connected blocks (matching + Tarjan). A linear block is solved symbolically; in a
   nonlinear block one variable is torn (made an iteration variable) and elimination
   resumes; the equations left over become residuals of a Newton solver
   (``casadi.rootfinder`` with the code-generatable ``fast_newton`` method).
4. A structurally singular system (an index problem the simple reduction does not
   expose) or an unbalanced one is an error naming the equations and variables.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca

from ..errors import ModelicaExportError
from .flat_model import FlatModel, Variable

__all__ = ["OdeModel", "causalize"]

#: Stopping tolerances of the embedded Newton solver (residual and step, absolute).
NEWTON_OPTIONS = {"abstol": 1e-13, "abstolStep": 1e-14, "max_iter": 100}


@dataclass
class OdeModel:
    """The explicit form of a flat model.

    ``function(time, x, u, p, guess) -> (der_x, values, tears, residuals)`` computes the
    state derivatives, the values of ``computed`` variables (in that order), the solution
    of the torn nonlinear equations (Newton started from ``guess``) and their residuals
    at that solution (the generated C code rejects a solution whose residual is large).
    """

    flat: FlatModel
    states: list[Variable]
    derivatives: list[Variable]
    inputs: list[Variable]
    parameters: list[Variable]
    tears: list[Variable]
    computed: list[Variable]
    function: ca.Function
    demoted: list[str] = field(default_factory=list)
    linear_blocks: list[list[str]] = field(default_factory=list)
    residuals: int = 0

    def summary(self) -> str:
        """One line describing the structure (states, index reduction, loops)."""
        parts = [f"{len(self.states)} states", f"{len(self.computed)} computed variables"]
        if self.demoted:
            parts.append("index reduction demoted " + ", ".join(self.demoted))
        if self.linear_blocks:
            parts.append(f"{len(self.linear_blocks)} linear blocks")
        if self.tears:
            parts.append("Newton on " + ", ".join(v.name for v in self.tears))
        return "; ".join(parts)


def _names(expr: ca.SX) -> set[str]:
    return {s.name() for s in ca.symvar(expr)}


def _short(expr: ca.SX, limit: int = 120) -> str:
    text = str(expr)
    return text if len(text) <= limit else text[:limit] + "..."


def _match(equations: list[set[str]], unknowns: list[str]) -> dict[int, str]:
    """Maximum matching equation index -> unknown (augmenting paths)."""
    owner: dict[str, int] = {}

    def augment(i: int, seen: set[str]) -> bool:
        for u in equations[i]:
            if u in seen:
                continue
            seen.add(u)
            if u not in owner or augment(owner[u], seen):
                owner[u] = i
                return True
        return False

    for i in range(len(equations)):
        augment(i, set())
    return {i: u for u, i in owner.items()}


def _blocks(equations: list[set[str]], matching: dict[int, str]) -> list[list[int]]:
    """Strongly connected components, dependencies first (Tarjan)."""
    solver_of = {u: i for i, u in matching.items()}
    graph = {i: sorted({solver_of[u] for u in eq if u in solver_of and solver_of[u] != i})
             for i, eq in enumerate(equations)}
    index: dict[int, int] = {}
    low: dict[int, int] = {}
    stack: list[int] = []
    on_stack: set[int] = set()
    out: list[list[int]] = []
    counter = [0]

    def visit(v: int) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            out.append(sorted(component))

    for v in range(len(equations)):
        if v not in index:
            visit(v)
    return out


class _Causalizer:
    def __init__(self, flat: FlatModel) -> None:
        self.flat = flat
        self.by_name = {v.name: v for v in flat.variables}
        self.states = flat.role("state")
        self.derivative_of = {v.state: v for v in flat.role("derivative")}
        calculated = flat.role("calculated")
        equations = list(flat.equations)
        if calculated:
            equations = ca.substitute(equations, [v.symbol for v in calculated], [v.value for v in calculated])
        self.pending: list[ca.SX] = list(equations)
        self.unknown: set[str] = {v.name for v in flat.role("derivative") + flat.role("algebraic")}
        self.input_names = {v.name for v in flat.role("input")}
        self.solved: dict[str, ca.SX] = {}
        self.order: list[str] = []
        self.tears: list[Variable] = []
        self.residuals: list[ca.SX] = []
        self.demoted: list[str] = []
        self.linear_blocks: list[list[str]] = []
        if len(self.pending) != len(self.unknown):
            raise ModelicaExportError(
                f"model {flat.class_name} is not balanced: {len(self.pending)} equations for "
                f"{len(self.unknown)} unknowns (derivatives and algebraic variables)")

    # ------------------------------------------------------------------ bookkeeping
    def record(self, names: list[str], exprs: list[ca.SX]) -> None:
        syms = [self.by_name[n].symbol for n in names]
        if self.pending:
            self.pending = ca.substitute(self.pending, syms, exprs)
        if self.residuals:
            self.residuals = ca.substitute(self.residuals, syms, exprs)
        if self.solved:
            keys = list(self.solved)
            values = ca.substitute([self.solved[k] for k in keys], syms, exprs)
            self.solved = dict(zip(keys, values))
        for n, e in zip(names, exprs):
            self.solved[n] = e
            self.order.append(n)
            self.unknown.discard(n)

    def unknowns_in(self, expr: ca.SX) -> set[str]:
        return _names(expr) & self.unknown

    # ------------------------------------------------------------------ index reduction
    def reduce_index(self, g: ca.SX) -> None:
        names = _names(g)
        inputs = sorted(names & self.input_names)
        if inputs:
            raise ModelicaExportError(
                f"unsupported construct: constraint {_short(g)} = 0 involves input(s) {inputs}; index "
                f"reduction would need their derivatives (model {self.flat.class_name})")
        candidates = [s for s in self.states if s.name in names]
        free = [s for s in candidates if not s.fixed]
        if not free:
            raise ModelicaExportError(
                f"constraint {_short(g)} = 0 between states {[s.name for s in candidates]} that all have "
                f"fixed = true: over-determined initial values (model {self.flat.class_name}; "
                f"declared in {self.flat.locate(candidates[0].name)})")
        chosen = free[-1]
        self.states = [s for s in self.states if s is not chosen]
        self.demoted.append(chosen.name)
        x = ca.vertcat(*[s.symbol for s in candidates])
        dx = ca.vertcat(*[self.derivative_of[s.name].symbol for s in candidates])
        dg = ca.jtimes(g, x, dx) + ca.jacobian(g, self.flat.time)
        if self.solved:
            keys = list(self.solved)
            dg = ca.substitute([dg], [self.by_name[k].symbol for k in keys], [self.solved[k] for k in keys])[0]
        self.unknown.add(chosen.name)
        self.pending.append(g)
        self.pending.append(dg)

    # ------------------------------------------------------------------ main loop
    def eliminate(self) -> bool:
        """One sweep of single-unknown solves and constraint handling; True on progress."""
        progress = False
        i = 0
        while i < len(self.pending):
            eq = self.pending[i]
            unknown = self.unknowns_in(eq)
            if not unknown:
                del self.pending[i]
                names = _names(eq)
                if names & {t.name for t in self.tears}:
                    self.residuals.append(eq)
                elif names & {s.name for s in self.states}:
                    self.reduce_index(eq)
                    return True
                elif eq.is_zero():
                    pass  # redundant equation 0 = 0
                else:
                    raise ModelicaExportError(
                        f"equation {_short(eq)} = 0 has no unknowns left (over-determined or inconsistent "
                        f"model {self.flat.class_name})")
                progress = True
                continue
            if len(unknown) == 1:
                name = next(iter(unknown))
                sym = self.by_name[name].symbol
                d = ca.jacobian(eq, sym)
                if not ca.depends_on(d, sym) and not d.is_zero():
                    rest = ca.substitute(eq, sym, ca.SX(0))
                    del self.pending[i]
                    self.record([name], [ca.simplify(-rest / d)])
                    progress = True
                    continue
            i += 1
        return progress

    def stuck(self) -> None:
        """No single-unknown equation left: solve the first block or tear a variable."""
        unknowns = sorted(self.unknown)
        sets = [self.unknowns_in(eq) for eq in self.pending]
        matching = _match(sets, unknowns)
        if len(matching) < len(self.pending) or len(matching) < len(unknowns):
            free_eqs = [_short(self.pending[i], 80) for i in range(len(self.pending)) if i not in matching]
            free_vars = sorted(set(unknowns) - set(matching.values()))
            where = self.flat.locate(free_vars[0]) if free_vars else self.flat.class_name
            raise ModelicaExportError(
                f"structurally singular system in {self.flat.class_name}: equations {free_eqs} and variables "
                f"{free_vars} cannot be matched (a higher-index constraint the simple index reduction does "
                f"not expose; first variable declared in {where})")
        block = _blocks(sets, matching)[0]
        eqs = [self.pending[i] for i in block]
        names = [matching[i] for i in block]
        syms = ca.vertcat(*[self.by_name[n].symbol for n in names])
        residual = ca.vertcat(*eqs)
        jac = ca.jacobian(residual, syms)
        if not ca.depends_on(jac, syms):
            rest = ca.substitute(residual, syms, ca.SX.zeros(syms.shape))
            solution = ca.solve(jac, -rest)
            for i in sorted(block, reverse=True):
                del self.pending[i]
            self.linear_blocks.append(names)
            self.record(names, [ca.simplify(solution[k]) for k in range(len(names))])
            return
        counts = {n: sum(n in sets[i] for i in block) for n in names}
        tear = max(names, key=lambda n: (counts[n], -names.index(n)))
        self.tears.append(self.by_name[tear])
        self.unknown.discard(tear)

    def run(self) -> None:
        while self.pending:
            if not self.eliminate() and self.pending:
                self.stuck()
        if len(self.residuals) != len(self.tears):
            raise ModelicaExportError(
                f"{len(self.residuals)} residual equations for {len(self.tears)} iteration variables in "
                f"{self.flat.class_name} (inconsistent algebraic loop)")
        if self.unknown:
            raise ModelicaExportError(f"variables {sorted(self.unknown)} of {self.flat.class_name} are not "
                                      "determined by any equation")


def causalize(flat: FlatModel) -> OdeModel:
    """Turn a flat DAE into an explicit ODE function (see the module docstring).

    Raises
    ------
    ModelicaExportError
        Unbalanced or structurally singular systems, constraints on inputs, inconsistent
        algebraic loops.
    """
    work = _Causalizer(flat)
    work.run()
    states = work.states
    derivatives = [work.derivative_of[s.name] for s in states]
    tears = work.tears
    inputs = flat.role("input")
    parameters = flat.role("parameter")
    state_names = {s.name for s in states}
    known = state_names | {v.name for v in inputs + parameters}
    computed = [v for v in flat.variables if v.name not in known]
    # the demoted states and their derivatives are ordinary computed variables now
    for v in flat.role("state"):
        if v.name not in state_names:
            v.role = "algebraic"
    for v in flat.role("derivative"):
        if v.state not in state_names:
            v.role = "algebraic"

    def value(v: Variable) -> ca.SX:
        if v.role == "calculated":
            return v.value  # type: ignore[return-value]
        if v.name in work.solved:
            return work.solved[v.name]
        if any(t is v for t in tears):
            return v.symbol
        raise ModelicaExportError(f"no value for {v.name} in {flat.class_name}")

    t = flat.time
    x = ca.vertcat(*[s.symbol for s in states])
    u = ca.vertcat(*[v.symbol for v in inputs])
    p = ca.vertcat(*[v.symbol for v in parameters])
    z = ca.vertcat(*[v.symbol for v in tears])
    xdot = ca.vertcat(*[value(d) for d in derivatives])
    values = ca.vertcat(*[value(v) for v in computed])
    names_in = ["time", "x", "u", "p", "guess"]
    names_out = ["der_x", "values", "tears", "residuals"]
    if not tears:
        guess = ca.SX.sym("guess", 0, 1)
        function = ca.Function("model_eval", [t, x, u, p, guess], [xdot, values, ca.SX(0, 1), ca.SX(0, 1)],
                               names_in, names_out)
    else:
        known_vec = ca.vertcat(t, x, u, p)
        residual = ca.vertcat(*work.residuals)
        solver = ca.rootfinder("newton", "fast_newton", {"x": z, "p": known_vec, "g": residual},
                               NEWTON_OPTIONS)
        post = ca.Function("post", [t, x, u, p, z], [xdot, values, residual])
        mt, mx, mu, mp = (ca.MX.sym("time"), ca.MX.sym("x", x.shape), ca.MX.sym("u", u.shape),
                          ca.MX.sym("p", p.shape))
        mg = ca.MX.sym("guess", z.shape)
        mz = solver(mg, ca.vertcat(mt, mx, mu, mp))
        mxdot, mvalues, mres = post(mt, mx, mu, mp, mz)
        function = ca.Function("model_eval", [mt, mx, mu, mp, mg], [mxdot, mvalues, mz, mres],
                               names_in, names_out)
    return OdeModel(flat=flat, states=states, derivatives=derivatives, inputs=inputs, parameters=parameters,
                    tears=tears, computed=computed, function=function, demoted=work.demoted,
                    linear_blocks=work.linear_blocks, residuals=len(work.residuals))
