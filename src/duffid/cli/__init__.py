"""The command-line interface ``duffid``: one module per subcommand (identify, discover, inspect, simulate,
nonlinearity, silverbox, build-fmus, cosim, campaign, demo, paper-cases, paper-report), each with ``add_parser``
and ``run``."""
from __future__ import annotations

import argparse
import signal
import sys
import threading
from typing import Sequence

from ..errors import DuffidError
from . import (
    build_estimator,
    build_fmus,
    campaign,
    cosim,
    demo,
    discover,
    identify,
    inspect,
    nonlinearity,
    paper_cases,
    paper_report,
    silverbox,
    simulate,
)

__all__ = ["main", "build_parser", "COMMANDS"]

#: Subcommand -> its module (``add_parser(sub)``, ``run(args)``), in the order of ``duffid --help``.
COMMANDS = {"identify": identify, "discover": discover, "inspect": inspect, "simulate": simulate, "nonlinearity": nonlinearity, "silverbox": silverbox,
            "build-fmus": build_fmus, "build-estimator": build_estimator, "cosim": cosim, "campaign": campaign,
            "demo": demo, "paper-cases": paper_cases, "paper-report": paper_report}


def build_parser() -> argparse.ArgumentParser:
    """The argument parser (exposed for documentation and tests)."""
    parser = argparse.ArgumentParser(prog="duffid", description="Online algebraic identification of "
                                     "Duffing-type oscillators: " + ", ".join(COMMANDS) + ".")
    sub = parser.add_subparsers(dest="command", required=True)
    for module in COMMANDS.values():
        module.add_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``duffid`` command; returns the exit status.

    Errors duffid raises on purpose (:class:`~duffid.errors.DuffidError`) and files that cannot
    be read or written are reported in one line with exit status 2; anything else is a bug and
    surfaces as a traceback.
    """
    args = build_parser().parse_args(identify.bare_offset(sys.argv[1:] if argv is None else argv))
    main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _terminated) if main_thread else None
    try:
        return COMMANDS[args.command].run(args)
    except DuffidError as exc:
        print(f"duffid {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"duffid {args.command}: error: {exc.strerror or exc}"
              + (f": {exc.filename}" if exc.filename else ""), file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"duffid {args.command}: interrupted", file=sys.stderr)
        return 130
    finally:
        if main_thread:
            signal.signal(signal.SIGTERM, previous)


def _terminated(signum: int, frame: object) -> None:
    """SIGTERM stops a command as Ctrl-C does (what it has done is kept: a co-simulation's rows,
    a campaign's results)."""
    raise KeyboardInterrupt("SIGTERM")
