"""Measured or simulated input/output records and their files.

A :class:`Record` holds evenly sampled time ``t``, forces (inputs) ``f`` and
displacements (outputs) ``x``.  It validates its data on construction and
reads and writes:

* CSV with a header line, ``t,f,x`` for one degree of freedom or
  ``t,f1..f<nf>,x1..x<nx>`` otherwise (see :meth:`Record.read_csv`);
* MATLAB ``.mat`` files, v5 to v7.3 (see :meth:`Record.read_mat`);
* every format of :mod:`duffid.data.formats` (TDMS, UFF 58/58b, HDF5, WAV, and the
  above) by :meth:`Record.read`, and SDyPy SEP-005 channels
  (:meth:`Record.from_sep005`, :meth:`Record.to_sep005`).

duffid never silently drops, clips, interpolates or resamples data: every
problem in a file is reported as a :class:`RecordError` whose message names
the file, the line (or row) and the column (or variable) concerned.
"""

from __future__ import annotations

import csv
import math
import os
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np
import scipy.io
from scipy.io.matlab import MatReadError

from ..errors import InputError, OptionError, RecordError
from .channels import (FAMILY_WORDS, MOTION_FAMILIES, ROLE_PATTERN, Channel, assemble, check_roles,
                       check_source_voltage, motion_of, select, unit_in_name, unit_suffix)
from .formats import detect_format, read_arrays
from .readers.matlab import is_v73
from .readers.matlab import open_channels as open_mat_channels
from .units import ROLE_QUANTITIES, lookup

__all__ = ["Record", "RecordError"]

ARRAY_SOURCE = "array input"

_NUMBER_RE = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?", re.ASCII)
_NONFINITE_RE = re.compile(r"[+-]?(?:nan|inf|infinity)", re.ASCII | re.IGNORECASE)
_NUMBERED_RE = re.compile(r"([fx])([1-9][0-9]*)", re.ASCII)
_MATLAB_NAME_RE = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,62}", re.ASCII)
_CSV_LAYOUTS = "t,f,x (one DOF) or t,f1..f<nf>,x1..x<nx> with nf <= nx"
_MAT_HEADER_KEYS = ("__header__", "__version__", "__globals__")
#: Samples per chunk of the sampling checks.
_CHUNK = 1 << 20




def _fmt_pair(a: float, b: float) -> tuple[str, str]:
    """Format two floats compactly, with full precision if they would look equal."""
    sa, sb = f"{a:.12g}", f"{b:.12g}"
    if sa == sb:
        sa, sb = repr(float(a)), repr(float(b))
    return sa, sb


def _check_samples(
    t: np.ndarray,
    columns: Sequence[tuple[str, np.ndarray]],
    *,
    source: str,
    sampling_rtol: float,
    where: Callable[[int], str],
    t_desc: str | None,
) -> float:
    """Check finiteness, monotonic time and even sampling; return the median step.

    Parameters
    ----------
    t : numpy.ndarray
        Time stamps, shape ``(N,)``, float64.
    columns : sequence of (str, numpy.ndarray)
        Description (for messages, e.g. ``"column 'x2'"``) and data of every
        signal column, each of shape ``(N,)``; the time column comes first.
    source : str
        Name of the data source for messages.
    sampling_rtol : float
        Allowed relative deviation of every step from the median step.
    where : callable
        Maps a 0-based sample index to a place description such as
        ``"line 12"``.
    t_desc : str or None
        Description of the time column added to time messages, if any.

    Returns
    -------
    float
        The median time step.

    Raises
    ------
    RecordError
        On the first problem found.
    """
    n = t.shape[0]
    if n < 2:
        raise RecordError(f"{source}: a record needs at least 2 samples, found {n}")
    for desc, values in columns:
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            i = int(bad[0])
            raise RecordError(
                f"{source}, {where(i)}, {desc}: value '{float(values[i])!r}' is not finite"
            )
    tplace = "" if t_desc is None else f", {t_desc}"
    steps = np.diff(t)
    bad = np.flatnonzero(~(steps > 0.0))
    if bad.size:
        i = int(bad[0]) + 1
        raise RecordError(
            f"{source}, {where(i)}{tplace}: time {float(t[i])!r} does not increase "
            f"(previous {float(t[i - 1])!r})"
        )
    dt = float(np.median(steps, overwrite_input=True))  # sorts steps in place: no copy of a long record
    del steps
    for lo in range(0, n - 1, _CHUNK):  # chunks: a long record's check needs no record-sized temporaries
        steps = np.diff(t[lo:lo + _CHUNK + 1])
        bad = np.flatnonzero(np.abs(steps - dt) > sampling_rtol * dt)
        if bad.size:
            break
    if bad.size:
        i = int(bad[0]) + 1
        step_s, dt_s = _fmt_pair(float(steps[i - 1]), dt)
        i += lo
        raise RecordError(
            f"{source}, {where(i)}{tplace}: uneven sampling, step {step_s} differs "
            f"from dt {dt_s} by more than the tolerance (rtol {sampling_rtol:g}); "
            "duffid never resamples: resample before identification"
        )
    return dt


def _check_rtol(sampling_rtol: Any) -> float:
    """Validate a sampling tolerance and return it as float."""
    if isinstance(sampling_rtol, bool) or not isinstance(
        sampling_rtol, (int, float, np.integer, np.floating)
    ):
        raise OptionError(f"sampling_rtol must be a real number, got {sampling_rtol!r}")
    value = float(sampling_rtol)
    if not math.isfinite(value) or value < 0.0:
        raise InputError(f"sampling_rtol must be finite and >= 0, got {value!r}")
    return value


def _numeric_array(value: Any, name: str, source: str) -> np.ndarray:
    """Return a float64 copy of a real numeric array-like, or raise RecordError."""
    arr = np.asarray(value)
    if arr.dtype == np.bool_ or not (
        np.issubdtype(arr.dtype, np.integer) or np.issubdtype(arr.dtype, np.floating)
    ):
        raise RecordError(
            f"{source}: {name} must be a real numeric array, got dtype {arr.dtype}"
        )
    if arr is value and arr.dtype == np.float64 and arr.flags.owndata and not arr.flags.writeable:
        return arr  # already immutable and owned (what the file readers hand over): no copy
    return np.array(arr, dtype=np.float64, copy=True)


def _names_list(names: str | Sequence[str], param: str) -> list[str] | None:
    """Return None for a single name, or the list of names of a sequence."""
    if isinstance(names, str):
        if not names:
            raise InputError(f"{param}: variable name must not be empty")
        return None
    try:
        out = list(names)
    except TypeError:
        raise OptionError(
            f"{param} must be a variable name or a sequence of names, got {names!r}"
        ) from None
    if not out or not all(isinstance(n, str) and n for n in out):
        raise InputError(
            f"{param} must be a variable name or a non-empty sequence of names, got {names!r}"
        )
    return out


