"""``duffid paper-cases``: the paper's 1-DOF and 2-DOF cases identified from simulated records."""
from __future__ import annotations

import argparse
import io
import json
from pathlib import Path
from typing import Any

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> argparse.ArgumentParser:
    """Add the ``paper-cases`` subcommand."""
    p = sub.add_parser("paper-cases", help="identify the paper's 1-DOF and 2-DOF cases from simulated records")
    p.add_argument("--out", type=Path, default=Path("out"), help="output folder (default out/)")
    p.add_argument("--json", action="store_true", help="print a JSON summary instead of tables")
    return p


def run(args: argparse.Namespace) -> int:
    """Run ``duffid paper-cases``: tables (or ``--json``) and plots in ``--out``."""
    from ..apps.paper_cases import run_paper_cases
    if args.json:
        summary = run_paper_cases(args.out, stream=io.StringIO())
        print(json.dumps(summary))
    else:
        run_paper_cases(args.out)
    return 0
