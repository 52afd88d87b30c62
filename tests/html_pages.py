"""Reading built HTML pages as a reader would: chromium (Debian's package) renders a page to a
screenshot and its DOM; the internal links of a folder of pages are checked without network."""
from __future__ import annotations

import re
import shutil
import subprocess
import tempfile
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit

import pytest

__all__ = ["chromium", "screenshot", "printed_pages", "rendered_dom", "not_blank", "broken_links",
           "external_resources"]

#: No page may reach the network: every host name resolves to nothing.
_OFFLINE = "--host-resolver-rules=MAP * ~NOTFOUND"


def chromium() -> str:
    """The chromium executable; the test is skipped, naming the package, when it is missing."""
    path = shutil.which("chromium")
    if path is None:
        pytest.skip("chromium is not installed (Debian package chromium; .ci/run installs it)")
    return path


def _run(page: Path, *args: str) -> subprocess.CompletedProcess:
    with tempfile.TemporaryDirectory() as profile:
        return subprocess.run([chromium(), "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                               "--no-first-run", f"--user-data-dir={profile}", _OFFLINE, *args,
                               page.resolve().as_uri()], capture_output=True, text=True, timeout=120)


def screenshot(page: Path, png: Path, size: tuple[int, int] = (1200, 2400)) -> Path:
    """Render ``page`` in headless chromium into ``png``."""
    done = _run(page, f"--window-size={size[0]},{size[1]}", f"--screenshot={png}")
    assert png.is_file(), f"chromium wrote no screenshot of {page}: {done.stderr[-2000:]}"
    return png


def printed_pages(page: Path, pdf: Path) -> int:
    """Print ``page`` to ``pdf`` as chromium does (A4/Letter, print style sheet); its number of pages."""
    done = _run(page, "--no-pdf-header-footer", f"--print-to-pdf={pdf}")
    assert pdf.is_file(), f"chromium printed nothing of {page}: {done.stderr[-2000:]}"
    return len(re.findall(rb"/Type\s*/Page[^s]", pdf.read_bytes()))


def rendered_dom(page: Path) -> str:
    """The DOM of ``page`` after chromium has loaded it (scripts run)."""
    done = _run(page, "--dump-dom")
    assert done.returncode == 0 and "<body" in done.stdout, f"chromium could not load {page}: {done.stderr[-2000:]}"
    return done.stdout


def not_blank(png: Path) -> tuple[float, int]:
    """(fraction of pixels that are not background, number of distinct grey levels) of a screenshot."""
    from PIL import Image

    with Image.open(png) as image:
        grey = image.convert("L")
        histogram = grey.histogram()
    total = sum(histogram)
    background = max(range(256), key=histogram.__getitem__)
    ink = sum(n for level, n in enumerate(histogram) if abs(level - background) > 24) / total
    return ink, sum(1 for n in histogram if n)


class _Links(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.ids: set[str] = set()
        self.links: list[str] = []
        self.resources: list[str] = []  # what the browser loads by itself: scripts, styles, images

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        values = dict(attrs)
        for key in ("id", "name"):
            if values.get(key) and (key == "id" or tag == "a"):
                self.ids.add(values[key])
        for key in ("href", "src"):
            if values.get(key) and not (tag == "link" and key == "href" and values.get("rel") == "canonical"):
                self.links.append(values[key])
        if tag in ("script", "img", "iframe") and values.get("src"):
            self.resources.append(values["src"])
        if tag == "link" and values.get("rel") in ("stylesheet", "icon", "preload") and values.get("href"):
            self.resources.append(values["href"])


def _parse(page: Path) -> _Links:
    parser = _Links()
    parser.feed(page.read_text(encoding="utf-8", errors="replace"))
    return parser


def broken_links(root: Path) -> list[str]:
    """Every relative link or image of the pages under ``root`` whose file or ``#anchor`` is missing."""
    parsed = {page: _parse(page) for page in root.rglob("*.html")}
    broken = []
    for page, links in parsed.items():
        for link in links.links:
            parts = urlsplit(link)
            if parts.scheme or parts.netloc or link.startswith(("mailto:", "javascript:", "data:")):
                continue
            target = (page.parent / unquote(parts.path)).resolve() if parts.path else page
            if target.is_dir():
                target = target / "index.html"
            if not target.exists():
                broken.append(f"{page.relative_to(root)}: {link} (no file)")
                continue
            if parts.fragment and target.suffix == ".html":
                ids = parsed[target].ids if target in parsed else _parse(target).ids
                if unquote(parts.fragment) not in ids:
                    broken.append(f"{page.relative_to(root)}: {link} (no anchor)")
    return broken


def external_resources(root: Path) -> list[str]:
    """Every script, style sheet or image of the pages under ``root`` loaded from another host."""
    found = []
    for page in root.rglob("*.html"):
        for link in _parse(page).resources:
            if urlsplit(link).scheme or link.startswith("//"):
                found.append(f"{page.relative_to(root)}: {link}")
    return found
