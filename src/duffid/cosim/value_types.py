"""The kinds of values the co-simulation master exchanges, one per FMI variable type, and the
names of array elements.

Every FMI 2 and FMI 3 variable type except Clock has a *kind*: FMI 2 Real and FMI 3 Float64
are ``"Real"``, FMI 2 Integer and FMI 3 Int32 are ``"Integer"``, FMI 3 Float32, Int8 .. UInt64
keep their names, and Boolean, Enumeration, String and Binary are their own kinds. Values of
one kind are held in one buffer (:data:`DTYPES`); a connection joins two variables of the same
kind (so FMI 2 Real to FMI 3 Float64, FMI 2 Integer to FMI 3 Int32, and Enumeration to
Enumeration of the same items: FMI 2 exchanges them as Integer, FMI 3 as Int64, both held as
int64; no other conversion is made). String values are Python ``str``, Binary values
``bytes``; Result CSV files write a Binary value as its bytes in hexadecimal.

An element of an array variable (FMI 3 ``<Dimension>``) is named ``name[i]`` or ``name[i,j]``
(indices from 1, in the order of the dimensions, as FMI's structured naming convention does);
its values are exchanged in row-major order.
"""
from __future__ import annotations

import ctypes
import math
import numbers
import re
from typing import Any, Sequence

import numpy as np

__all__ = ["VARIABLE_KINDS", "DTYPES", "OBJECT_KINDS", "INTEGER_KINDS", "FLOAT_KINDS", "FMI_FUNCTIONS",
           "check_value", "parse_start", "element_names", "split_element", "flat_index", "csv_text"]

#: FMI 2 and FMI 3 variable types -> the kind duffid exchanges them as.
VARIABLE_KINDS = {"Real": "Real", "Float64": "Real", "Float32": "Float32", "Integer": "Integer", "Int32": "Integer",
                  "Int8": "Int8", "UInt8": "UInt8", "Int16": "Int16", "UInt16": "UInt16", "UInt32": "UInt32",
                  "Int64": "Int64", "UInt64": "UInt64", "Boolean": "Boolean", "Enumeration": "Enumeration",
                  "String": "String", "Binary": "Binary"}
#: The buffer type of each kind (Boolean as int32 0/1; String and Binary as Python objects).
DTYPES = {"Real": np.float64, "Float32": np.float32, "Integer": np.int32, "Int8": np.int8, "UInt8": np.uint8,
          "Int16": np.int16, "UInt16": np.uint16, "UInt32": np.uint32, "Int64": np.int64, "UInt64": np.uint64,
          "Boolean": np.int32, "Enumeration": np.int64, "String": object, "Binary": object}
#: Kinds held as Python objects (copied by Python; the compiled loop calls back for them).
OBJECT_KINDS = ("String", "Binary")
FLOAT_KINDS = ("Real", "Float32")
INTEGER_KINDS = ("Integer", "Int8", "UInt8", "Int16", "UInt16", "UInt32", "Int64", "UInt64", "Enumeration")

#: kind -> (get function, set function, C type of one value) per FMI version.
FMI_FUNCTIONS = {
    2: {"Real": ("fmi2GetReal", "fmi2SetReal", ctypes.c_double),
        "Integer": ("fmi2GetInteger", "fmi2SetInteger", ctypes.c_int),
        "Boolean": ("fmi2GetBoolean", "fmi2SetBoolean", ctypes.c_int),
        "Enumeration": ("fmi2GetInteger", "fmi2SetInteger", ctypes.c_int),
        "String": ("fmi2GetString", "fmi2SetString", ctypes.c_char_p)},
    3: {"Real": ("fmi3GetFloat64", "fmi3SetFloat64", ctypes.c_double),
        "Float32": ("fmi3GetFloat32", "fmi3SetFloat32", ctypes.c_float),
        "Integer": ("fmi3GetInt32", "fmi3SetInt32", ctypes.c_int32),
        "Int8": ("fmi3GetInt8", "fmi3SetInt8", ctypes.c_int8),
        "UInt8": ("fmi3GetUInt8", "fmi3SetUInt8", ctypes.c_uint8),
        "Int16": ("fmi3GetInt16", "fmi3SetInt16", ctypes.c_int16),
        "UInt16": ("fmi3GetUInt16", "fmi3SetUInt16", ctypes.c_uint16),
        "UInt32": ("fmi3GetUInt32", "fmi3SetUInt32", ctypes.c_uint32),
        "Int64": ("fmi3GetInt64", "fmi3SetInt64", ctypes.c_int64),
        "UInt64": ("fmi3GetUInt64", "fmi3SetUInt64", ctypes.c_uint64),
        "Boolean": ("fmi3GetBoolean", "fmi3SetBoolean", ctypes.c_bool),
        "Enumeration": ("fmi3GetInt64", "fmi3SetInt64", ctypes.c_int64),
        "String": ("fmi3GetString", "fmi3SetString", ctypes.c_char_p),
        "Binary": ("fmi3GetBinary", "fmi3SetBinary", ctypes.c_void_p)},
}

