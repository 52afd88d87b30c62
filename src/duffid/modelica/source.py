"""Modelica source files: class index with line numbers, name lookup, unsupported constructs.

pymoca's syntax tree carries no source positions, so this module keeps its own light
token index of the files. It knows where every class starts and ends, resolves class
names the way Modelica looks them up in enclosing scopes, finds the classes a model
uses, and rejects constructs the export does not translate (events, ``when``,
algorithms, discrete variables, ...) with the construct, class and line.
"""
from __future__ import annotations

import bisect
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Sequence

from ..errors import ModelicaExportError

__all__ = ["Token", "ClassSpan", "ModelicaSource"]

_TOKEN = re.compile(
    r"""
    (?P<ws>\s+)
  | (?P<comment>//[^\n]*|/\*.*?\*/)
  | (?P<string>"(?:\\.|[^"\\])*")
  | (?P<qident>'(?:\\.|[^'\\])*')
  | (?P<number>(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)
  | (?P<ident>[A-Za-z_][A-Za-z0-9_]*)
  | (?P<op><=|>=|==|<>|:=|\.\+|\.-|\.\*|\./|\.\^|[-+*/^<>=(){}\[\];,.:])
    """,
    re.S | re.X,
)

_CLASS_KEYWORDS = {"class", "model", "record", "block", "connector", "type", "package", "function", "operator"}
_CLASS_PREFIXES = {"encapsulated", "partial", "final", "expandable", "pure", "impure", "redeclare",
                   "replaceable", "inner", "outer"}
_END_STATEMENTS = {"for", "if", "when", "while"}
#: Built-in operators outside the continuous subset the export translates.
_UNSUPPORTED_CALLS = {
    "pre": "pre() (discrete-time operator)",
    "edge": "edge() (event operator)",
    "change": "change() (event operator)",
    "reinit": "reinit() (state reset at an event)",
    "sample": "sample() (sampled event)",
    "delay": "delay()",
    "initial": "initial() (event operator)",
    "terminal": "terminal()",
    "terminate": "terminate()",
    "assert": "assert()",
    "smooth": "smooth()",
    "homotopy": "homotopy()",
    "semiLinear": "semiLinear()",
    "spatialDistribution": "spatialDistribution()",
    "cardinality": "cardinality()",
    "inStream": "inStream() (stream connector)",
    "actualStream": "actualStream() (stream connector)",
    "sign": "sign() (event-generating)",
    "floor": "floor() (event-generating)",
    "ceil": "ceil() (event-generating)",
    "integer": "integer() (event-generating)",
    "div": "div() (event-generating)",
    "mod": "mod() (event-generating)",
    "rem": "rem() (event-generating)",
}
_UNSUPPORTED_KEYWORDS = {
    "when": "when-clause (events)",
    "elsewhen": "when-clause (events)",
    "algorithm": "algorithm section",
    "discrete": "discrete variable",
    "stream": "stream connector",
    "inner": "inner/outer component",
    "outer": "inner/outer component",
    "expandable": "expandable connector",
}
_RELATIONS = {"<", "<=", ">", ">=", "==", "<>"}
_SECTION_KEYWORDS = {"equation", "algorithm", "public", "protected", "initial", "end", "annotation"}


@dataclass(frozen=True)
class Token:
    """One lexical token of a Modelica file."""

    kind: str
    text: str
    line: int


@dataclass
class ClassSpan:
    """Where a class is defined: file, first and last line, and its own tokens."""

    name: str
    kind: str
    file: Path
    line: int
    end_line: int
    tokens: list[Token] = field(default_factory=list)  # excluding nested classes
    short: bool = False

    @property
    def location(self) -> str:
        """``file:line`` of the class header."""
        return f"{self.file}:{self.line}"


def _tokenize(text: str) -> list[Token]:
    lines = [m.start() for m in re.finditer("\n", text)]
    tokens = []
    pos = 0
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if m is None:
            line = bisect.bisect_right(lines, pos) + 1
            raise ModelicaExportError(f"unexpected character {text[pos]!r} at line {line}")
        kind = m.lastgroup or ""
        if kind not in ("ws", "comment"):
            tokens.append(Token(kind, m.group(), bisect.bisect_right(lines, m.start()) + 1))
        pos = m.end()
    return tokens


def _skip_parentheses(tokens: Sequence[Token], i: int) -> int:
    """Index after the parenthesised group starting at tokens[i] == '('."""
    depth = 0
    while i < len(tokens):
        if tokens[i].text == "(":
            depth += 1
        elif tokens[i].text == ")":
            depth -= 1
            if depth == 0:
                return i + 1
        i += 1
    return i


