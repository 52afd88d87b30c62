"""The online identifier as C co-simulation FMUs (FMI 2.0 and 3.0) on the shared FMI glue.

:func:`build_estimator_fmus` compiles the portable estimator core
(``fmus/estimator/duffid_estimator.c``, ``duffid_linalg.c``) with the discrete-time FMU
model ``fmus/estimator/fmu_model_estimator.c`` and the glue of ``fmus/common`` into

- ``DuffingEstimator1.fmu`` (FMI 2.0 CS) and ``DuffingEstimator1_fmi3.fmu`` (FMI 3.0 CS):
  inputs ``x``, ``f``; outputs ``m_hat``, ``b_hat``, ``k_hat``, ``kp_hat``;
- ``DuffingEstimator2.fmu`` and ``DuffingEstimator2_fmi3.fmu``: inputs ``x1``, ``x2``,
  ``f1``; outputs ``m1_hat``, ``b1_hat``, ``k1_hat``, ``kp1_hat``, ``b2_hat``, ``k2_hat``,
  ``kp2_hat``, ``m2_hat``;

each also with the outputs ``identified`` (0/1), ``condition``, ``uncertainty``,
``window_length`` [s] and ``<name>_status`` per parameter (Integer: the index of its status
in :data:`duffid.identification.engine.STATUSES`: 0 uncertain, 1 published, 2 not excited,
3 lost) and ``outliers`` (Integer: isolated displacement outliers excluded, each logged
with its time), and adds the pythonfmu fallbacks of :mod:`duffid.fmu.python_estimator`. The parameters
``<name>_nominal`` are optional prior sizes (0: none, the scale comes from the data).

Interface differences to the pythonfmu FMU: the glue has no String variables, so the
options ``method`` (0 robust, 1 paper), ``rows`` (0 integrals, 1 bernstein, 2 paper) and
``quadrature`` (0 adams3, 1 trapezoid) are Integer (FMI 3: Int32) codes; ``n_rows`` is
Integer, ``sign_in_numerator`` and ``identified`` Boolean as there; all parameters are
``fixed`` (set them before initialisation ends). Start values are ``duffid_default_config``'s (those of
identify()); an option left at its start value keeps the default of the chosen method.

Semantics are those of the pythonfmu FMU: each ``doStep(t, h)`` consumes the inputs set
for time ``t`` with ``h`` as sampling period; the first step fixes the period (and builds
the estimator, its only allocation), a later step of another size fails with Discard and
a logged error; non-finite inputs are rejected when set (Error, logged). Estimates are
NaN unless published. To identify a record of ``n`` samples, simulate from ``t[0]`` to
``t[-1] + dt`` with communication step ``dt``.
"""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

from ..assets import fmu_sources
from ..cbuild import Platform
from ..errors import InputError
from ..identification.engine import status_codes
from ..identification.options import ONLINE_METHODS, fmu_parameters
from ..models.chain import Duffing1, Duffing2
from .c_model import build_c_model_fmu
from .python_estimator import build_python_fmu
from .variables import FmuVariable

__all__ = ["build_estimator_fmus", "build_estimator_fmu", "estimator_variables", "variable_types",
           "C_FMU_NAMES", "OPTIONS", "TYPES"]

#: Model name -> model identifier of the C FMUs (FMI 3 files get a ``_fmi3`` suffix).
C_FMU_NAMES = {"duffing1": "DuffingEstimator1", "duffing2": "DuffingEstimator2"}
_CODES = {"duffing1": 1, "duffing2": 2}
_INPUTS = {"duffing1": (("x", "m", "displacement of the mass"), ("f", "N", "force on the mass")),
           "duffing2": (("x1", "m", "displacement of m1"), ("x2", "m", "displacement of m2"),
                        ("f1", "N", "force on m1"))}
_PARAM_UNITS = {"m": "kg", "b": "N.s/m", "k": "N/m", "kp": "N/m3"}
#: Parameters in value-reference order (name, unit, description): the method, then the
#: options of the schema (duffid.identification.options), which also generates the C table.
OPTIONS = (("method", None, "identification method: " + ", ".join(f"{i} {m}" for i, m in enumerate(ONLINE_METHODS))),
           *((o.name, o.unit, o.coded_description) for o in fmu_parameters()))
#: Variables that are not Float64 (and every ``<name>_status``: Integer).
TYPES = {"method": "Integer", "identified": "Boolean",
         **{o.name: "Boolean" if o.kind == "bool" else "Integer" for o in fmu_parameters() if o.c_kind == "CODE"}}


def variable_types(model_name: str) -> dict[str, str]:
    """:data:`TYPES` with the ``<name>_status`` outputs of the model."""
    model = Duffing1() if model_name == "duffing1" else Duffing2()
    return {**TYPES, "outliers": "Integer", **{f"{name}_status": "Integer" for name in model.parameters}}
_CORE_FILES = ("duffid_estimator.c", "duffid_estimator.h", "duffid_options.h", "duffid_linalg.c", "duffid_linalg.h",
               "fmu_model_estimator.c")


