"""Which format a record file is in, and reading its channels: the one entry point over the
readers of :mod:`duffid.data.readers`.

The format comes from the ``format`` argument (``--format``) or the file's extension
(:data:`FORMATS`). :func:`list_channels` describes a file (``duffid inspect``);
:func:`read_arrays` reads the selected channels into SI time, forces and displacements for
:meth:`duffid.data.record.Record.read`.
"""
from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from types import ModuleType

import numpy as np

from ..errors import InputError, RecordError
from .channels import Channel, assemble, motion_of, select
from .readers import hdf5, matlab, tdms, text, uff, wav

__all__ = ["FORMATS", "detect_format", "list_channels", "read_arrays"]

#: Format name -> its reader module (``EXTENSIONS``, ``open_channels``), in the order of ``--format``.
FORMATS: dict[str, ModuleType] = {"csv": text, "mat": matlab, "tdms": tdms, "uff": uff, "hdf5": hdf5, "wav": wav}


def detect_format(path: str | os.PathLike[str], format: str | None = None) -> str:
    """The format of ``path``: ``format`` if given, else the one its extension names.

    Raises
    ------
    InputError
        An unknown ``format``.
    RecordError
        No ``format`` and an extension no format claims (the message lists the extensions).
    """
    if format is not None:
        if format not in FORMATS:
            raise InputError(f"unknown file format {format!r} (formats: {', '.join(FORMATS)})")
        return format
    suffix = Path(path).suffix.lower()
    for name, module in FORMATS.items():
        if suffix in module.EXTENSIONS:
            return name
    known = ", ".join(f"{name} ({' '.join(m.EXTENSIONS)})" for name, m in FORMATS.items())
    raise RecordError(f"{os.fspath(path)}: cannot tell the format from the extension {suffix or '(none)'!r}; "
                      f"give it (--format): {known}")


def _exists(source: str) -> None:
    if not os.path.exists(source):
        raise RecordError(f"{source}: no such file")


def list_channels(path: str | os.PathLike[str], format: str | None = None) -> list[Channel]:
    """The channels of a record file (name, unit, rate, start, length), without reading their values.

    Parameters
    ----------
    path : str or os.PathLike
        The file.
    format : str, optional
        One of :data:`FORMATS`; default: from the extension.

    Raises
    ------
    RecordError, MissingDependencyError
        The file cannot be read, or its format's library is not installed.
    """
    source = os.fspath(path)
    fmt = detect_format(source, format)
    _exists(source)
    with FORMATS[fmt].open_channels(source) as channels:
        return list(channels)


def read_arrays(path: str | os.PathLike[str], *, format: str | None = None,
                columns: Mapping[str, str | int] | None = None, scale: Mapping[str, float] | None = None,
                fs: float | None = None, motion: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray, str]:
    """Read the selected channels of a TDMS, UFF, HDF5, MATLAB or WAV file into SI arrays.

    Only the selected channels are read (h5py slices, npTDMS streaming).

    Parameters
    ----------
    path : str or os.PathLike
        The file.
    format : str, optional
        One of :data:`FORMATS` but ``csv``; default: from the extension.
    columns : mapping, optional
        Role -> channel name or 1-based number (see :func:`duffid.data.channels.select`).
    scale : mapping, optional
        Role -> factor into SI, replacing the unit's (required for integer PCM WAV channels).
    fs : float, optional
        Sampling rate [Hz] for files whose channels carry none (MATLAB).
    motion : bool, optional
        Whether velocity or acceleration channels may take the displacements' place.

    Returns
    -------
    t, f, x : numpy.ndarray
        Read-only float64 time, forces ``(N, nf)`` and motion ``(N, nx)``.
    family : str
        What ``x`` measures: ``x`` (displacements), ``v`` or ``a``.
    """
    source = os.fspath(path)
    fmt = detect_format(source, format)
    if fmt == "csv":
        raise InputError("CSV files are read by Record.read_csv")
    _exists(source)
    with FORMATS[fmt].open_channels(source) as channels:
        chosen = select(channels, columns, source, time=fs is None, motion=motion)
        return (*assemble(chosen, source, scale=scale, fs=fs), motion_of(list(chosen)))
