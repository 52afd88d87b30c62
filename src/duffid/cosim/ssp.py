"""SSP (System Structure and Parameterization) import and export of a co-simulated system.

An SSP archive (``.ssp``) is a ZIP file holding a System Structure Description
(``SystemStructure.ssd``), usually the FMUs and parameter files (``.ssv`` values, ``.ssm``
mappings). :func:`read_ssp` fills a :class:`duffid.cosim.system.System` from one (or from a
bare ``.ssd`` file), :func:`write_ssp` writes one::

    system = System.from_ssp("loop.ssp")                   # the system only
    run = read_ssp("loop.ssp", System())                   # and its default experiment
    result = run.system.run(run.stop_time, run.step, start_time=run.start_time)
    system.to_ssp("copy.ssp", stop_time=4.0, step=1e-3)

How SSP maps onto a system
--------------------------
* **Components**: ``<Component>`` of type ``application/x-fmu-sharedlibrary`` (FMI 2.0 or
  3.0 co-simulation; SSP 1.0 files, and SSP 2.0 files, which use the same namespaces and add
  FMI 3). ``source`` is a relative URI resolved against the SSD: a member of the archive,
  or, when it leaves the archive (``../plant.fmu``), a file beside the archive (the archive
  is read as a folder of its own name); ``file:`` URIs name local files. Declared
  connectors must exist in the FMU with the matching causality and type.
* **Connections** from a component output to a component input become
  :meth:`~duffid.cosim.system.System.connect` calls. A ``LinearTransformation`` and a unit
  conversion (connector units, else the FMU variables' units; definitions from the SSD's
  ``<Units>``, else the FMUs' unit definitions) become the connection's factor and offset:
  ``target = factor * convert(source) + offset``, the unit conversion first as SSP's
  parameter mapping specifies. ``suppressUnitConversion="true"`` connects without converting
  or checking units. A connection from a system input or parameter connector to a component
  input delivers the value bound to that system connector (a constant input; a system input
  without a value leaves the component input at its start value, with a warning); a
  connection from a component output to a system output connector has no effect on the run
  (a top-level system's outputs have no consumer). The system's input and output connectors
  are the interface of the container FMU that ``duffid cosim x.ssp --export-container``
  writes (:attr:`SspRun.interface`; the container's inputs start at the FMUs' start values).
* **Parameter bindings** (inline ``<ParameterValues>`` or an ``.ssv`` source, with an
  optional inline or ``.ssm`` parameter mapping, ``prefix`` honoured) on components and on
  the system: values bound to FMU parameters are set before initialisation, values bound to
  inputs become constant inputs (set at initialisation, never changed), values bound to a
  system connector feed the connections from it. As SSP says, later bindings take priority
  over earlier ones, and system-level over component-level ones; ``.ssv`` values with a unit
  are converted to the variable's unit. Unlike SSP (which ignores a value whose name
  matches nothing), duffid refuses it: a misspelt name would silently do nothing.
* **Default experiment**: ``startTime`` and ``stopTime``; the communication step and the
  master (Jacobi or Gauss-Seidel, and its order) come from duffid's annotation
  (:data:`ANNOTATION`, ``<duffid:Run step=... ordering=... order=...>`` in the default
  experiment's annotations) or from the caller (``duffid cosim --step``).

What duffid does not honour stops the import with an :class:`SspError` naming the file,
the line and the element: nested systems, signal dictionaries, Model Exchange components,
other component types, Boolean, Integer and Enumeration mapping transformations, array and
clocked connectors, binary and enumeration values, parameter sources relative to a
component, URIs other than relative ones and ``file:``, unknown elements. Annotations of
other tools are not understood (SSP makes annotations optional for the tools that do not
know them): each is reported in :attr:`SspRun.warnings` (with its file and line; ``duffid
cosim`` prints them), never dropped silently. One is understood: OMSimulator's
(:data:`OMSIMULATOR`) fixed-step master on the top-level system gives the step when duffid's
annotation does not; its variable-step master or solver settings, which duffid cannot
honour, stop the import. Graphical information
(geometry, notes) and meta-data are not needed to run and are skipped.

Export writes SSP 1.0 (valid against the schemas FMPy ships; also with FMI 3 components,
which SSP 2.0 describes with the same elements, since Ecos reads version 1.0 only): the FMUs under
``resources/``, one connector per connected variable, the connections (a factor or offset as
a ``LinearTransformation``, ``check_units=False`` as ``suppressUnitConversion``), the
parameter values and constant inputs as one ``resources/<component>.ssv`` per component,
bound on the component (parameter set :data:`PARAMETER_SET`), the default experiment and
duffid's run annotation.
"""
from __future__ import annotations

import math
import os
import shutil
import tempfile
import urllib.parse
import weakref
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping, Sequence

from lxml import etree

from ..errors import WiringError
from .elements import NAME_RE, ORDERINGS, SystemLike, unit_of
from .ssp_xml import SspArchive, SspError, XmlFile, local_name, parse_xml, resolve


__all__ = ["SspError", "SspRun", "read_ssp", "write_ssp", "ANNOTATION", "NS_SSD", "NS_SSC", "NS_SSV", "NS_SSM",
           "NS_DUFFID", "SSD_VERSIONS", "SSD_MEMBER", "PARAMETER_SET", "OMSIMULATOR"]

NS_SSD = "http://ssp-standard.org/SSP1/SystemStructureDescription"
NS_SSC = "http://ssp-standard.org/SSP1/SystemStructureCommon"
NS_SSV = "http://ssp-standard.org/SSP1/SystemStructureParameterValues"
NS_SSM = "http://ssp-standard.org/SSP1/SystemStructureParameterMapping"
NS_SSB = "http://ssp-standard.org/SSP1/SystemStructureSignalDictionary"
#: The namespace of the content of duffid's annotation.
NS_DUFFID = "https://duffid.github.io/ssp/1.0"
#: The ``type`` of duffid's annotation (reverse domain notation, as SSP asks).
ANNOTATION = "io.github.duffid.cosim"
#: The annotation type of OMSimulator (whose fixed-step master's step duffid takes).
OMSIMULATOR = "org.openmodelica"
#: SSD versions read (SSP 2.0 keeps the SSP1 namespaces and adds FMI 3 components).
SSD_VERSIONS = ("1.0", "2.0")
#: The default SSD of an archive.
SSD_MEMBER = "SystemStructure.ssd"
#: The name of the parameter sets :func:`write_ssp` writes (one ``resources/<component>.ssv``
#: per component, bound on the component; tools that select a parameter set by name, such as
#: Ecos, merge them under this name).
PARAMETER_SET = "parameters"

_SSP = {NS_SSD, NS_SSC, NS_SSV, NS_SSM, NS_SSB}
_FMU_TYPE = "application/x-fmu-sharedlibrary"
_SSV_TYPE = "application/x-ssp-parameter-set"
_SSM_TYPE = "application/x-ssp-parameter-mapping"
#: Elements without run semantics: skipped wherever they appear.
_PRESENTATION = {"ElementGeometry", "ConnectorGeometry", "ConnectionGeometry", "SystemGeometry",
                 "GraphicalElements", "MetaData", "Signature"}
