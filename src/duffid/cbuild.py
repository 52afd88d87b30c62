"""The one C build helper: compiler discovery, flags and the platforms of FMU binaries.

Every C binary duffid makes (the estimator core loaded through ctypes, and every FMU:
plants, estimators, controllers) is compiled by :func:`compile_shared_library` with
the flags below, by the compiler :func:`find_compiler` finds, for this machine or (FMUs)
for any :data:`PLATFORMS` entry whose cross compiler is installed:

========== ===================== ======================= ==================================
platform   FMI 2 folder          FMI 3 folder            compiler (Debian package)
========== ===================== ======================= ==================================
linux64    ``linux64``           ``x86_64-linux``        cc / gcc (gcc)
win64      ``win64``             ``x86_64-windows``      x86_64-w64-mingw32-gcc (gcc-mingw-w64-x86-64)
aarch64-linux ``aarch64-linux``  ``aarch64-linux``       aarch64-linux-gnu-gcc (gcc-aarch64-linux-gnu)
========== ===================== ======================= ==================================

FMI 2 names no folder for 64-bit ARM; duffid uses the FMI 3 tuple ``aarch64-linux`` there too.
Windows DLLs link the C runtime statically (``-static``): they import only Windows' own
KERNEL32.dll and msvcrt.dll.
"""
from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Sequence

import fmpy

from .errors import AssetError, BuildError, CompilerNotFoundError, InputError

__all__ = ["CFLAGS", "LIBRARY_FLAGS", "FMU_FLAGS", "find_compiler", "compile_shared_library",
           "FMI2_PLATFORM", "FMI3_PLATFORM", "SHARED_LIBRARY_SUFFIX", "fmu_binary_path",
           "Platform", "PLATFORMS", "HOST_PLATFORM", "resolve_platforms", "platform_compiler",
           "cached_library", "default_build_dir", "file_stamp"]

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


@dataclass(frozen=True)
class Platform:
    """A target of FMU binaries.

    Attributes
    ----------
    name : str
        The name ``--platforms`` takes (``linux64``, ``win64``, ``aarch64-linux``).
    fmi2 : str
        Folder under ``binaries/`` in an FMI 2 FMU.
    fmi3 : str
        Folder under ``binaries/`` in an FMI 3 FMU (the FMI 3 platform tuple).
    suffix : str
        File suffix of its shared libraries.
    compiler : str
        The cross compiler (ignored for the platform of this machine: :func:`find_compiler`).
    package : str
        The Debian package that installs the compiler.
    flags : tuple of str
        Flags added to :data:`CFLAGS` for this platform.
    runner : tuple of str
        Command prefix that runs this platform's executables on an x86_64 Linux machine
        (wine, qemu), empty for the host.
    runner_package : str
        The Debian package of the runner.
    """

    name: str
    fmi2: str
    fmi3: str
    suffix: str
    compiler: str
    package: str
    flags: tuple[str, ...] = ()
    runner: tuple[str, ...] = ()
    runner_package: str = ""

    @property
    def is_host(self) -> bool:
        """Whether binaries of this platform load on this machine."""
        return self.fmi3 == FMI3_PLATFORM

    def folder(self, fmi_version: int) -> str:
        """The folder under ``binaries/`` for FMI version ``fmi_version``."""
        return self.fmi2 if fmi_version == 2 else self.fmi3


_WINE = "/usr/lib/wine/wine64" if Path("/usr/lib/wine/wine64").exists() else "wine64"
#: The platforms duffid builds FMU binaries for, by name.
PLATFORMS: dict[str, Platform] = {
    "linux64": Platform("linux64", "linux64", "x86_64-linux", ".so", "x86_64-linux-gnu-gcc", "gcc"),
    "win64": Platform("win64", "win64", "x86_64-windows", ".dll", "x86_64-w64-mingw32-gcc",
                      "gcc-mingw-w64-x86-64", flags=("-static", "-Wl,--no-insert-timestamp"),
                      runner=(_WINE,), runner_package="wine64"),
    "aarch64-linux": Platform("aarch64-linux", "aarch64-linux", "aarch64-linux", ".so", "aarch64-linux-gnu-gcc",
                        "gcc-aarch64-linux-gnu (and libc6-dev-arm64-cross)",
                        runner=("qemu-aarch64", "-L", "/usr/aarch64-linux-gnu"), runner_package="qemu-user"),
}
#: The platform of this machine (an entry of :data:`PLATFORMS`, or one made from fmpy's names).
HOST_PLATFORM = next((p for p in PLATFORMS.values() if p.is_host),
                     Platform(FMI2_PLATFORM, FMI2_PLATFORM, FMI3_PLATFORM, SHARED_LIBRARY_SUFFIX, "cc", "a C compiler"))


