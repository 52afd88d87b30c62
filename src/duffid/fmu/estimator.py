"""The online identifier as C co-simulation FMUs (FMI 2.0 and 3.0) on the shared FMI glue.

:func:`build_estimator_fmus` compiles the portable estimator core
(``fmus/estimator/duffid_estimator.c``, ``duffid_linalg.c``) with the discrete-time FMU
model ``fmus/estimator/fmu_model_estimator.c`` and the glue of ``fmus/common`` into

- ``DuffingEstimator1.fmu`` (FMI 2.0 CS) and ``DuffingEstimator1_fmi3.fmu`` (FMI 3.0 CS):
  inputs ``x``, ``f``; outputs ``m_hat``, ``b_hat``, ``k_hat``, ``kp_hat``;
- ``DuffingEstimator2.fmu`` and ``DuffingEstimator2_fmi3.fmu``: inputs ``x1``, ``x2``,
  ``f1``; outputs ``m1_hat``, ``b1_hat``, ``k1_hat``, ``kp1_hat``, ``b2_hat``, ``k2_hat``,
  ``kp2_hat``, ``m2_hat``;
- ``DuffingCircuitEstimator.fmu`` and ``DuffingCircuitEstimator_fmi3.fmu`` (the series circuit
  ``L q'' + R q' + q/C + a q^3 = u``, :class:`~duffid.models.chain.DuffingCircuit`): inputs
  ``q`` [C], ``u`` [V]; outputs ``L_hat`` [H], ``R_hat`` [Ohm], ``C_hat`` [F], ``a_hat``
  [V/C3] (the Duffing1 core; C is output as the reciprocal of its stiffness);

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
for time ``t``; ``h`` must equal the parameter ``sample_period`` [s] (start value
:data:`~duffid.fmu.estimator_table.DEFAULT_SAMPLE_PERIOD`, the default experiment's step
size), otherwise the step fails with Discard and a logged error naming both values (a step
of several periods too: the samples in between are unknown). The first step builds the
estimator, its only allocation; non-finite inputs are rejected when set (Error, logged).
Estimates are NaN unless published. To identify a record of ``n`` samples, set
``sample_period`` to its ``dt`` and simulate from ``t[0]`` to ``t[-1] + dt`` with
communication step ``dt``. The variable table is :mod:`duffid.fmu.estimator_table`.
"""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

from ..assets import fmu_sources
from ..cbuild import Platform
from .c_model import build_c_model_fmu
from .estimator_table import (
    C_FMU_NAMES,
    DEFAULT_SAMPLE_PERIOD,
    MODEL_CODES,
    MODELS,
    RECIPROCAL,
    estimator_variables,
    variable_types,
)
from .python_estimator import FMU_NAMES, build_python_fmu

__all__ = ["build_estimator_fmus", "build_estimator_fmu"]

_CORE_FILES = ("duffid_estimator.c", "duffid_estimator.h", "duffid_model.h", "duffid_options.h", "duffid_linalg.c",
               "duffid_linalg.h",
               "fmu_model_estimator.c")


def build_estimator_fmu(model_name: str, out_dir: str | Path, fmi_version: int = 2,
                        compiler: str | None = None, platforms: Sequence[Platform] | None = None) -> Path:
    """Build one C estimator FMU.

    Parameters
    ----------
    model_name : str
        ``"duffing1"``, ``"duffing2"`` or ``"circuit"``.
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
    names = list(MODELS[model_name]().parameters)
    mask = sum(1 << names.index(p) for p in RECIPROCAL.get(model_name, ()))
    model = type(MODELS[model_name]()).__name__
    return build_c_model_fmu(out_dir, C_FMU_NAMES[model_name], fmi_version, table, prefix="estimator",
                             model_dir=fmu_sources("estimator"), model_files=_CORE_FILES,
                             description=f"duffid online algebraic identification of {model} (C estimator core)",
                             types=variable_types(model_name),
                             defines={"MODEL": MODEL_CODES[model_name], "RECIPROCAL_MASK": mask},
                             sample_period=DEFAULT_SAMPLE_PERIOD, compiler=compiler, platforms=platforms)


def build_estimator_fmus(out_dir: str | Path = Path("build/fmus"), *, python: bool = True,
                         platforms: Sequence[Platform] | None = None) -> list[Path]:
    """Build the C estimator FMUs (FMI 2 and 3 of every model of
    :data:`~duffid.fmu.estimator_table.C_FMU_NAMES`) and (``python=True``) the pythonfmu
    fallbacks of the Duffing models.

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
    paths = [build_estimator_fmu(name, out_dir, version, platforms=platforms)
             for name in C_FMU_NAMES for version in (2, 3)]
    if python:
        paths += [build_python_fmu(name, out_dir) for name in FMU_NAMES]
    return paths
