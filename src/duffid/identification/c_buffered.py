"""The buffered identifier (paper Figure 15) in C: its tables as C source, and a ctypes binding.

:class:`~duffid.identification.buffered.BufferedIdentifier` computes, once per identifier,
the fixed matrices of its window (projection weights ``Q``, the operational matrices'
powers ``P_m``, the kept coefficients, the model's terms). :func:`tables_source` writes them
as a C file for ``fmus/estimator/duffid_buffered.c``, which does the per-sample and
per-window arithmetic on a microcontroller (no heap; the window's coefficients are
accumulated sample by sample, and only its displacements are kept, for its noise errors). :class:`CBufferedIdentifier` runs that C
code from Python (compiled on demand, cached) and is tested against the Python class
(``tests/test_buffered_c.py``).

What the C module covers: chain models (Duffing1, Duffing2, :class:`~duffid.models.chain.Chain`,
the circuit) in the per-DOF form, each window alone, where every public parameter is one
unknown of one equation (all DOFs forced, or one DOF). Anything else is refused with a
message (an unforced DOF's ratios, the matrix form, ``accumulate=True``, an equation model's
own channels).
"""
from __future__ import annotations

import ctypes
import os
from pathlib import Path
from typing import Any

import numpy as np

from ..cbuild import LIBRARY_FLAGS, cached_library
from ..errors import InputError
from ..models.chain import Chain
from .buffered import BufferedIdentifier, solve_groups
from .c_core import check_precision, source_dir, write_generated_source
from .orthogonal import make_basis, projection_matrix

__all__ = ["CHANNEL_KINDS", "tables_source", "build_buffered_library", "CBufferedIdentifier", "SOURCES", "HEADERS"]

#: C sources of the buffered module, relative to :func:`~duffid.identification.c_core.source_dir`.
SOURCES = ("duffid_buffered.c", "duffid_linalg.c")
HEADERS = ("duffid_buffered.h", "duffid_estimator.h", "duffid_linalg.h", "duffid_model.h", "duffid_options.h",
           "duffid_facts.h",
           "duffid_build.h")
#: Channel kinds of :class:`~duffid.models.chain.Channel` and their codes (duffid_buffered.h).
CHANNEL_KINDS = {"x": 0, "deflection": 1, "force": 2, "sign_velocity": 3, "one": 4}
#: The tables' symbol in the generated C file.
TABLES_SYMBOL = "duffid_buffered_model"
_MAX_PARAMS = 40


def _model_channels(model: Chain, labels: tuple[str, ...]) -> list[Any]:
    channels: dict[Any, None] = {}
    for eq in model.equations():
        for c in eq.channels:
            channels.setdefault(c, None)
    chans = list(channels)
    if tuple(c.label for c in chans) != tuple(labels):
        raise InputError(f"{model.name}: the model's channels {[c.label for c in chans]} are not those of the "
                         f"identifier's regression {list(labels)}")
    for c in chans:
        if c.kind not in CHANNEL_KINDS:
            raise InputError(f"{model.name}: channel {c.label} ({c.kind}) is not computed by the C buffered "
                             f"identifier (kinds {', '.join(CHANNEL_KINDS)})")
    return chans


def _parameter_map(ident: BufferedIdentifier) -> list[tuple[int, int]]:
    """(equation, unknown) of each public parameter, found by probing the regression's finish."""
    reg = ident.regression
    probes, owner = [], {}
    value = 1.0
    for e, names in enumerate(reg.unknowns):
        sol = {}
        for u, name in enumerate(names):
            value += 1.0
            sol[name] = value * 1.0009765625  # distinct, exactly representable
            owner[sol[name]] = (e, u)
        probes.append(sol)
    out = reg.finish(probes)
    mapping = []
    for name in reg.parameter_names:
        v = out.get(name)
        if v not in owner:
            raise InputError(f"{reg.name}: parameter {name} is not one unknown of one equation (an unforced "
                             "degree of freedom gives ratios); the C buffered identifier covers models whose "
                             "every DOF is forced, or one DOF")
        mapping.append(owner[v])
    return mapping