def fmu_binary_path(model_identifier: str, fmi_version: int, platform: Platform | None = None) -> str:
    """Where an FMU keeps its binary for ``platform`` (default: this machine's), e.g.
    ``binaries/linux64/X.so``."""
    platform = platform or HOST_PLATFORM
    return f"binaries/{platform.folder(fmi_version)}/{model_identifier}{platform.suffix}"


def platform_compiler(platform: Platform) -> str | None:
    """The compiler for ``platform``: :func:`find_compiler`'s for this machine, else the cross
    compiler when it is on PATH and can build (its C library is installed), else None."""
    if platform.is_host:
        return find_compiler()
    path = shutil.which(platform.compiler)
    if path is None:
        return None
    probe = subprocess.run([path, "-E", "-x", "c", "-", "-o", os.devnull], input="#include <math.h>\n",
                           capture_output=True, text=True)
    return path if probe.returncode == 0 else None


def resolve_platforms(names: Iterable[str] | None = None) -> tuple[list[Platform], list[str]]:
    """The platforms to build for and one line per requested platform that is skipped.

    Parameters
    ----------
    names : iterable of str, optional
        Names of :data:`PLATFORMS` (``"all"``: every one); default: every one.

    Returns
    -------
    platforms : list of Platform
        The requested platforms whose compiler works, this machine's first.
    skipped : list of str
        ``"skipping win64 binaries: x86_64-w64-mingw32-gcc not found (install the Debian
        package gcc-mingw-w64-x86-64)"`` for each other one.

    Raises
    ------
    InputError
        For a name that is not a platform.
    """
    wanted = list(PLATFORMS) if names is None else [n for name in names for n in
                                                     (PLATFORMS if name == "all" else [name])]
    unknown = [n for n in wanted if n not in PLATFORMS and n != HOST_PLATFORM.name]
    if unknown:
        raise InputError(f"--platforms: unknown platform {', '.join(unknown)}; choose from "
                         f"{', '.join(PLATFORMS)} or all")
    chosen: list[Platform] = []
    skipped: list[str] = []
    for name in dict.fromkeys(wanted):
        platform = PLATFORMS.get(name, HOST_PLATFORM)
        if platform.is_host or platform_compiler(platform) is not None:
            chosen.append(platform)
        else:
            skipped.append(f"skipping {name} binaries: {platform.compiler} not found or cannot compile "
                           f"(install the Debian package {platform.package})")
    chosen.sort(key=lambda p: not p.is_host)
    return chosen, skipped


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
                           compiler: str | None = None, platform: Platform | None = None) -> None:
    """Compile ``sources`` into the shared library ``output`` with :data:`CFLAGS` + ``flags``.

    Parameters
    ----------
    sources : sequence of path
        The C files.
    output : path
        The library to write.
    include_dirs : sequence of path
        ``-I`` folders.
    flags : sequence of str
        Added to :data:`CFLAGS` (and the platform's own flags).
    compiler : str, optional
        The compiler for this machine (see :func:`find_compiler`).
    platform : Platform, optional
        Target; default: this machine. Another platform is built by its cross compiler.

    Raises
    ------
    CompilerNotFoundError
        If no compiler is found (for a cross platform: naming the Debian package).
    BuildError
        If compilation fails (the message holds the command and the compiler's output).
    """
    platform = platform or HOST_PLATFORM
    if platform.is_host:
        cc = find_compiler(compiler)
    else:
        found = platform_compiler(platform)
        if found is None:
            raise CompilerNotFoundError(f"no {platform.name} cross compiler: {platform.compiler} not found or "
                                        f"cannot compile (install the Debian package {platform.package})")
        cc = found
    base = [f for f in CFLAGS if not (platform.suffix == ".dll" and f == "-fPIC")]
    Path(output).parent.mkdir(parents=True, exist_ok=True)
    command = [cc, *base, *platform.flags, *flags, *(f"-I{d}" for d in include_dirs), *(str(s) for s in sources),
               "-o", str(output), "-lm"]
    done = subprocess.run(command, capture_output=True, text=True)
    if done.returncode != 0:
        raise BuildError(f"compiling {Path(output).name} for {platform.name} failed:\n{' '.join(command)}\n"
                         f"{(done.stdout + done.stderr).strip()}")