_ELEMENT = re.compile(r"(?P<base>.+)\[(?P<index>\s*\d+\s*(,\s*\d+\s*)*)\]\Z")


def check_value(kind: str, value: Any, where: str) -> Any:
    """``value`` as a value of ``kind`` (float, int, bool, str or bytes), or ValueError naming
    ``where`` and what is wrong: a fraction or an out-of-range number for an integer kind, a
    Boolean other than 0/1/True/False, a String that is not text, a Binary that is neither bytes
    nor a hexadecimal text."""
    if kind in OBJECT_KINDS:
        if kind == "String" and isinstance(value, str):
            return value
        if kind == "Binary" and isinstance(value, (bytes, bytearray)):
            return bytes(value)
        if kind == "Binary" and isinstance(value, str):
            try:
                return bytes.fromhex(value)
            except ValueError:
                raise ValueError(f"{where} is Binary; {value!r} is not hexadecimal text") from None
        raise ValueError(f"{where} is {kind}; got {value!r}")
    if isinstance(value, np.generic):
        value = value.item()
    if kind == "Boolean":
        if isinstance(value, bool) or (isinstance(value, numbers.Real) and value in (0, 1)):
            return bool(value)
        raise ValueError(f"{where} is Boolean; got {value!r} (not 0, 1, True or False)")
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{where} is {kind}; got {value!r}")
    if kind in FLOAT_KINDS:
        return float(value)
    if isinstance(value, float) and (not math.isfinite(value) or value != int(value)):
        raise ValueError(f"{where} is {kind}; got {value!r} (not an integer)")
    number = int(value)
    info = np.iinfo(DTYPES[kind])
    if not info.min <= number <= info.max:
        raise ValueError(f"{where} is {kind}; {number!r} is outside its range [{info.min}, {info.max}]")
    return number


def parse_start(kind: str, text: str | None, size: int) -> list[Any]:
    """The ``size`` start values of a variable from its start attribute (space separated;
    a String's or Binary's whole text; zero, False, "" or b"" without one; the last value
    repeated when fewer are given)."""
    if text is None:
        return [{"String": "", "Binary": b""}.get(kind, 0)] * size
    if kind == "String":
        return [text] * size
    if kind == "Binary":
        return [bytes.fromhex(text)] * size
    tokens = text.split() or ["0"]
    values: list[Any] = []
    for token in tokens:
        if kind == "Boolean":
            values.append(token.lower() in ("true", "1"))
        elif kind in FLOAT_KINDS:
            values.append(float(token))
        else:
            values.append(int(token))
    return (values + [values[-1]] * size)[:size]


def element_names(name: str, shape: Sequence[int]) -> list[str]:
    """``name[1,1]``, ``name[1,2]``, ... in row-major order (``[name]`` for a scalar)."""
    if not shape:
        return [name]
    return [f"{name}[{','.join(str(i + 1) for i in index)}]" for index in np.ndindex(*shape)]


def split_element(name: str) -> tuple[str, tuple[int, ...] | None]:
    """``"u[2,1]"`` -> ``("u", (2, 1))``; a name without indices -> ``(name, None)``."""
    match = _ELEMENT.match(name)
    if match is None:
        return name, None
    return match["base"], tuple(int(i) for i in match["index"].split(","))


def flat_index(index: tuple[int, ...], shape: Sequence[int], where: str) -> int:
    """The row-major position of the element ``index`` (from 1) of an array of ``shape``, or
    ValueError naming ``where``."""
    if len(index) != len(shape):
        raise ValueError(f"{where}: {len(index)} indices given, the variable has {len(shape)} dimension(s) "
                         f"{tuple(shape)}")
    if any(not 1 <= i <= n for i, n in zip(index, shape)):
        raise ValueError(f"{where}: index {list(index)} is outside the variable's shape {tuple(shape)} "
                         "(indices from 1)")
    return int(np.ravel_multi_index(tuple(i - 1 for i in index), tuple(shape)))


def csv_text(kind: str, value: Any) -> str:
    """A value as Result CSV files write it: floats in full precision (``repr``), integers and
    Booleans (0/1) as integers, Strings as they are, Binary values as hexadecimal."""
    if kind == "Binary":
        return bytes(value).hex()
    if kind == "String":
        return str(value)
    if kind in FLOAT_KINDS:
        return repr(float(value))
    return repr(int(value))
