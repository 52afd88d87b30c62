"""What the subcommands share: reading a record file (flags and errors that name the flag
to fix), choosing a model, and argument types."""
from __future__ import annotations

import argparse
import re
from pathlib import Path
from typing import Any

import numpy as np

from ..data.channels import ROLE_PATTERN
from ..data.formats import FORMATS, detect_format
from ..data.record import Record
from ..errors import RecordError
from ..identification.offsets import OFFSETS
from ..models.registry import MODEL_NAMES, model_from_name

__all__ = ["MODELS", "positive_float", "positive_int", "window_value", "role_pairs", "columns_value", "scales_value",
           "delimiter_value", "add_file_arguments", "add_model_arguments", "model_from_arguments", "read_record"]

#: The --model choices (duffid.models.registry).
MODELS = MODEL_NAMES


def positive_float(text: str) -> float:
    """An argument type: a finite positive number."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not (np.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"{text!r} must be a positive number")
    return value


def positive_int(text: str) -> int:
    """An argument type: a whole number of at least 1."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{text!r} must be at least 1")
    return value


def window_value(text: str) -> float | str:
    """``--window``: ``auto`` or a positive number of seconds."""
    return "auto" if text == "auto" else positive_float(text)


def role_pairs(text: str, flag: str, value: Any) -> dict[str, Any]:
    """``ROLE=VALUE,...`` of ``flag`` as a dict (roles t, f, x, v, a, f1.., x1..)."""
    out: dict[str, Any] = {}
    for item in (part.strip() for part in re.split(r",(?![^(]*\))", text)):  # not the comma of x(:,2)
        role, sep, raw = item.partition("=")
        role, raw = role.strip(), raw.strip()
        if not sep or not role or not raw:
            raise argparse.ArgumentTypeError(f"{item!r} is not ROLE=" + ("COLUMN" if flag == "--columns" else "FACTOR"))
        if not ROLE_PATTERN.fullmatch(role):
            raise argparse.ArgumentTypeError(f"unknown role {role!r} (roles: t, f, x, v, a, or f1.., x1..)")
        if role in out:
            raise argparse.ArgumentTypeError(f"{role} is given twice")
        out[role] = value(raw)
    return out


def columns_value(text: str) -> dict[str, str | int]:
    """``--columns ROLE=COLUMN,...``: the column or channel of each signal, by name (``group/channel``,
    a dataset path) or 1-based number."""
    return role_pairs(text, "--columns", lambda raw: int(raw) if raw.isdigit() else raw)


def scales_value(text: str) -> dict[str, float]:
    """``--scale ROLE=FACTOR,...``: finite non-zero factors into SI units."""
    def factor(raw: str) -> float:
        try:
            value = float(raw)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{raw!r} is not a number") from None
        if not (np.isfinite(value) and value != 0):
            raise argparse.ArgumentTypeError(f"{raw!r} must be a finite non-zero number")
        return value
    return role_pairs(text, "--scale", factor)


def delimiter_value(text: str) -> str:
    """``--delimiter``: one character, or a name such as ``tab``."""
    text = {"tab": "\t", "\\t": "\t", "space": " "}.get(text, text)
    if len(text) != 1:
        raise argparse.ArgumentTypeError(f"one character (or tab, space), got {text!r}")
    return text


def add_file_arguments(p: argparse.ArgumentParser) -> None:
    """The options that say how to read a record file (CSV from a logger, .mat, TDMS, UFF, HDF5, WAV)."""
    g = p.add_argument_group("reading the file (CSV from a logger, .mat, TDMS, UFF 58/58b, HDF5, WAV)")
    g.add_argument("--format", choices=tuple(FORMATS), default=None,
                   help="the file's format (default: from its extension; duffid inspect FILE lists its channels)")
    g.add_argument("--columns", type=columns_value, default=None, metavar="ROLE=CHANNEL,...",
                   help="the column or channel of each signal, by name or 1-based number, e.g. "
                        "t=time_s,f=force_N,x=3 (roles t, f, x, or f1.., x1..; identify also takes a velocity v= "
                        "or an acceleration a= instead of x); TDMS: group/channel, HDF5: "
                        "dataset path, .mat: variable, WAV: channel number. Default: CSV header t,f,x; other "
                        "formats: the one force and one displacement channel, by unit or name")
    g.add_argument("--delimiter", type=delimiter_value, default=",", help="CSV field separator (default ','; tab, ';', ...)")
    g.add_argument("--decimal", choices=(".", ","), default=".",
                   help="CSV decimal mark (default '.'; ',' for files that write 1,5 - with --delimiter ';' or tab)")
    g.add_argument("--scale", type=scales_value, default=None, metavar="ROLE=FACTOR,...",
                   help="multiply columns into SI units (s, N, m, m/s, m/s^2), e.g. x=1e-3 for millimetres; replaces the "
                        "factor of a unit the file names; required for integer PCM WAV (the SI value at full "
                        "scale) and sensor voltages (1 / sensitivity)")
    g.add_argument("--fs", type=positive_float, default=None,
                   help="sampling frequency [Hz] of a file without a time column or variable")
    g.add_argument("--sampling-tolerance", type=positive_float, default=1e-6,
                   help="largest relative deviation of a time step from the median step (default 1e-6)")
    g.add_argument("--x-var", default="x", help=".mat: displacement variable name(s), comma separated")
    g.add_argument("--f-var", default="f", help=".mat: force variable name(s), comma separated")
    g.add_argument("--t-var", default=None, help=".mat: time variable name (or give --fs)")


