"""``duffid identify``: a model's parameters from a record, published only where the record
supports them."""
from __future__ import annotations

import argparse
import math
import json
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from ..data.units import si_unit
from ..errors import InputError
from ..identification.changes import change_test_options, find_changes, identify_segments
from ..identification.engine import METHODS
from ..identification.options import (
    BUFFERED_METHODS,
    add_arguments,
    add_shared_arguments,
    options_from_arguments,
)
from ..identification.offsets import OFFSETS
from ..identification.trust import identify
from ..models.registry import model_from_name
from .common import (
    MODELS,
    add_file_arguments,
    add_model_arguments,
    model_from_arguments,
    positive_int,
    read_record,
)

__all__ = ["add_parser", "run", "equation_text", "result_text", "bare_offset"]


def add_parser(sub: Any) -> argparse.ArgumentParser:
    """Add the ``identify`` subcommand."""
    p = sub.add_parser("identify", help="identify a model's parameters from a record file")
    p.add_argument("file", type=Path, help="record: CSV (t, f, x or t, f1.., x1..), .mat (v5 or v7.3), TDMS, "
                                           "UFF 58/58b, HDF5 or WAV (duffid inspect FILE lists its channels)")
    add_model_arguments(p)
    p.add_argument("--method", choices=METHODS, default=None,
                   help="robust (default), paper, or a buffered basis (the same for --equation)")
    p.add_argument("--equation", default=None, metavar="TEXT",
                   help='model equation, e.g. "m*der(x,2) + b*der(x) + k*x + kp*x^3 = f": names that are '
                        "columns of the file are signals, all other names unknown parameters; a model name ("
                        + ", ".join(m for m in MODELS if m != "circuit") + ") stands for that model's "
                        "equations (--n-dof, --orders, --coulomb as for --model), printed with the results")
    g = p.add_argument_group("options of several methods (each method reads its own meaning and default)")
    add_shared_arguments(g, ("window", "max_uncertainty", "max_condition", "quadrature", "deadband"),
                         METHODS)
    g = p.add_argument_group("robust method options")
    add_arguments(g, "robust", ("window_periods", "max_window", "forgetting", "rows", "n_rows", "settle",
                                "change_threshold", "change_memory", "jump_restart"))
    g.add_argument("--no-refine", action="store_true",
                   help="do not refine by output-error least squares when the algebraic estimate leaves "
                        "excited parameters undetermined (faster; fewer values published)")
    g = p.add_argument_group("paper method options")
    add_arguments(g, "paper", ("gamma", "sign_in_numerator"))
    g = p.add_argument_group("options of both online methods (robust and paper)")
    add_arguments(g, "robust", ("min_time",))
    g = p.add_argument_group("buffered methods (" + ", ".join(BUFFERED_METHODS) + ")")
    add_arguments(g, BUFFERED_METHODS[0], ("n_terms", "every", "form", "repeated", "accumulate"))
    add_file_arguments(p)
    p.add_argument("--segments", action="store_true",
                   help="find where the plant changed (the robust method's online change test) and identify each "
                        "stretch between the changes with every check")
    p.add_argument("--jobs", type=positive_int, default=None, metavar="N",
                   help="threads for the checks' independent estimator runs (default: every core this "
                        "process may use); the results are the same, bit for bit, for any number")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--plot", type=Path, default=None, help="write estimates vs time to this PNG")

    return p


def _method_options(args: argparse.Namespace, method: str) -> dict[str, Any]:
    """The options given on the command line that ``method`` takes (the schema's names)."""
    return options_from_arguments(args, method)


def run(args: argparse.Namespace) -> int:
    """Run ``duffid identify``: read, identify, check, print (table or ``--json``), plot."""
    record = read_record(args, motion=True)
    method = args.method or "robust"
    options = _method_options(args, method)
    if record.motion != "x":
        return _run_motion(args, record, method, options)
    if args.equation is not None:
        if args.offset not in (None, "force"):
            raise InputError(f"--offset {args.offset} applies to the named models; with --equation write the "
                             "offset into the equation (e.g. '... + c = f'), or --offset force to add a constant "
                             "to each equation")
        from ..identification.equation import identify_equation
        result = identify_equation(record, equation_text(args, record.n_dof), method, offsets=args.offset,
                                   refine=not args.no_refine, jobs=args.jobs, **options)
    else:
        model = model_from_arguments(args, record.n_dof)
        if args.segments:
            return _run_segments(args, record, model, method, options)
        result = identify(record, model, method, offsets=args.offset, refine=not args.no_refine, jobs=args.jobs,
                          **options)
    if args.plot is not None:
        from ..apps.plots import plot_estimates
        plot_estimates(result, args.plot)
    if args.json:
        print(result.to_json())
        return 0
    print(f"{record.source}: {record.n_samples} samples, dt {record.dt:g} s, model {result.model}, method {method}")
    if args.equation is not None:
        print(f"  equation: {result.options['equation']}")
    elif not model.reciprocal:  # the circuit's q/C has no text linear in its parameters
        print(f"  equation: {model.equation_text()}")
    print(result_text(result))
    if args.equation is None and method == "robust" and not result.is_identified:  # did the plant change?
        changes = find_changes(record, model, **change_test_options(options))
        if changes:
            print("  - the online change test flagged a change of the plant: "
                  + "; ".join(c.describe() for c in changes) + ". --segments identifies each stretch between them")
    return 0


