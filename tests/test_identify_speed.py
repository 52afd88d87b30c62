"""The checked identification's fast paths give today's answers: the C batch fed in blocks,
the checks' re-runs without history, the same result for any number of jobs, and a clean stop
on Ctrl-C."""
from __future__ import annotations

import threading

import numpy as np
import pytest

from duffid import Duffing1, Duffing2, Multisine, Record, identify, measure, simulate
from duffid.errors import InputError
from duffid.identification import assessment, dispatch
from duffid.identification.c_core import CIdentifier


@pytest.fixture(scope="module")
def record():
    plant = Duffing1()
    rec = measure(simulate(plant, Multisine(8.0, 0.5, 10.0, 2.0, phases="random", seed=1), 3.0, 1e-3),
                  pulses_per_cm=None, snr_db=40, seed=2)
    x = rec.x.copy()
    x[1000, 0] += 5 * np.ptp(x)  # an isolated outlier: the blocks must report it as the whole run does
    return Record(rec.t, rec.f, x, source="test")


@pytest.mark.parametrize("model", [Duffing1(), Duffing2()], ids=["1-DOF", "2-DOF"])
def test_blocks_and_final_estimates_equal_one_batch_call(record, model, monkeypatch):
    if model.n_dof == 2:
        record = measure(simulate(model, Multisine(8.0, 0.5, 10.0, 2.0, phases="random", seed=1), 3.0, 1e-3),
                         pulses_per_cm=None, snr_db=40, seed=2)
    for name in ("BLOCK_SAMPLES", "HISTORY_BLOCK"):
        monkeypatch.setattr(dispatch, name, 1 << 30)
    whole = dispatch.run_estimator(record, model)
    with CIdentifier(model, record.dt) as core:  # one batch call into fresh outputs
        single = core.identify_record(record)
    for name in ("BLOCK_SAMPLES", "HISTORY_BLOCK"):  # the history's buffer reused block to block
        monkeypatch.setattr(dispatch, name, 700)
    blocks = dispatch.run_estimator(record, model)
    np.testing.assert_array_equal(list(single.estimates.values()), list(whole.estimates.values()))
    np.testing.assert_array_equal(single.condition, whole.condition)
    for name in whole.history:
        np.testing.assert_array_equal(whole.history[name], blocks.history[name])
    np.testing.assert_array_equal(whole.condition, blocks.condition)
    np.testing.assert_array_equal(whole.identified, blocks.identified)
    final = dispatch.final_estimates(record, model)
    for values in (blocks.estimates, final):
        np.testing.assert_array_equal(list(whole.estimates.values()), [values[k] for k in whole.estimates])
    assert whole.outliers == blocks.outliers and whole.online_status == blocks.online_status
    assert whole.window == blocks.window


def test_outputs_into_a_reused_buffer_or_none_advance_the_core_alike(record):
    x, f = record.x[:3000], record.f[:3000]
    with CIdentifier(Duffing1(), record.dt) as fresh, CIdentifier(Duffing1(), record.dt) as reused, \
            CIdentifier(Duffing1(), record.dt) as silent:
        rows = fresh.run(x, f)
        buffer = np.empty(1000, dtype=reused.output_dtype)
        for start in range(0, 3000, 1000):
            into = reused.run(x[start:start + 1000], f[start:start + 1000], out=buffer)
            assert into.tobytes() == rows[start:start + 1000].tobytes()
        silent.consume(x, f)
        last = silent.latest()
        np.testing.assert_array_equal(list(last.current.values()), rows["current"][-1, :4])
        np.testing.assert_array_equal(list(last.parameters.values()), rows["parameters"][-1, :4])
        assert last.identified == bool(rows["identified"][-1]) and last.condition == rows["condition"][-1]
        with pytest.raises(InputError, match="out must be"):
            reused.run(x, f, out=buffer)  # too short for 3000 samples


def test_a_set_cancel_event_stops_a_run(record):
    cancel = threading.Event()
    cancel.set()
    with pytest.raises(dispatch.Cancelled):
        dispatch.run_estimator(record, Duffing1(), cancel=cancel)
    with pytest.raises(dispatch.Cancelled):
        dispatch.final_estimates(record, Duffing1(), cancel=cancel)


