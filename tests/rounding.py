"""Tolerances that follow from the problem, not from one machine's rounding.

Two implementations of the same estimator (the C core and the Python identifier; or the
same Python code on two BLAS kernels) do not round alike: OpenBLAS picks its kernels by CPU
(Prescott, Sandybridge, Haswell/Zen, SkylakeX), and a different summation order or fused
multiply-add changes the last bits of every QR, SVD and product. How far that moves an
estimate is a property of the record and the model, not of the code: on a well-conditioned
1-DOF record it is ~1e-12, on the 2-DOF chain's weakly excited kp2 it is ~1e-6.

:func:`rounding_spread` measures that property on the record itself: it perturbs every input
sample by one unit in the last place (a relative normal perturbation of size ``eps``) and
reruns the computation, a few times, recording the largest relative change of each output.
Comparisons are then made at :data:`SAFETY` times that spread.

How SAFETY was chosen (measured with ``benchmarks/kernels.py --calibrate``): over the 1-DOF
and 2-DOF chain records, robust and paper methods, the C-vs-Python difference under each of
the Prescott, Sandybridge, Haswell and SkylakeX kernels, divided by the spread of four
one-ulp trials, was at most 10 (largest over the history; 7 at the end of the record; the
spread of a few random trials is itself a noisy figure). SAFETY = 30 keeps a margin of 3
over that while staying orders of magnitude below any real discrepancy (a wrong sign, a
missed sample, a changed option give differences of 1e-3 and more). :data:`FLOOR` keeps the
tolerance above the last bits of a float64 where the spread happens to be zero.
"""
from __future__ import annotations

import dataclasses
import hashlib
from typing import Callable

import numpy as np

EPS = float(np.finfo(float).eps)
#: multiple of the measured one-ulp spread at which two computations are compared
SAFETY = 30.0
#: smallest relative tolerance ever used (a few hundred ulps): below it nothing is meaningful
FLOOR = 64 * EPS
#: number of independently perturbed reruns whose largest change is the spread
TRIALS = 4
#: the final estimates are compared at the largest spread over this many last samples
FINAL_SAMPLES = 50


def perturbed(record, seed: int, ulps: float = 1.0):
    """The record with every sample of x and f scaled by (1 + ulps * eps * N(0, 1))."""
    rng = np.random.default_rng(seed)
    x = np.asarray(record.x, dtype=float)
    f = np.asarray(record.f, dtype=float)
    return dataclasses.replace(record, x=x * (1.0 + ulps * EPS * rng.standard_normal(x.shape)),
                               f=f * (1.0 + ulps * EPS * rng.standard_normal(f.shape)))


def rounding_spreads(compute: Callable[[object], np.ndarray], record,
                     trials: int = TRIALS) -> tuple[np.ndarray, np.ndarray]:
    """Largest relative and absolute changes of ``compute(record)`` under one-ulp input perturbations.

    ``compute`` maps a record to an array of floats (e.g. the history of estimates, samples x
    parameters). Returns two arrays of that shape: ``max |y' - y| / |y|`` and ``max |y' - y|``
    over ``trials`` perturbed records. A change is 0 where both values are equal or both NaN,
    ``inf`` where a value becomes infinite or leaves 0; where only one is NaN it is ignored
    (the tests compare NaN patterns exactly).
    """
    base = np.asarray(compute(record), dtype=float)
    relative = np.zeros_like(base)
    absolute = np.zeros_like(base)
    with np.errstate(divide="ignore", invalid="ignore"):
        for seed in range(trials):
            other = np.asarray(compute(perturbed(record, seed)), dtype=float)
            same = (other == base) | (np.isnan(base) & np.isnan(other))
            change = np.where(same, 0.0, np.abs(other - base))
            absolute = np.fmax(absolute, change)
            relative = np.fmax(relative, np.where(same, 0.0, change / np.abs(base)))
    return relative, absolute


def rounding_spread(compute: Callable[[object], np.ndarray], record, trials: int = TRIALS) -> np.ndarray:
    """Largest relative change of ``compute(record)`` under one-ulp input perturbations
    (see :func:`rounding_spreads`)."""
    return rounding_spreads(compute, record, trials)[0]


def tolerance(spread: np.ndarray | float) -> np.ndarray:
    """Relative tolerance for a comparison whose one-ulp spread is ``spread``."""
    return np.maximum(SAFETY * np.asarray(spread, dtype=float), FLOOR)


def assert_close(actual, expected, relative_tolerance) -> None:
    """Values ``actual`` equal ``expected`` (dicts by name; NaN equals NaN) within
    ``relative_tolerance`` (a dict by name), with a message naming every one that is not."""
    bad = {}
    for name, want in expected.items():
        got, want = float(actual[name]), float(want)
        if np.isnan(want) and np.isnan(got):
            continue
        rel = abs(got - want) / abs(want) if got != want else 0.0
        if not rel <= relative_tolerance[name]:
            bad[name] = f"{got!r} vs {want!r}: relative {rel:.3g} > {relative_tolerance[name]:.3g}"
    assert not bad, bad


def final_spread(identify_final, record) -> dict:
    """Relative tolerance per parameter of ``identify_final(record)`` (a dict by name, e.g.
    ``identify(...).parameters``) from its one-ulp spread on ``record``."""
    names = list(identify_final(record))
    spread = rounding_spread(lambda rec: np.array([identify_final(rec)[k] for k in names]), record)
    return dict(zip(names, tolerance(spread)))


