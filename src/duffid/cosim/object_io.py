"""FMI get and set calls for String and Binary values, which the master holds as Python objects
(``str``, ``bytes``) in its object buffers (private to :mod:`duffid.cosim.runner`).

An FMU owns the memory its String and Binary getters return, valid only until its next call, so
each get copies the values into the buffer at once; each set passes pointers to the buffer's
objects, kept alive for the call. The calls have the signatures of the raw FMI functions that
the runner's loops call (``call() -> status``).
"""
from __future__ import annotations

import ctypes
from typing import Any, Callable, Sequence

import numpy as np

__all__ = ["object_getter", "object_setter"]


def object_getter(function: Any, handle: ctypes.c_void_p, vrs: Any, n_values: int, kind: str, version: int,
                  buffer: np.ndarray, lo: int) -> Callable[[], int]:
    """A call reading ``n_values`` String or Binary values of the variables ``vrs`` into
    ``buffer[lo:lo + n_values]``; returns the FMI status."""
    n_vr = ctypes.c_size_t(len(vrs))
    n = ctypes.c_size_t(n_values)
    if kind == "String":
        texts = (ctypes.c_char_p * n_values)()
        args = (handle, vrs, n_vr, texts) + ((n,) if version == 3 else ())

        def get_strings() -> int:
            status = function(*args)
            if status <= 1:
                buffer[lo:lo + n_values] = [t.decode("utf-8", "replace") if t is not None else "" for t in texts]
            return status

        return get_strings
    sizes = (ctypes.c_size_t * n_values)()
    pointers = (ctypes.c_void_p * n_values)()

    def get_binaries() -> int:
        status = function(handle, vrs, n_vr, sizes, pointers, n)
        if status <= 1:
            buffer[lo:lo + n_values] = [ctypes.string_at(p, s) if p else b"" for p, s in zip(pointers, sizes)]
        return status

    return get_binaries


def object_setter(function: Any, handle: ctypes.c_void_p, vrs: Any, kind: str, version: int, buffer: np.ndarray,
                  index: Sequence[int]) -> Callable[[], int]:
    """A call setting the String or Binary variables ``vrs`` to ``buffer[index]``; returns the
    FMI status."""
    n_vr = ctypes.c_size_t(len(vrs))
    n = ctypes.c_size_t(len(index))
    index = list(index)

    def set_objects() -> int:
        values = [buffer[i] for i in index]
        if kind == "String":
            texts = (ctypes.c_char_p * len(values))(*[v.encode("utf-8") for v in values])
            return function(handle, vrs, n_vr, texts, *((n,) if version == 3 else ()))
        held = [ctypes.c_char_p(bytes(v)) for v in values]  # alive until the call returns
        pointers = (ctypes.c_void_p * len(values))(*[ctypes.cast(h, ctypes.c_void_p).value for h in held])
        sizes = (ctypes.c_size_t * len(values))(*[len(v) for v in values])
        return function(handle, vrs, n_vr, sizes, pointers, n)

    return set_objects
