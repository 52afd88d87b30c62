"""``duffid cosim``: run a system of FMUs described in a JSON or TOML file."""
from __future__ import annotations

import argparse
import signal
import sys
import threading
import zipfile
from pathlib import Path
from typing import Any

from ..cosim import config as cosim_config
from ..cosim.compiled_loop import LOOP_MODES
from ..cosim.config import SSP_SUFFIXES, load_config, load_ssp
from ..cosim.runner import signals_held
from ..cosim.system import ORDERINGS
from ..errors import ConfigError, CosimError

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> argparse.ArgumentParser:
    """Add the ``cosim`` subcommand."""
    p = sub.add_parser("cosim", help="run a system of FMUs described in a JSON or TOML file",
                              description=cosim_config.__doc__.split("\n\n")[1] if cosim_config.__doc__ else None)
    p.add_argument("config", type=Path, help="configuration file (.json or .toml) or SSP (.ssp archive, .ssd)")
    p.add_argument("-o", "--output", type=Path, default=None, help="write the recorded outputs to this CSV")
    p.add_argument("--ordering", choices=ORDERINGS, default=None, help="override the file's run.ordering")
    p.add_argument("--loop", choices=LOOP_MODES, default=None,
                   help="override the file's run.loop: the macro steps in C (compiled) or Python; auto (default) "
                        "takes C unless a component is a Python FMU")
    p.add_argument("--progress", action="store_true", help="show a progress bar")
    p.add_argument("--export-container", type=Path, default=None, metavar="FMU",
                   help="write the system as one container FMU (its interface: the file's container section; for an "
                        "SSP, its system's input and output connectors) and exit")
    p.add_argument("--fmi", type=int, choices=(2, 3), default=2,
                   help="--export-container: the container's FMI version (default 2; its components may be "
                        "FMI 2 or 3 either way)")
    p.add_argument("--step", type=float, default=None,
                   help="communication step [s], overriding the file's (needed for an SSP without duffid's annotation)")
    p.add_argument("--parameter-set", type=Path, default=None, metavar="SSV",
                   help="an SSP's run: apply this parameter set (.ssv, names component.parameter) over the SSP's own")
    p.add_argument("--export-ssp", type=Path, default=None, metavar="SSP",
                   help="write the system and its run as an SSP 1.0 archive (FMUs, connections, parameter values, "
                        "constant inputs, default experiment) and exit")
    return p


def _exported(path: Path) -> str:
    """What ``--export-container`` wrote, in one line: the file, its interface and its platforms."""
    from fmpy import read_model_description

    md = read_model_description(str(path))
    with zipfile.ZipFile(path) as archive:
        names = archive.namelist()
    platforms = sorted({n.split("/")[1] for n in names if n.startswith("binaries/") and n.count("/") == 2})
    components = sorted({n.split("/")[1] for n in names if n.startswith("resources/") and n.count("/") >= 2})
    count = {c: sum(v.causality == c for v in md.modelVariables) for c in ("input", "output", "parameter")}
    step = md.defaultExperiment.stepSize if md.defaultExperiment is not None else None
    return (f"wrote {path}: container FMU (FMI {md.fmiVersion} co-simulation" + (f", step {step} s" if step else "") + ") "
            f"of {', '.join(components)}; {count['input']} input(s), {count['output']} output(s), "
            f"{count['parameter']} parameter(s); binaries for {', '.join(platforms)}")


def _stop_once(signum: int, frame: Any) -> None:
    """The first Ctrl-C stops the run; later ones (and SIGTERM) are ignored, so that the
    instances are released and the rows so far written whenever they come."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_IGN)
    raise KeyboardInterrupt(signal.Signals(signum).name)


def run(args: argparse.Namespace) -> int:
    """Run ``duffid cosim``; returns the exit status (1: the run failed; bad files raise)."""
    if threading.current_thread() is not threading.main_thread():
        return _run(args)
    previous = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}  # _stop_once sets both
    signal.signal(signal.SIGINT, _stop_once)
    try:
        return _run(args)
    finally:
        for sig, handler in previous.items():
            if handler is not None:
                signal.signal(sig, handler)


def _run(args: argparse.Namespace) -> int:
    try:
        if args.config.suffix.lower() in SSP_SUFFIXES:
            config = load_ssp(args.config, step=args.step, parameter_set=args.parameter_set)
        elif args.parameter_set is not None:
            raise ConfigError(f"--parameter-set applies to an SSP (.ssp, .ssd), not to {args.config}")
        else:
            config = load_config(args.config, step=args.step)
        for warning in config.warnings:
            print(f"duffid cosim: warning: {warning}", file=sys.stderr)
        if args.export_ssp is not None:
            written = config.export_ssp(args.export_ssp)
            print(f"wrote {written}: SSP 1.0 of {', '.join(config.system.components)}; "
                  f"{len(config.system.connections)} connection(s), {config.start_time:g} to {config.stop_time:g} s "
                  f"at step {config.step:g} s ({config.ordering})")
            return 0
        if args.export_container is not None:
            print(_exported(config.export_container(args.export_container, fmi_version=args.fmi)))
            return 0
        result = config.run(progress=args.progress, ordering=args.ordering, loop=args.loop)
    except CosimError as exc:
        print(f"duffid cosim: the run failed: {exc}", file=sys.stderr)
        if args.output is not None and exc.result is not None:
            with signals_held():  # a second Ctrl-C does not lose the rows
                exc.result.to_csv(args.output)
            print(f"duffid cosim: the {len(exc.result)} rows before the failure are in {args.output}",
                  file=sys.stderr)
        return 1
    if args.output is not None:
        with signals_held():
            result.to_csv(args.output)
    print(f"{len(result)} communication points from {result.time[0]:g} to {result.time[-1]:g} s "
          f"({config.ordering if args.ordering is None else args.ordering}, order {', '.join(result.order)})"
          + (f"; wrote {args.output}" if args.output is not None else ""))
    for warning in result.warnings:
        print(f"duffid cosim: warning: {warning}", file=sys.stderr)
    if result.ended is not None:
        print(f"the simulation ended early: {result.ended}")
    for name in result.names:
        final = result[name][-1]  # a String as text, a Binary in hexadecimal (as in the CSV file)
        shown = final.hex() if isinstance(final, bytes) else repr(final) if isinstance(final, str) else f"{final:.6g}"
        print(f"  {name:<32} final {shown}")
    return 0
