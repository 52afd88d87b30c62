"""Cross-references of the API reference: duffid's docstrings name objects by their defining
module (``duffid.identification.trust.identify``), the reference documents them by their
public name (``duffid.identify``).

A reference to a ``duffid`` object that exists is linked to its documented public name, or,
when the object is not in the curated API (``duffid.__all__``), shown as code without a link.
A reference to a ``duffid`` name that does not exist (a typo, a renamed function) stays a
warning, so that ``make docs`` with ``-W`` fails on it. Also: ``|x|`` in a docstring is an
absolute value (duffid's docstrings use no substitutions) and is escaped before parsing.
"""
from __future__ import annotations

import importlib
import re
from typing import Any

from docutils import nodes
from sphinx.addnodes import pending_xref
from sphinx.application import Sphinx
from sphinx.environment import BuildEnvironment

__all__ = ["resolve_object", "setup"]

_ABS = re.compile(r"(?<![|`\\])\|([A-Za-z_][\w.]*)\|(?![|_`])")


def resolve_object(target: str) -> Any | None:
    """The object ``target`` (``duffid.pkg.mod.Name.attr``) names, or None if there is none."""
    parts = target.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj: Any = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        try:
            for attr in parts[i:]:
                obj = getattr(obj, attr)
        except AttributeError:
            return None
        return obj
    return None


def _public_names() -> dict[int, str]:
    """id(object) -> its documented name, for the curated API and its classes' members."""
    import duffid

    names: dict[int, str] = {}
    for name in duffid.__all__:
        obj = getattr(duffid, name)
        names.setdefault(id(obj), f"duffid.{name}")
        if isinstance(obj, type):
            for member, value in vars(obj).items():
                if not member.startswith("_"):
                    names.setdefault(id(value), f"duffid.{name}.{member}")
    return names


def _missing(app: Sphinx, env: BuildEnvironment, node: pending_xref, contnode: nodes.Element) -> nodes.Node | None:
    target = node.get("reftarget", "")
    if node.get("refdomain") != "py":
        return None
    if not target.startswith("duffid."):
        module = node.get("py:module") or ""
        if module.startswith("duffid") and resolve_object(f"{module}.{target}") is not None:
            target = f"{module}.{target}"
        else:
            return None
    obj = resolve_object(target)
    if obj is None:
        return None  # a broken reference: Sphinx warns
    public = _public_names().get(id(obj))
    if public and public != target:
        domain = env.get_domain("py")
        for role in ("obj", "class", "func", "meth", "attr", "data", "mod"):
            found = domain.resolve_xref(env, node["refdoc"], app.builder, role, public, node, contnode)
            if found is not None:
                return found
    return contnode  # exists, not in the curated API: code without a link


def _escape_absolute_values(app: Sphinx, what: str, name: str, obj: Any, options: Any, lines: list[str]) -> None:
    for i, line in enumerate(lines):
        if "|" in line:  # not inside ``literals``: the even parts between the double backquotes
            parts = line.split("``")
            lines[i] = "``".join(_ABS.sub(r"\\|\1\\|", part) if k % 2 == 0 else part
                                 for k, part in enumerate(parts))


def setup(app: Sphinx) -> dict[str, bool]:
    app.connect("missing-reference", _missing)
    app.connect("autodoc-process-docstring", _escape_absolute_values)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
