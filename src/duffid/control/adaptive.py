"""Adaptive control on the online estimates: excite, identify, then feedback-linearise.

The plant is the Duffing oscillator ``m x'' + b x' + k x + kp x^3 = f`` (or the two-mass
chain of :class:`~duffid.models.chain.Duffing2`, force on m1, or the
:class:`~duffid.models.chain.DuffingCircuit` under the names ``m = L``, ``b = R``, ``k = 1/C``,
``kp = a``). :class:`AdaptiveController` runs in two phases:

1. **Excitation** (``phase`` 0): a step or a chirp, until the online identifier says
   ``identified`` and its estimates have *settled* (each one within
   ``settle_tolerance`` of a reference value for ``settle_time`` seconds), after at least
   ``min_excitation`` seconds and ``differentiator_samples`` samples.
2. **Control** (``phase`` 1): certainty-equivalence feedback linearisation

       f = m^ w + b^ v^ + k^ x^ + kp^ x^3          (2-DOF: plus the coupling force)

   which turns the model into the double integrator ``x'' = w`` whatever the estimates;
   ``w = x_d'' - K1 (x^ - x_d) - K2 (v^ - x_d')`` tracks the desired trajectory ``x_d``
   (below). The state ``(x^, v^)`` comes from a predictor-corrector observer that also
   compensates the one-sample computational delay of a co-simulation (the force computed
   at ``t_k`` acts from ``t_{k+1}`` on).

The desired trajectory (setting ``reference_model``). Both start bumplessly: at the
switch, ``x_d, x_d', x_d''`` are the observer's prediction ``x^, v^`` at ``t_{k+1}`` and the
model's acceleration under the current force, so the first law output equals that force.

- ``"filter"`` (0, default): the triple-pole reference model
  ``x_d''' = w_r^3 (r - x_d) - 3 w_r^2 x_d' - 3 w_r x_d''`` (``w_r`` =
  ``reference_bandwidth``) driven by ``r`` (held over the step). ``x_d`` lags ``r`` by
  about ``3/w_r`` (0.1 s), so ``x - r`` is dominated by that lag for a varying ``r``.
- ``"derivatives"`` (1): ``x_d = r + z``, ``x_d' = r' + z'``, ``x_d'' = r'' + z''`` with
  the inputs ``r_dot``, ``r_ddot`` and the transient
  ``z''' = -w_r^3 z - 3 w_r^2 z' - 3 w_r z''`` started at ``z = x_d - r``,
  ``z' = x_d' - r'``, ``z'' = x_d'' - r''`` of the switch: it decays to 0 and ``x`` tracks
  ``r`` itself. The law is evaluated at ``t_{k+1}`` but the inputs are the samples at
  ``t_k``: the controller predicts ``r(t_{k+1}) ~ r_k + h r'_k + h^2/2 r''_k``,
  ``r'(t_{k+1}) ~ r'_k + h r''_k`` and ``r''(t_{k+1}) ~ r''_k`` (second-order Taylor;
  errors ``h^3/6 r'''``, ``h^2/2 r'''``, ``h r'''``). The alternative, an orchestrator
  that knows ``r`` ahead feeding the values at ``t_{k+1}``, is not what the controller
  and its FMUs do: they always predict from the inputs at ``t_k``.

In both modes the reference model (or ``z``) advances by one RK4 step per sample.

``mode`` 1 (*fixed*) is the baseline: the same law on the ``*_nominal`` parameters,
switching at ``switch_time``.

:func:`~duffid.control.design.design` computes the gains ``K`` and ``L`` with python-control once, on the ZOH
discretisation of the double integrator; :func:`controller_parameters` turns a design and
settings into the parameter values of the C FMUs ``AdaptiveController1/2``
(:mod:`duffid.control.controller_fmu`), which :class:`AdaptiveController` mirrors operation for
operation (their outputs agree to rounding, see ``tests/test_fmu_controller.py``).

Timing (Jacobi co-simulation at a fixed step ``h``): the inputs of :meth:`AdaptiveController.step`
are the samples at ``t_k``; its output ``f`` is the force applied over
``[t_{k+1}, t_{k+2})``. The output of :meth:`AdaptiveController.initialize` is the force over
``[t_0, t_1)``.

Results (:func:`~duffid.control.python_loop.closed_loop`, ``h`` = 1 ms, 4 s, RMS of ``x - r`` from one second after
the switch on; baseline: fixed mode on :func:`~duffid.control.design.mismatched` ``(truth, 0.3)`` from the same
switch time; ``reference_model="derivatives"``): 1-DOF paper plant, 10 N step,
``r`` = 4 mm + 3 mm sin 2 pi t + 1 mm sin 6 pi t: 1.4 um against 0.28 mm; two-mass chain,
10 N step, 3 mm + 2 mm sin 2 pi t + 1 mm sin 5 pi t: 1.5 um against 0.18 mm;
DuffingCircuit, 15 V step, 5 mC + 4 mC sin 4 pi t + 1 mC sin 10 pi t: 77 uC against
2.7 mC. The adaptive residual comes mostly from the cancellation ``b^ v^ + k^ x^ + ...``,
computed at ``t_{k+1}`` and held over the step (acceleration error about ``(k/m) v h/2``:
largest for the circuit, k/m = 10^4 s^-2), and from ``r''`` held over the step.

Defaults (1-DOF paper plant, natural frequency 22.4 rad/s, ``h`` = 1 ms):
closed-loop bandwidth 60 rad/s with damping 0.9, observer 250 rad/s (damping 0.9),
reference model 30 rad/s (triple pole), 10 N step excitation, force limit 20 N, a
10-sample differentiator, 0.2 s minimum excitation, estimates settled to 0.2 % for
0.05 s.
"""
from __future__ import annotations