def _array(name: str, ctype: str, values: Any, per_line: int = 6) -> str:
    vals = list(values)
    if ctype == "int":
        items = [str(int(v)) for v in vals]
    else:
        items = [f"V({float(v):.17g})" for v in vals]
    lines = [", ".join(items[i:i + per_line]) for i in range(0, len(items), per_line)] or ["0"]
    body = ",\n    ".join(lines)
    return f"static const {ctype} {name}[] = {{\n    {body}\n}};\n"


def tables_source(ident: BufferedIdentifier, model: Chain, symbol: str = TABLES_SYMBOL) -> str:
    """The C tables (``duffid_buffered_tables``) of a buffered identifier of a chain model.

    Parameters
    ----------
    ident : BufferedIdentifier
        The Python identifier (its basis, window, options and regression).
    model : Chain
        The model it was built from (its channels).
    symbol : str
        Name of the ``const duffid_buffered_tables`` defined.

    Raises
    ------
    InputError
        If the identifier uses what the C module does not cover (see the module docstring).
    """
    o = ident.options
    if not isinstance(model, Chain):
        raise InputError("the C buffered identifier needs a chain model (Duffing1, Duffing2, Chain, the circuit)")
    if o["form"] != "per-dof":
        raise InputError("the C buffered identifier covers form='per-dof' only, not the matrix form")
    if o["accumulate"]:
        raise InputError("the C buffered identifier solves each window alone: accumulate=True is not covered")
    reg = ident.regression
    if any(len(eqs) > 1 for eqs, _ in solve_groups(reg)):
        raise InputError(f"{reg.name}: equations sharing unknowns (solved jointly) are not covered by the C "
                         "buffered identifier")
    chans = _model_channels(model, reg.channel_labels)
    params = _parameter_map(ident)
    if len(params) > _MAX_PARAMS:
        raise InputError(f"{reg.name}: {len(params)} parameters; the C module holds at most {_MAX_PARAMS}")
    n = reg.max_order
    N = ident.n_intervals
    basis = make_basis(ident.method, o["n_terms"])
    Q = np.asarray(projection_matrix(basis, N, o["quadrature"]))  # r x (N+1)
    kept = [int(k) for k in ident.kept]
    exact = o["repeated"] == "exact"
    starts, index, value = [], [], []
    for m in range(1, n + 1):
        P = basis.integration_matrix(m, exact)
        for rho, col in enumerate(kept):
            starts.append(len(index))
            rows = np.flatnonzero(P[:, col])
            index += rows.tolist()
            value += P[rows, col].tolist()
        starts.append(len(index))
    w_norm = np.linalg.norm(ident.kernels, axis=2)  # (n+1) x kept
    terms = []
    for e, eq_terms in enumerate(reg.terms):
        for t in eq_terms:
            terms.append(f"{{{e}, {-1 if t.unknown is None else t.unknown}, {t.channel}, {t.order}, V({float(t.coef):.17g})}}")
    names = ", ".join(f'"{name}"' for name in reg.parameter_names)
    text = [
        "/* GENERATED by duffid.identification.c_buffered.tables_source: the buffered identifier's tables",
        f" * for {reg.name}, basis {ident.method} ({o['n_terms']} functions, {len(kept)} kept), a window of {N} "
        f"sample intervals,",
        f" * quadrature {o['quadrature']}, repeated integration {o['repeated']}. Do not edit. */",
        '#include "duffid_buffered.h"',
        "",
        "#define V(x) ((duffid_real)(x))",
        "",
        "static const duffid_buffered_channel CHANNELS[] = {"
        + ", ".join(f"{{{CHANNEL_KINDS[c.kind]}, {c.index}, {c.power if c.kind == 'deflection' else 1}}}"
                    for c in chans) + "};",
        _array("Q", "duffid_real", Q.T.ravel()),
        _array("P_START", "int", starts or [0]),
        _array("P_INDEX", "int", index or [0]),
        _array("P_VALUE", "duffid_real", value or [0.0]),
        _array("KEPT", "int", kept),
        _array("W_NORM", "duffid_real", w_norm.ravel()),
        _array("N_UNKNOWNS", "int", [len(u) for u in reg.unknowns]),
        "static const duffid_buffered_term TERMS[] = {\n    " + ",\n    ".join(terms) + "\n};",
        f"static const char *const NAMES[] = {{{names}}};",
        _array("PARAMETER_EQUATION", "int", [e for e, _ in params]),
        _array("PARAMETER_UNKNOWN", "int", [u for _, u in params]),
        f"extern const duffid_buffered_tables {symbol};",
        f"const duffid_buffered_tables {symbol} = {{",
        f'    "{reg.name}", "{ident.method}", {reg.n_dof}, {reg.n_forces}, {len(chans)}, CHANNELS, {n}, '
        f"{o['n_terms']}, {len(kept)}, {N}L, Q,",
        f"    P_START, P_INDEX, P_VALUE, KEPT, W_NORM, {len(reg.unknowns)}, N_UNKNOWNS, {len(terms)}, TERMS,",
        f"    {len(params)}, NAMES, PARAMETER_EQUATION, PARAMETER_UNKNOWN}};",
        "",
    ]
    return "\n".join(text)


