"""Math shown as its TeX source (``<code class="math">``) instead of MathJax, which the browser
would load from a CDN: the built pages need no network to be read."""
from __future__ import annotations

import html

from docutils import nodes
from sphinx.application import Sphinx

__all__ = ["setup"]


def _inline(self, node: nodes.Element) -> None:
    self.body.append(f'<code class="math">{html.escape(node.astext())}</code>')
    raise nodes.SkipNode


def _block(self, node: nodes.Element) -> None:
    self.body.append(f'<pre class="math">{html.escape(node.astext())}</pre>')
    raise nodes.SkipNode


def setup(app: Sphinx) -> dict[str, bool]:
    app.add_html_math_renderer("plain", inline_renderers=(_inline, None), block_renderers=(_block, None))
    return {"parallel_read_safe": True, "parallel_write_safe": True}
