"""modelDescription.xml (FMI 2.0 and 3.0) and buildDescription.xml (FMI 3.0) writers."""
from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from typing import Iterable

from ..models.units import SI_BASE, si_exponents
from .variables import FmuVariable

__all__ = ["FmuInfo", "model_description_fmi2", "model_description_fmi3", "build_description",
           "unit_exponents", "unit_definitions", "GENERATION_TOOL", "C_MODEL_GENERATION_TOOL",
           "ANNOTATION_TOOL", "SAMPLED_INPUTS", "add_sampled_inputs", "declares_sampled_inputs"]

#: generationTool of the plant FMUs exported from Modelica.
GENERATION_TOOL = "duffid.modelica (pymoca front end, CasADi code generation)"
#: generationTool of the hand-written C models on duffid's FMI glue (estimators, controllers).
C_MODEL_GENERATION_TOOL = "duffid (C model on duffid's FMI glue, fmus/common)"
LOG_CATEGORIES = {
    "logStatusError": "Errors (always logged)",
    "logStatusDiscard": "Discarded steps (always logged)",
    "logStatusWarning": "Warnings",
    "logAll": "All messages",
}
#: The tool name of duffid's annotations in a modelDescription (FMI 2 ``<VendorAnnotations><Tool
#: name=...>``, FMI 3 ``<Annotations><Annotation type=...>``).
ANNOTATION_TOOL = "io.github.duffid"
#: duffid's annotation of an FMU that reads its inputs as samples of one instant (an estimator:
#: a force and a displacement from two instants read as physics). duffid's Gauss-Seidel master
#: delivers all of such a component's inputs from the same instant
#: (:meth:`duffid.cosim.system.System.gauss_seidel_order`).
SAMPLED_INPUTS = "SampledInputs"
#: SI base-unit exponents of a unit string (``N.s/m``; None: unknown), see :mod:`duffid.models.units`.
unit_exponents = si_exponents


@dataclass(frozen=True)
class FmuInfo:
    """Model-level data of a modelDescription.

    ``variable_step``: the co-simulation interface accepts a communication step of any
    size (an integrating plant); False for the discrete-time models whose step is their
    sample period (estimators, controllers). ``experiment`` keys: StartTime, StopTime,
    Tolerance, Interval (the default experiment's step size).
    """

    model_name: str
    model_identifier: str
    token: str
    description: str
    sources: tuple[str, ...]
    model_exchange: bool
    co_simulation: bool
    experiment: dict
    variable_step: bool = True
    generation_tool: str = GENERATION_TOOL
    sampled_inputs: bool = False  # annotated with SAMPLED_INPUTS


def _bool(value: bool) -> str:
    return "true" if value else "false"


def _num(value: float) -> str:
    return repr(float(value))


def _units(parent: ET.Element, table: list[FmuVariable]) -> None:
    unit_definitions(parent, [v.unit for v in table if v.unit])


def unit_definitions(parent: ET.Element, names: Iterable[str]) -> None:
    """Append ``<UnitDefinitions>`` of the unit ``names`` (with their SI base units where
    :func:`unit_exponents` knows them) to ``parent``; nothing when there is none."""
    units = sorted(set(names))
    if not units:
        return
    defs = ET.SubElement(parent, "UnitDefinitions")
    for unit in units:
        element = ET.SubElement(defs, "Unit", name=unit)
        exps = unit_exponents(unit)
        if exps is not None:
            ET.SubElement(element, "BaseUnit", {b: str(e) for b, e in zip(SI_BASE, exps) if e})


def _log_categories(parent: ET.Element) -> None:
    cats = ET.SubElement(parent, "LogCategories")
    for name, text in LOG_CATEGORIES.items():
        ET.SubElement(cats, "Category", name=name, description=text)


def _experiment(parent: ET.Element, info: FmuInfo) -> None:
    exp = info.experiment
    attrs = {}
    for key, attr in (("StartTime", "startTime"), ("StopTime", "stopTime"), ("Tolerance", "tolerance"),
                      ("Interval", "stepSize")):
        if key in exp:
            attrs[attr] = _num(exp[key])
    ET.SubElement(parent, "DefaultExperiment", attrs)


