"""``duffid paper-report``: the paper's tables and figures reproduced as one HTML page."""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> argparse.ArgumentParser:
    """Add the ``paper-report`` subcommand."""
    p = sub.add_parser("paper-report", help="reproduce the paper's tables 1-5 and figures 4-15 as one HTML page",
                       description="Run the paper's experiments (simulated) and write an HTML page with every "
                                   "table and data-based figure next to the paper's published values, each "
                                   "deviation explained. Takes about a minute.")
    p.add_argument("-o", "--out", type=Path, default=Path("report"),
                   help="output folder: index.html, its figures, summary.md (default report/)")
    p.add_argument("--notes", type=Path, default=None,
                   help="the paper's NOTES.md (default: shared/paper/NOTES.md beside the checkout)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    return p


def run(args: argparse.Namespace) -> int:
    """Run ``duffid paper-report``: the page in ``--out``."""
    from ..apps.paper_report import build_paper_report
    page = build_paper_report(args.out, notes=args.notes, progress=not args.no_progress)
    print(f"duffid paper-report: wrote {page}")
    return 0