import math
import numbers
from typing import Any, Mapping

from ..errors import InputError, OptionError
from ..models.chain import Duffing1, Duffing2
from .design import ControllerDesign
from .design import design as default_design
from .settings import MAX_DIFFERENTIATOR_SAMPLES, PARAMETERS, SETTINGS, coded
from .settings import check_parameters as check_settings

__all__ = ["controller_parameters", "AdaptiveController", "PARAMETER_NAMES", "SETTINGS", "MAX_DIFFERENTIATOR_SAMPLES",
           "check_parameters"]

#: Parameters the law uses, in the estimator's output order, per number of DOFs.
PARAMETER_NAMES = {1: ("m", "b", "k", "kp"), 2: ("m1", "b1", "k1", "kp1", "b2", "k2", "kp2", "m2")}
_DT_RTOL = 1e-9       # a step size may differ from sample_period by this much (relative)
_SWITCH_RTOL = 1e-6   # mode 1 switches when t_{k+1} >= switch_time - 1e-6 h


def _nominal_defaults(dofs: int) -> dict[str, float]:
    return dict((Duffing1() if dofs == 1 else Duffing2()).parameters)


def controller_parameters(design: ControllerDesign, *, dofs: int = 1, **settings: Any) -> dict[str, Any]:
    """Parameter values of an ``AdaptiveController<dofs>`` FMU (and of :class:`AdaptiveController`).

    Parameters
    ----------
    design : ControllerDesign
        Gains and sample period (:func:`~duffid.control.design.design`).
    dofs : {1, 2}
        The plant: 1-DOF Duffing (or circuit), or the two-mass chain (tracks ``x1``).
    **settings
        Any of :data:`SETTINGS`: ``mode`` ("adaptive" or "fixed", or 0/1),
        ``excitation`` ("step" or "chirp", or 0/1), ``excitation_amplitude`` [N],
        ``chirp_f0``, ``chirp_f1`` [Hz], ``chirp_duration`` [s] (linear sweep, then f1),
        ``min_excitation`` [s], ``settle_time`` [s], ``settle_tolerance`` (relative),
        ``force_limit`` [N] (at least ``|excitation_amplitude|``),
        ``differentiator_samples`` (3 .. 64), ``freeze`` (keep the estimates of the
        switch; False: follow finite estimates while identified), ``fallback`` ("hold" or
        "nominal", or 0/1: with ``freeze`` False, what the law uses while the estimates
        are withdrawn, e.g. after the estimator flagged a parameter ``changed``: the
        parameters it had, or ``nominal``), ``nominal`` (parameters of the fixed mode and
        of the fallback, by name as :data:`PARAMETER_NAMES`; default the paper's plant),
        ``switch_time`` [s] (fixed mode; the FMU parameter is named ``fixed_switch_time``
        because the output ``switch_time`` reports the switch) and
        ``reference_model`` ("filter" or "derivatives", or 0/1: what the law tracks,
        see the module documentation).

    Returns
    -------
    dict
        FMU parameter name -> value (Integer codes as int, Booleans as bool).
    """
    if dofs not in (1, 2):
        raise InputError(f"dofs must be 1 or 2, got {dofs!r}")
    unknown = set(settings) - set(SETTINGS)
    if unknown:
        raise OptionError(f"unknown controller settings {sorted(unknown)}; known: {sorted(SETTINGS)}")
    s = {**SETTINGS, **settings}
    nominal = _nominal_defaults(dofs)
    if s["nominal"] is not None:
        given = dict(s["nominal"])
        if set(given) != set(nominal):
            raise InputError(f"nominal needs exactly the parameters {list(nominal)}, got {sorted(given)}")
        nominal = {name: float(given[name]) for name in nominal}
    from_design = {"sample_period": design.sample_period, "K1": design.K[0], "K2": design.K[1],
                   "L1": design.L[0], "L2": design.L[1], "reference_bandwidth": design.reference_bandwidth}
    params: dict[str, Any] = {}
    for p in PARAMETERS:  # in FMU order; the nominal values go after freeze
        if p.name == "fixed_switch_time":
            params.update({f"{name}_nominal": value for name, value in nominal.items()})
        value = from_design[p.name] if p.setting is None else coded(p.setting, s[p.setting])
        params[p.name] = float(value) if p.kind == "real" and isinstance(value, numbers.Real) else \
            bool(value) if p.kind == "bool" else value
    check_parameters(params, dofs)
    return params


