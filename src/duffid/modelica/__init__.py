"""Modelica to FMU translation (:mod:`duffid.modelica.export` is the entry point).

Modules, in pipeline order: :mod:`.source` (files, class index, unsupported
constructs), :mod:`.pymoca_fixes`, :mod:`.arrays` (component arrays),
:mod:`.flat_model` (pymoca front end to scalar CasADi SX), :mod:`.causalize` (DAE to
ODE), :mod:`.table` (value references), :mod:`.codegen` (C code); then
:mod:`duffid.fmu` writes modelDescription.xml, compiles and zips. The FMI glue in C
lives in ``fmus/common``.
"""
from __future__ import annotations

from ..errors import MissingDependencyError, ModelicaExportError

try:
    import pymoca  # noqa: F401  (the optional dependency of this package)
except ImportError as _missing:  # pragma: no cover - exercised in a subprocess by the tests
    raise MissingDependencyError("the Modelica export needs pymoca 0.12.0, an optional dependency: "
                                 "pip install 'duffid[modelica]'") from _missing

from .causalize import OdeModel, causalize
from .flat_model import FlatModel, Variable, flatten_model

__all__ = ["ModelicaExportError", "FlatModel", "Variable", "flatten_model", "OdeModel", "causalize"]
