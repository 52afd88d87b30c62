"""``duffid campaign``: many identification, nonlinearity or co-simulation runs on Dask."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from ..campaign.runner import run_campaign
from ..campaign.spec import KEYS, load_spec
from ..campaign.summary import summary_lines, write_plots

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> argparse.ArgumentParser:
    """Add the ``campaign`` subcommand."""
    p = sub.add_parser("campaign", help="run a campaign of tasks (a TOML spec) on Dask workers",
                       description="Run every task of a campaign spec (identification, nonlinearity or "
                       "co-simulation runs over factors and seeds) on a local cluster of worker processes or "
                       "an existing Dask cluster; results go to a Parquet file as they arrive, then a summary "
                       "table (and plots with --plots). The spec: [campaign] kind = identification, "
                       "nonlinearity or cosim, seeds = N; [task] the settings every run shares; [factors] lists "
                       "of values, run as a full factorial grid; [metrics] (cosim) scoring functions. Keys per "
                       "kind: " + "; ".join(f"{kind}: {', '.join(keys)}" for kind, keys in KEYS.items())
                       + " (identification and nonlinearity: plant.<parameter>; identification: "
                       "options.<option>; cosim: <component>.<parameter>). Examples: examples/campaigns/.")
    p.add_argument("spec", type=Path, help="campaign spec (.toml)")
    p.add_argument("-o", "--output", type=Path, default=None,
                   help="results file (Parquet; default: the spec's name with .parquet, here)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="address of a running Dask scheduler, e.g. tcp://host:8786 (default: a local cluster)")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="worker processes of the local cluster (default: one per core)")
    p.add_argument("--resume", action="store_true",
                   help="keep the results already in the output and run only the tasks not done yet")
    p.add_argument("--plots", type=Path, default=None, metavar="DIR",
                   help="write the summary plots (PNG) into this folder")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    return p


def run(args: argparse.Namespace) -> int:
    """Run ``duffid campaign``; returns the exit status (1: some tasks failed)."""
    spec = load_spec(args.spec)
    output = args.output if args.output is not None else Path(args.spec.stem + ".parquet")
    try:
        done = run_campaign(spec, output, scheduler=args.scheduler, workers=args.workers, resume=args.resume,
                            progress=not args.no_progress, log=lambda line: print(line, flush=True))
    except KeyboardInterrupt:
        print(f"duffid campaign: interrupted; the results so far are in {output}: --resume continues",
              file=sys.stderr)
        return 130
    print(f"ran {done.ran} task(s) in {done.seconds:.1f} s"
          + (f", skipped {done.skipped} already done" if done.skipped else "")
          + (f", {done.failed} failed" if done.failed else "") + f"; results in {done.output}")
    if done.table is not None:
        for line in summary_lines(done.table, spec):
            print(line)
        if args.plots is not None:
            for path in write_plots(done.table, spec, args.plots):
                print(f"plot: {path}")
    return 1 if done.failed else 0