#: SSP value/connector types -> the kind duffid exchanges them as (None: not supported).
_TYPES = {"Real": "Real", "Float64": "Real", "Float32": "Real", "Integer": "Integer", "Int8": "Integer",
          "UInt8": "Integer", "Int16": "Integer", "UInt16": "Integer", "Int32": "Integer", "UInt32": "Integer",
          "Int64": "Integer", "UInt64": "Integer", "Boolean": "Boolean", "String": "String",
          "Enumeration": None, "Binary": None, "Clock": None}
_FMI_KIND = {"Real": "Real", "Float64": "Real", "Float32": "Real", "Integer": "Integer", "Int8": "Integer",
             "UInt8": "Integer", "Int16": "Integer", "UInt16": "Integer", "Int32": "Integer", "UInt32": "Integer",
             "Int64": "Integer", "UInt64": "Integer", "Enumeration": "Integer", "Boolean": "Boolean",
             "String": "String"}
_BASE = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")


@dataclass
class SspRun:
    """What :func:`read_ssp` read: the system and how the file says to run it.

    Attributes
    ----------
    path : Path
        The ``.ssp`` (or ``.ssd``) file.
    system : SystemLike
        The system, filled.
    start_time : float
        ``DefaultExperiment/@startTime`` (0 when absent).
    stop_time : float or None
        ``DefaultExperiment/@stopTime``.
    step : float or None
        The communication step of duffid's annotation (None: the caller must give one).
    ordering : str
        ``"jacobi"`` (default) or ``"gauss-seidel"``, from duffid's annotation.
    order : list of str or None
        The Gauss-Seidel order of duffid's annotation.
    warnings : list of str
        What was read but not understood (other tools' annotations), with file and line.
    name : str
        The SSD's ``name``.
    interface : dict
        The system's own connectors as a container FMU's interface (``duffid cosim x.ssp
        --export-container``): ``{"inputs": {connector: [component inputs]}, "outputs":
        {connector: "component.output"}}``.
    """

    path: Path
    system: SystemLike
    start_time: float = 0.0
    stop_time: float | None = None
    step: float | None = None
    ordering: str = "jacobi"
    order: list[str] | None = None
    warnings: list[str] = field(default_factory=list)
    name: str = ""
    interface: dict[str, dict[str, Any]] = field(default_factory=lambda: {"inputs": {}, "outputs": {}})


# ------------------------------------------------------------------------------------ helpers
def _children(xml: XmlFile, element: etree._Element, allowed: Sequence[str]) -> Iterator[etree._Element]:
    """The child elements of ``element`` (comments skipped); an element of an SSP namespace
    not in ``allowed`` (nor presentation-only), or of another namespace, is an error."""
    for child in element:
        if not isinstance(child.tag, str):
            continue
        name = local_name(child)
        if etree.QName(child).namespace not in _SSP:
            raise SspError(f"{xml.where(child)}: an element of namespace {etree.QName(child).namespace!r} is not "
                           f"part of SSP here (inside <{local_name(element)}>)")
        if name in _PRESENTATION:
            continue
        if name not in allowed:
            raise SspError(f"{xml.where(child)}: <{name}> inside <{local_name(element)}> is not supported by duffid")
        yield child


def _number(xml: XmlFile, element: etree._Element, attribute: str, default: float | None = None) -> float | None:
    text = element.get(attribute)
    if text is None:
        return default
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise SspError(f"{xml.where(element)}: {attribute}={text!r} is not a finite number")
    return value


def _boolean(xml: XmlFile, element: etree._Element, attribute: str, default: bool = False) -> bool:
    text = element.get(attribute)
    if text is None:
        return default
    if text.strip() in ("true", "1"):
        return True
    if text.strip() in ("false", "0"):
        return False
    raise SspError(f"{xml.where(element)}: {attribute}={text!r} is not an XML boolean (true, false, 1, 0)")


def _typed_value(xml: XmlFile, element: etree._Element) -> tuple[str, Any, str | None]:
    """(kind, value, unit) of an ``ssv`` value element (``<ssv:Real value=... unit=...>``)."""
    name = local_name(element)
    kind = _TYPES.get(name)
    if kind is None:
        raise SspError(f"{xml.where(element)}: {name} values are not supported by duffid (Real, Integer, Boolean "
                       "and String are)")
    text = element.get("value")
    if text is None:
        raise SspError(f"{xml.where(element)}: no value attribute")
    if kind == "Real":
        return kind, _number(xml, element, "value"), element.get("unit")
    if kind == "Integer":
        try:
            return kind, int(text.strip()), None
        except ValueError:
            raise SspError(f"{xml.where(element)}: value={text!r} is not an integer") from None
    if kind == "Boolean":
        return kind, _boolean(xml, element, "value"), None
    return kind, text, None


def _annotations(xml: XmlFile, element: etree._Element, warnings: list[str], handled: Sequence[str] = ()
                 ) -> list[etree._Element]:
    """The contents of duffid's annotations inside ``<Annotations>`` ``element``; every other
    annotation (but those of the ``handled`` types) is reported in ``warnings``."""
    ours = []
    for annotation in _children(xml, element, ("Annotation",)):
        kind = annotation.get("type")
        if kind == ANNOTATION:
            ours += [c for c in annotation if isinstance(c.tag, str)]
        elif kind not in handled:
            warnings.append(f"{xml.where(annotation)}: annotation of type {kind!r} is not understood by duffid "
                            "and was not applied")
    return ours


@dataclass(frozen=True)
class _Unit:
    exponents: tuple[int, ...]
    factor: float
    offset: float


def _units(xml: XmlFile, element: etree._Element, into: dict[str, _Unit]) -> None:
    """Read ``<Units>`` (ssc:Unit with its BaseUnit) into ``into``."""
    for unit in _children(xml, element, ("Unit",)):
        base = next((c for c in _children(xml, unit, ("BaseUnit", "Annotations"))
                     if local_name(c) == "BaseUnit"), None)
        if base is None or unit.get("name") is None:
            raise SspError(f"{xml.where(unit)}: a unit needs a name and a <BaseUnit>")
        exponents = []
        for b in _BASE:
            text = base.get(b, "0")
            try:
                exponents.append(int(text))
            except ValueError:
                raise SspError(f"{xml.where(base)}: {b}={text!r} is not an integer exponent") from None
        into[unit.get("name")] = _Unit(tuple(exponents), _number(xml, base, "factor", 1.0),
                                       _number(xml, base, "offset", 0.0))


