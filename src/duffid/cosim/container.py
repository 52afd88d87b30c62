"""Export a :class:`duffid.cosim.system.System` as one container FMU on duffid's own runtime.

The container is an FMI 2.0 or 3.0 Co-Simulation FMU whose binary is duffid's container runtime
(``fmus/container``) on the shared FMI glue (``fmus/common``), compiled for this container:
its description (variables, components, connections, the container variables' mapping,
the internal step) is a generated C header, so nothing is parsed when it runs. The
components' FMUs (FMI 2 or FMI 3 co-simulation) are unpacked in ``resources/<component>/``;
at instantiation the runtime loads each binary, resolves its FMI functions and makes one
instance (every failure logged through the container's logger, naming the component and
its FMU: a binary that does not load, an instantiation that fails, a call that returns an
error).

Its ``doStep`` runs the Jacobi master of :meth:`duffid.cosim.system.System.run` with
``ordering="jacobi"`` at a fixed internal step, with the orchestrator's own compiled loop
(``fmus/cosim/duffid_cosim_loop.c``); it accepts a whole multiple of that step only (so
``canHandleVariableCommunicationStepSize`` is false). Container variables carry the units
and the descriptions of the component variables they map to (one unit per container
variable, else an error), with the components' unit definitions.

What is exported:

* every component and every connection of the system: connections of every FMI type
  (Float64/Real, Float32, Int8 .. UInt64, Integer/Int32, Boolean, Enumeration (FMI 2 <-> FMI 3 too),
  String and Binary, copied into memory the container owns), whole arrays included; a connection
  into one element of an array input is refused by name (System.run handles it);
* container inputs: each maps to one or more component inputs
  (``inputs={"r": ["controller.r"], "f": ["plant.f", "estimator.f"]}``);
* container outputs: each maps to one component output (``outputs={"x": "plant.x"}``);
  the container's own variables are scalar Real/Float64, Integer/Int32 and Boolean (the shared
  FMI glue's types; anything else is refused by name);
* parameters: every parameter value given to :meth:`~duffid.cosim.system.System.add` becomes a
  container parameter named ``"component.parameter"`` whose start value is that value
  (the container sets its parameters into its components before their initialisation, so
  the values take effect, and an importer may change them); ``parameters={"mass":
  ["plant.m"]}`` exposes further component parameters (start: the add() value or the
  component's own start) under names of your choice. A value given to add() that the
  container cannot expose as its own variable (a structural parameter, an array, a type other
  than Real/Float64, Integer/Int32 and Boolean) is fixed in it instead: set into its component
  before initialisation, a structural parameter in Configuration Mode.

The states evolve exactly as under ``System.run(ordering="jacobi")`` (the tests check
equality to 1e-12): the components are set up, given their parameters and initialised as
the orchestrator does (connected inputs start from zero during initialisation), then every
internal step calls every doStep with the inputs held, reads every connected output and
sets every connected input. One difference in what is *read*: the container's outputs are
read from its components after its step, when the connected inputs already hold the new
values, so an output with direct feedthrough from a connected input (e.g. a gain
``y = k u``) shows ``k u(t_{k+1})``, where :meth:`~duffid.cosim.system.System.run` records the
value returned right after ``doStep`` (``k u(t_k)``). Outputs without direct
feedthrough (states, the estimator's and controller's sampled outputs) are identical.

External inputs of the system (:meth:`~duffid.cosim.system.System.set_input`) cannot be part of
the container: every input they drive must be mapped to a container input (else
:class:`~duffid.errors.WiringError`). Inputs that are neither connected nor driven keep
their start values.

The container has binaries for the platforms (:data:`duffid.cbuild.PLATFORMS`) on which
every component has a binary and a compiler is installed; none is an error. It cannot save
its state (``canGetAndSetFMUstate`` false: the state functions are refused with a logged
error). A component that fails during a step discards the container's step: its time and
variables stay those of the step's start, and only terminate, reset or free may follow
(the components cannot be rolled back). A component asking to end the simulation (FMI 2:
``Discard`` with ``fmi2Terminated``; FMI 3: ``terminateSimulation``, with ``earlyReturn`` when it
stopped inside its step) ends the container's step within that internal step: the other components
complete it, the container's outputs are read then, and the container asks to end the simulation
as an FMI 2 FMU does (``Discard``, ``fmi2GetBooleanStatus(fmi2Terminated)`` true,
``fmi2LastSuccessfulTime`` the earliest time reached by a component that asked), which fmpy and
:meth:`~duffid.cosim.system.System.run` take as the end of the run. The container ignores a tolerance given to it (its components use
their own, as under the orchestrator). An FMI 3 component that declares ``hasEventMode`` runs with
Event Mode as under the orchestrator: its events are handled after the internal step in which it
asks (``updateDiscreteStates`` until settled), and after its initialisation.
"""
from __future__ import annotations

