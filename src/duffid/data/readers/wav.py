"""WAV files (sound-card DAQs) through scipy.io.wavfile, memory-mapped where scipy can.

Channels are numbered 1, 2, ... A WAV file names no units: float samples are taken as SI
values; integer PCM samples (8, 16, 24 or 32 bit) are fractions of full scale (-1 to 1), and a
scale per channel is required: the SI value at full scale (``--scale f=500`` for a load cell
whose full scale is 500 N).
"""
from __future__ import annotations

import re
import warnings
import wave
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import numpy as np
import scipy.io.wavfile

from ...errors import RecordError
from ..channels import Channel
from . import reading

__all__ = ["EXTENSIONS", "open_channels"]

EXTENSIONS = (".wav",)
#: scipy's integer dtype -> (full scale, zero): 24-bit samples come left-justified in int32.
_FULL_SCALE = {np.dtype(np.uint8): (128.0, 128.0), np.dtype(np.int16): (2.0**15, 0.0),
               np.dtype(np.int32): (2.0**31, 0.0)}


def _reader(data: np.ndarray, k: int) -> Callable[[], np.ndarray]:
    def read() -> np.ndarray:
        column = data[:, k] if data.ndim == 2 else data
        if data.dtype not in _FULL_SCALE:
            return column
        full, zero = _FULL_SCALE[data.dtype]
        out = column.astype(np.float64)
        if zero:
            out -= zero
        out /= full
        return out
    return read


def _bits(path: str) -> str:
    """``"24-bit"``: the sample width of a PCM file, which scipy's int32 does not tell (24 or 32)."""
    try:
        with wave.open(path) as fh:
            return f"{8 * fh.getsampwidth()}-bit"
    except (wave.Error, EOFError, OSError):
        return ""


def _read(path: str, mmap: bool) -> tuple[int, np.ndarray]:
    """scipy's ``(rate, data)``; a file shorter than its header says is refused, not cut."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", scipy.io.wavfile.WavFileWarning)
        failure: ValueError | None = None
        try:
            rate, data = scipy.io.wavfile.read(path, mmap=mmap)
        except ValueError as exc:  # scipy fails on a part frame, after its warning
            failure, data = exc, None
    for warning in caught:
        text = str(warning.message)
        if "EOF" not in text:
            warnings.warn_explicit(warning.message, warning.category, warning.filename, warning.lineno)
            continue
        sizes = [int(n) for n in re.findall(r"(\d+) bytes", text)[:2]]
        if data is None or len(sizes) != 2:  # scipy's message as it is
            raise RecordError(f"{path}: the WAV file is cut short ({text}); duffid never reads part of a record")
        finished, expected = sizes
        frame = data.itemsize * (data.shape[1] if data.ndim == 2 else 1)
        declared = -(-(data.shape[0] * frame + expected - finished) // frame)  # the part frame rounds up
        raise RecordError(f"{path}: the WAV file is cut short: its header declares {declared} frames, the file "
                          f"holds {data.shape[0]}; duffid never reads part of a record")
    if failure is not None:
        raise failure  # for :func:`reading`, or the caller's second try without mmap
    return rate, data


@contextmanager
def open_channels(path: str) -> Iterator[list[Channel]]:
    """The channels of the WAV file ``path``.

    Errors as :mod:`duffid.data.readers` says; a file shorter than its header declares too.
    """
    with reading(path, "WAV file"):
        try:
            rate, data = _read(path, mmap=True)
        except ValueError as exc:  # 24-bit and a few other layouts cannot be memory-mapped
            if "mmap" not in str(exc):
                raise
            rate, data = _read(path, mmap=False)
    integer = data.dtype in _FULL_SCALE
    if not integer and not np.issubdtype(data.dtype, np.floating):
        raise RecordError(f"{path}: WAV samples of type {data.dtype} are not supported")
    kind = f"PCM {_bits(path) or data.dtype}" if integer else f"{data.dtype} (float)"
    note = "integer PCM, in fractions of full scale: its SI value at full scale is required" if integer else ""
    n_channels = data.shape[1] if data.ndim == 2 else 1
    yield [Channel(str(k + 1), None, int(data.shape[0]), float(rate), 0.0, kind, note, read=_reader(data, k))
           for k in range(n_channels)]
