"""``duffid simulate``: a simulated record (CSV) of a named model."""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from ..data.signals import from_spec
from ..errors import InputError
from ..models.simulation import measure, simulate
from .common import add_model_arguments, model_from_arguments, positive_float

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> argparse.ArgumentParser:
    """Add the ``simulate`` subcommand."""
    p = sub.add_parser("simulate", help="write a simulated record (CSV) of a named model")
    add_model_arguments(p)
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="parameter value, e.g. kp=-1.2e6 (repeatable; names as in the model)")
    p.add_argument("--excitation", default="step:10", help="e.g. step:10, chirp:2,0,20,10, sweep:2.96,2.5,20, "
                   "multisine:1,1,30,2, sums with + (default step:10)")
    p.add_argument("--t-end", type=positive_float, default=2.0, help="duration [s]")
    p.add_argument("--dt", type=positive_float, default=1e-3, help="sampling period [s]")
    p.add_argument("--pulses-per-cm", type=positive_float, default=None, help="encoder quantisation (paper: 2266)")
    p.add_argument("--snr-db", type=float, default=None, help="Gaussian noise on x at this SNR [dB]")
    p.add_argument("--seed", type=int, default=0, help="noise seed")
    p.add_argument("-o", "--output", type=Path, required=True, help="CSV file to write")

    return p


def run(args: argparse.Namespace) -> int:
    """Run ``duffid simulate``: simulate the named model and write the record as CSV."""
    if args.offset not in (None, "force"):
        raise InputError(f"--offset {args.offset} is for identify: a simulated record has no sensor offsets "
                         f"(add one to the written x column)")
    model = model_from_arguments(args, offset=args.offset is not None)
    values = {}
    for item in args.param:
        name, sep, text = item.partition("=")
        if not sep:
            raise InputError(f"--param {item!r}: expected NAME=VALUE")
        try:
            values[name.strip()] = float(text)
        except ValueError:
            raise InputError(f"--param {item!r}: {text!r} is not a number") from None
    if values:
        params = {**model.parameters, **values}
        unknown = set(values) - set(model.parameters)
        if unknown:
            raise InputError(f"--param: unknown parameter(s) {sorted(unknown)} of {model.name}; "
                             f"known: {', '.join(model.parameters)}")
        model = type(model)(**params, offset=model.offset) if model.name != "chain" else model.with_parameters(**values)
    record = simulate(model, from_spec(args.excitation), args.t_end, args.dt)
    if args.pulses_per_cm is not None or args.snr_db is not None:
        record = measure(record, pulses_per_cm=args.pulses_per_cm, snr_db=args.snr_db, seed=args.seed)
    record.to_csv(args.output)
    print(f"wrote {args.output}: {record.n_samples} samples of {model.name}")
    return 0