def _fmu_units(md: Any) -> dict[str, _Unit]:
    out = {}
    for unit in getattr(md, "unitDefinitions", None) or []:
        base = getattr(unit, "baseUnit", None)
        if base is not None:
            out[unit.name] = _Unit(tuple(int(getattr(base, b, 0) or 0) for b in _BASE),
                                   float(getattr(base, "factor", 1.0) or 1.0), float(getattr(base, "offset", 0.0) or 0.0))
    return out


def _conversion(source: str, target: str, definitions: Sequence[Mapping[str, _Unit]], context: str
                ) -> tuple[float, float]:
    """(factor, offset) converting a value in unit ``source`` to unit ``target``."""
    if source == target:
        return 1.0, 0.0
    found = []
    for unit in (source, target):
        definition = next((d[unit] for d in definitions if unit in d), None)
        if definition is None:
            raise SspError(f"{context}: cannot convert [{source}] to [{target}]: the unit {unit!r} has no definition "
                           "(in the SSD's <Units> or the FMU's unit definitions); suppressUnitConversion=\"true\" "
                           "connects without converting")
        found.append(definition)
    a, b = found
    if a.exponents != b.exponents:
        raise SspError(f"{context}: cannot convert [{source}] to [{target}]: different base units")
    return a.factor / b.factor, (a.offset - b.offset) / b.factor


# ------------------------------------------------------------------------------------ package
class _Package:
    """Where the SSD and its references live: an archive (members extracted on demand into a
    folder deleted with the system) or a folder holding a bare ``.ssd``."""

    def __init__(self, path: Path, system: SystemLike) -> None:
        self.path = path
        self.archive: SspArchive | None = None
        self.folder: Path | None = None
        if not path.is_file():
            raise SspError(f"{path}: no such file")
        if zipfile.is_zipfile(path) or path.suffix.lower() == ".ssp":
            self.archive = SspArchive(path)
            self.folder = Path(tempfile.mkdtemp(prefix="duffid-ssp-"))
            weakref.finalize(system, shutil.rmtree, str(self.folder), True)
        self.extracted: dict[str, Path] = {}

    def close(self) -> None:
        if self.archive is not None:
            self.archive.close()

    def ssd(self) -> XmlFile:
        if self.archive is None:
            return parse_xml(self.path.read_bytes(), str(self.path))
        if not self.archive.has(SSD_MEMBER):
            raise SspError(f"{self.path}: the archive has no {SSD_MEMBER} at its root")
        return self.archive.xml(SSD_MEMBER)

    def locate(self, xml: XmlFile, element: etree._Element, attribute: str) -> tuple[str, Any]:
        """("member", name) or ("file", Path) of the URI in ``element``'s ``attribute``."""
        reference = element.get(attribute)
        if not reference:
            raise SspError(f"{xml.where(element)}: no {attribute} attribute")
        parts = urllib.parse.urlsplit(reference)
        if parts.scheme == "file":
            return "file", Path(urllib.parse.unquote(parts.path))
        if parts.scheme or parts.netloc:
            raise SspError(f"{xml.where(element)}: {attribute}={reference!r}: only relative URIs and file: URIs are "
                           "supported")
        relative = urllib.parse.unquote(parts.path)
        if relative.startswith("/"):
            return "file", Path(relative)
        if self.archive is None:
            return "file", Path(xml.name).parent / relative
        member = resolve(xml.member or SSD_MEMBER, relative)
        if member == ".." or member.startswith("../"):  # beside the archive: the archive as a folder of its name
            return "file", self.path.parent / member[3:]
        if not self.archive.has(member):
            raise SspError(f"{xml.where(element)}: {attribute}={reference!r}: the archive has no member {member!r}")
        return "member", member

    def file(self, xml: XmlFile, element: etree._Element, attribute: str) -> Path:
        """A local file for the reference (an archive member is extracted once)."""
        kind, where_ = self.locate(xml, element, attribute)
        if kind == "file":
            if not where_.is_file():
                raise SspError(f"{xml.where(element)}: {attribute}={element.get(attribute)!r}: no such file {where_}")
            return where_
        if where_ not in self.extracted:
            assert self.archive is not None and self.folder is not None
            self.extracted[where_] = self.archive.extract(where_, self.folder)
        return self.extracted[where_]

    def xml(self, xml: XmlFile, element: etree._Element, attribute: str) -> XmlFile:
        """The XML file the reference names, parsed safely."""
        kind, where_ = self.locate(xml, element, attribute)
        if kind == "member":
            assert self.archive is not None
            return self.archive.xml(where_)
        if not where_.is_file():
            raise SspError(f"{xml.where(element)}: {attribute}={element.get(attribute)!r}: no such file {where_}")
        return parse_xml(where_.read_bytes(), str(where_))


# ------------------------------------------------------------------------------------ reading
def _check_fmu(path: Path, place: str) -> None:
    """An FMU from the SSP passes the same checks as the SSP itself before fmpy reads it: its
    member names, and its model description parsed safely (no DTD, no entities)."""
    with SspArchive(path) as fmu:
        if not fmu.has("modelDescription.xml"):
            raise SspError(f"{place}: {path.name} has no modelDescription.xml (not an FMU)")
        fmu.xml("modelDescription.xml")


@dataclass
class _Connector:
    name: str
    kind: str
    type: str | None
    unit: str | None
    place: str


@dataclass
class _Value:
    kind: str
    value: Any
    unit: str | None
    place: str
    definitions: tuple[Mapping[str, _Unit], ...] = ()
    then: tuple[float, float] = (1.0, 0.0)   # a mapping's linear transformation, after the unit conversion


@dataclass
class _Element:
    name: str
    fmu: Path
    md: Any
    place: str
    connectors: dict[str, _Connector] = field(default_factory=dict)
    bindings: list[tuple[XmlFile, etree._Element]] = field(default_factory=list)