def build_buffered_library(ident: BufferedIdentifier, model: Chain,
                           build_dir: str | os.PathLike[str] | None = None, *, compiler: str | None = None,
                           precision: str = "double") -> Path:
    """Compile the C buffered module with the tables of ``ident`` into a shared library
    (cached by the hash of the sources, the tables' included)."""
    check_precision(precision)
    path, digest, build_dir = write_generated_source(tables_source(ident, model), "buffered", "duffid_buffered_tables",
                                                     build_dir)
    single = precision == "float"
    return cached_library(f"libduffid_buffered_{digest}" + ("_float" if single else ""), source_dir(), SOURCES,
                          HEADERS, flags=(*LIBRARY_FLAGS, *(("-DDUFFID_REAL=float",) if single else ())),
                          build_dir=build_dir, compiler=compiler, extra_sources=[path])


def _types(real: Any) -> tuple[type[ctypes.Structure], type[ctypes.Structure]]:
    class Config(ctypes.Structure):
        _fields_ = [("tables", ctypes.c_void_p), ("dt", real), ("every", ctypes.c_long),
                    ("max_condition", real), ("max_uncertainty", real), ("deadband", real)]

    class Output(ctypes.Structure):
        _fields_ = [("t", real), ("parameters", real * _MAX_PARAMS), ("current", real * _MAX_PARAMS),
                    ("n_parameters", ctypes.c_int), ("identified", ctypes.c_int), ("solved", ctypes.c_int),
                    ("windows", ctypes.c_long), ("condition", real), ("uncertainty", real), ("window", real)]
    return Config, Output


_REALS = {"double": ctypes.c_double, "float": ctypes.c_float}