@dataclass(frozen=True, eq=False, repr=False)
class Record:
    """Evenly sampled input/output record of an oscillator.

    Parameters
    ----------
    t : array_like, shape (N,)
        Strictly increasing, evenly sampled time stamps [s].
    f : array_like, shape (N,) or (N, nf)
        Forces or inputs; force ``j`` acts on degree of freedom ``j``, so
        ``1 <= nf <= nx``.  A 1-D array is stored as shape ``(N, 1)``.
    x : array_like, shape (N,) or (N, nx)
        Displacements or outputs, ``nx >= 1``.  A 1-D array is stored as
        shape ``(N, 1)``.
    source : str, optional
        Where the data came from (a file path); used in error messages.
    sampling_rtol : float, optional
        Allowed relative deviation of every time step from the median step
        ``dt``: ``max |diff(t) - dt| <= sampling_rtol * dt``.
    motion : {"x", "v", "a"}, optional
        What the ``x`` columns measure: displacements (default), velocities [m/s] or
        accelerations [m/s^2] (an accelerometer's record). Only
        :func:`duffid.identification.motion.identify_motion` (``duffid identify``) takes a
        velocity or acceleration record; everything that needs a displacement refuses it
        (:meth:`require_displacement`).

    Raises
    ------
    RecordError
        If the shapes are inconsistent, there are fewer than 2 samples, a
        value is NaN or infinite, ``t`` does not strictly increase or is not
        evenly sampled.  The message names the column and the 0-based sample
        index.

    Notes
    -----
    The arrays are stored as read-only float64 copies; a read-only float64
    array that owns its data (what the file readers hand over) is kept as is,
    so that a long record is not held twice.  Two records compare
    equal when their ``t``, ``f``, ``x`` and ``sampling_rtol`` are identical;
    ``source`` is ignored.
    """

    t: np.ndarray
    f: np.ndarray
    x: np.ndarray
    source: str = ARRAY_SOURCE
    sampling_rtol: float = 1e-6
    motion: str = "x"

    def __post_init__(self) -> None:
        if not isinstance(self.source, str):
            raise OptionError(f"source must be a string, got {self.source!r}")
        if self.motion not in MOTION_FAMILIES:
            raise OptionError(f"motion must be one of {', '.join(MOTION_FAMILIES)} (displacement, velocity, "
                              f"acceleration), got {self.motion!r}")
        source = self.source
        rtol = _check_rtol(self.sampling_rtol)
        t = _numeric_array(self.t, "t", source)
        if t.ndim != 1:
            raise RecordError(f"{source}: t must be 1-D, got shape {t.shape}")
        n = t.shape[0]
        arrays: dict[str, np.ndarray] = {}
        for name, value in (("f", self.f), ("x", self.x)):
            arr = _numeric_array(value, name, source)
            if arr.ndim == 1:
                arr = arr.reshape(-1, 1)
            if arr.ndim != 2:
                raise RecordError(
                    f"{source}: {name} must be 1-D or 2-D (samples x channels), "
                    f"got shape {arr.shape}"
                )
            if arr.shape[0] != n:
                raise RecordError(
                    f"{source}: {name} has {arr.shape[0]} samples but t has {n}"
                )
            if arr.shape[1] < 1:
                raise RecordError(f"{source}: {name} has no columns")
            arrays[name] = arr
        f, x = arrays["f"], arrays["x"]
        if f.shape[1] > x.shape[1]:
            raise RecordError(
                f"{source}: {f.shape[1]} force columns but only {x.shape[1]} "
                "displacement columns; force j acts on DOF j, so nf <= nx is required"
            )
        names = _column_names(f.shape[1], x.shape[1])
        columns = [(f"column '{names[0]}'", t)]
        columns += [(f"column '{names[1 + j]}'", f[:, j]) for j in range(f.shape[1])]
        columns += [
            (f"column '{names[1 + f.shape[1] + j]}'", x[:, j]) for j in range(x.shape[1])
        ]
        dt = _check_samples(
            t,
            columns,
            source=source,
            sampling_rtol=rtol,
            where=lambda i: f"sample index {i}",
            t_desc=None,
        )
        for arr in (t, f, x):
            arr.setflags(write=False)
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "f", f)
        object.__setattr__(self, "x", x)
        object.__setattr__(self, "sampling_rtol", rtol)
        object.__setattr__(self, "_dt", dt)

    # ------------------------------------------------------------------ dunder
    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Record):
            return NotImplemented
        return (
            self.sampling_rtol == other.sampling_rtol
            and self.motion == other.motion
            and np.array_equal(self.t, other.t)
            and np.array_equal(self.f, other.f)
            and np.array_equal(self.x, other.x)
        )

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        return (
            f"Record(n_samples={self.n_samples}, n_forces={self.n_forces}, "
            f"n_dof={self.n_dof}, dt={self.dt!r}, source={self.source!r}"
            + (f", motion={self.motion!r})" if self.motion != "x" else ")")
        )

    # -------------------------------------------------------------- properties
    @property
    def dt(self) -> float:
        """Sampling step: the median of ``diff(t)`` [s]."""
        return self._dt  # type: ignore[attr-defined, no-any-return]

    @property
    def fs(self) -> float:
        """Sampling rate ``1 / dt`` [Hz]."""
        return 1.0 / self.dt

    @property
    def n_samples(self) -> int:
        """Number of samples ``N``."""
        return int(self.t.shape[0])

    @property
    def n_dof(self) -> int:
        """Number of displacement columns ``nx`` (degrees of freedom)."""
        return int(self.x.shape[1])

    @property
    def n_forces(self) -> int:
        """Number of force columns ``nf``."""
        return int(self.f.shape[1])

    @property
    def duration(self) -> float:
        """Time span ``t[-1] - t[0]`` [s]."""
        return float(self.t[-1] - self.t[0])

    @property
    def column_names(self) -> list[str]:
        """Column names used in CSV files.

        ``['t', 'f', 'x']`` when ``nf == nx == 1``, otherwise
        ``['t', 'f1', ..., 'f<nf>', 'x1', ..., 'x<nx>']``.
        """
        return _column_names(self.n_forces, self.n_dof, self.motion)

    def require_displacement(self, what: str) -> None:
        """Refuse a velocity or acceleration record where ``what`` needs a displacement.

        Raises
        ------
        RecordError
            Naming the record, what it measures and where such a record is taken.
        """
        if self.motion != "x":
            word = FAMILY_WORDS[self.motion]
            raise RecordError(f"{self.source}: the record measures {word} ({self.motion}), not displacements: "
                              f"{what} needs a displacement. A velocity or acceleration record is identified by "
                              "duffid identify (duffid.identify), online by duffid.OnlineMotionIdentifier")

    # ----------------------------------------------------------------- methods
    def require_samples(self, n: int, purpose: str) -> None:
        """Raise if the record has fewer than `n` samples.

        Parameters
        ----------
        n : int
            Minimum number of samples needed.
        purpose : str
            What needs them, for the message (e.g. ``"identification window"``).

        Raises
        ------
        RecordError
            ``"<source>: <purpose> needs at least <n> samples, the record has <N>"``.
        """
        if self.n_samples < n:
            raise RecordError(
                f"{self.source}: {purpose} needs at least {n} samples, "
                f"the record has {self.n_samples}"
            )

    def slice(self, start: float | None = None, stop: float | None = None) -> Record:
        """Return the samples with ``start <= t <= stop``.

        Parameters
        ----------
        start, stop : float or None, optional
            Time limits [s], both inclusive; ``None`` means unbounded.  A
            sample within ``1e-9 * dt`` of a limit counts as inside, so limits
            computed as multiples of ``dt`` select the expected samples.

        Returns
        -------
        Record
            New record with the selected samples; ``t`` is kept as is (not
            shifted to start at zero) and ``source`` is unchanged.

        Raises
        ------
        RecordError
            If ``start > stop`` or fewer than 2 samples are selected.
        """
        for name, value in (("start", start), ("stop", stop)):
            if value is not None and not math.isfinite(float(value)):
                raise InputError(f"{name} must be a finite time or None, got {value!r}")
        if start is not None and stop is not None and start > stop:
            raise RecordError(f"{self.source}: slice start {start!r} is after stop {stop!r}")
        tol = 1e-9 * self.dt
        mask = np.ones(self.n_samples, dtype=bool)
        if start is not None:
            mask &= self.t >= float(start) - tol
        if stop is not None:
            mask &= self.t <= float(stop) + tol
        count = int(mask.sum())
        if count < 2:
            raise RecordError(
                f"{self.source}: slice [{start!r}, {stop!r}] selects {count} sample(s) "
                f"of the record spanning [{float(self.t[0])!r}, {float(self.t[-1])!r}]; "
                "at least 2 are needed"
            )
        return Record(
            self.t[mask],
            self.f[mask],
            self.x[mask],
            source=self.source,
            sampling_rtol=self.sampling_rtol,
            motion=self.motion,
        )

    # --------------------------------------------------------------------- CSV
    def scaled(self, factors: Mapping[str, float]) -> Record:
        """The record with its time (``t``), forces (``f``) and displacements (``x``) multiplied
        by ``factors`` (e.g. ``{"x": 1e-3}`` for millimetres)."""
        return _scaled(self, factors)

    def to_csv(self, path: str | os.PathLike[str]) -> None:
        """Write the record as a CSV file.

        The header line holds :attr:`column_names`; values are written with
        ``'%.17g'`` so that :meth:`read_csv` gives back bit-identical arrays.

        Parameters
        ----------
        path : str or os.PathLike
            File to write (overwritten if it exists).
        """
        data = np.column_stack([self.t, self.f, self.x])
        np.savetxt(
            os.fspath(path),
            data,
            fmt="%.17g",
            delimiter=",",
            header=",".join(self.column_names),
            comments="",
        )

    @classmethod
    def read_csv(
        cls, path: str | os.PathLike[str], *, sampling_rtol: float = 1e-6,
        columns: Mapping[str, str | int] | None = None, delimiter: str = ",",
        scale: Mapping[str, float] | None = None, fs: float | None = None, decimal: str = ".",
        motion: bool = False,
    ) -> Record:
        """Read a record from a CSV file: duffid's own layout, or what a logger wrote.

        Parameters
        ----------
        path : str or os.PathLike
            CSV file (UTF-8).
        sampling_rtol : float, optional
            Allowed relative deviation of every time step from the median step.
        columns : mapping, optional
            Which file column holds each signal: role (``t``, ``f``, ``x``, or ``f1``..,
            ``x1``.. for several) -> header name or 1-based column number, e.g.
            ``{"t": "time_s", "f": "force_N", "x": 4}``. Other columns are not read. A row
            right after the header whose fields are all non-numeric is a units row: a mapped
            column in a unit that is not SI (``mm``, ``kN``, ...) must be scaled (``scale``).
            Default: duffid's own layout (below).
        delimiter : str, optional
            Field separator, one character (``","``, ``";"``, ``"\t"``, ...).
        scale : mapping, optional
            Role -> factor multiplying that column into SI units, e.g. ``{"x": 1e-3}`` for
            millimetres (``x``/``f`` apply to every displacement/force column).
        fs : float, optional
            Sampling rate [Hz] of a file without a time column (``t = k / fs``).
        decimal : {".", ","}, optional
            Decimal mark of the numbers (``","`` for loggers and spreadsheets of countries
            that write ``1,5``; then the delimiter must not be ``","``).
        motion : bool, optional
            Whether ``columns`` may select velocities (``v``) or accelerations (``a``) in the
            displacements' place (:attr:`motion` of the record).

        Returns
        -------
        Record
            The record, with ``source`` set to ``str(path)``.

        Raises
        ------
        RecordError
            On any problem; the message names the file, the line (header =
            line 1, comment lines counted) and the column.

        Notes
        -----
        Format rules, checked strictly:

        * Lines starting with ``#`` (and blank lines) before the header are
          comments.  The header is required and its first column is ``t``.
        * The other columns, in any order, are either ``f,x`` (one DOF) or
          ``f1..f<nf>,x1..x<nx>`` with both families numbered contiguously
          from 1 and ``nf <= nx``.  Unknown, duplicated or missing columns are
          errors.  Whitespace around names and values is ignored.
        * Every data row has exactly one value per column; values are decimal
          numbers (``1``, ``-2.5``, ``3e-4``).  Empty, non-numeric, NaN and
          infinite values are errors, as are blank lines between data rows
          (blank lines at the end are fine) and comment lines after the header.
        * At least 2 data rows; ``t`` strictly increasing and evenly sampled
          within `sampling_rtol`.  Nothing is ever dropped or resampled.
        """
        rtol = _check_rtol(sampling_rtol)
        source = os.fspath(path)
        if len(delimiter) != 1:
            raise InputError(f"the delimiter must be one character, got {delimiter!r}")
        if decimal not in (".", ","):
            raise InputError(f"the decimal mark must be '.' or ',', got {decimal!r}")
        if fs is not None and not (np.isfinite(fs) and fs > 0):
            raise InputError(f"the sampling rate must be a positive number of Hz, got {fs!r}")
        lines = _read_text_lines(source)
        delimiter = _declared_delimiter(lines, source, delimiter)
        if decimal == delimiter:
            raise InputError(f"the decimal mark and the delimiter are both {decimal!r}: a file with decimal commas "
                             "separates its columns with something else (';' or a tab, say)")
        if columns is None and motion:  # a header t,f,a (t,f1,v1,v2, ...): those roles by name
            header = next((line for line in lines if line.strip() and not line.lstrip().startswith("#")), "")
            names = [n.strip() for n in next(csv.reader([header], delimiter=delimiter))] if header else []
            if names[:1] == ["t"] and {n[0] for n in names[1:]} in ({"f", "v"}, {"f", "a"}) and \
                    all(ROLE_PATTERN.fullmatch(n) for n in names[1:]):
                columns = {n: n for n in names}
        if columns is None and delimiter == "," and fs is None and decimal == ".":
            record = _parse_csv_lines(lines, source, rtol)
            return record if not scale else record.scaled(scale)
        return _parse_logger_lines(lines, source, rtol, columns, delimiter, scale or {}, fs, decimal, motion)

    # ------------------------------------------------------------ every format
    @classmethod
    def read(
        cls, path: str | os.PathLike[str], *, format: str | None = None,
        columns: Mapping[str, str | int] | None = None, scale: Mapping[str, float] | None = None,
        fs: float | None = None, sampling_rtol: float = 1e-6, delimiter: str = ",", decimal: str = ".",
        motion: bool = False,
    ) -> Record:
        """Read a record from a file in any format duffid reads: CSV, MATLAB (v5 and v7.3), TDMS,
        UFF 58/58b, HDF5 or WAV.

        Parameters
        ----------
        path : str or os.PathLike
            The file.
        format : str, optional
            ``csv``, ``mat``, ``tdms``, ``uff``, ``hdf5`` or ``wav``
            (:data:`duffid.data.formats.FORMATS`); default: from the extension.
        columns : mapping, optional
            Role (``t``, ``f``, ``x``, or ``f1``.., ``x1``..) -> channel: ``group/channel`` in
            TDMS, a dataset path in HDF5, a variable in MATLAB (``x(:,2)`` for a matrix's
            column), a data set's ID line in UFF, a header name in CSV, or any channel's 1-based
            number (a WAV channel). Default: a file with one force and one displacement channel
            (by unit, else name) is read as such; CSV files as :meth:`read_csv` says.
        scale : mapping, optional
            Role (or ``f``, ``x``, ``t`` for all of them) -> factor into SI. It replaces the
            factor of the channel's unit; required for integer PCM WAV channels (the SI value
            at full scale), for sensor voltages (1 / sensitivity) and units duffid does not know.
        fs : float, optional
            Sampling rate [Hz] of channels without one (MATLAB, CSV without a time column).
        sampling_rtol : float, optional
            Allowed relative deviation of every time step from the median step.
        delimiter, decimal : str, optional
            CSV only: see :meth:`read_csv`.
        motion : bool, optional
            Whether velocity (``v``) or acceleration (``a``) channels may take the
            displacements' place (the record's :attr:`motion` then says which).

        Returns
        -------
        Record
            In SI units, with ``source`` set to ``str(path)``.

        Raises
        ------
        RecordError
            A channel that is not there (listing those found, with their units), a unit that is
            unknown or of the wrong quantity, channels of different rates, start times or lengths
            (naming both), a velocity or acceleration channel (not identifiable yet), or data that
            fail the checks of :class:`Record`.
        MissingDependencyError
            The format's library is missing (``pip install 'duffid[files]'``).
        """
        rtol = _check_rtol(sampling_rtol)
        source = os.fspath(path)
        if detect_format(source, format) == "csv":
            return cls.read_csv(path, sampling_rtol=rtol, columns=columns, delimiter=delimiter, scale=scale,
                                fs=fs, decimal=decimal, motion=motion)
        t, f, x, family = read_arrays(path, format=format, columns=columns, scale=scale, fs=fs, motion=motion)
        return cls(t, f, x, source=source, sampling_rtol=rtol, motion=family)

    @classmethod
    def from_sep005(
        cls, channels: Sequence[Mapping[str, Any]], *, columns: Mapping[str, str | int] | None = None,
        scale: Mapping[str, float] | None = None, sampling_rtol: float = 1e-6, source: str = "SEP-005 channels",
    ) -> Record:
        """A record from SDyPy SEP-005 channels (the ecosystem's in-memory time series).

        Parameters
        ----------
        channels : sequence of mapping
            One dict per channel: ``data`` (1-D), ``name``, ``unit_str`` and ``fs`` [Hz] or
            ``time`` [s] (an evenly sampled vector; its first value is the start time).
        columns : mapping, optional
            Role -> channel name or 1-based number, as for :meth:`read`; default: one force and
            one displacement channel recognised by unit or name.
        scale : mapping, optional
            Role -> factor into SI, as for :meth:`read`.
        sampling_rtol : float, optional
            Allowed relative deviation of every time step from the median step.
        source : str, optional
            Where the channels came from, for messages.

        Returns
        -------
        Record
            In SI units.

        Raises
        ------
        RecordError
            A channel without ``data``, ``name`` or a time base, an unevenly sampled ``time``,
            or the problems :meth:`read` reports.
        """
        rtol = _check_rtol(sampling_rtol)
        t, f, x = assemble(select(_sep005_channels(channels, source, rtol), columns, source), source, scale=scale)
        return cls(t, f, x, source=source, sampling_rtol=rtol)

    def to_sep005(self, units: Mapping[str, str] | None = None) -> list[dict[str, Any]]:
        """The record as SDyPy SEP-005 channels: one dict per force and displacement column.

        Parameters
        ----------
        units : mapping, optional
            ``{"f": ..., "x": ...}``: the units of the forces and displacements (default N and
            m; a circuit's record is in V and C).

        Returns
        -------
        list of dict
            ``name`` (the CSV column name), ``data`` (a copy), ``unit_str``, and ``fs`` [Hz]
            when the record starts at t = 0, else ``time`` (a copy of ``t``).
        """
        units = {"f": "N", "x": "m", **(units or {})}
        out: list[dict[str, Any]] = []
        for k, name in enumerate(self.column_names[1:]):
            data = self.f[:, k] if k < self.n_forces else self.x[:, k - self.n_forces]
            entry: dict[str, Any] = {"name": name, "data": data.copy(), "unit_str": units[name[0]]}
            if self.t[0] == 0.0:
                entry["fs"] = self.fs
            else:
                entry["time"] = self.t.copy()
            out.append(entry)
        return out

    # --------------------------------------------------------------------- MAT
    def to_mat(
        self,
        path: str | os.PathLike[str],
        *,
        t: str = "t",
        f: str | Sequence[str] = "f",
        x: str | Sequence[str] = "x",
    ) -> None:
        """Write the record as a MATLAB (version 5/7) ``.mat`` file.

        Parameters
        ----------
        path : str or os.PathLike
            File to write; no ``.mat`` extension is appended.
        t : str, optional
            Variable name of the time column vector.
        f, x : str or sequence of str, optional
            A single name stores the ``(N, n)`` matrix under that name; a
            sequence of ``n`` names stores one ``(N, 1)`` column per name.

        Raises
        ------
        ValueError
            If a name is not a valid MATLAB identifier, names repeat, or the
            number of names does not match the number of columns.
        """
        data: dict[str, np.ndarray] = {}

        def put(name: str, value: np.ndarray) -> None:
            if not isinstance(name, str) or not _MATLAB_NAME_RE.fullmatch(name):
                raise InputError(
                    f"{name!r} is not a valid MATLAB variable name (letter first, then "
                    "letters, digits or '_', at most 63 characters)"
                )
            if name in data:
                raise InputError(f"variable name {name!r} is used twice")
            data[name] = np.ascontiguousarray(value)

        put(t, self.t.reshape(-1, 1))
        for param, names, arr in (("f", f, self.f), ("x", x, self.x)):
            listed = _names_list(names, param)
            if listed is None:
                put(names, arr)  # type: ignore[arg-type]
            else:
                if len(listed) != arr.shape[1]:
                    raise InputError(
                        f"{param}: {len(listed)} names given for {arr.shape[1]} columns"
                    )
                for j, name in enumerate(listed):
                    put(name, arr[:, j : j + 1])
        scipy.io.savemat(os.fspath(path), data, appendmat=False, format="5")

    @classmethod
    def read_mat(
        cls,
        path: str | os.PathLike[str],
        *,
        x: str | Sequence[str],
        f: str | Sequence[str],
        t: str | None = None,
        fs: float | None = None,
        sampling_rtol: float = 1e-6,
    ) -> Record:
        """Read a record from a MATLAB ``.mat`` file (version 4 to 7, and 7.3 through h5py).

        Parameters
        ----------
        path : str or os.PathLike
            The ``.mat`` file; no extension is appended.
        x, f : str or sequence of str
            Variable name of a vector or ``(N, n)`` matrix (a ``(1, N)`` row
            vector is taken as a column), or a sequence of names of vectors,
            one column each.
        t : str or None, optional
            Variable name of the time vector.
        fs : float or None, optional
            Sampling rate [Hz], used when there is no time variable:
            ``t = arange(N) / fs``.  Give exactly one of `t` and `fs`.
        sampling_rtol : float, optional
            Allowed relative deviation of every time step from the median step.

        Returns
        -------
        Record
            The record, with ``source`` set to ``str(path)``.

        Raises
        ------
        RecordError
            If the file cannot be read, a
            variable is missing (the message lists those present), not real
            numeric, has the wrong shape, lengths differ, neither or both of
            `t` and `fs` are given, or the data fail the :class:`Record`
            checks (the message names variable and 1-based row).
        """
        rtol = _check_rtol(sampling_rtol)
        source = os.fspath(path)
        x_names = _names_list(x, "x")
        f_names = _names_list(f, "f")
        if t is not None and not (isinstance(t, str) and t):
            raise InputError(f"t must be a variable name or None, got {t!r}")
        if t is not None and fs is not None:
            raise RecordError(
                f"{source}: give either the time variable t={t!r} or the sampling "
                f"rate fs={fs!r}, not both"
            )
        if t is None and fs is None:
            raise RecordError(
                f"{source}: no time given: name the time variable (t=NAME; duffid: --t-var NAME or --columns "
                "t=NAME,...) or give the sampling rate (fs; duffid: --fs HZ)"
            )
        if is_v73(source):
            return cls._read_mat_v73(source, x, f, t, fs, rtol)
        contents = _load_mat(source)
        present = sorted(k for k in contents if k not in _MAT_HEADER_KEYS)
        wanted = [] if t is None else [t]
        for names, listed in ((f, f_names), (x, x_names)):
            wanted += [names] if listed is None else listed  # type: ignore[list-item]
        for name in wanted:
            if name not in present:
                found = ", ".join(present) if present else "none"
                raise RecordError(
                    f"{source}: variable '{name}' not found (variables present: {found})"
                )

        def fetch(name: str) -> np.ndarray:
            value = contents[name]
            if not isinstance(value, np.ndarray):
                raise RecordError(
                    f"{source}, variable '{name}': not a numeric array "
                    f"(found {type(value).__name__})"
                )
            dtype = value.dtype
            if dtype == np.bool_ or not (
                np.issubdtype(dtype, np.integer) or np.issubdtype(dtype, np.floating)
            ):
                kind = "complex" if np.issubdtype(dtype, np.complexfloating) else str(dtype)
                raise RecordError(
                    f"{source}, variable '{name}': not a real numeric array "
                    f"(dtype {kind})"
                )
            if value.ndim != 2 or value.size == 0:
                raise RecordError(
                    f"{source}, variable '{name}': expected a non-empty vector or "
                    f"matrix, got shape {_shape(value)}"
                )
            arr = value.astype(np.float64)
            if arr.shape[0] == 1:
                arr = arr.T
            return arr

        def vector(name: str, role: str) -> np.ndarray:
            arr = fetch(name)
            if arr.shape[1] != 1:
                raise RecordError(
                    f"{source}, variable '{name}': expected a vector ({role}), "
                    f"got shape {_shape(contents[name])}"
                )
            return arr

        # (description, data (N, 1)) pairs per family, and variables for length checks
        lengths: list[tuple[str, np.ndarray]] = []
        families: dict[str, list[tuple[str, np.ndarray]]] = {}
        for family, single, listed in (("f", f, f_names), ("x", x, x_names)):
            cols: list[tuple[str, np.ndarray]] = []
            if listed is None:
                arr = fetch(single)  # type: ignore[arg-type]
                lengths.append((single, arr))  # type: ignore[arg-type]
                if arr.shape[1] == 1:
                    cols.append((f"variable '{single}'", arr))
                else:
                    cols += [
                        (f"variable '{single}' column {j + 1}", arr[:, j : j + 1])
                        for j in range(arr.shape[1])
                    ]
            else:
                role = f"one column per name in {family}={listed!r}"
                for name in listed:
                    arr = vector(name, role)
                    lengths.append((name, arr))
                    cols.append((f"variable '{name}'", arr))
            families[family] = cols
        t_arr: np.ndarray | None = None
        if t is not None:
            t_arr = vector(t, "time stamps")
            lengths.insert(0, (t, t_arr))
        sizes = {arr.shape[0] for _, arr in lengths}
        if len(sizes) > 1:
            parts = ", ".join(
                f"{name} {arr.shape[0]} (shape {_shape(contents[name])})" for name, arr in lengths
            )
            raise RecordError(
                f"{source}: variables have different lengths: {parts}; samples must "
                "run along the rows (one column per channel)"
            )
        n = sizes.pop()
        if t_arr is None:
            try:
                fs_val = float(fs)  # type: ignore[arg-type]
            except (TypeError, ValueError):
                fs_val = math.nan
            if not math.isfinite(fs_val) or fs_val <= 0.0:
                raise RecordError(f"{source}: sampling rate fs must be finite and > 0, got {fs!r}")
            t_vec = np.arange(n, dtype=np.float64) / fs_val
        else:
            t_vec = t_arr[:, 0]
        f_mat = np.column_stack([arr[:, 0] for _, arr in families["f"]])
        x_mat = np.column_stack([arr[:, 0] for _, arr in families["x"]])
        if f_mat.shape[1] > x_mat.shape[1]:
            raise RecordError(
                f"{source}: {f_mat.shape[1]} force columns but only {x_mat.shape[1]} "
                "displacement columns; force j acts on DOF j, so nf <= nx is required"
            )
        columns = [(f"variable '{t}'", t_vec)] if t is not None else []
        columns += [(desc, arr[:, 0]) for desc, arr in families["f"] + families["x"]]
        _check_samples(
            t_vec,
            columns,
            source=source,
            sampling_rtol=rtol,
            where=lambda i: f"row {i + 1}",
            t_desc=None if t is None else f"variable '{t}'",
        )
        return cls(t_vec, f_mat, x_mat, source=source, sampling_rtol=rtol)


    @classmethod
    def _read_mat_v73(cls, source: str, x: str | Sequence[str], f: str | Sequence[str], t: str | None,
                      fs: float | None, rtol: float) -> Record:
        """:meth:`read_mat` of a MATLAB v7.3 (HDF5) file, through h5py: a matrix's columns are its
        channels ``name(:,k)``."""
        with open_mat_channels(source) as channels:
            names = [c.name for c in channels]

            def roles(spec: str | Sequence[str], fam: str) -> dict[str, str]:
                listed: list[str] = []
                for name in [spec] if isinstance(spec, str) else list(spec):
                    parts = [n for n in names if n.startswith(f"{name}(:,")]
                    listed += parts if name not in names and parts else [name]
                if len(listed) == 1:
                    return {fam: listed[0]}
                return {f"{fam}{j + 1}": n for j, n in enumerate(listed)}

            columns = {**({"t": t} if t is not None else {}), **roles(f, "f"), **roles(x, "x")}
            arrays = assemble(select(channels, columns, source), source, fs=fs)
        return cls(*arrays, source=source, sampling_rtol=rtol)


