"""ctypes binding of the portable C99 estimator core (``fmus/estimator/``).

The C core is a port of :class:`~duffid.identification.engine.OnlineIdentifier` (methods
``robust`` and ``paper``) for :class:`~duffid.models.chain.Duffing1` and
:class:`~duffid.models.chain.Duffing2` (with or without ``offset``), written for co-simulation
FMUs and embedded targets. This module compiles it on demand with the system C compiler,
caches the shared library by a hash of the sources and flags, and exposes
:class:`CIdentifier`, a drop-in replacement of ``OnlineIdentifier`` for those models.

Examples
--------
>>> from duffid import Duffing1                                  # doctest: +SKIP
>>> ident = CIdentifier(Duffing1(), dt=1e-3)                     # doctest: +SKIP
>>> estimate = ident.update(x, f)                                # doctest: +SKIP
"""
from __future__ import annotations

import ctypes
import os
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from ..assets import fmu_sources
from ..cbuild import CFLAGS as CBUILD_FLAGS
from ..cbuild import LIBRARY_FLAGS, cached_library, default_build_dir
from ..data.record import Record
from ..errors import AssetError, InputError
from ..models.chain import Chain, Duffing1, Duffing2, model_from_name
from .engine import STATUSES, Estimate, Identification, check_record, prior_sizes
from .identifier import Identifier
from .options import C_HEADER_NAME, check_options, ctypes_fields, to_c

__all__ = [
    "CIdentifier",
    "CConfig",
    "build_library",
    "load_library",
    "source_dir",
    "SOURCES",
    "CFLAGS",
]

#: C sources of the core, relative to :func:`source_dir`.
SOURCES = ("duffid_estimator.c", "duffid_linalg.c")
HEADERS = ("duffid_estimator.h", "duffid_linalg.h", C_HEADER_NAME)
#: Compiler flags of the shared library (:mod:`duffid.cbuild`'s, strict C99).
CFLAGS = CBUILD_FLAGS + LIBRARY_FLAGS

_MAX_PARAMS = 10
_MODELS = {"duffing1": 1, "duffing2": 2}
_METHODS = {"robust": 0, "paper": 1}
_STATUS = {0: "ok", -1: "invalid argument", -2: "invalid configuration", -3: "sample not finite"}






class CConfig(ctypes.Structure):
    """The C core's ``duffid_config`` (duffid_estimator.h), field for field."""

    _fields_ = [
        ("model", ctypes.c_int),
        ("method", ctypes.c_int),
        ("offset", ctypes.c_int),
        ("dt", ctypes.c_double),
        ("nominal", ctypes.c_double * _MAX_PARAMS),
        *ctypes_fields(),  # the options, from the schema that generates the C header
    ]


class _Output(ctypes.Structure):
    _fields_ = [
        ("t", ctypes.c_double),
        ("parameters", ctypes.c_double * _MAX_PARAMS),
        ("n_parameters", ctypes.c_int),
        ("identified", ctypes.c_int),
        ("condition", ctypes.c_double),
        ("uncertainty", ctypes.c_double),
        ("window", ctypes.c_double),
        ("current", ctypes.c_double * _MAX_PARAMS),
        ("status", ctypes.c_int * _MAX_PARAMS),
        ("outliers", ctypes.c_long),
        ("outlier_t", ctypes.c_double),
        ("outlier_column", ctypes.c_int),
        ("outlier_value", ctypes.c_double),
        ("outlier_replaced_by", ctypes.c_double),
    ]


_OUTPUT_DTYPE = np.dtype([("t", "f8"), ("parameters", "f8", (_MAX_PARAMS,)), ("n_parameters", "i4"),
                          ("identified", "i4"), ("condition", "f8"), ("uncertainty", "f8"), ("window", "f8"),
                          ("current", "f8", (_MAX_PARAMS,)), ("status", "i4", (_MAX_PARAMS,)),
                          ("outliers", "i8"), ("outlier_t", "f8"), ("outlier_column", "i4"), ("outlier_value", "f8"),
                          ("outlier_replaced_by", "f8")],
                         align=True)


