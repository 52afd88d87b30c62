"""duffid's exceptions: one base, :class:`DuffidError`, and a family per layer.

Every error duffid raises for a problem with the user's input, files, models or tools
derives from :class:`DuffidError`; the ``duffid`` command reports those as one line in
its own voice (exit status 2) and lets anything else surface as the bug it is. Each
class also derives from the built-in exception a caller would expect (``ValueError``
for bad values, ``TypeError`` for unknown options, ``RuntimeError`` for failures of a
solver, a compiler or an FMU), so ``except ValueError`` keeps working.
"""
from __future__ import annotations

from typing import Any

__all__ = ["DuffidError", "InputError", "OptionError", "RecordError", "SimulationError", "EquationError",
           "ModelicaExportError", "MissingDependencyError", "BuildError", "CompilerNotFoundError", "AssetError", "WiringError",
           "CosimError", "ConfigError"]


class DuffidError(Exception):
    """Base of every error duffid raises on purpose (bad input, failed tools)."""


class InputError(DuffidError, ValueError):
    """An argument, option value or setting out of range or unknown; the message names it."""


class OptionError(DuffidError, TypeError):
    """An option or keyword argument the function does not have, or of the wrong type;
    the message lists those it has."""


class RecordError(DuffidError, ValueError):
    """Bad record data or record file.

    The message always names the source (a file path or ``'array input'``),
    the place (line of a CSV file with the header on line 1, row of a MATLAB
    variable, or sample index of an array) and/or the column or variable, and
    what is wrong.
    """


class SimulationError(DuffidError, RuntimeError):
    """The ODE solver failed or the response left any physical range."""


class EquationError(InputError):
    """An equation that cannot be parsed or integrated by parts; the message names the term."""


class ModelicaExportError(DuffidError, RuntimeError):
    """A model uses a construct outside the supported subset, or cannot be translated.

    The message names the construct, the Modelica class and the source line where
    they are known; the export never writes an FMU after this error.
    """


class MissingDependencyError(DuffidError, ImportError):
    """An optional dependency a feature needs is not installed (the message says how to install it)."""


class BuildError(DuffidError, RuntimeError):
    """The C compiler failed (the message holds the command and the compiler's output)."""


class CompilerNotFoundError(BuildError):
    """No C compiler was found (``$CC``, cc, gcc or clang)."""


class AssetError(DuffidError, FileNotFoundError):
    """duffid's package data (C sources, Modelica library) is missing: an incomplete installation."""


class WiringError(DuffidError, ValueError):
    """A system that cannot be built: unknown component or variable, wrong causality,
    type or unit mismatch, an input driven twice, a bad parameter or input source."""


class ConfigError(DuffidError, ValueError):
    """A configuration file that cannot be used; the message names the file and the entry."""


class CosimError(DuffidError, RuntimeError):
    """A co-simulation run stopped by a failure.

    Attributes
    ----------
    result : duffid.cosim.elements.Result or None
        What was recorded up to the last complete communication point.
    failure : duffid.cosim.elements.Failure
        Component, FMU, time, function, status and logged messages.
    """

    def __init__(self, failure: Any, result: Any = None) -> None:
        super().__init__(str(failure))
        self.failure = failure
        self.result = result
