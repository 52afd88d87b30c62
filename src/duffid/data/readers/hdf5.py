"""HDF5 files (modern DAQs, h5py/pandas exports) through h5py: only the selected datasets are read.

Every numeric dataset that is a vector (shape ``(N,)``, ``(N, 1)`` or ``(1, N)``) is a channel,
named by its path (``run1/force``). Its rate, start and unit come from attributes of the
dataset or, failing that, of the groups above it: a rate in Hz (:data:`RATE_ATTRIBUTES`) or a
step in s (:data:`STEP_ATTRIBUTES`; both from the nearest node that has either, so that a
dataset's own rate overrides its file's step), a start time (:data:`START_ATTRIBUTES`) and a unit
(:data:`UNIT_ATTRIBUTES`; a byte string that is not UTF-8 is read as Latin-1). A packed
dataset (:data:`PACKING_ATTRIBUTES`) needs the user's scale.
"""
from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np

from ...errors import RecordError
from ..channels import Channel, numeric
from . import optional_import

__all__ = ["EXTENSIONS", "RATE_ATTRIBUTES", "STEP_ATTRIBUTES", "START_ATTRIBUTES", "UNIT_ATTRIBUTES",
           "PACKING_ATTRIBUTES", "open_file", "open_channels"]

EXTENSIONS = (".h5", ".hdf5", ".hdf", ".he5")
#: Attributes holding a sampling rate [Hz], in the order they are looked for.
RATE_ATTRIBUTES = ("fs", "sample_rate", "sampling_rate", "sampling_frequency", "rate")
#: Attributes holding a sampling step [s].
STEP_ATTRIBUTES = ("dt", "wf_increment", "increment", "sample_interval")
#: Attributes holding the time of the first sample [s].
START_ATTRIBUTES = ("t0", "start_time", "wf_start_offset", "start")
#: Attributes holding a unit string.
UNIT_ATTRIBUTES = ("unit", "units", "unit_string", "unit_str")
#: A dataset's packing attributes (netCDF/CF: stored value x scale_factor + add_offset).
PACKING_ATTRIBUTES = ("scale_factor", "add_offset")


@contextmanager
def open_file(path: str, what: str, advice: str = "") -> Iterator[Any]:
    """The HDF5 file ``path`` open for reading (``what``: the format's name for messages; ``advice``:
    the message when it cannot be read, ``{exc}`` standing for h5py's reason)."""
    h5py = optional_import("h5py", what + "s")
    try:
        handle = h5py.File(path, "r")
    except FileNotFoundError:
        raise RecordError(f"{path}: no such file") from None
    except OSError as exc:
        reason = advice.format(exc=exc) if advice else f"not a readable {what} ({exc})"
        raise RecordError(f"{path}: {reason}") from None
    with handle:
        yield handle


def _attribute(node: Any, names: tuple[str, ...], climb: bool = True) -> Any:
    """The first of the attributes ``names`` on ``node`` or (``climb``) a group above it (None: none)."""
    while True:
        for name in names:
            if name in node.attrs:
                value = node.attrs[name]
                if isinstance(value, np.ndarray) and value.size == 1:
                    value = value.reshape(-1)[0]
                return _text(value) if isinstance(value, bytes) else value
        if node.name == "/" or not climb:
            return None
        node = node.parent


def _text(value: bytes) -> str:
    """A byte-string attribute as text: UTF-8, else Latin-1 (older DAQ software's ``b'\\xb5m'``)."""
    try:
        return value.decode("utf-8")
    except UnicodeDecodeError:
        return value.decode("latin-1")


def _packing(ds: Any) -> tuple[str, str]:
    """``(needs_scale, problem)`` of a dataset stored packed (netCDF/CF ``scale_factor`` and
    ``add_offset`` attributes): duffid does not unpack, so the user gives the SI value of one
    stored unit (``--scale``); an offset cannot be given that way."""
    factor, offset = (ds.attrs.get(key) for key in PACKING_ATTRIBUTES)
    said = ", ".join(f"{key} {np.asarray(value).tolist()}" for key, value in zip(PACKING_ATTRIBUTES, (factor, offset))
                     if value is not None)
    if offset is not None and np.any(np.asarray(offset) != 0):
        return "", f"is stored packed ({said}); duffid does not unpack values: store them unpacked"
    if factor is not None:
        return f"is stored packed ({said}), which duffid does not apply: give the SI value of one stored unit", ""
    return "", ""


def _nearest(node: Any, names: tuple[str, ...]) -> Any:
    """``node`` or the nearest group above it with one of the attributes ``names`` (the root
    when none has)."""
    while node.name != "/" and not any(name in node.attrs for name in names):
        node = node.parent
    return node


def _number(path: str, node: Any, names: tuple[str, ...], climb: bool = True) -> float | None:
    value = _attribute(node, names, climb)
    if value is None:
        return None
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise RecordError(f"{path}, dataset {node.name.lstrip('/')!r}: attribute {names} is {value!r}, not a "
                          "number") from None
    if not (np.isfinite(number) and (number > 0 or names is START_ATTRIBUTES)):
        raise RecordError(f"{path}, dataset {node.name.lstrip('/')!r}: attribute {names} is {value!r}, not a "
                          "positive number")
    return number


def _vector_reader(dataset: Any) -> Any:
    """``read_part(start, stop)`` of a vector dataset: h5py reads only that slice."""
    shape = dataset.shape

    def read_part(start: int, stop: int) -> np.ndarray:
        if len(shape) == 1:
            return dataset[start:stop]
        return dataset[start:stop, 0] if shape[1] == 1 else dataset[0, start:stop]
    return read_part


@contextmanager
def open_channels(path: str) -> Iterator[list[Channel]]:
    """The vector datasets of the HDF5 file ``path`` as channels (open while the context lasts).

    Errors as :mod:`duffid.data.readers` says.
    """
    with open_file(path, "HDF5 file") as handle:
        h5py = optional_import("h5py", "HDF5 files")  # loaded by open_file
        datasets: list[Any] = []
        handle.visititems(lambda _, node: datasets.append(node) if isinstance(node, h5py.Dataset) else None)
        channels = []
        for ds in datasets:
            if not numeric(ds.dtype) or ds.ndim not in (1, 2) or (ds.ndim == 2 and 1 not in ds.shape):
                continue
            holder = _nearest(ds, RATE_ATTRIBUTES + STEP_ATTRIBUTES)  # the dataset's own timing before its groups'
            rate, step = (_number(path, holder, names, climb=False) for names in (RATE_ATTRIBUTES, STEP_ATTRIBUTES))
            if rate is not None and step is not None and not np.isclose(rate * step, 1.0, rtol=1e-9, atol=0.0):
                raise RecordError(f"{path}, dataset {ds.name.lstrip('/')!r}: its rate {rate:g} Hz and step {step:g} s "
                                  "disagree")
            unit = _attribute(ds, UNIT_ATTRIBUTES)
            needs_scale, problem = _packing(ds)
            channels.append(Channel(ds.name.lstrip("/"), str(unit).strip() or None if unit is not None else None,
                                    int(max(ds.shape)) if ds.size else 0,
                                    rate if rate is not None else (1.0 / step if step is not None else None),
                                    _number(path, ds, START_ATTRIBUTES) or 0.0, str(ds.dtype),
                                    needs_scale=needs_scale, problem=problem, read_part=_vector_reader(ds)))
        yield channels