# ---------------------------------------------------------------------- building
def source_dir() -> Path:
    """Folder of the C sources: ``$DUFFID_C_SOURCES``, else duffid's package data ``fmus/estimator``."""
    env = os.environ.get("DUFFID_C_SOURCES")
    if env:
        return Path(env)
    return fmu_sources("estimator")


def build_library(build_dir: str | os.PathLike[str] | None = None, *, compiler: str | None = None,
                  force: bool = False) -> Path:
    """Compile the C core into a shared library (cached by source and flag hash).

    Parameters
    ----------
    build_dir : path, optional
        Where the library goes; default ``$DUFFID_BUILD_DIR``, else ``build/estimator``
        of the checkout, else ``~/.cache/duffid/estimator``.
    compiler : str, optional
        C compiler command; default :func:`duffid.cbuild.find_compiler`'s.
    force : bool
        Rebuild even if a library with the same hash exists.

    Returns
    -------
    Path
        The shared library.

    Raises
    ------
    CompilerNotFoundError
        If no C compiler is available.
    BuildError
        If compilation fails (the compiler's messages are included).
    """
    src = source_dir()
    missing = [name for name in SOURCES + HEADERS if not (src / name).is_file()]
    if missing:
        raise AssetError(f"C sources of the estimator core not found in {src}: {missing} "
                         "(set DUFFID_C_SOURCES to the fmus/estimator folder)")
    if build_dir is None:
        build_dir = default_build_dir(fmu_sources("estimator"), "estimator")
    return cached_library("libduffid_estimator", src, SOURCES, HEADERS, flags=LIBRARY_FLAGS, build_dir=build_dir,
                          compiler=compiler, force=force)


_LIBRARIES: dict[str, ctypes.CDLL] = {}


def load_library(path: str | os.PathLike[str] | None = None) -> ctypes.CDLL:
    """Load (building if needed) the shared library and declare its functions."""
    path = str(path if path is not None else build_library())
    lib = _LIBRARIES.get(path)
    if lib is not None:
        return lib
    lib = ctypes.CDLL(path)
    cfg_p, out_p = ctypes.POINTER(CConfig), ctypes.POINTER(_Output)
    est_p, dbl_p = ctypes.c_void_p, ctypes.POINTER(ctypes.c_double)
    signatures = {
        "duffid_default_config": (ctypes.c_int, [cfg_p, ctypes.c_int, ctypes.c_int, ctypes.c_double]),
        "duffid_check_config": (ctypes.c_int, [cfg_p, ctypes.c_char_p, ctypes.c_size_t]),
        "duffid_memory_size": (ctypes.c_size_t, [cfg_p]),
        "duffid_create": (ctypes.c_int, [ctypes.POINTER(est_p), cfg_p, ctypes.c_char_p, ctypes.c_size_t]),
        "duffid_destroy": (None, [est_p]),
        "duffid_reset": (None, [est_p]),
        "duffid_flush": (ctypes.c_int, [est_p, out_p]),
        "duffid_update": (ctypes.c_int, [est_p, dbl_p, dbl_p, out_p]),
        "duffid_run": (ctypes.c_int, [est_p, ctypes.c_long, dbl_p, dbl_p, out_p, ctypes.POINTER(ctypes.c_long)]),
        "duffid_n_parameters": (ctypes.c_int, [est_p]),
        "duffid_parameter_name": (ctypes.c_char_p, [est_p, ctypes.c_int]),
        "duffid_capacity": (ctypes.c_long, [est_p]),
        "duffid_config_size": (ctypes.c_size_t, []),
        "duffid_output_size": (ctypes.c_size_t, []),
    }
    for name, (restype, argtypes) in signatures.items():
        fn = getattr(lib, name)
        fn.restype = restype
        fn.argtypes = argtypes
    if lib.duffid_config_size() != ctypes.sizeof(CConfig) or lib.duffid_output_size() != ctypes.sizeof(_Output):
        raise RuntimeError(f"{path}: the C structures do not match this binding (rebuild the library)")
    _LIBRARIES[path] = lib
    return lib


# ---------------------------------------------------------------------- identifier
def _resolve_model(model: Chain | str) -> Chain:
    if isinstance(model, str):
        model = model_from_name(model)
    if not isinstance(model, (Duffing1, Duffing2)):
        raise InputError(f"the C estimator core supports the models duffing1 and duffing2, "
                         f"got {getattr(model, 'name', model)!r}")
    return model


