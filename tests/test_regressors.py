"""Integrated-by-parts regressors against exact integration (by parts) of test signals.

Tolerances: kernel entries against adaptive quadrature at the quadrature rule's accuracy
(2e-5, 2e-4 for the raw term); sliding moments against batch moments at 1e-11 relative plus
1e-14 absolute: sums of at most 100 products of O(1) data with weights in [0, 1] round to
~100 eps relative to the sum of |terms|, which the data keep within a factor ~10 of |sum|.
"""
from __future__ import annotations

from math import factorial

import numpy as np
import pytest
from scipy.integrate import quad

from duffid.identification.regressors import (
    KernelBank,
    SlidingMoments,
    batch_moments,
    GREGORY_POINTS,
    gregory_corrections,
    gregory_end,
    gregory_points,
    row_exponents,
)

H = 1e-3


def _signal(kind):
    if kind == "poly":
        return (lambda t: 0.3 + 2 * t - 5 * t**2 + 4 * t**3,
                lambda t: 2 - 10 * t + 12 * t**2,
                lambda t: -10 + 24 * t)
    w = 23.0
    return (lambda t: np.sin(w * t) + 0.2 * np.cos(3 * t),
            lambda t: w * np.cos(w * t) - 0.6 * np.sin(3 * t),
            lambda t: -w**2 * np.sin(w * t) - 1.8 * np.cos(3 * t))


def _entries(bank, g, n, N, window):
    sm = SlidingMoments(N, bank.degree, 1)
    for i in range(n + 1):
        moments, L = sm.push(np.array([g(i * H)]), window)
    return bank.entries(L / N, moments, np.array([g(n * H)]), N * H), L


@pytest.mark.parametrize("kind", ["poly", "sine"])
@pytest.mark.parametrize("family", ["integrals", "bernstein", "paper"])
@pytest.mark.parametrize("window", [150, 400])
def test_entries_equal_integrals_of_derivatives(kind, family, window):
    """Entry of order d == int W(s) g^(d)(t - s) ds / int W (integration by parts), to quadrature accuracy."""
    bank = KernelBank.build(row_exponents(family, 4), 2)
    derivs = _signal(kind)
    n = 300
    E, L = _entries(bank, derivs[0], n, 400, window)
    t, T = n * H, L * H
    assert L == min(n, window)
    for r, (a, b) in enumerate(bank.rows):
        W = lambda s: s**a * (T - s) ** b / factorial(a)  # noqa: E731
        norm = quad(W, 0, T)[0]
        for d in range(3):
            exact = quad(lambda s: W(s) * derivs[d](t - s), 0, T, epsabs=1e-13, limit=200)[0] / norm
            scale = max(1.0, abs(exact))
            assert E[r, d, 0] == pytest.approx(exact, abs=(2e-5 if d < 2 else 2e-4) * scale), (r, d)


def test_paper_rows_have_the_raw_measurement_term():
    bank = KernelBank.build(row_exponents("paper", 4), 2)
    assert list(bank.raw_b) == [2, -1, -1, -1]
    assert row_exponents("integrals", 2) == ((3, 2), (4, 2))


def test_gregory_rule_is_exact_to_its_order():
    """Newton-Cotes below six intervals; above, exact for polynomials of degree
    gregory_points - 1 (GREGORY_POINTS - 1 once the window is long enough), and not beyond:
    the corrections are the highest order the points allow."""
    assert [str(d) for d in gregory_end(3)] == ["-5/8", "1/6", "-1/24"]  # the classical rule
    for L in [1, 2, 3, 4, 5, 6, 7, 9, 13, 14, 40]:
        offsets, deltas = gregory_corrections(L)
        w = np.ones(L + 1)
        np.add.at(w, offsets, deltas)
        s = np.arange(L + 1) * H
        exact_to = {1: 1, 2: 3, 3: 3, 4: 5, 5: 5}.get(L, gregory_points(L) - 1)
        if L >= 14:
            assert exact_to == GREGORY_POINTS - 1
        for p in range(exact_to + 1):
            assert np.sum(w * s**p) * H == pytest.approx((L * H) ** (p + 1) / (p + 1), rel=1e-12), (L, p)
        if L >= 6 and exact_to % 2 == 0:  # an even degree's exactness brings the next odd one
            exact_to += 1
        if L >= 6:
            p = exact_to + 1
            assert abs(np.sum(w * s**p) * H / ((L * H) ** (p + 1) / (p + 1)) - 1) > 1e-11, (L, p)


