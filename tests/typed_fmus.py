"""duffid's typed test FMUs: one variable table per model, from which the modelDescription.xml
and the C header ``typed_model.h`` are generated, compiled with duffid's C build helper.

* ``Feedthrough3`` (FMI 3.0): an input, a parameter and an output of every FMI 3 type (Float32,
  Float64, Int8 .. UInt64, Boolean, String, Binary, Enumeration), each output a copy of its input
  or parameter, plus arrays (a 2x3 Float64 and a 3-element Int32 array).
* ``StateSpace3`` (FMI 3.0): ``der(x) = A x + B u, y = C x + D u`` with the sizes m, n, r as
  structural parameters (arrays sized by them), one explicit Euler step per doStep.
* ``Stair3`` (FMI 3.0, ``hasEventMode``): a counter that rises at time events, updated in
  Event Mode when the importer uses it.
* ``Feedthrough2`` (FMI 2.0): Real, Integer, Boolean, String and Enumeration inputs,
  parameters and outputs.

The C sources are in ``tests/fmus`` (duffid's own code). ``description_only=True`` packs an
FMU without binary (for what duffid refuses when it reads the model description).
"""
from __future__ import annotations

import uuid
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from xml.sax.saxutils import quoteattr

from duffid.cbuild import FMU_FLAGS, compile_shared_library, fmu_binary_path
from duffid.fmu.package import fmi_include_dir

SOURCES = Path(__file__).parent / "fmus"
FMI3_TYPES = ("Float32", "Float64", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64",
              "Boolean", "String", "Binary", "Enumeration")
FMI2_TYPES = ("Real", "Integer", "Boolean", "String", "Enumeration")
_C_TYPE = {t: f"T_{t.upper()}" for t in FMI3_TYPES + ("Clock",)}
_C_TYPE.update({"Real": "T_FLOAT64", "Integer": "T_INT32"})
_CAUSALITY = {"parameter": "C_PARAMETER", "structuralParameter": "C_STRUCTURAL", "calculatedParameter": "C_CALCULATED",
              "input": "C_INPUT", "output": "C_OUTPUT", "local": "C_LOCAL", "independent": "C_INDEPENDENT"}
_VARIABILITY = {"constant": "V_CONSTANT", "fixed": "V_FIXED", "tunable": "V_TUNABLE", "discrete": "V_DISCRETE",
                "continuous": "V_CONTINUOUS"}
#: Start values of the inputs and parameters of every type (the outputs start as their sources).
STARTS = {"Float32": "0.5", "Float64": "1.5", "Int8": "-8", "UInt8": "8", "Int16": "-16", "UInt16": "16",
          "Int32": "-32", "UInt32": "32", "Int64": "-64", "UInt64": "64", "Boolean": "true", "String": "hello",
          "Binary": "0a0b", "Enumeration": "2", "Real": "1.5", "Integer": "-32"}


@dataclass
class Var:
    """One variable of a test model."""

    name: str
    type: str
    causality: str
    variability: str
    start: str | None = None
    dims: tuple = ()              # ints (fixed) or names of structural parameters
    feed: str | None = None       # the variable this output copies
    max: int | None = None        # structural parameters: largest value
    capacity: int = 1


@dataclass
class Model:
    name: str
    fmi: int
    sources: tuple[str, ...]
    variables: list[Var] = field(default_factory=list)


def _variability(type_name: str, causality: str) -> str:
    if causality == "parameter":
        return "fixed"
    return "continuous" if type_name in ("Float32", "Float64", "Real") else "discrete"


def _feed_variables(types: tuple[str, ...]) -> list[Var]:
    """An input, a parameter and their copies ``<type>_output``, ``<type>_parameter_output`` per type."""
    variables = []
    for t in types:
        for role in ("input", "parameter"):
            variables.append(Var(f"{t}_{role}", t, role, _variability(t, role), STARTS[t]))
        for source in ("input", "parameter"):
            variables.append(Var(f"{t}_{source}_output".replace("_input", ""), t, "output", _variability(t, "output"),
                                 feed=f"{t}_{source}"))
    return variables


def feedthrough3() -> Model:
    model = Model("Feedthrough3", 3, ("typed_fmu3.c", "feedthrough3.c"), [Var("time", "Float64", "independent",
                                                                            "continuous")])
    model.variables += _feed_variables(FMI3_TYPES) + [
        Var("Float64_array_input", "Float64", "input", "continuous", "1 2 3 4 5 6", dims=(2, 3)),
        Var("Float64_array_output", "Float64", "output", "continuous", dims=(2, 3), feed="Float64_array_input"),
        Var("Int32_array_input", "Int32", "input", "discrete", "1 2 3", dims=(3,)),
        Var("Int32_array_output", "Int32", "output", "discrete", dims=(3,), feed="Int32_array_input"),
        Var("String_input_length", "Int32", "output", "discrete"),     # bytes of String_input
        Var("Binary_input_length", "Int32", "output", "discrete")]     # bytes of Binary_input
    return model