class CIdentifier(Identifier):
    """The C core with the interface of :class:`~duffid.identification.engine.OnlineIdentifier`.

    Parameters
    ----------
    model : Duffing1, Duffing2 or {"duffing1", "duffing2"}
        Model structure (its parameter values are not used); its ``offset`` flag adds the
        offset unknowns.
    dt : float
        Sampling period [s].
    method : {"robust", "paper"}
        Estimator.
    **options
        The options of ``OnlineIdentifier`` with the same defaults and validation
        (``n_rows`` at most 12 in the C core).
    library : path, optional (keyword)
        A prebuilt shared library; default: build/load with :func:`load_library`.

    Raises
    ------
    CompilerNotFoundError
        If the library has to be built and there is no C compiler.
    """

    def __init__(self, model: Chain | str, dt: float, method: str = "robust", *,
                 library: str | os.PathLike[str] | None = None, **options: Any) -> None:
        if method not in _METHODS:
            raise InputError(f"unknown method {method!r}; the C core supports {', '.join(_METHODS)}")
        super().__init__(_resolve_model(model), dt, method, check_options(method, options))
        self._lib = load_library(library)
        cfg = CConfig()
        self._lib.duffid_default_config(ctypes.byref(cfg), _MODELS[self.model.name], _METHODS[method], self.dt)
        cfg.offset = int(bool(self.model.offset))
        sizes = prior_sizes(self.model, self.options.get("nominal"))
        for i, name in enumerate(self.model.parameters):
            cfg.nominal[i] = sizes.get(self.model.canonical_name(name), 0.0)
        for name, value in self.options.items():
            if name != "nominal":  # the prior sizes went to cfg.nominal above
                setattr(cfg, name, to_c(name, value))
        self._config = cfg
        handle = ctypes.c_void_p()
        msg = ctypes.create_string_buffer(512)
        rc = self._lib.duffid_create(ctypes.byref(handle), ctypes.byref(cfg), msg, len(msg))
        if rc != 0:
            raise InputError(f"C estimator core: {msg.value.decode() or _STATUS.get(rc, rc)}")
        self._handle = handle
        self._names = tuple(self._lib.duffid_parameter_name(handle, i).decode()
                            for i in range(self._lib.duffid_n_parameters(handle)))
        self.capacity = int(self._lib.duffid_capacity(handle)) if method == "robust" else None
        self._x = (ctypes.c_double * self.model.n_dof)()
        self._f = (ctypes.c_double * self.model.n_forces)()
        self._out = _Output()
        self.n = -1

    def __del__(self) -> None:
        self.close()

    def close(self) -> None:
        """Release the C estimator (also done when the object is collected)."""
        handle = getattr(self, "_handle", None)
        if handle is not None and handle.value:
            self._lib.duffid_destroy(handle)
            self._handle = None

    def __enter__(self) -> "CIdentifier":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _live(self) -> ctypes.c_void_p:
        if self._handle is None:
            raise InputError("the C estimator was closed")
        return self._handle

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """Public parameter names of the model, in output order."""
        return self._names

    def reset(self) -> None:
        """Forget all samples (start a new identification)."""
        self._lib.duffid_reset(self._live())
        self.n = -1

    def update(self, x: float | Sequence[float] | np.ndarray, f: float | Sequence[float] | np.ndarray) -> Estimate:
        """Consume one sample of displacements ``x`` and forces ``f``; return the estimate."""
        xa, fa = self.checked_sample(x, f)
        for i, v in enumerate(xa):
            self._x[i] = v
        for i, v in enumerate(fa):
            self._f[i] = v
        rc = self._lib.duffid_update(self._live(), self._x, self._f, ctypes.byref(self._out))
        if rc == -3:
            raise InputError(f"{self.model.name}: sample {self.n + 1} is not finite (x={xa}, f={fa})")
        if rc != 0:
            raise RuntimeError(f"C estimator core: {_STATUS.get(rc, rc)}")
        self.n += 1
        return self._estimate()

    def flush(self) -> Estimate | None:
        """Process a sample held back as a suspect outlier (see ``OnlineIdentifier.flush``)."""
        return self._estimate() if self._lib.duffid_flush(self._live(), ctypes.byref(self._out)) else None

    def _estimate(self) -> Estimate:
        out = self._out
        params = {name: out.parameters[i] for i, name in enumerate(self._names)}
        current = {name: out.current[i] for i, name in enumerate(self._names)}
        status = {name: STATUSES[out.status[i]] for i, name in enumerate(self._names)}
        return Estimate(out.t, params, bool(out.identified), out.condition, out.uncertainty, out.window, current,
                        status, int(out.outliers))

    def run(self, x: np.ndarray, f: np.ndarray) -> np.ndarray:
        """Consume many samples in one call: ``x`` (n, n_dof), ``f`` (n, n_forces).

        Returns the outputs as a structured array with fields ``t``, ``parameters``
        (n, parameters), ``identified``, ``condition``, ``uncertainty``, ``window``,
        ``current`` and ``status`` (codes: indices into
        :data:`~duffid.identification.engine.STATUSES`; see :class:`~duffid.identification.engine.Estimate`).
        """
        xa = np.ascontiguousarray(np.asarray(x, dtype=float).reshape(len(x), -1))
        fa = np.ascontiguousarray(np.asarray(f, dtype=float).reshape(len(f), -1))
        if xa.shape[1] != self.model.n_dof or fa.shape[1] != self.model.n_forces or len(xa) != len(fa):
            raise InputError(f"{self.model.name}: run needs x of shape (n, {self.model.n_dof}) and f of shape "
                             f"(n, {self.model.n_forces}), got {xa.shape} and {fa.shape}")
        n = len(xa)
        out = (_Output * n)()
        failed = ctypes.c_long(-1)
        dbl_p = ctypes.POINTER(ctypes.c_double)
        rc = self._lib.duffid_run(self._live(), n, xa.ctypes.data_as(dbl_p), fa.ctypes.data_as(dbl_p),
                                  out, ctypes.byref(failed))
        if rc == -3:
            k = failed.value
            self.n += k
            raise InputError(f"{self.model.name}: sample {self.n + 1} is not finite (x={xa[k]}, f={fa[k]})")
        if rc != 0:
            raise RuntimeError(f"C estimator core: {_STATUS.get(rc, rc)}")
        self.n += n
        return np.frombuffer(memoryview(out).cast("B"), dtype=_OUTPUT_DTYPE) if n else np.zeros(0, _OUTPUT_DTYPE)

    def identify_record(self, record: Record) -> Identification:
        """Run the identifier over a record in one call (like ``OnlineIdentifier.identify_record``)."""
        check_record(record, self.model, self.dt)
        self.reset()
        rows = self.run(record.x, record.f)
        if len(rows) and self._lib.duffid_flush(self._live(), ctypes.byref(self._out)):
            rows = rows.copy()
            rows[-1] = np.frombuffer(memoryview(self._out).cast("B"), dtype=_OUTPUT_DTYPE)[0]
        found = np.flatnonzero(np.diff(rows["outliers"], prepend=0) > 0)
        history = {name: rows["parameters"][:, i].copy() for i, name in enumerate(self._names)}
        flags = rows["identified"].astype(bool)
        return Identification(
            model=self.model.name, method=self.method,
            parameters={name: float(history[name][-1]) for name in self._names},
            t=record.t - record.t[0], history=history, condition=rows["condition"].copy(), identified=flags,
            t_identified=float(record.t[np.argmax(flags)] - record.t[0]) if flags.any() else None,
            window=float(rows["window"][-1]), options=dict(self.options), source=record.source,
            estimates={name: float(rows["current"][-1, i]) for i, name in enumerate(self._names)},
            online_status={name: STATUSES[rows["status"][-1, i]] for i, name in enumerate(self._names)},
            outliers=[{"t": float(rows["outlier_t"][k]), "column": f"x{int(rows['outlier_column'][k]) + 1}",
                       "value": float(rows["outlier_value"][k]), "replaced_by": float(rows["outlier_replaced_by"][k])}
                      for k in found],
        )
