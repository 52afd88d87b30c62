"""Expansion of component arrays (``Mass mass[n](m = m)``) before pymoca flattens a model.

pymoca flattens a component array into vector-valued variables and writes the
components' scalar equations as vector equations, where ``m*a`` becomes a matrix
product: wrong or failing. This module rewrites the syntax tree of the exported class
instead, as a Modelica tool does: ``mass[n]`` becomes the components ``mass[1]`` ..
``mass[n]`` (array modifiers distributed element-wise), for-equations are unrolled and
subscripts evaluated, so that pymoca sees scalar components named ``mass[1]`` etc.

Only the exported class itself may declare component arrays, with one dimension given
by an Integer parameter of that class (or a literal); anything else is reported with
class and line.
"""
from __future__ import annotations

import copy
import operator
from typing import Callable

from pymoca import ast

from ..errors import ModelicaExportError
from .source import ModelicaSource

__all__ = ["expand_component_arrays", "find_class", "set_structural_parameters"]

_BUILTIN_TYPES = {"Real", "Integer", "Boolean", "String"}
_INT_OPS: dict[str, Callable[[int, int], int]] = {
    "+": operator.add, "-": operator.sub, "*": operator.mul,
    "div": lambda a, b: int(a / b),
}


def find_class(tree: ast.Tree, class_name: str) -> ast.Class:
    """The ast.Class of a dotted class name in a parsed tree."""
    node: ast.Class | ast.Tree = tree
    for part in class_name.split("."):
        try:
            node = node.classes[part]
        except KeyError:
            raise ModelicaExportError(f"class {class_name} not found") from None
    return node  # type: ignore[return-value]


def _binding(symbol: ast.Symbol):
    """The declaration equation (``= value``) of a symbol, or None."""
    mod = symbol.class_modification
    for arg in mod.arguments if mod else []:
        value = arg.value
        if isinstance(value, ast.ElementModification) and value.component.name == "value":
            return value.modifications[0] if value.modifications else None
    return None


def set_structural_parameters(source: ModelicaSource, tree: ast.Tree, class_name: str,
                              values: dict[str, int | bool]) -> None:
    """Override the bindings of Integer/Boolean parameters of ``class_name`` (e.g. ``n``)."""
    cls = find_class(tree, class_name)
    for name, value in values.items():
        sym = cls.symbols.get(name)
        type_name = sym.type.name if sym is not None and isinstance(sym.type, ast.ComponentRef) else None
        if sym is None or "parameter" not in sym.prefixes or type_name not in ("Integer", "Boolean"):
            raise ModelicaExportError(
                f"structural parameter {name!r} is not an Integer or Boolean parameter of class {class_name} "
                f"({source.span(class_name).location})")
        if isinstance(value, bool) != (type_name == "Boolean") or not isinstance(value, int):
            raise ModelicaExportError(f"structural parameter {name} of {class_name} needs a {type_name} value, "
                                      f"got {value!r}")
        mod = sym.class_modification or ast.ClassModification()
        arguments = [a for a in mod.arguments if not (isinstance(a.value, ast.ElementModification)
                                                      and a.value.component.name == "value")]
        arguments.append(ast.ClassModificationArgument(value=ast.ElementModification(
            component=ast.ComponentRef(name="value"), modifications=[ast.Primary(value=value)]), scope=cls))
        sym.class_modification = ast.ClassModification(arguments=arguments)


