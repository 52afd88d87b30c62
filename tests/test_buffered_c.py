"""The buffered identifier in C (fmus/estimator/duffid_buffered.c, paper Figure 15) against
the Python class it ports (duffid.identification.buffered.BufferedIdentifier).

The C module associates the window's products the other way (coefficients accumulated sample
by sample, then the operational matrices), so results agree to rounding amplified by the
conditioning: |c - python| <= ROUNDING_ULPS x eps x condition x |python| per window.
"""
from __future__ import annotations

import numpy as np
import pytest

from duffid import Duffing1, Duffing2, Multisine, measure, simulate
from duffid.errors import InputError
from duffid.identification.buffered import BufferedIdentifier
from duffid.identification.c_buffered import CBufferedIdentifier, tables_source

EPS = np.finfo(float).eps
#: Rounding of one window's sums (a few hundred samples, a few thousand operations), in ulps
#: of the condition-amplified solution; measured below 2e2 on these records.
ROUNDING_ULPS = 1e4
PLANT = Duffing1(m=0.35, b=1.1, k=2.2e3, kp=6e7)   # not the paper's plant: ~12.6 Hz, hardening


@pytest.fixture(scope="module")
def record():
    rec = simulate(PLANT, Multisine(12.0, 2.0, 30.0, 1.2, phases="random", seed=11), 2.0, 5e-4)
    return measure(rec, pulses_per_cm=None, snr_db=55.0, seed=4)


def _python_windows(ident, rec):
    res = ident.identify_record(rec)
    names = ident.parameter_names
    ends = np.arange(ident.n_intervals, rec.n_samples, ident.every)
    values = np.array([[res.history[k][e] for k in names] for e in ends])
    return ends, values, res.condition[ends], res.identified[ends]


def _python_uncertainties(ident, rec, ends):
    """The stated relative error of each window ending at ``ends``, sample by sample (update)."""
    ident.reset()
    stated = {}
    for i in range(ends[-1] + 1):
        est = ident.update(rec.x[i], rec.f[i])
        stated[i] = est.uncertainty
    return np.array([stated[e] for e in ends])


@pytest.mark.parametrize("method, options", [
    ("legendre", {}),
    ("chebyshev", {"n_terms": 16}),
    ("block-pulse", {"n_terms": 64}),
    ("haar", {"n_terms": 32, "repeated": "exact"}),
    ("legendre", {"window": 0.2, "every": 130}),     # overlapping windows: two open at once
    ("legendre", {"window": 0.05, "n_terms": 12, "every": 3}),  # a solve every 3 samples: 3 stages
    ("legendre", {"window": 0.02, "n_terms": 8, "every": 2}),   # every 2: solved at the window's end
])
def test_double_equals_python_per_window(record, method, options):
    c = CBufferedIdentifier(Duffing1(), record.dt, method, **options)
    out = c.run(record.x, record.f)
    ends, values, cond, identified = _python_windows(BufferedIdentifier(Duffing1(), record.dt, method, **options),
                                                     record)
    solved = np.flatnonzero(out["solved"])
    ends = ends[ends + c.latency < record.n_samples]
    assert solved.tolist() == (ends + c.latency).tolist()
    values, cond, identified = values[:len(ends)], cond[:len(ends)], identified[:len(ends)]
    got = out["current"][solved]
    tol = ROUNDING_ULPS * EPS * np.maximum(cond, 1.0)[:, None] * np.abs(values)
    assert np.all(np.abs(got - values) <= tol), np.max(np.abs(got - values) / tol)
    assert np.allclose(out["condition"][solved], cond, rtol=ROUNDING_ULPS * EPS * max(1.0, cond.max()))
    assert out["identified"][solved].tolist() == identified.tolist()
    # the stated errors (the residual's, the noise's, the basis check's) as Python's
    stated = _python_uncertainties(BufferedIdentifier(Duffing1(), record.dt, method, **options), record, ends)
    assert np.allclose(out["uncertainty"][solved], stated, rtol=1e-6 + ROUNDING_ULPS * EPS * max(1.0, cond.max()))
    # published exactly when identified; NaN otherwise
    published = out["parameters"][solved]
    assert np.array_equal(np.isfinite(published).all(axis=1), identified)


