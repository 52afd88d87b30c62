"""``duffid build-estimator``: the online identifier of the user's own equations as an FMU
(pythonfmu, FMI 2.0 co-simulation; runs in a Python host with duffid installed)."""
from __future__ import annotations

import argparse
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
    p = sub.add_parser("build-estimator", help="build an estimator FMU for your own equation (pythonfmu, FMI 2.0)",
                       description="Write the online identifier of your equations (the robust method by default, "
                                   "the same engine and options as `duffid identify --equation`) as an FMI 2.0 "
                                   "co-simulation FMU: inputs are the equation's displacements and forces, "
                                   "outputs <param>_hat (NaN unless published), <param>_status, identified, "
                                   "condition, uncertainty, window_length and outliers; parameters are the "
                                   "estimator options, <param>_nominal and sample_period (each doStep consumes "
                                   "one sample). The FMU runs in a Python host (fmpy, ...) with duffid installed.")
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
                   help="the signals as record columns (default t,f,x; 2 DOF: t,f,x1,x2)")
    p.add_argument("--units", type=unit_assignments, default=None, metavar="LIST",
                   help="units of the signals (x=m,f=N): the parameters' units follow from the equation; "
                        "give a parameter's unit too where they do not (k=N.m for k*sin(x))")
    p.add_argument("-o", "--output", type=Path, default=None, help="the FMU to write (default <name>.fmu)")
    return p


def run(args: argparse.Namespace) -> int:
    """Build the FMU; print its path and its variables' units."""
    from ..fmu.python_estimator import build_chain_fmu, build_equation_fmu

    columns = [c.strip() for c in args.columns.split(",") if c.strip()]
    name = args.name or ("EquationEstimator" if args.equation is not None else f"ChainEstimator{args.chain}")
    output = args.output or Path(f"{name}.fmu")
    if output.suffix != ".fmu":
        raise InputError(f"-o {output}: the file must end in .fmu")
    if output.stem != name:
        raise InputError(f"-o {output}: an FMU's file stem is its model name; use --name {output.stem} "
                         f"or -o {name}.fmu")
    import fmpy

    if args.chain is not None:
        if args.units:
            raise InputError("--units applies to --equation; a chain is in m, N and s")
        try:
            orders = [int(o) for o in args.orders.split(",") if o.strip()]
        except ValueError:
            raise InputError(f"--orders must be integers separated by commas, got {args.orders!r}") from None
        path = build_chain_fmu(args.chain, output.parent, orders=orders, coulomb=args.coulomb, name=name)
    else:
        path = build_equation_fmu(args.equation, output.parent, name=name, columns=columns, units=args.units)
    print(path)
    md = fmpy.read_model_description(str(path))
    for v in md.modelVariables:
        if v.causality == "input" or v.name.endswith("_hat"):
            print(f"  {v.causality:<7} {v.name:<16} {v.unit or '(no unit: give --units)'}")
    return 0
