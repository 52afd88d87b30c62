"""Output-error refinement of identified parameters (an offline step).

The algebraic estimator (:mod:`duffid.identification.engine`) is an *equation-error* method:
it fits the integrated equation of motion to the measured signals, which is fast, online
and needs no initial guess, but weights the errors by the regressors and is biased when
the quadrature or the noise model are imperfect. This module refines an estimate by the
*output-error* criterion instead: the identified ODE is simulated under the measured
input and the parameters (and the initial state) are adjusted by
:func:`scipy.optimize.least_squares` until the simulated output matches the measured one
in the least-squares sense. It needs the whole record and a good starting point (the
algebraic estimate), so it is **offline only**.

Simulator
---------
:class:`OdeSimulator` integrates a :class:`~duffid.models.chain.Chain` (any number of masses,
polynomial springs, Coulomb friction, offsets) with the classical fixed-step Runge-Kutta
method (RK4), ``substeps`` steps per sample. The input is needed at every step and
half-step; it is interpolated between the samples either band-limited (the record was
sampled with an anti-alias filter, as measured data are: :func:`upsample`) or linearly
(piecewise-linear inputs, e.g. simulated steps). The step is built symbolically with
CasADi (a dependency of duffid) and run over the whole record by its compiled
virtual machine (``Function.mapaccum``), so a 100k-sample simulation takes a fraction of
a second. The same step propagates the exact derivatives of the discrete solution with
respect to the free parameters and the initial state (forward sensitivities), which
give :func:`scipy.optimize.least_squares` an exact Jacobian.

RK4's local error is ``O((omega h)^5)``. At the Silverbox's 9 samples per period the
default four steps per sample (``omega h ~ 0.17``) agree with SciPy's DOP853 at tolerance
1e-10 to about 1e-4 of the output RMS (5e-4 is asserted in ``tests/test_refine.py``; one
step per sample errs by several per cent, two by about 3e-3): for the Silverbox 0.006 mV,
far below its 0.3 mV error figures. Smoothed Coulomb friction
(``tanh(v / friction_velocity)``) is stiff: raise ``substeps`` for such models.
"""
from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import casadi as ca
import numpy as np
from tqdm import tqdm

from ..data.record import Record
from ..errors import InputError, RecordError
from ..models.chain import Chain

__all__ = [
    "upsample",
    "OdeSimulator",
    "canonical_from_public",
    "fit_initial_state",
    "simulate_record",
    "rms_error",
    "refine",
    "Refinement",
    "stretches",
    "correlation_factor",
]

INTERPOLATIONS = ("bandlimited", "linear")
#: :func:`refine` solves with a dense Jacobian (exact trust-region steps) up to this many
#: entries, with a sparse one (LSMR steps) beyond.
DENSE_JACOBIAN = 20_000_000
_FILTER_HALF = 24     # taps per side of the interpolation filter, in input samples
_FILTER_BETA = 8.6    # Kaiser window: passband ripple ~1e-5 up to 0.33 fs


