"""One reader per file format, each over its well-kept library: TDMS (npTDMS), UFF 58/58b
(pyuff), HDF5 (h5py), MATLAB v5 (scipy) and v7.3 (h5py), WAV (scipy), CSV (listing only; the
record itself is read by :meth:`duffid.data.record.Record.read_csv`).

Every reader module has ``EXTENSIONS`` and ``open_channels(path)``, a context manager that
yields the file's :class:`~duffid.data.channels.Channel` list; a channel reads its values only
when asked, while the file is open. The libraries of TDMS, UFF and HDF5 are optional (the
``files`` extra): :func:`optional_import` says in one line what to install.
"""
from __future__ import annotations

import importlib
from types import ModuleType

from ...errors import MissingDependencyError

__all__ = ["optional_import", "FILES_EXTRA"]

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
