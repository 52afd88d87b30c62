"""The results of a campaign in a Parquet file, written as they arrive.

While a campaign runs, rows are appended in small Parquet files in ``<output>.parts/``
(each one complete on disk as soon as it is written, so that an interruption, even a
killed process, loses at most the rows not yet flushed); when the campaign ends or is
interrupted, the parts and any earlier results are merged into ``<output>`` (written to a
temporary file and renamed), one row per task, the latest.
"""
from __future__ import annotations

import math
import os
import shutil
import time
from pathlib import Path
from typing import Any, Iterable, Sequence

import pyarrow as pa
import pyarrow.parquet as pq

from ..errors import InputError

__all__ = ["ResultStore", "read_results"]


def _parts_folder(output: Path) -> Path:
    return output.with_name(output.name + ".parts")


def _read_tables(output: Path) -> list[pa.Table]:
    tables = []
    sources = ([output] if output.is_file() else []) + (
        sorted(_parts_folder(output).glob("part-*.parquet")) if _parts_folder(output).is_dir() else [])
    for source in sources:
        try:
            tables.append(pq.read_table(source))
        except (pa.ArrowInvalid, OSError) as exc:
            if source == output:
                raise InputError(f"{output}: not a results file of duffid campaign ({exc})") from None
            # a part cut short by a killed process: its rows run again
    return tables


def _merge(tables: Iterable[pa.Table]) -> pa.Table | None:
    tables = [t for t in tables if t.num_rows]
    if not tables:
        return None
    table = pa.concat_tables(tables, promote_options="permissive")
    ids = table.column("task").to_pylist()
    last = {task: i for i, task in enumerate(ids)}
    keep = sorted(last.values())
    return table.take(pa.array(keep, type=pa.int64())) if len(keep) != len(ids) else table


def read_results(output: str | os.PathLike[str]) -> pa.Table | None:
    """The results so far of a campaign: ``output`` and its unmerged parts, one row per
    task (the latest); None when there are none."""
    return _merge(_read_tables(Path(output)))


class ResultStore:
    """Rows appended to ``output`` as they arrive (see the module documentation).

    Parameters
    ----------
    output : str or os.PathLike
        The Parquet file.
    resume : bool
        Keep the results already there (:attr:`done` lists the tasks that succeeded);
        without it, existing results are an error rather than overwritten.
    flush_rows, flush_seconds : int, float
        A part is written when this many rows are waiting or this long has passed since
        the last one (the first row is written at once).
    """

    def __init__(self, output: str | os.PathLike[str], *, resume: bool = False, flush_rows: int = 64,
                 flush_seconds: float = 2.0) -> None:
        self.output = Path(output)
        self.parts = _parts_folder(self.output)
        if not resume and (self.output.exists() or self.parts.exists()):
            raise InputError(f"{self.output}: results are already there"
                             + (" (an interrupted campaign)" if self.parts.exists() else "")
                             + ": --resume continues the campaign; remove the file to start again")
        previous = read_results(self.output) if resume else None
        self.previous = previous
        self.done: set[str] = set()
        if previous is not None:
            status = previous.column("status").to_pylist()
            self.done = {t for t, s in zip(previous.column("task").to_pylist(), status) if s == "ok"}
        self.flush_rows, self.flush_seconds = flush_rows, flush_seconds
        self._rows: list[dict[str, Any]] = []
        self._last = -math.inf  # the first row is written as soon as it arrives
        self._count = len(list(self.parts.glob("part-*.parquet"))) if self.parts.is_dir() else 0
        self.written = 0

    def add(self, row: dict[str, Any]) -> None:
        """Append one row (written with the next part)."""
        self._rows.append(row)
        if len(self._rows) >= self.flush_rows or time.monotonic() - self._last >= self.flush_seconds:
            self.flush()

    def flush(self) -> None:
        """Write the waiting rows as one part."""
        self._last = time.monotonic()
        if not self._rows:
            return
        self.parts.mkdir(parents=True, exist_ok=True)
        columns = list(dict.fromkeys(key for row in self._rows for key in row))  # every row's columns
        table = pa.Table.from_pydict({key: [row.get(key) for row in self._rows] for key in columns})
        self._count += 1
        final = self.parts / f"part-{self._count:06d}.parquet"
        temporary = final.with_suffix(".tmp")
        pq.write_table(table, temporary)
        temporary.replace(final)
        self.written += len(self._rows)
        self._rows = []

    def close(self, order: Sequence[str] = ()) -> pa.Table | None:
        """Flush, merge the parts and earlier results into the output file; the table.

        Parameters
        ----------
        order : sequence of str
            Task ids in the order the rows should have (the spec's); others follow.
        """
        self.flush()
        table = read_results(self.output)
        if table is not None:
            rank = {task: i for i, task in enumerate(order)}
            ids = table.column("task").to_pylist()
            table = table.take(pa.array(sorted(range(len(ids)), key=lambda i: (rank.get(ids[i], len(rank)), i)),
                                        type=pa.int64()))
            temporary = self.output.with_name(self.output.name + ".tmp")
            pq.write_table(table, temporary)
            temporary.replace(self.output)
        shutil.rmtree(self.parts, ignore_errors=True)
        return table
