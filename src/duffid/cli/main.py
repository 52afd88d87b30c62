"""Command-line interface ``duffid`` (argparse: identify, simulate, nonlinearity, silverbox, build-fmus, cosim,
demo, paper-cases)."""
from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from ..analysis import silverbox
from ..cosim import config as cosim_config
from ..data.record import Record
from ..data.signals import from_spec
from ..errors import DuffidError, InputError, RecordError
from ..identification.engine import METHODS
from ..identification.options import ONLINE_METHODS, add_arguments, options_from_arguments
from ..identification.trust import OFFSETS, identify
from ..modelica import export as modelica
from ..models.chain import model_from_name
from ..models.simulation import measure, simulate

__all__ = ["main", "build_parser"]

MODELS = ("duffing1", "duffing2", "chain", "circuit")


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not (np.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"{text!r} must be a positive number")
    return value


def _window(text: str) -> float | str:
    return "auto" if text == "auto" else _positive_float(text)


def _role_pairs(text: str, flag: str, value: Any) -> dict[str, Any]:
    """``ROLE=VALUE,...`` of ``flag`` as a dict (roles t, f, x, f1.., x1..)."""
    out: dict[str, Any] = {}
    for item in (part.strip() for part in text.split(",")):
        role, sep, raw = item.partition("=")
        role, raw = role.strip(), raw.strip()
        if not sep or not role or not raw:
            raise argparse.ArgumentTypeError(f"{item!r} is not ROLE=" + ("COLUMN" if flag == "--columns" else "FACTOR"))
        if not re.fullmatch(r"[tfx]|[fx][1-9][0-9]*", role):
            raise argparse.ArgumentTypeError(f"unknown role {role!r} (roles: t, f, x, or f1.., x1..)")
        if role in out:
            raise argparse.ArgumentTypeError(f"{role} is given twice")
        out[role] = value(raw)
    return out


def _columns(text: str) -> dict[str, str | int]:
    return _role_pairs(text, "--columns", lambda raw: int(raw) if raw.isdigit() else raw)


def _scales(text: str) -> dict[str, float]:
    def factor(raw: str) -> float:
        try:
            value = float(raw)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{raw!r} is not a number") from None
        if not (np.isfinite(value) and value != 0):
            raise argparse.ArgumentTypeError(f"{raw!r} must be a finite non-zero number")
        return value
    return _role_pairs(text, "--scale", factor)


def _delimiter(text: str) -> str:
    text = {"tab": "\t", "\\t": "\t", "space": " "}.get(text, text)
    if len(text) != 1:
        raise argparse.ArgumentTypeError(f"one character (or tab, space), got {text!r}")
    return text


def _add_file_arguments(p: argparse.ArgumentParser) -> None:
    """The options that say how to read a record file (CSV from a logger, or .mat)."""
    g = p.add_argument_group("reading the file (CSV from a logger, .mat)")
    g.add_argument("--columns", type=_columns, default=None, metavar="ROLE=COLUMN,...",
                   help="CSV: the column of each signal, by header name or 1-based number, e.g. "
                        "t=time_s,f=force_N,x=3 (roles t, f, x, or f1.., x1..); default: header t,f,x")
    g.add_argument("--delimiter", type=_delimiter, default=",", help="CSV field separator (default ','; tab, ';', ...)")
    g.add_argument("--scale", type=_scales, default=None, metavar="ROLE=FACTOR,...",
                   help="multiply columns into SI units (s, N, m), e.g. x=1e-3 for millimetres")
    g.add_argument("--fs", type=_positive_float, default=None,
                   help="sampling frequency [Hz] of a file without a time column or variable")
    g.add_argument("--sampling-tolerance", type=_positive_float, default=1e-6,
                   help="largest relative deviation of a time step from the median step (default 1e-6)")
    g.add_argument("--x-var", default="x", help=".mat: displacement variable name(s), comma separated")
    g.add_argument("--f-var", default="f", help=".mat: force variable name(s), comma separated")
    g.add_argument("--t-var", default=None, help=".mat: time variable name (or give --fs)")


def _add_model_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--model", choices=MODELS, default="duffing1", help="model structure (default duffing1)")
    p.add_argument("--n-dof", type=int, default=None, help="chain: number of masses (default: from the file)")
    p.add_argument("--orders", default="1,3", help="chain: stiffness orders, e.g. 1,2,3 (default 1,3)")
    p.add_argument("--coulomb", action="store_true", help="chain: Coulomb friction terms")
    p.add_argument("--offset", nargs="?", const="force", default=None, choices=tuple(OFFSETS), metavar="KIND",
                   help="identify sensor offsets (real data): " + "; ".join(f"{k}: {v}" for k, v in OFFSETS.items())
                        + ". The offsets found are reported")