class _Reader:
    def __init__(self, path: Path, system: SystemLike, parameter_set: Path | None = None,
                 parameters: Mapping[str, Any] | None = None) -> None:
        self.path, self.system, self.parameter_set = path, system, parameter_set
        self.overrides = {name: _python_value(name, value) for name, value in (parameters or {}).items()}
        if parameter_set is not None and not parameter_set.is_file():
            raise SspError(f"{parameter_set}: no such parameter set (.ssv) file")
        self.package = _Package(path, system)
        self.run = SspRun(path=path, system=system)
        self.units: dict[str, _Unit] = {}
        self.elements: dict[str, _Element] = {}
        self.system_connectors: dict[str, _Connector] = {}
        self.system_bindings: list[tuple[XmlFile, etree._Element]] = []
        self.connections: list[tuple[XmlFile, etree._Element]] = []
        self.tool_step: float | None = None

    # -- the SSD
    def read(self) -> SspRun:
        try:
            xml = self.package.ssd()
            root = xml.root
            if etree.QName(root).namespace != NS_SSD or local_name(root) != "SystemStructureDescription":
                raise SspError(f"{xml.where(root)}: not an SSD (expected <ssd:SystemStructureDescription> in "
                               f"namespace {NS_SSD})")
            if root.get("version") not in SSD_VERSIONS:
                raise SspError(f"{xml.where(root)}: version={root.get('version')!r}: duffid reads SSD versions "
                               f"{', '.join(SSD_VERSIONS)}")
            self.run.name = root.get("name", "")
            system = None
            for child in _children(xml, root, ("System", "Enumerations", "Units", "DefaultExperiment",
                                               "Annotations")):
                name = local_name(child)
                if name == "System":
                    system = child
                elif name == "Units":
                    _units(xml, child, self.units)
                elif name == "DefaultExperiment":
                    self._experiment(xml, child)
                elif name == "Annotations":
                    for content in _annotations(xml, child, self.run.warnings):
                        raise SspError(f"{xml.where(content)}: duffid's annotation belongs in <DefaultExperiment>")
            if system is None:
                raise SspError(f"{xml.where(root)}: no <System>")
            self._system(xml, system)
            if self.run.step is None:
                self.run.step = self.tool_step
            self._build()
        finally:
            self.package.close()
        return self.run

    def _experiment(self, xml: XmlFile, element: etree._Element) -> None:
        self.run.start_time = _number(xml, element, "startTime", 0.0)
        self.run.stop_time = _number(xml, element, "stopTime")
        for child in _children(xml, element, ("Annotations",)):
            for content in _annotations(xml, child, self.run.warnings):
                if etree.QName(content).namespace != NS_DUFFID or local_name(content) != "Run":
                    raise SspError(f"{xml.where(content)}: duffid's annotation holds one <duffid:Run> element "
                                   f"(namespace {NS_DUFFID})")
                unknown = sorted(set(content.attrib) - {"step", "ordering", "order"})
                if unknown:
                    raise SspError(f"{xml.where(content)}: unknown attribute(s) {unknown} (step, ordering, order)")
                step = _number(xml, content, "step")
                if step is not None and step <= 0:
                    raise SspError(f"{xml.where(content)}: step must be > 0")
                ordering = content.get("ordering", "jacobi")
                if ordering not in ORDERINGS:
                    raise SspError(f"{xml.where(content)}: ordering={ordering!r}: one of {', '.join(ORDERINGS)}")
                self.run.step, self.run.ordering = step, ordering
                order = content.get("order")
                self.run.order = order.split() if order is not None else None

    def _system(self, xml: XmlFile, element: etree._Element) -> None:
        for child in _children(xml, element, ("Connectors", "ParameterBindings", "Elements", "Connections",
                                              "Annotations", "SignalDictionaries")):
            name = local_name(child)
            if name == "Connectors":
                self.system_connectors = self._connectors(xml, child)
            elif name == "ParameterBindings":
                self.system_bindings += [(xml, b) for b in _children(xml, child, ("ParameterBinding",))]
            elif name == "Elements":
                for item in _children(xml, child, ("Component", "System", "SignalDictionaryReference")):
                    if local_name(item) != "Component":
                        raise SspError(f"{xml.where(item)}: {'nested systems' if local_name(item) == 'System' else 'signal dictionary references'} are not supported by duffid")
                    self._component(xml, item)
            elif name == "Connections":
                self.connections += [(xml, c) for c in _children(xml, child, ("Connection",))]
            elif name == "SignalDictionaries":
                raise SspError(f"{xml.where(child)}: signal dictionaries are not supported by duffid")
            else:
                self._system_annotations(xml, child)

    def _system_annotations(self, xml: XmlFile, element: etree._Element) -> None:
        """The top-level system's annotations: OMSimulator's fixed-step master gives the step
        (when duffid's annotation does not); a variable-step master or solver settings cannot
        be honoured (an error); everything else is reported."""
        for annotation in _children(xml, element, ("Annotation",)):
            if annotation.get("type") != OMSIMULATOR:
                continue
            found = [f"{xml.where(annotation)}: annotation of type {OMSIMULATOR!r}: only its fixed-step master is "
                     "understood by duffid, the rest was not applied"]
            for item in annotation.iter():
                name = local_name(item) if isinstance(item.tag, str) else ""
                if name in ("VariableStepMaster", "VariableStepSolver", "FixedStepSolver"):
                    raise SspError(f"{xml.where(item)}: OMSimulator's <{name}> cannot be honoured: duffid runs the "
                                   "co-simulation components at a fixed communication step")
                if name == "FixedStepMaster":
                    step = _number(xml, item, "stepSize")
                    if step is None or step <= 0:
                        raise SspError(f"{xml.where(item)}: stepSize must be a positive number")
                    self.tool_step = step
                    found.append(f"{xml.where(item)}: the communication step {step!r} s is taken from OMSimulator's "
                                 "fixed-step master (unless duffid's annotation or --step gives one)")
            self.run.warnings += found
        _annotations(xml, element, self.run.warnings, handled=(OMSIMULATOR,))

    def _connectors(self, xml: XmlFile, element: etree._Element) -> dict[str, _Connector]:
        out: dict[str, _Connector] = {}
        for connector in _children(xml, element, ("Connector",)):
            name, kind = connector.get("name"), connector.get("kind")
            if not name or not kind:
                raise SspError(f"{xml.where(connector)}: a connector needs a name and a kind")
            if name in out:
                raise SspError(f"{xml.where(connector)}: connector {name!r} is declared twice")
            type_, unit = None, None
            for child in _children(xml, connector, tuple(_TYPES) + ("Annotations", "Dimension")):
                tag = local_name(child)
                if tag == "Annotations":
                    _annotations(xml, child, self.run.warnings)
                    continue
                if tag == "Dimension" or _TYPES[tag] is None:
                    raise SspError(f"{xml.where(child)}: {'array' if tag == 'Dimension' else tag} connectors are not "
                                   "supported by duffid")
                type_, unit = tag, child.get("unit")
            out[name] = _Connector(name, kind, type_, unit, xml.where(connector))
        return out

    def _component(self, xml: XmlFile, element: etree._Element) -> None:
        import fmpy

        name = element.get("name")
        place = xml.where(element)
        if not name or not NAME_RE.match(name):
            raise SspError(f"{place}: duffid needs component names that are identifiers (letters, digits, _)")
        if name in self.elements:
            raise SspError(f"{place}: a second element named {name!r}")
        kind = element.get("type", _FMU_TYPE)
        if kind != _FMU_TYPE:
            raise SspError(f"{place}: type={kind!r}: duffid runs FMU components ({_FMU_TYPE}) only")
        implementation = element.get("implementation", "any")
        if implementation not in ("any", "CoSimulation"):
            raise SspError(f"{place}: implementation={implementation!r}: duffid runs co-simulation FMUs only "
                           "(Model Exchange components are not supported)")
        path = self.package.file(xml, element, "source")
        _check_fmu(path, place)
        try:
            md = fmpy.read_model_description(str(path))
        except Exception as exc:  # fmpy raises plain Exceptions for bad archives / XML
            raise SspError(f"{place}: cannot read the FMU {path.name}: {exc}") from None
        if md.coSimulation is None:
            raise SspError(f"{place}: {path.name} has no Co-Simulation interface (Model Exchange components are not "
                           "supported)")
        comp = _Element(name, path, md, place)
        variables = {v.name: v for v in md.modelVariables}
        for child in _children(xml, element, ("Connectors", "ParameterBindings", "Annotations")):
            tag = local_name(child)
            if tag == "Connectors":
                comp.connectors = self._connectors(xml, child)
                for connector in comp.connectors.values():
                    self._check_connector(comp, connector, variables)
            elif tag == "ParameterBindings":
                comp.bindings += [(xml, b) for b in _children(xml, child, ("ParameterBinding",))]
            else:
                _annotations(xml, child, self.run.warnings)
        self.elements[name] = comp

    @staticmethod
    def _check_connector(comp: _Element, connector: _Connector, variables: Mapping[str, Any]) -> None:
        variable = variables.get(connector.name)
        if variable is None:
            raise SspError(f"{connector.place}: the FMU {comp.fmu.name} of component {comp.name!r} has no variable "
                           f"{connector.name!r}")
        if variable.causality != connector.kind:
            raise SspError(f"{connector.place}: kind={connector.kind!r}, but {connector.name} is "
                           f"{variable.causality!r} in {comp.fmu.name}")
        if connector.type is not None and _TYPES[connector.type] != _FMI_KIND.get(variable.type):
            raise SspError(f"{connector.place}: declared {connector.type}, but {connector.name} is {variable.type} "
                           f"in {comp.fmu.name}")

    # -- parameter values
    def _binding_values(self, xml: XmlFile, binding: etree._Element) -> dict[str, _Value]:
        """name (prefix applied, mapping applied) -> value of one ParameterBinding."""
        place = xml.where(binding)
        self._check_reference(xml, binding, _SSV_TYPE, "parameter sets")
        values: dict[str, _Value] = {}
        inline = None
        mapping: list[tuple[str, str, bool, tuple[float, float] | None, str]] | None = None
        for child in _children(xml, binding, ("ParameterValues", "ParameterMapping", "Annotations")):
            tag = local_name(child)
            if tag == "ParameterValues":
                inline = next(_children(xml, child, ("ParameterSet",)), None)
                if inline is None:
                    raise SspError(f"{xml.where(child)}: no <ssv:ParameterSet> inside")
            elif tag == "ParameterMapping":
                mapping = self._mapping(xml, child)
            else:
                _annotations(xml, child, self.run.warnings)
        if binding.get("source") is not None:
            if inline is not None:
                raise SspError(f"{place}: both a source and inline <ParameterValues>")
            ssv = self.package.xml(xml, binding, "source")
            values = self._parameter_set(ssv, ssv.root)
        elif inline is not None:
            values = self._parameter_set(xml, inline)
        else:
            raise SspError(f"{place}: neither a source nor inline <ParameterValues>")
        prefix = binding.get("prefix", "")
        values = {prefix + name: value for name, value in values.items()}
        if mapping is None:
            return values
        mapped: dict[str, _Value] = {}
        for source, target, suppress, linear, where_ in mapping:
            if source not in values:
                raise SspError(f"{where_}: maps {source!r}, which the parameter set does not give")
            value = values[source]
            if linear is not None and value.kind != "Real":
                raise SspError(f"{where_}: a LinearTransformation applies to Real values, {source!r} is {value.kind}")
            # the transformation is applied after the unit conversion (SSP's parameter mapping)
            mapped[target] = _Value(value.kind, value.value, None if suppress else value.unit, where_,
                                    value.definitions, linear or (1.0, 0.0))
        return mapped

    def _transformation(self, xml: XmlFile, element: etree._Element) -> tuple[float, float] | None:
        """(factor, offset) of the ``LinearTransformation`` inside a connection or mapping
        entry (None without one); the other transformations are refused."""
        linear = None
        for child in _children(xml, element, ("LinearTransformation", "BooleanMappingTransformation",
                                              "IntegerMappingTransformation", "EnumerationMappingTransformation",
                                              "Annotations")):
            tag = local_name(child)
            if tag == "LinearTransformation":
                linear = (_number(xml, child, "factor", 1.0), _number(xml, child, "offset", 0.0))
            elif tag == "Annotations":
                _annotations(xml, child, self.run.warnings)
            else:
                raise SspError(f"{xml.where(child)}: {tag} is not supported by duffid (LinearTransformation is)")
        return linear

    @staticmethod
    def _check_reference(xml: XmlFile, element: etree._Element, mime: str, what: str) -> None:
        """A parameter source or mapping must be SSP's own format, relative to the SSD."""
        if element.get("type", mime) != mime:
            raise SspError(f"{xml.where(element)}: type={element.get('type')!r}: duffid reads {what} ({mime})")
        if element.get("sourceBase", "SSD") != "SSD":
            raise SspError(f"{xml.where(element)}: sourceBase={element.get('sourceBase')!r}: only sources relative "
                           "to the SSD are supported")

    def _mapping(self, xml: XmlFile, element: etree._Element) -> list[tuple[str, str, bool, tuple[float, float] | None, str]]:
        place = xml.where(element)
        self._check_reference(xml, element, _SSM_TYPE, "parameter mappings")
        if element.get("source") is not None:
            ssm = self.package.xml(xml, element, "source")
            root = ssm.root
        else:
            ssm = xml
            root = next(_children(xml, element, ("ParameterMapping",)), None)
            if root is None:
                raise SspError(f"{place}: neither a source nor an inline <ssm:ParameterMapping>")
        if etree.QName(root).namespace != NS_SSM or local_name(root) != "ParameterMapping":
            raise SspError(f"{ssm.where(root)}: not a parameter mapping (<ssm:ParameterMapping>)")
        out = []
        for entry in _children(ssm, root, ("MappingEntry", "Annotations")):
            if local_name(entry) == "Annotations":
                _annotations(ssm, entry, self.run.warnings)
                continue
            source, target = entry.get("source"), entry.get("target")
            if not source or not target:
                raise SspError(f"{ssm.where(entry)}: a mapping entry needs a source and a target")
            linear = self._transformation(ssm, entry)
            out.append((source, target, _boolean(ssm, entry, "suppressUnitConversion"), linear, ssm.where(entry)))
        return out

    def _parameter_set(self, xml: XmlFile, root: etree._Element) -> dict[str, _Value]:
        if etree.QName(root).namespace != NS_SSV or local_name(root) != "ParameterSet":
            raise SspError(f"{xml.where(root)}: not a parameter set (<ssv:ParameterSet>)")
        if root.get("version") not in SSD_VERSIONS:
            raise SspError(f"{xml.where(root)}: version={root.get('version')!r}: duffid reads versions "
                           f"{', '.join(SSD_VERSIONS)}")
        units: dict[str, _Unit] = {}
        parameters = []
        for child in _children(xml, root, ("Parameters", "Enumerations", "Units", "Annotations")):
            tag = local_name(child)
            if tag == "Parameters":
                parameters += list(_children(xml, child, ("Parameter",)))
            elif tag == "Units":
                _units(xml, child, units)
            elif tag == "Annotations":
                _annotations(xml, child, self.run.warnings)
        values: dict[str, _Value] = {}
        for parameter in parameters:
            name = parameter.get("name")
            if not name:
                raise SspError(f"{xml.where(parameter)}: a parameter needs a name")
            typed = [c for c in _children(xml, parameter, tuple(_TYPES) + ("Annotations",))
                     if local_name(c) != "Annotations"]
            if len(typed) != 1:
                raise SspError(f"{xml.where(parameter)}: a parameter needs exactly one value element")
            kind, value, unit = _typed_value(xml, typed[0])
            values[name] = _Value(kind, value, unit, xml.where(parameter), (units, self.units))
        return values

    # -- building the system
    def _build(self) -> None:
        # the values bound to each component variable: component level first, then system level (priority)
        bound: dict[str, dict[str, _Value]] = {name: {} for name in self.elements}
        system_values: dict[str, _Value] = {}
        for comp in self.elements.values():
            for xml, binding in comp.bindings:
                for name, value in self._binding_values(xml, binding).items():
                    if name not in {v.name for v in comp.md.modelVariables}:
                        raise SspError(f"{value.place}: component {comp.name!r} ({comp.fmu.name}) has no variable "
                                       f"{name!r} (SSP would ignore the value; duffid refuses it)")
                    bound[comp.name][name] = value
        sources = [self._binding_values(xml, binding) for xml, binding in self.system_bindings]
        if self.parameter_set is not None:  # the caller's, after the SSD's: it takes priority
            ssv = parse_xml(self.parameter_set.read_bytes(), str(self.parameter_set))
            sources.append(self._parameter_set(ssv, ssv.root))
        sources.append(self.overrides)
        for values in sources:
            for name, value in values.items():
                if name in self.system_connectors:
                    system_values[name] = value
                    continue
                head, _, rest = name.partition(".")
                comp = self.elements.get(head)
                if comp is None or not rest or rest not in {v.name for v in comp.md.modelVariables}:
                    raise SspError(f"{value.place}: {name!r} names no variable of the system (neither a system "
                                   "connector nor component.variable; SSP would ignore the value, duffid refuses it)")
                bound[head][rest] = value
        connections = [self._connection(xml, c) for xml, c in self.connections]
        connected = {t for kind, _, t, *_ in connections if kind == "connect"}
        for comp in self.elements.values():
            variables = {v.name: v for v in comp.md.modelVariables}
            parameters, inputs = {}, {}
            for name, value in bound[comp.name].items():
                variable = variables[name]
                converted = self._converted(value, variable, comp)
                if variable.causality == "input":
                    if f"{comp.name}.{name}" in connected:
                        raise SspError(f"{value.place}: binds a value to {comp.name}.{name}, an input that a "
                                       "connection drives: duffid cannot set the start value of a connected input")
                    inputs[name] = converted
                else:
                    parameters[name] = converted
            try:
                self.system.add(comp.name, comp.fmu, parameters=parameters)
            except WiringError as exc:
                raise WiringError(f"{comp.place}: {exc}") from None
            for name, value in inputs.items():
                self._wired(bound[comp.name][name].place, self.system.set_input, f"{comp.name}.{name}", value)
        for kind, source, target, factor, offset, check_units, place in connections:
            if kind == "connect":
                self._wired(place, self.system.connect, source, target, check_units=check_units, factor=factor,
                            offset=offset)
            elif kind == "output":
                self.run.interface["outputs"][target] = source
            else:  # from a system connector
                connector = self.system_connectors[source]
                if connector.kind == "input":
                    self.run.interface["inputs"].setdefault(source, []).append(target)
                value = system_values.get(source)
                if value is None:
                    if connector.kind != "input":
                        raise SspError(f"{place}: the system parameter {source!r} is given no value (bind one in the "
                                       "system's <ParameterBindings>)")
                    if (factor, offset) != (1.0, 0.0):
                        raise SspError(f"{place}: the system input {source!r} has no value and its connection a "
                                       "LinearTransformation: a container input cannot carry it")
                    self.run.warnings.append(f"{place}: the system input {source!r} is given no value: {target} keeps "
                                             "its start value in a run (it is an input of an exported container)")
                    continue
                if value.kind != "Real" and (factor, offset) != (1.0, 0.0):
                    raise SspError(f"{place}: a LinearTransformation applies to Real values")
                comp = self.elements[target.split(".", 1)[0]]
                variable = next(v for v in comp.md.modelVariables if v.name == target.split(".", 1)[1])
                number = self._converted(value, variable, comp)
                if value.kind == "Real":
                    number = factor * number + offset
                self._wired(place, self.system.set_input, target, number)

    @staticmethod
    def _wired(place: str, call: Callable[..., Any], *args: Any, **kwargs: Any) -> None:
        try:
            call(*args, **kwargs)
        except WiringError as exc:
            raise WiringError(f"{place}: {exc}") from None

    @staticmethod
    def _converted(value: _Value, variable: Any, comp: _Element) -> Any:
        """A bound value in the variable's unit (when both have one and they differ), then
        through its mapping's linear transformation."""
        if value.kind != "Real":
            return value.value
        number, target = value.value, unit_of(variable)
        if value.unit and target and value.unit != target:
            factor, offset = _conversion(value.unit, target, value.definitions + (_fmu_units(comp.md),),
                                         f"{value.place} -> {comp.name}.{variable.name}")
            number = factor * number + offset
        return value.then[0] * number + value.then[1]

    def _endpoint(self, xml: XmlFile, element: etree._Element, side: str) -> tuple[str | None, _Connector, Any]:
        """(component or None for the system, connector, fmpy variable or None) of one end."""
        name, connector = element.get(f"{side}Element"), element.get(f"{side}Connector")
        place = xml.where(element)
        if name is None:
            found = self.system_connectors.get(connector or "")
            if found is None:
                raise SspError(f"{place}: {side}Connector={connector!r}: the system declares no such connector")
            return None, found, None
        comp = self.elements.get(name)
        if comp is None:
            raise SspError(f"{place}: {side}Element={name!r}: no such component in the system")
        found = comp.connectors.get(connector or "")
        if found is None:
            raise SspError(f"{place}: {side}Connector={connector!r}: component {name!r} declares no such connector "
                           "(connected variables must be declared in its <Connectors>)")
        variable = next(v for v in comp.md.modelVariables if v.name == found.name)
        return name, found, variable

    def _connection(self, xml: XmlFile, element: etree._Element) -> tuple[str, str, str, float, float, bool, str]:
        """("connect", source, target, factor, offset, check_units, place), ("constant", system
        connector, target, factor, offset, _, place) or ("output", ...)."""
        place = xml.where(element)
        linear = self._transformation(xml, element) or (1.0, 0.0)
        suppress = _boolean(xml, element, "suppressUnitConversion")
        start, start_connector, start_variable = self._endpoint(xml, element, "start")
        end, end_connector, end_variable = self._endpoint(xml, element, "end")
        if end is None:
            if start is None or end_connector.kind != "output" or start_connector.kind != "output":
                raise SspError(f"{place}: duffid supports connections from a component output to a component input, "
                               "from a system input or parameter to a component input, and from a component output "
                               "to a system output")
            return "output", f"{start}.{start_connector.name}", end_connector.name, 1.0, 0.0, True, place
        if end_connector.kind != "input":
            raise SspError(f"{place}: the end {end}.{end_connector.name} is {end_connector.kind!r}, not an input "
                           "(connections run from outputs to inputs)")
        target = f"{end}.{end_connector.name}"
        if start is None:
            if start_connector.kind not in ("input", "parameter"):
                raise SspError(f"{place}: the system connector {start_connector.name!r} is {start_connector.kind!r}: "
                               "only system inputs and parameters can drive a component input")
            return "constant", start_connector.name, target, linear[0], linear[1], True, place
        if start_connector.kind not in ("output", "calculatedParameter", "local"):
            raise SspError(f"{place}: the start {start}.{start_connector.name} is {start_connector.kind!r}, not an "
                           "output")
        source_unit = start_connector.unit or unit_of(start_variable)
        target_unit = end_connector.unit or unit_of(end_variable)
        factor, offset, check_units = linear[0], linear[1], True
        if suppress:
            check_units = False
        elif source_unit and target_unit and source_unit != target_unit:
            definitions = (self.units, _fmu_units(self.elements[start].md), _fmu_units(self.elements[end].md))
            uf, uo = _conversion(source_unit, target_unit, definitions, place)
            factor, offset, check_units = linear[0] * uf, linear[0] * uo + linear[1], False
        return "connect", f"{start}.{start_connector.name}", target, factor, offset, check_units, place