# ---------------------------------------------------------------------- helpers
def _column_names(nf: int, nx: int, motion: str = "x") -> list[str]:
    """CSV column names for `nf` forces and `nx` motion columns (``motion``: x, v or a)."""
    if nf == 1 and nx == 1:
        return ["t", "f", motion]
    return ["t"] + [f"f{j + 1}" for j in range(nf)] + [f"{motion}{j + 1}" for j in range(nx)]


def _declared_delimiter(lines: list[str], source: str, delimiter: str) -> str:
    """The delimiter a spreadsheet export declares on its first line (``sep=;``, Excel's
    convention; that line then becomes a comment), else ``delimiter``. A declared delimiter
    other than a non-default ``delimiter`` given is an error."""
    for k, line in enumerate(lines):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        match = re.fullmatch(r"\s*sep=(.)\s*", line)
        if match is None:
            return delimiter
        declared = match.group(1)
        if delimiter not in (",", declared):
            raise RecordError(f"{source}, line {k + 1}: the file declares the delimiter {declared!r} (sep=), "
                              f"but {delimiter!r} was given")
        lines[k] = "#" + line
        return declared
    return delimiter


def _shape(arr: np.ndarray) -> str:
    """MATLAB-style shape text, e.g. ``'2x1000'``."""
    return "x".join(str(s) for s in arr.shape)


