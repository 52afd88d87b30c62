"""``duffid build-estimator``: the online identifier of the user's own equations (or of a chain)
as a co-simulation FMU: C (FMI 2.0 or 3.0, binaries for the chosen platforms, runs in any
host) or pythonfmu (FMI 2.0, a Python host with duffid installed) when there is no C compiler."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from ..errors import InputError

__all__ = ["add_parser", "run", "unit_assignments"]


def unit_assignments(text: str) -> dict[str, str]:
    """``"x=m,f=N,k=N.m"`` -> ``{"x": "m", "f": "N", "k": "N.m"}`` (argparse type of --units)."""
    out: dict[str, str] = {}
    for item in (part.strip() for part in text.split(",") if part.strip()):
        name, sep, unit = item.partition("=")
        if not sep or not name.strip() or not unit.strip():
            raise argparse.ArgumentTypeError(f"{item!r} is not name=unit (e.g. x=m,f=N)")
        if name.strip() in out:
            raise argparse.ArgumentTypeError(f"{name.strip()!r} is given twice")
        out[name.strip()] = unit.strip()
    return out


def add_parser(sub: Any) -> argparse.ArgumentParser:
    """Add the ``build-estimator`` subcommand."""
    from ..cbuild import PLATFORMS
    from ..fmu.estimator_table import MOTION_INPUTS
    from ..identification.options import ENGINES

    p = sub.add_parser("build-estimator", help="build an estimator FMU for your own equation (C, FMI 2.0 or 3.0)",
                       description="Write the online identifier of your equations (the robust method by default, "
                                   "the same engine and options as `duffid identify --equation`) as a "
                                   "co-simulation FMU: inputs are the equation's displacements and forces, "
                                   "outputs <param>_hat (NaN unless published), <param>_status, identified, "
                                   "condition, uncertainty, window_length and outliers; parameters are the "
                                   "estimator options, <param>_nominal and sample_period (each doStep consumes "
                                   "one sample). With a C compiler (--backend auto, the default) the FMU is the "
                                   "C estimator core with its sources, binaries for --platforms, FMI 2.0 or 3.0; "
                                   "without one it is a pythonfmu FMU (FMI 2.0), which runs in a Python host "
                                   "(fmpy, ...) with duffid installed.")
    what = p.add_mutually_exclusive_group(required=True)
    what.add_argument("--equation", metavar="TEXT",
                      help='e.g. "m*der(x,2) + b*der(x) + c*x^2*der(x) + k*x + kp*x^3 = f" (several: separated by ;)')
    what.add_argument("--chain", type=int, metavar="N",
                      help="a chain of N masses from a wall, force on mass 1 (inputs x1..xN [m], f1 [N])")
    p.add_argument("--orders", default="1,3", help="--chain: the springs' stiffness orders (default 1,3)")
    p.add_argument("--coulomb", action="store_true", help="--chain: Coulomb friction on each mass")
    p.add_argument("--name", default=None,
                   help="model name and file stem (default EquationEstimator, or ChainEstimator<N>)")
    p.add_argument("--columns", default="t,f,x", metavar="LIST",
                   help="the signals as record columns (default t,f,x; 2 DOF: t,f,x1,x2); a, a1.. or v, v1.. for "
                        "a measured acceleration or velocity of the equation's x, x1.. (as --motion)")
    p.add_argument("--motion", choices=tuple(MOTION_INPUTS), default=None,
                   help="what the motion inputs measure: x displacement (default), v velocity or a acceleration "
                        "(inputs v1.., a1..): the online output-error fit, a pythonfmu FMU (FMI 2.0, a Python "
                        "host); --equation: default from --columns")
    p.add_argument("--units", type=unit_assignments, default=None, metavar="LIST",
                   help="units of the signals (x=m,f=N): the parameters' units follow from the equation; "
                        "give a parameter's unit too where they do not (k=N.m for k*sin(x))")
    p.add_argument("--fmi", type=int, choices=(2, 3), default=2, help="FMI version (default 2; 3 needs the C backend)")
    p.add_argument("--engine", "--backend", dest="backend", choices=ENGINES, default="auto",
                   help="c: the C estimator core; python: pythonfmu (FMI 2.0, a Python host); auto (default): "
                        "C when a C compiler is found, else python (one line says why)")
    p.add_argument("--platforms", default="all", metavar="LIST",
                   help=f"C backend: comma-separated binary platforms, {', '.join(PLATFORMS)} or all (default: "
                        "those whose compiler is installed; a missing cross compiler is skipped with one line "
                        "naming the Debian package)")
    p.add_argument("-o", "--output", type=Path, default=None,
                   help="a folder for the FMU, or the FMU file (its stem must be the name, with _fmi3 for FMI 3); "
                        "default: <name>.fmu / <name>_fmi3.fmu here")
    return p


def _target(output: Path | None, name: str, fmi: int) -> Path:
    """The folder of the FMU from -o (a folder, or the FMU file whose stem must match)."""
    stem = name if fmi == 2 else f"{name}_fmi3"
    if output is None:
        return Path(".")
    if output.suffix != ".fmu":
        if output.exists() and not output.is_dir():
            raise InputError(f"-o {output}: not a folder, and an FMU file must end in .fmu")
        return output
    if output.stem != stem:
        raise InputError(f"-o {output}: an FMU's file stem is its model name (FMI 3: <name>_fmi3); use "
                         f"--name {output.stem.removesuffix('_fmi3')} or -o {output.with_name(stem + '.fmu')}")
    return output.parent


def run(args: argparse.Namespace) -> int:
    """Build the FMU; print its path and its variables' units."""
    from ..cbuild import resolve_platforms
    from ..fmu.estimator import build_chain_fmu, build_equation_fmu

    from ..identification.motion import displacement_columns, measured_motion

    columns = [c.strip() for c in args.columns.split(",") if c.strip()]
    motion = measured_motion(columns)
    if args.motion is not None and motion != "x" and args.motion != motion:
        raise InputError(f"--columns {','.join(columns)} measure {motion}, --motion {args.motion}: give one of them")
    motion = args.motion or motion
    columns = displacement_columns(columns)  # the equation is written in the displacements
    name = args.name or ("EquationEstimator" if args.equation is not None else f"ChainEstimator{args.chain}")
    folder = _target(args.output, name, args.fmi)
    platforms, skipped = resolve_platforms(n.strip() for n in args.platforms.split(",") if n.strip())
    if args.backend != "python":
        for line in skipped:
            print(f"duffid build-estimator: {line}", file=sys.stderr)
    import fmpy

    common = {"name": name, "fmi_version": args.fmi, "backend": args.backend, "platforms": platforms,
              "motion": motion}
    if args.chain is not None:
        if args.units:
            raise InputError("--units applies to --equation; a chain is in m, N and s")
        try:
            orders = [int(o) for o in args.orders.split(",") if o.strip()]
        except ValueError:
            raise InputError(f"--orders must be integers separated by commas, got {args.orders!r}") from None
        path = build_chain_fmu(args.chain, folder, orders=orders, coulomb=args.coulomb, **common)
    else:
        path = build_equation_fmu(args.equation, folder, columns=columns, units=args.units, **common)
    print(path)
    md = fmpy.read_model_description(str(path))
    for v in md.modelVariables:
        if v.causality == "input" or v.name.endswith("_hat"):
            print(f"  {v.causality:<7} {v.name:<16} {v.unit or '(no unit: give --units)'}")
    return 0
