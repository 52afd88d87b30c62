"""CSV and other delimited text files, listed for ``duffid inspect``: the header's columns,
the units row if there is one, and the number of data rows (the record itself is read by
:meth:`duffid.data.record.Record.read_csv`, strictly)."""
from __future__ import annotations

import csv
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np

from ...errors import RecordError
from ..channels import Channel, unit_in_name
from ..units import lookup
from . import reading

__all__ = ["EXTENSIONS", "open_channels"]

EXTENSIONS = (".csv", ".txt", ".tsv", ".dat")


@contextmanager
def open_channels(path: str) -> Iterator[list[Channel]]:
    """The columns of the text file ``path`` (names, units row, rows; the rate from a ``t`` column).

    Errors as :mod:`duffid.data.readers` says.
    """
    with reading(path, "text file"), open(path, encoding="utf-8-sig", newline="") as fh:
        lines = [line for line in fh.read().splitlines() if line.strip()]
    body = [line for line in lines if not line.lstrip().startswith("#")]
    if not body:
        raise RecordError(f"{path}: empty file, expected a header line followed by data rows")
    try:
        dialect = csv.Sniffer().sniff(body[0], delimiters=",;\t ")
    except csv.Error:
        dialect = csv.excel
    rows = list(csv.reader(body, dialect))
    names = [n.strip() for n in rows[0]]

    def number(text: str) -> float | None:
        try:
            return float(text)
        except ValueError:
            return None

    units = [""] * len(names)
    data = rows[1:]
    if data and all(number(f) is None for f in data[0]):
        units, data = [u.strip() for u in data[0]], data[1:]
    rate = None
    time_unit = lookup(units[0] or unit_in_name(names[0])) if names else None
    seconds = time_unit.factor if time_unit is not None and time_unit.quantity == "time" else 1.0
    if names and (names[0].lower() in ("t", "time", "time_s") or time_unit is not None) and len(data) > 1:
        t0, t1 = number(data[0][0]), number(data[1][0])
        if t0 is not None and t1 is not None and t1 > t0:
            rate = 1.0 / ((t1 - t0) * seconds)
    def not_here() -> np.ndarray:
        raise RecordError(f"{path}: a text file's columns are read by Record.read_csv")

    yield [Channel(name, units[k] if k < len(units) and units[k] else None, len(data), rate, kind="text",
                   read=not_here) for k, name in enumerate(names)]
