"""The Python reference loops of the adaptive controller: the controller run over given inputs
(:func:`run`), and plant <-> online identifier <-> controller simulated in Python
(:func:`closed_loop`), the reference the co-simulated FMU loops are compared with."""
from __future__ import annotations

import math
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from ..errors import InputError, OptionError
from ..identification.engine import OnlineIdentifier
from ..models.chain import Chain, Duffing1, Duffing2, DuffingCircuit
from ..models.simulation import check_changes
from .adaptive import AdaptiveController

__all__ = ["run", "closed_loop"]


def run(controller: AdaptiveController, t: Sequence[float], inputs: Mapping[str, Any],
        t0: float | None = None) -> dict[str, np.ndarray]:
    """Drive ``controller`` with input arrays sampled at ``t`` (uniform step).

    Parameters
    ----------
    controller : AdaptiveController
    t : sequence of float
        Sample times ``t_0 .. t_{n-1}``, passed to :meth:`AdaptiveController.step` as
        given, with the step ``sample_period``.
    inputs : mapping
        Input name -> array of n values (``identified`` as 0/1 or bool); a scalar is
        held; ``r_dot`` and ``r_ddot`` may be left out (0).
    t0 : float, optional
        Start time (default ``t[0]``).

    Returns
    -------
    dict
        ``time`` (n + 1 values: t0, then ``t_k + h``) and every output: row 0 at
        initialisation, row k + 1 after the sample at ``t_k``.
    """
    t = np.asarray(t, dtype=float)
    h = controller.parameters["sample_period"]
    rows = [controller.initialize(float(t[0]) if t0 is None else t0)]
    columns = {name: np.broadcast_to(np.asarray(inputs[name], dtype=float), t.shape)
               for name in controller.input_names if name in inputs}
    for k, tk in enumerate(t):
        rows.append(controller.step(float(tk), h, {name: columns[name][k] for name in columns}))
    out = {"time": np.concatenate([[float(t[0]) if t0 is None else float(t0)], t + h])}
    for name in controller.output_names:
        out[name] = np.array([row[name] for row in rows], dtype=float)
    return out


# ---------------------------------------------------------------------- closed loop
def _controller_estimates(model: Chain, parameters: Mapping[str, float]) -> dict[str, float]:
    """Identifier estimates under the controller's names (circuit: m = L, b = R, k = 1/C, kp = a)."""
    if isinstance(model, DuffingCircuit):
        c = parameters["C"]
        k = 1.0 / c if math.isfinite(c) and c != 0.0 else math.nan
        return {"m": parameters["L"], "b": parameters["R"], "k": k, "kp": parameters["a"]}
    return dict(parameters)


def _reference_signals(reference: Any) -> Callable[[float], tuple[float, float, float]]:
    """t -> (r, r_dot, r_ddot) from the ``reference`` argument of :func:`closed_loop`."""
    if isinstance(reference, (tuple, list)):
        if len(reference) != 3 or not all(callable(f) for f in reference):
            raise OptionError("a reference sequence must hold three callables (r, r_dot, r_ddot)")
        return lambda t: (float(reference[0](t)), float(reference[1](t)), float(reference[2](t)))
    if not callable(reference):
        raise OptionError(f"reference must be callable or three callables, got {reference!r}")
    derivative = getattr(reference, "derivative", None)
    if callable(derivative):
        return lambda t: (float(reference(t)), float(derivative(t, 1)), float(derivative(t, 2)))
    return lambda t: (float(reference(t)), 0.0, 0.0)