def _param_unit(name: str) -> str:
    return _PARAM_UNITS[name.rstrip("0123456789")]


def _defaults(model_name: str) -> dict[str, float]:
    """Parameter start values: the robust method and the schema's defaults as the C core codes them."""
    values = {"method": 0.0, **{o.name: float(o.c_default) for o in fmu_parameters()}}
    model = Duffing1() if model_name == "duffing1" else Duffing2()
    values.update({f"{name}_nominal": 0.0 for name in model.parameters})
    return values


def estimator_variables(model_name: str) -> list[FmuVariable]:
    """The variable table of an estimator FMU (value references 0, 1, ...)."""
    if model_name not in C_FMU_NAMES:
        raise InputError(f"unknown model {model_name!r}; choose {', '.join(C_FMU_NAMES)}")
    model = Duffing1() if model_name == "duffing1" else Duffing2()
    defaults = _defaults(model_name)
    table: list[FmuVariable] = []

    def add(name: str, causality: str, variability: str, initial: str | None, start: float | None,
            unit: str | None, description: str) -> None:
        table.append(FmuVariable(name=name, vr=len(table), causality=causality, variability=variability,
                                 initial=initial, start=start, internal_start=start if start is not None
                                 else float("nan"), unit=unit, description=description))

    add("time", "independent", "continuous", None, None, "s", "simulation time")
    for name, unit, text in _INPUTS[model_name]:
        add(name, "input", "continuous", None, 0.0, unit, f"{text} (one sample per doStep)")
    for name in model.parameters:
        add(f"{name}_hat", "output", "discrete", "calculated", None, _param_unit(name),
            f"estimate of {name} (NaN unless published)")
    add("identified", "output", "discrete", "calculated", None, None, "1 when every estimate is trustworthy")
    add("condition", "output", "discrete", "calculated", None, "1", "largest condition number of the equations")
    add("uncertainty", "output", "discrete", "calculated", None, "1", "largest relative standard error (robust)")
    add("window_length", "output", "discrete", "calculated", None, "s", "window length")
    for name in model.parameters:
        add(f"{name}_status", "output", "discrete", "calculated", None, None,
            f"status of {name}: {status_codes()}")
    add("outliers", "output", "discrete", "calculated", None, None,
        "isolated displacement outliers excluded so far (each one logged, category logStatusWarning)")
    for name, unit, text in OPTIONS:
        add(name, "parameter", "fixed", "exact", defaults[name], unit, text)
    for name in model.parameters:
        add(f"{name}_nominal", "parameter", "fixed", "exact", defaults[f"{name}_nominal"], _param_unit(name),
            f"optional prior size of {name} for the trust test (0: none, the scale comes from the data)")
    return table


def build_estimator_fmu(model_name: str, out_dir: str | Path, fmi_version: int = 2,
                        compiler: str | None = None, platforms: Sequence[Platform] | None = None) -> Path:
    """Build one C estimator FMU.

    Parameters
    ----------
    model_name : str
        ``"duffing1"`` or ``"duffing2"``.
    out_dir : str or Path
        Output folder; the file is ``<identifier>.fmu`` (FMI 2) or ``<identifier>_fmi3.fmu``.
    fmi_version : int
        2 or 3.
    compiler : str
        C compiler; default: the one :func:`duffid.cbuild.find_compiler` finds.
    platforms : sequence of Platform, optional
        Targets of the binaries (default: this machine; see :func:`duffid.cbuild.resolve_platforms`).

    Returns
    -------
    Path
        The FMU written.
    """
    table = estimator_variables(model_name)
    model = "Duffing1" if model_name == "duffing1" else "Duffing2"
    return build_c_model_fmu(out_dir, C_FMU_NAMES[model_name], fmi_version, table, prefix="estimator",
                             model_dir=fmu_sources("estimator"), model_files=_CORE_FILES,
                             description=f"duffid online algebraic identification of {model} (C estimator core)",
                             types=variable_types(model_name), defines={"MODEL": _CODES[model_name]},
                             compiler=compiler, platforms=platforms)


def build_estimator_fmus(out_dir: str | Path = Path("build/fmus"), *, python: bool = True,
                         platforms: Sequence[Platform] | None = None) -> list[Path]:
    """Build the four C estimator FMUs and (``python=True``) the two pythonfmu fallbacks.

    Parameters
    ----------
    out_dir : str or Path
        Output folder (created).
    python : bool
        Also build ``DuffingEstimator{1,2}_python.fmu`` (needs pythonfmu).
    platforms : sequence of Platform, optional
        Targets of the C FMUs' binaries (default: this machine).

    Returns
    -------
    list of Path
        The FMUs written.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = [build_estimator_fmu(name, out_dir, version, platforms=platforms) for name in C_FMU_NAMES for version in (2, 3)]
    if python:

        paths += [build_python_fmu(name, out_dir) for name in C_FMU_NAMES]
    return paths
