"""The error raised for Modelica models the FMU export cannot translate faithfully."""
from __future__ import annotations

__all__ = ["ModelicaExportError"]


class ModelicaExportError(RuntimeError):
    """A model uses a construct outside the supported subset, or cannot be translated.

    The message names the construct, the Modelica class and the source line where
    they are known; the export never writes an FMU after this error.
    """