def _read_text_lines(source: str) -> list[str]:
    """Read a text file as lines (universal newlines), raising RecordError."""
    try:
        with open(source, encoding="utf-8-sig", newline=None) as fh:
            text = fh.read()
    except UnicodeDecodeError as exc:
        raise RecordError(
            f"{source}: not a UTF-8 text file (undecodable byte at offset {exc.start})"
        ) from None
    except OSError as exc:
        raise RecordError(f"{source}: cannot read file: {exc.strerror or exc}") from None
    lines = text.split("\n")
    if lines and lines[-1] == "":
        lines.pop()
    return lines


def _split_fields(line: str) -> list[str]:
    """Split one CSV line into stripped fields."""
    return [field.strip() for field in next(csv.reader([line]))]


def _parse_header(
    names: list[str], source: str, lineno: int
) -> tuple[list[int], list[int]]:
    """Map header names to (force column indices, displacement column indices)."""
    where = f"{source}, line {lineno} (header)"
    found = ", ".join(n if n else "''" for n in names)
    if names[0] != "t":
        hint = ""
        seen = [sep for sep in (";", "\t", " ") if sep in names[0]] if len(names) == 1 else []
        if seen:
            hint = f"; the line is separated by {seen[0]!r}, not commas: is that the delimiter?"
        raise RecordError(
            f"{where}: first column must be 't', found {names[0]!r}{hint} "
            f"(expected {_CSV_LAYOUTS})"
        )
    for k, name in enumerate(names):
        if not name:
            trailing = " (every line ends with the delimiter? remove it)" if k == len(names) - 1 else ""
            raise RecordError(f"{where}: column {k + 1} has an empty name (found {found}){trailing}")
    seen: set[str] = set()
    for name in names:
        if name in seen:
            raise RecordError(f"{where}: duplicate column {name!r} (found {found})")
        seen.add(name)
    plain: dict[str, int] = {}
    numbered: dict[str, dict[int, int]] = {"f": {}, "x": {}}
    unknown: list[str] = []
    for k, name in enumerate(names[1:], start=1):
        if name in ("f", "x"):
            plain[name] = k
            continue
        match = _NUMBERED_RE.fullmatch(name)
        if match:
            numbered[match.group(1)][int(match.group(2))] = k
        else:
            unknown.append(name)
    if unknown:
        listed = ", ".join(repr(n) for n in unknown)
        raise RecordError(
            f"{where}: unknown column{'s' if len(unknown) > 1 else ''} {listed} "
            f"(found {found}; expected {_CSV_LAYOUTS})"
        )
    any_numbered = bool(numbered["f"] or numbered["x"])
    if plain and any_numbered:
        raise RecordError(
            f"{where}: mixes unnumbered {', '.join(repr(n) for n in plain)} with "
            f"numbered columns (found {found}; expected {_CSV_LAYOUTS})"
        )
    if not any_numbered:
        for fam in ("f", "x"):
            if fam not in plain:
                raise RecordError(f"{where}: missing column '{fam}' (found {found})")
        return [plain["f"]], [plain["x"]]
    result: list[list[int]] = []
    for fam in ("f", "x"):
        indices = numbered[fam]
        top = max(indices) if indices else 1
        missing = [f"{fam}{j}" for j in range(1, top + 1) if j not in indices]
        if missing:
            listed = ", ".join(repr(n) for n in missing)
            raise RecordError(
                f"{where}: missing column{'s' if len(missing) > 1 else ''} {listed} "
                f"(found {found})"
            )
        result.append([indices[j] for j in range(1, top + 1)])
    f_idx, x_idx = result
    if len(f_idx) > len(x_idx):
        raise RecordError(
            f"{where}: {len(f_idx)} force columns but only {len(x_idx)} displacement "
            f"columns (found {found}); force j acts on DOF j, so nf <= nx is required"
        )
    return f_idx, x_idx


