"""Tests of duffid.data.signals: values, periodicity, peak scaling and spec texts.

Tolerances: signal values are closed-form expressions of t (sin, polynomial phase) of
amplitude up to ~10: compared at 1e-9 absolute (or 1e-9 of the amplitude), well above the
rounding of phases up to ~1e3 rad (~1e-13 rad).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from duffid.data.signals import Chirp, Multisine, Signal, Step, Sum, Zero, from_spec


# ----------------------------------------------------------------------- Step
def test_step_values_and_types() -> None:
    s = Step(10.0, t_on=0.05)
    assert s(0.0) == 0.0 and s(0.049999) == 0.0
    assert s(0.05) == 10.0 and s(3.0) == 10.0
    assert type(s(1.0)) is float and type(s(1)) is float
    t = np.array([[-1.0, 0.05], [0.04, 1.0]])
    out = s(t)
    assert isinstance(out, np.ndarray) and out.shape == (2, 2)
    np.testing.assert_array_equal(out, [[0.0, 10.0], [0.0, 10.0]])
    assert Step(-2.5)(0.0) == -2.5
    assert Step(3)(np.arange(3.0)).tolist() == [3.0, 3.0, 3.0]


def test_zero() -> None:
    z = Zero()
    assert z(1.5) == 0.0 and type(z(1.5)) is float
    np.testing.assert_array_equal(z(np.linspace(0, 1, 7)), np.zeros(7))


# ---------------------------------------------------------------------- Chirp
def test_chirp_linear_matches_formula() -> None:
    c = Chirp(2.0, 1.0, 21.0, 10.0)
    t = np.linspace(0.0, 12.0, 1001)  # past t1 the law continues
    expected = 2.0 * np.sin(2 * np.pi * (1.0 * t + (21.0 - 1.0) / (2 * 10.0) * t**2))
    np.testing.assert_allclose(c(t), expected, atol=1e-9)
    assert c(0.0) == 0.0


def test_paper_sweep_formula_and_zero_crossings() -> None:
    amp, rate, duration = 2.96, 2.5, 4.1  # rate * duration**2 = 42.025
    sweep = Chirp.paper_sweep(amp, rate, duration=duration)
    assert sweep == Chirp(amp, 0.0, rate * duration, duration, "linear")
    t = np.linspace(0.0, duration, 400_001)
    y = sweep(t)
    np.testing.assert_allclose(y, amp * np.sin(2 * np.pi * (rate / 2) * t**2), atol=1e-9)
    # zeros of sin(pi * rate * t^2) lie at t_n = sqrt(n / rate): the
    # instantaneous frequency is rate * t Hz
    idx = np.flatnonzero(np.sign(y[1:-1]) * np.sign(y[2:]) < 0) + 1
    t0 = t[idx] - y[idx] * (t[idx + 1] - t[idx]) / (y[idx + 1] - y[idx])
    n = np.arange(1, t0.size + 1)
    assert t0.size == math.floor(rate * duration**2) == 42
    np.testing.assert_allclose(t0, np.sqrt(n / rate), atol=2e-6)
    # local frequency from the half-period between crossings
    mid = 0.5 * (t0[1:] + t0[:-1])
    freq = 0.5 / np.diff(t0)
    np.testing.assert_allclose(freq, rate * mid, rtol=2e-3)


def test_paper_sweep_default_rate() -> None:
    s = Chirp.paper_sweep(1.0, duration=20.0)
    assert (s.f0, s.f1, s.t1, s.method) == (0.0, 50.0, 20.0, "linear")


INSTANTANEOUS_FREQUENCY = {
    "linear": lambda t, f0, f1, t1: f0 + (f1 - f0) * t / t1,
    "quadratic": lambda t, f0, f1, t1: f0 + (f1 - f0) * t**2 / t1**2,
    "logarithmic": lambda t, f0, f1, t1: f0 * (f1 / f0) ** (t / t1),
    "hyperbolic": lambda t, f0, f1, t1: f0 * f1 * t1 / ((f0 - f1) * t + f1 * t1),
}


@pytest.mark.parametrize(
    ("method", "f0", "f1"),
    [
        ("linear", 2.0, 9.0),
        ("linear", 9.0, 2.0),
        ("quadratic", 1.0, 8.0),
        ("logarithmic", 1.0, 8.0),
        ("logarithmic", 3.0, 3.0),
        ("hyperbolic", 8.0, 1.0),
        ("hyperbolic", 1.0, 8.0),
    ],
)
def test_chirp_phase_integrates_instantaneous_frequency(method: str, f0: float, f1: float) -> None:
    c = Chirp(1.5, f0, f1, 3.0, method=method)
    t = np.linspace(0.0, 3.0, 60_001)
    freq = INSTANTANEOUS_FREQUENCY[method](t, f0, f1, 3.0)
    cycles = np.concatenate([[0.0], np.cumsum(0.5 * (freq[1:] + freq[:-1]) * np.diff(t))])
    np.testing.assert_allclose(c(t), 1.5 * np.sin(2 * np.pi * cycles), atol=1e-6)
    np.testing.assert_allclose(c.phase(t), 2 * np.pi * cycles, atol=1e-6)
    assert c(0.0) == 0.0


# ------------------------------------------------------------------ Multisine
def test_multisine_frequencies_and_schroeder_phases() -> None:
    m = Multisine(1.0, 1.0, 30.0, 2.0)
    np.testing.assert_allclose(m.frequencies, np.arange(2, 61) / 2.0)
    K = 59
    j = np.arange(1, K + 1)
    np.testing.assert_allclose(m.component_phases, -np.pi * j * (j - 1) / K)
    # band edges that are not harmonics, and DC excluded
    m2 = Multisine(1.0, 0.0, 2.2, 1.0)
    np.testing.assert_allclose(m2.frequencies, [1.0, 2.0])


def test_multisine_formula() -> None:
    m = Multisine(0.7, 2.0, 5.0, 1.0, phases="random", seed=4)
    t = np.linspace(0.0, 1.0, 101)
    direct = sum(
        np.cos(2 * np.pi * f * t + p) for f, p in zip(m.frequencies, m.component_phases)
    )
    np.testing.assert_allclose(m(t), m.scale * direct, atol=1e-12)


@pytest.mark.parametrize(
    "m",
    [
        Multisine(1.0, 1.0, 30.0, 2.0),
        Multisine(0.25, 0.5, 12.0, 4.0, phases="random", seed=11),
        Multisine(3.0, 40.0, 41.0, 1.0),
    ],
)
def test_multisine_peak_and_periodicity(m: Multisine) -> None:
    t = np.linspace(0.0, m.period, 200 * int(m.frequencies[-1] * m.period) + 1)
    y = m(t)
    i = int(np.argmax(np.abs(y)))
    assert np.abs(y[i]) <= m.amplitude * (1 + 1e-12)
    assert np.abs(y[i]) == pytest.approx(m.amplitude, rel=2e-5)
    # the true peak lies within one grid step of the grid maximum
    local = m(np.linspace(t[i] - t[1], t[i] + t[1], 4001))
    assert np.max(np.abs(local)) == pytest.approx(m.amplitude, rel=1e-9)
    np.testing.assert_allclose(m(t + m.period), y, atol=1e-9 * m.amplitude)
    np.testing.assert_allclose(m(t + 7 * m.period), y, atol=1e-9 * m.amplitude)
    assert abs(np.mean(y[:-1])) < 1e-9 * m.amplitude  # no DC component


def test_multisine_random_phases_seeded() -> None:
    a = Multisine(1.0, 1.0, 10.0, 1.0, phases="random", seed=3)
    b = Multisine(1.0, 1.0, 10.0, 1.0, phases="random", seed=3)
    c = Multisine(1.0, 1.0, 10.0, 1.0, phases="random", seed=4)
    np.testing.assert_array_equal(a.component_phases, b.component_phases)
    assert not np.allclose(a.component_phases, c.component_phases)
    assert a == b and a != c
    assert np.all((a.component_phases >= 0) & (a.component_phases < 2 * np.pi))


def test_multisine_scalar_and_zero_amplitude() -> None:
    m = Multisine(1.0, 1.0, 3.0, 1.0)
    assert type(m(0.25)) is float
    assert m(0.25) == pytest.approx(float(m(np.array([0.25]))[0]))
    assert Multisine(0.0, 1.0, 3.0, 1.0)(0.3) == 0.0


# ------------------------------------------------------------------------ Sum
def test_sum_and_add() -> None:
    step = Step(10.0)
    ms = Multisine(0.5, 1.0, 30.0, 2.0)
    total = step + ms
    assert isinstance(total, Sum) and total.terms == (step, ms)
    t = np.linspace(0.0, 1.0, 11)
    np.testing.assert_allclose(total(t), 10.0 + ms(t), atol=1e-12)
    assert total(0.3) == pytest.approx(10.0 + ms(0.3))
    three = total + Zero()
    assert three.terms == (step, ms, Zero())
    assert Sum(step, Sum(ms, Zero())) == three
    with pytest.raises(ValueError, match="at least 2 terms"):
        Sum(step)
    with pytest.raises(TypeError, match="Sum terms must be signals"):
        Sum(step, 3.0)  # type: ignore[arg-type]
    with pytest.raises(TypeError):
        step + 1.0  # type: ignore[operator]


# ----------------------------------------------------------------------- spec
@pytest.mark.parametrize(
    "signal",
    [
        Step(10.0),
        Step(-2.5, 0.05),
        Step(0.1 + 0.2, t_on=1 / 3),
        Step(1e20),
        Chirp(2.0, 0.0, 20.0, 10.0),
        Chirp(1.0, 0.5, 40.0, 3.0, "logarithmic"),
        Chirp(1.0, 0.5, 40.0, 3.0, "quadratic"),
        Chirp.paper_sweep(2.96, 2.5, duration=20.0),
        Multisine(1.0, 1.0, 30.0, 2.0),
        Multisine(1.0, 1.0, 30.0, 2.0, phases="random"),
        Multisine(0.5, 0.0, 7.5, 1.5, phases="random", seed=7),
        Multisine(0.5, 0.0, 7.5, 1.5, phases="schroeder", seed=2),
        Zero(),
        Step(1e20) + Multisine(0.5, 1.0, 30.0, 2.0) + Zero(),
    ],
)
def test_spec_round_trip(signal: Signal) -> None:
    text = signal.spec
    back = from_spec(text)
    assert back == signal
    assert type(back) is type(signal)
    assert back.spec == text
    t = np.linspace(0.0, 2.0, 51)
    np.testing.assert_array_equal(back(t), signal(t))


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("step:10", Step(10.0)),
        ("step:10,0.05", Step(10.0, 0.05)),
        ("chirp:2,0,20,10", Chirp(2.0, 0.0, 20.0, 10.0)),
        ("chirp:2,1,20,10,Logarithmic", Chirp(2.0, 1.0, 20.0, 10.0, "logarithmic")),
        ("sweep:2.96,2.5,20", Chirp(2.96, 0.0, 50.0, 20.0)),
        ("multisine:1,1,30,2", Multisine(1.0, 1.0, 30.0, 2.0)),
        ("multisine:1,1,30,2,random,5", Multisine(1.0, 1.0, 30.0, 2.0, "random", 5)),
        ("zero", Zero()),
        (" step : 10 + multisine:0.5, 1, 30, 2 ", Sum(Step(10.0), Multisine(0.5, 1.0, 30.0, 2.0))),
        ("step:1e+3+step:-2E-1", Sum(Step(1000.0), Step(-0.2))),
    ],
)
def test_from_spec_examples(text: str, expected: Signal) -> None:
    assert from_spec(text) == expected


@pytest.mark.parametrize(
    ("text", "part"),
    [
        ("", "the spec is empty"),
        ("step", "step takes 1 to 2 parameters, got 0"),
        ("step:", "amplitude '' is not a finite decimal number"),
        ("step:1,2,3", "step takes 1 to 2 parameters, got 3"),
        ("step:ten", "amplitude 'ten' is not a finite decimal number"),
        ("step:nan", "amplitude 'nan' is not a finite decimal number"),
        ("step:1_0", "amplitude '1_0' is not a finite decimal number"),
        ("step:__import__('os')", "is not a finite decimal number"),
        ("chirp:1,2,3", "chirp takes 4 to 5 parameters, got 3"),
        ("chirp:1,0,20,0", "t1 must be > 0"),
        ("chirp:1,0,20,5,cubic", "chirp method 'cubic' is not one of"),
        ("chirp:1,0,20,5,logarithmic", "f0 must be > 0 for the logarithmic method"),
        ("sweep:1,2.5", "sweep takes 3 parameters, got 2"),
        ("sweep:1,-2.5,10", "rate must be > 0"),
        ("multisine:1,30,1,2", "f_max must be > f_min"),
        ("multisine:1,1,30,0", "period must be > 0"),
        ("multisine:1,1.2,1.4,1", "no harmonic of 1/period"),
        ("multisine:1,1,30,2,crest", "multisine phases 'crest' is not one of"),
        ("multisine:1,1,30,2,random,-1", "seed '-1' is not a non-negative integer"),
        ("multisine:1,1,30,2,random,1.5", "seed '1.5' is not a non-negative integer"),
        ("zero:1", "'zero' takes no parameters"),
        ("square:1", "unknown signal kind 'square'"),
        ("step:1+", "term 2 is empty"),
        ("step:1+foo", "in term 'foo', unknown signal kind 'foo'"),
        ("step:1 * 2", "amplitude '1 * 2' is not a finite decimal number"),
    ],
)
def test_from_spec_errors(text: str, part: str) -> None:
    with pytest.raises(ValueError) as info:
        from_spec(text)
    message = str(info.value)
    assert message.startswith(f"invalid signal spec {text!r}: ")
    assert part in message
    assert "Accepted forms: step:A[,t_on]; chirp:A,f0,f1,t1" in message
    assert "multisine:A,f_min,f_max,period[,schroeder|random[,seed]]; zero" in message


def test_from_spec_rejects_non_string() -> None:
    with pytest.raises(TypeError, match="must be a string"):
        from_spec(10)  # type: ignore[arg-type]


# ----------------------------------------------------------- parameter checks
@pytest.mark.parametrize(
    ("factory", "exc", "match"),
    [
        (lambda: Step(float("nan")), ValueError, "amplitude must be finite"),
        (lambda: Step(1.0, t_on=float("inf")), ValueError, "t_on must be finite"),
        (lambda: Step("1"), TypeError, "amplitude must be a real number"),
        (lambda: Step(True), TypeError, "amplitude must be a real number"),
        (lambda: Chirp(1.0, -1.0, 10.0, 1.0), ValueError, "f0 must be >= 0"),
        (lambda: Chirp(1.0, 0.0, -1.0, 1.0), ValueError, "f1 must be >= 0"),
        (lambda: Chirp(1.0, 0.0, 10.0, -1.0), ValueError, "t1 must be > 0"),
        (lambda: Chirp(1.0, 1.0, 10.0, 1.0, "sawtooth"), ValueError, "method must be one of"),
        (lambda: Chirp(1.0, 1.0, 0.0, 1.0, "hyperbolic"), ValueError, "f1 must be > 0 for the hyperbolic"),
        (lambda: Chirp.paper_sweep(1.0, 0.0, duration=10.0), ValueError, "rate must be > 0"),
        (lambda: Chirp.paper_sweep(1.0, duration=0.0), ValueError, "duration must be > 0"),
        (lambda: Multisine(-1.0, 1.0, 2.0, 1.0), ValueError, "amplitude .* must be >= 0"),
        (lambda: Multisine(1.0, -1.0, 2.0, 1.0), ValueError, "f_min must be >= 0"),
        (lambda: Multisine(1.0, 2.0, 2.0, 1.0), ValueError, "f_max must be > f_min"),
        (lambda: Multisine(1.0, 1.0, 2.0, -1.0), ValueError, "period must be > 0"),
        (lambda: Multisine(1.0, 1.0, 2.0, float("nan")), ValueError, "period must be finite"),
        (lambda: Multisine(1.0, 1.0, 2.0, 1.0, phases="zero"), ValueError, "phases must be one of"),
        (lambda: Multisine(1.0, 1.0, 2.0, 1.0, seed=-3), ValueError, "seed must be >= 0"),
        (lambda: Multisine(1.0, 1.0, 2.0, 1.0, seed=1.5), TypeError, "seed must be an integer"),
        (lambda: Multisine(1.0, 0.1, 0.9, 1.0), ValueError, "no harmonic of 1/period = 1 Hz"),
        (lambda: Multisine(1.0, 1.0, 1e6, 10.0), ValueError, "components, more than"),
    ],
)
def test_parameter_validation(factory, exc: type[Exception], match: str) -> None:
    with pytest.raises(exc, match=match):
        factory()


def test_gated_signal_switches_off_and_round_trips() -> None:
    from duffid.data.signals import Gated

    g = from_spec("sweep:3,2.5,4@4")
    assert isinstance(g, Gated) and g.t_off == 4.0
    t = np.array([1.0, 3.99, 4.0, 6.0])
    np.testing.assert_array_equal(g(t)[2:], 0.0)
    assert g(1.0) == Chirp.paper_sweep(3, 2.5, duration=4)(1.0)
    assert from_spec(g.spec) == g
    assert from_spec("step:1@0.5+step:2").spec == "step:1@0.5+step:2"
    with pytest.raises(ValueError, match="after '@'"):
        from_spec("step:1@x")
    with pytest.raises(TypeError, match="single"):
        Gated(Step(1) + Step(2), 1.0)