# ---------------------------------------------------------------------- interpolation
def upsample(values: np.ndarray, factor: int, *, method: str = "bandlimited") -> np.ndarray:
    """Interpolate evenly sampled signals onto a grid ``factor`` times finer.

    Parameters
    ----------
    values : array_like, shape (N,) or (N, channels)
        Samples along axis 0.
    factor : int
        Upsampling factor ``q >= 1``.
    method : {"bandlimited", "linear"}
        ``bandlimited``: polyphase interpolation (:func:`scipy.signal.resample_poly`)
        with a Kaiser-windowed sinc of 24 input samples per side (relative error about
        1e-5 for frequencies up to a third of the sampling rate); the record is extended
        at both ends by odd reflection so that its ends are not pulled towards zero.
        Exact for band-limited signals away from the ends (the first and last few
        samples carry an extrapolation error). ``linear``: straight lines between
        samples (exact for piecewise-linear inputs such as ramps and steps on a sample).

    Returns
    -------
    numpy.ndarray, shape (q (N - 1) + 1, ...)
        Interpolated signal; every ``q``-th value is the original sample.
    """
    from scipy.signal import firwin, resample_poly  # imported here: keeps `import duffid.identification.refine` light

    x = np.asarray(values, dtype=float)
    q = int(factor)
    if q != factor or q < 1:
        raise InputError(f"upsampling factor must be an integer >= 1, got {factor!r}")
    if method not in INTERPOLATIONS:
        raise InputError(f"unknown interpolation {method!r}; choose {' or '.join(INTERPOLATIONS)}")
    n = x.shape[0]
    if q == 1 or n < 2:
        return x.copy()
    if method == "linear":
        fine = np.arange(q * (n - 1) + 1) / q
        flat = x.reshape(n, -1)
        out = np.column_stack([np.interp(fine, np.arange(n), flat[:, c]) for c in range(flat.shape[1])])
        return out.reshape((len(fine),) + x.shape[1:])
    pad = min(_FILTER_HALF + 1, n - 1)
    left = 2.0 * x[:1] - x[pad:0:-1]
    right = 2.0 * x[-1:] - x[-2:-pad - 2:-1]
    extended = np.concatenate([left, x, right], axis=0)
    taps = firwin(2 * _FILTER_HALF * q + 1, 1.0 / q, window=("kaiser", _FILTER_BETA))
    fine = resample_poly(extended, q, 1, axis=0, window=taps)
    out = fine[q * pad: q * pad + q * (n - 1) + 1].copy()
    out[::q] = x
    return out


# ---------------------------------------------------------------------- dynamics
def canonical_from_public(model: Chain, values: Mapping[str, float]) -> dict[str, float]:
    """Canonical parameters (``m1``, ``b1``, ``k1_3``, ``c1``, ...) from public or canonical ones.

    Parameters
    ----------
    model : Chain
        Model structure; its own values fill parameters that ``values`` lacks.
    values : mapping
        Parameter values under the model's public names (e.g. ``m, b, k, kp`` of
        :class:`~duffid.models.chain.Duffing1`, ``L, R, C, a`` of the circuit) or canonical names.

    Raises
    ------
    ValueError
        On a name the model does not know.
    """
    canonical = model.canonical_parameters()
    values = dict(values)
    if set(values) <= set(canonical):
        return {**canonical, **{k: float(v) for k, v in values.items()}}
    public = model.parameters
    unknown = set(values) - set(public) - set(canonical)
    if unknown:
        raise InputError(f"{model.name}: unknown parameter(s) {sorted(unknown)}; "
                         f"known: {', '.join(public)}")
    offsets = {k: float(v) for k, v in values.items() if k in canonical and k not in public}
    named = {k: float(values.get(k, v)) for k, v in public.items()
             if not (k.startswith("c") and k[1:].isdigit() and model.offset)}
    try:
        rebuilt = type(model)(**named, offset=model.offset)  # type: ignore[call-arg]
    except TypeError as exc:
        raise InputError(f"{model.name}: cannot map public parameters to canonical ones ({exc}); "
                         "give canonical names") from None
    out = rebuilt.canonical_parameters()
    for k in canonical:
        if k.startswith("c") and k[1:].isdigit():
            out[k] = float(values.get(k, offsets.get(k, 0.0)))
    return out


