"""The one C build helper: compiler discovery, flags and the platform names of FMU binaries.

Every C binary duffid makes (the estimator core loaded through ctypes, and every FMU:
plants, estimators, controllers) is compiled by :func:`compile_shared_library` with
the flags below, by the compiler :func:`find_compiler` finds.
"""
from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path
from typing import Sequence

import fmpy

from .errors import BuildError, CompilerNotFoundError

__all__ = ["CFLAGS", "LIBRARY_FLAGS", "FMU_FLAGS", "find_compiler", "compile_shared_library",
           "FMI2_PLATFORM", "FMI3_PLATFORM", "SHARED_LIBRARY_SUFFIX", "fmu_binary_path"]

#: Flags of every C build: optimised, position independent, warnings are errors, and no
#: fused multiply-adds, so the C code computes what its Python reference computes,
#: operation for operation (the equality tests hold on FMA hardware too).
CFLAGS = ("-O2", "-ffp-contract=off", "-fPIC", "-shared", "-Wall", "-Werror")
#: Added for the hand-written estimator core library (strict C99; every function exported).
LIBRARY_FLAGS = ("-std=c99", "-Wextra", "-pedantic")
#: Added for FMUs: only the FMI functions are exported (the generated model code is gnu99).
FMU_FLAGS = ("-std=gnu99", "-fvisibility=hidden")
#: Platform folders of the FMU's binaries for this host (from fmpy), by FMI version.
FMI2_PLATFORM = fmpy.platform
FMI3_PLATFORM = fmpy.platform_tuple
#: File suffix of a shared library on this host.
SHARED_LIBRARY_SUFFIX = fmpy.sharedLibraryExtension


def fmu_binary_path(model_identifier: str, fmi_version: int) -> str:
    """Where an FMU for this host keeps its binary, e.g. ``binaries/linux64/X.so``."""
    platform = FMI2_PLATFORM if fmi_version == 2 else FMI3_PLATFORM
    return f"binaries/{platform}/{model_identifier}{SHARED_LIBRARY_SUFFIX}"


def find_compiler(compiler: str | None = None) -> str:
    """The C compiler: ``compiler`` if given, else ``$CC``, else the first of cc, gcc, clang on PATH.

    Raises
    ------
    CompilerNotFoundError
        If none is found (the message names the candidates).
    """
    env = os.environ.get("CC")
    candidates = [compiler] if compiler else [env] if env else ["cc", "gcc", "clang"]
    for name in candidates:
        path = shutil.which(name) if name else None
        if path:
            return path
    raise CompilerNotFoundError(
        f"no C compiler found: none of {', '.join(c for c in candidates if c)} is on PATH "
        "(install gcc, e.g. `apt install gcc`, or set CC)")


def compile_shared_library(sources: Sequence[str | os.PathLike[str]], output: str | os.PathLike[str], *,
                           include_dirs: Sequence[str | os.PathLike[str]] = (), flags: Sequence[str] = FMU_FLAGS,
                           compiler: str | None = None) -> None:
    """Compile ``sources`` into the shared library ``output`` with :data:`CFLAGS` + ``flags``.

    Raises
    ------
    CompilerNotFoundError
        If no compiler is found.
    BuildError
        If compilation fails (the message holds the command and the compiler's output).
    """
    cc = find_compiler(compiler)
    Path(output).parent.mkdir(parents=True, exist_ok=True)
    command = [cc, *CFLAGS, *flags, *(f"-I{d}" for d in include_dirs), *(str(s) for s in sources),
               "-o", str(output), "-lm"]
    done = subprocess.run(command, capture_output=True, text=True)
    if done.returncode != 0:
        raise BuildError(f"compiling {Path(output).name} failed:\n{' '.join(command)}\n"
                         f"{(done.stdout + done.stderr).strip()}")
