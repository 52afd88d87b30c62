"""``duffid nonlinearity``: is the plant dominantly linear? The Hilbert-transform index, a
calibrated verdict with its reasons, and the nonlinear share of the restoring force."""
from __future__ import annotations

import argparse
import json
import re
from pathlib import Path
from typing import Any

from .common import MODELS, add_file_arguments, model_from_arguments, read_record

__all__ = ["add_parser", "run", "group_labels"]


def add_parser(sub: Any) -> argparse.ArgumentParser:
    """Add the ``nonlinearity`` subcommand."""
    p = sub.add_parser("nonlinearity", help="is the plant dominantly linear? Hilbert-transform index and verdict",
                       description="Hilbert-transform nonlinearity index eta (the paper's eqs. 8-9) and distortion D "
                                   "of each record's FRF, and a verdict - 'dominantly linear', 'nonlinear' or "
                                   "'cannot tell' - with what it rests on. Records of one plant at several "
                                   "amplitudes are also compared with each other (homogeneity test).")
    p.add_argument("files", type=Path, nargs="+",
                   help="records (CSV, .mat, TDMS, UFF, HDF5, WAV): sweeps with a ring-down, random-force records, or stepped sines")
    p.add_argument("--estimator", choices=("auto", "sweep", "h1"), default="auto",
                   help="FRF estimator: sweep = ratio of transforms (sweep or burst plus ring-down), h1 = averaged "
                        "H1 with coherence (stationary random force), auto = sweep when the record starts and ends "
                        "at rest, else h1 (default)")
    p.add_argument("--segments", type=int, default=8, help="h1: Welch segments (default 8, 50 %% overlap)")
    p.add_argument("--band", type=float, nargs=2, metavar=("F1", "F2"), default=None,
                   help="band [Hz] (default: the central 99.5 %% of the input's energy)")
    p.add_argument("--uncorrected", action="store_true",
                   help="report eta without the band-edge correction (the paper's figures; the verdict always "
                        "uses the corrected transform)")
    p.add_argument("--stepped", action="store_true", help="the files are stepped sines: one FRF from all")
    p.add_argument("--modes", type=int, default=None, help="modes of the linear extension (default: DOFs)")
    p.add_argument("--output", type=int, default=1, help="displacement column x<N> to analyse (default 1)")
    p.add_argument("--group", default=None, metavar="LABEL,...",
                   help="one plant label per file, e.g. a,a,b: records with one label are one plant at several "
                        "amplitudes (default: files whose names differ only in their numbers)")
    p.add_argument("--model", choices=MODELS, default=None,
                   help="also identify this model on each record and report the nonlinear share of the restoring "
                        "force kp x^2/k at the record's peak, with its uncertainty")
    p.add_argument("--n-dof", type=int, default=None, help="--model chain: number of masses (default: from the file)")
    p.add_argument("--plot", type=Path, default=None,
                   help="PNG: Argand and Bode plots (one file), or eta and D vs amplitude, one curve per plant "
                        "(several files)")
    p.add_argument("--json", action="store_true", help="print JSON: one object, or a list for several files")
    add_file_arguments(p)
    p.set_defaults(orders="1,3", coulomb=False)
    return p


def group_labels(paths: list[Path], given: str | None) -> list[str]:
    """The plant label of each file: ``--group`` if given, else the file name with its numbers as ``#``."""
    from ..errors import OptionError

    if given is not None:
        labels = [g.strip() for g in given.split(",")]
        if len(labels) != len(paths) or not all(labels):
            raise OptionError(f"--group needs one non-empty label per file: {len(paths)} files, "
                              f"got {len(labels)} label(s) in {given!r}")
        return labels
    return [str(path.parent / re.sub(r"[-+]?\d+(?:[.,_]\d+)*(?:[eE][-+]?\d+)?", "#", path.name)) for path in paths]