def check_parameters(params: Mapping[str, Any], dofs: int) -> None:
    """Raise :class:`~duffid.errors.InputError` (naming the parameter) unless ``params`` is a
    valid parameter set of ``AdaptiveController<dofs>``; the C core's ``duffid_ctrl_check``
    applies the same table (:mod:`duffid.control.settings`)."""
    check_settings(params, dofs, PARAMETER_NAMES[dofs])


# ---------------------------------------------------------------------- the controller
def _diff_coefficients(n: int) -> list[float]:
    """Weights c_j of x_{k-j} (j = 0 .. n-1) of the derivative at the newest sample of the
    least-squares quadratic through n samples, per sample period (times 1/h: velocity).
    Every sum and cofactor is an integer below 2^53 for n <= 64, hence exact."""
    s0 = s1 = s2 = s3 = s4 = 0.0
    for j in range(n):
        tau = -float(j)
        s0 += 1.0
        s1 += tau
        s2 += tau * tau
        s3 += tau * tau * tau
        s4 += tau * tau * tau * tau
    det = s0 * (s2 * s4 - s3 * s3) - s1 * (s1 * s4 - s3 * s2) + s2 * (s1 * s3 - s2 * s2)
    c0 = -(s1 * s4 - s3 * s2)
    c1 = s0 * s4 - s2 * s2
    c2 = -(s0 * s3 - s1 * s2)
    return [(c0 + c1 * (-float(j)) + c2 * (float(j) * float(j))) / det for j in range(n)]


