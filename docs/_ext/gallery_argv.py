"""The command line sphinx-gallery gives each example it runs: ``--out`` into the build folder
(``docs/_build/gallery-out/<example>``) for the examples that write files, so that building
the documentation writes nothing into the checkout."""
from __future__ import annotations

from pathlib import Path
from typing import Any

__all__ = ["reset_argv"]

OUT = Path(__file__).resolve().parent.parent / "_build" / "gallery-out"


def reset_argv(gallery_conf: dict[str, Any], script_vars: dict[str, Any]) -> list[str]:
    """``["--out", <folder>]`` for an example that takes ``--out``, else no arguments."""
    source = Path(script_vars["src_file"])
    return ["--out", str(OUT / source.stem)] if "--out" in source.read_text() else []
