"""Integrated-by-parts regressors derived symbolically with CasADi from a model equation.

Input: equations ``residual(x, x', x'', f, t; theta) = 0`` linear in the parameters
``theta``, as text (``"m*der(x,2) + b*der(x) + k*x + kp*x^3 = f"``, parsed by a small
recursive-descent parser: no ``eval``) or as CasADi SX expressions. Output: a
:class:`DerivedRegressor`, the equation multiplied by ``tau^n`` (``tau = t - t0``, ``n`` the
highest derivative order) and integrated by parts ``n`` times::

    int^(n) tau^n g^(d) = sum_k (-1)^k C(d, k) n!/(n-k)! int^(n-d+k) tau^(n-k) g

so that it holds only iterated integrals of ``tau^j g(x, f, t)``: no derivative of a
measured signal and no initial condition is left. It comes as CasADi Functions (and
generated C): ``bank`` (the integrator inputs ``tau^j g``), ``rows`` (the rows
``A theta = D`` of eqs. 16-17 from the integrator outputs) and ``channels`` (the ``g``),
with the list of integrator channels :attr:`DerivedRegressor.bank`.

What a derivative may do
------------------------
- ``der(x,2)`` times parameters and numbers;
- ``der(x)`` times a polynomial in the displacements whose coefficients of the
  ``der(x_i)`` form a gradient: ``sum_i g_i(x) x_i' = d/dt G(x)``, integrated by parts
  exactly (``G`` by Gauss-Legendre quadrature along the ray ``s x``, exact for polynomials);
- ``sign(der(x))``: a signal of its own, from the sign of position increments.

Any other use (``der(x)^2``, ``abs(der(x))``, ``x*der(x,2)``, ``sin(t)*der(x)``,
``der(f)``) is rejected with an error that names the term.

Text syntax
-----------
Numbers, names, ``+ - * / ^`` (``**`` too), parentheses and the functions ``abs``,
``sign``, ``sin``, ``cos``, ``exp`` and ``der(name)`` / ``der(name, 2)``. Names that are
columns of the record (``t``, ``f``, ``x`` or ``f1 ..``, ``x1 ..``) are signals; every
other name is an unknown parameter. Several equations (one per degree of freedom) are
separated by ``;``; a parameter named in several equations is one unknown, and such
equations are solved together by the buffered methods.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from math import comb, factorial
from pathlib import Path
from typing import Sequence

import casadi as ca
import numpy as np

from ..errors import EquationError, InputError, OptionError
from .regression import LinearTerm, Regression

__all__ = [
    "EquationError",
    "Signals",
    "IntegratorChannel",
    "DerivedRegressor",
    "parse_equations",
    "derive",
    "derive_regressor",
]

_FUNCTIONS = ("abs", "sign", "sin", "cos", "exp", "der")




# ---------------------------------------------------------------------- parser
@dataclass(frozen=True)
class _Node:
    kind: str                 # num, name, neg, add, sub, mul, div, pow, call
    text: str                 # source text of the node
    value: float = 0.0
    name: str = ""
    args: tuple["_Node", ...] = ()


_TOKEN = re.compile(r"\s*(?:(\d+\.?\d*(?:[eE][+-]?\d+)?|\.\d+(?:[eE][+-]?\d+)?)"  # number
                    r"|([A-Za-z_][A-Za-z_0-9]*)"                                # name
                    r"|(\*\*|[-+*/^(),=]))")                                      # operator


class _Parser:
    """Recursive descent over ``expr = expr``; every node keeps its source text."""

    def __init__(self, text: str) -> None:
        self.text = text
        self.tokens: list[tuple[str, str, int, int]] = []  # (kind, value, start, end)
        pos = 0
        while pos < len(text):
            if text[pos:].strip() == "":
                break
            m = _TOKEN.match(text, pos)
            if not m:
                raise EquationError(f"unexpected character {text[pos:].lstrip()[0]!r} at position "
                                    f"{len(text) - len(text[pos:].lstrip()) + 1} of {text!r}")
            kind = "num" if m.group(1) else "name" if m.group(2) else "op"
            value = m.group(1) or m.group(2) or ("^" if m.group(3) == "**" else m.group(3))
            self.tokens.append((kind, value, m.start(m.lastindex), m.end()))
            pos = m.end()
        self.i = 0

    def _peek(self) -> tuple[str, str, int, int] | None:
        return self.tokens[self.i] if self.i < len(self.tokens) else None

    def _take(self, value: str | None = None) -> tuple[str, str, int, int]:
        tok = self._peek()
        if tok is None:
            raise EquationError(f"unexpected end of {self.text!r}" + (f": expected {value!r}" if value else ""))
        if value is not None and tok[1] != value:
            raise EquationError(f"expected {value!r} at position {tok[2] + 1} of {self.text!r}, found {tok[1]!r}")
        self.i += 1
        return tok

    def _span(self, start: int, end: int) -> str:
        return self.text[start:end].strip()

    def equation(self) -> tuple[_Node, _Node]:
        lhs = self.expr()
        self._take("=")
        rhs = self.expr()
        if self._peek() is not None:
            tok = self._peek()
            raise EquationError(f"unexpected {tok[1]!r} at position {tok[2] + 1} of {self.text!r}")
        return lhs, rhs

    def expr(self) -> _Node:
        start = self._peek()[2] if self._peek() else len(self.text)
        node = self.term()
        while self._peek() is not None and self._peek()[1] in "+-" and self._peek()[0] == "op":
            op = self._take()[1]
            right = self.term()
            text = self._span(start, self.tokens[self.i - 1][3])
            node = _Node("add" if op == "+" else "sub", text, args=(node, right))
        return node

    def term(self) -> _Node:
        start = self._peek()[2] if self._peek() else len(self.text)
        node = self.unary()
        while self._peek() is not None and self._peek()[1] in ("*", "/") and self._peek()[0] == "op":
            op = self._take()[1]
            right = self.unary()
            text = self._span(start, self.tokens[self.i - 1][3])
            node = _Node("mul" if op == "*" else "div", text, args=(node, right))
        return node

    def unary(self) -> _Node:
        tok = self._peek()
        if tok is not None and tok[0] == "op" and tok[1] in "+-":
            self._take()
            operand = self.unary()
            text = self._span(tok[2], self.tokens[self.i - 1][3])
            return operand if tok[1] == "+" else _Node("neg", text, args=(operand,))
        return self.power()

    def power(self) -> _Node:
        start = self._peek()[2] if self._peek() else len(self.text)
        base = self.atom()
        if self._peek() is not None and self._peek()[1] == "^":
            self._take()
            exponent = self.unary()  # right associative, binds tighter than unary minus on its left
            return _Node("pow", self._span(start, self.tokens[self.i - 1][3]), args=(base, exponent))
        return base

    def atom(self) -> _Node:
        tok = self._take()
        kind, value, start, _ = tok
        if kind == "num":
            return _Node("num", value, value=float(value))
        if kind == "name":
            if self._peek() is not None and self._peek()[1] == "(":
                if value not in _FUNCTIONS:
                    raise EquationError(f"unknown function {value!r} in {self.text!r}; "
                                        f"known: {', '.join(_FUNCTIONS)}")
                self._take("(")
                args = [self.expr()]
                while self._peek() is not None and self._peek()[1] == ",":
                    self._take(",")
                    args.append(self.expr())
                self._take(")")
                return _Node("call", self._span(start, self.tokens[self.i - 1][3]), name=value, args=tuple(args))
            if value in _FUNCTIONS:
                raise EquationError(f"{value!r} is a function: write {value}(...) in {self.text!r}")
            return _Node("name", value, name=value)
        if value == "(":
            node = self.expr()
            self._take(")")
            return _Node(node.kind, self._span(start, self.tokens[self.i - 1][3]), node.value, node.name, node.args)
        raise EquationError(f"unexpected {value!r} at position {start + 1} of {self.text!r}")


def _additive_terms(node: _Node, sign: float = 1.0) -> list[tuple[float, _Node]]:
    """Top-level terms of a sum, with their signs."""
    if node.kind == "add":
        return _additive_terms(node.args[0], sign) + _additive_terms(node.args[1], sign)
    if node.kind == "sub":
        return _additive_terms(node.args[0], sign) + _additive_terms(node.args[1], -sign)
    if node.kind == "neg":
        return _additive_terms(node.args[0], -sign)
    return [(sign, node)]


# ---------------------------------------------------------------------- signals
class Signals:
    """CasADi symbols of the measured signals of a record layout.

    Parameters
    ----------
    columns : sequence of str
        Record columns: ``t, f, x`` or ``t, f1 .. f<nf>, x1 .. x<nx>``.

    Attributes
    ----------
    x, dx, ddx, sgn : list of SX
        Displacements, their first and second derivatives and the signs of velocity.
    f : list of SX
        Forces.
    t : SX
        Time.
    """

    def __init__(self, columns: Sequence[str]) -> None:
        columns = list(columns)
        self.columns = tuple(columns)
        self.x_names = [c for c in columns if re.fullmatch(r"x\d*", c)]
        self.f_names = [c for c in columns if re.fullmatch(r"f\d*", c)]
        if not self.x_names or "t" not in columns:
            raise EquationError(f"record columns {columns} have no time or displacement column")
        self.x = [ca.SX.sym(n) for n in self.x_names]
        self.dx = [ca.SX.sym(f"der({n})") for n in self.x_names]
        self.ddx = [ca.SX.sym(f"der({n},2)") for n in self.x_names]
        self.sgn = [ca.SX.sym(f"sign(der({n}))") for n in self.x_names]
        self.f = [ca.SX.sym(n) for n in self.f_names]
        self.t = ca.SX.sym("t")

    @property
    def n_dof(self) -> int:
        """Displacement columns."""
        return len(self.x)

    @property
    def n_forces(self) -> int:
        """Force columns."""
        return len(self.f)

    def measured(self) -> list[ca.SX]:
        """Inputs of a channel: x, f, t, sgn (as column vectors)."""
        return [ca.vertcat(*self.x), ca.vertcat(*self.f) if self.f else ca.SX(0, 1), self.t, ca.vertcat(*self.sgn)]


@dataclass(frozen=True)
class _Parsed:
    texts: tuple[str, ...]
    residuals: tuple[ca.SX, ...]
    parameters: tuple[tuple[str, ...], ...]
    terms: tuple[tuple[tuple[str, ca.SX], ...], ...]  # (text, signed SX) of each user term
    symbols: dict[str, ca.SX]


def parse_equations(equations: str | Sequence[str], columns: Sequence[str]
                    ) -> tuple[list[ca.SX], list[list[ca.SX]], Signals]:
    """Parse ``;``-separated equations over the record ``columns`` into CasADi residuals.

    Returns
    -------
    residuals : list of casadi.SX
        ``lhs - rhs`` of each equation.
    parameters : list of list of casadi.SX
        The parameter symbols of each equation, in order of appearance (one symbol per
        name across equations).
    signals : Signals
        The signal symbols the residuals use.
    """
    signals = Signals(columns)
    parsed = _parse(_split_equations(equations), signals)
    return (list(parsed.residuals), [[parsed.symbols[n] for n in names] for names in parsed.parameters],
            signals)


def _split_equations(equations: str | Sequence[str]) -> list[str]:
    texts = [equations] if isinstance(equations, str) else list(equations)
    if not all(isinstance(t, str) for t in texts):
        raise OptionError(f"equations must be text, got {equations!r}")
    texts = [t.strip() for part in texts for t in part.split(";") if t.strip()]
    if not texts:
        raise EquationError("no equation given")
    return texts


def _parse(texts: list[str], signals: Signals) -> _Parsed:
    symbols: dict[str, ca.SX] = {}
    residuals, params, user_terms = [], [], []
    for text in texts:
        lhs, rhs = _Parser(text).equation()
        names: list[str] = []
        terms = []
        for side, node in ((1.0, lhs), (-1.0, rhs)):
            for sign, term in _additive_terms(node, side):
                sx = sign * _to_sx(term, signals, symbols, names, text)
                terms.append((term.text if sign > 0 else f"-({term.text})", sx))
        residuals.append(sum((sx for _, sx in terms), ca.SX(0)))
        params.append(tuple(names))
        user_terms.append(tuple(terms))
    return _Parsed(tuple(texts), tuple(residuals), tuple(params), tuple(user_terms), symbols)


def _to_sx(node: _Node, sig: Signals, symbols: dict[str, ca.SX], names: list[str], text: str) -> ca.SX:
    rec = lambda n: _to_sx(n, sig, symbols, names, text)  # noqa: E731
    k = node.kind
    if k == "num":
        return ca.SX(node.value)
    if k == "name":
        cols = {n: s for n, s in zip(sig.x_names, sig.x)} | {n: s for n, s in zip(sig.f_names, sig.f)} | {"t": sig.t}
        if node.name in cols:
            return cols[node.name]
        if node.name in sig.columns:
            raise EquationError(f"column {node.name!r} cannot appear in an equation ({text!r})")
        if re.fullmatch(r"[fxFX]\d*|[tT]", node.name):
            case = (f" (names are case-sensitive: did you mean {node.name.lower()!r}?)"
                    if node.name.lower() in sig.columns else "")
            raise EquationError(f"{node.name!r} is not a column: columns are {', '.join(sig.columns)}{case}; "
                                f"in {text!r} (rename it if it is a parameter)")
        if node.name not in symbols:
            symbols[node.name] = ca.SX.sym(node.name)
        if node.name not in names:
            names.append(node.name)
        return symbols[node.name]
    if k == "neg":
        return -rec(node.args[0])
    if k in ("add", "sub", "mul", "div", "pow"):
        a, b = rec(node.args[0]), rec(node.args[1])
        return {"add": a + b, "sub": a - b, "mul": a * b, "div": a / b, "pow": a ** b}[k]
    # call
    name, args = node.name, node.args
    if name == "der":
        return _derivative(node, sig, text)
    if len(args) != 1:
        raise EquationError(f"{name}() takes one argument: {node.text!r} in {text!r}")
    if name == "sign" and args[0].kind == "call" and args[0].name == "der":
        dx = _derivative(args[0], sig, text)
        for d, s in zip(sig.dx, sig.sgn):
            if ca.is_equal(dx, d):
                return s
        raise EquationError(f"sign() of a second derivative is not supported: {node.text!r} in {text!r}")
    return {"abs": ca.fabs, "sign": ca.sign, "sin": ca.sin, "cos": ca.cos, "exp": ca.exp}[name](rec(args[0]))


def _derivative(node: _Node, sig: Signals, text: str) -> ca.SX:
    args = node.args
    if not 1 <= len(args) <= 2:
        raise EquationError(f"der() takes a signal and an optional order 1 or 2: {node.text!r} in {text!r}")
    target = args[0]
    if target.kind != "name" or target.name not in sig.x_names:
        what = target.text
        raise EquationError(f"der() applies to a displacement column ({', '.join(sig.x_names)}), "
                            f"not {what!r}: {node.text!r} in {text!r}")
    order = 1
    if len(args) == 2:
        if args[1].kind != "num" or args[1].value not in (1.0, 2.0):
            raise EquationError(f"der() order must be 1 or 2: {node.text!r} in {text!r}")
        order = int(args[1].value)
    i = sig.x_names.index(target.name)
    return sig.dx[i] if order == 1 else sig.ddx[i]


# ---------------------------------------------------------------------- polynomials
def _polynomial(e: ca.SX, xs: list[ca.SX]) -> dict[tuple[int, ...], float] | None:
    """Expanded polynomial ``{exponents: coefficient}`` of a scalar SX in ``xs``, or None."""
    hashes = {x.element_hash(): i for i, x in enumerate(xs)}
    zero = (0,) * len(xs)
    memo: dict[int, dict | None] = {}

    def mul(a: dict, b: dict) -> dict:
        out: dict[tuple[int, ...], float] = {}
        for ea, ca_ in a.items():
            for eb, cb in b.items():
                key = tuple(i + j for i, j in zip(ea, eb))
                out[key] = out.get(key, 0.0) + ca_ * cb
        return out

    def add(a: dict, b: dict, sb: float = 1.0) -> dict:
        out = dict(a)
        for key, v in b.items():
            out[key] = out.get(key, 0.0) + sb * v
        return out

    def constant(p: dict | None) -> float | None:
        if p is None or any(key != zero and v != 0.0 for key, v in p.items()):
            return None
        return p.get(zero, 0.0)

    def walk(e: ca.SX) -> dict | None:
        h = e.element_hash()
        if h in memo:
            return memo[h]
        if e.is_constant():
            out: dict | None = {zero: float(ca.evalf(e))}
        elif e.is_symbolic():
            if h in hashes:
                key = [0] * len(xs)
                key[hashes[h]] = 1
                out = {tuple(key): 1.0}
            else:
                out = None
        else:
            op = e.op()
            a = walk(e.dep(0))
            b = walk(e.dep(1)) if e.n_dep() > 1 else None
            out = None
            if a is not None:
                if op == ca.OP_ADD and b is not None:
                    out = add(a, b)
                elif op == ca.OP_SUB and b is not None:
                    out = add(a, b, -1.0)
                elif op == ca.OP_MUL and b is not None:
                    out = mul(a, b)
                elif op == ca.OP_NEG:
                    out = {key: -v for key, v in a.items()}
                elif op == ca.OP_SQ:
                    out = mul(a, a)
                elif op == ca.OP_TWICE:
                    out = {key: 2.0 * v for key, v in a.items()}
                elif op == ca.OP_DIV and constant(b):
                    out = {key: v / constant(b) for key, v in a.items()}
                elif op in (ca.OP_POW, ca.OP_CONSTPOW):
                    n = constant(b)
                    if n is not None and n >= 0 and n == int(n) and n <= 64:
                        out = {zero: 1.0}
                        for _ in range(int(n)):
                            out = mul(out, a)
                elif op == ca.OP_INV and constant(a):
                    out = {zero: 1.0 / constant(a)}
        memo[h] = out
        return out

    return walk(e)


def _derivative_poly(p: dict, i: int) -> dict:
    out: dict[tuple[int, ...], float] = {}
    for key, v in p.items():
        if key[i] > 0 and v != 0.0:
            k = list(key)
            k[i] -= 1
            out[tuple(k)] = out.get(tuple(k), 0.0) + v * key[i]
    return out


def _close(a: dict, b: dict, scale: float) -> bool:
    keys = set(a) | set(b)
    return all(abs(a.get(k, 0.0) - b.get(k, 0.0)) <= 1e-12 * scale for k in keys)


# ---------------------------------------------------------------------- derivation
@dataclass(frozen=True)
class IntegratorChannel:
    """One input of the integrator bank: ``tau^power * g[channel]``, integrated ``depth`` times."""

    channel: int
    label: str
    power: int
    depth: int

    @property
    def input_label(self) -> str:
        """Readable input, e.g. ``tau^2*(x^3)``."""
        pre = "" if self.power == 0 else ("tau*" if self.power == 1 else f"tau^{self.power}*")
        return f"{pre}({self.label})" if pre else self.label


@dataclass(frozen=True)
class DerivedRegressor:
    """The integrated-by-parts regressor of a system of equations (see the module docs).

    Attributes
    ----------
    equations : tuple of str
        Source equations.
    parameters : tuple of str
        All unknown parameters, in order of appearance.
    unknowns : tuple of tuple of str
        Parameters of each equation (column order of its ``A``).
    order : int
        ``n``: the equations are multiplied by ``tau^n`` and integrated ``n`` times.
    channels : tuple of str
        Labels of the signals ``g`` the regressor integrates.
    terms : tuple of tuple of LinearTerm
        Each equation as ``sum coef * theta * d^order g = sum known terms``.
    n_rows : tuple of int
        Rows ``I^0 .. I^(p-1)`` of each equation (default: its number of unknowns).
    bank : tuple of IntegratorChannel
        The integrator bank the rows need.
    depth : int
        Integrations per bank input (``n + max(n_rows) - 1``).
    signals : Signals
        The symbols of the measured signals.
    channel_function, bank_function, rows_function : casadi.Function
        ``channels(x, f, t, sgn) -> g``; ``bank(x, f, t, sgn, tau) -> u`` (inputs of the
        integrators); ``rows(Y) -> A1, D1, A2, D2, ...`` with ``Y[k, b]`` the ``k``-fold
        integral of bank input ``b`` (``k = 0``: the input itself).
    residuals : tuple of casadi.SX
        ``lhs - rhs`` of each equation in the signal symbols (``signals``) and the parameters.
    symbols : dict
        Parameter name -> its CasADi symbol.
    channel_exprs : tuple of casadi.SX
        The channels ``g`` as expressions of the signal symbols.
    """

    equations: tuple[str, ...]
    parameters: tuple[str, ...]
    unknowns: tuple[tuple[str, ...], ...]
    order: int
    channels: tuple[str, ...]
    terms: tuple[tuple[LinearTerm, ...], ...]
    n_rows: tuple[int, ...]
    bank: tuple[IntegratorChannel, ...]
    depth: int
    signals: Signals
    channel_function: ca.Function
    bank_function: ca.Function
    rows_function: ca.Function
    residuals: tuple[ca.SX, ...] = ()
    symbols: dict[str, ca.SX] | None = None
    channel_exprs: tuple[ca.SX, ...] = ()

    def c_code(self, name: str = "duffid_regressor") -> str:
        """C source of the three functions (CasADi code generation)."""
        gen = ca.CodeGenerator(f"{name}.c", {"with_header": False})
        for fn in (self.channel_function, self.bank_function, self.rows_function):
            gen.add(fn)
        return gen.dump()

    def generate_c(self, directory: str | Path, name: str = "duffid_regressor") -> Path:
        """Write the C source to ``directory/name.c`` and return its path."""
        path = Path(directory) / f"{name}.c"
        path.write_text(self.c_code(name))
        return path

    def evaluate_channels(self, x: np.ndarray, f: np.ndarray, t: np.ndarray, sgn: np.ndarray) -> np.ndarray:
        """Channel values (n, channels) for n samples (the batch form of ``channel_function``)."""
        n = len(t)
        out = self.channel_function.map(n)(np.asarray(x, float).T, np.asarray(f, float).T,
                                            np.asarray(t, float)[None, :], np.asarray(sgn, float).T)
        return np.asarray(out).T.reshape(n, len(self.channels))

    def rows(self, Y: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        """``(A, D)`` of each equation from the integrator outputs ``Y`` (depth+1, bank)."""
        out = self.rows_function(np.asarray(Y, float))
        out = out if isinstance(out, (list, tuple)) else [out]
        return [(np.asarray(out[2 * e]), np.asarray(out[2 * e + 1]).ravel()) for e in range(len(self.equations))]

    def regression(self, name: str = "equation") -> Regression:
        """The structure for the buffered estimator (:mod:`duffid.identification.buffered`), equations joint."""
        params = self.parameters

        def finish(solutions: list[dict[str, float]]) -> dict[str, float]:
            merged: dict[str, float] = {}
            for sol in solutions:
                merged.update(sol)
            return {k: float(merged.get(k, np.nan)) for k in params}

        return Regression(name, self.unknowns, self.terms, self.channels,
                          self.evaluate_channels, finish, params, self.signals.n_dof,
                          self.signals.n_forces, joint=True)


def derive(equations: str | Sequence[str], columns: Sequence[str] = ("t", "f", "x"),
           n_rows: int | Sequence[int] | None = None) -> DerivedRegressor:
    """Parse equations over the record ``columns`` and derive their regressor.

    Parameters
    ----------
    equations : str or sequence of str
        ``"m*der(x,2) + b*der(x) + k*x + kp*x^3 = f"``; several separated by ``;``.
    columns : sequence of str
        Record columns (``Record.column_names``).
    n_rows : int or sequence of int, optional
        Rows per equation; default its number of unknowns (the paper's square system).
    """
    signals = Signals(columns)
    parsed = _parse(_split_equations(equations), signals)
    theta = [[parsed.symbols[n] for n in names] for names in parsed.parameters]
    return derive_regressor(parsed.residuals, theta, signals, texts=parsed.texts, user_terms=parsed.terms,
                            n_rows=n_rows)


def derive_regressor(residuals: Sequence[ca.SX], parameters: Sequence[Sequence[ca.SX]], signals: Signals, *,
                     texts: Sequence[str] | None = None, user_terms=None,
                     n_rows: int | Sequence[int] | None = None) -> DerivedRegressor:
    """Derive the integrated-by-parts regressor of residuals linear in their parameters.

    Parameters
    ----------
    residuals : sequence of casadi.SX
        One scalar residual per equation, in the symbols of ``signals`` and the parameters.
    parameters : sequence of sequence of casadi.SX
        The parameter symbols of each equation (the same symbol in two equations is one
        unknown).
    signals : Signals
        Signal symbols.
    texts : sequence of str, optional
        Source text of each equation (for messages).
    user_terms : optional
        Per equation, ``(text, SX)`` of each additive term (to name offending terms).
    n_rows : int or sequence of int, optional
        Rows per equation (default: its number of unknowns).

    Raises
    ------
    EquationError
        A residual is not linear in its parameters, a derivative is used in a way that
        cannot be integrated by parts, or a parameter has no effect.
    """
    texts = tuple(texts) if texts is not None else tuple(str(r) for r in residuals)
    user_terms = user_terms if user_terms is not None else [((t, r),) for t, r in zip(texts, residuals)]
    ctx = _Context(signals)
    unique: dict[str, ca.SX] = {}
    for ps in parameters:
        for p in ps:
            unique.setdefault(p.name(), p)
    all_theta = list(unique.values())
    unknowns, terms = [], []
    names_order: list[str] = []
    for e, (res, theta) in enumerate(zip(residuals, parameters)):
        names = [p.name() for p in theta]
        for n in names:
            if n not in names_order:
                names_order.append(n)
        if not names:
            raise EquationError(f"equation {texts[e]!r} has no unknown parameter")
        th = ca.vertcat(*theta)
        J = ca.jacobian(res, th)
        if ca.depends_on(J, ca.vertcat(*all_theta)):
            bad = [t for t, sx in user_terms[e] if ca.depends_on(ca.jacobian(sx, th), th)]
            raise EquationError(f"equation {texts[e]!r} is not linear in its parameters: term(s) "
                                f"{', '.join(repr(b) for b in bad) or repr(texts[e])}")
        eq_terms: list[LinearTerm] = []
        for j, name in enumerate(names):
            regressor = J[j]
            where = [t for t, sx in user_terms[e] if ca.depends_on(sx, theta[j])]
            pieces = ctx.classify(regressor, texts[e], where)
            if not pieces:
                raise EquationError(f"parameter {name!r} has no effect in {texts[e]!r}")
            eq_terms += [LinearTerm(j, ch, order, coef) for order, ch, coef in pieces]
        known = ca.substitute(res, th, ca.DM.zeros(th.numel()))
        where = [t for t, sx in user_terms[e] if not ca.depends_on(sx, th)]
        eq_terms += [LinearTerm(None, ch, order, -coef) for order, ch, coef in ctx.classify(known, texts[e], where)]
        unknowns.append(tuple(names))
        terms.append(tuple(eq_terms))
    order = max([t.order for eq in terms for t in eq] + [0])
    if n_rows is None:
        rows = tuple(len(u) for u in unknowns)
    elif isinstance(n_rows, (int, np.integer)):
        rows = (int(n_rows),) * len(unknowns)
    else:
        rows = tuple(int(r) for r in n_rows)
    if len(rows) != len(unknowns) or any(r < 1 for r in rows):
        raise InputError(f"n_rows must give one positive count per equation, got {n_rows!r}")
    return _build(texts, tuple(names_order), tuple(unknowns), tuple(terms), order, rows, ctx,
                  tuple(residuals), dict(unique))


class _Context:
    """Channel registry and the classification of regressor expressions."""

    def __init__(self, signals: Signals) -> None:
        self.sig = signals
        self.exprs: list[ca.SX] = []
        self.labels: list[str] = []
        s = signals
        self._not_x = ca.vertcat(*(s.dx + s.ddx + s.f + s.sgn + [s.t]))
        self._all = ca.vertcat(*(s.x + s.dx + s.ddx + s.f + s.sgn + [s.t]))

    def channel(self, expr: ca.SX, label: str | None = None) -> int:
        for i, e in enumerate(self.exprs):
            if ca.is_equal(e, expr, 64):
                return i
        self.exprs.append(expr)
        self.labels.append(label if label is not None else _label(expr))
        return len(self.exprs) - 1

    def classify(self, rho: ca.SX, text: str, where: list[str]) -> list[tuple[int, int, float]]:
        """``[(order, channel, coef)]`` with ``rho = sum coef * d^order g_channel``."""
        s = self.sig
        named = ", ".join(repr(w) for w in where) or repr(text)
        out: list[tuple[int, int, float]] = []
        ddx, dx = ca.vertcat(*s.ddx), ca.vertcat(*s.dx)
        a2 = ca.jacobian(rho, ddx)
        for i in range(s.n_dof):
            if ca.depends_on(a2[i], self._all):
                raise EquationError(f"in {text!r}: der({s.x_names[i]},2) may only be multiplied by parameters "
                                    f"and numbers: {named}")
            value = float(ca.evalf(a2[i]))
            if value != 0.0:
                out.append((2, self.channel(s.x[i], s.x_names[i]), value))
        rho1 = ca.substitute(rho, ddx, ca.DM.zeros(s.n_dof))
        g = ca.jacobian(rho1, dx)
        bad_dep = ca.depends_on(g, self._not_x)
        polys = None if bad_dep else [_polynomial(g[i], s.x) for i in range(s.n_dof)]
        if bad_dep or any(p is None for p in polys):
            raise EquationError(f"in {text!r}: der(x) may only be multiplied by a polynomial in the "
                                f"displacements: {named}")
        scale = max([abs(v) for p in polys for v in p.values()] + [1.0])
        for i in range(s.n_dof):
            for j in range(i + 1, s.n_dof):
                if not _close(_derivative_poly(polys[i], j), _derivative_poly(polys[j], i), scale):
                    raise EquationError(
                        f"in {text!r}: the factors of der({s.x_names[i]}) and der({s.x_names[j]}) are not the "
                        "gradient of one function of the displacements, so they cannot be integrated by "
                        f"parts: {named}")
        out += self._antiderivative(polys, g)
        rho0 = ca.substitute(rho1, dx, ca.DM.zeros(s.n_dof))
        for coef, core in _split(rho0):
            if coef != 0.0:
                out.append((0, self.channel(core), coef))
        return _merge(out)

    def _antiderivative(self, polys: list[dict], g: ca.SX) -> list[tuple[int, int, float]]:
        """``G`` with ``dG/dx_i = g_i``: channels of order 1."""
        s = self.sig
        degree = max([sum(k) for p in polys for k, v in p.items() if v != 0.0] + [-1])
        if degree < 0:
            return []
        if degree == 0:  # constant factors: G is linear, one channel per displacement
            return [(1, self.channel(s.x[i], s.x_names[i]), float(p.get((0,) * s.n_dof, 0.0)))
                    for i, p in enumerate(polys) if p.get((0,) * s.n_dof, 0.0) != 0.0]
        nodes, weights = np.polynomial.legendre.leggauss(degree // 2 + 1)
        x = ca.vertcat(*s.x)
        G = ca.SX(0)
        for node, weight in zip((nodes + 1) / 2, weights / 2):
            G += weight * ca.dot(ca.substitute(g.T, x, node * x), x)
        # label: G expanded, for reading only (the channel evaluates the unexpanded form)
        terms: dict[tuple[int, ...], float] = {}
        for i, p in enumerate(polys):
            for k, v in p.items():
                key = list(k)
                key[i] += 1
                terms[tuple(key)] = terms.get(tuple(key), 0.0) + v / (sum(k) + 1)
        scale = max(abs(v) for v in terms.values())
        label = " + ".join(_monomial(v, k, s.x_names) for k, v in sorted(terms.items(), reverse=True)
                           if abs(v) > 1e-14 * scale).replace("+ -", "- ")
        return [(1, self.channel(G, f"G = {label}"), 1.0)]


def _monomial(coef: float, key: tuple[int, ...], names: Sequence[str]) -> str:
    factors = [n if e == 1 else f"{n}^{e}" for n, e in zip(names, key) if e > 0]
    sign = "-" if coef < 0 else ""
    number = [] if abs(coef) == 1.0 and factors else [f"{abs(coef):.6g}"]
    return sign + "*".join(number + factors)


_INFIX = {ca.OP_ADD: ("+", 1), ca.OP_SUB: ("-", 1), ca.OP_MUL: ("*", 2), ca.OP_DIV: ("/", 2)}
_CALLS = {ca.OP_SIN: "sin", ca.OP_COS: "cos", ca.OP_EXP: "exp", ca.OP_FABS: "abs", ca.OP_SIGN: "sign"}


def _label(e: ca.SX) -> str:
    """Readable text of a scalar SX (no shared subexpressions), e.g. ``(x2-x1)^3``."""
    def text(e: ca.SX) -> tuple[str, int]:  # (text, precedence)
        if e.is_constant():
            return f"{float(ca.evalf(e)):g}", 4
        if e.is_symbolic():
            return e.name(), 4
        op = e.op()
        if op in _INFIX:
            sym, prec = _INFIX[op]
            a, pa = text(e.dep(0))
            b, pb = text(e.dep(1))
            if op == ca.OP_MUL and e.dep(1).op() == ca.OP_SQ and ca.is_equal(e.dep(0), e.dep(1).dep(0), 64):
                return f"{wrap(a, pa, 3)}^3", 3
            a = wrap(a, pa, prec)
            b = wrap(b, pb, prec + (op in (ca.OP_SUB, ca.OP_DIV)))
            return f"{a}{sym}{b}", prec
        if op == ca.OP_NEG:
            a, pa = text(e.dep(0))
            return f"-{wrap(a, pa, 3)}", 2
        if op == ca.OP_SQ:
            a, pa = text(e.dep(0))
            return f"{wrap(a, pa, 4)}^2", 3
        if op == ca.OP_TWICE:
            a, pa = text(e.dep(0))
            return f"2*{wrap(a, pa, 2)}", 2
        if op in (ca.OP_POW, ca.OP_CONSTPOW):
            a, pa = text(e.dep(0))
            b, pb = text(e.dep(1))
            return f"{wrap(a, pa, 4)}^{wrap(b, pb, 4)}", 3
        if op in _CALLS:
            return f"{_CALLS[op]}({text(e.dep(0))[0]})", 4
        return str(e), 0

    def wrap(s: str, prec: int, need: int) -> str:
        return f"({s})" if prec < need else s

    return text(e)[0]


def _split(e: ca.SX, coef: float = 1.0) -> list[tuple[float, ca.SX]]:
    """Top-level additive pieces ``coef * core`` of a scalar SX."""
    if e.is_constant():
        value = float(ca.evalf(e))
        return [(coef * value, ca.SX(1.0))] if value != 0.0 else []
    op = e.op()
    if op == ca.OP_ADD:
        return _split(e.dep(0), coef) + _split(e.dep(1), coef)
    if op == ca.OP_SUB:
        return _split(e.dep(0), coef) + _split(e.dep(1), -coef)
    if op == ca.OP_NEG:
        return _split(e.dep(0), -coef)
    if op == ca.OP_TWICE:
        return _split(e.dep(0), 2.0 * coef)
    if op == ca.OP_MUL and e.dep(0).is_constant():
        return _split(e.dep(1), coef * float(ca.evalf(e.dep(0))))
    if op == ca.OP_MUL and e.dep(1).is_constant():
        return _split(e.dep(0), coef * float(ca.evalf(e.dep(1))))
    if op == ca.OP_DIV and e.dep(1).is_constant():
        return _split(e.dep(0), coef / float(ca.evalf(e.dep(1))))
    return [(coef, e)]


def _merge(pieces: list[tuple[int, int, float]]) -> list[tuple[int, int, float]]:
    total: dict[tuple[int, int], float] = {}
    for order, ch, coef in pieces:
        total[(order, ch)] = total.get((order, ch), 0.0) + coef
    return [(o, c, v) for (o, c), v in total.items() if v != 0.0]


def _build(texts, parameters, unknowns, terms, order, rows, ctx: _Context, residuals, symbols) -> DerivedRegressor:
    s = ctx.sig
    n = order
    depth = n + max(rows) - 1
    # bank inputs: tau^(n-k) g for every (channel, order d) and k <= d
    needed: list[tuple[int, int]] = []
    for eq in terms:
        for t in eq:
            for k in range(t.order + 1):
                if (t.channel, n - k) not in needed:
                    needed.append((t.channel, n - k))
    needed.sort()
    bank = tuple(IntegratorChannel(c, ctx.labels[c], p, depth) for c, p in needed)
    inputs = s.measured()
    G = ca.vertcat(*ctx.exprs) if ctx.exprs else ca.SX(0, 1)
    channel_function = ca.Function("duffid_channels", inputs, [G], ["x", "f", "t", "sgn"], ["g"])
    tau = ca.SX.sym("tau")
    u = ca.vertcat(*[tau ** p * ctx.exprs[c] if p else ctx.exprs[c] for c, p in needed])
    bank_function = ca.Function("duffid_bank", inputs + [tau], [u], ["x", "f", "t", "sgn", "tau"], ["u"])
    Y = ca.SX.sym("Y", depth + 1, len(needed))
    outputs, out_names = [], []
    for e, (eq, n_rows) in enumerate(zip(terms, rows)):
        A = ca.SX.zeros(n_rows, len(unknowns[e]))
        D = ca.SX.zeros(n_rows, 1)
        for p in range(n_rows):
            for t in eq:
                entry = ca.SX(0)
                for k in range(t.order + 1):
                    alpha = (-1) ** k * comb(t.order, k) * factorial(n) / factorial(n - k)
                    entry += alpha * Y[n - t.order + k + p, needed.index((t.channel, n - k))]
                if t.unknown is None:
                    D[p] += t.coef * entry
                else:
                    A[p, t.unknown] += t.coef * entry
        outputs += [A, D]
        out_names += [f"A{e + 1}", f"D{e + 1}"]
    rows_function = ca.Function("duffid_rows", [Y], outputs, ["Y"], out_names)
    return DerivedRegressor(texts, parameters, unknowns, n, tuple(ctx.labels), terms, rows, bank, depth, s,
                            channel_function, bank_function, rows_function, residuals, symbols,
                            tuple(ctx.exprs))
