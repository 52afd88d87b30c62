"""TDMS files (NI LabVIEW, DAQmx loggers) through npTDMS, streaming: only the selected channels
are read.

A channel is named ``group/channel``; its rate is ``1 / wf_increment``, its start time
``wf_start_offset`` [s] and its unit ``unit_string`` (the properties LabVIEW's waveforms write).
DAQmx raw data are scaled by npTDMS as the file's scaling says.
"""
from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np

from ...errors import RecordError
from ..channels import Channel, numeric
from . import optional_import, reading

__all__ = ["EXTENSIONS", "open_channels"]

EXTENSIONS = (".tdms",)


def _reader(path: str, name: str, channel: Any) -> Any:
    """``read_part(start, stop)`` of a channel: npTDMS streams only those samples from the file."""
    def read_part(start: int, stop: int) -> np.ndarray:
        data = channel[start:stop]
        if not numeric(data.dtype):
            raise RecordError(f"{path}, channel {name!r}: holds {data.dtype} values, not numbers")
        return data
    return read_part


@contextmanager
def open_channels(path: str) -> Iterator[list[Channel]]:
    """The channels of the TDMS file ``path`` (open while the context lasts).

    Errors as :mod:`duffid.data.readers` says.
    """
    nptdms = optional_import("nptdms", "TDMS files")
    with reading(path, "TDMS file"):
        handle = nptdms.TdmsFile.open(path)
    with handle:
        channels = []
        for group in handle.groups():
            for channel in group.channels():
                props = channel.properties
                name = f"{group.name}/{channel.name}"
                increment = props.get("wf_increment")
                rate = 1.0 / float(increment) if increment and float(increment) > 0 else None
                unit = str(props.get("unit_string", "")).strip() or None
                channels.append(Channel(name, unit, len(channel), rate, float(props.get("wf_start_offset", 0.0)),
                                        str(channel.dtype), read_part=_reader(path, name, channel)))
        yield channels