def run(args: argparse.Namespace) -> int:
    """Run ``duffid nonlinearity``: eta, D and the verdict of each record, of each plant, and the shares."""
    from ..analysis import nonlinearity as nl
    from ..analysis.share import nonlinear_shares
    from ..analysis.verdict import decide_group, thresholds
    from ..apps.plots import plot_eta_vs_amplitude, plot_hilbert
    from ..errors import OptionError

    if args.segments < 2:
        raise OptionError(f"--segments must be at least 2, got {args.segments}")
    if args.stepped and args.estimator != "auto":
        raise OptionError("--estimator applies to single records, not to --stepped sines")
    if args.stepped and args.group is not None:
        raise OptionError("--group applies to separate records, not to --stepped sines (one FRF from all files)")
    records = [read_record(args, path) for path in args.files]
    band = tuple(args.band) if args.band else None
    output = args.output - 1
    if args.stepped:
        frf = nl.frf_from_stepped_sines(records, output=output, n_modes=args.modes or records[0].n_dof)
        results = [nl.analyse(frf, band=band, corrected=not args.uncorrected, n_modes=args.modes)]
        labels = ["stepped sines"]
    else:
        labels = group_labels(list(args.files), args.group)
        results = [nl.analyse(r, band=band, corrected=not args.uncorrected, n_modes=args.modes, output=output,
                              estimator=args.estimator, segments=args.segments) for r in records]
    # one verdict per plant with several records
    groups: dict[str, list[int]] = {}
    for i, label in enumerate(labels):
        groups.setdefault(label, []).append(i)
    group_decisions = {label: decide_group([results[i].decision for i in idx], [results[i].frf for i in idx])
                       for label, idx in groups.items() if len(idx) > 1}
    shares: list[list[Any] | None] = [None] * len(results)
    if args.model is not None:
        if args.stepped:
            share_note = "the nonlinear share is not given for stepped sines (identify one record instead)"
        else:
            share_note = ""
            for i, record in enumerate(records):
                shares[i] = nonlinear_shares(record, model_from_arguments(args, record.n_dof))
    if args.plot is not None:
        if len(results) == 1:
            plot_hilbert(results[0], args.plot)
        else:
            plot_eta_vs_amplitude({label: sorted((results[i] for i in idx), key=lambda r: r.amplitude)
                                   for label, idx in groups.items()}, args.plot)
    if args.json:
        dicts = []
        for i, r in enumerate(results):
            d = r.to_dict()
            d["group"] = labels[i]
            if labels[i] in group_decisions:
                d["group_verdict"] = group_decisions[labels[i]].to_dict()
            if args.model is not None:
                d["shares"] = [s.to_dict() for s in shares[i]] if shares[i] is not None else None
            d["thresholds"] = thresholds()
            dicts.append(d)
        print(json.dumps(dicts[0] if len(dicts) == 1 else dicts))
        return 0
    print(f"{'source':<40} {'estimator':>9} {'amplitude':>10} {'band [Hz]':>13} {'eta':>9} {'uncorrected':>11} "
          f"{'D [dB]':>7} {'floor':>6}  verdict")
    for i, r in enumerate(results):
        band_text = f"{r.band[0]:.3g}-{r.band[1]:.3g}"
        print(f"{r.source[-40:]:<40} {r.estimator:>9} {r.amplitude:>10.4g} {band_text:>13} {r.eta:>9.5f} "
              f"{r.eta_uncorrected:>11.5f} {r.distortion_db:>7.1f} {r.distortion_floor_db:>6.0f}  {r.verdict}")
        for reason in r.reasons:
            print(f"    {reason}")
        for s in shares[i] or ():
            if s.reason:
                print(f"    {s.spring}: {s.reason}" + "".join(f"\n      {n}" for n in s.notes))
            else:
                kind = "hardening" if s.share > 0 else "softening"
                print(f"    {s.spring}: nonlinear share of the restoring force kp x^2/k = {100 * s.share:+.3g} % "
                      f"+- {100 * s.uncertainty:.2g} % ({kind}) at the peak deflection {s.deflection:.4g}")
    if args.model is not None and args.stepped:
        print(f"    {share_note}")
    for label, decision in group_decisions.items():
        idx = groups[label]
        amps = sorted(results[i].amplitude for i in idx)
        print(f"plant {label} ({len(idx)} records, amplitudes {amps[0]:.4g}-{amps[-1]:.4g}): {decision.verdict}")
        for reason in decision.reasons:
            print(f"    {reason}")
    print("thresholds (set by the simulation study of benchmarks/nonlinearity.py): "
          + ", ".join(f"{k} {v:g}" for k, v in thresholds().items()))
    return 0
