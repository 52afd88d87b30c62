"""``duffid demo``: the main job (plant <-> identifier <-> adaptive controller co-simulation)."""
from __future__ import annotations

import argparse
import io
import json
from pathlib import Path
from typing import Any

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> argparse.ArgumentParser:
    """Add the ``demo`` subcommand."""
    p = sub.add_parser("demo", help="the main job: plant <-> identifier <-> adaptive controller co-simulation")
    p.add_argument("--out", type=Path, default=Path("out"), help="output folder (default out/)")
    p.add_argument("--fmu-dir", type=Path, default=Path("build/fmus"),
                   help="FMU folder, built there if missing or stale (default build/fmus)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of tables")
    p.add_argument("--progress", action="store_true", help="progress bars for the co-simulation runs")

    return p


def run(args: argparse.Namespace) -> int:
    """Run ``duffid demo``: tables (or ``--json``), plots and records in ``--out``."""
    from ..apps.demo import run_demo
    if args.json:
        summary = run_demo(args.out, fmu_dir=args.fmu_dir, stream=io.StringIO(), progress=args.progress)
        print(json.dumps(summary))
    else:
        run_demo(args.out, fmu_dir=args.fmu_dir, progress=args.progress)
    return 0