def _number(text: str, place: str, decimal: str = ".") -> float:
    """The decimal number ``text`` of a CSV field (``decimal``: its decimal mark); RecordError
    naming ``place`` otherwise."""
    plain = text.replace(",", ".", 1) if decimal == "," and "." not in text else text
    if _NUMBER_RE.fullmatch(plain):
        return float(plain)
    if not text:
        raise RecordError(f"{place}: empty value")
    if _NONFINITE_RE.fullmatch(text):
        raise RecordError(f"{place}: value '{text}' is not finite")
    hint = ""
    if decimal == "." and _NUMBER_RE.fullmatch(text.replace(",", ".", 1)):
        hint = ": a decimal comma? give the decimal mark ','"
    raise RecordError(f"{place}: value '{text}' is not a number{hint}")


def _parse_csv_lines(lines: list[str], source: str, rtol: float) -> Record:
    """Parse the lines of a CSV record file (see :meth:`Record.read_csv`)."""
    pos = 0
    while pos < len(lines) and (not lines[pos].strip() or lines[pos].lstrip().startswith("#")):
        pos += 1
    if pos == len(lines):
        raise RecordError(
            f"{source}: empty file, expected a header line such as 't,f,x' "
            "followed by data rows"
        )
    header_line = pos + 1
    names = _split_fields(lines[pos])
    f_idx, x_idx = _parse_header(names, source, header_line)
    ncol = len(names)
    rows: list[list[float]] = []
    linenos: list[int] = []
    blank_at: int | None = None
    for k in range(pos + 1, len(lines)):
        lineno = k + 1
        line = lines[k]
        if not line.strip():
            if blank_at is None:
                blank_at = lineno
            continue
        if blank_at is not None:
            raise RecordError(
                f"{source}, line {blank_at}: blank line inside the data "
                f"(data continues on line {lineno})"
            )
        if line.lstrip().startswith("#"):
            raise RecordError(
                f"{source}, line {lineno}: comment lines are only allowed before the header"
            )
        fields = _split_fields(line)
        if len(fields) != ncol:
            raise RecordError(
                f"{source}, line {lineno}: {len(fields)} field"
                f"{'s' if len(fields) != 1 else ''}, the header has {ncol} columns"
            )
        rows.append([_number(text, f"{source}, line {lineno}, column '{name}'") for name, text in zip(names, fields)])
        linenos.append(lineno)
    if len(rows) < 2:
        what = "no data rows (header only)" if not rows else "only 1 data row"
        raise RecordError(f"{source}: {what}; a record needs at least 2 samples")
    data = np.array(rows, dtype=np.float64)
    t = data[:, 0]
    f = data[:, f_idx]
    x = data[:, x_idx]
    _check_samples(
        t,
        [(f"column '{names[k]}'", data[:, k]) for k in range(ncol)],
        source=source,
        sampling_rtol=rtol,
        where=lambda i: f"line {linenos[i]}",
        t_desc=None,
    )
    return Record(t, f, x, source=source, sampling_rtol=rtol)


