"""``duffid nonlinearity``: the Hilbert-transform nonlinearity index of swept-sine records."""
from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from .common import add_file_arguments, read_record

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> argparse.ArgumentParser:
    """Add the ``nonlinearity`` subcommand."""
    p = sub.add_parser("nonlinearity", help="Hilbert-transform nonlinearity index of swept-sine records")
    p.add_argument("files", type=Path, nargs="+", help="sweep records (CSV or .mat, with ring-down)")
    p.add_argument("--band", type=float, nargs=2, metavar=("F1", "F2"), default=None,
                   help="band [Hz] (default: the central 99.5 %% of the input's energy)")
    p.add_argument("--uncorrected", action="store_true",
                   help="report eta without the band-edge correction (the paper's figures)")
    p.add_argument("--stepped", action="store_true", help="the files are stepped sines: one FRF from all")
    p.add_argument("--modes", type=int, default=None, help="modes of the linear extension (default: DOFs)")
    p.add_argument("--output", type=int, default=1, help="displacement column x<N> to analyse (default 1)")
    p.add_argument("--plot", type=Path, default=None,
                   help="PNG: Argand and Bode plots (one file), or eta vs amplitude (several files)")
    p.add_argument("--json", action="store_true", help="print JSON: one object, or a list for several files")
    add_file_arguments(p)

    return p


def run(args: argparse.Namespace) -> int:
    """Run ``duffid nonlinearity``: eta and the Hilbert distortion of each record (or of the stepped sines)."""
    from ..analysis import nonlinearity as nl
    from ..apps.plots import plot_eta_vs_amplitude, plot_hilbert

    records = [read_record(args, path) for path in args.files]
    band = tuple(args.band) if args.band else None
    output = args.output - 1
    if args.stepped:
        frf = nl.frf_from_stepped_sines(records, output=output, n_modes=args.modes or records[0].n_dof)
        results = [nl.analyse(frf, band=band, corrected=not args.uncorrected, n_modes=args.modes)]
    else:
        results = [nl.analyse(r, band=band, corrected=not args.uncorrected, n_modes=args.modes, output=output)
                   for r in records]
    if args.plot is not None:
        if len(results) == 1:
            plot_hilbert(results[0], args.plot)
        else:
            plot_eta_vs_amplitude({"records": sorted(results, key=lambda r: r.amplitude)}, args.plot)
    if args.json:
        dicts = [r.to_dict() for r in results]
        print(json.dumps(dicts[0] if len(dicts) == 1 else dicts))
        return 0
    print(f"{'source':<40} {'amplitude':>10} {'band [Hz]':>17} {'eta':>9} {'uncorrected':>12} "
          f"{'distortion':>11}  verdict")
    for r in results:
        band_text = f"{r.band[0]:.3g}-{r.band[1]:.3g}"
        print(f"{r.source[-40:]:<40} {r.amplitude:>10.4g} {band_text:>17} {r.eta:>9.5f} "
              f"{r.eta_uncorrected:>12.5f} {r.distortion_db:>8.1f} dB  {r.verdict}")
    return 0