def _run_motion(args: argparse.Namespace, record: Any, method: str, options: dict[str, Any]) -> int:
    """``identify`` of a velocity or acceleration record: the output-error fit of
    :func:`~duffid.identification.motion.identify_motion` (table or ``--json``)."""
    from ..identification.motion import MOTIONS, displacement_columns, identify_motion
    from ..models.equation_model import EquationModel

    word = MOTIONS[record.motion]
    refused = [flag for flag, given in (("--segments", args.segments),
                                        ("--method", args.method not in (None, "robust")),
                                        ("--offset", args.offset is not None))
               if given]
    others = sorted(set(options) - {"max_uncertainty"})
    if refused or others:
        named = refused + [f"--{name.replace('_', '-')}" for name in others]
        raise InputError(f"{record.source}: {', '.join(named)} do(es) not apply to this {word} record: it is identified "
                         f"by fitting the simulated {word} to the measured one (with the sensor's bias), only "
                         "--max-uncertainty, --equation, --plot, --jobs and the file flags apply")
    if args.equation is not None:  # written in the displacements whose motion the record measures
        model = EquationModel(equation_text(args, record.n_dof), displacement_columns(record))
    else:
        model = model_from_arguments(args, record.n_dof)
    extra = {"max_uncertainty": options["max_uncertainty"]} if "max_uncertainty" in options else {}
    result = identify_motion(record, model, **extra)
    if args.plot is not None:  # the online fit's published values vs time, and the record's
        from dataclasses import replace

        from ..apps.plots import plot_estimates
        from ..identification.motion_online import run_motion_online
        online = run_motion_online(record, model, **extra)
        plot_estimates(replace(result, t=online.t, history=online.history, t_identified=online.t_identified),
                       args.plot, title=f"{result.model}: {online.method} (published values vs time), and the "
                                        "record's fit", run_label="published online")
    if args.json:
        print(result.to_json())
        return 0
    print(f"{record.source}: {record.n_samples} samples, dt {record.dt:g} s, {word} measured, model {result.model}, "
          f"method {result.method}")
    if isinstance(model, EquationModel):
        print(f"  equation: {'; '.join(model.texts)}")
    elif not model.reciprocal:
        print(f"  equation: {model.equation_text()}")
    print(result_text(result))
    return 0


def _run_segments(args: argparse.Namespace, record: Any, model: Any, method: str, options: dict[str, Any]) -> int:
    """``identify --segments``: the changes, then each stretch identified (table or JSON)."""
    if method != "robust":
        raise InputError(f"--segments: the change test is the robust method's; --method {method} has none")
    test = change_test_options(options)
    if test.get("change_threshold", 0.0) is None:
        raise InputError("--segments needs the change test: --change-threshold must not be none")
    changes = find_changes(record, model, **test)
    segments = identify_segments(record, model, changes, offsets=args.offset, refine=not args.no_refine,
                                 jobs=args.jobs, **options)
    if args.json:
        print(json.dumps({"source": record.source, "model": model.name,
                          "changes": [{"flagged": c.flagged, "onset": c.onset, "parameters": list(c.parameters)}
                                      for c in changes],
                          "segments": [{"start": s.start, "stop": s.stop, "note": s.note,
                                        "result": None if s.result is None else json.loads(s.result.to_json())}
                                       for s in segments]}))
        return 0
    print(f"{record.source}: {record.n_samples} samples, dt {record.dt:g} s, model {model.name}, method {method}")
    print("  changes of the plant: " + ("; ".join(c.describe() for c in changes) if changes else
                                        "none found (the whole record is one stretch)"))
    for s in segments:
        print(f"stretch {s.start:.4g} s .. {s.stop:.4g} s")
        print(result_text(s.result) if s.result is not None else f"  not identified: {s.note}")
    return 0


def equation_text(args: argparse.Namespace, n_dof: int) -> str:
    """The text of ``--equation``: as given, or the equations of the model it names
    (:meth:`duffid.models.chain.Chain.equation_text`, sized by --n-dof or the record)."""
    name = args.equation.strip()
    if name not in MODELS:
        return args.equation
    orders = [int(o) for o in args.orders.split(",") if o.strip()]
    try:
        return model_from_name(name, args.n_dof or n_dof, orders=orders, coulomb=args.coulomb).equation_text()
    except InputError as exc:
        raise InputError(f"--equation: {exc}") from None


def result_text(result: Any) -> str:
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
        lines.append("  not checked against the record: treat these values as unverified")
        return "\n".join(lines)
    fit = a.fit
    lines.append(f"  identified: {'yes' if result.is_identified else 'no (not every parameter is published)'}")
    sim, noise = fit.get("simulation_nrmse"), fit.get("noise_nrmse")
    if sim is not None and np.isfinite(sim):
        periods = fit.get("samples_per_period")
        lines.append(f"  fit: the identified model misses the measured {fit.get('signal', 'displacement')} by "
                     f"{100 * sim:.3g} % RMS (measurement noise {100 * noise:.2g} %)"
                     + (f"; {periods:.3g} samples per period" if periods is not None else "")
                     + (f" after upsampling x{fit['upsampled']}" if fit.get("upsampled", 1) > 1 else ""))
    bias = fit.get("bias")
    if bias:
        errors = fit.get("bias_std") or [math.nan] * len(bias)
        unit = fit.get("bias_unit") or si_unit(fit.get("signal", "displacement"))
        lines.append("  sensor bias (fitted): " + ", ".join(f"{b:.4g} {unit} (standard error {e:.2g} {unit})"
                                                          for b, e in zip(bias, errors)))
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


def bare_offset(argv: Sequence[str]) -> list[str]:
    """``argv`` with a bare ``--offset`` written before an existing file (``--offset rec.csv``, as
    scripts wrote it before the flag took a KIND) spelled ``--offset=force``."""
    out = list(argv)
    for i, item in enumerate(out[:-1]):
        following = out[i + 1]
        if item == "--offset" and following not in OFFSETS and not following.startswith("-") \
                and Path(following).exists():
            out[i] = "--offset=force"
    return out
