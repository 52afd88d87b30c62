"""FMUs extracted once and instances reused across runs (duffid.cosim.instances): the same
results bit for bit as new instances, only healthy instances kept, logs reaching the run that
uses an instance, everything freed and deleted at the end."""
from __future__ import annotations

import numpy as np
import pytest

from duffid.control.controller_fmu import build_controller_fmu
from duffid.cosim.instances import InstancePool, active, reusing_instances
from duffid.cosim.system import System
from duffid.errors import CosimError
from duffid.fmu.estimator import build_estimator_fmu
from duffid.modelica.export import build_all

ESTIMATES = ("m_hat", "b_hat", "k_hat", "kp_hat")


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    out = tmp_path_factory.mktemp("reuse_fmus")
    paths = list(build_all(out, ("Oscillator1DOF",)))
    paths += [build_estimator_fmu("duffing1", out, v) for v in (2, 3)]
    paths += [build_controller_fmu(1, out, v) for v in (2, 3)]
    return {p.stem: p for p in paths}


def _loop(fmus, suffix=("", "_fmi3", "")) -> System:
    s = (System().add("plant", fmus["Oscillator1DOF" + suffix[0]])
         .add("est", fmus["DuffingEstimator1" + suffix[1]]).add("ctrl", fmus["AdaptiveController1" + suffix[2]]))
    s.connect("plant.x", "est.x").connect("plant.x", "ctrl.x")
    for name in ESTIMATES:
        s.connect(f"est.{name}", f"ctrl.{name}")
    s.connect("est.identified", "ctrl.identified").connect("ctrl.f", "plant.f").connect("ctrl.f_sample", "est.f")
    return s.set_input("ctrl.r", 0.005)


def _same(a, b) -> None:
    assert a.names == b.names
    for name in a.names:
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)


def test_reused_instances_give_the_same_runs_bit_for_bit(fmus, freed, tmp_path):
    """FMI 2 and FMI 3 components, Jacobi and Gauss-Seidel: three runs on reset instances equal
    runs on new ones; each FMU extracted once, instantiated once; at the end everything freed
    and the folder deleted."""
    system = _loop(fmus)
    fresh = {o: system.run(1.5, 1e-3, ordering=o) for o in ("jacobi", "gauss-seidel")}
    freed.clear()
    with reusing_instances(tmp_path / "pool") as pool:
        assert active() is pool
        for _ in range(3):
            for ordering, reference in fresh.items():
                _same(system.run(1.5, 1e-3, ordering=ordering), reference)
        assert (pool.extractions, pool.instantiations, pool.reuses) == (3, 3, 15)
        assert freed == []  # kept, not freed, between runs
        assert (tmp_path / "pool").is_dir()
    assert sorted(freed) == ["ctrl", "est", "plant"] and not (tmp_path / "pool").exists() and active() is None


def test_a_failed_run_frees_its_instances_and_logs_reach_the_run_that_uses_them(fmus, freed):
    """A run that fails keeps nothing (its instances are freed); the next run instantiates
    anew. A reused estimator that logs an error logs it into the run that uses it."""
    good = System().add("plant", fmus["Oscillator1DOF"]).set_input("plant.f", 1.0)
    bad = System().add("plant", fmus["Oscillator1DOF"]).set_input("plant.f", 20.0)  # leaves its well: Discard
    with reusing_instances() as pool:
        reference = good.run(0.2, 1e-3)
        with pytest.raises(CosimError, match="Discard"):
            bad.run(1.0, 1e-3)  # takes the kept instance, fails: freed
        assert pool.reuses == 1 and "plant" in freed
        _same(good.run(0.2, 1e-3), reference)
        assert pool.instantiations == 2
        est = System().add("est", fmus["DuffingEstimator1"]).set_input("est.x", 0.0).set_input("est.f", 0.0)
        est.run(0.01, 1e-3)
        wrong = System().add("est", fmus["DuffingEstimator1"], {"sample_period": 2e-3})
        wrong.set_input("est.x", 0.0).set_input("est.f", 0.0)
        with pytest.raises(CosimError) as info:
            wrong.run(0.01, 1e-3)  # the reused instance refuses the step and says why, to this run
        assert pool.reuses == 2 and any("sample_period" in m for m in info.value.failure.messages)


def test_what_is_reused():
    pool = InstancePool(reuse="duffid")
    try:
        assert pool.reusable("duffid (C model on duffid's FMI glue, fmus/common)")
        assert pool.reusable("duffid.modelica (pymoca front end, CasADi code generation)")
        assert not pool.reusable("PythonFMU 0.7.0") and not pool.reusable(None)
        assert InstancePool(pool.folder / "a", reuse="all").reusable("PythonFMU 0.7.0")
        assert not InstancePool(pool.folder / "b", reuse="none").reusable("duffid")
        with pytest.raises(ValueError, match="reuse must be one of"):
            InstancePool(pool.folder / "c", reuse="yes")
    finally:
        pool.close()
    assert not pool.folder.exists()
