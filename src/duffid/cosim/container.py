"""Export a :class:`duffid.cosim.system.System` as one container FMU (fmpy's ``container_fmu``).

The container is an FMI 2.0 Co-Simulation FMU whose binary (shipped with fmpy) runs the
components it holds in ``resources/``: a Jacobi master at a fixed internal step, the
same algorithm as :meth:`duffid.cosim.system.System.run` with ``ordering="jacobi"``. Its
``doStep`` accepts a whole multiple of that step only (so
``canHandleVariableCommunicationStepSize`` is false). Container variables carry the units
of the component variables they map to (one unit per container variable, else an error).

What is exported:

* every component and every connection of the system;
* container inputs: each maps to one or more component inputs
  (``inputs={"r": ["controller.r"], "f": ["plant.f", "estimator.f"]}``);
* container outputs: each maps to one component output (``outputs={"x": "plant.x"}``);
* parameters: every parameter value given to :meth:`~duffid.cosim.system.System.add` becomes a
  container parameter named ``"component.parameter"`` whose start value is that value
  (the container sets start values into its components before initialisation, so the
  values take effect, and an importer may change them); ``parameters={"mass":
  ["plant.m"]}`` exposes further component parameters (start: the add() value or the
  component's own start) under names of your choice.

The states evolve exactly as under ``System.run(ordering="jacobi")`` (the tests check
equality to 1e-12). One difference in what is *read*: after each internal step the
container passes the new outputs to the connected inputs before its own outputs are
read, so an output with direct feedthrough from a connected input (e.g. a gain
``y = k u``) shows ``k u(t_{k+1})``, where :meth:`~duffid.cosim.system.System.run` records the
value returned right after ``doStep`` (``k u(t_k)``). Outputs without direct
feedthrough (states, the estimator's and controller's sampled outputs) are identical.

External inputs of the system (:meth:`~duffid.cosim.system.System.set_input`) cannot be part of
the container: every input they drive must be mapped to a container input (else
:class:`~duffid.errors.WiringError`). Inputs that are neither connected nor driven keep
their start values.

The container carries fmpy's container binaries only for the platforms on which every
component has a binary (fmpy ships linux64, win64 and darwin64 ones); none in common is an
error.

Two defects of fmpy 0.3.32 are worked around: connections of FMI 2 components are
written with their FMI 2 type names, which the container binary rejects, so the
connection variables are passed as copies typed ``Float64``/``Int32`` (Boolean needs
no change); and the generated modelDescription has no ModelStructure, so outputs and
initial unknowns are filled in (``fmpy validate`` then reports no problems).

FMI 3.0 components are accepted by the container format; the container itself is
always FMI 2.0.
"""
from __future__ import annotations

import os
import shutil
import tempfile
import uuid
import zipfile
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Sequence

from ..errors import WiringError
from .elements import VARIABLE_KINDS, with_article

if TYPE_CHECKING:
    from .system import System

__all__ = ["export_container"]

_FMI2_TYPE = {"Real": "Real", "Integer": "Integer", "Boolean": "Boolean"}
_CONTAINER_TYPE = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean"}


