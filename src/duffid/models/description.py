"""A model as data: what a compiled identification engine needs to know about a model.

:func:`describe` turns any model the online identifier accepts (a
:class:`~duffid.models.chain.Chain` or its named shortcuts, an
:class:`~duffid.models.equation_model.EquationModel`) into a :class:`ModelDescription`:
the channel function ``g(x, f, t, sgn)`` as a CasADi function (so that CasADi can generate
its C code), the blocks of equations as terms over the channels' derivatives, and what the
model answers about each parameter (physical sign, natural period, offset, how the blocks'
solutions combine into it, where its share of the force balance is read, the linearised
mass and stiffness matrices). The C estimator core (``fmus/estimator/duffid_model.h``) runs
on this description; :mod:`duffid.identification.c_core` writes it as C.

Nothing here changes a model: every fact is read through the model's own interface
(``equations``, ``share_sources``, ``is_physical``, ``period_parameters``, ...), except
the combination rules of a chain's unforced degrees of freedom and the linearisation,
which restate :meth:`Chain.combine_solutions` and :meth:`Chain.linear_natural_frequencies`
as data.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import casadi as ca

from ..errors import InputError
from .chain import Chain, Channel

__all__ = ["ModelDescription", "BlockDescription", "ParameterDescription", "describe",
           "ALLOW_POSITIVE", "ALLOW_ZERO", "ALLOW_NEGATIVE"]

#: Bits of :attr:`ParameterDescription.physical`: the signs a physical value may have.
ALLOW_POSITIVE, ALLOW_ZERO, ALLOW_NEGATIVE = 1, 2, 4


@dataclass(frozen=True)
class BlockDescription:
    """One block: equations solved together (``parts``), linear in their unknowns.

    Attributes
    ----------
    unknowns : tuple of str
        Column order of the block's least-squares problem.
    parts : int
        Equations of the block (each gives its own rows).
    terms : tuple of (part, unknown, channel, order, coef)
        ``coef * theta[unknown] * d^order g[channel]`` (unknown -1: a known term, on the
        right-hand side); identical (part, unknown, channel, order) merged.
    forced : bool
        True: the unknowns are absolute values; False: ratios to the block's scale (a
        chain's unforced mass), found by ``rules``.
    rules : tuple of (unknown, other, other_unknown)
        The scale is ``scale(other) * theta_other[other_unknown] / theta[unknown]``: the
        first rule whose ``other`` block has a known scale (and ``theta[unknown] != 0``).
    """

    unknowns: tuple[str, ...]
    parts: int
    terms: tuple[tuple[int, int, int, int, float], ...]
    forced: bool = True
    rules: tuple[tuple[int, int, int], ...] = ()


@dataclass(frozen=True)
class ParameterDescription:
    """What the model says about one canonical parameter.

    Attributes
    ----------
    name : str
        Canonical name.
    physical : int
        Bits ``ALLOW_*`` of the values ``is_physical`` accepts (7: any).
    period : bool
        Sets a natural period (the auto window waits for it).
    offset : bool
        Multiplies a constant only.
    scale_of : int
        The unforced block whose scale it is (-1: none).
    sources : tuple of (block, unknown)
        Its value: the first source whose block has a known scale, times that scale.
    shares : tuple of (block, unknown)
        Its share of the force balance: the largest over these (unknown -1: the block's
        right-hand side).
    """

    name: str
    physical: int
    period: bool
    offset: bool
    scale_of: int
    sources: tuple[tuple[int, int], ...]
    shares: tuple[tuple[int, int], ...]


@dataclass(frozen=True)
class ModelDescription:
    """A model as data (see the module documentation).

    Attributes
    ----------
    name : str
        The model's name.
    n_dof, n_forces : int
        Displacement and force columns of a sample.
    max_order : int
        Highest derivative order of a term.
    channel_labels : tuple of str
        Readable name of each channel.
    channel_function : casadi.Function
        ``(x[n_dof], f[n_forces], t, sgn[n_dof]) -> g[channels]``.
    uses_sign : bool
        A channel reads the sign of a velocity.
    channel_forces : tuple of int
        Per channel, the force it is (0-based), or -1: the channels whose jumps between two
        samples bias the rows (:data:`duffid.identification.engine.JUMP_ERROR`).
    blocks : tuple of BlockDescription
    parameters : tuple of ParameterDescription
        Canonical order (the order of ``model.canonical_parameters()``).
    public : tuple of (name, canonical index, reciprocal)
        The public parameters in output order; ``reciprocal``: the public value is one over
        the canonical one (the circuit's C = 1 / k).
    mass, stiffness : tuple of (row, col, parameter, coef), or None
        The linearised M and K: ``M[row, col] += coef * theta[parameter]`` (parameter -1:
        ``+= coef``), in this order; None when the model has no linearisation (its natural
        frequencies are unknown: the auto window keeps its longest length).
    """

    name: str
    n_dof: int
    n_forces: int
    max_order: int
    channel_labels: tuple[str, ...]
    channel_function: ca.Function
    uses_sign: bool
    channel_forces: tuple[int, ...]
    blocks: tuple[BlockDescription, ...]
    parameters: tuple[ParameterDescription, ...]
    public: tuple[tuple[str, int, bool], ...]
    mass: tuple[tuple[int, int, int, float], ...] | None
    stiffness: tuple[tuple[int, int, int, float], ...] | None


def describe(model: Any) -> ModelDescription:
    """The description of ``model`` (a Chain, a named chain or an EquationModel).

    Raises
    ------
    InputError
        For a model whose equations use a channel kind without a symbolic form.
    """
    equations = model.equations()
    channels: dict[Channel, None] = {}
    for eq in equations:
        for c in eq.channels:
            channels.setdefault(c, None)
    chans = tuple(channels)
    index = {c: i for i, c in enumerate(chans)}
    function, uses_sign = _channel_function(model, chans)
    canonical = list(model.canonical_parameters())
    position = {name: i for i, name in enumerate(canonical)}
    is_chain = isinstance(model, Chain)
    blocks = []
    for j, eq in enumerate(equations):
        merged: dict[tuple[int, int, int, int], float] = {}
        for term in eq.lhs + eq.rhs:
            unknown = -1 if term.unknown is None else eq.unknowns.index(term.unknown)
            key = (term.part, unknown, index[term.channel], term.order)
            merged[key] = merged.get(key, 0.0) + float(term.sign)
        forced = j in model.forced if is_chain else True
        rules = _chain_rules(model, equations, j) if is_chain and not forced else ()
        blocks.append(BlockDescription(eq.unknowns, eq.parts, tuple((*k, v) for k, v in merged.items()),
                                       forced, rules))
    periods = set(model.period_parameters())
    offsets = set(model.offset_parameters())
    parameters = []
    for name in canonical:
        physical = sum(bit for bit, v in ((ALLOW_POSITIVE, 1.0), (ALLOW_ZERO, 0.0), (ALLOW_NEGATIVE, -1.0))
                       if model.is_physical(name, v))
        shares = tuple((j, -1 if key is None else equations[j].unknowns.index(key))
                       for j, key in model.share_sources(name))
        scale_of, sources = -1, ()
        if is_chain:
            i = int(name[1:]) - 1 if name[0] == "m" and name[1:].isdigit() else -1
            if i >= 0 and i not in model.forced:
                scale_of = i
            else:
                sources = tuple((j, eq.unknowns.index(key)) for j, eq in enumerate(equations)
                                for key in [name if j in model.forced else f"{name}/m{j + 1}"]
                                if key in eq.unknowns)
        else:
            sources = tuple((j, equations[j].unknowns.index(key)) for j, key in model.share_sources(name))
        parameters.append(ParameterDescription(name, physical, name in periods, name in offsets, scale_of,
                                               sources, shares))
    reciprocal = getattr(model, "reciprocal", ())
    public = [(name, position[model.canonical_name(name)], name in reciprocal) for name in model.parameters]
    mass, stiffness = _linear_maps(model, position) if is_chain else _equation_linear_maps(model, position)
    return ModelDescription(model.name, model.n_dof, model.n_forces, max(eq.max_order for eq in equations),
                            tuple(c.label for c in chans), function, uses_sign,
                            tuple(c.index if c.kind == "force" else -1 for c in chans), tuple(blocks),
                            tuple(parameters), tuple(public), mass, stiffness)


def _channel_function(model: Any, chans: tuple[Channel, ...]) -> tuple[ca.Function, bool]:
    """``g(x, f, t, sgn)``: the model's own channel function (an equation model) or the
    chain's channels written with CasADi symbols."""
    n, nf = model.n_dof, model.n_forces
    x, f, t, sgn = ca.SX.sym("x", n), ca.SX.sym("f", nf), ca.SX.sym("t"), ca.SX.sym("sgn", n)
    inner = None
    if any(c.kind == "expression" for c in chans):
        inner = model.regressor.channel_function
        values = inner(x, f if nf else ca.SX(0, 1), t, sgn)
    out = []
    for c in chans:
        if c.kind == "x":
            out.append(x[c.index])
        elif c.kind == "deflection":
            y = x[c.index] - x[c.index - 1] if c.index > 0 else x[c.index]
            out.append(y if c.power == 1 else y ** c.power)
        elif c.kind == "force":
            out.append(f[c.index])
        elif c.kind == "sign_velocity":
            out.append(sgn[c.index])
        elif c.kind == "one":
            out.append(ca.SX(1.0))
        elif c.kind == "expression":
            out.append(values[c.index])
        else:
            raise InputError(f"{model.name}: channel {c.label} of kind {c.kind!r} has no symbolic form")
    g = ca.vertcat(*out)
    return ca.Function("duffid_channels", [x, f, t, sgn], [g], ["x", "f", "t", "sgn"], ["g"]), \
        bool(ca.depends_on(g, sgn))


def _chain_rules(model: Chain, equations: tuple, i: int) -> tuple[tuple[int, int, int], ...]:
    """Chain.combine_solutions' ways to the scale (mass) of unforced DOF ``i``, in its order."""
    n = model.n_dof
    rules = []
    for e in (i + 1, i + 2):  # left and right element of mass i (1-based elements)
        key = f"k{e}_1/m{i + 1}"
        if key not in equations[i].unknowns:
            continue
        for j in (e - 2, e - 1):  # the equations that contain element e
            if j == i or not 0 <= j < n:
                continue
            other = f"k{e}_1" if j in model.forced else f"k{e}_1/m{j + 1}"
            if other in equations[j].unknowns:
                rules.append((equations[i].unknowns.index(key), j, equations[j].unknowns.index(other)))
    return tuple(rules)


def _linear_maps(model: Chain, position: dict[str, int]):
    """Chain.linear_natural_frequencies' M = diag(m) and K (the chain matrix of k<i>_1), as
    coefficient lists in the order numpy sums them."""
    n = model.n_dof
    mass = tuple((i, i, position[f"m{i + 1}"], 1.0) for i in range(n))
    k = [position.get(f"k{i + 1}_1", -1) for i in range(n)]
    stiffness = [(i, i, k[i], 1.0) for i in range(n) if k[i] >= 0]
    stiffness += [(i, i, k[i + 1], 1.0) for i in range(n - 1) if k[i + 1] >= 0]
    for i in range(n - 1):
        if k[i + 1] >= 0:
            stiffness += [(i, i + 1, k[i + 1], -1.0), (i + 1, i, k[i + 1], -1.0)]
    return mass, tuple(stiffness)


def _equation_linear_maps(model: Any, position: dict[str, int]):
    """M = d residual / d der(x, 2) and K = d residual / d x at rest (zero signals), affine in
    the parameters: their constant parts and coefficients; None unless the equations give one
    acceleration per displacement (EquationModel.linear_natural_frequencies raises then)."""
    reg = model.regressor
    if len(model.texts) != model.n_dof:
        return None, None
    sig = reg.signals
    res = ca.vertcat(*reg.residuals)
    names = list(position)
    theta = ca.vertcat(*[reg.symbols[k] for k in names])
    signals = ca.vertcat(*(sig.x + sig.dx + sig.ddx + sig.f + sig.sgn + [sig.t]))
    out = []
    for wrt in (ca.vertcat(*sig.ddx), ca.vertcat(*sig.x)):
        J = ca.substitute(ca.jacobian(res, wrt), signals, ca.DM.zeros(signals.numel()))
        fn = ca.Function("linear", [theta], [J, ca.jacobian(ca.vec(J), theta)])
        constant, coef = (ca.DM(v).full() for v in fn(ca.DM.zeros(len(names))))
        n = model.n_dof
        entries = []
        for col in range(n):      # vec() is column-major
            for row in range(n):
                flat = col * n + row
                if constant[row, col] != 0.0:
                    entries.append((row, col, -1, float(constant[row, col])))
                entries += [(row, col, p, float(coef[flat, p])) for p in range(len(names)) if coef[flat, p] != 0.0]
        entries.sort(key=lambda e: (e[0], e[1]))
        out.append(tuple(entries))
    return out[0], out[1]
