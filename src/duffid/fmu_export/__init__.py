"""Modelica to FMU translation: the machinery behind :mod:`duffid.modelica`.

Modules, in pipeline order: :mod:`.source` (files, class index, unsupported
constructs), :mod:`.pymoca_fixes`, :mod:`.arrays` (component arrays),
:mod:`.flat_model` (pymoca front end to scalar CasADi SX), :mod:`.causalize` (DAE to
ODE), :mod:`.variables` (value references), :mod:`.codegen` (C code),
:mod:`.fmi_xml` (modelDescription / buildDescription) and :mod:`.package`
(compile and zip). The FMI glue in C lives in ``fmus/common``.
"""
from __future__ import annotations

from .causalize import OdeModel, causalize
from .errors import ModelicaExportError
from .flat_model import FlatModel, Variable, flatten_model

__all__ = ["ModelicaExportError", "FlatModel", "Variable", "flatten_model", "OdeModel", "causalize"]