class OdeSimulator:
    """Fixed-step RK4 simulation of a chain model under a sampled input, with sensitivities.

    Parameters
    ----------
    model : Chain
        Model structure; parameter values are passed to each call.
    dt : float
        Sampling period of the records [s].
    substeps : int
        RK4 steps per sample (default 4).
    interpolation : {"bandlimited", "linear"}
        How the input is interpolated between samples (see :func:`upsample`).
    free : sequence of str, optional
        Canonical parameters whose sensitivities are propagated (default: all).
    friction_velocity : float
        Smoothing velocity of Coulomb friction, as in :func:`duffid.simulate`.

    Attributes
    ----------
    names : tuple of str
        Canonical parameter names, the order of the parameter vector.
    """

    def __init__(self, model: Chain, dt: float, *, substeps: int = 4, interpolation: str = "bandlimited",
                 free: Sequence[str] | None = None, friction_velocity: float = 1e-4) -> None:
        if not (math.isfinite(dt) and dt > 0):
            raise InputError(f"dt must be a positive number of seconds, got {dt!r}")
        if int(substeps) != substeps or substeps < 1:
            raise InputError(f"substeps must be an integer >= 1, got {substeps!r}")
        if interpolation not in INTERPOLATIONS:
            raise InputError(f"unknown interpolation {interpolation!r}; choose {' or '.join(INTERPOLATIONS)}")
        self.model = model
        self.dt = float(dt)
        self.substeps = int(substeps)
        self.interpolation = interpolation
        self.names = tuple(model.canonical_parameters())
        free = self.names if free is None else tuple(free)
        unknown = set(free) - set(self.names)
        if unknown:
            raise InputError(f"{model.name}: unknown free parameter(s) {sorted(unknown)}; "
                             f"canonical names are {', '.join(self.names)}")
        self.free = tuple(n for n in self.names if n in free)
        self.friction_velocity = float(friction_velocity)
        self._build()
        self._cache: dict[tuple[bool, int], ca.Function] = {}

    # -------------------------------------------------------------- construction
    def _build(self) -> None:
        n, nf = self.model.n_dof, self.model.n_forces
        z = ca.SX.sym("z", 2 * n)
        u = ca.SX.sym("u", 3 * nf)  # input at t, t + h/2, t + h
        p = ca.SX.sym("p", len(self.names))
        h = ca.SX.sym("h")
        named = {name: p[i] for i, name in enumerate(self.names)}

        def rhs(state: ca.SX, force: ca.SX) -> ca.SX:
            xs = [state[i] for i in range(n)]
            vs = [state[n + i] for i in range(n)]
            fs = [force[i] for i in range(nf)]
            acc = self.model.symbolic_acceleration(named, xs, vs, fs, self.friction_velocity)
            return ca.vertcat(*vs, *acc)

        u0, uh, u1 = u[:nf], u[nf:2 * nf], u[2 * nf:]
        k1 = rhs(z, u0)
        k2 = rhs(z + h / 2 * k1, uh)
        k3 = rhs(z + h / 2 * k2, uh)
        k4 = rhs(z + h * k3, u1)
        z_next = z + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        self._step = ca.Function("rk4", [z, u, p, h], [z_next])
        # sensitivities S = dz/d(free parameters, initial state), propagated exactly
        free_idx = [self.names.index(name) for name in self.free]
        n_sens = len(free_idx) + 2 * n
        S = ca.SX.sym("S", 2 * n, n_sens)
        dz = ca.jacobian(z_next, z)
        dp = ca.jacobian(z_next, p)[:, free_idx] if free_idx else ca.SX(2 * n, 0)
        S_next = dz @ S + ca.horzcat(dp, ca.SX(2 * n, 2 * n))
        self._step_sens = ca.Function("rk4_sens", [ca.vertcat(z, ca.vec(S)), u, p, h],
                                      [ca.vertcat(z_next, ca.vec(S_next))])
        self._n_sens = n_sens

    def _runner(self, sensitivities: bool, steps: int) -> ca.Function:
        key = (sensitivities, steps)
        if key not in self._cache:
            step = self._step_sens if sensitivities else self._step
            if len(self._cache) > 8:
                self._cache.clear()
            self._cache[key] = step.mapaccum("simulate", steps)
        return self._cache[key]

    # -------------------------------------------------------------- evaluation
    def parameter_vector(self, parameters: Mapping[str, float]) -> np.ndarray:
        """The canonical parameters as a vector in :attr:`names` order."""
        missing = set(self.names) - set(parameters)
        if missing:
            raise InputError(f"{self.model.name}: missing parameter(s) {sorted(missing)}")
        return np.array([float(parameters[name]) for name in self.names])

    def stage_inputs(self, f: np.ndarray) -> np.ndarray:
        """The input at every RK4 stage: shape ``(3 nf, substeps (N - 1))``, columns per step
        (start, middle, end). A stretch of it, ``[:, substeps i : substeps j]``, drives
        :meth:`simulate_stages` from sample ``i`` to ``j`` with the interpolation of the
        whole record (no edge of its own)."""
        f = np.asarray(f, dtype=float).reshape(len(f), -1)
        if f.shape[1] != self.model.n_forces:
            raise InputError(f"{self.model.name} has {self.model.n_forces} input(s), got {f.shape[1]} column(s)")
        fine = upsample(f, 2 * self.substeps, method=self.interpolation)
        return np.vstack([fine[0:-1:2].T, fine[1::2].T, fine[2::2].T])

    def simulate(self, parameters: Mapping[str, float], f: np.ndarray, x0: Sequence[float],
                 v0: Sequence[float], *, sensitivities: bool = False
                 ) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """Simulate from the state ``(x0, v0)`` under the sampled input ``f``.

        Parameters
        ----------
        parameters : mapping
            Canonical parameter values.
        f : array_like, shape (N,) or (N, nf)
            Input samples, one every ``dt``.
        x0, v0 : sequence of float
            Displacements and velocities at the first sample.
        sensitivities : bool
            Also return the derivatives of the displacements.

        Returns
        -------
        x : numpy.ndarray, shape (N, n_dof)
            Simulated displacements at the samples (non-finite where the solution escaped).
        dx : numpy.ndarray, shape (N, n_dof, len(free) + 2 n_dof)
            Only with ``sensitivities``: derivatives of ``x`` with respect to the free
            parameters (in :attr:`free` order) and the initial state ``(x0, v0)``.
        """
        return self.simulate_stages(parameters, self.stage_inputs(f), x0, v0, sensitivities=sensitivities)

    def simulate_stages(self, parameters: Mapping[str, float], stages: np.ndarray, x0: Sequence[float],
                        v0: Sequence[float], *, sensitivities: bool = False
                        ) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """:meth:`simulate` under stage inputs (:meth:`stage_inputs`, or a stretch of them)."""
        n = self.model.n_dof
        U = stages
        samples = U.shape[1] // self.substeps + 1
        z0 = np.concatenate([np.asarray(x0, float).reshape(n), np.asarray(v0, float).reshape(n)])
        p = self.parameter_vector(parameters)
        h = self.dt / self.substeps
        if sensitivities:
            S0 = np.zeros((2 * n, self._n_sens))
            S0[:, self._n_sens - 2 * n:] = np.eye(2 * n)
            z0 = np.concatenate([z0, S0.ravel(order="F")])
        if samples < 2:
            out = z0[:, None]
        else:
            states = np.asarray(self._runner(sensitivities, U.shape[1])(z0, U, p, h))
            out = np.column_stack([z0, states[:, self.substeps - 1::self.substeps]])
        x = out[:n].T.copy()
        if not sensitivities:
            return x
        S = out[2 * n:].reshape(2 * n, self._n_sens, samples, order="F")
        return x, np.transpose(S[:n], (2, 0, 1)).copy()