def _literal(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    return str(value)


def _as_list(value: str | Sequence[str], what: str) -> list[str]:
    items = [value] if isinstance(value, str) else list(value)
    if not items:
        raise WiringError(f"{what}: maps to no component variable")
    return items


def _one_unit(variables: Sequence[Any], what: str) -> str | None:
    """The unit shared by the component ``variables`` a container variable maps to."""
    units = {v.unit for v in variables if v.unit}
    if len(units) > 1:
        raise WiringError(f"{what} maps to variables of different units: {', '.join(sorted(map(str, units)))}")
    return units.pop() if units else None


def _unit_definitions(names: set[str], descriptions: Sequence[Any]) -> list[Any]:
    """The components' definitions of the units ``names`` (a unit no component defines is
    declared by its name alone)."""
    from fmpy.model_description import Unit

    defined: dict[str, Any] = {}
    for md in descriptions:
        for unit in md.unitDefinitions:
            defined.setdefault(unit.name, unit)
    return [defined.get(name) or Unit(name=name) for name in sorted(names)]


def export_container(system: System, path: str | os.PathLike[str],
                     inputs: Mapping[str, str | Sequence[str]] | None = None,
                     outputs: Mapping[str, str] | None = None, step: float = 1e-3,
                     parameters: Mapping[str, str | Sequence[str]] | None = None) -> Path:
    """Write ``system`` as one FMI 2.0 co-simulation container FMU.

    Parameters
    ----------
    system : System
        Components and connections to export.
    path : str or os.PathLike
        The ``.fmu`` file to write (overwritten).
    inputs : mapping, optional
        Container input name -> component input(s) it drives (``"comp.var"`` or a list).
        The inputs must not be connected inside the system; their start value is that of
        the first component input.
    outputs : mapping, optional
        Container output name -> component output (``"comp.var"``). Default: every
        output of every component, named ``"comp.var"``.
    step : float
        The container's fixed internal step (its master is Jacobi at this step).
    parameters : mapping, optional
        Container parameter name -> component parameter(s), in addition to the
        ``"comp.param"`` parameters made for the values given to ``add()``.

    Returns
    -------
    Path
        The FMU written.

    Raises
    ------
    WiringError
        Unknown or ill-typed variables, bad names, an input both connected and exported,
        mixed types in one mapping, types the container cannot carry.
    """
    from fmpy import read_model_description
    from fmpy.container_fmu.cli import create_container_fmu
    from fmpy.container_fmu.config import Component, Configuration, Connection
    from fmpy.model_description import CoSimulation, DefaultExperiment, ModelDescription, ModelVariable, Unknown

    if not system._components:
        raise WiringError("the system has no components")
    if not (isinstance(step, (int, float)) and step > 0):
        raise WiringError(f"step must be a positive number, got {step!r}")
    path = Path(path)
    work = Path(tempfile.mkdtemp(prefix="duffid-container-"))
    try:
        # component FMUs copied under their component names: resources/<name>/ is unique
        components: dict[str, Any] = {}
        for name, comp in system._components.items():
            copy = work / "fmus" / f"{name}.fmu"
            copy.parent.mkdir(exist_ok=True)
            shutil.copyfile(comp.path, copy)
            components[name] = Component(name=name, filename=copy, modelDescription=read_model_description(str(copy)))

        def resolve(full: str, role: str) -> tuple[Any, Any, str]:
            comp, var = system._lookup(full, role)
            kind = comp.kind(var, "exported")
            md_var = next(v for v in components[comp.name].modelDescription.modelVariables if v.name == var.name)
            return components[comp.name], md_var, kind

        def container_copy(var: Any, kind: str) -> Any:
            # workaround 1: the binary expects FMI 3 type names (Float64, Int32)
            from attrs import evolve

            return evolve(var, type=_CONTAINER_TYPE[kind])

        # the binary numbers its variables from value reference 1: 0 is the time
        variables: list[Any] = [ModelVariable(name="time", valueReference=0, type="Real", causality="independent",
                                              variability="continuous", description="simulation time")]
        mappings: dict[Any, list[tuple[Any, Any]]] = {}
        used: set[str] = {"time"}

        def new_variable(name: str, kind: str, causality: str, variability: str, initial: str | None,
                         start: str | None, description: str, unit: str | None = None) -> Any:
            if not name or name in used:
                raise WiringError(f"container variable name {name!r} is empty or used twice")
            used.add(name)
            v = ModelVariable(name=name, valueReference=len(variables), type=_FMI2_TYPE[kind], causality=causality,
                              variability=variability, initial=initial, description=description)
            v.start = start
            v.unit = unit if kind == "Real" else None
            variables.append(v)
            return v

        connected = {c.target for c in system._connections}
        for name, targets in (inputs or {}).items():
            entries = []
            for full in _as_list(targets, f"container input {name!r}"):
                comp, var = system._lookup(full, "container input target")
                if var.causality != "input":
                    raise WiringError(f"container input {name!r}: {full} is {with_article(var.causality)}, not an input")
                if full in connected:
                    raise WiringError(f"container input {name!r}: {full} is already connected inside the system")
                entries.append(resolve(full, "container input target"))
            kinds = {e[2] for e in entries}
            if len(kinds) != 1:
                raise WiringError(f"container input {name!r} maps to variables of different types")
            kind = kinds.pop()
            start = entries[0][1].start
            v = new_variable(name, kind, "input", "discrete" if kind != "Real" else "continuous", None,
                             start if start is not None else ("false" if kind == "Boolean" else "0"),
                             f"drives {', '.join(_as_list(targets, name))}",
                             _one_unit([m for _, m, _ in entries], f"container input {name!r}"))
            mappings[v] = [(c, m) for c, m, _ in entries]
        exported = {full for targets in (inputs or {}).values() for full in _as_list(targets, "container input")}
        lost = sorted(set(system._externals) - exported)
        if lost:
            raise WiringError(f"{', '.join(lost)} {'is' if len(lost) == 1 else 'are'} driven by the system's external "
                              "inputs (set_input, inputs_from_csv), which a container cannot hold: map "
                              f"{'it' if len(lost) == 1 else 'them'} to container inputs")
        if outputs is None:
            outputs = {f"{c.name}.{v.name}": f"{c.name}.{v.name}" for c in system._components.values()
                       for v in c.outputs()}
        out_vars = []
        for name, source in outputs.items():
            if not isinstance(source, str):
                raise WiringError(f"container output {name!r} must map to one 'component.output'")
            comp, var = system._lookup(source, "container output source")
            if var.causality != "output":
                raise WiringError(f"container output {name!r}: {source} is {with_article(var.causality)}, not an output")
            c, m, kind = resolve(source, "container output source")
            v = new_variable(name, kind, "output", "continuous" if kind == "Real" else "discrete", "calculated",
                             None, f"output {source}", m.unit)
            mappings[v] = [(c, m)]
            out_vars.append(v)
        exposed: dict[str, list[str]] = {name: _as_list(t, f"container parameter {name!r}")
                                        for name, t in (parameters or {}).items()}
        covered = {full for targets in exposed.values() for full in targets}
        for comp in system._components.values():
            for pname in comp.parameters:
                full = f"{comp.name}.{pname}"
                if full not in covered:
                    exposed[full] = [full]
        for name, targets in exposed.items():
            entries, starts = [], []
            for full in targets:
                comp, var = system._lookup(full, "container parameter target")
                if var.causality != "parameter" or var.variability not in ("fixed", "tunable"):
                    raise WiringError(f"container parameter {name!r}: {full} is {with_article(var.causality)} "
                                      f"({var.variability}), not a settable parameter")
                if var.type not in VARIABLE_KINDS:
                    raise WiringError(f"container parameter {name!r}: {full} has type {var.type}; the container "
                                      "carries Real, Integer and Boolean parameters only")
                entries.append(resolve(full, "container parameter target"))
                given = comp.parameters.get(var.name)
                starts.append(_literal(given) if given is not None else var.start)
            kinds = {e[2] for e in entries}
            if len(kinds) != 1:
                raise WiringError(f"container parameter {name!r} maps to variables of different types")
            kind = kinds.pop()
            if len(set(starts)) != 1:
                raise WiringError(f"container parameter {name!r}: its targets have different values {starts}")
            v = new_variable(name, kind, "parameter", "fixed", "exact", starts[0],
                             f"sets {', '.join(targets)}",
                             _one_unit([m for _, m, _ in entries], f"container parameter {name!r}"))
            mappings[v] = [(c, m) for c, m, _ in entries]

        connections = []
        for conn in system._connections:
            sc, sv, kind = resolve(conn.source, "source")
            tc, tv, _ = resolve(conn.target, "target")
            connections.append(Connection(startElement=sc, startConnectors=[container_copy(sv, kind)],
                                          endElement=tc, endConnectors=[tv]))

        md = ModelDescription(fmiVersion="2.0", modelName=path.stem, instantiationToken="{" + str(uuid.uuid4()) + "}",
                              description=f"duffid co-simulation container: {', '.join(system._components)} "
                                          f"(Jacobi, fixed step {step!r} s)",
                              generationTool="duffid.cosim.system + fmpy.container_fmu",
                              coSimulation=CoSimulation(modelIdentifier="container_fmu",
                                                        canHandleVariableCommunicationStepSize=False,
                                                        fixedInternalStepSize=float(step)),
                              defaultExperiment=DefaultExperiment(startTime="0", stepSize=repr(float(step))))
        md.modelVariables = variables
        md.unitDefinitions = _unit_definitions({v.unit for v in variables if v.unit},
                                               [c.modelDescription for c in components.values()])
        # workaround 2: ModelStructure (outputs are initial unknowns too)
        md.outputs = [Unknown(variable=v) for v in out_vars]
        md.initialUnknowns = [Unknown(variable=v) for v in out_vars]
        config = Configuration(parallelDoStep=False, modelDescription=md, components=list(components.values()),
                               connections=connections, variableMappings=mappings)
        unzipdir = work / "container"
        unzipdir.mkdir()
        built = work / "Container.fmu"
        create_container_fmu(config, unzipdir, built)
        _finish_archive(built, list(components))
        path.parent.mkdir(parents=True, exist_ok=True)
        shutil.move(str(built), str(path))
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return path


#: The container binary's platform folder -> the component folders (FMI 2, FMI 3) it can load.
_CONTAINER_PLATFORMS = {"linux64": {"linux64", "x86_64-linux"}, "win64": {"win64", "x86_64-windows"},
                        "darwin64": {"darwin64", "x86_64-darwin", "aarch64-darwin"}}


def _finish_archive(fmu: Path, components: Sequence[str]) -> None:
    """Drop a half-written copy of the archive that ``shutil.make_archive`` may have put
    inside itself (fmpy writes the zip into the directory it archives), and the container
    binaries of platforms for which a component has no binary (the container would load
    there and then fail to load that component).

    Raises
    ------
    WiringError
        If no platform has binaries of every component.
    """
    with zipfile.ZipFile(fmu) as z:
        names = z.namelist()
        folders = {name: {n.split("/")[3] for n in names if n.startswith(f"resources/{name}/binaries/")
                          and n.count("/") >= 4} for name in components}
        keep = {p for p, accepted in _CONTAINER_PLATFORMS.items() if all(folders[c] & accepted for c in components)}
        if not keep:
            raise WiringError("no platform has binaries of every component: "
                              + "; ".join(f"{c}: {', '.join(sorted(f)) or 'none'}" for c, f in folders.items()))

        def wanted(name: str) -> bool:
            parts = name.split("/")
            return not name.endswith("Container.zip") and not (
                parts[0] == "binaries" and len(parts) > 1 and parts[1] and parts[1] not in keep)

        if all(wanted(n) for n in names):
            return
        entries = [(info, z.read(info)) for info in z.infolist() if wanted(info.filename)]
    with zipfile.ZipFile(fmu, "w", zipfile.ZIP_DEFLATED) as z:
        for info, data in entries:
            z.writestr(info, data)
