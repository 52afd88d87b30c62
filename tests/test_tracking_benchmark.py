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
