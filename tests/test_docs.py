"""The documentation as built by ``make docs`` (CI builds it before the tests, with warnings as
errors): its internal links resolve, and a browser renders its index page with the guide, the
API and CLI references and the paper report reachable from it."""
from __future__ import annotations

from pathlib import Path

import pytest

from html_pages import broken_links, external_resources, not_blank, rendered_dom, screenshot

HTML = Path(__file__).resolve().parent.parent / "docs" / "_build" / "html"
#: Pages every build has: the index links to them.
PAGES = ("getting-started.html", "guide/index.html", "api.html", "cli.html", "paper.html", "notes.html",
         "auto_examples/index.html", "paper-report/index.html")


@pytest.fixture(scope="module")
def built() -> Path:
    if not (HTML / "index.html").is_file():
        pytest.skip("the documentation is not built: run `make docs` (CI does before the tests)")
    return HTML


def test_every_page_is_there(built):
    missing = [p for p in PAGES if not (built / p).is_file()]
    assert not missing


def test_internal_links_and_anchors_resolve(built):
    """Without network: every relative href/src of every page names an existing file and anchor."""
    assert not broken_links(built)


def test_pages_load_nothing_from_the_network(built):
    """No script, style sheet or image from a CDN: the site is read offline as built."""
    assert not external_resources(built)


def test_cli_reference_lists_every_command(built):
    from duffid.cli import COMMANDS

    html = (built / "cli.html").read_text(encoding="utf-8")
    assert all(f'id="duffid-{name}"' in html for name in COMMANDS)


def test_api_reference_documents_the_public_api(built):
    import duffid

    html = (built / "api.html").read_text(encoding="utf-8")
    assert all(f'id="duffid.{name}"' in html for name in duffid.__all__ if not name.startswith("__"))


def test_index_in_a_browser(built, tmp_path):
    """Headless chromium renders the index page: not blank, with its navigation to the guide."""
    png = screenshot(built / "index.html", tmp_path / "index.png", size=(1200, 1600))
    ink, levels = not_blank(png)
    assert ink > 0.02 and levels > 32, (ink, levels)
    dom = rendered_dom(built / "index.html")
    for page in ("getting-started.html", "guide/index.html", "paper.html", "api.html", "cli.html"):
        assert f'href="{page}' in dom, page


def test_paper_page_in_a_browser(built, tmp_path):
    """The paper page shows the report's tables (generated) and links to the full report."""
    png = screenshot(built / "paper.html", tmp_path / "paper.png")
    ink, levels = not_blank(png)
    assert ink > 0.02 and levels > 32, (ink, levels)
    dom = rendered_dom(built / "paper.html")
    assert dom.count("<table") >= 5 and 'href="paper-report/index.html"' in dom


def test_cross_references_resolve_to_existing_objects_only():
    """The API reference's resolver (docs/_ext/api_xref.py) links duffid's own names by their defining
    module and leaves a name that does not exist unresolved (a warning: -W fails the build)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("api_xref", HTML.parents[1] / "_ext" / "api_xref.py")
    api_xref = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(api_xref)
    import duffid

    assert api_xref.resolve_object("duffid.identification.trust.identify") is duffid.identify
    assert api_xref.resolve_object("duffid.Identification.to_dict") is duffid.Identification.to_dict
    assert api_xref.resolve_object("duffid.identification.trust.no_such_function") is None
    assert api_xref.resolve_object("duffid.no_such_module.anything") is None
    assert api_xref._public_names()[id(duffid.identify)] == "duffid.identify"
