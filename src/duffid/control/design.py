"""The controller's gains, designed once with python-control on the double integrator the
feedback linearisation leaves (see :mod:`duffid.control.adaptive`), and the mismatched
parameters of the baseline."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from ..errors import InputError

__all__ = ["ControllerDesign", "design", "mismatched", "DEFAULT_SIGNS"]

#: Default sign of each parameter's error in :func:`mismatched` (by name without digits).
DEFAULT_SIGNS = {"m": 1.0, "b": -1.0, "k": -1.0, "kp": 1.0, "L": 1.0, "R": -1.0, "C": 1.0, "a": 1.0}


@dataclass(frozen=True)
class ControllerDesign:
    """Gains of the law and of the observer for one sampling period.

    Attributes
    ----------
    K : ndarray (2,)
        State feedback ``w = x_d'' - K1 (x^ - x_d) - K2 (v^ - x_d')``.
    L : ndarray (2,)
        Observer correction ``[x^, v^] += L (x_k - x^)``.
    sample_period : float
        ``h`` [s].
    reference_bandwidth : float
        Triple pole of the reference model [rad/s].
    method : str
        ``"place"`` or ``"lqr"``.
    poles : ndarray
        Eigenvalues of ``Phi - Gamma K`` (discrete, closed loop of the double integrator).
    observer_poles : ndarray
        Eigenvalues of ``Phi (I - L C)`` (discrete, predicted-estimate error).
    """

    K: np.ndarray
    L: np.ndarray
    sample_period: float
    reference_bandwidth: float
    method: str
    poles: np.ndarray
    observer_poles: np.ndarray


def _positive(name: str, value: float) -> float:
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number, got {value!r}") from None
    if not (math.isfinite(value) and value > 0.0):
        raise InputError(f"{name} must be a finite positive number, got {value!r}")
    return value


def _s_poles(bandwidth: float, damping: float) -> np.ndarray:
    """Continuous poles of natural frequency ``bandwidth`` and damping ``damping``."""
    if damping >= 1.0:  # real poles: w * (-zeta +- sqrt(zeta^2 - 1)); a double pole at zeta = 1
        root = math.sqrt(damping * damping - 1.0)
        return np.array([bandwidth * (-damping + root), bandwidth * (-damping - root)]) if root > 0 else \
            np.array([-bandwidth, -bandwidth * (1.0 + 1e-6)])
    root = math.sqrt(1.0 - damping * damping)
    return np.array([bandwidth * complex(-damping, root), bandwidth * complex(-damping, -root)])


def design(sample_period: float, *, method: str = "place", bandwidth: float = 60.0, damping: float = 0.9,
           observer_bandwidth: float = 250.0, observer_damping: float | None = None,
           Q: Sequence[Sequence[float]] | None = None, R: float | None = None,
           reference_bandwidth: float = 30.0) -> ControllerDesign:
    """Design the feedback and observer gains with python-control.

    The law cancels damping and stiffness, so the design model is the double integrator
    ``x'' = w`` (independent of the estimates), discretised with a zero-order hold at
    ``sample_period`` (``control.c2d``).

    Parameters
    ----------
    sample_period : float
        ``h`` [s].
    method : {"place", "lqr"}
        ``"place"``: ``control.place`` with the continuous poles of ``bandwidth`` and
        ``damping`` mapped by ``exp(s h)``; ``"lqr"``: ``control.dlqr`` with ``Q`` and ``R``.
    bandwidth, damping : float
        Closed-loop natural frequency [rad/s] and damping ratio (``"place"``; with
        ``"lqr"``, ``bandwidth`` sets the default weights).
    observer_bandwidth, observer_damping : float
        Poles of the observer error (``control.place`` on the dual system); the damping
        defaults to ``damping``.
    Q, R : array_like, float
        LQR weights on ``(x - x_d, v - x_d')`` and ``w``; default ``diag(bandwidth^4, 0)``
        and 1 (in continuous time: natural frequency ``bandwidth``, damping 0.71).
    reference_bandwidth : float
        Triple pole of the reference model [rad/s].

    Returns
    -------
    ControllerDesign
    """
    import control

    h = _positive("sample_period", sample_period)
    if method not in ("place", "lqr"):
        raise InputError(f"method must be 'place' or 'lqr', got {method!r}")
    bandwidth = _positive("bandwidth", bandwidth)
    damping = _positive("damping", damping)
    observer_bandwidth = _positive("observer_bandwidth", observer_bandwidth)
    observer_damping = damping if observer_damping is None else _positive("observer_damping", observer_damping)
    reference_bandwidth = _positive("reference_bandwidth", reference_bandwidth)
    for name, value in (("bandwidth", bandwidth), ("observer_bandwidth", observer_bandwidth),
                        ("reference_bandwidth", reference_bandwidth)):
        if value * h > 1.0:
            raise InputError(f"{name} {value} rad/s is too fast for sample_period {h} s "
                             f"(needs {name} * sample_period <= 1)")
    if method == "place" and (Q is not None or R is not None):
        raise InputError("Q and R are the weights of method='lqr'; method='place' uses bandwidth and damping")
    plant = control.c2d(control.ss([[0.0, 1.0], [0.0, 0.0]], [[0.0], [1.0]], [[1.0, 0.0]], [[0.0]]), h, "zoh")
    Phi, Gamma, C = np.asarray(plant.A), np.asarray(plant.B), np.asarray(plant.C)
    if method == "place":
        K = np.asarray(control.place(Phi, Gamma, np.exp(_s_poles(bandwidth, damping) * h))).ravel()
    else:
        Qm = np.diag([bandwidth**4, 0.0]) if Q is None else np.asarray(Q, dtype=float)
        Rm = np.array([[1.0 if R is None else float(R)]])
        if Qm.shape != (2, 2) or not np.all(np.isfinite(Qm)) or not np.allclose(Qm, Qm.T):
            raise InputError(f"Q must be a finite symmetric 2x2 matrix, got {Q!r}")
        if np.min(np.linalg.eigvalsh(Qm)) < 0.0:
            raise InputError("Q must be positive semidefinite")
        if not (np.isfinite(Rm[0, 0]) and Rm[0, 0] > 0.0):
            raise InputError(f"R must be a finite positive number, got {R!r}")
        K = np.asarray(control.dlqr(plant, Qm, Rm)[0]).ravel()
    # observer: the error of the predicted estimate obeys e+ = Phi (I - L C) e = (Phi - M C) e
    # with M = Phi L; place the eigenvalues of Phi - M C on the dual (Phi', C') and solve L.
    M = np.asarray(control.place(Phi.T, C.T, np.exp(_s_poles(observer_bandwidth, observer_damping) * h))).T
    L = np.linalg.solve(Phi, M).ravel()
    poles = np.linalg.eigvals(Phi - Gamma @ K[None, :])
    observer_poles = np.linalg.eigvals(Phi @ (np.eye(2) - L[:, None] @ C))
    return ControllerDesign(K=K, L=L, sample_period=h, reference_bandwidth=reference_bandwidth, method=method,
                            poles=poles, observer_poles=observer_poles)




def mismatched(parameters: Mapping[str, float], fraction: float,
               signs: Mapping[str, float] | None = None) -> dict[str, float]:
    """Parameters wrong by ``fraction``: ``p (1 + sign_p fraction)``.

    The default signs (:data:`DEFAULT_SIGNS`, by name without trailing digits) are
    ``m +, b -, k -, kp +`` (circuit ``L +, R -, C +, a +``): heavier, less damped, softer
    in the linear term and more cubic, not a scaling of all parameters (which the law's
    feedback would see as a mere gain error). ``signs`` overrides any of them (by full
    or base name; values -1, 0 or +1).
    """
    fraction = float(fraction)
    if not (math.isfinite(fraction) and -1.0 < fraction < 1.0):
        raise InputError(f"fraction must be in (-1, 1), got {fraction!r}")
    out = {}
    for name, value in parameters.items():
        base = name.rstrip("0123456789")
        sign = None
        for key in (name, base):
            if signs is not None and key in signs:
                sign = float(signs[key])
                break
        if sign is None:
            if base not in DEFAULT_SIGNS:
                raise InputError(f"no default sign for parameter {name!r}; give it in signs")
            sign = DEFAULT_SIGNS[base]
        if sign not in (-1.0, 0.0, 1.0):
            raise InputError(f"sign of {name} must be -1, 0 or +1, got {sign!r}")
        out[name] = float(value) * (1.0 + sign * fraction)
    return out