import ctypes
import itertools
import math
import os
import re
import tempfile
import xml.etree.ElementTree as ET
import zipfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..assets import fmu_sources
from ..cbuild import (
    FMU_FLAGS,
    Platform,
    compile_shared_library,
    fmu_binary_path,
    resolve_platforms,
)
from ..errors import WiringError
from ..fmu.c_model import config_header, retype
from ..fmu.fmi_xml import FmuInfo, model_description_fmi2, model_description_fmi3
from ..fmu.package import COMMON_FILES, fmi_include_dir, token_from, write_zip
from ..fmu.variables import FmuVariable
from .elements import WiredSystem, with_article
from .value_types import FMI_FUNCTIONS

__all__ = ["CONTAINER_GENERATION_TOOL", "RUNTIME_FILES", "export_container", "carried_kind"]

#: generationTool of container FMUs.
CONTAINER_GENERATION_TOOL = "duffid.cosim.container (duffid's container runtime, fmus/container)"
#: The runtime's sources, by folder of ``fmus/`` (the glue's FMI 2 files are added).
RUNTIME_FILES = {"container": ("duffid_container.c", "duffid_container.h"),
                 "cosim": ("duffid_cosim_loop.c", "duffid_cosim_loop.h")}
_CONFIG = "container_fmu_config.h"
#: The container's type of each component variable kind (fmus/common VARTYPE_* names): what its own
#: variables (inputs, outputs, parameters) can be.
_GLUE_TYPE = {"Real": "Float64", "Integer": "Integer", "Boolean": "Boolean"}
#: The kinds of the connections inside the container, in the order of their codes (the first three
#: are the glue's VARTYPE_* codes): per FMI version the get and set functions and the bytes of one
#: value they exchange (None: the version has no such type); the container's buffer of a kind
#: holds values of the first size given (Boolean as int32, Enumeration as int64).
_KINDS = ("Real", "Integer", "Boolean", "Float32", "Int8", "UInt8", "Int16", "UInt16", "UInt32", "Int64", "UInt64",
          "Enumeration", "String", "Binary")
#: C expressions of the bytes per value of each kind's buffer (String: an owned copy, Binary: its
#: size and an owned copy of its bytes).
_BUFFER_SIZES = {"Real": "8", "Integer": "4", "Boolean": "4", "Float32": "4", "Int8": "1", "UInt8": "1", "Int16": "2",
                 "UInt16": "2", "UInt32": "4", "Int64": "8", "UInt64": "8", "Enumeration": "8",
                 "String": "sizeof(char *)", "Binary": "sizeof(ContainerBinary)"}


@dataclass
class _Variable:
    """One container variable and the component variables it maps to."""

    name: str
    kind: str                      # Real, Integer, Boolean
    causality: str                 # input, output, parameter
    start: str | None
    description: str
    unit: str | None
    links: list[tuple[int, int, str]] = field(default_factory=list)  # (component index, vr, "comp.var")