def statespace3() -> Model:
    def real(name: str, causality: str, start: str | None, dims: tuple) -> Var:
        return Var(name, "Float64", causality, "fixed" if causality == "parameter" else "continuous", start, dims)

    return Model("StateSpace3", 3, ("typed_fmu3.c", "statespace3.c"), [
        Var("time", "Float64", "independent", "continuous"),
        Var("m", "UInt64", "structuralParameter", "fixed", "1", max=4),
        Var("n", "UInt64", "structuralParameter", "fixed", "2", max=4),
        Var("r", "UInt64", "structuralParameter", "fixed", "2", max=4),
        real("A", "parameter", "0 1 -1 -0.5", ("n", "n")),
        real("B", "parameter", "0 1", ("n", "m")),
        real("C", "parameter", "1 0 0 1", ("r", "n")),
        real("D", "parameter", "0 0", ("r", "m")),
        real("x0", "parameter", "1 0", ("n",)),
        real("u", "input", "0", ("m",)),
        real("y", "output", None, ("r",)),
        real("x", "local", None, ("n",))])


def stair3() -> Model:
    """Time events: ``counter`` rises at every multiple of ``period`` (see tests/fmus/stair3.c)."""
    return Model("Stair3", 3, ("typed_fmu3.c", "stair3.c"), [
        Var("time", "Float64", "independent", "continuous"),
        Var("period", "Float64", "parameter", "fixed", "0.2"),
        Var("counter", "Int32", "output", "discrete"),
        Var("event_updates", "Int32", "output", "discrete"),
        Var("next_tick", "Float64", "local", "discrete")])


def feedthrough2() -> Model:
    return Model("Feedthrough2", 2, ("feedthrough2.c",), _feed_variables(FMI2_TYPES))


# ----------------------------------------------------------------------------- generation
def _sizes(model: Model) -> None:
    """Each variable's capacity (its largest number of elements)."""
    by_name = {v.name: v for v in model.variables}
    for v in model.variables:
        v.capacity = 1
        for d in v.dims:
            v.capacity *= d if isinstance(d, int) else by_name[d].max


def _enumeration_types(fmi: int) -> str:
    items = "".join(f'<Item name="Option{i}" value="{i}"/>' for i in (1, 2, 3))
    if fmi == 3:
        return f'<TypeDefinitions><EnumerationType name="Option">{items}</EnumerationType></TypeDefinitions>'
    return f'<TypeDefinitions><SimpleType name="Option"><Enumeration>{items}</Enumeration></SimpleType></TypeDefinitions>'


def _xml3(model: Model, token: str, extra: str) -> str:
    vrs = {v.name: i for i, v in enumerate(model.variables)}
    lines = []
    for i, v in enumerate(model.variables):
        attrs = f'name="{v.name}" valueReference="{i}" causality="{v.causality}" variability="{v.variability}"'
        if v.type == "Enumeration":
            attrs += ' declaredType="Option"'
        if v.max is not None:
            attrs += f' max="{v.max}"'
        if v.causality == "output" or v.causality == "local" and v.start is None:
            attrs += ' initial="calculated"'
        inner = "".join(f'<Dimension start="{d}"/>' if isinstance(d, int) else f'<Dimension valueReference="{vrs[d]}"/>'
                        for d in v.dims)
        if v.start is not None and v.type in ("String", "Binary"):
            inner += f"<Start value={quoteattr(v.start)}/>"
        elif v.start is not None:
            attrs += f" start={quoteattr(v.start)}"
        lines.append(f"<{v.type} {attrs}>{inner}</{v.type}>")
    outputs = [i for i, v in enumerate(model.variables) if v.causality == "output"]
    structure = "".join(f'<Output valueReference="{i}"/>' for i in outputs) + \
        "".join(f'<InitialUnknown valueReference="{i}"/>' for i in outputs)
    types = _enumeration_types(3) if any(v.type == "Enumeration" for v in model.variables) else ""
    return (f'<?xml version="1.0" encoding="UTF-8"?>\n<fmiModelDescription fmiVersion="3.0" modelName="{model.name}" '
            f'instantiationToken="{token}" generationTool="duffid tests (typed_fmus.py)" '
            f'variableNamingConvention="structured">'
            f'<CoSimulation modelIdentifier="{model.name}" canHandleVariableCommunicationStepSize="true"{extra}/>'
            f'{types}<ModelVariables>{"".join(lines)}</ModelVariables>'
            f'<ModelStructure>{structure}</ModelStructure></fmiModelDescription>\n')


