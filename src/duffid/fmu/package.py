"""Compile an FMU's C sources and pack the FMU as a deterministic zip archive."""
from __future__ import annotations

import hashlib
import tempfile
import uuid
import zipfile
from pathlib import Path
from typing import Mapping, Sequence

import fmpy

from ..assets import fmu_sources
from ..cbuild import FMU_FLAGS, Platform, compile_shared_library, fmu_binary_path
from ..errors import AssetError

__all__ = ["fmi_include_dir", "write_zip", "token_from", "build_fmu_archive", "COMMON_FILES"]

#: Files of fmus/common that every FMU needs, by FMI version.
COMMON_FILES = {2: ("fmu_model.h", "fmu_instance.h", "fmu_instance.c", "fmi2_functions.c"),
                3: ("fmu_model.h", "fmu_instance.h", "fmu_instance.c", "fmi3_functions.c")}
_ZIP_DATE = (1980, 1, 1, 0, 0, 0)


def fmi_include_dir() -> Path:
    """The FMI 2.0 and 3.0 headers shipped with fmpy (its ``c-code`` folder)."""
    path = Path(fmpy.__file__).resolve().parent / "c-code"
    if not (path / "fmi2Functions.h").exists():
        raise AssetError(f"FMI headers not found in {path} (reinstall fmpy)")
    return path


def token_from(*parts: bytes | str) -> str:
    """A GUID-style token derived from the content (same sources, same token)."""
    digest = hashlib.sha256()
    for part in parts:
        digest.update(part.encode() if isinstance(part, str) else part)
    return "{" + str(uuid.UUID(bytes=digest.digest()[:16])) + "}"


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
                      compiler: str | None = None, platforms: Sequence[Platform] | None = None) -> None:
    """Copy the glue and generated sources, compile for each platform, and pack ``path``.

    ``generated`` maps file names (placed in ``sources/``) to C text; the glue files of
    ``fmus/common`` are added for the FMI version. ``platforms`` (default: this machine's)
    are compiled by :func:`duffid.cbuild.compile_shared_library` (``compiler`` is this
    machine's compiler); pick them with :func:`duffid.cbuild.resolve_platforms`.
    """
    common = fmu_sources("common")
    sources: dict[str, bytes] = {name: (common / name).read_bytes() for name in COMMON_FILES[fmi_version]}
    sources.update({name: text.encode() for name, text in generated.items()})
    sources.update(extra_sources or {})
    c_files = sorted(n for n in sources if n.endswith(".c"))
    with tempfile.TemporaryDirectory(prefix="duffid-fmu-") as tmp:
        src = Path(tmp) / "sources"
        src.mkdir()
        for name, data in sources.items():
            (src / name).write_bytes(data)
        files = {"modelDescription.xml": model_description}
        for platform in platforms or [None]:
            inside = fmu_binary_path(model_identifier, fmi_version, platform)
            binary = Path(tmp) / inside
            compile_shared_library([src / name for name in c_files], binary, include_dirs=[src, fmi_include_dir()],
                                   flags=FMU_FLAGS, compiler=compiler, platform=platform)
            files[inside] = binary.read_bytes()
        files.update({f"sources/{name}": data for name, data in sources.items()})
        write_zip(files, path)
