"""The named models, in one place, and what every model answers.

:data:`REGISTRY` maps each name a user types (``--model duffing1``, a campaign's ``model``,
``build-estimator duffing2``) to its class, the C core's built-in description (if any), the
estimator FMU's name and its input signals. The command line, the campaigns, the estimator
FMUs and the C binding read it; the C core's model codes are generated from it into
``fmus/estimator/duffid_facts.h`` (:mod:`duffid.identification.c_facts`).

:class:`IdentifiableModel` is the protocol every identifiable model follows (a
:class:`~duffid.models.chain.Chain` and its subclasses, the user's
:class:`~duffid.models.equation_model.EquationModel`): code that accepts "a model" checks it
with ``isinstance(model, IdentifiableModel)``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping, Protocol, Sequence, runtime_checkable

from ..errors import InputError
from .chain import Chain, Duffing1, Duffing2, DuffingCircuit

__all__ = ["IdentifiableModel", "ModelEntry", "Signal", "REGISTRY", "MODEL_NAMES", "PLANT_NAMES",
           "GENERATED_MODEL_CODE", "model_from_name", "entry"]


@runtime_checkable
class IdentifiableModel(Protocol):
    """What every identifiable model answers: its name, sizes, parameters and equations."""

    @property
    def name(self) -> str: ...

    @property
    def n_dof(self) -> int: ...

    @property
    def n_forces(self) -> int: ...

    @property
    def parameters(self) -> Mapping[str, float]: ...

    def equations(self) -> Sequence[Any]: ...


@dataclass(frozen=True)
class Signal:
    """One input signal of a model's estimator FMU: name, unit, meaning."""

    name: str
    unit: str
    description: str


@dataclass(frozen=True)
class ModelEntry:
    """One named model.

    Attributes
    ----------
    name : str
        What the user types.
    cls : type or None
        Its class (None: ``chain``, built from its size and orders by :func:`model_from_name`).
    description : str
        One line for help texts.
    c_code : int or None
        The C core's own description of it (``DUFFID_DUFFING1`` ...), None when it is
        described by generated code (``DUFFID_GENERATED``).
    fmu_name : str or None
        Model identifier of its C estimator FMU (FMI 3 files add ``_fmi3``); None: no named FMU.
    signals : tuple of Signal
        The estimator FMU's inputs: displacements (or charges), then forces (or voltages).
    """

    name: str
    cls: type[Chain] | None
    description: str
    c_code: int | None = None
    fmu_name: str | None = None
    signals: tuple[Signal, ...] = ()


#: The C core's code of a model described by generated code (chains, equations).
GENERATED_MODEL_CODE = 3

#: Every named model, in the order help texts list them.
REGISTRY: dict[str, ModelEntry] = {e.name: e for e in (
    ModelEntry("duffing1", Duffing1, "1-DOF hardening oscillator m x'' + b x' + k x + kp x^3 = f", 1,
               "DuffingEstimator1", (Signal("x", "m", "displacement of the mass"),
                                     Signal("f", "N", "force on the mass"))),
    ModelEntry("duffing2", Duffing2, "2-DOF chain of the paper (force on m1)", 2, "DuffingEstimator2",
               (Signal("x1", "m", "displacement of m1"), Signal("x2", "m", "displacement of m2"),
                Signal("f1", "N", "force on m1"))),
    ModelEntry("chain", None, "a chain of masses from a wall (--n-dof, --orders, --coulomb)"),
    # the circuit is the Duffing1 equation with L = m, R = b, 1/C = k, a = kp: the same C description
    ModelEntry("circuit", DuffingCircuit, "Duffing-type circuit L q'' + R q' + q/C + a q^3 = u", 1,
               "DuffingCircuitEstimator", (Signal("q", "C", "charge of the capacitor"),
                                           Signal("u", "V", "source voltage"))),
)}
#: The names, in order.
MODEL_NAMES = tuple(REGISTRY)
#: The names of the models with fixed structure and nominal values (simulated plants).
PLANT_NAMES = tuple(name for name, e in REGISTRY.items() if e.cls is not None)


def entry(name: str) -> ModelEntry:
    """The registry's entry of ``name``; InputError naming the known ones."""
    try:
        return REGISTRY[name]
    except KeyError:
        raise InputError(f"unknown model {name!r}; choose one of {', '.join(MODEL_NAMES)}") from None


def model_from_name(name: str, n_dof: int = 1, *, orders: Sequence[int] = (1, 3),
                    coulomb: bool = False, offset: bool = False,
                    forced: Sequence[int] = (0,)) -> Chain:
    """Build a named model (structure with nominal parameter values).

    Parameters
    ----------
    name : str
        A name of :data:`REGISTRY`.
    n_dof : int
        Number of masses of a ``chain``.
    orders : sequence of int
        Stiffness orders of a ``chain``.
    coulomb : bool
        Coulomb friction terms in a ``chain``.
    offset : bool
        Add an unknown constant offset per equation.
    forced : sequence of int
        0-based DOFs carrying force inputs (``chain`` only).
    """
    model = entry(name)
    if model.cls is not None:
        return model.cls(offset=offset)
    if n_dof < 1:
        raise InputError(f"a chain needs n_dof >= 1, got {n_dof}")
    orders = tuple(sorted(set(int(o) for o in orders)))
    stiffness = tuple({1: 1000.0} for _ in range(n_dof))
    return Chain(masses=(1.0,) * n_dof, damping=(1.0,) * n_dof, stiffness=stiffness,
                 coulomb=(0.0,) * n_dof if coulomb else None, forced=tuple(forced), offset=offset, orders=orders)
