"""``duffid inspect``: what a record file holds (channels, units, rates, start times, lengths) and
which channels ``identify`` would read from it."""
from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from ..data.channels import ROLE_PATTERN, channel_table, select
from ..data.formats import FORMATS, detect_format, list_channels
from ..errors import RecordError

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> argparse.ArgumentParser:
    """Add the ``inspect`` subcommand."""
    p = sub.add_parser("inspect", help="list a record file's channels: names, units, rates, lengths",
                       description="List the channels of a record file (CSV, .mat, TDMS, UFF 58/58b, HDF5, WAV) "
                                   "with their units, sampling rates, start times and lengths, and say which "
                                   "channels identify and nonlinearity read without --columns.")
    p.add_argument("file", type=Path, help="the record file")
    p.add_argument("--format", choices=tuple(FORMATS), default=None, help="the file's format (default: from its "
                                                                          "extension)")
    p.add_argument("--json", action="store_true", help="print JSON: the channels and the default selection")
    return p


def _plain_header(names: list[str]) -> bool:
    """Whether a CSV header is one ``duffid identify`` reads without ``--columns``."""
    families = {n[0] for n in names[1:]}
    return (len(names) >= 3 and names[0] == "t" and all(ROLE_PATTERN.fullmatch(n) for n in names[1:])
            and "f" in families and len(families) == 2 and "t" not in families)


def run(args: argparse.Namespace) -> int:
    """Run ``duffid inspect``: one line per channel, then the channels read by default (or why none)."""
    channels = list_channels(args.file, args.format)
    rows = channel_table(channels)
    try:  # identify also takes a velocity or acceleration; the other commands a displacement only
        if detect_format(args.file, args.format) == "csv":  # read by its header's names alone
            names = [c.name for c in channels]
            if not _plain_header(names):
                raise RecordError(f"{args.file}: a CSV file is read by its header t,f,x (t,f1..,x1..; a or v for "
                                  "an acceleration or a velocity); give --columns t=NAME,f=NAME,x=NAME")
            chosen = {name: name for name in names}
        else:
            chosen = {role: c.name for role, c in select(channels, None, str(args.file), motion=True).items()}
        default = "without --columns: " + ", ".join(f"{role}={name}" for role, name in chosen.items())
        if not {"v", "a"}.isdisjoint(chosen):
            default += " (" + ("a velocity" if "v" in chosen else "an acceleration") + ": duffid identify only)"
    except RecordError as exc:
        chosen = {}
        reason = str(exc).split(" (channels: ")[0].removeprefix(f"{args.file}: ")
        default = f"without --columns: {reason}"
    if args.json:
        print(json.dumps({"source": str(args.file), "channels": rows, "default_columns": chosen}))
        return 0
    print(f"{args.file}: {len(rows)} channel{'s' if len(rows) != 1 else ''}")
    print(f"  {'#':>3} {'name':<32} {'unit':<8} {'quantity':<13} {'rate [Hz]':>11} {'start [s]':>10} "
          f"{'samples':>9}  kind")
    for r in rows:
        rate = f"{r['rate']:.6g}" if r["rate"] else "-"
        print(f"  {r['number']:>3} {str(r['name']):<32} {str(r['unit']) or '-':<8} {str(r['quantity']) or '-':<13} "
              f"{rate:>11} {r['start']:>10.4g} {r['length']:>9}  {r['kind']}" + (f"; {r['note']}" if r["note"] else ""))
    print(f"  {default}")
    return 0