def _python_value(name: str, value: Any) -> _Value:
    """A caller's parameter value as a bound value (its kind from its Python type)."""
    place = f"parameters[{name!r}]"
    if isinstance(value, bool):
        return _Value("Boolean", value, None, place)
    if isinstance(value, int):
        return _Value("Integer", value, None, place)
    if isinstance(value, float) and math.isfinite(value):
        return _Value("Real", value, None, place)
    if isinstance(value, str):
        return _Value("String", value, None, place)
    raise SspError(f"{place}: {value!r} is not a finite number, a bool or a string")


def read_ssp(path: str | os.PathLike[str], system: SystemLike, *, parameter_set: str | os.PathLike[str] | None = None,
             parameters: Mapping[str, Any] | None = None) -> SspRun:
    """Fill ``system`` (empty) from an SSP archive or a bare ``.ssd`` file.

    Parameters
    ----------
    path : str or os.PathLike
        ``.ssp`` archive (``SystemStructure.ssd`` at its root) or ``.ssd`` file.
    system : SystemLike
        An empty system, filled in place (FMUs inside an archive are extracted into a
        temporary folder deleted with the system).
    parameter_set : str or os.PathLike, optional
        An ``.ssv`` file applied as a system-level binding after the SSD's (names
        ``component.variable`` or system connectors; it takes priority).
    parameters : mapping, optional
        ``"component.variable"`` (or system connector) -> value, applied last (priority
        over everything): Real as float, Integer as int, Boolean as bool.

    Returns
    -------
    SspRun
        The system and the default experiment.

    Raises
    ------
    SspError
        What duffid cannot read or honour (see the module documentation), naming the file,
        line and element.
    WiringError
        A wiring error of the system, prefixed with the file, line and element it comes from.
    """
    if system.components:
        raise WiringError("read_ssp fills an empty system")
    return _Reader(Path(path), system, None if parameter_set is None else Path(parameter_set), parameters).read()


