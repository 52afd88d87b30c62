"""MATLAB ``.mat`` files: version 4 to 7 through scipy, version 7.3 (HDF5 inside) through h5py.

Every numeric variable that is a vector is a channel named as the variable (``force``); a
matrix of samples x channels gives one channel per column, named ``x(:,2)`` as MATLAB writes
it; a struct's fields are named ``s.field`` in v7.3 files. MATLAB stores neither units nor
rates: the values are taken as SI, the time is a variable (``t=``) or the sampling rate. A
complex variable is refused when read (v7.3: listed as such; v5: ``whosmat`` does not tell, so
only its values show it): a record is real.
"""
from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np
import scipy.io

from ...errors import MissingDependencyError, RecordError
from ..channels import Channel, numeric
from . import optional_import, reading
from .hdf5 import open_file

__all__ = ["EXTENSIONS", "is_v73", "open_channels"]

EXTENSIONS = (".mat",)
_COMPLEX = "holds complex values; a record is real: select its real part saved as a variable of its own"
_NUMERIC_CLASSES = {"double", "single", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64"}


def is_v73(path: str) -> bool:
    """Whether ``path`` is a MATLAB v7.3 file (an HDF5 file), which scipy cannot read."""
    with reading(path, "MATLAB .mat file"), open(path, "rb") as fh:
        head = fh.read(128)
    return head.startswith(b"MATLAB 7.3") or head.startswith(b"\x89HDF")


def _columns(name: str, shape: tuple[int, ...], kind: str, column: Callable[[int], Callable[[], np.ndarray]],
             problem: str = "") -> list[Channel]:
    """Channels of a MATLAB variable of (MATLAB) ``shape``: one for a vector, one per column of a matrix."""
    rows, cols = shape
    if rows == 1 or cols == 1:
        return [Channel(name, None, rows * cols, kind=kind, problem=problem, read=column(-1))]
    return [Channel(f"{name}(:,{k + 1})", None, rows, kind=kind, problem=problem, read=column(k))
            for k in range(cols)]


@contextmanager
def _v5(path: str) -> Iterator[list[Channel]]:
    with reading(path, "MATLAB .mat file"):
        listed = scipy.io.whosmat(path, appendmat=False)
    cache: dict[str, np.ndarray] = {}

    def column(name: str) -> Callable[[int], Callable[[], np.ndarray]]:
        def reader(k: int) -> Callable[[], np.ndarray]:
            def read() -> np.ndarray:
                if name not in cache:
                    cache[name] = scipy.io.loadmat(path, appendmat=False, variable_names=[name])[name]
                value = cache[name]
                if np.iscomplexobj(value):  # whosmat does not tell: refused once read
                    raise RecordError(f"{path}, variable {name!r}: {_COMPLEX}")
                return value.reshape(-1) if k < 0 else value[:, k]
            return read
        return reader

    channels: list[Channel] = []
    for name, shape, cls in listed:
        if cls in _NUMERIC_CLASSES and len(shape) == 2 and 0 not in shape:
            channels += _columns(name, shape, cls, column(name))
    yield channels


@contextmanager
def _v73(path: str) -> Iterator[list[Channel]]:
    advice = ("the file is a MATLAB v7.3 (HDF5) file that h5py cannot read ({exc}); save it with "
              "save(..., '-v7') in MATLAB")
    try:
        h5py = optional_import("h5py", "MATLAB v7.3 files")
    except MissingDependencyError as exc:
        raise MissingDependencyError(f"{path}: the file is a MATLAB v7.3 (HDF5) file; {exc} (or save it with "
                                     "save(..., '-v7') in MATLAB)") from None
    with open_file(path, "MATLAB v7.3 file", advice) as handle:
        channels: list[Channel] = []

        def visit(name: str, node: Any) -> None:
            cls = node.attrs.get("MATLAB_class", b"")
            cls = cls.decode() if isinstance(cls, bytes) else str(cls)
            is_complex = isinstance(node, h5py.Dataset) and set(node.dtype.names or ()) == {"real", "imag"}
            if not isinstance(node, h5py.Dataset) or name.startswith("#") or cls not in _NUMERIC_CLASSES \
                    or "MATLAB_empty" in node.attrs or not (numeric(node.dtype) or is_complex) or node.ndim != 2:
                return

            def reader(k: int, ds: Any = node) -> Callable[[], np.ndarray]:
                # HDF5 holds MATLAB's column-major arrays transposed: MATLAB column k is row k here
                return lambda: ds[()].reshape(-1) if k < 0 else ds[k, :]
            channels.extend(_columns(name.replace("/", "."), node.shape[::-1], cls, reader,
                                     _COMPLEX if is_complex else ""))

        handle.visititems(visit)
        yield channels


@contextmanager
def open_channels(path: str) -> Iterator[list[Channel]]:
    """The numeric variables of the MATLAB file ``path`` as channels (v5 and v7.3).

    Errors as :mod:`duffid.data.readers` says.
    """
    with (_v73 if is_v73(path) else _v5)(path) as channels:
        yield channels
