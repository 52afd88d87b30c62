"""The single-precision build of the C estimator core (-DDUFFID_REAL=float) against the
default double build, on the x86 host through ctypes (CIdentifier(precision="float")).

Issue 28: on the records of benchmarks/trust.py, every value the float build publishes is
within its stated uncertainty of the double build's, and a value that float arithmetic cannot
determine is not published. The comparison is benchmarks/embedded.py's ``float_accuracy``
(its float-against-double section runs every record): at every sample where the float build
publishes a parameter and both builds estimate over the same window,
|v_float - current_double| <= uncertainty_float |v_float|. Here it runs on a few records
chosen for speed (the simulated records are cached by benchmarks/embedded.py's
``trust_record``), with a negative control showing the check sees a value off by more than
its stated uncertainty.
"""
from __future__ import annotations

import shutil

import numpy as np
import pytest

from duffid import Duffing1
from duffid.errors import InputError
from duffid.identification.c_core import PRECISIONS, CIdentifier
from duffid.identification.engine import STATUSES

pytestmark = pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None,
                                reason="no C compiler")

from benchmark_modules import load_benchmark

embedded = load_benchmark("embedded")

#: Well excited: both builds publish every parameter over the same window (compared samples).
WELL_EXCITED = "lab softening random 40 dB"
#: Records of benchmarks/trust.py that simulate in seconds: 1-DOF softening and hardening, the
#: circuit (a generated model), the 2-DOF chain, random and hammer excitation, 200 Hz to 2 kHz.
RECORDS = [WELL_EXCITED, "lab softening hammer 40 dB", "circuit random 50 dB", "2-DOF random 40 dB",
           "lab hardening random 40 dB 200 Hz"]
PUBLISHED = STATUSES.index("published")


@pytest.fixture(scope="module")
def runs():
    """{record: (names, {precision: outputs}, dt, truth)} of both builds over RECORDS."""
    trust = embedded.trust_module()
    out = {}
    for case in (c for c in trust.CASES if c.name in RECORDS):
        x, f, dt, truth, model = embedded.trust_record(case)
        names, outputs = embedded.run_precisions(model, dt, x, f)
        out[case.name] = (names, outputs, dt, truth)
    assert sorted(out) == sorted(RECORDS)
    return out


def test_float_values_within_their_stated_uncertainty_of_double(runs):
    rows = [embedded.float_accuracy(name, *run) for name, run in runs.items()]
    for r in rows:
        assert r.violations == 0, f"{r.record}: ratio {r.max_ratio:.3g} at sample {r.worst[0]} ({r.worst[1]})"
    compared = {r.record: r.compared for r in rows}
    # Not vacuous: the well-excited records are compared at (nearly) every published sample.
    assert compared[WELL_EXCITED] > 20_000 and compared["circuit random 50 dB"] > 20_000, compared


def test_float_values_within_their_stated_uncertainty_over_the_same_windows(runs):
    """With the window fixed at the double build's automatic one, both builds estimate over the
    same windows at every sample: every value the float build publishes is compared."""
    trust = embedded.trust_module()
    for case in (c for c in trust.CASES if c.name in RECORDS):
        x, f, dt, truth, model = embedded.trust_record(case)
        window = float(runs[case.name][1]["double"]["window"][-1])
        names, outputs = embedded.run_precisions(model, dt, x, f, window=window)
        r = embedded.float_accuracy(case.name, names, outputs, dt, truth)
        assert r.violations == 0, f"{r.record}: ratio {r.max_ratio:.3g} at sample {r.worst[0]} ({r.worst[1]})"
        assert r.compared == r.published_float, r
        # not vacuous (the 200 Hz record publishes nothing online since its accumulated rows'
        # degrees of freedom count WINDOW_EQUATIONS per window: its values were 'lost' before)
        assert r.published_float > 0 or case.name == "lab hardening random 40 dB 200 Hz", r


def test_the_check_sees_a_value_beyond_its_stated_uncertainty(runs):
    names, outputs, dt, truth = runs[WELL_EXCITED]
    off = outputs["float"].copy()
    last = len(off) - 1
    assert off["status"][last, 0] == PUBLISHED
    off["parameters"][last, 0] *= 1 + 2 * off["uncertainty"][last]
    r = embedded.float_accuracy(WELL_EXCITED, names, {"double": outputs["double"], "float": off}, dt, truth)
    assert r.violations == 1 and r.worst == (last, names[0]) and 1.5 < r.max_ratio < 2.5, r


def test_float_publishes_the_well_excited_record(runs):
    names, outputs, dt, truth = runs[WELL_EXCITED]
    last = outputs["float"][-1]
    for i, name in enumerate(names):
        assert last["status"][i] == PUBLISHED, f"{name}: {STATUSES[last['status'][i]]}"
        value = float(last["parameters"][i])
        assert abs(value - truth[name]) <= 0.02 * abs(truth[name]), f"{name}: {value} against {truth[name]}"


def test_float_build_runs_in_single_precision(runs):
    names, outputs, dt, truth = runs[WELL_EXCITED]
    k = len(names)
    d, fl = outputs["double"], outputs["float"]
    assert fl["parameters"].dtype.base == np.float32 and d["parameters"].dtype.base == np.float64
    # Not the double build's answer rounded to float: single-precision arithmetic differs.
    current_d = d["current"][-1, :k].astype(np.float32)
    assert np.any(current_d != fl["current"][-1, :k])
    # The float build accounts for its rounding: it states no smaller uncertainty at the end.
    assert fl["uncertainty"][-1] >= d["uncertainty"][-1]


def test_first_samples_alike_and_unpublished(runs):
    for name, (names, outputs, dt, truth) in runs.items():
        k = len(names)
        d, fl = outputs["double"][:8], outputs["float"][:8]
        np.testing.assert_array_equal(fl["status"][:, :k], d["status"][:, :k], err_msg=name)
        np.testing.assert_array_equal(fl["identified"], d["identified"], err_msg=name)
        assert not (fl["status"][:, :k] == PUBLISHED).any(), name
        assert np.isnan(fl["parameters"][:, :k]).all(), name


def test_paper_method_refused_in_float():
    with pytest.raises(InputError, match="double precision"):
        CIdentifier(Duffing1(), 1e-3, method="paper", precision="float")
    CIdentifier(Duffing1(), 1e-3, method="paper", precision="double").close()


def test_unknown_precision_names_the_valid_ones():
    with pytest.raises(InputError) as error:
        CIdentifier(Duffing1(), 1e-3, precision="half")
    message = str(error.value)
    assert "half" in message and all(p in message for p in PRECISIONS), message
