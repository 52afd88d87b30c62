"""``benchmarks/tracking.py``'s measures on one record of each kind (the C core): the figures
its table reports for a step and a drift, within bounds that fail if a change is no longer
flagged, re-identified, or shown beyond its stated errors for long."""
from __future__ import annotations

import shutil

import pytest

from benchmark_modules import load_benchmark

pytestmark = pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None,
                                reason="no C compiler")


@pytest.mark.parametrize("name, flagged, shown", [("k +25 %", 0.3, 0.5), ("k drift +20 %", 1.4, 0.6)])
def test_a_change_is_flagged_re_identified_and_seldom_shown_beyond_its_errors(name, flagged, shown):
    """Seed 0, measured: the step flagged after 0.27 s, values beyond 3 stated errors for
    0.43 s (the kp of the growing response, 0.17 s, and k until the flag); the drift flagged
    after 1.24 s, 0.46 s beyond (3.95 s in the median of 5 seeds before the lines weighed
    each sample by its own time)."""
    tracking = load_benchmark("tracking")
    rig, changed, changes, start = tracking.CHANGES[name]
    out = tracking.run(rig, changed, changes, start, 0)
    assert out["flagged after"] <= flagged
    assert out["re-published after"] <= 0.5
    assert out["last s"] <= 0.02 and out["worst vs last s"] <= 0.05
    assert out["shown so"] <= shown and out["beyond 3 SE"] <= 0.1


@pytest.mark.slow
def test_a_stiffness_step_below_resonance_is_not_shown_stale_for_seconds():
    """The quasi-static plant's seed 0: its inertia shows only in windows of 40-90 ms while
    the window grows, never together with a steady stiffness, so the window grew to
    ``max_window`` (1 s) and a 10 % drop of k was published 12.7 % off for 5.0 s (the change
    test's memory is two windows). Now the mass's steady value of the short windows gives the
    natural period the window is fixed from (111 ms here): k's old value is withdrawn 0.73 s
    after the step, nothing published is further than 1.94 % from the last second's truth,
    and values beyond 3 stated errors are shown for 0.87 s."""
    tracking = load_benchmark("tracking")
    rig, changed, changes, start = tracking.CHANGES["quasi-static k -10 %"]
    out = tracking.run(rig, changed, changes, start, 0)
    assert out["worst vs last s"] <= 0.03
    assert out["shown so"] <= 1.2


@pytest.mark.slow
def test_both_engines_fix_the_window_from_a_mass_seen_while_the_window_grew():
    """The Python engine fixes the same window as the C core on that record (111 ms), where
    both grew to ``max_window`` before."""
    import numpy as np

    from duffid import Duffing1
    from duffid.identification.c_core import CIdentifier
    from duffid.identification.engine import OnlineIdentifier

    tracking = load_benchmark("tracking")
    rig, _, changes, _ = tracking.CHANGES["quasi-static k -10 %"]
    record = tracking.record_of(rig, changes, 0)
    n = 1500
    python = OnlineIdentifier(Duffing1(), tracking.DT)
    windows = [python.update(record.x[i], record.f[i]).window for i in range(n)]
    c = CIdentifier(Duffing1(), tracking.DT).run(record.x[:n], record.f[:n])
    assert windows[-1] == pytest.approx(0.111)
    np.testing.assert_allclose(windows, c["window"], rtol=0, atol=1e-12)
