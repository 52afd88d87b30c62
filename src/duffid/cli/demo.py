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
    from ..control.closed_loop import FALLBACKS, PAYLOAD_SHARE, PAYLOAD_SPAN, PAYLOAD_TIME, loop_cases

    p = sub.add_parser("demo", help="the main job: plant <-> identifier <-> adaptive controller co-simulation")
    p.add_argument("--out", type=Path, default=Path("out"), help="output folder (default out/)")
    p.add_argument("--fmu-dir", type=Path, default=Path("build/fmus"),
                   help="FMU folder, built there if missing or stale (default build/fmus)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of tables")
    p.add_argument("--progress", action="store_true", help="progress bars for the co-simulation runs")
    p.add_argument("--case", action="append", choices=list(loop_cases()), default=None, metavar="NAME",
                   help=f"run only this loop (repeat for several; default all: {', '.join(loop_cases())})")
    p.add_argument("--payload-mass", type=float, default=None, metavar="KG",
                   help=f"mass added to the 1-DOF plant during control in the payload loop "
                        f"(default {100 * PAYLOAD_SHARE:g} %% of m)")
    p.add_argument("--payload-time", type=float, default=None, metavar="S",
                   help=f"when the payload is added (default {PAYLOAD_TIME:g} s; the run lasts {PAYLOAD_SPAN:g} s "
                        "longer)")
    p.add_argument("--fallback", choices=FALLBACKS, default=None,
                   help="what the adaptive law uses in the payload loop while the estimator has withdrawn the "
                        "parameters: hold the ones it had (default) or the baseline's nominal ones")
    return p


def run(args: argparse.Namespace) -> int:
    """Run ``duffid demo``: tables (or ``--json``), plots and records in ``--out``."""
    from ..apps.demo import run_demo
    from ..control.closed_loop import loop_cases, with_payload

    cases = loop_cases()
    if (args.payload_mass, args.payload_time, args.fallback) != (None, None, None):
        cases["oscillator1dof_payload"] = with_payload(cases["oscillator1dof"], args.payload_mass, args.payload_time,
                                                       args.fallback or "hold")
    if args.case is not None:
        cases = {name: cases[name] for name in dict.fromkeys(args.case)}
    if args.json:
        summary = run_demo(args.out, fmu_dir=args.fmu_dir, stream=io.StringIO(), progress=args.progress, cases=cases)
        print(json.dumps(summary))
    else:
        run_demo(args.out, fmu_dir=args.fmu_dir, progress=args.progress, cases=cases)
    return 0