def _sep005_channels(channels: Sequence[Mapping[str, Any]], source: str, rtol: float) -> list[Channel]:
    """:class:`Channel` descriptions of SEP-005 channel dicts (checked: data, name, time base)."""
    if isinstance(channels, Mapping) or not isinstance(channels, Sequence):
        raise RecordError(f"{source}: SEP-005 data are a list of channel dicts, got {type(channels).__name__}")
    out = []
    for k, entry in enumerate(channels):
        place = f"{source}, channel {k + 1}"
        if not isinstance(entry, Mapping) or "data" not in entry or not entry.get("name"):
            raise RecordError(f"{place}: a SEP-005 channel is a dict with 'data', 'name', 'unit_str' and 'fs' "
                              f"or 'time', got {entry!r:.80}")
        name = str(entry["name"])
        data = _numeric_array(entry["data"], f"channel {name!r} data", source)
        if data.ndim != 1:
            raise RecordError(f"{source}, channel {name!r}: data must be 1-D, got shape {data.shape}")
        if "fs" in entry:
            try:
                rate = float(entry["fs"])
            except (TypeError, ValueError):
                rate = math.nan
            if not (math.isfinite(rate) and rate > 0):
                raise RecordError(f"{source}, channel {name!r}: fs must be a positive number of Hz, got "
                                  f"{entry['fs']!r}")
            start = 0.0
        elif "time" in entry:
            time = _numeric_array(entry["time"], f"channel {name!r} time", source)
            if time.shape != data.shape:
                raise RecordError(f"{source}, channel {name!r}: time has {time.size} values, data {data.size}")
            dt = _check_samples(time, [(f"channel {name!r} time", time)], source=source, sampling_rtol=rtol,
                                where=lambda i: f"sample index {i}", t_desc=f"channel {name!r} time")
            rate, start = 1.0 / dt, float(time[0])
        else:
            raise RecordError(f"{source}, channel {name!r}: neither 'fs' nor 'time' is given")
        unit = entry.get("unit_str")
        out.append(Channel(name, str(unit) if unit is not None else None, int(data.size), rate, start,
                           read=lambda data=data: data))
    return out


