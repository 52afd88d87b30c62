"""``duffid build-fmus``: every FMU duffid makes (the Modelica example plants, the estimator
FMUs in C and pythonfmu, the controller FMUs and the 1-DOF loop as a container FMU), with
binaries for every platform whose compiler is installed (``--platforms`` selects)."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from ..assets import EXAMPLE_PLANTS
from ..cbuild import PLATFORMS, resolve_platforms
from ..errors import InputError

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> argparse.ArgumentParser:
    """Add the ``build-fmus`` subcommand."""
    p = sub.add_parser("build-fmus", help="build the example plant FMUs (FMI 2.0 and 3.0, with sources)",
                       description="Build every Modelica example plant as <Name>.fmu (FMI 2.0) and "
                                   "<Name>_fmi3.fmu (FMI 3.0), the estimator FMUs DuffingEstimator{1,2}.fmu, "
                                   "_fmi3.fmu (C) and _python.fmu (pythonfmu) and DuffingCircuitEstimator.fmu, "
                                   "_fmi3.fmu (C), the controller FMUs "
                                   "AdaptiveController{1,2}.fmu and the whole 1-DOF loop as the container FMU "
                                   "ClosedLoop1DOF.fmu (with --chain N, also the chain estimator "
                                   "ChainEstimator<N>.fmu and _fmi3.fmu). The C FMUs carry binaries for every platform of "
                                   "--platforms whose compiler is installed; a missing cross compiler is "
                                   "skipped with one line naming the Debian package to install.")
    p.add_argument("--out", type=Path, default=Path("build/fmus"), help="output folder (default build/fmus/)")
    p.add_argument("--plant", action="append", choices=EXAMPLE_PLANTS, default=None,
                   help="build only this plant (repeatable)")
    p.add_argument("--no-estimators", action="store_true",
                   help="build the plant FMUs only (no estimators, controllers or ClosedLoop1DOF; "
                        "--chain still builds its chain estimators)")
    p.add_argument("--chain", type=int, action="append", default=None, metavar="N",
                   help="also build the chain estimator ChainEstimator<N>.fmu and _fmi3.fmu (C) for a chain of "
                        "N masses from a wall, force on mass 1 (repeatable; see --orders, --coulomb)")
    p.add_argument("--orders", default="1,3", help="--chain: stiffness orders, e.g. 1,2,3 (default 1,3)")
    p.add_argument("--coulomb", action="store_true", help="--chain: Coulomb friction terms")
    p.add_argument("--platforms", default="all", metavar="LIST",
                   help=f"comma-separated binary platforms of the C FMUs: {', '.join(PLATFORMS)} or all "
                        "(default all: those whose compiler is installed)")
    return p


def run(args: argparse.Namespace) -> int:
    """Plant FMUs (Modelica export), then the estimator and controller FMUs and the loop; one
    line per FMU written, one line on stderr per platform skipped."""
    from ..modelica.export import build_all  # pymoca: an optional dependency, loaded when used

    orders = _orders(args.orders) if args.chain else None
    platforms, skipped = resolve_platforms(n.strip() for n in args.platforms.split(",") if n.strip())
    for line in skipped:
        print(f"duffid build-fmus: {line}", file=sys.stderr)
    for path in build_all(args.out, tuple(args.plant) if args.plant else EXAMPLE_PLANTS, platforms):
        print(path)
    if not (args.no_estimators or args.plant):
        from ..control.closed_loop import build_closed_loop_fmu, mark_fmus_current
        from ..control.controller_fmu import build_controller_fmus
        from ..fmu.estimator import build_estimator_fmus

        for path in [*build_estimator_fmus(args.out, platforms=platforms),
                     *build_controller_fmus(args.out, platforms)]:
            print(path)
        mark_fmus_current(args.out)
        print(build_closed_loop_fmu(args.out))
    if args.chain:
        from ..fmu.estimator import build_chain_fmu

        for n in args.chain:
            for version in (2, 3):
                print(build_chain_fmu(n, args.out, orders=orders, coulomb=args.coulomb, fmi_version=version,
                                      backend="c", platforms=platforms))
    return 0


def _orders(text: str) -> list[int]:
    try:
        return [int(o) for o in text.split(",") if o.strip()]
    except ValueError:
        raise InputError(f"--orders {text}: give stiffness orders as integers, e.g. 1,2,3") from None
