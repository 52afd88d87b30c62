"""A self-contained HTML page built section by section (tables, figures beside it as files,
printable), and its Markdown summary.

Only the structure lives here; :mod:`duffid.apps.paper_report` decides the content.
"""
from __future__ import annotations

import html
import re
from dataclasses import dataclass, field
from typing import Sequence

__all__ = ["Page", "Table", "slug", "markdown_to_html"]

_CSS = """
body { font-family: system-ui, -apple-system, "Segoe UI", sans-serif; max-width: 72rem; margin: 2rem auto;
       padding: 0 1rem; line-height: 1.45; color: #1d1d1f; background: #fff; }
h1 { font-size: 1.8rem; } h2 { margin-top: 2.5rem; border-bottom: 1px solid #ccc; padding-bottom: .2rem; }
table { border-collapse: collapse; margin: 1rem 0; font-size: .92rem; }
caption { text-align: left; font-weight: 600; padding-bottom: .3rem; }
th, td { border: 1px solid #bbb; padding: .25rem .6rem; text-align: right; }
th:first-child, td:first-child { text-align: left; }
thead th { background: #eef2f7; }
figure { margin: 1rem 0; } figure img { max-width: 100%; border: 1px solid #ddd; }
figcaption { font-size: .9rem; color: #444; }
.paper { background: #f7f4ea; border-left: 4px solid #c9a227; padding: .5rem 1rem; }
.why { background: #eef6ee; border-left: 4px solid #3a8f3a; padding: .5rem 1rem; }
nav ol { columns: 2; } code { background: #f2f2f2; padding: 0 .2rem; }
.progress { color: #555; font-size: .9rem; }
@media print { body { max-width: none; margin: 0; } h2 { page-break-before: auto; }
               figure, table { page-break-inside: avoid; } nav { display: none; } a { color: inherit; } }
"""


def slug(text: str) -> str:
    """An HTML id made of ``text``'s lowercase words joined by dashes."""
    return re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-")


@dataclass
class Table:
    """A table: caption, header and rows of already formatted cells (text, escaped when rendered)."""

    caption: str
    header: Sequence[str]
    rows: list[Sequence[str]] = field(default_factory=list)
    id: str = ""

    def html(self) -> str:
        """The ``<table>`` element."""
        head = "".join(f"<th>{html.escape(h)}</th>" for h in self.header)
        body = "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in row) + "</tr>"
                       for row in self.rows)
        ident = f' id="{self.id}"' if self.id else ""
        return (f"<table{ident} class=\"report-table\"><caption>{html.escape(self.caption)}</caption>"
                f"<thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>")

    def markdown(self) -> str:
        """The table as a Markdown pipe table, its caption above in bold."""
        def cells(row: Sequence[str]) -> str:
            return "| " + " | ".join(str(c).replace("|", "\\|") for c in row) + " |"
        lines = [f"**{self.caption}**", "", cells(self.header), "|" + "---|" * len(self.header)]
        return "\n".join(lines + [cells(r) for r in self.rows])


class Page:
    """An HTML page assembled from sections, each with its own anchor for the contents list."""

    def __init__(self, title: str) -> None:
        self.title = title
        self._parts: list[str] = []
        self._sections: list[tuple[str, str]] = []

    def section(self, title: str, anchor: str | None = None) -> str:
        """Start a section; returns its anchor."""
        anchor = anchor or slug(title)
        self._sections.append((anchor, title))
        self._parts.append(f'<h2 id="{anchor}">{html.escape(title)}</h2>')
        return anchor

    def text(self, text: str, css: str | None = None) -> None:
        """A paragraph of plain text (escaped)."""
        self.raw(f"<p>{html.escape(text)}</p>", css)

    def raw(self, fragment: str, css: str | None = None) -> None:
        """An HTML fragment, as is (the caller escapes its text)."""
        self._parts.append(f'<div class="{css}">{fragment}</div>' if css else fragment)

    def items(self, items: Sequence[str], css: str | None = None, ordered: bool = False, title: str = "") -> None:
        """A list of plain-text items (escaped), with an optional bold title."""
        tag = "ol" if ordered else "ul"
        head = f"<p><strong>{html.escape(title)}</strong></p>" if title else ""
        self.raw(head + f"<{tag}>" + "".join(f"<li>{html.escape(i)}</li>" for i in items) + f"</{tag}>", css)

    def table(self, table: Table) -> None:
        """A table."""
        self._parts.append(table.html())

    def figure(self, src: str, caption: str) -> None:
        """An image file beside the page, with its caption (also its alternative text)."""
        self._parts.append(f'<figure><img src="{html.escape(src)}" alt="{html.escape(caption)}">'
                           f"<figcaption>{html.escape(caption)}</figcaption></figure>")

    def render(self, intro: str = "") -> str:
        """The whole page: head with the style sheet, title, contents, sections."""
        nav = "".join(f'<li><a href="#{a}">{html.escape(t)}</a></li>' for a, t in self._sections)
        return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
                "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">"
                f"<title>{html.escape(self.title)}</title><style>{_CSS}</style></head><body>"
                f"<h1>{html.escape(self.title)}</h1>{intro}<nav><ol>{nav}</ol></nav>"
                + "\n".join(self._parts) + "</body></html>\n")


def markdown_to_html(text: str, anchor_prefix: str = "") -> str:
    """A small subset of Markdown as HTML: ``#`` headings (with ids from their words), ``-``
    lists with continued lines, paragraphs, and inline code; enough for NOTES.md."""
    out: list[str] = []
    in_list = False
    paragraph: list[str] = []

    def inline(s: str) -> str:
        return re.sub(r"`([^`]+)`", r"<code>\1</code>", html.escape(s))

    def flush() -> None:
        nonlocal in_list
        if paragraph:
            out.append(("<li>" if in_list else "<p>") + inline(" ".join(paragraph))
                       + ("</li>" if in_list else "</p>"))
            paragraph.clear()

    for line in text.splitlines():
        stripped = line.strip()
        heading = re.match(r"^(#+)\s+(.*)", stripped)
        if heading or not stripped:
            flush()
            if in_list:
                out.append("</ul>")
                in_list = False
            if heading:
                level = min(len(heading.group(1)) + 2, 6)
                title = heading.group(2)
                out.append(f'<h{level} id="{anchor_prefix}{slug(title)}">{inline(title)}</h{level}>')
            continue
        if stripped.startswith("- "):
            flush()
            if not in_list:
                out.append("<ul>")
                in_list = True
            paragraph.append(stripped[2:])
        else:
            paragraph.append(stripped)
    flush()
    if in_list:
        out.append("</ul>")
    return "\n".join(out)
