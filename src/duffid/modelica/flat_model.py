"""Flat model: scalar variables with metadata and scalar residual equations in CasADi SX.

The front end: parse the Modelica files with pymoca (with the fixes of
:mod:`~duffid.modelica.pymoca_fixes`), expand component arrays, flatten the class,
let pymoca's CasADi backend build MX residuals, and convert everything to scalar SX
symbols (``x[2]`` for array elements) with units, descriptions, start values and
parameter values taken from the flattened tree.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Mapping

import casadi as ca
import numpy as np

from ..errors import ModelicaExportError
from . import pymoca_fixes
from .arrays import expand_component_arrays, find_class, set_structural_parameters
from .source import ModelicaSource

__all__ = ["Variable", "FlatModel", "flatten_model"]

@dataclass
class Variable:
    """One scalar variable of a flat model.

    ``role`` is one of ``parameter`` (independent, settable), ``calculated`` (a
    parameter bound to an expression of other parameters), ``input``, ``state``,
    ``derivative`` (of the state named by ``state``) and ``algebraic``.
    """

    name: str
    symbol: ca.SX
    role: str
    output: bool = False
    start: float | None = None
    fixed: bool = False
    unit: str | None = None
    description: str = ""
    value: float | ca.SX | None = None
    state: str | None = None
    minimum: float | None = None
    maximum: float | None = None


@dataclass
class FlatModel:
    """A flattened model: variables, residual equations ``0 = r`` and time."""

    class_name: str
    description: str
    variables: list[Variable]
    equations: list[ca.SX]
    time: ca.SX
    experiment: dict[str, float] = field(default_factory=dict)
    source: ModelicaSource | None = None
    used_classes: list[str] = field(default_factory=list)

    def role(self, role: str) -> list[Variable]:
        """Variables of one role, in declaration order."""
        return [v for v in self.variables if v.role == role]

    def variable(self, name: str) -> Variable:
        """The variable called ``name``."""
        for v in self.variables:
            if v.name == name:
                return v
        raise KeyError(name)

    def locate(self, name: str) -> str:
        """Where the variable ``name`` is declared (class and line), for messages."""
        if self.source is None:
            return self.class_name
        return self.source.find_declaration(name.removeprefix("der(").rstrip(")"), self.used_classes)


# ---------------------------------------------------------------------- helpers
def _primary(value):
    """Python value of an ast.Primary (or a unary minus of one), else None."""
    from pymoca import ast

    if isinstance(value, ast.Primary):
        return value.value
    if isinstance(value, ast.Expression) and value.operator == "-" and len(value.operands) == 1:
        inner = _primary(value.operands[0])
        return -inner if isinstance(inner, (int, float)) else None
    return None


def _experiment(cls) -> dict[str, float]:
    from pymoca import ast

    out: dict[str, float] = {}
    annotation = getattr(cls, "annotation", None)
    for arg in annotation.arguments if annotation else []:
        mod = arg.value
        if isinstance(mod, ast.ElementModification) and mod.component.name == "experiment" and mod.modifications:
            inner = mod.modifications[0]
            for sub in getattr(inner, "arguments", []):
                value = _primary(sub.value.modifications[0]) if sub.value.modifications else None
                if isinstance(value, (int, float)) and not isinstance(value, bool):
                    out[sub.value.component.name] = float(value)
    return out


def _elements(value, n: int) -> list:
    """A parameter value or start value as a list of n items (floats or MX)."""
    if isinstance(value, ca.MX):
        if value.numel() == n:
            return [value[i] for i in range(n)] if n > 1 else [value]
        raise ModelicaExportError(f"value of shape {value.shape} for {n} elements")
    if isinstance(value, ca.DM):
        return [float(v) for v in np.asarray(value).ravel()]
    if isinstance(value, (list, tuple, np.ndarray)):
        items = []
        for item in (value.tolist() if isinstance(value, np.ndarray) else value):
            items.extend(_elements(item, 1) if not isinstance(item, (list, tuple)) else _elements(item, len(item)))
        if len(items) != n:
            raise ModelicaExportError(f"value with {len(items)} elements for {n} elements")
        return items
    if isinstance(value, (bool, int, float, np.floating, np.integer)):
        return [float(value)] * n
    raise ModelicaExportError(f"unsupported value {value!r}")


def _scalar_names(name: str, n: int) -> list[str]:
    return [name] if n == 1 else [f"{name}[{i + 1}]" for i in range(n)]


def _load_tree(source: ModelicaSource):
    from pymoca import parser

    tree = None
    for path, text in source.files.items():
        try:
            parsed = parser.parse(text)
        except Exception as exc:  # pymoca's syntax errors carry the line in their args
            info = exc.args[1] if len(exc.args) > 1 and isinstance(exc.args[1], tuple) else None
            where = f"{path}:{info[1]}" if info else str(path)
            owner = source.class_at(path, info[1]) if info else None
            in_class = f" in class {owner}" if owner else ""
            raise ModelicaExportError(f"Modelica syntax error{in_class} at {where}: "
                                      f"{exc.args[0] if exc.args else exc}") from exc
        if parsed is None:
            raise ModelicaExportError(f"{path}: pymoca could not parse the file")
        if tree is None:
            tree = parsed
        else:
            tree.extend(parsed)
    return tree


def _metadata(flat_class, name: str) -> tuple[str | None, str, float | None, float | None]:
    sym = flat_class.symbols.get(name)
    if sym is None:
        return None, "", None, None
    unit = _primary(sym.unit)
    unit = unit if isinstance(unit, str) and unit else None
    lo, hi = _primary(sym.min), _primary(sym.max)
    lo = float(lo) if isinstance(lo, (int, float)) and not isinstance(lo, bool) else None
    hi = float(hi) if isinstance(hi, (int, float)) and not isinstance(hi, bool) else None
    return unit, sym.comment or "", lo, hi


# ---------------------------------------------------------------------- front end
def flatten_model(paths: Path | str | Iterable[Path | str], class_name: str,
                  structural_parameters: Mapping[str, int | bool] | None = None) -> FlatModel:
    """Flatten ``class_name`` from Modelica files into a :class:`FlatModel`.

    Parameters
    ----------
    paths : path or sequence of paths
        Modelica package directories and/or ``.mo`` files.
    class_name : str
        Full name of the model, e.g. ``"Duffid.Examples.Oscillator1DOF"``.
    structural_parameters : mapping, optional
        New values of Integer/Boolean parameters of the class (array sizes such as the
        ``n`` of ``ChainNDOF``); they are fixed in the FMU.

    Raises
    ------
    ModelicaExportError
        For unsupported constructs (with class and line) and translation failures.
    """
    with pymoca_fixes.applied():
        return _flatten(paths, class_name, structural_parameters)


def _flatten(paths: Path | str | Iterable[Path | str], class_name: str,
             structural_parameters: Mapping[str, int | bool] | None) -> FlatModel:
    from pymoca import ast
    from pymoca.backends.casadi._options import _merge_default_options
    from pymoca.backends.casadi.generator import Generator, GeneratorWalker
    from pymoca.backends.casadi.model import _DefaultValue
    from pymoca.tree import flatten

    source = ModelicaSource(paths)
    span = source.span(class_name)
    if span.kind not in ("model", "block", "class"):
        raise ModelicaExportError(f"{class_name} ({span.location}) is a {span.kind}, not a model")
    source.check_supported(class_name)
    used = source.used_classes(class_name)
    tree = _load_tree(source)
    if structural_parameters:
        set_structural_parameters(source, tree, class_name, dict(structural_parameters))
    expand_component_arrays(source, tree, class_name)
    cls = find_class(tree, class_name)
    try:
        flat_tree = flatten(tree, ast.ComponentRef.from_string(class_name))
        generator = Generator(flat_tree, class_name, _merge_default_options({}))
        GeneratorWalker().walk(generator, flat_tree)
    except ModelicaExportError:
        raise
    except Exception as exc:
        raise ModelicaExportError(
            f"pymoca could not translate class {class_name} ({span.location}): "
            f"{type(exc).__name__}: {exc}") from exc
    model = generator.model
    flat_class = flat_tree.classes[class_name]

    # ---- scalar SX symbols for every MX symbol
    mx_args: list[ca.MX] = [model.time]
    sx_args: list[ca.SX] = []
    time = ca.SX.sym("time")
    sx_args.append(time)
    records = []  # (pymoca variable, role, scalar names, SX elements)

    def add(var, role: str) -> None:
        sym = var.symbol
        if sym.size2() != 1:
            raise ModelicaExportError(
                f"unsupported construct: matrix variable {sym.name()} ({sym.shape}) in "
                f"{source.find_declaration(sym.name(), used)}")
        n = sym.size1()
        names = _scalar_names(sym.name(), n)
        if role in ("structural", "constant"):
            try:
                values = [float(v) for v in _elements(var.value, n)]
            except (ModelicaExportError, TypeError) as exc:
                raise ModelicaExportError(
                    f"{'constant' if role == 'constant' else 'Integer/Boolean parameter'} {sym.name()} in "
                    f"{source.find_declaration(sym.name(), used)} needs a literal value: {exc}") from None
            elements = [ca.SX(v) for v in values]
        else:
            elements = [ca.SX.sym(nm) for nm in names]
        mx_args.append(sym)
        sx_args.append(ca.vertcat(*elements))
        records.append((var, role, names, elements))

    for var in model.constants:
        add(var, "constant")
    for var in model.parameters:
        add(var, "structural" if var.python_type in (int, bool) else "parameter")
    for var in model.inputs:
        add(var, "input")
    for var, der in zip(model.states, model.der_states):
        add(var, "state")
        add(der, "derivative")
    for var in model.alg_states:
        if var.python_type in (int, bool):
            raise ModelicaExportError(
                f"unsupported construct: discrete (Integer/Boolean) variable {var.symbol.name()} in "
                f"{source.find_declaration(var.symbol.name(), used)}")
        add(var, "algebraic")

    # ---- equations as scalar SX residuals
    if model.initial_equations:
        raise ModelicaExportError(f"unsupported construct: initial equations in class {class_name}")
    residual = ca.veccat(*[ca.vec(e) for e in model.equations]) if model.equations else ca.MX(0, 1)
    try:
        fun = ca.Function("residual", mx_args, [residual])
        equations = ca.vertsplit(fun(*sx_args))
    except Exception as exc:
        raise ModelicaExportError(f"cannot convert the equations of {class_name} to CasADi SX: {exc}") from exc
    equations = [e for e in equations if not (e.is_constant() and float(e) == 0.0)]

    # ---- parameter values (possibly expressions of other parameters), start values
    value_items: list[tuple[Variable, object]] = []
    variables: list[Variable] = []
    outputs = set(model.outputs)
    for var, role, names, elements in records:
        if role in ("structural", "constant"):
            continue
        base = var.symbol.name()
        unit, comment, lo, hi = _metadata(flat_class, base)
        try:
            starts = _elements(var.start, len(names)) if not isinstance(var.start, _DefaultValue) else [None] * len(names)
        except ModelicaExportError as exc:
            raise ModelicaExportError(f"start value of {base}: {exc}") from None
        values = None
        if role == "parameter":
            value = var.value
            if isinstance(value, float) and math.isnan(value):
                raise ModelicaExportError(
                    f"parameter {base} in {source.find_declaration(base, used)} has no value")
            values = _elements(value, len(names))
        fixed = bool(float(var.fixed)) if isinstance(var.fixed, (bool, int, float)) else False
        for k, (name, sx) in enumerate(zip(names, elements)):
            start = starts[k]
            if isinstance(start, ca.MX):
                if start.is_constant():
                    start = float(ca.DM(start))
                else:
                    raise ModelicaExportError(
                        f"unsupported construct: start value of {name} depends on parameters "
                        f"({source.find_declaration(base, used)})")
            v = Variable(name=name, symbol=sx, role=role, output=base in outputs, start=start, fixed=fixed,
                         unit=unit, description=comment, minimum=lo, maximum=hi)
            if role == "derivative":
                v.state = name[4:-1]
                v.description = f"der({v.state})"
            if values is not None:
                item = values[k]
                if isinstance(item, ca.MX) and item.is_constant():
                    item = float(ca.DM(item))
                if isinstance(item, ca.MX):
                    v.role = "calculated"
                    value_items.append((v, item))
                else:
                    v.value = float(item)
            variables.append(v)
    if value_items:
        try:
            fun = ca.Function("values", mx_args, [ca.veccat(*[item for _, item in value_items])])
            exprs = ca.vertsplit(fun(*sx_args))
        except Exception as exc:
            raise ModelicaExportError(f"cannot evaluate the parameter bindings of {class_name}: {exc}") from exc
        parameters = ca.vertcat(*[v.symbol for v in variables if v.role in ("parameter", "calculated")])
        for (v, _), expr in zip(value_items, exprs):
            others = ca.symvar(expr)
            bad = [s.name() for s in others if not ca.depends_on(parameters, s)]
            if bad:
                raise ModelicaExportError(
                    f"parameter {v.name} in {source.find_declaration(v.name, used)} is bound to "
                    f"non-parameter variables {bad}")
            v.value = expr
    # resolve chains of calculated parameters (calculated bound to calculated)
    calculated = [v for v in variables if v.role == "calculated"]
    for _ in range(len(calculated)):
        syms = [v.symbol for v in calculated]
        exprs = [v.value for v in calculated]
        new = ca.substitute(exprs, syms, exprs) if calculated else []
        if all(ca.is_equal(a, b, 100) for a, b in zip(new, exprs)):
            break
        for v, e in zip(calculated, new):
            v.value = e
    for v in calculated:
        if any(ca.depends_on(v.value, c.symbol) for c in calculated):
            raise ModelicaExportError(f"parameter {v.name} is bound to itself (cyclic parameter bindings)")

    return FlatModel(class_name=class_name, description=cls.comment or "", variables=variables,
                     equations=equations, time=time, experiment=_experiment(cls), source=source,
                     used_classes=used)