class _Expander:
    def __init__(self, source: ModelicaSource, cls: ast.Class, class_name: str) -> None:
        self.source = source
        self.cls = cls
        self.class_name = class_name
        self.arrays: dict[str, int] = {}

    def fail(self, message: str, word: str | None = None) -> None:
        raise ModelicaExportError(f"{message} in class {self.class_name} "
                                  f"({self.source.where(self.class_name, word)})")

    # ------------------------------------------------------------------ integers
    def integer(self, node, env: dict[str, int], word: str | None = None) -> int:
        """Evaluate an Integer expression of literals, loop indices and Integer parameters."""
        if isinstance(node, ast.Primary) and isinstance(node.value, (int, float)) and \
                not isinstance(node.value, bool) and int(node.value) == node.value:
            return int(node.value)
        if isinstance(node, ast.ComponentRef) and not node.child:
            if node.name in env:
                return env[node.name]
            sym = self.cls.symbols.get(node.name)
            if sym is not None and ("parameter" in sym.prefixes or "constant" in sym.prefixes):
                value = _binding(sym)
                if value is not None:
                    return self.integer(value, env, node.name)
        if isinstance(node, ast.Expression) and isinstance(node.operator, str):
            ops = [self.integer(o, env, word) for o in node.operands]
            if node.operator in _INT_OPS and len(ops) == 2:
                return _INT_OPS[node.operator](ops[0], ops[1])
            if node.operator == "-" and len(ops) == 1:
                return -ops[0]
        self.fail(f"cannot evaluate the Integer expression {node!r} (array size or subscript)", word)
        raise AssertionError  # unreachable

    # ------------------------------------------------------------------ declarations
    def is_component(self, symbol: ast.Symbol) -> bool:
        type_name = str(symbol.type.name) if isinstance(symbol.type, ast.ComponentRef) else str(symbol.type)
        ref = symbol.type
        while isinstance(ref, ast.ComponentRef) and ref.child:
            ref = ref.child[0]
            type_name += "." + ref.name
        if type_name in _BUILTIN_TYPES:
            return False
        full = self.source.resolve(type_name, self.class_name)
        return full is not None and self.source.classes[full].kind not in ("type",)

    def expand_declarations(self) -> None:
        new_symbols = {}
        for name, sym in self.cls.symbols.items():
            dims = sym.dimensions
            scalar = all(d is None or (isinstance(d, ast.Primary) and d.value is None) for sub in dims for d in sub)
            if scalar or not self.is_component(sym):
                new_symbols[name] = sym
                continue
            if len(dims) != 1 or len(dims[0]) != 1:
                self.fail(f"multi-dimensional component array {name}", name)
            n = self.integer(dims[0][0], {}, name)
            if n < 1:
                self.fail(f"component array {name} has size {n}", name)
            self.arrays[name] = n
            for i in range(1, n + 1):
                element = copy.copy(sym)
                element.name = f"{name}[{i}]"
                element.dimensions = [[ast.Primary(value=None)]]
                element.class_modification = self.distribute(sym, i, n)
                new_symbols[element.name] = element
        self.cls.symbols.clear()
        self.cls.symbols.update(new_symbols)

    def distribute(self, sym: ast.Symbol, i: int, n: int) -> ast.ClassModification | None:
        mod = sym.class_modification
        if mod is None or not mod.arguments:
            return mod
        arguments = []
        for arg in mod.arguments:
            value = arg.value
            if not isinstance(value, ast.ElementModification) or len(value.modifications) != 1 or \
                    isinstance(value.modifications[0], ast.ClassModification):
                self.fail(f"modifier of component array {sym.name} other than 'name = value'", sym.name)
            item = value.modifications[0]
            if isinstance(item, ast.Array):
                if len(item.values) != n:
                    self.fail(f"array modifier {value.component.name} of {sym.name} has {len(item.values)} "
                              f"elements, the component array {n}", sym.name)
                item = copy.deepcopy(item.values[i - 1])
            elif isinstance(item, ast.ComponentRef) and not item.child and item.name in self.cls.symbols and \
                    not all(d is None or (isinstance(d, ast.Primary) and d.value is None)
                            for sub in self.cls.symbols[item.name].dimensions for d in sub):
                item = ast.ComponentRef(name=item.name, indices=[[ast.Primary(value=i)]])
            elif not isinstance(item, (ast.Primary, ast.ComponentRef, ast.Expression)):
                self.fail(f"unsupported modifier {value.component.name} of component array {sym.name}", sym.name)
            # a scalar modifier applies to each element (Modelica's 'each')
            new_value = copy.copy(value)
            new_value.modifications = [item]
            new_arg = copy.copy(arg)
            new_arg.value = new_value
            arguments.append(new_arg)
        return ast.ClassModification(arguments=arguments)

    # ------------------------------------------------------------------ equations
    def substitute(self, node, env: dict[str, int]):
        """Deep copy of an equation node with loop indices replaced and subscripts evaluated."""
        if isinstance(node, list):
            return [self.substitute(item, env) for item in node]
        if isinstance(node, ast.ComponentRef):
            if node.name in env and not node.child and all(x is None for sub in node.indices for x in sub):
                return ast.Primary(value=env[node.name])
            ref = copy.copy(node)
            ref.indices = [[self.subscript(x, env) for x in sub] for sub in node.indices]
            ref.child = [self.substitute(c, env) for c in node.child]
            return ref
        if isinstance(node, ast.Node):
            new = copy.copy(node)
            for key, value in vars(node).items():
                if isinstance(value, (ast.Node, list)) and not key.startswith("_") and key != "scope":
                    setattr(new, key, self.substitute(value, env))
            return new
        return node

    def subscript(self, x, env: dict[str, int]):
        if x is None or isinstance(x, ast.Slice) or (isinstance(x, ast.Primary) and x.value is None):
            return x
        uses_index = self._uses(x, env)
        if uses_index or isinstance(x, ast.Expression):
            return ast.Primary(value=self.integer(x, env))
        return x

    def _uses(self, node, env) -> bool:
        if isinstance(node, ast.ComponentRef):
            return node.name in env
        if isinstance(node, ast.Expression):
            return any(self._uses(o, env) for o in node.operands)
        return False

    def unroll(self, equations: list, env: dict[str, int]) -> list:
        out = []
        for eq in equations:
            if isinstance(eq, ast.ForEquation):
                if len(eq.indices) != 1:
                    self.fail("for-equation with several iterators")
                index = eq.indices[0]
                rng = index.expression
                if not isinstance(rng, ast.Slice):
                    self.fail(f"for-equation over {rng!r} (only start:stop or start:step:stop)", "for")
                start = self.integer(rng.start, env, "for")
                stop = self.integer(rng.stop, env, "for")
                step = self.integer(rng.step, env, "for") if rng.step is not None else 1
                if step == 0:
                    self.fail("for-equation with step 0", "for")
                for k in range(start, stop + (1 if step > 0 else -1), step):
                    out.extend(self.unroll(eq.equations, {**env, index.name: k}))
            elif isinstance(eq, ast.IfEquation):
                new = copy.copy(eq)
                new.conditions = [self.substitute(c, env) for c in eq.conditions]
                new.blocks = [self.unroll(block, env) for block in eq.blocks]
                out.append(new)
            else:
                out.append(self.substitute(eq, env))
        return out

    def rename(self, node):
        """Rename references ``mass[k].x`` to the scalar components ``mass[k]`` (in place)."""
        if isinstance(node, list):
            for item in node:
                self.rename(item)
            return
        if isinstance(node, ast.ComponentRef):
            if node.name in self.arrays:
                sub = node.indices
                if len(sub) != 1 or len(sub[0]) != 1 or not isinstance(sub[0][0], ast.Primary) or \
                        not isinstance(sub[0][0].value, int):
                    self.fail(f"reference to component array {node.name} without a constant subscript",
                              node.name)
                k = sub[0][0].value
                if not 1 <= k <= self.arrays[node.name]:
                    self.fail(f"subscript {k} out of range 1..{self.arrays[node.name]} of {node.name}", node.name)
                node.name = f"{node.name}[{k}]"
                node.indices = [[None]]
            for c in node.child:
                self.rename(c)
            for sub in node.indices:
                for x in sub:
                    if isinstance(x, ast.Node):
                        self.rename(x)
            return
        if isinstance(node, ast.Node):
            for key, value in vars(node).items():
                if isinstance(value, (ast.Node, list)) and not key.startswith("_") and key != "scope":
                    self.rename(value)


def expand_component_arrays(source: ModelicaSource, tree: ast.Tree, class_name: str) -> bool:
    """Expand the component arrays of ``class_name`` in ``tree`` (in place).

    Returns True when the class had component arrays (its for-equations are then unrolled).
    Raises :class:`ModelicaExportError` for component arrays in other classes the model uses.
    """
    cls = find_class(tree, class_name)
    expander = _Expander(source, cls, class_name)
    expander.expand_declarations()
    for name in source.used_classes(class_name):
        if name == class_name or source.classes[name].kind in ("type", "package"):
            continue
        other = find_class(tree, name)
        for sym_name, sym in other.symbols.items():
            dims = sym.dimensions
            scalar = all(d is None or (isinstance(d, ast.Primary) and d.value is None) for sub in dims for d in sub)
            if not scalar and _Expander(source, other, name).is_component(sym):
                raise ModelicaExportError(
                    f"unsupported construct: component array {sym_name} in class {name} "
                    f"({source.where(name, sym_name)}); component arrays are supported in the exported "
                    "class only")
    if not expander.arrays:
        return False
    cls.equations = expander.unroll(cls.equations, {})
    expander.rename(cls.equations)
    return True
