"""``duffid discover``: the terms a record asks for beyond a base equation, chosen by the
checks of ``identify`` (:mod:`duffid.identification.discover`)."""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from ..identification.discover import DEFAULT_LIBRARY, MAX_TERMS, Discovery, discover
from ..identification.options import add_shared_arguments, options_from_arguments
from .common import add_file_arguments, positive_int, read_record
from .identify import result_text

__all__ = ["add_parser", "run", "library_value", "discovery_text"]

#: The word of ``--library`` that stands for the default library.
DEFAULT_WORD = "default"


def library_value(text: str) -> tuple[str, ...]:
    """``--library``: terms separated by ``;`` (the word ``default`` stands for the default
    library), e.g. ``"default; x^4"``."""
    terms: list[str] = []
    for item in text.split(";"):
        item = item.strip()
        if not item:
            continue
        terms.extend(DEFAULT_LIBRARY if item == DEFAULT_WORD else [item])
    if not terms:
        raise argparse.ArgumentTypeError(f"no term in {text!r}: give terms separated by ';', e.g. 'x^2; sign(der(x))'")
    return tuple(dict.fromkeys(terms))


def add_parser(sub: Any) -> argparse.ArgumentParser:
    """Add the ``discover`` subcommand."""
    p = sub.add_parser("discover", help="find the terms a record asks for beyond a base equation")
    p.add_argument("file", type=Path, help="record: CSV (t, f, x), .mat, TDMS, UFF 58/58b, HDF5 or WAV")
    p.add_argument("--base", default="duffing1", metavar="MODEL|EQUATION",
                   help='the base equation: a model name (duffing1, duffing2: its equations) or an equation, '
                        'e.g. "m*der(x,2) + b*der(x) + k*x = f" (default duffing1)')
    p.add_argument("--library", type=library_value, default=None, metavar="TERMS",
                   help="candidate terms in the equation syntax, in x and der(x), separated by ';' (the word "
                        f"'{DEFAULT_WORD}' stands for the default library: {'; '.join(DEFAULT_LIBRARY)}; '1' is a "
                        "constant force), e.g. 'default; x^4'")
    p.add_argument("--max-terms", type=int, default=MAX_TERMS, metavar="N",
                   help=f"most terms added (default {MAX_TERMS})")
    add_shared_arguments(p, ("max_uncertainty",), ("robust",))
    p.add_argument("--refine", action="store_true",
                   help="refine the chosen equation's values by output-error least squares where the algebraic "
                        "estimate leaves them undetermined, as identify does (slower; more values published)")
    p.add_argument("--jobs", type=positive_int, default=None, metavar="N",
                   help="threads for each identification's checks (default: every core)")
    add_file_arguments(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--plot", type=Path, default=None,
                   help="write the best equation's force residual against x and dx/dt to this PNG")
    return p


def run(args: argparse.Namespace) -> int:
    """Run ``duffid discover``: read, search, print (table or ``--json``), plot."""
    record = read_record(args)
    options = options_from_arguments(args, "robust")
    found = discover(record, args.base, library=args.library, max_terms=args.max_terms,
                     refine=args.refine, jobs=args.jobs, progress=False if args.json else None, **options)
    if args.plot is not None:
        from ..apps.plots import plot_discovery_residual
        plot_discovery_residual(found, record, args.plot)
    if args.json:
        print(json.dumps(found.to_dict()))
        return 0
    print(f"{record.source}: {record.n_samples} samples, dt {record.dt:g} s")
    print(discovery_text(found))
    return 0


def discovery_text(found: Discovery) -> str:
    """The search as the CLI prints it: the candidates tried, the best equation's values
    (published only) and the notes."""
    lines = [f"  base: {found.base}",
             "  screening (held-out equation error with the term / without it; below 1: it predicts better):"]
    for chosen, ranking in found.screening:
        lines.append(f"    {'with ' + ', '.join(chosen) if chosen else 'base'}: "
                     + ", ".join(f"{term} {ratio:.3g}" for term, ratio in ranking if np.isfinite(ratio)))
    lines.append(f"  {'added terms':<28} {'simulation':>10} {'noise':>7}  verdict")
    for c in found.candidates:
        fit = c.fit
        sim, noise = fit.get("simulation_nrmse", math.nan), fit.get("noise_nrmse", math.nan)
        shown = f"{100 * sim:.3g} %" if sim is not None and np.isfinite(sim) else "escapes"
        lines.append(f"  {(', '.join(c.added) or '(base)'):<28} {shown:>10} {100 * noise:>5.2g} %  {c.verdict}")
    lines.append(f"  best: {found.best.equation}")
    lines.append(result_text(found.best.identification))
    if found.best.units:
        lines.append("  units (the record's in SI, m and N): "
                     + ", ".join(f"{name} {unit}" for name, unit in found.best.units.items()))
    lines.extend(f"  * {note}" for note in found.notes)
    lines.append(f"  ({found.seconds:.1f} s)")
    return "\n".join(lines)