def test_pool_keeps_order_and_at_most_jobs_inputs():
    alive, most = [0], [0]
    lock = threading.Lock()

    def make(i):
        def made():
            with lock:
                alive[0] += 1
                most[0] = max(most[0], alive[0])
            return i
        return made

    def call(i):
        with lock:
            alive[0] -= 1
        return i * i

    for jobs in (1, 3):
        alive[0] = most[0] = 0
        with dispatch.Pool(jobs) as pool:
            assert list(pool.ordered(call, (make(i) for i in range(10)))) == [i * i for i in range(10)]
        assert most[0] <= jobs


def test_the_result_is_the_same_for_any_number_of_jobs(record):
    one = identify(record, Duffing1(), jobs=1, progress=False)
    two = identify(record, Duffing1(), jobs=2, progress=False)
    assert one.assessment.to_dict() == two.assessment.to_dict()
    assert one.parameters == two.parameters and one.estimates == two.estimates


def test_ctrl_c_ends_with_a_message(record, monkeypatch, capsys):
    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr("duffid.identification.trust.assess", interrupted)
    with pytest.raises(KeyboardInterrupt):
        identify(record, Duffing1(), jobs=2, progress=False)
    assert "interrupted (Ctrl-C)" in capsys.readouterr().err


def test_the_bootstrap_draws_the_same_noise_as_one_sequence(record):
    seen = []

    def rerun(noisy):
        seen.append(noisy.x.copy())
        return {"m": 1.0}

    assessment._bootstrap_uncertainty(record, {"m": 1.0}, np.array([1e-3]), rerun, 3, seed=0)
    rng = np.random.default_rng(0)
    for x in seen:
        np.testing.assert_array_equal(x, record.x + rng.standard_normal(record.x.shape) * 1e-3)


def test_one_percent_of_isolated_glitches_are_excluded_and_the_values_published():
    plant = Duffing1()
    rec = measure(simulate(plant, Multisine(8.0, 0.5, 10.0, 4.0, phases="random", seed=1), 8.0, 1e-3),
                  pulses_per_cm=None, snr_db=40, seed=2)
    rng = np.random.default_rng(5)
    x = rec.x.copy()
    where = rng.choice(np.arange(5, len(x) - 5), size=len(x) // 100, replace=False)
    x[where, 0] += rng.choice([-1, 1], size=len(where)) * rng.uniform(0.2, 3, size=len(where)) * np.ptp(x)
    result = identify(Record(rec.t, rec.f, x, source="glitches"), plant, progress=False)
    a = result.assessment
    assert len(a.fit["outliers"]) >= 0.9 * len(where)
    assert a.identified
    for name, value in result.parameters.items():  # within 3 stated errors of the truth
        truth = plant.parameters[name]
        assert abs(value - truth) <= 3 * a.uncertainty[name] * abs(truth), name


def test_the_progress_bar_counts_every_run(record, monkeypatch):
    bars = []

    class Bar:
        def __init__(self, total, disable, **kwargs):
            self.total, self.disable, self.n = total, disable, 0
            bars.append(self)

            self.stages = []

        def update(self, n):
            self.n += n

        def set_postfix_str(self, stage, refresh=True):
            self.stages.append(stage)

        def close(self):
            pass

    monkeypatch.setattr("duffid.identification.trust.tqdm", Bar)
    identify(record, Duffing1(), jobs=1, progress=True)
    # two estimator runs, the simulation, 8 replicates, the half rate; then the simulations of
    # the output-error fit when it runs (it does on this record), each one more run
    bar = bars[0]
    assert len(bars) == 1 and not bar.disable and bar.n == bar.total
    assert bar.stages[:12] == ["estimator"] * 2 + ["simulation"] + ["uncertainty"] * 8 + ["half rate"]
    assert bar.total > 12 and bar.stages[12:] == ["output-error fit"] * (bar.total - 12)