def _load_mat(source: str) -> dict[str, Any]:
    """Load a .mat file with scipy, converting every failure to RecordError."""
    try:
        return scipy.io.loadmat(source, appendmat=False)  # type: ignore[no-any-return]
    except NotImplementedError:
        raise RecordError(
            f"{source}: the file is a MATLAB v7.3 (HDF5) file, which duffid cannot "
            "read; save it with save(..., '-v7') in MATLAB"
        ) from None
    except OSError as exc:
        raise RecordError(f"{source}: cannot read file: {exc.strerror or exc}") from None
    except (MatReadError, ValueError, TypeError, IndexError, KeyError) as exc:
        # scipy < 1.12 raises IndexError/KeyError on some files that are not .mat at all
        raise RecordError(f"{source}: not a readable MATLAB .mat file ({exc or type(exc).__name__})") from None


# ------------------------------------------------------------------------- logger files
#: SI units of each role; a units row naming another unit needs a scale factor.
SI_UNITS = {"t": ("s",), "f": ("N", "V"), "x": ("m", "C"), "v": ("m/s",), "a": ("m/s^2",)}


def _column_index(spec: str | int, role: str, names: list[str], where: str) -> int:
    """0-based index of the column ``spec`` (header name or 1-based number) for ``role``."""
    if isinstance(spec, (int, np.integer)) and not isinstance(spec, bool):
        if not 1 <= int(spec) <= len(names):
            raise RecordError(f"{where}: no column {int(spec)} for {role}: the header has {len(names)} columns")
        return int(spec) - 1
    if str(spec) not in names:
        raise RecordError(f"{where}: no column {str(spec)!r} for {role} (found: {', '.join(names)})")
    if names.count(str(spec)) > 1:
        raise RecordError(f"{where}: the header has {names.count(str(spec))} columns named {str(spec)!r}; "
                          f"give the column's number instead")
    return names.index(str(spec))