def default_build_dir(source_dir: str | os.PathLike[str], component: str) -> Path:
    """Where a library built from ``source_dir`` (``fmus/<component>``) is cached:
    ``$DUFFID_BUILD_DIR``; else ``build/<component>`` of a writable checkout (the sources are
    its files); else ``<user cache>/duffid/<component>``."""
    env = os.environ.get("DUFFID_BUILD_DIR")
    if env:
        return Path(env)
    root = Path(source_dir).resolve().parents[1]
    if (root / "pyproject.toml").is_file() and os.access(root, os.W_OK):
        return root / "build" / component
    cache = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(cache) / "duffid" / component


_DIGESTS: dict[tuple[Any, ...], str] = {}


def _source_digest(src: Path, names: Sequence[str], extra: Sequence[Path], flags: Sequence[str]) -> str:
    """The first 16 hex digits of the SHA-256 of the files (name and content) and the flags;
    remembered in this process while no file's size or modification time changes."""
    files = [*((name, src / name) for name in names), *((path.name, path) for path in extra)]
    key = (tuple((label, str(path), *file_stamp(path)) for label, path in files), tuple(flags))
    known = _DIGESTS.get(key)
    if known is not None:
        return known
    digest = hashlib.sha256()
    for label, path in files:
        digest.update(label.encode() + b"\0" + path.read_bytes())
    digest.update(" ".join((*CFLAGS, *flags)).encode())
    _DIGESTS[key] = digest.hexdigest()[:16]
    return _DIGESTS[key]


def file_stamp(path: str | os.PathLike[str]) -> tuple[int, int]:
    """A file's modification time [ns] and size: what tells a remembered digest is stale."""
    status = os.stat(path)
    return status.st_mtime_ns, status.st_size


def cached_library(stem: str, source_dir: str | os.PathLike[str], sources: Sequence[str],
                   headers: Sequence[str] = (), *, flags: Sequence[str] = LIBRARY_FLAGS,
                   build_dir: str | os.PathLike[str] | None = None, compiler: str | None = None,
                   force: bool = False, extra_sources: Sequence[str | os.PathLike[str]] = ()) -> Path:
    """A shared library for this machine compiled from ``sources`` (and ``headers``) of
    ``source_dir``, cached as ``<build_dir>/<stem>-<hash><suffix>`` by the hash of the files
    and the flags; stale builds of the same stem are removed.

    ``extra_sources`` are C files from elsewhere (e.g. generated code), hashed by name and
    content and compiled with ``source_dir`` on the include path.

    The library is written to a temporary file and renamed: concurrent builders never see a
    partial file. ``build_dir`` defaults to :func:`default_build_dir` of the source folder.

    Raises
    ------
    AssetError
        If a source or header is missing.
    CompilerNotFoundError, BuildError
        As :func:`compile_shared_library`.
    """
    src = Path(source_dir)
    missing = [name for name in (*sources, *headers) if not (src / name).is_file()]
    if missing:
        raise AssetError(f"C sources of {stem} not found in {src}: {missing}")
    extra = [Path(p) for p in extra_sources]
    missing = [str(p) for p in extra if not p.is_file()]
    if missing:
        raise AssetError(f"C sources of {stem} not found: {missing}")
    out_dir = Path(build_dir) if build_dir is not None else default_build_dir(src, src.name)
    target = out_dir / f"{stem}-{_source_digest(src, (*sources, *headers), extra, flags)}{SHARED_LIBRARY_SUFFIX}"
    if target.is_file() and not force:
        return target
    out_dir.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=target.stem + ".", suffix=target.suffix, dir=out_dir)
    os.close(fd)
    try:
        compile_shared_library([*(src / name for name in sources), *extra], tmp, flags=flags, compiler=compiler,
                               include_dirs=[src] if extra else ())
        os.replace(tmp, target)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    for stale in out_dir.glob(f"{stem}-*{SHARED_LIBRARY_SUFFIX}"):  # builds of older sources
        if stale != target and len(stale.stem) == len(target.stem):
            try:
                stale.unlink()
            except OSError:  # in use (Windows) or removed by another builder
                pass
    return target
