"""Modelica plant library and its export to FMUs (FMI 2.0 and 3.0, Model Exchange and Co-Simulation).

The library ``modelica/Duffid`` holds translational and electrical components and the
example plants of :data:`EXAMPLE_PLANTS`. :func:`export_fmu` translates a Modelica model
into an FMU with its C sources inside::

    from duffid.modelica.export import export_fmu, library_path
    export_fmu(library_path(), "Duffid.Examples.Oscillator1DOF", "build/fmus/Oscillator1DOF.fmu")

The chain: pymoca parses and flattens the model, CasADi holds the equations, duffid's
own causalisation, index reduction and tearing turn the DAE into an ODE
(:mod:`duffid.modelica.causalize`), CasADi generates C code for it and the shared FMI
glue of ``fmus/common`` (state machine, argument checks, embedded Dormand-Prince 5(4)
integrator for co-simulation, FMU state) wraps it. Events, ``when``, algorithms and other
constructs outside the continuous subset raise :class:`ModelicaExportError` naming the
construct, class and line.

:func:`build_all` and the ``duffid build-fmus`` subcommand (:mod:`duffid.cli.build_fmus`) build
every example plant as ``<Name>.fmu`` (FMI 2.0) and ``<Name>_fmi3.fmu`` (FMI 3.0). If OpenModelica's ``omc`` is on PATH,
:func:`export_fmu_omc` offers the alternative export through OpenModelica (optional).
"""
from __future__ import annotations

import shutil
import subprocess
import tempfile
from pathlib import Path
from typing import Iterable, Mapping, Sequence

from ..assets import EXAMPLE_PLANTS, modelica_library
from ..cbuild import Platform
from ..errors import InputError, ModelicaExportError
from ..fmu.fmi_xml import FmuInfo, build_description, model_description_fmi2, model_description_fmi3
from ..fmu.package import COMMON_FILES, build_fmu_archive, token_from
from .causalize import OdeModel, causalize
from .codegen import casadi_source, model_source
from .flat_model import flatten_model
from .table import variable_table

__all__ = [
    "EXAMPLE_PLANTS",  # (from duffid.assets)
    "KINDS",
    "ModelicaExportError",
    "library_path",
    "translate",
    "export_fmu",
    "export_fmu_omc",
    "build_all",
    "DEFAULT_TOLERANCE",
]

#: FMU interface kinds: Model Exchange, Co-Simulation or both in one FMU.
KINDS: tuple[str, ...] = ("both", "me", "cs")
#: Co-simulation tolerance without fmi2SetupExperiment / fmi3EnterInitializationMode.
DEFAULT_TOLERANCE = 1e-8


def library_path() -> Path:
    """The ``Duffid`` Modelica package directory (duffid's package data)."""
    return modelica_library()


def translate(mo_path: Path | str | Iterable[Path | str], class_name: str, *,
              structural_parameters: Mapping[str, int | bool] | None = None) -> OdeModel:
    """Flatten and causalise a Modelica model (the export without code generation).

    Parameters
    ----------
    mo_path : path or sequence of paths
        Modelica package directories and/or ``.mo`` files.
    class_name : str
        Full class name, e.g. ``"Duffid.Examples.DuffingCircuit"``.
    structural_parameters : mapping, optional
        Values of Integer/Boolean parameters of the class that fix its structure, e.g.
        ``{"n": 5}`` for ``ChainNDOF``.

    Returns
    -------
    OdeModel
        States, inputs, parameters, computed variables and the CasADi function of the ODE.
    """
    return causalize(flatten_model(mo_path, class_name, structural_parameters))


def _model_identifier(class_name: str) -> str:
    return class_name.rsplit(".", 1)[-1]


def export_fmu(mo_path: Path | str | Iterable[Path | str], class_name: str, out: Path | str,
               fmi_version: int = 2, kind: str = "both", *, tolerance: float = DEFAULT_TOLERANCE,
               structural_parameters: Mapping[str, int | bool] | None = None, compiler: str | None = None,
               platforms: Sequence[Platform] | None = None) -> Path:
    """Export a Modelica model as an FMU with sources.

    Parameters
    ----------
    mo_path : path or sequence of paths
        Modelica package directories and/or ``.mo`` files (e.g. :func:`library_path`).
    class_name : str
        Full name of the model.
    out : path
        The ``.fmu`` file to write, or a directory (created if missing; then ``<Name>.fmu``
        for FMI 2 and ``<Name>_fmi3.fmu`` for FMI 3 inside it).
    fmi_version : {2, 3}
        FMI version.
    kind : {"both", "me", "cs"}
        Model Exchange and Co-Simulation in one FMU, or only one of them.
    tolerance : float
        Default relative tolerance of the embedded co-simulation integrator (used when the
        importer does not pass one to fmi2SetupExperiment / fmi3EnterInitializationMode).
    structural_parameters : mapping, optional
        Integer/Boolean parameters fixed at export, e.g. ``{"n": 5}`` for ``ChainNDOF``.
    compiler : str
        C compiler; default: the one :func:`duffid.cbuild.find_compiler` finds.
    platforms : sequence of Platform, optional
        Targets of the binaries (default: this machine; e.g.
        ``duffid.cbuild.resolve_platforms(["linux64", "win64"])[0]``).

    Returns
    -------
    Path
        The FMU written.

    Raises
    ------
    ModelicaExportError
        Unsupported constructs (naming construct, class and line), translation or
        compilation failures. No FMU is written then.
    """
    _check_options(fmi_version, kind, tolerance)
    ode = translate(mo_path, class_name, structural_parameters=structural_parameters)
    return _write_fmu(ode, Path(out), fmi_version, kind, tolerance, compiler, platforms)


