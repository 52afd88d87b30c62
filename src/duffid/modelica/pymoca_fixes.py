"""Fixes for bugs of pymoca 0.12 that silently mistranslate models (see :func:`applied`).

The fixes patch pymoca's modules only inside ``with applied():`` (which
:func:`duffid.modelica.flat_model.flatten_model` wraps around each translation); the
originals are restored when the block ends, so other users of pymoca in the same
process see pymoca as it is. They are written against pymoca 0.12.0 exactly: another
version is refused with a clear error rather than patched blindly.

1. A modification value is resolved to its flat name in the right scope, but a later
   pass (``ComponentRefFlattener`` in ``flatten_to_tree``) prefixes it again with the
   component's own path whenever the component has a member of the same name:
   ``Mass mass(m = m)`` flattens to ``mass.m = mass.m`` and
   ``PolynomialSpring spring(k = {k, 0, kp})`` to ``spring.k = {spring.k, 0, kp}``.
   Array modification values are not resolved at all, and a subscripted value
   (``mass[1](m = m[1])``) loses its subscript. The fix marks every reference
   resolved in a modification's own scope as final and resolves array elements the same
   way, so that the later pass leaves them alone (Modelica: modifiers are looked up in
   the scope where they are written).
2. A declaration with a short-class type (``input Force f "applied force"`` with
   ``type Force = Real(unit="N")``) loses its ``input``/``output`` prefix, its
   description string and its array dimensions. The fix copies them from the
   declaration to the flat symbol.
3. An array of parameters bound to other parameters (``k = {c, 0, cp}``) raised
   KeyError in the CasADi generator; ``noEvent(e)`` is translated as ``e``.

Also replaces the missing ``__div__`` of CasADi 3.8 in pymoca's operator map.
"""
from __future__ import annotations

import copy
import threading
from contextlib import contextmanager
from typing import Iterator

import pymoca
from pymoca import ast
from pymoca.backends.casadi import generator as _generator
from pymoca.tree import _flattening as _fl

from ..errors import ModelicaExportError

__all__ = ["applied", "PYMOCA_VERSION"]

#: The pymoca version the fixes are written for.
PYMOCA_VERSION = "0.12.0"
_FLAT = "_duffid_flat_name"
_LOCK = threading.RLock()
_depth = 0


def _mark(ref: ast.ComponentRef) -> ast.ComponentRef:
    setattr(ref, _FLAT, True)
    return ref


def _resolve_crefs(node, scope, flat_class, name_flat_class, guard, opts):
    """Rewrite (in place) the component references of an Expression or Array."""
    items = node.operands if isinstance(node, ast.Expression) else node.values
    for i, item in enumerate(items):
        if isinstance(item, ast.ComponentRef):
            try:
                resolved = _fl._resolve_name(item, scope, flat_class, name_flat_class=name_flat_class,
                                             guard=guard, opts=opts)
            except Exception:  # builtins, for-loop indices: left as they are
                continue
            constant = _fl._get_constant_value(resolved) if isinstance(resolved, _fl.InstanceSymbol) else None
            if isinstance(constant, ast.Primary):
                items[i] = constant
                continue
            item.name = resolved.name
            item.child = []
            _mark(item)
        elif isinstance(item, (ast.Expression, ast.Array)):
            _resolve_crefs(item, scope, flat_class, name_flat_class, guard, opts)


def _patched_rewrite_expression_crefs(expr, scope, flat_class, name_flat_class, guard, opts) -> None:
    _resolve_crefs(expr, scope, flat_class, name_flat_class, guard, opts)


_orig_to_ast_value = _fl._to_ast_value


def _patched_to_ast_value(val):
    out = _orig_to_ast_value(val)
    if isinstance(val, _fl.InstanceSymbol) and isinstance(out, ast.ComponentRef):
        _mark(out)
    return out


_orig_resolve_modification_attribute = _fl._resolve_modification_attribute


def _patched_resolve_modification_attribute(symbol, arg, *, flat_class, guard, opts):
    mods = arg.value.modifications
    indices = None
    if mods and isinstance(mods[0], ast.ComponentRef) and not _is_scalar(mods[0].indices):
        indices = copy.deepcopy(mods[0].indices)  # ``m = k[2]``: pymoca dropped the subscript
    _orig_resolve_modification_attribute(symbol, arg, flat_class=flat_class, guard=guard, opts=opts)
    name = arg.value.component.name
    value = getattr(symbol, name, None)
    if indices is not None and isinstance(value, _fl.InstanceSymbol):
        setattr(symbol, name, _mark(ast.ComponentRef(name=value.name, indices=indices)))
        return
    if isinstance(value, ast.Array):
        scope = arg.scope if isinstance(arg.scope, _fl.InstanceClass) else symbol.parent_instance
        value = copy.deepcopy(value)
        _resolve_crefs(value, scope, symbol.parent_instance, flat_class, guard, opts)
        setattr(symbol, name, value)


