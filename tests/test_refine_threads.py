"""The refinement's linear algebra runs on :data:`~duffid.identification.refine.BLAS_THREADS`
BLAS threads, whatever the process's default (a spinning BLAS thread pool on a busy machine)."""
from __future__ import annotations

import scipy.optimize
from threadpoolctl import threadpool_info, threadpool_limits

from duffid import Duffing1, Multisine, measure, simulate
from duffid.identification import refine as refine_module


def test_the_refinement_solves_on_one_blas_thread(monkeypatch):
    seen: list[int] = []
    original = scipy.optimize.least_squares

    def spy(*args, **kwargs):
        seen.extend(pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas")
        return original(*args, **kwargs)

    monkeypatch.setattr(scipy.optimize, "least_squares", spy)
    plant = Duffing1()
    record = measure(simulate(plant, Multisine(8.0, 0.5, 10.0, 2.0, phases="random", seed=1), 2.0, 1e-3),
                     pulses_per_cm=None, snr_db=60.0, seed=2)
    start = {k: 1.05 * v for k, v in plant.parameters.items()}
    with threadpool_limits(limits=2, user_api="blas"):  # the caller's default stays as it was
        refine_module.refine(record, plant, start, progress=False)
        after = [pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas"]
    assert seen and set(seen) == {refine_module.BLAS_THREADS}
    assert all(n <= 2 for n in after)
