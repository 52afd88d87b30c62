"""``duffid silverbox``: the Silverbox electronic Duffing oscillator (real data) identified,
with the simulation errors on its standard test records."""
from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from ..analysis.silverbox import DATA_FILE, default_data_dir, identify_silverbox
from ..apps.plots import plot_silverbox

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> argparse.ArgumentParser:
    """Add the ``silverbox`` subcommand."""
    p = sub.add_parser(
        "silverbox", help="identify the Silverbox electronic Duffing oscillator (real data)",
        description="Identify m y'' + d y' + k y + k2 y^2 + k3 y^3 + offset = u on the Silverbox "
                    "training record (algebraic estimator, then offline output-error refinement) and "
                    "report the simulation RMS errors on the standard test records.")
    p.add_argument("path", nargs="?", type=Path, default=None,
                   help=f"folder holding {DATA_FILE} or the file (default: {default_data_dir()})")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--plot", type=Path, default=None, help="write measured vs simulated output to this PNG")
    p.add_argument("--out", type=Path, default=None,
                   help="write silverbox.json and silverbox.png into this folder")
    p.add_argument("--no-refine", action="store_true", help="skip the output-error refinement")

    return p


def run(args: argparse.Namespace) -> int:
    """Run ``duffid silverbox``; returns the exit status."""
    result = identify_silverbox(args.path, refine_model=not args.no_refine)
    summary = result.to_dict()
    plots = [args.plot] if args.plot is not None else []
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "silverbox.json").write_text(json.dumps(summary, indent=2))
        plots.append(args.out / "silverbox.png")
    for png in plots:
        plot_silverbox(result, png)
    if args.json:
        print(json.dumps(summary))
    else:
        print(result.format())
        for png in plots:
            print(f"wrote {png}")
    return 0