# ------------------------------------------------------------------------------------ writing
def _q(namespace: str, tag: str) -> str:
    return f"{{{namespace}}}{tag}"


def _literal(kind: str, value: Any) -> str:
    if kind == "Boolean":
        return "true" if value else "false"
    if kind == "Integer":
        return str(int(value))
    if kind == "Real":
        return repr(float(value))
    return str(value)


def _value_kind(variable: Any) -> str:
    return _FMI_KIND.get(variable.type, variable.type)


def _resources(system: SystemLike) -> dict[str, str]:
    """Component -> archive member of its FMU (one member per FMU file)."""
    members: dict[str, str] = {}
    by_file: dict[Path, str] = {}
    taken: set[str] = set()
    for name in system.components:
        path = system.fmu(name).resolve()
        if path not in by_file:
            stem, i = path.stem, 1
            member = f"resources/{stem}.fmu"
            while member in taken:
                i += 1
                member = f"resources/{stem}_{i}.fmu"
            taken.add(member)
            by_file[path] = member
        members[name] = by_file[path]
    return members


def _parameter_sets(system: SystemLike) -> dict[str, etree._Element]:
    """Component -> the ``ssv:ParameterSet`` of its parameter values and constant inputs
    (names relative to the component; components without values have none)."""
    sets: dict[str, etree._Element] = {}
    values = [(c, v, value) for c in system.components for v, value in system.parameter_values(c).items()]
    values += [(*full.split(".", 1), value) for full, value in system.constant_inputs.items()]
    for component, name, value in values:
        variable = system.variable(f"{component}.{name}")
        kind = _value_kind(variable)
        if kind not in ("Real", "Integer", "Boolean", "String"):
            raise WiringError(f"{component}.{name}: a {variable.type} value cannot be written to an SSV file")
        if component not in sets:
            sets[component] = etree.Element(_q(NS_SSV, "ParameterSet"), nsmap={"ssv": NS_SSV, "ssc": NS_SSC},
                                            version="1.0", name=PARAMETER_SET)
            etree.SubElement(sets[component], _q(NS_SSV, "Parameters"))
        parameter = etree.SubElement(sets[component][0], _q(NS_SSV, "Parameter"), name=name)
        etree.SubElement(parameter, _q(NS_SSV, kind), value=_literal(kind, value))
    return sets