def add_sampled_inputs(root: ET.Element) -> None:
    """Annotate the modelDescription ``root`` (FMI 2 or 3) with :data:`SAMPLED_INPUTS`, in the
    place each schema gives annotations (FMI 2: before ``ModelVariables``; FMI 3: last)."""
    if root.get("fmiVersion", "").startswith("2"):
        element = ET.Element("VendorAnnotations")
        ET.SubElement(ET.SubElement(element, "Tool", name=ANNOTATION_TOOL), SAMPLED_INPUTS)
        root.insert(list(root).index(root.find("ModelVariables")), element)
    else:
        annotations = root.find("Annotations")
        if annotations is None:
            annotations = ET.SubElement(root, "Annotations")
        ET.SubElement(ET.SubElement(annotations, "Annotation", type=ANNOTATION_TOOL), SAMPLED_INPUTS)


def declares_sampled_inputs(root: ET.Element) -> bool:
    """Whether the modelDescription ``root`` (FMI 2 or 3) carries :data:`SAMPLED_INPUTS`."""
    paths = (f"VendorAnnotations/Tool[@name='{ANNOTATION_TOOL}']/{SAMPLED_INPUTS}",
             f"Annotations/Annotation[@type='{ANNOTATION_TOOL}']/{SAMPLED_INPUTS}")
    return any(root.find(path) is not None for path in paths)


def _serialize(root: ET.Element) -> bytes:
    ET.indent(root, space="  ")
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="utf-8") + b"\n"


def _initial_unknown(v: FmuVariable) -> bool:
    return (v.causality == "output" and v.initial in ("calculated", "approx")) or \
        v.causality == "calculatedParameter" or v.derivative_of is not None or \
        (v.variability == "continuous" and v.initial in ("calculated", "approx") and
         v.causality != "local" and v.causality != "independent")


def model_description_fmi2(info: FmuInfo, table: list[FmuVariable]) -> bytes:
    """modelDescription.xml for FMI 2.0 (Model Exchange and/or Co-Simulation)."""
    root = ET.Element("fmiModelDescription", {
        "fmiVersion": "2.0", "modelName": info.model_name, "guid": info.token,
        "description": info.description, "generationTool": info.generation_tool,
        "variableNamingConvention": "structured", "numberOfEventIndicators": "0"})
    common = {"modelIdentifier": info.model_identifier, "canNotUseMemoryManagementFunctions": "true",
              "canGetAndSetFMUstate": "true", "canSerializeFMUstate": "true",
              "providesDirectionalDerivative": "false"}
    for enabled, tag, extra in (
            (info.model_exchange, "ModelExchange", {"completedIntegratorStepNotNeeded": "true"}),
            (info.co_simulation, "CoSimulation", {"canHandleVariableCommunicationStepSize": _bool(info.variable_step),
                                                  "canInterpolateInputs": "false",
                                                  "maxOutputDerivativeOrder": "0"})):
        if enabled:
            element = ET.SubElement(root, tag, {**common, **extra})
            files = ET.SubElement(element, "SourceFiles")
            for name in info.sources:
                ET.SubElement(files, "File", name=name)
    _units(root, table)
    _log_categories(root)
    _experiment(root, info)
    variables = ET.SubElement(root, "ModelVariables")
    for v in table:
        attrs = _variable_attributes(v)
        sv = ET.SubElement(variables, "ScalarVariable", attrs)
        real = _value_attributes(v)
        if v.derivative_of is not None:
            real["derivative"] = str(v.derivative_of + 1)
        ET.SubElement(sv, "Real", real)
    if info.sampled_inputs:
        add_sampled_inputs(root)
    structure = ET.SubElement(root, "ModelStructure")
    outputs = [v for v in table if v.causality == "output"]
    if outputs:
        element = ET.SubElement(structure, "Outputs")
        for v in outputs:
            ET.SubElement(element, "Unknown", index=str(v.vr + 1))
    derivatives = [v for v in table if v.derivative_of is not None]
    if derivatives:
        element = ET.SubElement(structure, "Derivatives")
        for v in derivatives:
            ET.SubElement(element, "Unknown", index=str(v.vr + 1))
    initial = [v for v in table if _initial_unknown(v)]
    if initial:
        element = ET.SubElement(structure, "InitialUnknowns")
        for v in initial:
            ET.SubElement(element, "Unknown", index=str(v.vr + 1))
    return _serialize(root)


