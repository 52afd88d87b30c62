"""Package data: the C sources of every FMU duffid builds (``fmus/``) and the ``Duffid``
Modelica library (``modelica/``), found through :mod:`importlib.resources`, so the
same code works in a checkout (where these folders are links to the top-level ones)
and in an installed wheel (where they are copies)."""
from __future__ import annotations

from importlib.resources import files
from pathlib import Path

from ..errors import AssetError

__all__ = ["asset_path", "fmu_sources", "modelica_library", "EXAMPLE_PLANTS"]

#: The example plants of the library (``Duffid.Examples``), built by ``duffid build-fmus``.
EXAMPLE_PLANTS: tuple[str, ...] = ("Oscillator1DOF", "Oscillator2DOF", "ChainNDOF", "DuffingCircuit",
                                   "SaturatingCircuit")


def asset_path(*parts: str) -> Path:
    """The file or folder ``parts`` of the package data, as a path on disk.

    Raises
    ------
    AssetError
        If it is missing (an incomplete installation).
    """
    path = Path(str(files(__name__).joinpath(*parts)))
    if not path.exists():
        raise AssetError(f"duffid's package data {'/'.join(parts)} is missing (looked for {path}); "
                         "reinstall duffid")
    return path


def fmu_sources(component: str) -> Path:
    """The C sources of one FMU component: ``common`` (the FMI glue), ``estimator``, ``controller``."""
    return asset_path("fmus", component)


def modelica_library() -> Path:
    """The ``Duffid`` Modelica package directory."""
    return asset_path("modelica", "Duffid")