_orig_enter_component_ref = _fl.ComponentRefFlattener.enterComponentRef


def _patched_enter_component_ref(self, tree):
    if getattr(tree, _FLAT, False):
        self.depth += 1
        self.cutoff_depth = min(self.cutoff_depth, self.depth)
        return
    _orig_enter_component_ref(self, tree)


_orig_flatten_instance = _fl._flatten_instance


def _is_scalar(dimensions) -> bool:
    return all(d is None or (isinstance(d, ast.Primary) and d.value is None) for sub in dimensions for d in sub)


def _patched_flatten_instance(instance, flat_class, *, guard=None, opts=None, prefix=""):
    guard = guard if guard is not None else _fl.RecursionGuard()
    opts = opts if opts is not None else _fl.LookupOptions()
    _orig_flatten_instance(instance, flat_class, guard=guard, opts=opts, prefix=prefix)
    for name, symbol in list(instance.symbols.items()):
        if name in _fl.InstanceTree.BUILTIN_TYPES:
            continue
        flat_name = f"{prefix}.{name}" if prefix else name
        leaf = flat_class.symbols.get(flat_name)
        if leaf is None or leaf is symbol:
            continue
        if not _is_scalar(symbol.dimensions) and _is_scalar(leaf.dimensions):
            resolved = copy.copy(symbol)
            resolved.dimensions = [list(d) for d in symbol.dimensions]
            _fl._resolve_dimensions(resolved, instance, flat_class, guard=guard, opts=opts)
            leaf.dimensions = resolved.dimensions
        comment = getattr(symbol, "comment", "")
        if comment and not getattr(leaf, "comment", ""):
            leaf.comment = comment
        if not prefix:
            for p in ("input", "output"):
                if p in symbol.prefixes and p not in leaf.prefixes:
                    leaf.prefixes.append(p)


def _patched_exit_array(self, tree) -> None:
    # pymoca looks array elements up in its cache only: a parameter array bound to
    # other parameters (``k = {c, 0, cp}``) raised KeyError.
    self.src[tree] = [self.get_mx(e) if isinstance(e, ast.ComponentRef) else self.src[e] for e in tree.values]


def _patches() -> list[tuple[object, str, object]]:
    """(owner, attribute, replacement) of every fix."""
    return [(_fl, "_rewrite_expression_crefs", _patched_rewrite_expression_crefs),
            (_fl, "_to_ast_value", _patched_to_ast_value),
            (_fl, "_resolve_modification_attribute", _patched_resolve_modification_attribute),
            (_fl.ComponentRefFlattener, "enterComponentRef", _patched_enter_component_ref),
            (_fl, "_flatten_instance", _patched_flatten_instance),
            (_generator.Generator, "exitArray", _patched_exit_array)]


_OPERATORS = {"/": "__truediv__", "noEvent": "__pos__"}


@contextmanager
def applied() -> Iterator[None]:
    """Install the fixes for the duration of the block (re-entrant), then restore pymoca.

    Raises
    ------
    ModelicaExportError
        If the installed pymoca is not the version the fixes are written for.
    """
    global _depth
    if pymoca.__version__ != PYMOCA_VERSION:
        raise ModelicaExportError(f"the Modelica export needs pymoca {PYMOCA_VERSION} (its fixes patch that "
                                  f"version's internals); installed is {pymoca.__version__}: "
                                  f"pip install pymoca=={PYMOCA_VERSION}")
    with _LOCK:
        saved = [(owner, name, owner.__dict__[name]) for owner, name, _ in _patches()] if _depth == 0 else []
        saved_ops = {op: _generator.OP_MAP.get(op) for op in _OPERATORS} if _depth == 0 else {}
        if _depth == 0:
            for owner, name, replacement in _patches():
                setattr(owner, name, replacement)
            _generator.OP_MAP.update(_OPERATORS)
        _depth += 1
        try:
            yield
        finally:
            _depth -= 1
            if _depth == 0:
                for owner, name, original in saved:
                    setattr(owner, name, original)
                for op, original in saved_ops.items():
                    if original is None:
                        _generator.OP_MAP.pop(op, None)
                    else:
                        _generator.OP_MAP[op] = original
