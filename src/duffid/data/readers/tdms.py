"""TDMS files (NI LabVIEW, DAQmx loggers) through npTDMS, streaming: only the selected channels
are read.

A channel is named ``group/channel``; its rate is ``1 / wf_increment``, its start time
``wf_start_offset`` [s] after its ``wf_start_time`` (counted from the file's earliest, so that
channels started at different instants are refused, not aligned) and its unit ``unit_string``
(the properties LabVIEW's waveforms write).
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
        found = [(f"{group.name}/{channel.name}", channel) for group in handle.groups() for channel in group.channels()]
        stamps = {name: np.datetime64(channel.properties["wf_start_time"], "ns") for name, channel in found
                  if _is_time(channel.properties.get("wf_start_time"))}
        first = min(stamps.values()) if stamps else None
        channels = []
        for name, channel in found:
            props = channel.properties
            problems = []
            increment = _property(props, "wf_increment", problems)
            if increment is not None and not increment > 0:
                problems.append(f"its wf_increment {increment!r} is not a positive step")
            offset = _property(props, "wf_start_offset", problems) or 0.0
            # the waveform's absolute start (LabVIEW's t0), from the file's earliest
            start = offset + (float((stamps[name] - first) / np.timedelta64(1, "ns")) * 1e-9 if name in stamps else 0.0)
            unit = str(props.get("unit_string", "")).strip() or None
            channels.append(Channel(name, unit, len(channel), 1.0 / increment if increment and increment > 0 else None,
                                    start, str(channel.dtype), problem="; ".join(problems),
                                    read_part=_reader(path, name, channel)))
        yield channels


def _is_time(value: Any) -> bool:
    """Whether a ``wf_start_time`` property is a time stamp (npTDMS: numpy.datetime64)."""
    try:
        return value is not None and not np.isnat(np.datetime64(value, "ns"))
    except (TypeError, ValueError):
        return False


def _property(props: dict[str, Any], key: str, problems: list[str]) -> float | None:
    """A numeric waveform property (None: absent; a text that is no number adds to ``problems``)."""
    value = props.get(key)
    if value is None:
        return None
    try:
        number = float(value)
    except (TypeError, ValueError):
        problems.append(f"its {key} {value!r} is not a number of seconds")
        return None
    if not np.isfinite(number):
        problems.append(f"its {key} {value!r} is not finite")
        return None
    return number