def _literal(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    return str(value)


def _number(start: str | None, kind: str) -> float | None:
    """A start attribute as the double the glue stores (Booleans 0/1)."""
    if start is None:
        return None
    if kind == "Boolean":
        return 1.0 if str(start).strip().lower() in ("true", "1") else 0.0
    return float(start)


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


def _describe(what: str, variables: Sequence[Any], targets: Sequence[str]) -> str:
    """``what`` (e.g. "drives plant.f") and the component variables' own descriptions."""
    own = list(dict.fromkeys(v.description for v in variables if v.description))
    return f"{what} {', '.join(targets)}" + (f": {'; '.join(own)}" if own else "")


def _c_string(text: str) -> str:
    """``text`` as a C string literal (UTF-8; quotes, backslashes and non-printables escaped)."""
    out = []
    for byte in text.encode("utf-8"):
        ch = chr(byte)
        if ch in '"\\?':
            out.append("\\" + ch)
        elif 32 <= byte < 127:
            out.append(ch)
        else:
            out.append(f"\\{byte:03o}")
    return '"' + "".join(out) + '"'


def _identifier(stem: str) -> str:
    """The container's modelIdentifier (its binary's name) from the file's stem."""
    ident = re.sub(r"\W", "_", stem, flags=re.ASCII) or "container"
    return ident if not ident[0].isdigit() else "_" + ident


def carried_kind(comp: Any, var: Any, role: str, inside: bool = False) -> str:
    """The kind of a component variable the container exchanges, or WiringError naming the
    component, its FMU, the variable and why. Its own variables (inputs, outputs, parameters: the
    shared FMI glue holds doubles) are scalar Real/Float64, Integer/Int32 and Boolean; connections
    ``inside`` it carry every type (String and Binary values copied into memory the container
    owns) and arrays."""
    kind = comp.kind(var, "exported")
    if inside and kind in _KINDS:
        return kind
    if kind not in _GLUE_TYPE or var.dimensions:
        what = f"an array of {var.type}" if var.dimensions else var.type
        carried = ("scalar Real/Float64, Integer/Int32 and Boolean values as its own variables; the other types "
                   "(arrays too) in its connections only")
        raise WiringError(f"{role} {comp.where()}: {var.name} is {what}; the container runtime carries {carried} "
                          "(run the system with System.run, or leave the variable out of the container)")
    return kind


@dataclass
class _Setting:
    """A parameter value given to ``System.add`` that the container cannot expose as its own
    variable (a structural parameter, an array, a type other than the glue's): fixed in it, set
    before initialisation (a structural one in Configuration Mode)."""

    index: int                     # the component's
    component: Any
    variable: Any
    value: Any                     # as typed_parameter returns it (an array: a flat list)


def _plan(system: WiredSystem, inputs: Mapping[str, str | Sequence[str]] | None, outputs: Mapping[str, str] | None,
          parameters: Mapping[str, str | Sequence[str]] | None) -> tuple[list[_Variable], list[_Setting]]:
    """The container variables, checked (WiringError for anything the container cannot carry), and
    the parameter values fixed in it."""
    order = {name: i for i, name in enumerate(system.wiring.components)}
    variables: list[_Variable] = []
    settings: list[_Setting] = []
    used: set[str] = {"time"}

    def add(var: _Variable) -> _Variable:
        if not var.name or var.name in used:
            raise WiringError(f"container variable name {var.name!r} is empty or used twice")
        used.add(var.name)
        variables.append(var)
        return var

    def find(full: str, role: str) -> tuple[Any, Any]:
        if isinstance(full, str) and "[" in full and system.wiring.channel is not None:  # an array element
            comp, var, _ = system.wiring.channel(full, role)
            raise WiringError(f"{role} {full!r}: {comp.where()}: an element of the array {var.name}; the container's "
                              "own variables map to whole scalar variables (connect the element to a component "
                              "inside, or run the system with System.run)")
        return system.wiring.lookup(full, role)

    def resolve(full: str, role: str) -> tuple[Any, Any, str]:
        comp, var = find(full, role)
        return comp, var, carried_kind(comp, var, role)

    for conn in system.wiring.connections:
        ends = [system.wiring.channel(full, "connection") for full in (conn.source, conn.target)]
        for comp, var, _ in ends:
            carried_kind(comp, var, f"the connection {conn}:", inside=True)
        if ends[1][2] is not None:
            raise WiringError(f"the connection {conn}: the container sets an array input whole; connect the whole "
                              "array, or run the system with System.run")
    connected = {c.target for c in system.wiring.connections}
    for name, targets in (inputs or {}).items():
        entries = []
        for full in _as_list(targets, f"container input {name!r}"):
            comp, var = find(full, "container input target")
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
        full_names = _as_list(targets, name)
        var = add(_Variable(name, kind, "input", start if start is not None else ("false" if kind == "Boolean" else "0"),
                            _describe("drives", [e[1] for e in entries], full_names),
                            _one_unit([e[1] for e in entries], f"container input {name!r}") if kind == "Real" else None))
        var.links = [(order[c.name], v.valueReference, full) for (c, v, _), full in zip(entries, full_names)]
    exported = {full for targets in (inputs or {}).values() for full in _as_list(targets, "container input")}
    lost = sorted(set(system.wiring.externals) - exported)
    if lost:
        raise WiringError(f"{', '.join(lost)} {'is' if len(lost) == 1 else 'are'} driven by the system's external "
                          "inputs (set_input, inputs_from_csv), which a container cannot hold: map "
                          f"{'it' if len(lost) == 1 else 'them'} to container inputs")
    if outputs is None:  # every output; one the container cannot carry is refused by name
        outputs = {f"{c.name}.{v.name}": f"{c.name}.{v.name}" for c in system.wiring.components.values()
                   for v in c.outputs()}
    for name, source in outputs.items():
        if not isinstance(source, str):
            raise WiringError(f"container output {name!r} must map to one 'component.output'")
        comp, var = find(source, "container output source")
        if var.causality != "output":
            raise WiringError(f"container output {name!r}: {source} is {with_article(var.causality)}, not an output")
        comp, var, kind = resolve(source, "container output source")
        out = add(_Variable(name, kind, "output", None, _describe("output", [var], [source]),
                            var.unit if kind == "Real" else None))
        out.links = [(order[comp.name], var.valueReference, source)]
    exposed: dict[str, list[str]] = {name: _as_list(t, f"container parameter {name!r}")
                                    for name, t in (parameters or {}).items()}
    covered = {full for targets in exposed.values() for full in targets}
    for comp in system.wiring.components.values():
        for pname, value in comp.parameters.items():
            full = f"{comp.name}.{pname}"
            var = comp.variables[pname]
            if full in covered:
                continue
            if var.causality == "structuralParameter" or var.dimensions or comp.kind(var, "set") not in _GLUE_TYPE:
                settings.append(_Setting(order[comp.name], comp, var, value))  # fixed in the container
            else:
                exposed[full] = [full]
    for name, targets in exposed.items():
        entries, starts = [], []
        for full in targets:
            comp, var = find(full, "container parameter target")
            if var.causality != "parameter" or var.variability not in ("fixed", "tunable"):
                raise WiringError(f"container parameter {name!r}: {full} is {with_article(var.causality)} "
                                  f"({var.variability}), not a settable parameter")
            entries.append(resolve(full, "container parameter target"))
            given = comp.parameters.get(var.name)
            starts.append(_literal(given) if given is not None else var.start)
        kinds = {e[2] for e in entries}
        if len(kinds) != 1:
            raise WiringError(f"container parameter {name!r} maps to variables of different types")
        kind = kinds.pop()
        if len(set(starts)) != 1:
            raise WiringError(f"container parameter {name!r}: its targets have different values {starts}")
        if starts[0] is None:
            raise WiringError(f"container parameter {name!r}: {targets[0]} has no start value")
        par = add(_Variable(name, kind, "parameter", starts[0], _describe("sets", [e[1] for e in entries], targets),
                            _one_unit([e[1] for e in entries], f"container parameter {name!r}")
                            if kind == "Real" else None))
        par.links = [(order[c.name], v.valueReference, full) for (c, v, _), full in zip(entries, targets)]
    return variables, settings


def _table(variables: list[_Variable]) -> list[FmuVariable]:
    """The glue's variable table: the time at value reference 0, then the container variables."""
    table = [FmuVariable("time", 0, "independent", "continuous", None, None, math.nan,
                         description="simulation time")]
    for i, var in enumerate(variables, start=1):
        variability = {"parameter": "fixed"}.get(var.causality, "continuous" if var.kind == "Real" else "discrete")
        initial = {"output": "calculated", "parameter": "exact"}.get(var.causality)
        start = _number(var.start, var.kind)
        table.append(FmuVariable(var.name, i, var.causality, variability, initial, start,
                                 math.nan if start is None else start, unit=var.unit, description=var.description))
    return table


def _header(system: WiredSystem, variables: list[_Variable], settings: list[_Setting], table: list[FmuVariable],
            identifier: str, token: str, step: float) -> str:
    """The generated container_fmu_config.h: the glue's tables and the container's description."""
    comps = list(system.wiring.components.values())
    order = {c.name: i for i, c in enumerate(comps)}
    types = {v.name: _GLUE_TYPE[v.kind] for v in variables}
    text = config_header("container", table, types, {"IDENTIFIER": identifier, "TOKEN": token})
    text = text.rsplit("#endif", 1)[0]

    def array(ctype: str, name: str, rows: list[str], count: str) -> str:
        body = ",\n    ".join(rows) if rows else "0" if ctype == "intptr_t" else "{0}"  # C has no empty arrays
        return f"#define {count} {len(rows)}\nstatic const {ctype} container_{name}[] = {{\n    {body}\n}};\n"

    component_rows = [f"{{{_c_string(c.name)}, {_c_string(c.path.name)}, "
                      f"{_c_string(c.md.coSimulation.modelIdentifier)}, {c.version}, "
                      f"{_c_string(c.md.guid if c.version == 2 else c.md.instantiationToken)}, "
                      f"{int(c.event_mode)}}}" for c in comps]
    # connection sources: unique variables, sorted by (component, kind); n values each, in the buffer of their kind
    ends = {}
    for conn in system.wiring.connections:
        for full in (conn.source, conn.target):
            comp, var, index = system.wiring.channel(full, "connection")
            ends[full] = (order[comp.name], var.valueReference, _KINDS.index(comp.kind(var, "connected")),
                          comp.size(var), index)
    sources = sorted({ends[c.source][:4] for c in system.wiring.connections}, key=lambda s: (s[0], s[2], s[1]))
    slots, counts = {}, [0] * len(_KINDS)
    for source in sources:
        slots[source] = counts[source[2]]
        counts[source[2]] += source[3]
    # connection targets: one per input variable, each value gathered from a slot of its kind's buffer
    gathers: dict[tuple, list[int]] = {}
    for conn in system.wiring.connections:
        source, target = ends[conn.source], ends[conn.target]
        first = slots[source[:4]] + (source[4] or 0)
        gathers[target[:4]] = [first + i for i in range(target[3])] if source[4] is None and target[4] is None else [first]
    targets = sorted(gathers, key=lambda t: (t[0], t[2], t[1]))
    starts = list(itertools.accumulate([len(gathers[t]) for t in targets], initial=0))
    links = [(vr, comp, cvr, full) for vr, var in enumerate(variables, start=1) for comp, cvr, full in var.links]
    text += (f"\n/* The container's description (duffid_container.h). */\n#define CONTAINER_STEP {float(step)!r}\n"
             + array("ContainerComponent", "components", component_rows, "CONTAINER_N_COMPONENTS")
             + _kind_tables()
             + array("ContainerSource", "sources", [f"{{{c}, {vr}u, {k}, {slots[(c, vr, k, n)]}, {n}}}"
                                                    for c, vr, k, n in sources], "CONTAINER_N_SOURCES")
             + array("ContainerTarget", "targets", [f"{{{c}, {vr}u, {k}, {first}, {len(gathers[(c, vr, k, n)])}}}"
                                                    for (c, vr, k, n), first in zip(targets, starts)],
                     "CONTAINER_N_TARGETS")
             + array("intptr_t", "target_slots", [str(slot) for t in targets for slot in gathers[t]],
                     "CONTAINER_N_TARGET_VALUES")
             + _settings_table(settings)
             + array("ContainerLink", "links", [f"{{{vr}u, {c}, {cvr}u}}" for vr, c, cvr, _ in links],
                     "CONTAINER_N_LINKS")
             + "static const char *const container_link_names[] = {\n    "
             + (",\n    ".join(_c_string(full) for *_, full in links) or '""') + "\n};\n")
    return text + "\n#endif\n"


def _kind_tables() -> str:
    """The C tables of the connection kinds (duffid_container.c reads them): buffer sizes, and per
    FMI version the get/set function names and value sizes (:data:`FMI_FUNCTIONS`)."""
    def names(version: int, which: int) -> str:
        return ", ".join(_c_string(FMI_FUNCTIONS[version][k][which]) if k in FMI_FUNCTIONS[version] else "NULL"
                         for k in _KINDS)

    def sizes(version: int) -> str:
        return ", ".join(str(ctypes.sizeof(FMI_FUNCTIONS[version][k][2])) if k in FMI_FUNCTIONS[version] else "0"
                         for k in _KINDS)

    return (f"#define CONTAINER_N_KINDS {len(_KINDS)}\n#define CONTAINER_KIND_STRING {_KINDS.index('String')}\n"
            f"#define CONTAINER_KIND_BINARY {_KINDS.index('Binary')}\n"
            f"static const size_t container_buffer_size[] = {{{', '.join(_BUFFER_SIZES[k] for k in _KINDS)}}};\n"
            f"static const char *const container_get_names[2][CONTAINER_N_KINDS] = {{{{{names(2, 0)}}}, {{{names(3, 0)}}}}};\n"
            f"static const char *const container_set_names[2][CONTAINER_N_KINDS] = {{{{{names(2, 1)}}}, {{{names(3, 1)}}}}};\n"
            f"static const size_t container_fmi_size[2][CONTAINER_N_KINDS] = {{{{{sizes(2)}}}, {{{sizes(3)}}}}};\n")


#: C types of one value as the FMI set functions take it.
_C_TYPES = {ctypes.c_double: "double", ctypes.c_float: "float", ctypes.c_int: "int", ctypes.c_int8: "int8_t",
            ctypes.c_uint8: "uint8_t", ctypes.c_int16: "int16_t", ctypes.c_uint16: "uint16_t",
            ctypes.c_int32: "int32_t", ctypes.c_uint32: "uint32_t", ctypes.c_int64: "int64_t",
            ctypes.c_uint64: "uint64_t", ctypes.c_bool: "_Bool", ctypes.c_char_p: "const char *"}


def _c_value(kind: str, value: Any) -> str:
    """A C literal of a parameter value (an integer of 64 bits with its suffix, the least Int64 as
    an expression, a String as a string literal)."""
    if kind == "String":
        return _c_string(value)
    if kind in ("Real", "Float32"):
        return repr(float(value))
    number = int(value)
    if number == -2**63:
        return "(-9223372036854775807LL - 1)"
    return f"{number}{'ULL' if kind == 'UInt64' else 'LL' if kind in ('Int64', 'Enumeration') else ''}"


def _settings_table(settings: Sequence[_Setting]) -> str:
    """The parameter values fixed in the container (container_settings, CONTAINER_N_SETTINGS)."""
    arrays, rows = [], []
    for i, s in enumerate(settings):
        kind = s.component.kind(s.variable, "set")
        values = s.value if isinstance(s.value, list) else [s.value]
        sizes = "NULL"
        if kind == "Binary":
            for j, v in enumerate(values):
                arrays.append(f"static const unsigned char container_setting_{i}_{j}[] = "
                              f"{{{', '.join(str(b) for b in v) or '0'}}};")
            arrays.append(f"static const unsigned char *const container_setting_{i}[] = "
                          f"{{{', '.join(f'container_setting_{i}_{j}' for j in range(len(values)))}}};")
            arrays.append(f"static const size_t container_setting_{i}_sizes[] = {{{', '.join(str(len(v)) for v in values)}}};")
            sizes = f"container_setting_{i}_sizes"
        else:
            ctype = _C_TYPES[FMI_FUNCTIONS[s.component.version][kind][2]]
            arrays.append(f"static {ctype} const container_setting_{i}[] = "
                          f"{{{', '.join(_c_value(kind, v) for v in values)}}};")
        rows.append(f"{{{_c_string(f'{s.component.name}.{s.variable.name}')}, {s.index}, "
                    f"{s.variable.valueReference}u, {_KINDS.index(kind)}, "
                    f"{int(s.variable.causality == 'structuralParameter')}, {len(values)}, container_setting_{i}, "
                    f"{sizes}}}")
    body = ",\n    ".join(rows) or "{0}"
    return ("\n".join(arrays) + f"\n#define CONTAINER_N_SETTINGS {len(rows)}\n"
            f"static const ContainerSetting container_settings[] = {{\n    {body}\n}};\n")


def _unit_elements(system: WiredSystem) -> dict[str, ET.Element]:
    """The components' own unit definitions, by unit name (the first component's wins)."""
    units: dict[str, ET.Element] = {}
    for comp in system.wiring.components.values():
        with zipfile.ZipFile(comp.path) as z:
            root = ET.fromstring(z.read("modelDescription.xml"))
        for unit in root.iter("Unit"):
            for display in unit.iter("DisplayUnit"):
                display.attrib.pop("inverse", None)  # FMI 3 only: dropped, so both versions read it
            units.setdefault(unit.get("name", ""), unit)
    return units


def _model_description(system: WiredSystem, identifier: str, token: str, table: list[FmuVariable], step: float,
                       sources: tuple[str, ...], types: Mapping[str, str], fmi_version: int = 2) -> bytes:
    info = FmuInfo(model_name=identifier, model_identifier=identifier, token=token,
                   description=f"duffid co-simulation container: {', '.join(system.wiring.components)} "
                               f"(Jacobi, fixed step {step!r} s)",
                   sources=sources, model_exchange=False, co_simulation=True,
                   experiment={"StartTime": 0.0, "Interval": float(step)}, variable_step=False,
                   generation_tool=CONTAINER_GENERATION_TOOL)
    describe = model_description_fmi2 if fmi_version == 2 else model_description_fmi3
    root = ET.fromstring(retype(describe(info, table), fmi_version, types))
    cs = root.find("CoSimulation")
    state = "FMUstate" if fmi_version == 2 else "FMUState"  # FMI 3 spells it with a capital S
    for attribute in list(cs.attrib):
        if attribute.lower() in ("cangetandsetfmustate", "canserializefmustate"):
            del cs.attrib[attribute]
    cs.set(f"canGetAndSet{state}", "false")
    cs.set(f"canSerialize{state}", "false")
    definitions = root.find("UnitDefinitions")
    if definitions is not None:
        own = _unit_elements(system)
        for i, unit in enumerate(list(definitions)):
            if unit.get("name") in own:
                definitions.remove(unit)
                definitions.insert(i, own[unit.get("name")])
    ET.indent(root, space="  ")
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="utf-8") + b"\n"


