"""Simulation of chain models with scipy and the measurement model (encoder, noise)."""
from __future__ import annotations

from typing import Callable, Sequence

import numpy as np
from scipy.integrate import solve_ivp

from ..data.record import Record
from ..errors import InputError, SimulationError
from .chain import Chain

__all__ = ["simulate", "measure", "quantize", "check_changes", "SimulationError", "ENCODER_PULSES_PER_CM"]

#: Effective resolution of the paper's encoder (Section 3.1).
ENCODER_PULSES_PER_CM = 2266.0

Force = Callable[[float], float] | Sequence[Callable[[float], float]]




def _force_function(force: Force, n_forces: int) -> Callable[[np.ndarray], np.ndarray]:
    if callable(force):
        def single(t):
            value = np.asarray(force(t), dtype=float)
            if value.shape == np.shape(t):  # one value per time: a scalar input
                value = value[..., None]
            return np.broadcast_to(value, np.shape(t) + (n_forces,))
        return single
    funcs = list(force)
    if len(funcs) != n_forces:
        raise InputError(f"the model has {n_forces} force inputs, {len(funcs)} force functions were given")
    return lambda t: np.stack([np.broadcast_to(np.asarray(g(t), dtype=float), np.shape(t)) for g in funcs], axis=-1)


def simulate(model: Chain, force: Force, t_end: float, dt: float, *,
             x0: Sequence[float] | None = None, v0: Sequence[float] | None = None,
             rtol: float = 1e-10, atol: float = 1e-14, max_displacement: float = 1.0,
             friction_velocity: float = 1e-4, changes: Sequence[tuple[float, Chain]] = ()) -> Record:
    """Simulate ``model`` under ``force`` and sample it every ``dt``.

    Parameters
    ----------
    model : Chain
        Plant (any chain, e.g. :class:`~duffid.models.chain.Duffing1`).
    force : callable or sequence of callables
        ``force(t)`` giving the force on each forced DOF (a scalar for one input), or
        one callable per force input. Excitations from :mod:`duffid.data.signals` fit.
    t_end, dt : float
        Duration and sampling period [s]; samples at ``k * dt`` for ``k = 0 .. t_end/dt``.
    x0, v0 : sequence of float, optional
        Initial displacements and velocities (default rest).
    rtol, atol : float
        Tolerances of the DOP853 solver (tight by default).
    max_displacement : float
        Abort with :class:`SimulationError` when any displacement exceeds this [m]: the
        softening spring of the paper lets the mass escape its potential well (14 N step).
    friction_velocity : float
        Smoothing velocity of Coulomb friction (``tanh(v / friction_velocity)``).
    changes : sequence of (float, Chain), optional
        A plant that changes: from each time [s] (increasing, within the record) on, the
        plant is that chain (same degrees of freedom and forces), its displacements and
        velocities continuing (a payload added, a spring that cracks). A drift is a
        staircase of small changes.

    Returns
    -------
    Record
        Exact (noise-free) samples of the forces and displacements.
    """
    if not (np.isfinite(dt) and dt > 0 and np.isfinite(t_end) and t_end > dt):
        raise InputError(f"need 0 < dt < t_end, got dt={dt!r}, t_end={t_end!r}")
    n = model.n_dof
    n_samples = int(round(t_end / dt)) + 1
    t = np.arange(n_samples) * dt
    forcing = _force_function(force, model.n_forces)
    state0 = np.concatenate([np.zeros(n) if x0 is None else np.asarray(x0, float),
                             np.zeros(n) if v0 is None else np.asarray(v0, float)])
    if state0.shape != (2 * n,):
        raise InputError(f"x0 and v0 need {n} values each")

    plants = check_changes(model, changes, t[-1])
    bounds = [0.0, *(time for time, _ in plants), float(t[-1])]
    pieces = []
    for k, plant in enumerate([model, *(p for _, p in plants)]):
        start, stop = bounds[k], bounds[k + 1]
        inside = t[(t >= start) & (t < stop)] if k + 1 < len(bounds) - 1 else t[t >= start]
        y, state0 = _integrate(plant, forcing, start, stop, inside, state0, rtol, atol, max_displacement,
                               friction_velocity, dt)
        pieces.append(y)
    x = np.concatenate(pieces, axis=1)[:n].T.copy()
    f = np.asarray(forcing(t), dtype=float).reshape(n_samples, model.n_forces)
    return Record(t=t, f=f, x=x, source=f"simulated {model.name}" + (" (changing)" if plants else ""))