class CBufferedIdentifier:
    """The C buffered module over the tables of a :class:`BufferedIdentifier` of ``model``.

    Parameters
    ----------
    model : Chain
        Model structure.
    dt : float
        Sampling period [s].
    method : str
        Basis, as :class:`BufferedIdentifier`.
    precision : {"double", "float"}
        The C module's real type.
    **options
        As :class:`BufferedIdentifier` (``window``, ``n_terms``, ``every``, ``quadrature``,
        ``repeated``, ``max_condition``, ``max_uncertainty``, ``deadband``).

    Notes
    -----
    :meth:`run` returns one row per sample: ``current`` (the latest window's solution),
    ``parameters`` (the same, NaN unless that window was identified), ``identified``,
    ``solved``, ``condition``, ``uncertainty``. A window's solution appears :attr:`latency`
    samples after its last sample (Python's at that sample).
    """

    def __init__(self, model: Chain, dt: float, method: str = "legendre", *, precision: str = "double",
                 **options: Any) -> None:
        check_precision(precision)
        self.python = BufferedIdentifier(model, dt, method, **options)
        self.precision = precision
        self._real = _REALS[precision]
        lib = ctypes.CDLL(str(build_buffered_library(self.python, model, precision=precision)))
        Config, Output = _types(self._real)
        self._Output = Output
        if lib.duffid_buffered_output_size() != ctypes.sizeof(Output) or \
                lib.duffid_buffered_config_size() != ctypes.sizeof(Config):
            raise RuntimeError("the C buffered module's structures do not match this binding")
        tables = ctypes.c_void_p.in_dll(lib, TABLES_SYMBOL)
        cfg = Config()
        o = self.python.options
        cfg.tables = ctypes.addressof(tables)
        cfg.dt = dt
        cfg.every = int(self.python.every)
        cfg.max_condition = o["max_condition"]
        cfg.max_uncertainty = o["max_uncertainty"]
        cfg.deadband = o["deadband"]
        lib.duffid_buffered_memory_size.restype = ctypes.c_size_t
        size = lib.duffid_buffered_memory_size(ctypes.byref(cfg))
        msg = ctypes.create_string_buffer(256)
        if size == 0:
            lib.duffid_buffered_check_config(ctypes.byref(cfg), msg, ctypes.c_size_t(256))
            raise InputError(f"C buffered identifier: {msg.value.decode()}")
        self.memory_size = int(size)
        self._memory = ctypes.create_string_buffer(self.memory_size)
        self._handle = ctypes.c_void_p()
        rc = lib.duffid_buffered_init(ctypes.byref(self._handle), self._memory, ctypes.c_size_t(size),
                                      ctypes.byref(cfg), msg, ctypes.c_size_t(256))
        if rc != 0:
            raise InputError(f"C buffered identifier: {msg.value.decode()}")
        self._lib, self._cfg = lib, cfg
        lib.duffid_buffered_latency.restype = ctypes.c_long
        #: Samples between a window's last sample and the update that outputs its solution (the
        #: C module spreads a window's solve over them, to bound every update's work).
        self.latency = int(lib.duffid_buffered_latency(self._handle))
        self.parameter_names = tuple(self.python.parameter_names)

    def run(self, x: np.ndarray, f: np.ndarray) -> dict[str, np.ndarray]:
        """Feed every sample (``x`` (n, n_dof), ``f`` (n, n_forces)); the outputs per sample."""
        x = np.ascontiguousarray(np.atleast_2d(np.asarray(x, dtype=float).T).T)
        f = np.ascontiguousarray(np.atleast_2d(np.asarray(f, dtype=float).T).T)
        n, k = len(x), len(self.parameter_names)
        rows = {"current": np.full((n, k), np.nan), "parameters": np.full((n, k), np.nan),
                "identified": np.zeros(n, bool), "solved": np.zeros(n, bool), "condition": np.full(n, np.inf),
                "uncertainty": np.full(n, np.nan)}
        out = self._Output()
        xr = (self._real * x.shape[1])()
        fr = (self._real * max(1, f.shape[1]))()
        for i in range(n):
            xr[:] = x[i].tolist()
            fr[:f.shape[1]] = f[i].tolist()
            rc = self._lib.duffid_buffered_update(self._handle, xr, fr, ctypes.byref(out))
            if rc != 0:
                raise InputError(f"sample {i}: the C buffered identifier refused it (code {rc}: not finite)")
            rows["current"][i] = out.current[:k]
            rows["parameters"][i] = out.parameters[:k]
            rows["identified"][i] = bool(out.identified)
            rows["solved"][i] = bool(out.solved)
            rows["condition"][i] = out.condition
            rows["uncertainty"][i] = out.uncertainty
        return rows