class ModelicaSource:
    """The Modelica files of a model: a package directory, single files, or both.

    Parameters
    ----------
    paths : path or sequence of paths
        ``.mo`` files and package directories (a directory with ``package.mo``; its
        ``*.mo`` files and sub-packages are loaded too).
    """

    def __init__(self, paths: Path | str | Iterable[Path | str]) -> None:
        if isinstance(paths, (str, Path)):
            paths = [paths]
        self.files: dict[Path, str] = {}
        for path in paths:
            self._add(Path(path))
        if not self.files:
            raise ModelicaExportError(f"no Modelica files found in {list(map(str, paths))}")
        self.classes: dict[str, ClassSpan] = {}
        for path, text in self.files.items():
            self._index(path, text)

    # ------------------------------------------------------------------ loading
    def _add(self, path: Path) -> None:
        if path.is_dir():
            if not (path / "package.mo").exists():
                raise ModelicaExportError(f"{path}: a package directory needs a package.mo")
            self.files[path / "package.mo"] = (path / "package.mo").read_text(encoding="utf-8")
            for child in sorted(path.iterdir()):
                if child.suffix == ".mo" and child.name != "package.mo":
                    self.files[child] = child.read_text(encoding="utf-8")
                elif child.is_dir() and (child / "package.mo").exists():
                    self._add(child)
        elif path.suffix == ".mo" and path.exists():
            self.files[path] = path.read_text(encoding="utf-8")
        else:
            raise ModelicaExportError(f"{path}: not a .mo file or a Modelica package directory")

    def _index(self, path: Path, text: str) -> None:
        tokens = _tokenize(text)
        within = ""
        i = 0
        if tokens and tokens[0].text == "within":
            j = 1
            parts = []
            while j < len(tokens) and tokens[j].text != ";":
                parts.append(tokens[j].text)
                j += 1
            within = "".join(parts)
            i = j + 1
        stack: list[ClassSpan] = []
        while i < len(tokens):
            tok = tokens[i]
            # class header: [prefixes] keyword [keyword] IDENT
            if tok.kind == "ident" and tok.text in _CLASS_KEYWORDS | _CLASS_PREFIXES and not (
                i > 0 and tokens[i - 1].text == "end"
            ):
                j = i
                while j < len(tokens) and tokens[j].text in _CLASS_PREFIXES:
                    j += 1
                kinds = []
                while j < len(tokens) and tokens[j].text in _CLASS_KEYWORDS:
                    kinds.append(tokens[j].text)
                    j += 1
                if kinds and j < len(tokens) and tokens[j].kind == "ident":
                    scope = stack[-1].name if stack else within
                    name = f"{scope}.{tokens[j].text}" if scope else tokens[j].text
                    span = ClassSpan(name, kinds[-1], path, tok.line, tok.line)
                    if j + 1 < len(tokens) and tokens[j + 1].text == "=":  # short class definition
                        k = j + 1
                        while k < len(tokens) and tokens[k].text != ";":
                            span.tokens.append(tokens[k])
                            k += 1
                        span.short = True
                        span.end_line = tokens[min(k, len(tokens) - 1)].line
                        self.classes[name] = span
                        i = k + 1
                        continue
                    self.classes[name] = span
                    stack.append(span)
                    i = j + 1
                    continue
            if tok.text == "end" and i + 1 < len(tokens) and tokens[i + 1].kind == "ident" and \
                    tokens[i + 1].text not in _END_STATEMENTS and stack:
                span = stack.pop()
                if tokens[i + 1].text != span.name.rsplit(".", 1)[-1]:
                    raise ModelicaExportError(
                        f"'end {tokens[i + 1].text};' closes class {span.name} ({span.location}) "
                        f"at {path}:{tok.line}")
                span.end_line = tok.line
                i += 3
                continue
            if stack:
                stack[-1].tokens.append(tok)
            i += 1
        if stack:
            raise ModelicaExportError(f"class {stack[-1].name} ({stack[-1].location}) has no 'end'")

    # ------------------------------------------------------------------ lookup
    def span(self, class_name: str) -> ClassSpan:
        """The definition of a class given by its full name."""
        try:
            return self.classes[class_name]
        except KeyError:
            known = ", ".join(sorted(n for n in self.classes if self.classes[n].kind != "package"))
            raise ModelicaExportError(f"class {class_name} not found; known classes: {known}") from None

    def resolve(self, name: str, scope: str) -> str | None:
        """Full name of the class ``name`` referenced inside class ``scope``, if any."""
        parts = scope.split(".")
        for k in range(len(parts), -1, -1):
            candidate = ".".join(parts[:k] + [name])
            if candidate in self.classes:
                return candidate
        return None

    def class_at(self, path: Path, line: int) -> str | None:
        """The innermost class defined in ``path`` around ``line``, if any."""
        best = None
        for span in self.classes.values():
            if span.file == path and span.line <= line <= span.end_line:
                if best is None or span.line >= best.line:
                    best = span
        return best.name if best else None

    def where(self, class_name: str, word: str | None = None) -> str:
        """``file:line`` of the first token ``word`` in a class (its header without one)."""
        span = self.span(class_name)
        if word is not None:
            for tok in span.tokens:
                if tok.text == word:
                    return f"{span.file}:{tok.line}"
        return span.location

    def used_classes(self, class_name: str) -> list[str]:
        """The class and every class it references, transitively (an over-approximation)."""
        seen: dict[str, None] = {}
        todo = [class_name]
        while todo:
            name = todo.pop()
            if name in seen:
                continue
            seen[name] = None
            span = self.span(name)
            toks = span.tokens
            i = 0
            while i < len(toks):
                if toks[i].kind == "ident" and not (i > 0 and toks[i - 1].text == "."):
                    ref = toks[i].text
                    j = i + 1
                    while j + 1 < len(toks) and toks[j].text == "." and toks[j + 1].kind == "ident":
                        ref += "." + toks[j + 1].text
                        j += 2
                    # longest prefix of the dotted name that is a class
                    pieces = ref.split(".")
                    for k in range(len(pieces), 0, -1):
                        full = self.resolve(".".join(pieces[:k]), name)
                        if full is not None:
                            if full not in seen:
                                todo.append(full)
                            break
                    i = j
                else:
                    i += 1
        return list(seen)

    # ------------------------------------------------------------------ checks
    def check_supported(self, class_name: str) -> None:
        """Raise :class:`ModelicaExportError` for the first unsupported construct.

        Scans the class and every class it uses for events (``when``, relations outside
        ``noEvent``, event operators), algorithm and initial-equation sections, discrete
        and stream variables.
        """
        for name in self.used_classes(class_name):
            span = self.span(name)
            toks = span.tokens
            section = "declarations"
            statement_start = 0
            i = 0
            while i < len(toks):
                tok = toks[i]
                text = tok.text
                if text == ";":
                    statement_start = i + 1
                if text == "annotation":
                    i = _skip_parentheses(toks, i + 1) if i + 1 < len(toks) and toks[i + 1].text == "(" else i + 1
                    continue
                if tok.kind == "ident":
                    nxt = toks[i + 1].text if i + 1 < len(toks) else ""
                    if text == "initial" and nxt in ("equation", "algorithm"):
                        self._fail(f"initial {nxt} section", name, tok)
                    if text == "equation":
                        section = "equation"
                    elif text in ("public", "protected"):
                        section = "declarations"
                    if text in _UNSUPPORTED_KEYWORDS:
                        self._fail(_UNSUPPORTED_KEYWORDS[text], name, tok)
                    if nxt == "(" and text in _UNSUPPORTED_CALLS and not (i > 0 and toks[i - 1].text == "."):
                        self._fail(f"operator {_UNSUPPORTED_CALLS[text]}", name, tok)
                    if text == "noEvent" and nxt == "(":  # relations inside noEvent(...) are smooth
                        i = _skip_parentheses(toks, i + 1)
                        continue
                if tok.kind == "op" and text in _RELATIONS:
                    statement = {t.text for t in toks[statement_start:i]}
                    if section == "equation" or not statement & {"parameter", "constant"}:
                        self._fail(f"relation '{text}' outside noEvent() (generates events)", name, tok)
                i += 1

    def _fail(self, construct: str, class_name: str, tok: Token) -> None:
        span = self.span(class_name)
        raise ModelicaExportError(
            f"unsupported construct: {construct} in class {class_name} ({span.file}:{tok.line}); "
            "the FMU export handles continuous equations without events only")

    def find_declaration(self, flat_name: str, classes: Iterable[str]) -> str:
        """``file:line`` of a declaration of the last part of ``flat_name`` in ``classes``."""
        word = flat_name.rsplit(".", 1)[-1].split("[", 1)[0]
        for name in classes:
            span = self.span(name)
            for k, tok in enumerate(span.tokens):
                if tok.text == word and k > 0 and span.tokens[k - 1].kind == "ident":
                    return f"class {name} ({span.file}:{tok.line})"
        return "an unknown class"