def _variable_attributes(v: FmuVariable) -> dict[str, str]:
    """The attributes FMI 2 and FMI 3 variables share: name, reference, description,
    causality, variability and initial."""
    attrs = {"name": v.name, "valueReference": str(v.vr)}
    if v.description:
        attrs["description"] = v.description
    attrs["causality"] = v.causality
    attrs["variability"] = v.variability
    if v.initial is not None and v.causality not in ("input", "independent"):
        attrs["initial"] = v.initial
    return attrs


def _value_attributes(v: FmuVariable) -> dict[str, str]:
    """Unit, min, max and start of a Float64 variable (FMI 2 Real element, FMI 3 Float64)."""
    attrs = {}
    if v.unit:
        attrs["unit"] = v.unit
    if v.minimum is not None:
        attrs["min"] = _num(v.minimum)
    if v.maximum is not None:
        attrs["max"] = _num(v.maximum)
    if v.start is not None:
        attrs["start"] = _num(v.start)
    return attrs


def model_description_fmi3(info: FmuInfo, table: list[FmuVariable]) -> bytes:
    """modelDescription.xml for FMI 3.0 (Model Exchange and/or Co-Simulation)."""
    root = ET.Element("fmiModelDescription", {
        "fmiVersion": "3.0", "modelName": info.model_name, "instantiationToken": info.token,
        "description": info.description, "generationTool": info.generation_tool,
        "variableNamingConvention": "structured"})
    common = {"modelIdentifier": info.model_identifier, "canGetAndSetFMUState": "true",
              "canSerializeFMUState": "true", "providesDirectionalDerivatives": "false"}
    if info.model_exchange:
        ET.SubElement(root, "ModelExchange", {**common, "needsCompletedIntegratorStep": "false"})
    if info.co_simulation:
        ET.SubElement(root, "CoSimulation", {**common, "canHandleVariableCommunicationStepSize": _bool(info.variable_step),
                                             "hasEventMode": "false", "maxOutputDerivativeOrder": "0",
                                             "providesIntermediateUpdate": "false"})
    _units(root, table)
    _log_categories(root)
    _experiment(root, info)
    variables = ET.SubElement(root, "ModelVariables")
    for v in table:
        attrs = {**_variable_attributes(v), **_value_attributes(v)}
        if v.derivative_of is not None:
            attrs["derivative"] = str(v.derivative_of)
        ET.SubElement(variables, "Float64", attrs)
    structure = ET.SubElement(root, "ModelStructure")
    for v in table:
        if v.causality == "output":
            ET.SubElement(structure, "Output", valueReference=str(v.vr))
    for v in table:
        if v.derivative_of is not None:
            ET.SubElement(structure, "ContinuousStateDerivative", valueReference=str(v.vr))
    for v in table:
        if _initial_unknown(v):
            ET.SubElement(structure, "InitialUnknown", valueReference=str(v.vr))
    if info.sampled_inputs:
        add_sampled_inputs(root)
    return _serialize(root)


def build_description(model_identifier: str, sources: tuple[str, ...]) -> bytes:
    """sources/buildDescription.xml of an FMI 3.0 FMU (read by ``fmpy compile``)."""
    root = ET.Element("fmiBuildDescription", fmiVersion="3.0")
    config = ET.SubElement(root, "BuildConfiguration", modelIdentifier=model_identifier)
    files = ET.SubElement(config, "SourceFileSet", language="C99")
    for name in sources:
        ET.SubElement(files, "SourceFile", name=name)
    ET.SubElement(config, "Library", name="m")
    return _serialize(root)