def _ssd(system: SystemLike, name: str, members: Mapping[str, str], parameter_files: Mapping[str, str],
         start_time: float, stop_time: float, step: float, ordering: str, order: Sequence[str] | None
         ) -> etree._Element:
    root = etree.Element(_q(NS_SSD, "SystemStructureDescription"), nsmap={"ssd": NS_SSD, "ssc": NS_SSC},
                         version="1.0", name=name, generationTool="duffid")
    ssd_system = etree.SubElement(root, _q(NS_SSD, "System"), name=name)
    connected: dict[str, list[str]] = {c: [] for c in system.components}
    for connection in system.connections:
        for full in (connection.source, connection.target):
            component, variable = full.split(".", 1)
            if variable not in connected[component]:
                connected[component].append(variable)
    units: dict[str, Any] = {}
    elements = etree.SubElement(ssd_system, _q(NS_SSD, "Elements"))
    for component in system.components:
        element = etree.SubElement(elements, _q(NS_SSD, "Component"), name=component, source=members[component],
                                   type=_FMU_TYPE, implementation="CoSimulation")
        definitions = {u.name: u for u in getattr(system.model_description(component), "unitDefinitions", None) or []}
        connectors = etree.SubElement(element, _q(NS_SSD, "Connectors")) if connected[component] else None
        if component in parameter_files:
            bindings = etree.SubElement(element, _q(NS_SSD, "ParameterBindings"))
            etree.SubElement(bindings, _q(NS_SSD, "ParameterBinding"), type=_SSV_TYPE, source=parameter_files[component])
        for variable_name in connected[component]:
            variable = system.variable(f"{component}.{variable_name}")
            connector = etree.SubElement(connectors, _q(NS_SSD, "Connector"), name=variable_name,
                                         kind=variable.causality)
            typed = etree.SubElement(connector, _q(NS_SSC, _value_kind(variable)))
            unit = unit_of(variable)
            if unit and _value_kind(variable) == "Real" and unit in definitions and \
                    getattr(definitions[unit], "baseUnit", None) is not None:
                typed.set("unit", unit)
                units.setdefault(unit, definitions[unit].baseUnit)
    if system.connections:
        connections = etree.SubElement(ssd_system, _q(NS_SSD, "Connections"))
        for connection in system.connections:
            start_element, start_connector = connection.source.split(".", 1)
            end_element, end_connector = connection.target.split(".", 1)
            item = etree.SubElement(connections, _q(NS_SSD, "Connection"), startElement=start_element,
                                    startConnector=start_connector, endElement=end_element,
                                    endConnector=end_connector)
            if not connection.check_units:
                item.set("suppressUnitConversion", "true")
            if connection.transformed:
                etree.SubElement(item, _q(NS_SSC, "LinearTransformation"), factor=repr(connection.factor),
                                 offset=repr(connection.offset))
    if units:
        units_element = etree.SubElement(root, _q(NS_SSD, "Units"))
        for unit, base in units.items():
            unit_element = etree.SubElement(units_element, _q(NS_SSC, "Unit"), name=unit)
            attributes = {b: str(int(getattr(base, b, 0) or 0)) for b in _BASE if int(getattr(base, b, 0) or 0)}
            factor, offset = float(getattr(base, "factor", 1.0) or 1.0), float(getattr(base, "offset", 0.0) or 0.0)
            if factor != 1.0:
                attributes["factor"] = repr(factor)
            if offset != 0.0:
                attributes["offset"] = repr(offset)
            etree.SubElement(unit_element, _q(NS_SSC, "BaseUnit"), **attributes)
    experiment = etree.SubElement(root, _q(NS_SSD, "DefaultExperiment"), startTime=repr(float(start_time)),
                                  stopTime=repr(float(stop_time)))
    annotations = etree.SubElement(experiment, _q(NS_SSD, "Annotations"))
    annotation = etree.SubElement(annotations, _q(NS_SSC, "Annotation"), type=ANNOTATION)
    run = etree.SubElement(annotation, _q(NS_DUFFID, "Run"), nsmap={"duffid": NS_DUFFID}, step=repr(float(step)),
                           ordering=ordering)
    if order is not None:
        run.set("order", " ".join(order))
    return root


