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

- the estimator of any chain (:func:`build_chain_fmu`) or of the user's own equations
  (:func:`build_equation_fmu`): inputs the equations' displacements and forces, outputs
  ``<param>_hat`` with the units that follow from the signals' units
  (:func:`duffid.fmu.estimator_table.equation_interface`); the core runs the model's generated
  description (:func:`duffid.identification.c_core.model_source`, shipped in ``sources/`` as
  ``estimator_model.c`` with a ``duffid_build.h`` that selects it, so ``fmpy compile``
  rebuilds the FMU). ``backend="auto"`` builds the pythonfmu FMU of
  :mod:`duffid.fmu.python_estimator` instead when there is no C compiler;

each also with the outputs ``identified`` (0/1), ``condition``, ``uncertainty``,
``window_length`` [s] and ``<name>_status`` per parameter (Integer: the index of its status
in :data:`duffid.identification.engine.STATUSES`: 0 uncertain, 1 published, 2 not excited,
3 lost, 4 changed) and ``outliers`` (Integer: isolated displacement outliers excluded, each logged
with its time), ``<name>_std_error`` (the standard error of each published estimate) and
``residual`` (the window's one-step prediction error relative to its force balance), and adds the pythonfmu fallbacks of :mod:`duffid.fmu.python_estimator`. The parameters
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

import sys
from pathlib import Path
from typing import Mapping, Sequence

from ..assets import fmu_sources
from ..cbuild import Platform, find_compiler
from ..errors import CompilerNotFoundError, InputError
from ..identification.options import ENGINES
from .c_model import build_c_model_fmu
from .estimator_table import (
    C_FMU_NAMES,
    DEFAULT_SAMPLE_PERIOD,
    MOTION_INPUTS,
    EstimatorInterface,
    builtin_interface,
    chain_interface,
    equation_interface,
    estimator_variables,
    variable_types,
)
from .python_estimator import FMU_NAMES, build_python_fmu

__all__ = ["build_estimator_fmus", "build_estimator_fmu", "build_equation_fmu", "build_chain_fmu",
           "GENERATED_MODEL_FILE"]

_CORE_FILES = ("duffid_estimator.c", "duffid_estimator.h", "duffid_model.h", "duffid_build.h", "duffid_options.h", "duffid_facts.h",
               "duffid_linalg.c", "duffid_linalg.h", "fmu_model_estimator.c")
#: File of an FMU's ``sources/`` that holds the generated model (chains, equations).
GENERATED_MODEL_FILE = "estimator_model.c"
#: Backends of :func:`build_equation_fmu` and :func:`build_chain_fmu`.


def build_estimator_fmu(model: str | EstimatorInterface, out_dir: str | Path, fmi_version: int = 2,
                        compiler: str | None = None, platforms: Sequence[Platform] | None = None) -> Path:
    """Build one C estimator FMU.

    Parameters
    ----------
    model : str or EstimatorInterface
        ``"duffing1"``, ``"duffing2"`` or ``"circuit"``, or the interface of a chain or of
        equations (:func:`~duffid.fmu.estimator_table.chain_interface`,
        :func:`~duffid.fmu.estimator_table.equation_interface`).
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

    Raises
    ------
    InputError
        A model beyond the limits of the C core (the message names the limit).
    CompilerNotFoundError, BuildError
        No C compiler, or compilation failed.
    """
    interface = model if isinstance(model, EstimatorInterface) else builtin_interface(model)
    names = list(interface.parameters)
    mask = sum(1 << names.index(p) for p in interface.reciprocal)
    generated: dict[str, str] = {}
    if interface.kind != "builtin":
        from ..identification.c_core import BUILD_HEADER, GENERATED_BUILD_HEADER, model_source

        generated = {GENERATED_MODEL_FILE: model_source(interface.model()), BUILD_HEADER: GENERATED_BUILD_HEADER}
    table = estimator_variables(interface)
    return build_c_model_fmu(out_dir, interface.identifier, fmi_version, table, prefix="estimator",
                             model_dir=fmu_sources("estimator"), model_files=_CORE_FILES, generated_files=generated,
                             description=f"{interface.description} (C estimator core)",
                             types=variable_types(interface),
                             defines={"MODEL": interface.model_code, "N_DOF": len(interface.x),
                                      "N_FORCES": len(interface.f), "N_PARAMS": len(names),
                                      "RECIPROCAL_MASK": mask},
                             sample_period=DEFAULT_SAMPLE_PERIOD, compiler=compiler, platforms=platforms,
                             sampled_inputs=True)


def _use_c(backend: str, fmi_version: int, what: str, motion: str = "x") -> bool:
    """Whether to build the C FMU: ``backend`` "c", or "auto" with a C compiler (else one line
    on stderr says why the pythonfmu FMU is built); never for a velocity or acceleration
    (``motion``), which only the pythonfmu FMU takes."""
    if backend not in ENGINES:
        raise InputError(f"backend must be one of {', '.join(ENGINES)}, got {backend!r}")
    if fmi_version not in (2, 3):
        raise InputError(f"fmi_version must be 2 or 3, got {fmi_version!r}")
    if motion not in MOTION_INPUTS:
        raise InputError(f"motion must be one of {', '.join(MOTION_INPUTS)}, got {motion!r}")
    if motion != "x":
        word = MOTION_INPUTS[motion][0]
        if backend == "c" or fmi_version != 2:
            raise InputError(f"{what}: an estimator from a measured {word} is the output-error fit of the pythonfmu "
                             "FMU (FMI 2.0, a Python host): the C estimator core needs a displacement; use "
                             "--engine python (or auto) and FMI 2")
        if backend == "auto":
            print(f"duffid: building {what} as a pythonfmu FMU (runs in a Python host only): the C estimator "
                  f"core needs a displacement, not {'an' if word[0] in 'aeiou' else 'a'} {word}", file=sys.stderr)
        return False
    if backend == "python":
        if fmi_version != 2:
            raise InputError("the pythonfmu estimator FMU is FMI 2.0 only; use the C backend for FMI 3.0")
        return False
    if backend == "c":
        return True
    try:
        find_compiler()
    except CompilerNotFoundError as exc:
        if fmi_version != 2:
            raise CompilerNotFoundError(f"{what}: an FMI 3.0 estimator FMU needs the C backend: {exc}") from exc
        print(f"duffid: building {what} as a pythonfmu FMU (runs in a Python host only): {exc}", file=sys.stderr)
        return False
    return True


def build_equation_fmu(equation: str | Sequence[str], out_dir: str | Path, *, name: str = "EquationEstimator",
                       columns: Sequence[str] = ("t", "f", "x"), units: Mapping[str, str] | None = None,
                       fmi_version: int = 2, backend: str = "auto", platforms: Sequence[Platform] | None = None,
                       compiler: str | None = None, motion: str = "x") -> Path:
    """Build the estimator FMU of the user's own equations: ``<name>.fmu`` (FMI 2) or
    ``<name>_fmi3.fmu`` (FMI 3).

    Parameters
    ----------
    equation : str or sequence of str
        The equations, as for :func:`duffid.identification.equation.identify_equation`.
    out_dir : path
        Folder for the FMU (created if needed).
    name : str
        Model identifier and file stem (a Python identifier).
    columns : sequence of str
        The signals' names as record columns (``t, f, x`` or ``t, f1.., x1..``).
    units : mapping, optional
        Units of the signals (and of parameters the equations do not determine); see
        :func:`~duffid.fmu.estimator_table.equation_interface`.
    fmi_version : {2, 3}
        FMI version (the pythonfmu backend: 2 only).
    backend : {"auto", "c", "python"}
        "c": the C estimator core on the shared FMI glue (runs in any host, binaries for
        ``platforms``); "python": pythonfmu (:func:`duffid.fmu.python_estimator.build_equation_fmu`,
        a Python host with duffid installed); "auto": C when a C compiler is found, else
        pythonfmu with one line on stderr saying why.
    platforms : sequence of Platform, optional
        Targets of the C FMU's binaries (default: this machine).
    compiler : str, optional
        C compiler for this machine.
    motion : {"x", "v", "a"}
        What the motion inputs measure (:data:`~duffid.fmu.estimator_table.MOTION_INPUTS`):
        displacements, or velocities or accelerations (inputs ``v..``/``a..``, the output-error
        fit of :class:`~duffid.identification.motion_online.OnlineMotionIdentifier`: the
        pythonfmu FMU only, FMI 2.0).

    Raises
    ------
    EquationError, InputError
        An equation that cannot be identified (naming the term), a bad name or unit, a
        model beyond the limits of the C core, or a velocity or acceleration with backend
        "c" or FMI 3.
    CompilerNotFoundError, BuildError
        Backend "c" without a compiler, or compilation failed.
    """
    interface = equation_interface(equation, columns, units=units, name=name)
    if _use_c(backend, fmi_version, name, motion):
        return build_estimator_fmu(interface, out_dir, fmi_version, compiler=compiler, platforms=platforms)
    from .python_estimator import build_equation_fmu as build_python_equation_fmu

    return build_python_equation_fmu(equation, out_dir, name=name, columns=columns, units=units, motion=motion)


def build_chain_fmu(n_dof: int, out_dir: str | Path, *, orders: Sequence[int] = (1, 3), coulomb: bool = False,
                    name: str | None = None, fmi_version: int = 2, backend: str = "auto",
                    platforms: Sequence[Platform] | None = None, compiler: str | None = None,
                    motion: str = "x") -> Path:
    """Build the estimator FMU of a chain of ``n_dof`` masses (``ChainEstimator<n>.fmu`` by
    default; :func:`~duffid.fmu.estimator_table.chain_interface`): inputs ``x1 .. x<n>`` [m]
    and ``f1`` [N] (``a1 ..`` [m/s2] or ``v1 ..`` [m/s] with ``motion``). ``fmi_version``,
    ``backend``, ``platforms``, ``compiler`` and ``motion`` as for :func:`build_equation_fmu`.

    Raises
    ------
    InputError
        A chain of fewer than 1 mass, no stiffness order, a name that is not an identifier or
        a chain beyond the limits of the C core.
    CompilerNotFoundError, BuildError
        Backend "c" without a compiler, or compilation failed.
    """
    interface = chain_interface(n_dof, orders=orders, coulomb=coulomb, name=name)
    if _use_c(backend, fmi_version, interface.identifier, motion):
        return build_estimator_fmu(interface, out_dir, fmi_version, compiler=compiler, platforms=platforms)
    from .python_estimator import build_chain_fmu as build_python_chain_fmu

    return build_python_chain_fmu(n_dof, out_dir, orders=orders, coulomb=coulomb, name=interface.identifier,
                                  motion=motion)


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