def _platforms(system: WiredSystem) -> list[Platform]:
    """The platforms with a compiler on which every component has a binary.

    Raises
    ------
    WiringError
        If there is none.
    """
    available, _ = resolve_platforms()
    present: dict[str, set[str]] = {}
    for comp in system.wiring.components.values():
        with zipfile.ZipFile(comp.path) as z:
            present[comp.name] = set(z.namelist())
    chosen = [p for p in available if all(fmu_binary_path(c.md.coSimulation.modelIdentifier, c.version, p)
                                          in present[c.name] for c in system.wiring.components.values())]
    if not chosen:
        folders = {name: sorted({n.split("/")[1] for n in names if n.startswith("binaries/") and n.count("/") == 2})
                   for name, names in present.items()}
        raise WiringError("no platform has binaries of every component (and a compiler here): "
                          + "; ".join(f"{c}: {', '.join(f) or 'none'}" for c, f in folders.items())
                          + f"; compilers for {', '.join(p.name for p in available)}")
    return chosen


def export_container(system: WiredSystem, path: str | os.PathLike[str],
                     inputs: Mapping[str, str | Sequence[str]] | None = None,
                     outputs: Mapping[str, str] | None = None, step: float = 1e-3,
                     parameters: Mapping[str, str | Sequence[str]] | None = None, fmi_version: int = 2) -> Path:
    """Write ``system`` as one co-simulation container FMU (FMI 2.0 or 3.0).

    Parameters
    ----------
    system : System (or any WiredSystem)
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
    fmi_version : {2, 3}
        The container's own interface (its components may be FMI 2 or 3 either way): the
        same runtime on the shared glue's FMI 2 or FMI 3 functions.

    Returns
    -------
    Path
        The FMU written.

    Raises
    ------
    WiringError
        Unknown or ill-typed variables, bad names, an input both connected and exported,
        mixed types in one mapping, types the container cannot carry, no platform with
        binaries of every component.
    CompilerNotFoundError, BuildError
        Without a C compiler, or if the runtime does not compile (see :mod:`duffid.cbuild`).
    """
    if not system.wiring.components:
        raise WiringError("the system has no components")
    if fmi_version not in (2, 3):
        raise WiringError(f"fmi_version must be 2 or 3, got {fmi_version!r}")
    transformed = [str(c) for c in system.wiring.connections if c.transformed]
    if transformed:
        raise WiringError(f"the connection {transformed[0]} has a factor or offset (an SSP linear transformation "
                          "or unit conversion), which the container runtime cannot apply (it copies values)")
    if not (isinstance(step, (int, float)) and not isinstance(step, bool) and math.isfinite(step) and step > 0):
        raise WiringError(f"step must be a positive number, got {step!r}")
    path = Path(path)
    variables, settings = _plan(system, inputs, outputs, parameters)
    platforms = _platforms(system)
    identifier = _identifier(path.stem)
    table = _table(variables)
    types = {v.name: _GLUE_TYPE[v.kind] for v in variables if v.kind != "Real"}
    runtime = {name: (fmu_sources(folder) / name).read_bytes() for folder, names in RUNTIME_FILES.items()
               for name in names}
    runtime.update({name: (fmu_sources("common") / name).read_bytes() for name in COMMON_FILES[fmi_version]})
    components = {name: comp.path.read_bytes() for name, comp in system.wiring.components.items()}
    token = token_from(f"duffid-container-fmi{fmi_version}", identifier, repr(float(step)), *runtime.values(), *components.values(),
                       *[f"{v.name}|{v.kind}|{v.causality}|{v.start}|{v.unit}|{v.links}" for v in variables],
                       *[f"{c.source}>{c.target}" for c in system.wiring.connections],
                       *[f"{s.index}|{s.variable.name}|{s.value!r}" for s in settings])
    sources = dict(runtime)
    sources[_CONFIG] = _header(system, variables, settings, table, identifier, token, step).encode()
    c_files = tuple(sorted(n for n in sources if n.endswith(".c")))
    files = {"modelDescription.xml": _model_description(system, identifier, token, table, step, c_files, types,
                                                        fmi_version)}
    files.update({f"sources/{name}": data for name, data in sources.items()})
    for name, comp in system.wiring.components.items():
        with zipfile.ZipFile(comp.path) as z:
            for info in z.infolist():
                if not info.is_dir():
                    files[f"resources/{name}/{info.filename}"] = z.read(info)
    with tempfile.TemporaryDirectory(prefix="duffid-container-") as tmp:
        src = Path(tmp) / "sources"
        src.mkdir()
        for name, data in sources.items():
            (src / name).write_bytes(data)
        for platform in platforms:
            inside = fmu_binary_path(identifier, fmi_version, platform)
            binary = Path(tmp) / inside
            compile_shared_library([src / n for n in c_files], binary, include_dirs=[src, fmi_include_dir()],
                                   flags=FMU_FLAGS, platform=platform)
            files[inside] = binary.read_bytes()
    write_zip(files, path)
    return path