class AdaptiveController:
    """The controller of the ``AdaptiveController1/2`` FMUs, sample by sample, in Python.

    Every floating-point operation follows ``fmus/controller/duffid_controller.c`` in the
    same order, so that both give the same numbers to rounding.

    Parameters
    ----------
    dofs : {1, 2}
        1-DOF plant, or the two-mass chain (force on m1, tracks x1).
    design : ControllerDesign, optional
        Default ``design(1e-3)``.
    parameters : mapping, optional
        A complete FMU parameter set (as :func:`controller_parameters` returns), instead
        of ``design`` and ``settings``.
    **settings
        See :func:`controller_parameters`.

    Notes
    -----
    Inputs of :meth:`step` (a mapping): ``r``, ``r_dot``, ``r_ddot`` (the reference's
    derivatives, used by ``reference_model`` "derivatives" only; 0 when absent, their FMU
    start values), ``x`` (2-DOF ``x1``, ``x2``), the estimates ``<name>_hat`` (NaN
    allowed) and ``identified``. Outputs: ``f``, ``phase``,
    ``x_ref``, ``v_hat`` (2-DOF ``v1_hat``, ``v2_hat``), ``saturated``, ``switch_time``
    (the time from which the law acts, t_{k+1} of the switching sample; NaN before) and
    ``<name>_used``; all but ``f``, ``phase`` and ``saturated`` are NaN before the switch.
    """

    def __init__(self, dofs: int = 1, design: ControllerDesign | None = None, *,
                 parameters: Mapping[str, Any] | None = None, **settings: Any) -> None:
        if dofs not in (1, 2):
            raise InputError(f"dofs must be 1 or 2, got {dofs!r}")
        if parameters is not None:
            if design is not None or settings:
                raise OptionError("give either parameters or design and settings")
            params = dict(parameters)
            expected = set(controller_parameters(default_design(float(params["sample_period"])), dofs=dofs))
            if set(params) != expected:
                raise InputError(f"parameters need exactly {sorted(expected)}; got {sorted(params)}")
            check_parameters(params, dofs)
        else:
            if design is None:
                design = default_design(1e-3)
            params = controller_parameters(design, dofs=dofs, **settings)
        self.dofs = dofs
        self.parameters = params
        self.names = PARAMETER_NAMES[dofs]
        self._c = _diff_coefficients(int(params["differentiator_samples"]))
        self._t0: float | None = None

    # outputs' and inputs' names
    @property
    def input_names(self) -> tuple[str, ...]:
        x = ("x",) if self.dofs == 1 else ("x1", "x2")
        return ("r", "r_dot", "r_ddot", *x, *(f"{n}_hat" for n in self.names), "identified")

    @property
    def output_names(self) -> tuple[str, ...]:
        v = ("v_hat",) if self.dofs == 1 else ("v1_hat", "v2_hat")
        return ("f", "f_sample", "phase", "x_ref", *v, "saturated", "switch_time",
                *(f"{n}_used" for n in self.names))

    # ------------------------------------------------------------------ model
    def _coupling(self, th: list[float], x: list[float], v: list[float]) -> tuple[float, float]:
        """(restoring force on m1 from element 1 and 2, force of element 2)."""
        f1 = th[1] * v[0] + th[2] * x[0] + th[3] * (x[0] * x[0] * x[0])
        if self.dofs == 1:
            return f1, 0.0
        d = x[0] - x[1]
        f2 = th[4] * (v[0] - v[1]) + th[5] * d + th[6] * (d * d * d)
        return f1 + f2, f2

    def _deriv(self, th: list[float], f: float, y: list[float]) -> list[float]:
        n = self.dofs
        x, v = y[:n], y[n:]
        g, f2 = self._coupling(th, x, v)
        a1 = (f - g) / th[0]
        return [*v, a1] if n == 1 else [*v, a1, f2 / th[7]]

    def _predict(self, f: float, h: float) -> None:
        """One RK4 step of the plant model with theta and the force f held."""
        n = self.dofs
        th = self._theta
        y = [*self._xh, *self._vh]
        h2, h6 = 0.5 * h, h / 6.0
        k1 = self._deriv(th, f, y)
        k2 = self._deriv(th, f, [y[i] + h2 * k1[i] for i in range(2 * n)])
        k3 = self._deriv(th, f, [y[i] + h2 * k2[i] for i in range(2 * n)])
        k4 = self._deriv(th, f, [y[i] + h * k3[i] for i in range(2 * n)])
        y = [y[i] + h6 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]) for i in range(2 * n)]
        self._xh, self._vh = y[:n], y[n:]

    def _ref_deriv(self, r: float, y: list[float]) -> list[float]:
        w3, w2, w1 = self._w
        return [y[1], y[2], w3 * (r - y[0]) - w2 * y[1] - w1 * y[2]]

    def _advance_reference(self, y: list[float], r: float, h: float) -> list[float]:
        """One RK4 step of the triple-pole reference model from ``y`` with ``r`` held (r = 0:
        the homogeneous system of the transient z)."""
        h2, h6 = 0.5 * h, h / 6.0
        k1 = self._ref_deriv(r, y)
        k2 = self._ref_deriv(r, [y[i] + h2 * k1[i] for i in range(3)])
        k3 = self._ref_deriv(r, [y[i] + h2 * k2[i] for i in range(3)])
        k4 = self._ref_deriv(r, [y[i] + h * k3[i] for i in range(3)])
        return [y[i] + h6 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]) for i in range(3)]

    @staticmethod
    def _predicted_reference(r: list[float], h: float) -> list[float]:
        """(r, r', r'') at t_{k+1} from the samples at t_k (second-order Taylor)."""
        return [r[0] + h * r[1] + 0.5 * (h * h) * r[2], r[1] + h * r[2], r[2]]

    def _excitation(self, t: float) -> float:
        p = self.parameters
        if p["excitation"] == 0:
            return p["excitation_amplitude"]
        tau = t - self._t0
        f0, f1, T = p["chirp_f0"], p["chirp_f1"], p["chirp_duration"]
        if tau <= T:
            phi = f0 * tau + 0.5 * (f1 - f0) / T * (tau * tau)
        else:
            phi = f0 * T + 0.5 * (f1 - f0) * T + f1 * (tau - T)
        return p["excitation_amplitude"] * math.sin(2.0 * math.pi * phi)

    def _derivative(self, dof: int, h: float) -> float:
        n = len(self._c)
        acc = 0.0
        for j in range(n):
            acc += self._c[j] * self._buf[dof][(self._head - j + n) % n]
        return acc / h

    # ------------------------------------------------------------------ API
    def initialize(self, t0: float = 0.0) -> dict[str, float]:
        """Start at ``t0``; return the outputs at initialisation (the force over [t0, t0 + h))."""
        p = self.parameters
        n = self.dofs
        self._t0 = float(t0)
        wr = p["reference_bandwidth"]
        self._w = (wr * wr * wr, 3.0 * wr * wr, 3.0 * wr)
        self._buf = [[0.0] * len(self._c) for _ in range(n)]
        self._head = len(self._c) - 1
        self._count = 0
        self._have_ref = False
        self._p_ref = [0.0] * len(self.names)
        self._settle_start = 0.0
        self._phase = 0
        self._theta = [math.nan] * len(self.names)
        self._xh = [math.nan] * n
        self._vh = [math.nan] * n
        self._ref = [math.nan] * 3
        self._z = [math.nan] * 3
        self._switch_time = math.nan
        self._saturated = False
        self._f = self._excitation(self._t0)
        self._f_sample = self._f
        return self._outputs()

    def _finish(self, f_k: float) -> dict[str, float]:
        """Outputs after a step; ``f_k`` is the force over [t_k, t_{k+1})."""
        self._f_sample = 0.5 * (f_k + self._f)
        return self._outputs()

    def _outputs(self) -> dict[str, float]:
        out: dict[str, float] = {"f": self._f, "f_sample": self._f_sample, "phase": self._phase,
                                 "x_ref": self._ref[0]}
        if self.dofs == 1:
            out["v_hat"] = self._vh[0]
        else:
            out["v1_hat"], out["v2_hat"] = self._vh
        out["saturated"] = self._saturated
        out["switch_time"] = self._switch_time
        out.update({f"{name}_used": value for name, value in zip(self.names, self._theta)})
        return out

    def _estimates_usable(self, est: list[float]) -> bool:
        return all(math.isfinite(e) for e in est) and est[0] > 0.0 and (self.dofs == 1 or est[7] > 0.0)

    def _law(self, h: float) -> None:
        """Force at t_{k+1} from the predicted state and the reference model, limited."""
        K1, K2 = self.parameters["K1"], self.parameters["K2"]
        xd, vd, ad = self._ref
        w = ad - K1 * (self._xh[0] - xd) - K2 * (self._vh[0] - vd)
        g, _ = self._coupling(self._theta, self._xh, self._vh)
        f = self._theta[0] * w + g
        limit = self.parameters["force_limit"]
        self._saturated = f > limit or f < -limit
        self._f = limit if f > limit else (-limit if f < -limit else f)

    def step(self, t: float, h: float, inputs: Mapping[str, float]) -> dict[str, float]:
        """Consume the inputs at ``t`` (= t_k); return the outputs at ``t + h`` (the force
        applied over ``[t_{k+1}, t_{k+2})``).

        Raises ValueError when ``h`` differs from ``sample_period`` or a position, the
        reference or one of its derivatives is not finite (the FMU: Discard or Error, logged);
        ArithmeticError, the controller unchanged, when the step would leave a force or the
        observer not finite (it diverged; the FMU refuses such a step the same way).
        """
        saved = self._snapshot()
        out = self._step(t, h, inputs)
        bad = self._diverged()
        if bad is not None:
            self.__dict__ = saved
            raise ArithmeticError(f"the controller diverged at t = {t!r} (its {bad} would not be finite); "
                                  "step refused")
        return out

    def _snapshot(self) -> dict[str, Any]:
        """The state a step may change: every attribute, its lists (the positions' buffers,
        observer, reference model, parameters) copied two levels deep (the parameters' dict is
        never changed by a step)."""
        return {k: [list(r) if isinstance(r, list) else r for r in v] if isinstance(v, list) else v
                for k, v in self.__dict__.items()}

    def _diverged(self) -> str | None:
        """The first value the controller cannot have computed (as the C core's check), or None."""
        limit = self.parameters["force_limit"]
        for name, f in (("force", self._f), ("force sample", self._f_sample)):
            if not (math.isfinite(f) and abs(f) <= limit):
                return name
        if self._phase == 1:
            n = self.dofs
            values = [*self._xh[:n], *self._vh[:n], *self._ref, *self._theta]
            if not all(math.isfinite(v) for v in values):
                return "observer, reference model or law parameters"
        return None

    def _step(self, t: float, h: float, inputs: Mapping[str, float]) -> dict[str, float]:
        if self._t0 is None:
            raise RuntimeError("call initialize(t0) before step")
        p = self.parameters
        if abs(h - p["sample_period"]) > _DT_RTOL * p["sample_period"]:
            raise InputError(f"step size {h!r} at t = {t!r} differs from sample_period {p['sample_period']!r}")
        n = self.dofs
        x = [float(inputs["x"])] if n == 1 else [float(inputs["x1"]), float(inputs["x2"])]
        r = [float(inputs["r"]), float(inputs.get("r_dot", 0.0)), float(inputs.get("r_ddot", 0.0))]
        if not all(math.isfinite(v) for v in (*r, *x)):
            raise InputError(f"inputs r, r_dot, r_ddot and x must be finite at t = {t!r}, got "
                             f"r, r_dot, r_ddot = {r!r}, x = {x!r}")
        est = [float(inputs[f"{name}_hat"]) for name in self.names]
        identified = bool(inputs["identified"])
        usable = identified and self._estimates_usable(est)
        f_k = self._f
        if self._phase == 0:
            size = len(self._c)
            self._head = (self._head + 1) % size
            for i in range(n):
                self._buf[i][self._head] = x[i]
            if self._count < size:
                self._count += 1
            if not usable:
                self._have_ref = False
            elif not self._have_ref:
                self._p_ref, self._settle_start, self._have_ref = list(est), t, True
            elif any(abs(e - q) > p["settle_tolerance"] * abs(q) for e, q in zip(est, self._p_ref)):
                self._p_ref, self._settle_start = list(est), t
            buffered = self._count >= size
            if p["mode"] == 0:
                switch = buffered and self._have_ref and t - self._settle_start >= p["settle_time"] and \
                    t - self._t0 >= p["min_excitation"]
            else:
                switch = buffered and t + h >= p["fixed_switch_time"] - _SWITCH_RTOL * h
            if not switch:
                self._f = self._excitation(t + h)
                return self._finish(f_k)
            self._theta = est if p["mode"] == 0 else [p[f"{name}_nominal"] for name in self.names]
            self._xh = list(x)
            self._vh = [self._derivative(i, h) for i in range(n)]
            self._predict(f_k, h)
            g, _ = self._coupling(self._theta, self._xh, self._vh)
            self._ref = [self._xh[0], self._vh[0], (f_k - g) / self._theta[0]]
            if p["reference_model"] == 1:  # x_d = r + z: z starts at the filter's start
                rp = self._predicted_reference(r, h)
                self._z = [self._ref[i] - rp[i] for i in range(3)]
            self._phase = 1
            self._switch_time = t + h
            self._law(h)
            return self._finish(f_k)
        if p["mode"] == 0 and not p["freeze"] and usable:
            self._theta = est
        elif p["mode"] == 0 and not p["freeze"] and p["fallback"] == 1:
            self._theta = [p[f"{name}_nominal"] for name in self.names]
        L1, L2 = p["L1"], p["L2"]
        for i in range(n):
            e = x[i] - self._xh[i]
            self._xh[i] = self._xh[i] + L1 * e
            self._vh[i] = self._vh[i] + L2 * e
        self._predict(f_k, h)
        if p["reference_model"] == 0:
            self._ref = self._advance_reference(self._ref, r[0], h)
        else:
            self._z = self._advance_reference(self._z, 0.0, h)
            rp = self._predicted_reference(r, h)
            self._ref = [rp[i] + self._z[i] for i in range(3)]
        self._law(h)
        return self._finish(f_k)