def _is_number(text: str) -> bool:
    return bool(_NUMBER_RE.fullmatch(text) or _NONFINITE_RE.fullmatch(text))


def _parse_logger_lines(lines: list[str], source: str, rtol: float, columns: Mapping[str, str | int] | None,
                        delimiter: str, scale: Mapping[str, float], fs: float | None, decimal: str = ".",
                        motion: bool = False) -> Record:
    """Parse a CSV file with a column mapping, delimiter, units row, scale or sampling rate."""
    def split(line: str) -> list[str]:
        return [field.strip() for field in next(csv.reader([line], delimiter=delimiter))]

    pos = 0
    while pos < len(lines) and (not lines[pos].strip() or lines[pos].lstrip().startswith("#")):
        pos += 1
    if pos == len(lines):
        raise RecordError(f"{source}: empty file, expected a header line followed by data rows")
    header_line = pos + 1
    names = split(lines[pos])
    where = f"{source}, line {header_line} (header)"
    if len(names) == 1 and delimiter not in lines[pos]:
        seen = [d for d in (",", ";", "\t", " ") if d in lines[pos]]
        hint = f"; the line contains {seen[0]!r}: is that the delimiter?" if seen else ""
        raise RecordError(f"{where}: one column only with the delimiter {delimiter!r}{hint}")
    if columns is None:
        columns = {"t": "t", "f": "f", "x": "x"} if fs is None else {"f": "f", "x": "x"}
    t_role, f_roles, x_roles = check_roles(list(columns), source, motion=motion)
    unknown = sorted(set(scale) - {"t", "f", motion_of(x_roles)} - set(columns))
    if unknown:
        raise RecordError(f"{source}: a scale for {', '.join(unknown)}, which names no column")
    if t_role is not None and fs is not None:
        raise RecordError(f"{source}: a time column and a sampling rate were both given; give one of them")
    if t_role is None and fs is None:
        raise RecordError(f"{source}: no time column: give the sampling rate, or which column holds the time")
    roles = ([t_role] if t_role else []) + f_roles + x_roles
    index = {role: _column_index(columns[role], role, names, where) for role in roles}
    used = sorted(set(index.values()))
    if len(used) != len(roles):
        raise RecordError(f"{where}: one column is given for two signals ({', '.join(roles)})")
    pos += 1
    units: dict[str, str] = {}
    said: dict[str, str] = {}  # where each unit was found
    while pos < len(lines) and not lines[pos].strip():
        pos += 1
    if pos < len(lines):
        fields = split(lines[pos])
        def number(text: str) -> bool:  # in the file's decimal mark
            return _is_number(text) or (decimal == "," and _is_number(text.replace(",", ".", 1)))

        if len(fields) == len(names) and all(f and not number(f) for f in (fields[i] for i in used)):
            units = {role: fields[index[role]] for role in roles}
            said = {role: f"units row, line {pos + 1}" for role in roles}
            pos += 1
    for role in roles:  # else a unit closing the column's name: "x (mm)", "f [kN]", "load_kN"
        named = unit_in_name(names[index[role]])
        if role not in units and named:
            units[role], said[role] = named, "in its name"
        suffix = unit_suffix(names[index[role]], role)
        if role not in units and suffix:
            # ... not applied unless the user says so: a suffix may name something else
            units[role], said[role] = suffix, f"the end of its name; if it is in {SI_UNITS[role[0]][0]}, give it a scale of 1"
    volts = [r for r in f_roles if units.get(r) == "V" and scale.get(r, scale.get("f")) is None]
    if volts:  # the circuit's source voltage, never a force sensor's output
        check_source_voltage(source, names[index[volts[0]]], "V",
                             {names[index[r]]: units.get(r) for r in x_roles})
    for role, unit in units.items():
        fam = role[0]
        factor = scale.get(role, scale.get(fam))
        if factor is None and unit not in SI_UNITS[fam]:
            listed = lookup(unit)  # a unit of the role's quantity: say its factor (never applied)
            known = listed.factor if listed is not None and listed.quantity in ROLE_QUANTITIES[fam] else None
            raise RecordError(
                f"{source}: column {names[index[role]]!r} ({role}) is in {unit!r} ({said[role]}): duffid needs SI "
                f"units ({' or '.join(SI_UNITS[fam])}); scale it into {SI_UNITS[fam][0]}"
                + (f" (multiply {role} by {known:g})" if known else ""))
    rows: list[list[float]] = []
    linenos: list[int] = []
    blank_at: int | None = None
    for k in range(pos, len(lines)):
        lineno = k + 1
        line = lines[k]
        if not line.strip():
            blank_at = blank_at or lineno
            continue
        if blank_at is not None:
            raise RecordError(f"{source}, line {blank_at}: blank line inside the data (data continues on line {lineno})")
        fields = split(line)
        if len(fields) != len(names):
            raise RecordError(f"{source}, line {lineno}: {len(fields)} field{'s' if len(fields) != 1 else ''}, "
                              f"the header has {len(names)} columns")
        rows.append([_number(fields[index[role]], f"{source}, line {lineno}, column {names[index[role]]!r}", decimal)
                     for role in roles])
        linenos.append(lineno)
    if len(rows) < 2:
        raise RecordError(f"{source}: {'no data rows' if not rows else 'only 1 data row'}; a record needs at least 2 samples")
    data = np.array(rows, dtype=np.float64)
    for j, role in enumerate(roles):
        factor = scale.get(role, scale.get(role[0], 1.0))
        if not (np.isfinite(factor) and factor != 0):
            raise RecordError(f"{source}: the scale of {role} must be a finite non-zero number, got {factor!r}")
        data[:, j] *= factor
    if t_role is None:
        t = np.arange(len(rows)) / float(fs)  # type: ignore[arg-type]
        first = 0
    else:
        t = data[:, 0]
        first = 1
    f = data[:, first:first + len(f_roles)]
    x = data[:, first + len(f_roles):]
    _check_samples(t, [(f"column {names[index[role]]!r}", data[:, j]) for j, role in enumerate(roles)],
                   source=source, sampling_rtol=rtol, where=lambda i: f"line {linenos[i]}", t_desc=None)
    return Record(t, f, x, source=source, sampling_rtol=rtol, motion=motion_of(x_roles))


def _scaled(record: Record, scale: Mapping[str, float]) -> Record:
    """``record`` with its time, force and displacement columns multiplied by ``scale``."""
    roles = {"t", "f", record.motion}
    unknown = sorted(set(scale) - roles)
    if unknown:
        raise RecordError(f"{record.source}: a scale for {', '.join(unknown)}: the roles are t, f and {record.motion}")
    return Record(record.t * scale.get("t", 1.0), record.f * scale.get("f", 1.0),
                  record.x * scale.get(record.motion, 1.0), source=record.source, sampling_rtol=record.sampling_rtol,
                  motion=record.motion)