def _xml2(model: Model, token: str) -> str:
    lines = []
    for i, v in enumerate(model.variables):
        initial = ' initial="calculated"' if v.causality == "output" else ""
        element = "Real" if v.type == "Real" else v.type
        typed = f'declaredType="Option" start="{v.start}"' if v.type == "Enumeration" and v.start else \
            'declaredType="Option"' if v.type == "Enumeration" else f"start={quoteattr(v.start)}" if v.start else ""
        lines.append(f'<ScalarVariable name="{v.name}" valueReference="{i}" causality="{v.causality}" '
                     f'variability="{v.variability}"{initial}><{element} {typed}/></ScalarVariable>')
    outputs = [i + 1 for i, v in enumerate(model.variables) if v.causality == "output"]
    unknowns = "".join(f'<Unknown index="{i}"/>' for i in outputs)
    return (f'<?xml version="1.0" encoding="UTF-8"?>\n<fmiModelDescription fmiVersion="2.0" modelName="{model.name}" '
            f'guid="{token}" generationTool="duffid tests (typed_fmus.py)" numberOfEventIndicators="0">'
            f'<CoSimulation modelIdentifier="{model.name}" canHandleVariableCommunicationStepSize="true"/>'
            f'{_enumeration_types(2)}<ModelVariables>{"".join(lines)}</ModelVariables>'
            f'<ModelStructure><Outputs>{unknowns}</Outputs><InitialUnknowns>{unknowns}</InitialUnknowns>'
            f'</ModelStructure></fmiModelDescription>\n')


def _c_name(name: str) -> str:
    return "".join(c if c.isalnum() else "_" for c in name)


def _header(model: Model, token: str) -> str:
    index = {v.name: i for i, v in enumerate(model.variables)}
    rows = []
    for i, v in enumerate(model.variables):
        fixed = [d if isinstance(d, int) else 0 for d in v.dims] + [0, 0]
        dim = [-1 if isinstance(d, int) else index[d] for d in v.dims] + [-1, -1]
        start = f'"{v.start}"' if v.start is not None else "NULL"
        rows.append(f'    {{"{v.name}", {i}u, {_C_TYPE[v.type]}, {_CAUSALITY[v.causality]}, '
                    f'{_VARIABILITY[v.variability]}, {len(v.dims)}, {{{fixed[0]}, {fixed[1]}}}, {{{dim[0]}, {dim[1]}}}, '
                    f'{v.capacity}u, {start}, {v.max or 0}ull}}')
    feeds = [(index[v.name], index[v.feed]) for v in model.variables if v.feed]
    names = "\n".join(f"#define V_{_c_name(v.name)} {i}" for i, v in enumerate(model.variables))
    return (f'#ifndef TYPED_MODEL_H\n#define TYPED_MODEL_H\n#include "typed_fmu.h"\n'
            f'#define MODEL_IDENTIFIER "{model.name}"\n#define INSTANTIATION_TOKEN "{token}"\n'
            f"#define N_VARS {len(model.variables)}\n{names}\n"
            f"static const VarInfo VARS[N_VARS] = {{\n" + ",\n".join(rows) + "\n};\n"
            f"#define N_FEED {len(feeds)}\n"
            f"static const int FEED[{max(len(feeds), 1)}][2] = {{{', '.join(f'{{{a}, {b}}}' for a, b in feeds) or '{0, 0}'}}};\n"
            "#endif\n")


def build(model: Model, folder: Path, *, description_only: bool = False, cosimulation_attributes: str = "",
          extra_variables: str = "") -> Path:
    """Write ``folder/<name>.fmu`` for ``model`` (compiled unless ``description_only``).

    ``cosimulation_attributes`` is added to the ``<CoSimulation>`` element (e.g.
    ``' hasEventMode="true"'``) and ``extra_variables`` to the end of ``<ModelVariables>``
    (FMI 3; for the FMUs duffid must refuse).
    """
    _sizes(model)
    token = "{" + str(uuid.uuid5(uuid.NAMESPACE_URL, f"duffid-tests/{model.name}")) + "}"
    xml = _xml3(model, token, cosimulation_attributes) if model.fmi == 3 else _xml2(model, token)
    if extra_variables:
        xml = xml.replace("</ModelVariables>", extra_variables + "</ModelVariables>")
    folder.mkdir(parents=True, exist_ok=True)
    files = {"modelDescription.xml": xml.encode()}
    if not description_only:
        work = folder / f"{model.name}_build"
        work.mkdir(exist_ok=True)
        (work / "typed_model.h").write_text(_header(model, token))
        binary = work / "binary"
        compile_shared_library([SOURCES / s for s in model.sources], binary, include_dirs=[work, SOURCES,
                                                                                          fmi_include_dir()],
                               flags=FMU_FLAGS)
        files[fmu_binary_path(model.name, model.fmi)] = binary.read_bytes()
    path = folder / f"{model.name}{'_description' if description_only else ''}.fmu"
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        for name, data in files.items():
            z.writestr(name, data)
    return path