def _check_options(fmi_version: int, kind: str, tolerance: float) -> None:
    if fmi_version not in (2, 3):
        raise InputError(f"fmi_version must be 2 or 3, got {fmi_version!r}")
    if kind not in KINDS:
        raise InputError(f"kind must be one of {KINDS}, got {kind!r}")
    if not (tolerance > 0):
        raise InputError(f"tolerance must be positive, got {tolerance!r}")


def _write_fmu(ode: OdeModel, out: Path, fmi_version: int, kind: str, tolerance: float, compiler: str | None,
               platforms: Sequence[Platform] | None = None) -> Path:
    """Generate, compile and pack the FMU of a translated model."""
    class_name = ode.flat.class_name
    identifier = _model_identifier(class_name)
    if out.suffix != ".fmu":  # a directory
        out = out / (f"{identifier}.fmu" if fmi_version == 2 else f"{identifier}_fmi3.fmu")
    table = variable_table(ode)
    equations_c = casadi_source(ode)
    token = token_from(f"fmi{fmi_version}", kind, class_name, equations_c,
                       *[f"{v.name}|{v.causality}|{v.start}|{v.unit}" for v in table])
    generated = {"model.c": model_source(ode, table, identifier, token, tolerance,
                                         model_exchange=kind in ("both", "me"),
                                         co_simulation=kind in ("both", "cs")),
                 "model_casadi.c": equations_c}
    c_sources = tuple(sorted([n for n in COMMON_FILES[fmi_version] if n.endswith(".c")] + list(generated)))
    flat = ode.flat
    info = FmuInfo(model_name=class_name, model_identifier=identifier, token=token,
                   description=flat.description, sources=c_sources, model_exchange=kind in ("both", "me"),
                   co_simulation=kind in ("both", "cs"), experiment=flat.experiment)
    if fmi_version == 2:
        description = model_description_fmi2(info, table)
        extra = {}
    else:
        description = model_description_fmi3(info, table)
        extra = {"buildDescription.xml": build_description(identifier, c_sources)}
    build_fmu_archive(out, identifier, fmi_version, description, generated, extra, compiler, platforms)
    return out


def export_fmu_omc(mo_path: Path | str, class_name: str, out_dir: Path | str, fmi_version: int = 2,
                   kind: str = "both") -> Path:
    """Optional alternative: export through OpenModelica's ``omc`` (when installed).

    Runs ``loadFile`` and ``buildModelFMU`` in ``omc``; the FMU is OpenModelica's own
    (its runtime, solvers and event handling), not duffid's translation.

    Raises
    ------
    ModelicaExportError
        When ``omc`` is not on PATH or the export fails.
    """
    omc = shutil.which("omc")
    if omc is None:
        raise ModelicaExportError("OpenModelica's omc is not on PATH; use export_fmu instead")
    fmu_type = {"both": "me_cs", "me": "me", "cs": "cs"}[kind]
    path = Path(mo_path)
    package = path / "package.mo" if path.is_dir() else path
    out_dir = Path(out_dir).resolve()
    out_dir.mkdir(parents=True, exist_ok=True)
    script = (f'loadFile("{package.resolve().as_posix()}"); getErrorString();\n'
              f'buildModelFMU({class_name}, version="{fmi_version}.0", fmuType="{fmu_type}"); '
              "getErrorString();\n")
    with tempfile.TemporaryDirectory() as tmp:
        mos = Path(tmp) / "export.mos"
        mos.write_text(script)
        done = subprocess.run([omc, str(mos)], capture_output=True, text=True, cwd=out_dir)
    result = out_dir / f"{class_name}.fmu"
    if done.returncode != 0 or not result.exists():
        raise ModelicaExportError(f"omc failed to export {class_name}:\n{done.stdout}\n{done.stderr}")
    return result


def build_all(out_dir: Path | str = Path("build/fmus"), plants: Sequence[str] = EXAMPLE_PLANTS,
              platforms: Sequence[Platform] | None = None) -> list[Path]:
    """Build every example plant as ``<Name>.fmu`` (FMI 2.0) and ``<Name>_fmi3.fmu`` (FMI 3.0).

    Both contain Model Exchange and Co-Simulation and their C sources.

    Parameters
    ----------
    out_dir : path
        Output folder (created if missing).
    plants : sequence of str
        Names of classes in ``Duffid.Examples`` (default: all of :data:`EXAMPLE_PLANTS`).
    platforms : sequence of Platform, optional
        Targets of the binaries (default: this machine; see :func:`duffid.cbuild.resolve_platforms`).

    Returns
    -------
    list of Path
        The FMUs written, FMI 2 and FMI 3 for each plant.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    library = library_path()
    written = []
    for name in plants:
        if name not in EXAMPLE_PLANTS:
            raise InputError(f"unknown plant {name!r}; choose from {EXAMPLE_PLANTS}")
        ode = translate(library, f"Duffid.Examples.{name}")
        for version in (2, 3):
            written.append(_write_fmu(ode, out_dir, version, "both", DEFAULT_TOLERANCE, None, platforms))
    return written
