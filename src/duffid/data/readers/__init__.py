"""One reader per file format, each over its well-kept library: TDMS (npTDMS), UFF 58/58b
(pyuff), HDF5 (h5py), MATLAB v5 (scipy) and v7.3 (h5py), WAV (scipy), CSV (listing only; the
record itself is read by :meth:`duffid.data.record.Record.read_csv`).

Every reader module has ``EXTENSIONS`` and ``open_channels(path)``, a context manager that
yields the file's :class:`~duffid.data.channels.Channel` list; a channel reads its values only
when asked, while the file is open. A file that cannot be read raises
:class:`~duffid.errors.RecordError` naming it (:func:`reading`), a missing library
:class:`~duffid.errors.MissingDependencyError`. The libraries of TDMS, UFF and HDF5 are optional (the
``files`` extra): :func:`optional_import` says in one line what to install.
"""
from __future__ import annotations

import importlib
from collections.abc import Iterator
from contextlib import contextmanager
from types import ModuleType

from ...errors import MissingDependencyError, RecordError

__all__ = ["optional_import", "reading", "FILES_EXTRA"]

#: The pip requirement that installs every reader's library.
FILES_EXTRA = "pip install 'duffid[files]'"
_PACKAGES = {"nptdms": "npTDMS", "pyuff": "pyuff", "h5py": "h5py"}


def optional_import(module: str, what: str) -> ModuleType:
    """Import the optional library ``module`` that reading ``what`` needs.

    Raises
    ------
    MissingDependencyError
        ``"reading TDMS files needs npTDMS: pip install 'duffid[files]'"`` when it is missing.
    """
    try:
        return importlib.import_module(module)
    except ImportError:
        raise MissingDependencyError(f"reading {what} needs {_PACKAGES.get(module, module)}, an optional "
                                     f"dependency: {FILES_EXTRA}") from None


@contextmanager
def reading(path: str, what: str) -> Iterator[None]:
    """Report what a library raises while it parses ``path`` as a :class:`RecordError` naming the file.

    Parameters
    ----------
    path : str
        The file.
    what : str
        Its format, for the message (``"TDMS file"``).

    Raises
    ------
    RecordError
        ``"<path>: cannot read file: <reason>"`` (the system's error), else ``"<path>: not a
        readable <what> (<reason>)"``: the libraries raise ValueError, KeyError, struct.error or a
        bare Exception on a file they cannot parse.
    """
    try:
        yield
    except RecordError:
        raise
    except OSError as exc:
        raise RecordError(f"{path}: cannot read file: {exc.strerror or exc}") from None
    except Exception as exc:
        raise RecordError(f"{path}: not a readable {what} ({exc or type(exc).__name__})") from None