def test_legendre_default_is_accurate_on_an_unseen_plant(record):
    """Every window published is within 5 % (its stated uncertainty is at most 5 %), and most
    windows of a random force are published."""
    out = CBufferedIdentifier(Duffing1(), record.dt, "legendre").run(record.x, record.f)
    ends = np.flatnonzero(out["solved"])
    published = out["parameters"][ends]
    shown = np.isfinite(published).all(axis=1)
    truth = np.array([PLANT.parameters[k] for k in ("m", "b", "k", "kp")])
    assert shown.sum() >= len(ends) // 2
    assert np.all(np.abs(published[shown] / truth - 1.0) < 0.05), published[shown] / truth


def test_float_publishes_only_within_its_uncertainty_of_double(record):
    double = CBufferedIdentifier(Duffing1(), record.dt, "legendre").run(record.x, record.f)
    single = CBufferedIdentifier(Duffing1(), record.dt, "legendre", precision="float").run(record.x, record.f)
    assert single["solved"].tolist() == double["solved"].tolist()
    ends = np.flatnonzero(single["solved"])
    pub = single["parameters"][ends]
    ok = np.isfinite(pub)
    assert ok.any()
    gap = np.abs(pub - double["current"][ends])
    assert np.all(gap[ok] <= (single["uncertainty"][ends][:, None] * np.abs(pub))[ok])


def test_free_decay_window_is_held_and_not_published():
    """No force in a window: the scale is free; the previous solution is held, never published."""
    dt = 1e-3
    forced = simulate(PLANT, Multisine(12.0, 2.0, 30.0, 1.2, phases="random", seed=2), 0.5, dt)
    x = np.concatenate([forced.x[:, 0], forced.x[-1, 0] * np.exp(-np.arange(1, 501) * dt * 3.0)])
    f = np.concatenate([forced.f[:, 0], np.zeros(500)])
    out = CBufferedIdentifier(Duffing1(), dt, "legendre").run(x, f)
    ends = np.flatnonzero(out["solved"])
    last = ends[-1]
    assert last > 750  # a window of the unforced part
    assert np.isinf(out["condition"][last]) and not out["identified"][last]
    assert np.all(np.isnan(out["parameters"][last]))
    assert np.array_equal(out["current"][last], out["current"][ends[-3]]) or \
        np.array_equal(out["current"][last], out["current"][ends[-2]])


def test_poorly_excited_window_is_not_published():
    """A single low sine barely excites the cubic term: the window is solved, not published."""
    dt = 1e-3
    t = np.arange(0, 1.0, dt)
    f = 0.05 * np.sin(2 * np.pi * 1.0 * t)
    x = f / PLANT.parameters["k"]   # quasi-static and linear: m, b and kp undetermined
    out = CBufferedIdentifier(Duffing1(), dt, "legendre").run(x, f)
    ends = np.flatnonzero(out["solved"])
    assert len(ends) and not out["identified"][ends].any()
    assert np.all(np.isnan(out["parameters"][ends]))


def test_refusals_name_what_is_not_covered():
    with pytest.raises(InputError, match="unforced|ratios"):
        tables_source(BufferedIdentifier(Duffing2(), 1e-3, "legendre"), Duffing2())
    with pytest.raises(InputError, match="accumulate"):
        tables_source(BufferedIdentifier(Duffing1(), 1e-3, "legendre", accumulate=True), Duffing1())
    with pytest.raises(InputError, match="matrix"):
        tables_source(BufferedIdentifier(Duffing1(), 1e-3, "legendre", form="matrix"), Duffing1())


def test_non_finite_sample_is_refused_with_its_index():
    c = CBufferedIdentifier(Duffing1(), 1e-3, "legendre")
    x = np.zeros(10)
    x[7] = np.nan
    with pytest.raises(InputError, match="sample 7"):
        c.run(x, np.ones(10))


def test_memory_is_sized_to_the_model_and_precision():
    small = CBufferedIdentifier(Duffing1(), 1e-3, "legendre", n_terms=12)
    large = CBufferedIdentifier(Duffing1(), 1e-3, "legendre", n_terms=24)
    single = CBufferedIdentifier(Duffing1(), 1e-3, "legendre", n_terms=24, precision="float")
    overlapping = CBufferedIdentifier(Duffing1(), 1e-3, "legendre", n_terms=24, every=50)
    assert small.memory_size < large.memory_size < overlapping.memory_size
    assert single.memory_size < large.memory_size
    # the coefficients, the solve and the window's displacements (its noise errors) only
    assert single.memory_size < 8 * 1024