def add_model_arguments(p: argparse.ArgumentParser) -> None:
    """The flags that choose the model structure (--model, --n-dof, --orders, --coulomb, --offset)."""
    p.add_argument("--model", choices=MODELS, default="duffing1", help="model structure (default duffing1)")
    p.add_argument("--n-dof", type=int, default=None, help="chain: number of masses (default: from the file)")
    p.add_argument("--orders", default="1,3", help="chain: stiffness orders, e.g. 1,2,3 (default 1,3)")
    p.add_argument("--coulomb", action="store_true", help="chain: Coulomb friction terms")
    p.add_argument("--offset", nargs="?", const="force", default=None, choices=tuple(OFFSETS), metavar="KIND",
                   help="identify sensor offsets (real data): " + "; ".join(f"{k}: {v}" for k, v in OFFSETS.items())
                        + ". The offsets found are reported")


def model_from_arguments(args: argparse.Namespace, n_dof: int | None = None, *, offset: bool = False):
    """The model the flags name (a chain sized from the record when --n-dof is not given)."""
    orders = [int(o) for o in args.orders.split(",") if o.strip()]
    return model_from_name(args.model, args.n_dof or n_dof or 1, orders=orders,
                           coulomb=args.coulomb, offset=offset)


def read_record(args: argparse.Namespace, path: Path | None = None, *, motion: bool = False) -> Record:
    """The record of ``path`` (default ``args.file``) read as the file flags say; errors name the flag that fixes them.
    ``motion``: velocities (``v=``) or accelerations (``a=``) may take the displacements' place."""
    path = path if path is not None else args.file
    if not path.exists():
        raise RecordError(f"{path}: no such file")
    fmt = detect_format(path, args.format)
    if fmt not in ("csv", "mat") or (fmt == "mat" and args.columns is not None):
        return Record.read(path, format=fmt, columns=args.columns, scale=args.scale, fs=args.fs,
                           sampling_rtol=args.sampling_tolerance, motion=motion)
    if fmt == "mat" and args.t_var is None and args.fs is None and (args.x_var, args.f_var) == ("x", "f"):
        # no flag names the variables: the channels by name, as duffid inspect lists them (t, f, x)
        return Record.read(path, format=fmt, columns=None, scale=args.scale,
                           sampling_rtol=args.sampling_tolerance, motion=motion)
    if fmt == "mat":
        split = lambda s: [v.strip() for v in s.split(",")] if "," in s else s  # noqa: E731
        record = Record.read_mat(path, x=split(args.x_var), f=split(args.f_var), t=args.t_var, fs=args.fs,
                                 sampling_rtol=args.sampling_tolerance)
        return record.scaled(args.scale) if args.scale else record
    try:
        return Record.read_csv(path, sampling_rtol=args.sampling_tolerance, columns=args.columns,
                               delimiter=args.delimiter, scale=args.scale, fs=args.fs, decimal=args.decimal,
                               motion=motion)
    except RecordError as exc:  # say which flags fix it
        text = str(exc)
        known = re.search(r"\(multiply (\w+) by ([^)]+)\)$", text)
        if known:
            raise RecordError(f"{text[:known.start()].rstrip()}: --scale {known.group(1)}={known.group(2)}") from None
        for needle, flag in (("scale it into", " with --scale ROLE=FACTOR"),
                             ("give the sampling rate", " (--fs HZ, or --columns t=...)"),
                             ("sampling rate were both given", " (drop --fs or the t in --columns)"),
                             ("is that the delimiter", " (--delimiter)"),
                             ("give the decimal mark", " (--decimal ,)"),
                             ("uneven sampling", " (or widen --sampling-tolerance)")):
            if needle in text:
                raise RecordError(text + flag) from None
        raise
