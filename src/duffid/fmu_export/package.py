"""Compile an FMU's C sources with gcc and pack the FMU as a deterministic zip archive."""
from __future__ import annotations

import hashlib
import shutil
import subprocess
import tempfile
import uuid
import zipfile
from pathlib import Path
from typing import Mapping

from .errors import ModelicaExportError

__all__ = ["common_dir", "fmi_include_dir", "compile_shared_library", "write_zip", "token_from",
           "CFLAGS", "build_fmu_archive"]

#: Compiler flags of every FMU binary (warnings are errors).
# -ffp-contract=off: no fused multiply-adds, so the C models compute what their Python
# references compute, operation for operation (the equality tests hold on FMA hardware too)
CFLAGS = ("-shared", "-fPIC", "-O2", "-ffp-contract=off", "-fvisibility=hidden", "-Wall", "-Werror", "-std=gnu99")
#: Files of fmus/common that every FMU needs, by FMI version.
COMMON_FILES = {2: ("fmu_model.h", "fmu_instance.h", "fmu_instance.c", "fmi2_functions.c"),
                3: ("fmu_model.h", "fmu_instance.h", "fmu_instance.c", "fmi3_functions.c")}
_ZIP_DATE = (1980, 1, 1, 0, 0, 0)


def common_dir() -> Path:
    """The shared FMI glue sources (``fmus/common`` of the duffid repository)."""
    path = Path(__file__).resolve().parents[3] / "fmus" / "common"
    if not (path / "fmu_instance.c").exists():
        raise ModelicaExportError(f"FMI glue sources not found at {path} (needs a duffid source checkout)")
    return path


def fmi_include_dir() -> Path:
    """The FMI 2.0 and 3.0 headers shipped with fmpy (its ``c-code`` folder)."""
    import fmpy

    path = Path(fmpy.__file__).resolve().parent / "c-code"
    if not (path / "fmi2Functions.h").exists():
        raise ModelicaExportError(f"FMI headers not found in {path}")
    return path


def token_from(*parts: bytes | str) -> str:
    """A GUID-style token derived from the content (same sources, same token)."""
    digest = hashlib.sha256()
    for part in parts:
        digest.update(part.encode() if isinstance(part, str) else part)
    return "{" + str(uuid.UUID(bytes=digest.digest()[:16])) + "}"


def compile_shared_library(source_dir: Path, sources: list[str], output: Path, compiler: str = "gcc") -> None:
    """Compile ``sources`` (relative to ``source_dir``) into the shared library ``output``."""
    if shutil.which(compiler) is None:
        raise ModelicaExportError(f"C compiler {compiler!r} not found on PATH")
    output.parent.mkdir(parents=True, exist_ok=True)
    command = [compiler, *CFLAGS, f"-I{source_dir}", f"-I{fmi_include_dir()}",
               *[str(source_dir / s) for s in sources], "-o", str(output), "-lm"]
    done = subprocess.run(command, capture_output=True, text=True)
    if done.returncode != 0:
        raise ModelicaExportError(f"compiling {output.name} failed:\n{' '.join(command)}\n{done.stderr.strip()}")


def write_zip(files: Mapping[str, bytes], path: Path) -> None:
    """Write a zip archive whose bytes depend only on ``files`` (sorted, fixed dates)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as archive:
        for name in sorted(files):
            info = zipfile.ZipInfo(name, date_time=_ZIP_DATE)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            info.create_system = 3
            archive.writestr(info, files[name])
    tmp.replace(path)


def build_fmu_archive(path: Path, model_identifier: str, fmi_version: int, model_description: bytes,
                      generated: Mapping[str, str], extra_sources: Mapping[str, bytes] | None = None,
                      compiler: str = "gcc") -> None:
    """Copy the glue and generated sources, compile, and pack ``path``.

    ``generated`` maps file names (placed in ``sources/``) to C text; the glue files of
    ``fmus/common`` are added for the FMI version.
    """
    common = common_dir()
    sources: dict[str, bytes] = {name: (common / name).read_bytes() for name in COMMON_FILES[fmi_version]}
    sources.update({name: text.encode() for name, text in generated.items()})
    sources.update(extra_sources or {})
    c_files = sorted(n for n in sources if n.endswith(".c"))
    platform = "linux64" if fmi_version == 2 else "x86_64-linux"
    with tempfile.TemporaryDirectory(prefix="duffid-fmu-") as tmp:
        src = Path(tmp) / "sources"
        src.mkdir()
        for name, data in sources.items():
            (src / name).write_bytes(data)
        binary = Path(tmp) / f"{model_identifier}.so"
        compile_shared_library(src, c_files, binary, compiler)
        files = {"modelDescription.xml": model_description,
                 f"binaries/{platform}/{model_identifier}.so": binary.read_bytes()}
        files.update({f"sources/{name}": data for name, data in sources.items()})
        write_zip(files, path)
