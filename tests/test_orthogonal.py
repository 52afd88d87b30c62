"""Orthogonal bases: orthogonality, operational matrices against exact integrals, projections."""
from __future__ import annotations

import numpy as np
import pytest
from numpy.polynomial import Polynomial
from numpy.polynomial import chebyshev as npcheb
from numpy.polynomial import legendre as npleg

from duffid.identification.orthogonal import BASES, BlockPulse, Chebyshev, Haar, Legendre, make_basis, projection_matrix


def _exact_coefficients(basis, func):
    """Basis coefficients of ``func`` by high-order quadrature, independent of projection_matrix."""
    nodes, weights = np.polynomial.legendre.leggauss(60)
    nodes, weights = (nodes + 1) / 2, weights / 2
    if isinstance(basis, Chebyshev):  # s = (1 - cos theta)/2: w(s) ds = d theta
        theta = np.pi * nodes
        s, w = (1 - np.cos(theta)) / 2, np.pi * weights
    else:  # composite rule over the blocks (exact for piecewise polynomials on them)
        edges = np.linspace(0.0, 1.0, (basis.n_terms if not basis.polynomial else 1) + 1)
        s = (edges[:-1, None] + np.diff(edges)[:, None] * nodes[None, :]).ravel()
        w = (np.diff(edges)[:, None] * weights[None, :]).ravel()
    return (basis(s) * w[:, None]).T @ func(s) / basis.norms()


@pytest.mark.parametrize("name, r", [("legendre", 9), ("chebyshev", 9), ("block-pulse", 8), ("haar", 16)])
def test_functions_are_orthogonal_with_the_stated_norms(name, r):
    basis = make_basis(name, r)
    gram = np.array([_exact_coefficients(basis, lambda s, k=k: basis(s)[:, k]) for k in range(r)])
    np.testing.assert_allclose(gram, np.eye(r), atol=1e-12)


def test_legendre_operational_matrix_has_the_classical_form():
    P = Legendre(5).operational_matrix()
    expected = np.zeros((5, 5))
    expected[0, :2] = 0.5
    for k in range(1, 5):
        expected[k, k - 1] = -1 / (2 * (2 * k + 1))
        if k + 1 < 5:
            expected[k, k + 1] = 1 / (2 * (2 * k + 1))
    np.testing.assert_allclose(P, expected, atol=1e-15)


@pytest.mark.parametrize("cls", [Legendre, Chebyshev])
@pytest.mark.parametrize("m", [1, 2, 3])
def test_polynomial_bases_integrate_polynomials_exactly(cls, m):
    r = 10
    basis = cls(r)
    rng = np.random.default_rng(m)
    p = Polynomial(rng.normal(size=r - m))  # degree r-1-m: its m-fold integral fits the basis
    integral = p.integ(m)  # m-fold integral from 0
    c = _exact_coefficients(basis, p)
    np.testing.assert_allclose(c @ basis.integration_matrix(m), _exact_coefficients(basis, integral), atol=1e-12)


@pytest.mark.parametrize("cls, series, corrupted", [(Legendre, npleg.Legendre, (11,)),
                                                    (Chebyshev, npcheb.Chebyshev, (0, 11))])
def test_truncation_corrupts_only_the_listed_coefficients(cls, series, corrupted):
    r = 12
    basis = cls(r)
    assert basis.corrupted(2) == corrupted
    c = np.random.default_rng(0).normal(size=r)  # all r coefficients, the last one included
    p = series(c, domain=[0.0, 1.0])
    exact = _exact_coefficients(basis, p.integ(2, lbnd=0.0))
    np.testing.assert_allclose(_exact_coefficients(basis, p), c, atol=1e-13)
    error = np.abs(c @ basis.integration_matrix(2) - exact)
    good = np.setdiff1d(np.arange(r), corrupted)
    assert error[good].max() < 1e-12 and error[list(corrupted)].max() > 1e-6
    # the exact matrices of repeated integration leave nothing corrupted
    np.testing.assert_allclose(c @ basis.integration_matrix(2, exact=True), exact, atol=1e-12)


