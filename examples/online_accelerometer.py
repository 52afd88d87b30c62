"""Online identification from an accelerometer, and a plant that changes
=====================================================================

A small hardening rig (0.3 kg, 40 Hz, not the paper's plant) is shaken by random force; an
accelerometer (10 kHz, a bias of 0.02 g, 45 dB noise) and a load cell are read sample by
sample, as a real-time loop would, into :class:`duffid.OnlineMotionIdentifier`. At 3 s the
spring loses 10 % of its linear stiffness (a crack). The identifier publishes the parameters
once the simulated acceleration follows the measured one to its noise, withdraws them as
"changed" when the latest periods stop fitting, and publishes the new plant's values again.

Run: python examples/online_accelerometer.py
"""
from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp
from scipy.interpolate import CubicSpline

from duffid import Duffing1, Multisine, OnlineMotionIdentifier

M, B, K, KP = 0.3, 1.5, 0.3 * (2 * np.pi * 40.0) ** 2, 4e8  # kp x^2 = 0.21 k at 0.5 mm
CRACK_AT, CRACK = 3.0, 0.9  # k drops by 10 % at 3 s
DT, T_END = 1e-4, 5.0
G = 9.80665


def rig() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """t, force [N] and acceleration [m/s^2] of the rig (SciPy's DOP853)."""
    t = np.arange(0.0, T_END + DT / 2, DT)
    f = Multisine(20.0, 5.0, 120.0, T_END, phases="random", seed=11)(t)
    drive = CubicSpline(t, f)

    def stiffness(tt: float) -> float:
        return K * (CRACK if tt >= CRACK_AT else 1.0)

    def rhs(tt: float, y: np.ndarray) -> list[float]:
        return [y[1], (drive(tt) - B * y[1] - stiffness(tt) * y[0] - KP * y[0] ** 3) / M]

    options = {"method": "DOP853", "rtol": 1e-10, "atol": 1e-14, "max_step": 2 * DT}
    before = t < CRACK_AT
    first = solve_ivp(rhs, (0.0, t[before][-1]), [0.0, 0.0], t_eval=t[before], **options)
    second = solve_ivp(rhs, (t[before][-1], t[-1]), first.y[:, -1], t_eval=t[~before], **options)
    x, v = np.hstack([first.y, second.y])
    k = np.where(before, K, K * CRACK)
    return t, f, (f - B * v - k * x - KP * x ** 3) / M


def main() -> None:
    t, f, a = rig()
    rng = np.random.default_rng(5)
    rms = np.sqrt(np.mean(a ** 2))
    a_g = (a + 0.02 * G + rng.normal(0.0, rms / 10 ** (45 / 20), a.shape)) / G  # the logger's g
    f_meas = f + rng.normal(0.0, np.sqrt(np.mean(f ** 2)) / 1000, f.shape)

    ident = OnlineMotionIdentifier(Duffing1(), DT, "a")
    previous = None
    for i in range(len(t)):
        est = ident.update(a_g[i] * G, f_meas[i])  # SI units: m/s^2 and N
        if est.status["k"] != previous:
            truth = K * (CRACK if t[i] >= CRACK_AT else 1.0)
            shown = (f"k = {est.parameters['k']:.6g} N/m (true {truth:.6g}, stated error "
                     f"{est.std_errors['k']:.2g})" if np.isfinite(est.parameters["k"]) else "")
            print(f"t = {t[i]:6.3f} s  k {est.status['k']:<9} {shown}")
            previous = est.status["k"]
    truth = {"m": M, "b": B, "k": K * CRACK, "kp": KP}
    print("at the end:")
    for name, value in est.parameters.items():
        print(f"  {name:>2} = {value:12.6g}  {est.status[name]:<9} (true {truth[name]:.6g}, "
              f"{100 * (value / truth[name] - 1):+.3f} %, stated error {est.std_errors[name]:.2g})")
    print(f"{ident.fits} fits and {ident.checks} checks over {T_END:g} s of data")


if __name__ == "__main__":
    main()