def _bytes(root: etree._Element) -> bytes:
    return etree.tostring(root, xml_declaration=True, encoding="UTF-8", pretty_print=True)


def write_ssp(system: SystemLike, path: str | os.PathLike[str], *, stop_time: float, step: float,
              start_time: float = 0.0, ordering: str = "jacobi", order: Sequence[str] | None = None) -> Path:
    """Write ``system`` as an SSP 1.0 archive (see the module documentation).

    Parameters
    ----------
    system : SystemLike
        The system: its external inputs must be constants (SSP carries values, not signals).
    path : str or os.PathLike
        The ``.ssp`` file to write (its stem names the SSD and the system).
    stop_time, step, start_time : float
        The default experiment and the communication step (duffid's annotation).
    ordering : {"jacobi", "gauss-seidel"}
        The master, in duffid's annotation.
    order : sequence of str, optional
        The Gauss-Seidel order, in duffid's annotation.

    Returns
    -------
    Path
        The archive written.

    Raises
    ------
    WiringError
        An empty system, an input driven by a function or by samples, bad times or ordering.
    """
    path = Path(path)
    if not system.components:
        raise WiringError("the system has no components")
    for value, label in ((stop_time, "stop_time"), (step, "step"), (start_time, "start_time")):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise WiringError(f"{label} must be a finite number, got {value!r}")
    if step <= 0 or stop_time <= start_time:
        raise WiringError(f"the export needs step > 0 and stop_time > start_time (got step {step!r}, "
                          f"start {start_time!r}, stop {stop_time!r})")
    if ordering not in ORDERINGS:
        raise WiringError(f"ordering must be one of {ORDERINGS}, got {ordering!r}")
    if order is not None and ordering != "gauss-seidel":
        raise WiringError("order= applies to ordering='gauss-seidel' only")
    varying = {t: mode for t, mode in system.external_inputs.items() if mode != "constant"}
    if varying:
        target, mode = next(iter(varying.items()))
        raise WiringError(f"the input {target} is driven by {'a function' if mode == 'function' else 'samples'}: an "
                          "SSP carries constant inputs only (as parameter values); drive it with a constant, or "
                          "from a component")
    for full in [end for c in system.connections for end in (c.source, c.target)] + \
            [f"{c}.{p}" for c in system.components for p in system.parameter_values(c)] + \
            list(system.constant_inputs):
        if "[" in full or getattr(system.variable(full), "dimensions", None):
            raise WiringError(f"{full} is an array or an array element: SSP 1.0 has no arrays (duffid writes "
                              "SSP 1.0); run the system with System.run")
    name = path.stem or "system"
    members = _resources(system)
    sets = _parameter_sets(system)
    files = {component: f"resources/{component}.ssv" for component in sets}
    ssd = _ssd(system, name, members, files, start_time, stop_time, step, ordering, order)
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(path.name + ".part")
    contents = {SSD_MEMBER: _bytes(ssd)}
    contents.update({files[component]: _bytes(parameter_set) for component, parameter_set in sets.items()})
    contents.update({member: system.fmu(component).read_bytes() for component, member in members.items()})
    with zipfile.ZipFile(partial, "w") as archive:
        for member, data in contents.items():  # a fixed date: the same system gives the same bytes
            archive.writestr(zipfile.ZipInfo(member, date_time=(1980, 1, 1, 0, 0, 0)), data,
                             compress_type=zipfile.ZIP_DEFLATED)
    os.replace(partial, path)
    return path