def check_changes(model: Chain, changes: Sequence[tuple[float, Chain]], t_end: float) -> list[tuple[float, Chain]]:
    """``changes`` (as :func:`simulate` takes them) checked: increasing times within (0, t_end),
    chains shaped like ``model``; raises :class:`~duffid.errors.InputError` otherwise."""
    out, last = [], 0.0
    for i, item in enumerate(changes):
        try:
            time, plant = item
            time = float(time)
        except (TypeError, ValueError):
            raise InputError(f"changes[{i}] must be (time, chain), got {item!r}") from None
        if not (last < time < t_end):
            raise InputError(f"changes[{i}]: time {time!r} s is not after the previous change and within the "
                             f"record (0 .. {t_end:g} s)")
        if not isinstance(plant, Chain) or (plant.n_dof, plant.n_forces) != (model.n_dof, model.n_forces):
            raise InputError(f"changes[{i}]: the plant must be a chain with {model.n_dof} degree(s) of freedom "
                             f"and {model.n_forces} force(s) like {model.name}")
        out.append((time, plant))
        last = time
    return out


def _integrate(model: Chain, forcing: Callable[[np.ndarray], np.ndarray], start: float, stop: float,
               samples: np.ndarray, state0: np.ndarray, rtol: float, atol: float, max_displacement: float,
               friction_velocity: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """``model`` from ``state0`` at ``start`` to ``stop``: its states at ``samples`` and at ``stop``."""
    n = model.n_dof

    def rhs(time: float, state: np.ndarray) -> np.ndarray:
        x, v = state[:n], state[n:]
        f = np.asarray(forcing(time), dtype=float).reshape(model.n_forces)
        return np.concatenate([v, model.acceleration(x, v, f, friction_velocity)])

    def escaped(time: float, state: np.ndarray) -> float:
        return max_displacement - np.max(np.abs(state[:n]))

    escaped.terminal = True  # type: ignore[attr-defined]
    wanted = np.append(samples, stop) if not samples.size or samples[-1] < stop else samples
    if stop <= start:  # a single sample
        return state0[:, None].copy(), state0
    sol = solve_ivp(rhs, (start, stop), state0, method="DOP853", t_eval=wanted, rtol=rtol, atol=atol,
                    events=escaped, max_step=10 * dt)
    if sol.status == 1:
        t_escape = float(sol.t_events[0][0])
        raise SimulationError(
            f"{model.name}: a displacement exceeded {max_displacement} m at t = {t_escape:.4f} s "
            "(the response left the spring's potential well); shorten the record or lower the force")
    if not sol.success:
        raise SimulationError(f"{model.name}: ODE solver failed: {sol.message}")
    return sol.y[:, :samples.size], sol.y[:, -1]


def quantize(x: np.ndarray, pulses_per_cm: float = ENCODER_PULSES_PER_CM) -> np.ndarray:
    """Round displacements [m] to the encoder's resolution ``1 / (100 * pulses_per_cm)`` m."""
    counts_per_m = 100.0 * pulses_per_cm
    return np.round(np.asarray(x, dtype=float) * counts_per_m) / counts_per_m


def measure(record: Record, *, pulses_per_cm: float | None = ENCODER_PULSES_PER_CM,
            snr_db: float | None = None, seed: int | None = 0) -> Record:
    """Apply the measurement model to the displacements of ``record``.

    Gaussian noise is added first, at a signal-to-noise ratio ``snr_db`` defined per
    column on the mean square of the displacement (``10 log10(mean(x^2) / sigma^2)``),
    then the result is quantised by the encoder (what an encoder reports). Forces are
    left exact.

    Parameters
    ----------
    record : Record
        Exact record (e.g. from :func:`simulate`).
    pulses_per_cm : float or None
        Encoder resolution; None: no quantisation.
    snr_db : float or None
        Signal-to-noise ratio in dB; None: no noise.
    seed : int or None
        Seed of the noise generator (numpy ``default_rng``).
    """
    x = record.x.copy()
    if snr_db is not None:
        rng = np.random.default_rng(seed)
        sigma = np.sqrt(np.mean(x**2, axis=0) / 10.0 ** (snr_db / 10.0))
        x = x + rng.standard_normal(x.shape) * sigma
    if pulses_per_cm is not None:
        if not pulses_per_cm > 0:
            raise InputError(f"pulses_per_cm must be positive, got {pulses_per_cm!r}")
        x = quantize(x, pulses_per_cm)
    return Record(t=record.t, f=record.f, x=x, source=record.source + " (measured)")