def closed_loop(plant: Chain, controller: AdaptiveController, reference: Any,
                t_end: float, *, identifier: Any = None, measurement: Callable[[np.ndarray], np.ndarray] | None = None,
                rtol: float = 1e-10, atol: float = 1e-14,
                changes: Sequence[tuple[float, Chain]] = ()) -> dict[str, np.ndarray]:
    """Plant, online identifier and controller in a loop, all in Python (no FMUs).

    Each sample ``k``: the plant's positions ``x_k`` (through ``measurement``, e.g.
    quantisation) and the controller's ``f_sample`` (the mean of the forces applied before
    and after ``t_k``: the zero-order-hold staircase as a sample) go to the identifier; its estimates, ``x_k`` and the reference's ``r``, ``r'``, ``r''`` at
    ``t_k`` to the controller, whose output is the force over ``[t_{k+1}, t_{k+2})`` (the
    co-simulation's one-sample delay); the plant is integrated over ``[t_k, t_{k+1})`` with ``f_k`` held (DOP853).

    Parameters
    ----------
    plant : Chain
        The true plant (``Duffing1``, ``Duffing2`` or ``DuffingCircuit`` with any values).
    controller : AdaptiveController
    reference : callable or (callable, callable, callable)
        ``r(t)`` for x (2-DOF: x1). Its derivatives (the inputs ``r_dot``, ``r_ddot``,
        which ``reference_model`` "derivatives" tracks) come from a method
        ``derivative(t, order)`` when it has one (e.g.
        :class:`duffid.control.closed_loop.SineReference`), or give the three callables
        ``(r, r_dot, r_ddot)``; otherwise they are 0.
    t_end : float
        Duration [s].
    identifier : OnlineIdentifier, optional
        Default ``OnlineIdentifier(<the plant's structure>, h)`` (no prior sizes: pass an
        identifier with ``nominal=...`` for a term the loop barely excites).
    measurement : callable, optional
        Maps the true positions to the measured ones (default: exact).
    changes : sequence of (float, Chain), optional
        A plant that changes (e.g. a payload), as :func:`duffid.simulate`'s ``changes``:
        from each time [s] on (from the first sample at or after it), the plant is that
        chain, its positions and velocities continuing.

    Returns
    -------
    dict
        ``t`` (n), ``x_true`` (n, dofs), the controller's inputs at each sample (``identified``, the estimates
        ``<name>_hat``, ...) and its outputs valid at ``t_k`` (``x_ref``, ``phase``,
        ``saturated``, ``f`` = the force over [t_k, t_{k+1}), ...: those of the step
        at ``t_{k-1}``).
    """
    from scipy.integrate import solve_ivp


    h = controller.parameters["sample_period"]
    n_dof = plant.n_dof
    if n_dof != controller.dofs:
        raise InputError(f"the plant has {n_dof} DOFs, the controller {controller.dofs}")
    if identifier is None:
        structure = DuffingCircuit() if isinstance(plant, DuffingCircuit) else \
            (Duffing1() if n_dof == 1 else Duffing2())
        identifier = OnlineIdentifier(structure, dt=h)
    n = int(round(t_end / h)) + 1
    t = np.arange(n) * h
    plants = [(0.0, plant), *check_changes(plant, changes, float(t[-1]))]
    state = np.zeros(2 * n_dof)
    signals = _reference_signals(reference)
    out = controller.initialize(0.0)
    log: dict[str, list] = {name: [] for name in ("x_true", *controller.input_names, *controller.output_names)}

    def rhs(_time: float, y: np.ndarray, force: float, now: Chain) -> np.ndarray:
        return np.concatenate([y[n_dof:], now.acceleration(y[:n_dof], y[n_dof:], np.array([force]))])

    for k in range(n):
        x_true = state[:n_dof].copy()
        x_meas = x_true if measurement is None else np.asarray(measurement(x_true), dtype=float)
        f = out["f"]
        est = identifier.update(x_meas, [out["f_sample"]])  # the staircase's sample at t_k
        r = signals(float(t[k]))
        inputs = {"r": r[0], "r_dot": r[1], "r_ddot": r[2], "identified": est.identified,
                  **{f"{name}_hat": value for name, value in _controller_estimates(plant, est.parameters).items()}}
        if n_dof == 1:
            inputs["x"] = float(x_meas[0])
        else:
            inputs["x1"], inputs["x2"] = float(x_meas[0]), float(x_meas[1])
        log["x_true"].append(x_true)
        for name in controller.input_names:
            log[name].append(inputs[name])
        for name in controller.output_names:  # the outputs valid over [t_k, t_{k+1})
            log[name].append(out[name])
        out = controller.step(float(t[k]), h, inputs)
        if k + 1 < n:
            now = next(p for time, p in reversed(plants) if t[k] >= time - 1e-9 * h)
            sol = solve_ivp(rhs, (t[k], t[k + 1]), state, method="DOP853", rtol=rtol, atol=atol, args=(f, now))
            if not sol.success:
                raise RuntimeError(f"plant integration failed at t = {t[k]}: {sol.message}")
            state = sol.y[:, -1]
            if np.max(np.abs(state[:n_dof])) > 1.0:
                raise RuntimeError(f"the plant left its range at t = {t[k + 1]} (|x| > 1 m)")
    result = {name: np.asarray(values, dtype=float) for name, values in log.items()}
    result["t"] = t
    return result