@pytest.mark.parametrize("cls", [BlockPulse, Haar])
def test_piecewise_bases_integrate_steps_at_block_edges_exactly(cls):
    r = 16
    basis = cls(r)
    step = lambda s: np.where(s >= 5 / 16, 2.0, 0.0) - np.where(s >= 12 / 16, 3.0, 0.0)  # noqa: E731
    once = lambda s: 2.0 * np.maximum(s - 5 / 16, 0) - 3.0 * np.maximum(s - 12 / 16, 0)  # noqa: E731
    twice = lambda s: np.maximum(s - 5 / 16, 0) ** 2 - 1.5 * np.maximum(s - 12 / 16, 0) ** 2  # noqa: E731
    c = _exact_coefficients(basis, step)
    np.testing.assert_allclose(c @ basis.operational_matrix(), _exact_coefficients(basis, once), atol=1e-14)
    np.testing.assert_allclose(c @ basis.integration_matrix(2, exact=True), _exact_coefficients(basis, twice),
                               atol=1e-14)
    # P^2 is only an approximation of the double integral (O(1/r^2))
    assert np.abs(c @ basis.integration_matrix(2) - _exact_coefficients(basis, twice)).max() > 1e-4


def test_haar_is_an_orthogonal_transform_of_block_pulses():
    H = Haar(8).matrix()
    np.testing.assert_allclose(H @ H.T, 8 * np.eye(8), atol=1e-14)
    s = (np.arange(8) + 0.5) / 8
    np.testing.assert_allclose(Haar(8)(s), BlockPulse(8)(s) @ H.T)


@pytest.mark.parametrize("name", BASES)
def test_gauss_projection_of_cubic_samples_is_exact(name):
    basis = make_basis(name, 32)
    N = 200
    s = np.arange(N + 1) / N
    cubic = lambda s: 1 + 2 * s - 3 * s**2 + 0.5 * s**3  # noqa: E731
    c = projection_matrix(basis, N) @ cubic(s)
    np.testing.assert_allclose(c, _exact_coefficients(basis, cubic), atol=1e-12)


def test_trapezoid_coefficients_cannot_follow_high_orders_but_gauss_can():
    basis = Legendre(64)
    N = 250
    s = np.arange(N + 1) / N
    g = np.sin(20 * s) * np.exp(-s)
    exact = _exact_coefficients(basis, lambda s: np.sin(20 * s) * np.exp(-s))
    gauss = projection_matrix(basis, N, "gauss") @ g
    simpson = projection_matrix(basis, N, "simpson") @ g
    trapezoid = projection_matrix(basis, N, "trapezoid") @ g
    assert np.abs(gauss - exact).max() < 2e-6       # cubic interpolation of the samples: O(dt^4)
    assert np.abs(simpson - exact).max() < 2e-6
    assert np.abs(trapezoid - exact).max() > 1e-2   # wrong where the true coefficients are ~1e-15
    # the smallest true coefficients are ~1e-15: only the accurate rules keep the high orders small
    assert np.abs(gauss[40:]).max() < 1e-7 < 1e-3 < np.abs(trapezoid[40:]).max()


def test_projection_matrix_is_cached_and_read_only():
    Q = projection_matrix(Legendre(8), 50)
    assert Q is projection_matrix(Legendre(8), 50)
    with pytest.raises(ValueError):
        Q[0, 0] = 1.0


def test_bad_arguments_are_rejected():
    with pytest.raises(ValueError, match="unknown basis"):
        make_basis("fourier", 8)
    with pytest.raises(ValueError, match="power of two"):
        Haar(12)
    with pytest.raises(ValueError, match="n_terms"):
        Legendre(1)
    with pytest.raises(ValueError, match="quadrature"):
        projection_matrix(Legendre(4), 10, "midpoint")
    with pytest.raises(ValueError, match="at least 3"):
        projection_matrix(Legendre(4), 2)
    with pytest.raises(ValueError, match=">= 0"):
        Legendre(4).integration_matrix(-1)