def test_a_higher_order_rule_bounds_the_damping_at_few_samples_per_period():
    """The end corrections' order is what keeps a sinusoid's kernel integral right at ten
    samples per period: the classical fourth-order rule errs about ten times more (an
    acceleration row, whose kernel does not vanish at the ends)."""
    N, T = 400, 1.0
    h = T / N
    omega = 2 * np.pi / (10 * h)

    def kernel(u):  # the second derivative of s^2 (T - s)^2: the row of an acceleration term
        return 2 * (T - u) ** 2 - 8 * u * (T - u) + 2 * u**2

    s = np.arange(N + 1) * h
    g = kernel(s) * np.cos(omega * s + 0.3)
    exact = quad(lambda u: kernel(u) * np.cos(omega * u + 0.3), 0, T, limit=5000, epsabs=1e-14)[0]
    scale = quad(lambda u: abs(kernel(u)), 0, T)[0]

    def error(deltas_at_each_end):
        w = np.ones(N + 1)
        p = len(deltas_at_each_end)
        w[:p] += deltas_at_each_end
        w[N - p + 1:] += deltas_at_each_end[::-1]
        return abs(np.sum(w * g) * h - exact) / scale

    classical = error(np.array([float(d) for d in gregory_end(3)]))
    ours = error(np.array([float(d) for d in gregory_end(GREGORY_POINTS)]))
    assert ours < classical / 8


def test_sliding_moments_equal_batch_moments():
    rng = np.random.default_rng(1)
    G = rng.standard_normal((900, 3)) + np.linspace(0, 2, 900)[:, None]
    for N, window in [(100, 100), (100, 37), (50, 50)]:
        sm = SlidingMoments(N, 9, 3)
        online, lengths = zip(*(sm.push(g, window) for g in G))
        batch = batch_moments(G, np.array(lengths), N, 9)
        np.testing.assert_allclose(np.array(online), batch, rtol=1e-11, atol=1e-14)


def test_sliding_moments_do_not_drift_on_long_records():
    rng = np.random.default_rng(2)
    G = rng.standard_normal((20000, 1)) + 5.0
    sm = SlidingMoments(64, 8, 1)
    for g in G:
        moments, L = sm.push(g, 64)
    i = np.arange(65)
    exact = np.array([(i / 64) ** k @ G[-1 - i, 0] for k in range(9)])
    offsets, deltas = gregory_corrections(64)
    exact += np.array([((offsets / 64) ** k * deltas) @ G[-1 - offsets, 0] for k in range(9)])
    np.testing.assert_allclose(moments[:, 0], exact / 64, rtol=1e-12)


def test_kernel_rows_reject_too_few_integrations():
    with pytest.raises(ValueError, match="initial conditions"):
        KernelBank.build(((3, 1),), 2)


def _rule(samples_newest_first: np.ndarray, step: int, L: int, N: int, degree: int) -> np.ndarray:
    """The moments of a window of L intervals by the rule on every ``step``-th sample (the
    newest first), directly: (1/N) sum_m step c_m (i_m/N)^k g[i_m], i_m = step m."""
    intervals = L // step
    offsets, deltas = gregory_corrections(intervals)
    c = np.ones(intervals + 1)
    np.add.at(c, offsets, deltas)
    i = step * np.arange(intervals + 1)
    powers = (i[:, None] / N) ** np.arange(degree + 1)[None, :]
    return step * (powers * c[:, None]).T @ samples_newest_first[i] / N


def test_rate_difference_is_the_rule_minus_the_half_rate_rule_over_the_even_window():
    rng = np.random.default_rng(3)
    G = rng.standard_normal((700, 2)) + np.linspace(0, 3, 700)[:, None]
    N, degree = 120, 7
    for window in (120, 57):
        sm = SlidingMoments(N, degree, 2)
        for n, g in enumerate(G):
            sm.push(g, window)
            got = sm.rate_difference()
            L = n - sm.start
            if L < 2:
                assert got is None
                continue
            diff, even = got, L - L % 2
            newest_first = G[n::-1]
            expected = _rule(newest_first, 1, even, N, degree) - _rule(newest_first, 2, even, N, degree)
            scale = np.abs(_rule(newest_first, 1, even, N, degree)).max()
            np.testing.assert_allclose(diff, expected, rtol=0, atol=1e-12 * scale, err_msg=f"sample {n}")


@pytest.mark.parametrize("family", ["bernstein", "paper", "integrals"])
def test_time_weighted_entries_are_those_of_the_kernels_times_the_age(family):
    """KernelBank.within by Leibniz's rule, ``(s w)^(d) = s w^(d) + d w^(d-1)`` on the moments
    one power up, equals the entries of the kernels ``s w_r`` expanded directly (rows
    ``(a + 1, b)``, whose ``1 / (a + 1)!`` is ``1 / ((a + 1) a!)``), normalised as row r's."""
    rows = row_exponents(family, 5)
    bank = KernelBank.build(rows, 2)
    shifted = KernelBank.build(tuple((a + 1, b) for a, b in rows), 2)
    moments = np.random.default_rng(7).normal(size=(bank.degree + 2, 3))
    tau, t_ref = 0.7, 0.25
    direct = shifted.entries(tau, moments, np.zeros(3), t_ref)
    factor = np.array([a + 1 for a, _ in rows]) * bank.row_scale(tau) / shifted.row_scale(tau)
    np.testing.assert_allclose(bank.within(tau, moments, t_ref), direct * factor[:, None, None],
                               rtol=1e-12, atol=1e-12 * np.abs(direct).max())