class IdentifierSpread:
    """One-ulp spread of the Python online identifier on one record.

    Attributes
    ----------
    names : tuple of str
        Parameter names, in the identifier's output order.
    history : ndarray
        The unperturbed estimates (samples x parameters).
    parameters : ndarray
        Relative spread of each estimate at each sample (samples x parameters).
    parameters_absolute : ndarray
        The same in the parameters' units (for a parameter that is truly zero, e.g. an offset).
    condition : ndarray
        Relative spread of the condition figure at each sample.
    uncertainty : ndarray
        Absolute spread of the uncertainty figure at each sample (it is itself a relative
        error, and near rounding level on noise-free records, where a relative spread of
        it says nothing).
    current : ndarray
        Relative spread of the estimator's current solution (``Estimate.current``, published
        or not) at each sample.
    """

    def __init__(self, names, history, parameters, parameters_absolute, condition, uncertainty,
                 current) -> None:
        self.names = tuple(names)
        self.history = history
        self.parameters = parameters
        self.parameters_absolute = parameters_absolute
        self.condition = condition
        self.uncertainty = uncertainty
        self.current = current

    def assert_estimates(self, actual, expected) -> None:
        """Final current solutions ``actual`` equal ``expected`` (dicts by name, e.g.
        ``Identification.estimates``) within the largest spread of the current solution
        over the last :data:`FINAL_SAMPLES` samples."""
        spread = np.nan_to_num(self.current[-FINAL_SAMPLES:], nan=0.0).max(axis=0)
        assert_close(actual, expected, dict(zip(self.names, tolerance(spread))))

    def history_tolerance(self, rows: np.ndarray | None = None) -> np.ndarray:
        """Relative tolerance per parameter over the samples ``rows`` (all by default)."""
        spread = self.parameters if rows is None else self.parameters[rows]
        return tolerance(spread.max(axis=0, initial=0.0))

    def final_tolerance(self) -> np.ndarray:
        """Relative tolerance per parameter for the estimates after the last sample.

        An estimate that is held (published once, then kept) was computed at the sample where
        it last changed: its tolerance is the largest spread from :data:`FINAL_SAMPLES`
        samples before that sample to the end. A spread at one sample, from a few random
        trials, can be accidentally small (measured: 3e-14 at the sample that set a held kp,
        whose neighbours spread by 1e-12), while the sensitivity varies slowly in time.
        """
        out = np.empty(len(self.names))
        for j in range(len(self.names)):
            history = self.history[:, j]
            changed = np.flatnonzero(history[1:] != history[:-1]) + 1
            last = int(changed[-1]) if len(changed) else 0
            out[j] = self.parameters[max(0, last - FINAL_SAMPLES):, j].max()
        return tolerance(out)

    def assert_final(self, actual, expected) -> None:
        """Final estimates ``actual`` equal ``expected`` (dicts by name) within :meth:`final_tolerance`."""
        assert_close(actual, expected, dict(zip(self.names, self.final_tolerance())))

    def assert_history(self, actual, expected, rows: np.ndarray | None = None) -> None:
        """Histories ``actual`` equal ``expected`` (dicts of arrays by name, one value per sample):
        the same NaN pattern at every sample, values within :meth:`history_tolerance` over
        ``rows`` (a boolean mask; all samples by default). Pass the samples where the system
        is not singular to rounding, e.g. ``condition <= 1e8``: in the first few samples of the
        paper method the estimates are rounding noise."""
        tol = dict(zip(self.names, self.history_tolerance(rows)))
        rows = np.ones(len(self.parameters), bool) if rows is None else np.asarray(rows, bool)
        bad = {}
        for name, want in expected.items():
            got = np.asarray(actual[name], dtype=float)
            want = np.asarray(want, dtype=float)
            assert got.shape == want.shape == self.parameters[:, 0].shape, name
            assert np.array_equal(np.isnan(got), np.isnan(want)), f"{name}: NaN patterns differ"
            with np.errstate(all="ignore"):
                rel = np.where((got == want) | ~rows, 0.0, np.abs(got - want) / np.abs(want))
            worst = np.nanmax(rel, initial=0.0)
            if not worst <= tol[name]:
                bad[name] = f"relative {worst:.3g} > {tol[name]:.3g} at sample {int(np.nanargmax(rel))}"
        assert not bad, bad


_SPREADS: dict[tuple, IdentifierSpread] = {}


def identifier_spread(model, record, method: str = "robust", **options) -> IdentifierSpread:
    """:class:`IdentifierSpread` of ``OnlineIdentifier(model, record.dt, method, **options)``.

    Cached by the record's samples, the model's parameters, the method and the options,
    so the tests comparing several implementations on one record pay for it once.
    """
    from duffid import OnlineIdentifier

    key = (hashlib.sha256(np.ascontiguousarray(record.x).tobytes() + np.ascontiguousarray(record.f).tobytes()
                          + repr(record.dt).encode()).hexdigest(),
           model.name, tuple(sorted(model.parameters.items())), method, repr(sorted(options.items())))
    if key not in _SPREADS:
        names = tuple(model.parameters)

        def outputs(rec):
            ident = OnlineIdentifier(model, rec.dt, method, **options)
            rows = []
            for x, f in zip(rec.x, rec.f):
                e = ident.update(x, f)
                rows.append([e.parameters[k] for k in names] + [e.current[k] for k in names]
                            + [e.condition, e.uncertainty])
            return np.array(rows)

        relative, absolute = rounding_spreads(outputs, record)
        n = len(names)
        _SPREADS[key] = IdentifierSpread(names, outputs(record)[:, :n], relative[:, :n], absolute[:, :n],
                                         relative[:, -2], absolute[:, -1], relative[:, n:2 * n])
    return _SPREADS[key]
