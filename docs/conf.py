"""Sphinx configuration of duffid's documentation (``make docs``).

Generated at build time, never copied by hand: the API reference (autodoc over
``duffid.__all__``), the CLI reference (``_ext/cli_reference.py`` over ``duffid.cli.build_parser``),
the example gallery (sphinx-gallery runs the fast examples), the paper report's summary (the
tables of ``duffid paper-report``, which ``make docs`` runs first into
``docs/_build/extra/paper-report``) and the paper's notes (NOTES.md beside the checkout).
Nothing is downloaded: no intersphinx.
"""
from __future__ import annotations

import sys
from pathlib import Path

import duffid
from duffid.apps.paper_report import find_notes

DOCS = Path(__file__).resolve().parent
GENERATED = DOCS / "_generated"
REPORT = DOCS / "_build" / "extra" / "paper-report"
sys.path.insert(0, str(DOCS / "_ext"))

project = "duffid"
author = "duffid developers"
copyright = "duffid developers, MIT licence"
version = release = duffid.__version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx_gallery.gen_gallery",
    "cli_reference",
    "api_xref",
    "plain_math",
]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
exclude_patterns = ["_build", "Thumbs.db", ".DS_Store", "auto_examples/*.ipynb", "auto_examples/*.py",
                    "auto_examples/*.zip", "auto_examples/*.json", "auto_examples/*.md5"]
root_doc = "index"

html_theme = "furo"
html_title = f"duffid {release}"
html_extra_path = [str(REPORT.parent)] if REPORT.is_dir() else []
html_show_sourcelink = False
html_math_renderer = "plain"  # no MathJax from a CDN: the pages are read without network
smartquotes = False  # help strings and code-like text: "--flag" stays two hyphens

myst_heading_anchors = 3
myst_enable_extensions = ["colon_fence"]

autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_default_options = {"members": True, "show-inheritance": False}
napoleon_numpy_docstring = True
napoleon_google_docstring = False
napoleon_use_rtype = False
napoleon_use_ivar = True

# Every broken reference to duffid's own objects fails the build; names of numpy, the
# standard library and the informal numpydoc types ("array_like", "path", "float or None")
# cannot be resolved without intersphinx (no network) and are not checked.
nitpicky = True
nitpick_ignore_regex = [(r"py:.*", r"(?!duffid\.).*")]

# The gallery runs the examples that take seconds; the others (FMU builds, Dask clusters, the
# Silverbox's 390k samples) are shown unexecuted: tests/test_examples.py runs them all.
sphinx_gallery_conf = {
    "examples_dirs": str(DOCS.parent / "examples"),
    "gallery_dirs": str(DOCS / "auto_examples"),
    "filename_pattern": r"/(duffing_circuit|identify_paper_case_a|nonlinearity_index|online_loop)\.py$",
    "ignore_pattern": r"__init__\.py",
    "reset_argv": "gallery_argv.reset_argv",
    "abort_on_example_error": True,
    "only_warn_on_example_error": False,
    "download_all_examples": False,
    "remove_config_comments": True,
    "within_subsection_order": "FileNameSortKey",
    "image_scrapers": ("matplotlib",),
    "matplotlib_animations": False,
    "show_memory": False,
    "min_reported_time": 60,
    "write_computation_times": False,  # its page loads jQuery and DataTables from CDNs
}


def _generate(app) -> None:
    """The pages made from other sources: the paper's notes and the paper report's summary."""
    GENERATED.mkdir(exist_ok=True)
    notes = find_notes(DOCS.parent)
    body = (notes.read_text(encoding="utf-8") if notes else
            "NOTES.md (``shared/paper/NOTES.md`` beside the checkout) was not found when these pages were built.")
    _write(GENERATED / "paper-notes.md", "(paper-notes)=\n" + body)
    summary = REPORT / "summary.md"
    if not summary.is_file():
        raise RuntimeError(f"{summary}: missing; run `duffid paper-report -o {REPORT}` first (make docs does)")
    _write(GENERATED / "paper-summary.md", summary.read_text(encoding="utf-8"))


def _write(path: Path, text: str) -> None:
    if not path.is_file() or path.read_text(encoding="utf-8") != text:  # unchanged: no rebuild
        path.write_text(text, encoding="utf-8")


def setup(app) -> None:
    app.connect("builder-inited", _generate)