# ---------------------------------------------------------------------- helpers
def rms_error(measured: np.ndarray, simulated: np.ndarray, *, skip: int = 50) -> float:
    """Root-mean-square of ``simulated - measured`` over the samples from ``skip`` on.

    The Silverbox community's figure: the simulated (not one-step-ahead) output, the
    first 50 samples left out. Returns ``inf`` when the simulation escaped (non-finite).
    """
    a = np.asarray(measured, dtype=float)
    b = np.asarray(simulated, dtype=float)
    if a.shape != b.shape:
        raise InputError(f"measured {a.shape} and simulated {b.shape} outputs differ in shape")
    if a.shape[0] <= skip:
        raise InputError(f"{a.shape[0]} samples: nothing left after skipping {skip}")
    err = b[skip:] - a[skip:]
    if not np.all(np.isfinite(err)):
        return float("inf")
    return float(np.sqrt(np.mean(err**2)))


def _difference_state(x: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """First displacement and a second-order one-sided difference for the velocity."""
    if len(x) < 3:
        return x[0].copy(), (x[1] - x[0]) / dt
    return x[0].copy(), (-3.0 * x[0] + 4.0 * x[1] - x[2]) / (2.0 * dt)


def fit_initial_state(simulator: OdeSimulator, parameters: Mapping[str, float], record: Record,
                      *, window: int = 50) -> tuple[np.ndarray, np.ndarray]:
    """Initial state that best reproduces the first ``window`` samples of the record.

    Output-error least squares over two numbers per DOF (``x0``, ``v0``), started from
    the first sample and a finite-difference velocity; the model parameters are fixed.
    This is the "state initialisation window" of the Silverbox benchmark: errors are then
    reported from sample ``window`` on.
    """
    stop = min(max(window, 3), record.n_samples)
    # the input is interpolated over a margin past the window so that its end is not an edge
    stages = simulator.stage_inputs(record.f[:stop + _FILTER_HALF + 1])
    return _fit_state(simulator, parameters, stages[:, :simulator.substeps * (stop - 1)], record.x[:stop],
                      record.dt, float(np.std(record.x)))


def _fit_state(simulator: OdeSimulator, parameters: Mapping[str, float], stages: np.ndarray, x: np.ndarray,
               dt: float, spread: float) -> tuple[np.ndarray, np.ndarray]:
    """The state at the first of the samples ``x`` from which the simulation under ``stages``
    best reproduces them (started from a finite-difference state; kept when that escapes)."""
    from scipy.optimize import least_squares

    n = x.shape[1]
    x0, v0 = _difference_state(x, dt)
    scale_x = max(spread, 1e-300)
    scales = np.concatenate([np.full(n, scale_x), np.full(n, scale_x / dt)])

    def residual(z: np.ndarray) -> np.ndarray:
        s = z * scales
        out = simulator.simulate_stages(parameters, stages, s[:n], s[n:])
        r = (out - x).ravel() / scale_x
        return np.where(np.isfinite(r), r, 1e6)

    def jacobian(z: np.ndarray) -> np.ndarray:
        s = z * scales
        _, dx = simulator.simulate_stages(parameters, stages, s[:n], s[n:], sensitivities=True)
        J = dx[:, :, -2 * n:].reshape(-1, 2 * n) * scales / scale_x
        return np.where(np.isfinite(J), J, 0.0)

    start = np.concatenate([x0, v0]) / scales
    if not np.all(np.isfinite(residual(start))):
        return x0, v0
    sol = least_squares(residual, start, jac=jacobian, method="lm", max_nfev=50, xtol=1e-12, ftol=1e-12)
    s = sol.x * scales
    return s[:n], s[n:]


def simulate_record(record: Record, model: Chain, parameters: Mapping[str, float], *,
                    substeps: int = 4, interpolation: str = "bandlimited", init_window: int = 50,
                    initial_state: tuple[Sequence[float], Sequence[float]] | None = None) -> Record:
    """Simulate ``model`` under the inputs of ``record`` (the simulated-output predictor).

    Parameters
    ----------
    record : Record
        Measured record; its inputs drive the model.
    model : Chain
        Model structure.
    parameters : mapping
        Parameter values, public or canonical names (see :func:`canonical_from_public`).
    substeps, interpolation
        See :class:`OdeSimulator`.
    init_window : int
        Samples used to fit the initial state (:func:`fit_initial_state`); 0 starts from
        the first sample and a finite-difference velocity.
    initial_state : (x0, v0), optional
        Use this initial state instead.

    Returns
    -------
    Record
        Same ``t`` and ``f``; ``x`` is the simulated output.
    """
    canonical = canonical_from_public(model, parameters)
    sim = OdeSimulator(model, record.dt, substeps=substeps, interpolation=interpolation, free=())
    if initial_state is not None:
        x0, v0 = initial_state
    elif init_window > 0:
        x0, v0 = fit_initial_state(sim, canonical, record, window=init_window)
    else:
        x0, v0 = _difference_state(record.x, record.dt)
    x = sim.simulate(canonical, record.f, x0, v0)
    if not np.all(np.isfinite(x)):
        bad = int(np.argmax(~np.all(np.isfinite(x), axis=1)))
        raise RecordError(f"{record.source}: the simulated {model.name} escaped (non-finite output) "
                          f"at sample {bad}; the parameters do not describe a stable system for this input")
    return Record(record.t, record.f, x, source=f"{record.source} (simulated {model.name})")


# ---------------------------------------------------------------------- refinement
@dataclass
class Refinement:
    """Result of :func:`refine`.

    Attributes
    ----------
    model : str
        Model name.
    parameters : dict
        Refined parameters under the model's public names.
    canonical : dict
        Refined parameters under canonical names.
    start : dict
        Canonical starting values (the algebraic estimate).
    relative_std : dict
        Relative standard error of each free parameter from the final Jacobian
        (``s^2 (J^T J)^-1``, the stretches' initial states eliminated), inflated by the
        residual's autocorrelation (:func:`correlation_factor`); it assumes the model
        structure is right.
    initial_state : tuple of ndarray
        Fitted displacements and velocities at the first sample.
    rms_start, rms : float
        RMS output error (record units) before and after, over the fitted samples.
    nfev : int
        Simulations run by the optimiser.
    success : bool
        Whether :func:`scipy.optimize.least_squares` reported convergence.
    message : str
        Its message.
    """

    model: str
    parameters: dict[str, float]
    canonical: dict[str, float]
    start: dict[str, float]
    relative_std: dict[str, float]
    initial_state: tuple[np.ndarray, np.ndarray]
    rms_start: float
    rms: float
    nfev: int
    success: bool
    message: str
    options: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary."""
        def clean(v: float) -> float | None:
            return float(v) if np.isfinite(v) else None
        return {
            "model": self.model,
            "parameters": {k: clean(v) for k, v in self.parameters.items()},
            "start": {k: clean(v) for k, v in self.start.items()},
            "relative_std": {k: clean(v) for k, v in self.relative_std.items()},
            "rms_start": clean(self.rms_start),
            "rms": clean(self.rms),
            "nfev": self.nfev,
            "success": self.success,
            "message": self.message,
            "options": dict(self.options),
        }


def _progress_bar(enabled: bool | None, total: int, desc: str) -> tqdm:
    disable = not sys.stderr.isatty() if enabled is None else not enabled
    return tqdm(total=total, desc=desc, disable=disable, leave=False, unit="sim")


def refine(record: Record, model: Chain, start: Mapping[str, float], *, free: Sequence[str] | None = None,
           skip: int = 0, substeps: int = 4, interpolation: str = "bandlimited", max_nfev: int = 50,
           progress: bool | None = None, segment: int | None = None, **lsq_options: Any) -> Refinement:
    """Refine parameters by output-error least squares (offline).

    Minimises ``sum (x_sim - x)^2`` over the samples from ``skip`` on, where ``x_sim`` is
    the simulation (:class:`OdeSimulator`) of ``model`` under the inputs of ``record``
    from a fitted initial state, with :func:`scipy.optimize.least_squares`
    (trust-region reflective, exact Jacobian from the forward sensitivities, parameters
    scaled by their starting values).

    A lightly damped nonlinear plant's free run can drift onto another branch (or be
    chaotic: a hardening spring under random force) so that no parameter set follows a long
    record from one initial state. ``segment`` then cuts the record into stretches that are
    each simulated from their own state, fitted with the parameters (multiple shooting:
    ``2 n_dof`` more unknowns per stretch, a sparse Jacobian).

    Parameters
    ----------
    record : Record
        Measured record (all displacement columns are fitted).
    model : Chain
        Model structure.
    start : mapping
        Starting values, public or canonical names, typically
        ``identify(record, model).parameters``; every value must be finite.
    free : sequence of str, optional
        Canonical names of the parameters to adjust (default: all); the others stay at
        their starting values. The initial state is always fitted.
    skip : int
        Samples left out of the criterion at the start (0: all, the initial state is fitted).
    substeps, interpolation
        See :class:`OdeSimulator`.
    max_nfev : int
        Largest number of simulations.
    progress : bool or None
        tqdm progress bar; None: only when stderr is a terminal.
    segment : int, optional
        Samples per stretch (at least 4) for multiple shooting; None: one simulation over
        the whole record. The last stretch takes the remainder when it is shorter than half.
    **lsq_options
        Passed to :func:`scipy.optimize.least_squares` (e.g. ``ftol``, ``xtol``).

    Returns
    -------
    Refinement

    Raises
    ------
    ValueError
        On a non-finite starting value, a stretch shorter than 4 samples, or when the start
        does not simulate (escapes).
    RecordError
        When the record does not fit the model.
    """
    from scipy.optimize import least_squares
    from scipy.sparse import block_diag, csr_matrix, hstack

    bad = [k for k, v in start.items() if not np.isfinite(v)]
    canonical = canonical_from_public(model, start) if not bad else {}
    if bad:
        raise InputError(f"{model.name}: starting value(s) of {bad} not finite; the algebraic estimate "
                         "did not identify them (longer record, or looser max_uncertainty)")
    if record.n_dof != model.n_dof or record.n_forces != model.n_forces:
        raise RecordError(f"{record.source}: model {model.name} needs {model.n_dof} output(s) and "
                          f"{model.n_forces} input(s), the record has {record.n_dof} and {record.n_forces}")
    if record.n_samples <= skip + 3:
        raise RecordError(f"{record.source}: {record.n_samples} samples, too few to refine with skip={skip}")
    if segment is not None and (int(segment) != segment or segment < 4):
        raise InputError(f"segment must be a whole number of samples >= 4, got {segment!r}")
    sim = OdeSimulator(model, record.dt, substeps=substeps, interpolation=interpolation, free=free)
    n, q = model.n_dof, sim.substeps
    names = sim.free
    bounds = stretches(record.n_samples, record.n_samples if segment is None else int(segment))
    stages = sim.stage_inputs(record.f)
    drive = [stages[:, q * a:q * (b - 1)] for a, b in bounds]
    kept = [np.arange(a, b) >= skip for a, b in bounds]  # samples in the criterion
    p_scale = np.array([abs(canonical[k]) or abs(model.canonical_parameters()[k]) or 1.0 for k in names])
    x_scale = max(float(np.std(record.x)), 1e-300)
    s_scale = np.tile(np.concatenate([np.full(n, x_scale), np.full(n, x_scale / record.dt)]), len(bounds))
    scales = np.concatenate([p_scale, s_scale])
    window = 50 if segment is None else max(3, int(segment) // 4)
    states = [np.concatenate(_fit_state(sim, canonical, U[:, :q * (min(window, b - a) - 1)],
                                        record.x[a:a + min(window, b - a)], record.dt, x_scale))
              for U, (a, b) in zip(drive, bounds)]
    start_vec = np.concatenate([[canonical[k] for k in names], *states]) / scales
    target = np.concatenate([record.x[a:b][m] for (a, b), m in zip(bounds, kept)])
    bar = _progress_bar(progress, max_nfev, f"refine {model.name}")
    cache: dict[str, Any] = {}
    n_p = len(names)

    def unpack(z: np.ndarray) -> tuple[dict[str, float], np.ndarray]:
        values = z * scales
        params = dict(canonical)
        params.update(zip(names, values[:n_p]))
        return params, values[n_p:].reshape(len(bounds), 2 * n)

    def evaluate(z: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
        key = z.tobytes()
        if cache.get("key") != key:
            params, initial = unpack(z)
            xs, dxs = [], []
            for U, state, m in zip(drive, initial, kept):
                x, dx = sim.simulate_stages(params, U, state[:n], state[n:], sensitivities=True)
                xs.append(x[m])
                dxs.append(dx[m])
            cache.update(key=key, x=np.concatenate(xs), dx=dxs)
            bar.update(1)
        return cache["x"], cache["dx"]

    def residual(z: np.ndarray) -> np.ndarray:
        x, _ = evaluate(z)
        return ((x - target) / x_scale).ravel()

    def blocks(z: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        """Per stretch: the Jacobian's columns of the parameters and of its own state."""
        _, dxs = evaluate(z)
        out = []
        for i, dx in enumerate(dxs):
            J = dx.reshape(-1, dx.shape[2]) / x_scale
            J = np.where(np.isfinite(J), J, 0.0)
            out.append((J[:, :n_p] * p_scale, J[:, n_p:] * s_scale[2 * n * i:2 * n * (i + 1)]))
        return out

    rows, columns = target.size, len(scales)
    dense = len(bounds) == 1 or rows * columns <= DENSE_JACOBIAN

    def jacobian(z: np.ndarray) -> np.ndarray | Any:
        parts = blocks(z)
        if dense:
            out = np.zeros((rows, columns))
            row = 0
            for i, (p, s) in enumerate(parts):
                out[row:row + len(p), :n_p] = p
                out[row:row + len(p), n_p + 2 * n * i:n_p + 2 * n * (i + 1)] = s
                row += len(p)
            return out
        return hstack([csr_matrix(np.vstack([p for p, _ in parts])), block_diag([s for _, s in parts])],
                      format="csr")

    r0 = residual(start_vec)
    if not np.all(np.isfinite(r0)):
        bar.close()
        raise InputError(f"{record.source}: the starting model {model.name} escapes (non-finite simulated "
                         "output); refinement needs a start that simulates")
    options = {"method": "trf", "x_scale": 1.0, "max_nfev": max_nfev, **lsq_options}
    try:
        sol = least_squares(residual, start_vec, jac=jacobian, **options)
    finally:
        bar.close()
    params, initial = unpack(sol.x)
    rms_start = float(np.sqrt(np.mean(r0**2))) * x_scale
    rms = float(np.sqrt(np.mean(sol.fun**2))) * x_scale
    lag = max(1, min(len(target) // 10, 4 * (bounds[0][1] - bounds[0][0])))
    relative = _relative_std(blocks(sol.x), sol.fun.reshape(len(target), n), sol.x[:n_p], lag)
    return Refinement(
        model=model.name, parameters=model.from_canonical(params), canonical=params, start=canonical,
        relative_std=dict(zip(names, relative)), initial_state=(initial[0, :n], initial[0, n:]),
        rms_start=rms_start, rms=rms, nfev=int(sol.nfev), success=bool(sol.success), message=str(sol.message),
        options={"free": list(names), "skip": skip, "substeps": substeps, "interpolation": interpolation,
                 "max_nfev": max_nfev, "segment": segment, "stretches": len(bounds)},
    )


def stretches(n_samples: int, length: int) -> list[tuple[int, int]]:
    """Consecutive ``(start, stop)`` sample ranges of ``length`` (the last one takes a
    remainder shorter than half a stretch)."""
    bounds, start = [], 0
    while start < n_samples:
        stop = n_samples if n_samples - start < length + length // 2 else start + length
        bounds.append((start, stop))
        start = stop
    return bounds


def correlation_factor(residual: np.ndarray, max_lag: int) -> float:
    """Variance inflation of a mean over correlated residuals: ``1 + 2 sum rho_k`` over the
    lags ``1..max_lag`` up to the first non-positive autocorrelation (1 for white residuals;
    each column of ``residual`` is one sequence, the largest factor is returned)."""
    from scipy.signal import correlate

    worst = 1.0
    for r in np.asarray(residual, dtype=float).reshape(len(residual), -1).T:
        energy = float(r @ r)
        if energy == 0 or len(r) < 3:
            continue
        rho = correlate(r, r, mode="full", method="fft")[len(r):len(r) + max_lag] / energy
        stop = int(np.argmax(rho <= 0)) if np.any(rho <= 0) else len(rho)
        worst = max(worst, 1.0 + 2.0 * float(np.sum(rho[:stop])))
    return worst


def _relative_std(blocks: list[tuple[np.ndarray, np.ndarray]], r: np.ndarray, z: np.ndarray,
                  max_lag: int) -> np.ndarray:
    """Relative standard errors of the scaled parameters ``z`` (Gauss-Newton,
    ``s^2 (J^T J)^-1`` with the stretches' states eliminated by their Schur complement,
    inflated for the residual's autocorrelation, :func:`correlation_factor`)."""
    n_params = len(z)
    unknowns = n_params + sum(s.shape[1] for _, s in blocks)
    s2 = float(np.sum(r**2)) / max(r.size - unknowns, 1) * correlation_factor(r, max_lag)
    schur = np.zeros((n_params, n_params))
    for P, S in blocks:
        coupling = P.T @ S
        schur += P.T @ P - coupling @ np.linalg.pinv(S.T @ S) @ coupling.T
    try:
        cov = s2 * np.linalg.pinv(schur)
    except np.linalg.LinAlgError:
        return np.full(n_params, np.inf)
    std = np.sqrt(np.abs(np.diag(cov)))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(z != 0, std / np.abs(z), np.inf)