def _model(args: argparse.Namespace, n_dof: int | None = None, *, offset: bool = False):
    orders = [int(o) for o in args.orders.split(",") if o.strip()]
    return model_from_name(args.model, args.n_dof or n_dof or 1, orders=orders,
                           coulomb=args.coulomb, offset=offset)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser (exposed for documentation and tests)."""
    parser = argparse.ArgumentParser(prog="duffid", description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("identify", help="identify a model's parameters from a CSV or .mat record")
    p.add_argument("file", type=Path, help="record: CSV (t, f, x or t, f1.., x1..) or .mat")
    _add_model_arguments(p)
    p.add_argument("--method", choices=METHODS, default=None,
                   help="robust (default), paper, or a buffered basis; with --equation: paper (default) or a basis")
    p.add_argument("--equation", default=None, metavar="TEXT",
                   help='model equation, e.g. "m*der(x,2) + b*der(x) + k*x + kp*x^3 = f": names that are '
                        "columns of the file are signals, all other names unknown parameters")
    g = p.add_argument_group("robust method options")
    g.add_argument("--window", type=_window, default=None,
                   help="window length in s (robust: or auto, the default; buffered: default 0.25)")
    add_arguments(g, "robust", ("window_periods", "max_window", "forgetting", "rows", "n_rows", "settle"))
    g.add_argument("--max-uncertainty", type=_positive_float, default=None,
                   help="largest relative standard error of a published parameter (default 0.01)")
    g.add_argument("--no-refine", action="store_true",
                   help="do not refine by output-error least squares when the algebraic estimate leaves "
                        "excited parameters undetermined (faster; fewer values published)")
    g = p.add_argument_group("paper method options")
    add_arguments(g, "paper", ("gamma",))
    g.add_argument("--quadrature", choices=("adams3", "trapezoid", "gauss", "simpson"), default=None,
                   help="paper: adams3 (default) or trapezoid; buffered coefficients: gauss (default), "
                        "simpson or trapezoid")
    add_arguments(g, "paper", ("sign_in_numerator",))
    g = p.add_argument_group("options of both online methods (robust and paper)")
    add_arguments(g, "robust", ("max_condition", "min_time"))
    g = p.add_argument_group("buffered methods (legendre, chebyshev, block-pulse, haar)")
    g.add_argument("--terms", type=int, default=None, help="basis functions per window")
    g.add_argument("--every", type=int, default=None, help="samples between re-identifications (default: a window)")
    g.add_argument("--form", choices=("per-dof", "matrix"), default=None, help="per-DOF or matrix form (eqs. 36-37)")
    g.add_argument("--repeated", choices=("power", "exact"), default=None,
                   help="repeated integration: powers of P (paper) or the exact matrix")
    g.add_argument("--accumulate", action="store_true", help="least squares over all windows so far")
    _add_file_arguments(p)
    p.add_argument("--deadband", type=float, default=None, help="Coulomb: |dx| below which the velocity sign is held")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--plot", type=Path, default=None, help="write estimates vs time to this PNG")

    p = sub.add_parser("simulate", help="write a simulated record (CSV) of a named model")
    _add_model_arguments(p)
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="parameter value, e.g. kp=-1.2e6 (repeatable; names as in the model)")
    p.add_argument("--excitation", default="step:10", help="e.g. step:10, chirp:2,0,20,10, sweep:2.96,2.5,20, "
                   "multisine:1,1,30,2, sums with + (default step:10)")
    p.add_argument("--t-end", type=_positive_float, default=2.0, help="duration [s]")
    p.add_argument("--dt", type=_positive_float, default=1e-3, help="sampling period [s]")
    p.add_argument("--pulses-per-cm", type=_positive_float, default=None, help="encoder quantisation (paper: 2266)")
    p.add_argument("--snr-db", type=float, default=None, help="Gaussian noise on x at this SNR [dB]")
    p.add_argument("--seed", type=int, default=0, help="noise seed")
    p.add_argument("-o", "--output", type=Path, required=True, help="CSV file to write")

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
    _add_file_arguments(p)

    silverbox.add_cli(sub)
    p = modelica.add_cli(sub)
    p.description = ("Build every Modelica example plant as <Name>.fmu (FMI 2.0) and <Name>_fmi3.fmu "
                     "(FMI 3.0), the estimator FMUs DuffingEstimator{1,2}.fmu, _fmi3.fmu (C) and "
                     "_python.fmu (pythonfmu), the controller FMUs AdaptiveController{1,2}.fmu and the "
                     "whole 1-DOF loop as the container FMU ClosedLoop1DOF.fmu.")
    p.add_argument("--no-estimators", action="store_true",
                   help="build the plant FMUs only (no estimators, controllers or ClosedLoop1DOF)")

    cosim_config.add_cli(sub)

    p = sub.add_parser("demo", help="the main job: plant <-> identifier <-> adaptive controller co-simulation")
    p.add_argument("--out", type=Path, default=Path("out"), help="output folder (default out/)")
    p.add_argument("--fmu-dir", type=Path, default=Path("build/fmus"),
                   help="FMU folder, built there if missing or stale (default build/fmus)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of tables")
    p.add_argument("--progress", action="store_true", help="progress bars for the co-simulation runs")

    p = sub.add_parser("paper-cases", help="identify the paper's 1-DOF and 2-DOF cases from simulated records")
    p.add_argument("--out", type=Path, default=Path("out"), help="output folder (default out/)")
    p.add_argument("--json", action="store_true", help="print a JSON summary instead of tables")
    return parser


def _read_record(args: argparse.Namespace, path: Path | None = None) -> Record:
    path = path if path is not None else args.file
    if not path.exists():
        raise RecordError(f"{path}: no such file")
    if path.suffix.lower() == ".mat":
        split = lambda s: [v.strip() for v in s.split(",")] if "," in s else s  # noqa: E731
        record = Record.read_mat(path, x=split(args.x_var), f=split(args.f_var), t=args.t_var, fs=args.fs,
                                 sampling_rtol=args.sampling_tolerance)
        return record.scaled(args.scale) if args.scale else record
    try:
        return Record.read_csv(path, sampling_rtol=args.sampling_tolerance, columns=args.columns,
                               delimiter=args.delimiter, scale=args.scale, fs=args.fs)
    except RecordError as exc:  # say which flags fix it
        text = str(exc)
        known = re.search(r"\(multiply (\w+) by ([^)]+)\)$", text)
        if known:
            raise RecordError(f"{text[:known.start()].rstrip()}: --scale {known.group(1)}={known.group(2)}") from None
        for needle, flag in (("scale it into", " with --scale ROLE=FACTOR"),
                             ("give the sampling rate", " (--fs HZ, or --columns t=...)"),
                             ("sampling rate were both given", " (drop --fs or the t in --columns)"),
                             ("is that the delimiter", " (--delimiter)"),
                             ("uneven sampling", " (or widen --sampling-tolerance)")):
            if needle in text:
                raise RecordError(text + flag) from None
        raise


_BUFFERED_NAMES = {"window": "window", "terms": "n_terms", "every": "every", "quadrature": "quadrature",
                   "form": "form", "repeated": "repeated", "max_uncertainty": "max_uncertainty", "deadband": "deadband"}


def _method_options(args: argparse.Namespace, method: str) -> dict[str, Any]:
    """The options given on the command line that ``method`` takes."""
    if method in ONLINE_METHODS:
        return options_from_arguments(args, method)
    options = {option: getattr(args, arg) for arg, option in _BUFFERED_NAMES.items() if getattr(args, arg) is not None}
    if options.get("window") == "auto":
        raise InputError("--window auto applies to the robust method; give the buffered window in seconds")
    if args.accumulate:
        options["accumulate"] = True
    return options


def _identify(args: argparse.Namespace) -> int:
    record = _read_record(args)
    method = args.method or ("paper" if args.equation else "robust")
    options = _method_options(args, method)
    if args.equation is not None:
        if args.offset is not None:
            raise InputError("--offset applies to the named models; with --equation write the offset into the "
                             "equation (e.g. '... + c = f', or x - x0 in place of x)")
        if args.no_refine:
            raise InputError("--no-refine applies to the named models; equation models are not refined")
        from ..identification.equation import identify_equation
        result = identify_equation(record, args.equation, method, **options)
    else:
        result = identify(record, _model(args, record.n_dof), method, offsets=args.offset,
                          refine=not args.no_refine, **options)
    if args.plot is not None:
        from ..apps.plots import plot_estimates
        plot_estimates(result, args.plot)
    if args.json:
        print(result.to_json())
        return 0
    print(f"{record.source}: {record.n_samples} samples, dt {record.dt:g} s, model {result.model}, method {method}")
    print(_result_text(result))
    return 0


def _result_text(result: Any) -> str:
    """The identification as the CLI prints it: values only where published, with status and
    uncertainty, the fit figures and the notes (the same facts as the JSON)."""
    a = result.assessment
    lines = [f"  {'parameter':>10} {'value':>13}  {'status':<12} {'uncertainty':>11}"]
    for name, value in result.parameters.items():
        shown = f"{value:.6g}" if np.isfinite(value) else "-"
        if a is None:
            lines.append(f"  {name:>10} {shown:>13}  {'unchecked':<12}")
            continue
        u = a.uncertainty.get(name, float("nan"))
        lines.append(f"  {name:>10} {shown:>13}  {a.status[name]:<12} "
                     f"{(f'{100 * u:.2g} %' if np.isfinite(u) else '-'):>11}")
    if a is None:
        lines.append("  not checked against the record (equation models are not checked yet): "
                     "treat these values as unverified")
        return "\n".join(lines)
    fit = a.fit
    lines.append(f"  identified: {'yes' if result.is_identified else 'no (not every parameter is published)'}")
    sim, noise = fit.get("simulation_nrmse"), fit.get("noise_nrmse")
    if sim is not None and np.isfinite(sim):
        lines.append(f"  fit: the identified model misses the measured displacement by {100 * sim:.3g} % RMS "
                     f"(measurement noise {100 * noise:.2g} %); {fit['samples_per_period']:.3g} samples per period"
                     + (f" after upsampling x{fit['upsampled']}" if fit["upsampled"] > 1 else ""))
    offsets = fit.get("offsets") or {}
    if offsets:
        shown = []
        for name, entry in offsets.items():
            value, error = entry.get("value"), entry.get("standard_error")
            text = f"{value:.6g}" if value is not None and np.isfinite(value) else "-"
            if error is not None and np.isfinite(error):
                text += f" (standard error {error:.2g})"
            shown.append(f"{name} = {text} {entry.get('status', '')}")
        lines.append("  offsets (what the sensors read at zero force and displacement): " + ", ".join(shown))
    for note in a.notes:
        lines.append(f"  - {note}")
    return "\n".join(lines)


def _nonlinearity(args: argparse.Namespace) -> int:
    from ..analysis import nonlinearity as nl
    from ..apps.plots import plot_eta_vs_amplitude, plot_hilbert

    records = [_read_record(args, path) for path in args.files]
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


def _build_fmus(args: argparse.Namespace) -> int:
    """Plant FMUs (Modelica export), then the estimator FMUs (C core and pythonfmu)."""
    status = modelica.run_cli(args)
    if status or args.no_estimators or args.plant:
        return status
    from ..control.closed_loop import build_closed_loop_fmu, mark_fmus_current
    from ..control.controller_fmu import build_controller_fmus
    from ..fmu.estimator import build_estimator_fmus
    for path in [*build_estimator_fmus(args.out), *build_controller_fmus(args.out)]:
        print(path)
    mark_fmus_current(args.out)
    print(build_closed_loop_fmu(args.out))
    return 0


def _simulate(args: argparse.Namespace) -> int:
    if args.offset not in (None, "force"):
        raise InputError(f"--offset {args.offset} is for identify: a simulated record has no sensor offsets "
                         f"(add one to the written x column)")
    model = _model(args, offset=args.offset is not None)
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


def _demo(args: argparse.Namespace) -> int:
    from ..apps.demo import run_demo
    if args.json:
        import io
        summary = run_demo(args.out, fmu_dir=args.fmu_dir, stream=io.StringIO(), progress=args.progress)
        print(json.dumps(summary))
    else:
        run_demo(args.out, fmu_dir=args.fmu_dir, progress=args.progress)
    return 0


def _paper_cases(args: argparse.Namespace) -> int:
    from ..apps.paper_cases import run_paper_cases
    if args.json:
        import io
        summary = run_paper_cases(args.out, stream=io.StringIO())
        print(json.dumps(summary))
    else:
        run_paper_cases(args.out)
    return 0


def _bare_offset(argv: Sequence[str]) -> list[str]:
    """``argv`` with a bare ``--offset`` written before an existing file (``--offset rec.csv``, as
    scripts wrote it before the flag took a KIND) spelled ``--offset=force``."""
    out = list(argv)
    for i, item in enumerate(out[:-1]):
        following = out[i + 1]
        if item == "--offset" and following not in OFFSETS and not following.startswith("-") \
                and Path(following).exists():
            out[i] = "--offset=force"
    return out


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``duffid`` command; returns the exit status."""
    args = build_parser().parse_args(_bare_offset(sys.argv[1:] if argv is None else argv))
    handlers = {"identify": _identify, "simulate": _simulate, "nonlinearity": _nonlinearity,
                "silverbox": silverbox.run_cli, "build-fmus": _build_fmus, "demo": _demo,
                "cosim": cosim_config.run_cli,
                "paper-cases": _paper_cases}
    try:
        return handlers[args.command](args)
    except DuffidError as exc:  # the user's input or tools; anything else is a bug and surfaces
        print(f"duffid {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # a file that cannot be read or written
        print(f"duffid {args.command}: error: {exc.strerror or exc}"
              + (f": {exc.filename}" if exc.filename else ""), file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
