"""Co-simulation orchestrator (duffid.cosim.system) and its container export (duffid.cosim.container).

The small FMUs (ramp, integrator, gain: tests/cosim_models.mo) are exported once per
module with duffid's Modelica export; the plant and the C estimator are the project's.

Tolerances: the ramp/integrator/gain systems are a few additions and multiplications per
step on values of order 1 (no BLAS involved); their exact sums are compared at 1e-12
absolute, thousands of ulps above the rounding of a few hundred steps. The container FMU
runs the same binaries as the orchestrator: 1e-12 relative. The C estimator against
identify() is compared at the record's one-ulp spread (tests/rounding.py).
"""
from __future__ import annotations

import csv
import itertools
import os
import random
import shutil
import tempfile
import zipfile
from pathlib import Path

import numpy as np
import pytest

fmpy = pytest.importorskip("fmpy")

from fmpy.validation import validate_fmu  # noqa: E402
from rounding import identifier_spread  # noqa: E402

from duffid import Duffing1  # noqa: E402
from duffid.cbuild import FMI2_PLATFORM  # noqa: E402
from duffid.cosim.system import (  # noqa: E402  # noqa: E402
    Connection,
    CosimError,
    Result,
    System,
    WiringError,
    _exact_order,
    _greedy_order,
    _skewed,
    _order_cost,
)
from duffid.data.record import Record  # noqa: E402
from duffid.data.signals import Step  # noqa: E402
from duffid.fmu.estimator import build_estimator_fmu  # noqa: E402
from duffid.identification.batch import estimate  # noqa: E402
from duffid.modelica.export import build_all, export_fmu  # noqa: E402

if shutil.which("gcc") is None:
    pytest.skip("gcc is needed to build the test FMUs", allow_module_level=True)

MODELS = Path(__file__).with_name("cosim_models.mo")
H = 0.01


@pytest.fixture(scope="module")
def fmus(tmp_path_factory) -> dict[str, Path]:
    """Ramp, Integrator, Gain (FMI 2: ``Name``, FMI 3: ``Name_fmi3``), the 1-DOF plant and
    the C estimator, both versions."""
    out = tmp_path_factory.mktemp("cosim_fmus")
    paths = [export_fmu(MODELS, f"CosimTest.{name}", out, version, "cs")
             for name in ("Ramp", "Integrator", "Gain") for version in (2, 3)]
    paths += build_all(out, ("Oscillator1DOF",))
    paths += [build_estimator_fmu("duffing1", out, version) for version in (2, 3)]
    return {p.stem: p for p in paths}


def _v(version: int) -> str:
    return "" if version == 2 else "_fmi3"


def _chain(fmus, versions=(2, 2, 2), a=2.0, order=("ramp", "i1", "i2")) -> System:
    """ramp (slope a) -> i1 -> i2, components added in ``order``."""
    paths = {"ramp": fmus[f"Ramp{_v(versions[0])}"], "i1": fmus[f"Integrator{_v(versions[1])}"],
             "i2": fmus[f"Integrator{_v(versions[2])}"]}
    system = System()
    for name in order:
        system.add(name, paths[name], {"a": a} if name == "ramp" else None)
    return system.connect("ramp.y", "i1.u").connect("i1.y", "i2.u")


@pytest.fixture
def no_leftovers(monkeypatch):
    """Every directory made by tempfile.mkdtemp during the test is gone at its end, and
    no new duffid-cosim-* / duffid-container-* folder is left in the temporary folder."""
    made: list[str] = []
    real = tempfile.mkdtemp

    def tracking(*args, **kwargs):
        path = real(*args, **kwargs)
        made.append(path)
        return path

    monkeypatch.setattr(tempfile, "mkdtemp", tracking)
    mine = ("duffid-cosim-", "duffid-container-")
    before = {n for n in os.listdir(tempfile.gettempdir()) if n.startswith(mine)}
    yield made
    assert made, "the run made no temporary directory (tracking broken?)"
    assert [p for p in made if os.path.exists(p)] == []
    after = {n for n in os.listdir(tempfile.gettempdir()) if n.startswith(mine)}
    assert after <= before


# ------------------------------------------------------------------------------ 1. analytic chain
@pytest.mark.parametrize("versions", [(2, 2, 2), (3, 3, 3), (3, 2, 3)])
def test_jacobi_chain_gives_left_riemann_sums(fmus, versions, no_leftovers):
    a, t0 = 2.0, 0.25
    result = _chain(fmus, versions, a).run(stop_time=1.25, step=H, start_time=t0)
    n = np.arange(101)
    assert len(result) == 101
    assert np.array_equal(result.time, t0 + n * H)  # t0 + k h, never accumulated
    assert result.names == ["ramp.y", "i1.y", "i2.y"]
    # inputs held over each step: i1(t_n) = sum_{k<n} h a k h, i2(t_n) = sum_{k<n} h i1(t_k)
    np.testing.assert_allclose(result["ramp.y"], a * n * H, rtol=0, atol=1e-12)
    np.testing.assert_allclose(result["i1.y"], a * H ** 2 * n * (n - 1) / 2, rtol=0, atol=1e-12)
    np.testing.assert_allclose(result["i2.y"], a * H ** 3 * n * (n - 1) * (n - 2) / 6, rtol=0, atol=1e-12)
    assert result.failure is None and result.ordering == "jacobi"
    assert result.delayed == [Connection("ramp.y", "i1.u"), Connection("i1.y", "i2.u")]


def test_step_must_divide_the_interval(fmus):
    system = _chain(fmus)
    with pytest.raises(WiringError, match="integer multiple"):
        system.run(1.0, 0.3)
    with pytest.raises(WiringError, match="positive"):
        system.run(1.0, -0.1)
    with pytest.raises(WiringError, match="ordering"):
        system.run(1.0, H, ordering="seidel")
    assert len(system.run(0.3, 0.1)) == 4  # 0.3 / 0.1 = 2.9999999999999996: an integer within 1e-9


# ------------------------------------------------------------------------------ 2. Gauss-Seidel
def test_gauss_seidel_chain_is_one_step_ahead_per_stage(fmus):
    system = _chain(fmus, order=("i2", "i1", "ramp"))
    assert system.gauss_seidel_order() == (["ramp", "i1", "i2"], [])
    jacobi = system.run(1.0, H)
    gs = system.run(1.0, H, ordering="gauss-seidel")
    assert gs.order == ["ramp", "i1", "i2"] and gs.delayed == [] and gs.ordering == "gauss-seidel"
    np.testing.assert_allclose(gs["ramp.y"], jacobi["ramp.y"], rtol=0, atol=1e-12)
    # each stage sees its source at t_{k+1}: one step ahead of Jacobi per stage
    np.testing.assert_allclose(gs["i1.y"][:-1], jacobi["i1.y"][1:], rtol=0, atol=1e-12)
    np.testing.assert_allclose(gs["i2.y"][:-2], jacobi["i2.y"][2:], rtol=0, atol=1e-12)
    assert not np.allclose(gs["i2.y"], jacobi["i2.y"])
    # the reverse order delays every connection: that is Jacobi again
    backwards = system.run(1.0, H, ordering="gauss-seidel", order=["i2", "i1", "ramp"])
    assert backwards.delayed == [Connection("ramp.y", "i1.u"), Connection("i1.y", "i2.u")]
    for name in jacobi.names:
        np.testing.assert_array_equal(backwards[name], jacobi[name])


@pytest.mark.parametrize("first", ["int", "gain"])
def test_feedback_loop_orders_and_closed_forms(fmus, first):
    """der(y) = k y through integrator <-> gain: GS is explicit Euler, Jacobi delays twice."""
    k, n = -3.0, 100
    system = System()
    for name in (first, "gain" if first == "int" else "int"):
        if name == "int":
            system.add("int", fmus["Integrator"], {"y0": 1.0})
        else:
            system.add("gain", fmus["Gain_fmi3"], {"k": k})
    system.connect("int.y", "gain.u").connect("gain.y", "int.u")
    order, delayed = system.gauss_seidel_order()
    if first == "int":  # one connection must be delayed; ties go to insertion order
        assert order == ["int", "gain"] and delayed == [Connection("gain.y", "int.u")]
    else:
        assert order == ["gain", "int"] and delayed == [Connection("int.y", "gain.u")]
    gs = system.run(n * H, H, ordering="gauss-seidel")
    jacobi = system.run(n * H, H)
    assert gs.order == order and gs.delayed == delayed
    y_j, previous = [1.0], 0.0  # the gain's output at t_0 is k * (start of u = 0)
    for _ in range(n):
        y_j, previous = y_j + [y_j[-1] + H * k * previous], y_j[-1]
    np.testing.assert_allclose(jacobi["int.y"], y_j, rtol=0, atol=1e-12)
    if first == "gain":  # the gain sees y(t_k), the integrator k y(t_k) at t_{k+1}: explicit Euler
        np.testing.assert_allclose(gs["int.y"], (1 + k * H) ** np.arange(n + 1), rtol=0, atol=1e-12)
    else:  # the integrator sees the gain's output at t_k; at t_0 that is k * 0: Euler one step late
        np.testing.assert_allclose(gs["int.y"][1:], (1 + k * H) ** np.arange(n), rtol=0, atol=1e-12)
        assert gs["int.y"][0] == 1.0


def _brute_force(n, edges):
    best = min(_order_cost(p, edges) for p in itertools.permutations(range(n)))
    return next(list(p) for p in itertools.permutations(range(n)) if _order_cost(p, edges) == best)


def test_derived_order_is_the_best_permutation():
    rng = random.Random(7)
    for _ in range(60):
        n = rng.randint(1, 6)
        edges = [(rng.randrange(n), rng.randrange(n)) for _ in range(rng.randint(0, 10))]
        assert _exact_order(n, edges) == _brute_force(n, edges), edges
    # beyond the exact limit: the heuristic gives a permutation, a chain without delays
    chain = [(i, i + 1) for i in range(19)]
    order = _greedy_order(20, list(reversed(chain)))
    assert sorted(order) == list(range(20)) and _order_cost(order, chain) == 0
    ring = chain + [(19, 0)]
    assert _order_cost(_greedy_order(20, ring), ring) == 1


def _brute_force_one_instant(n, edges, together):
    fitting = [list(p) for p in itertools.permutations(range(n)) if _skewed(p, together) is None]
    if not fitting:
        return None
    best = min(_order_cost(p, edges) for p in fitting)
    return next(p for p in fitting if _order_cost(p, edges) == best)


def test_derived_order_feeds_a_sampled_component_from_one_instant():
    """A component that reads its inputs as samples of one instant (an estimator) steps before
    all its sources or after all of them; the best such permutation, None when there is none."""
    # the closed loop: plant 0, estimator 1, controller 2; est -> ctrl carries 5 connections
    edges = [(0, 1), (0, 2)] + [(1, 2)] * 5 + [(2, 0), (2, 1)]
    assert _exact_order(3, edges) == [0, 1, 2]  # fewest delays: x at t_k+1 with f at t_k
    assert _exact_order(3, edges, {1: (0b101, False)}) == [1, 0, 2]  # both at t_k (3 delays, not 2)
    # the estimator after both its sources when that costs fewer delays
    edges = [(0, 1), (2, 1), (0, 2)]
    assert _exact_order(3, edges, {1: (0b101, False)}) == [0, 2, 1]
    # a time-varying external input (or a connection from itself) arrives at t_k: before its sources
    assert _exact_order(3, edges, {1: (0b101, True)}) == [1, 0, 2]
    # two such components feeding each other: no order
    assert _exact_order(2, [(0, 1), (1, 0)], {0: (0b10, True), 1: (0b01, True)}) is None
    rng = random.Random(11)
    for _ in range(60):
        n = rng.randint(1, 6)
        edges = [(rng.randrange(n), rng.randrange(n)) for _ in range(rng.randint(0, 10))]
        together = {}
        for v in rng.sample(range(n), rng.randint(0, n)):
            sources = 0
            for s, d in edges:
                sources |= 1 << s if d == v and s != v else 0
            together[v] = (sources, any(s == d == v for s, d in edges) or rng.random() < 0.2)
        assert _exact_order(n, edges, together) == _brute_force_one_instant(n, edges, together), (edges, together)


# ------------------------------------------------------------------------------ 3. container
def _container_system(fmus) -> System:
    return (System().add("ramp", fmus["Ramp"], {"a": 2.0}).add("i1", fmus["Integrator_fmi3"], {"y0": 0.5})
            .add("gain", fmus["Gain"], {"k": -4.0})
            .connect("ramp.y", "i1.u").connect("i1.y", "gain.u"))


def test_container_equals_jacobi_and_validates(fmus, tmp_path, no_leftovers):
    system = _container_system(fmus)
    path = system.export_container(tmp_path / "chain.fmu", outputs={"y": "i1.y", "g": "gain.y", "r": "ramp.y"},
                                   step=H)
    assert validate_fmu(str(path)) == []
    md = fmpy.read_model_description(str(path))
    params = {v.name: v.start for v in md.modelVariables if v.causality == "parameter"}
    assert params == {"ramp.a": "2.0", "i1.y0": "0.5", "gain.k": "-4.0"}
    # the container binaries only of the platforms every component has (here: this machine's)
    with zipfile.ZipFile(path) as z:
        platforms = {n.split("/")[1] for n in z.namelist() if n.startswith("binaries/") and n.count("/") == 2}
    assert platforms == {FMI2_PLATFORM}
    expected = system.run(1.0, H)
    inner = System().add("c", path).run(1.0, H)
    for name, source in {"y": "i1.y", "r": "ramp.y"}.items():
        np.testing.assert_allclose(inner[f"c.{name}"], expected[source], rtol=1e-12, atol=1e-15)
    # the gain has direct feedthrough: the container propagates i1.y(t_k) to gain.u before
    # its outputs are read, the orchestrator reads gain.y right after doStep (u from t_{k-1})
    np.testing.assert_allclose(inner["c.g"], -4.0 * expected["i1.y"], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(expected["gain.y"][1:], -4.0 * expected["i1.y"][:-1], rtol=1e-12, atol=1e-15)
    # the add() parameters act inside the container: another value changes the result
    other = System().add("c", path, {"gain.k": -1.0}).run(1.0, H)
    np.testing.assert_allclose(other["c.g"], inner["c.g"] / 4.0, rtol=1e-12, atol=1e-15)
    # fmpy's own master (no logger= argument: see tests/fmu_helpers.py)
    fmpy_result = fmpy.simulate_fmu(str(path), start_time=0.0, stop_time=1.0, step_size=H, output_interval=H)
    np.testing.assert_allclose(fmpy_result["y"], expected["i1.y"], rtol=1e-12, atol=1e-15)


def test_container_with_inputs_boolean_outputs_and_parameters(fmus, tmp_path):
    """Plant and estimator in one container, the force an input of both, the estimator's
    window a renamed container parameter."""
    force = Step(10.0, 0.01)

    def system(window):
        return (System().add("plant", fmus["Oscillator1DOF"], {"m": 2.4})
                .add("est", fmus["DuffingEstimator1"], {"window": window})
                .connect("plant.x", "est.x"))

    path = system(0.1).export_container(tmp_path / "pe.fmu", inputs={"f": ["plant.f", "est.f"]},
                                        outputs={"x": "plant.x", "k": "est.k_hat", "ok": "est.identified"},
                                        step=1e-3, parameters={"window": "est.window"})
    assert validate_fmu(str(path)) == []
    md = {v.name: v for v in fmpy.read_model_description(str(path)).modelVariables}
    assert md["ok"].type == "Boolean" and md["window"].start == "0.1" and md["plant.m"].start == "2.4"
    expected = system(0.1).set_input("plant.f", force).set_input("est.f", force).run(0.4, 1e-3)
    inner = System().add("c", path).set_input("c.f", force).run(0.4, 1e-3)
    np.testing.assert_allclose(inner["c.x"], expected["plant.x"], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(inner["c.k"], expected["est.k_hat"], rtol=1e-12, equal_nan=True)
    np.testing.assert_array_equal(inner["c.ok"], expected["est.identified"])
    assert expected["est.identified"][-1] and not expected["est.identified"][0]
    changed = System().add("c", path, {"window": 0.2}).set_input("c.f", force).run(0.4, 1e-3)
    assert not np.allclose(changed["c.k"], inner["c.k"], equal_nan=True)
    signal = np.zeros(401, dtype=[("time", float), ("f", float)])
    signal["time"] = np.arange(401) * 1e-3
    signal["f"] = force(signal["time"])
    by_fmpy = fmpy.simulate_fmu(str(path), stop_time=0.4, step_size=1e-3, output_interval=1e-3, input=signal)
    np.testing.assert_allclose(by_fmpy["x"], expected["plant.x"], rtol=1e-12, atol=1e-15)


def test_container_wiring_errors(fmus, tmp_path):
    system = _container_system(fmus)
    with pytest.raises(WiringError, match="already connected"):
        system.export_container(tmp_path / "a.fmu", inputs={"u": ["i1.u"]})
    with pytest.raises(WiringError, match="not an output"):
        system.export_container(tmp_path / "a.fmu", outputs={"u": "ramp.a"})
    with pytest.raises(WiringError, match="did you mean 'y'"):
        system.export_container(tmp_path / "a.fmu", outputs={"u": "i1.yy"})
    assert not (tmp_path / "a.fmu").exists()


# ------------------------------------------------------------------------------ 4. failures
def _plant_estimator(fmus, version=2, est_force=None, est_params=None) -> System:
    return (System().add("plant", fmus[f"Oscillator1DOF{_v(version)}"])
            .add("est", fmus[f"DuffingEstimator1{_v(version)}"], est_params)
            .connect("plant.x", "est.x")
            .set_input("plant.f", Step(10.0)).set_input("est.f", est_force or Step(10.0)))


@pytest.mark.parametrize("version", [2, 3])
def test_nan_input_stops_the_run_with_a_named_error(fmus, version, no_leftovers, freed):
    clean = _plant_estimator(fmus, version).run(1.0, 1e-3)
    assert sorted(freed) == ["est", "plant"]
    system = _plant_estimator(fmus, version, lambda t: float("nan") if t >= 0.5 else 10.0)
    with pytest.raises(CosimError) as info:
        system.run(1.0, 1e-3)
    assert sorted(freed) == ["est", "est", "plant", "plant"]  # the failed instance too (Error)
    err = info.value
    message = str(err)
    function = "fmi2SetReal" if version == 2 else "fmi3SetFloat64"
    assert "'est'" in message and fmus[f"DuffingEstimator1{_v(version)}"].name in message
    assert function in message and "Error" in message and "t = 0.5" in message and "not finite" in message
    f = err.failure
    assert (f.component, f.function, f.status, f.time) == ("est", function, "Error", 0.5)
    assert any("not finite" in m for m in f.messages)
    partial = err.result
    assert isinstance(partial, Result) and partial.failure is f
    assert len(partial) == 501 and partial.time[-1] == 0.5  # rows up to t = 0.5 are complete
    for name in ("plant.x", "est.k_hat", "est.identified"):
        np.testing.assert_array_equal(partial[name][:500], clean[name][:500])
    assert np.isnan(partial["est.f"][-1])
    # every instance was freed: the same FMUs run again in this process
    again = _plant_estimator(fmus, version).run(0.1, 1e-3)
    np.testing.assert_array_equal(again["plant.x"], clean["plant.x"][:101])


def test_exception_in_an_input_function(fmus, no_leftovers):
    def force(t):
        if t >= 0.3:
            raise ZeroDivisionError("boom")
        return 10.0

    with pytest.raises(CosimError, match="input function of plant.f") as info:
        System().add("plant", fmus["Oscillator1DOF"]).set_input("plant.f", force).run(1.0, 1e-2)
    err = info.value
    assert isinstance(err.__cause__, ZeroDivisionError)
    assert err.failure.component == "plant" and err.failure.time == pytest.approx(0.3)
    assert "ZeroDivisionError: boom" in str(err)
    assert len(err.result) == 30 and err.result.time[-1] == pytest.approx(0.29)


def test_keyboard_interrupt_frees_everything(fmus, no_leftovers):
    def force(t):
        if t >= 0.05:
            raise KeyboardInterrupt
        return 1.0

    with pytest.raises(CosimError, match="KeyboardInterrupt") as info:
        _plant_estimator(fmus, 3, est_force=force).run(1.0, 1e-3)
    assert isinstance(info.value.__cause__, KeyboardInterrupt)
    assert len(info.value.result) == 50


@pytest.mark.parametrize("version", [2, 3])
def test_discard_from_do_step(fmus, version, no_leftovers, freed):
    # a 20 N force drives the softening plant out of its well: the integrator gives up
    system = System().add("plant", fmus[f"Oscillator1DOF{_v(version)}"]).set_input("plant.f", 20.0)
    with pytest.raises(CosimError) as info:
        system.run(1.0, 1e-3)
    assert freed == ["plant"]
    f = info.value.failure
    assert f.function == ("fmi2DoStep" if version == 2 else "fmi3DoStep") and f.status == "Discard"
    assert 0.1 < f.time < 0.5 and len(info.value.result) == round(f.time / 1e-3) + 1
    assert np.all(np.isfinite(info.value.result["plant.x"]))
    # an invalid estimator option: Discard at the first step, only row 0 kept
    with pytest.raises(CosimError, match="Discard") as info:
        _plant_estimator(fmus, version, est_params={"method": 5}).run(0.1, 1e-3)
    assert info.value.failure.time == 0.0 and len(info.value.result) == 1
    assert any("method" in m for m in info.value.failure.messages)


# ------------------------------------------------------------------------------ 5. wiring errors
def test_wiring_errors(fmus, tmp_path):
    s = _plant_estimator(fmus)
    with pytest.raises(WiringError, match=r"has no variable 'xx'; did you mean 'x'"):
        s.connect("plant.xx", "est.x")
    with pytest.raises(WiringError, match="no component 'plnt'.*did you mean 'plant'"):
        s.connect("plnt.x", "est.x")
    with pytest.raises(WiringError, match="Oscillator1DOF.fmu"):
        s.connect("plant.vv", "est.x")
    with pytest.raises(WiringError, match="'component.variable'"):
        s.connect("plant", "est.x")
    with pytest.raises(WiringError, match="m_hat is an output, not an input"):
        s.connect("plant.v", "est.m_hat")
    with pytest.raises(WiringError, match="f is an input, not an output"):
        s.connect("plant.f", "est.x")
    with pytest.raises(WiringError, match="already driven by the connection from 'plant.x'"):
        s.connect("plant.v", "est.x")
    with pytest.raises(WiringError, match="already driven by set_input"):
        s.connect("plant.v", "est.f")
    with pytest.raises(WiringError, match="already driven"):
        s.set_input("plant.f", 1.0)
    with pytest.raises(WiringError, match=r"'p.x' \[m\] to 'e.f' \[N\]: units differ"):
        System().add("p", fmus["Oscillator1DOF"]).add("e", fmus["DuffingEstimator1"]).connect("p.x", "e.f")
    g = System().add("e", fmus["DuffingEstimator1"]).add("g", fmus["Gain"])
    with pytest.raises(WiringError, match=r"\(Boolean\) to 'g.u' \(Real\): types differ"):
        g.connect("e.identified", "g.u")
    with pytest.raises(WiringError, match="already in the system"):
        g.add("g", fmus["Gain"])
    with pytest.raises(WiringError, match="identifier"):
        g.add("a.b", fmus["Gain"])
    with pytest.raises(WiringError, match="does not exist"):
        g.add("h", tmp_path / "missing.fmu")


def test_parameter_errors(fmus):
    est = fmus["DuffingEstimator1"]
    with pytest.raises(WiringError, match=r"DuffingEstimator1.fmu.*no variable 'windw'; did you mean 'window'"):
        System().add("est", est, {"windw": 0.1})
    with pytest.raises(WiringError, match="parameter method is Integer; got 0.5"):
        System().add("est", est, {"method": 0.5})
    with pytest.raises(WiringError, match="parameter window is Real; got '0.1'"):
        System().add("est", est, {"window": "0.1"})
    with pytest.raises(WiringError, match="parameter sign_in_numerator is Boolean; got 2"):
        System().add("est", est, {"sign_in_numerator": 2})
    with pytest.raises(WiringError, match="k_hat is an output .*not a settable parameter"):
        System().add("est", est, {"k_hat": 1.0})
    with pytest.raises(WiringError, match="is an input; drive it with set_input"):
        System().add("est", est, {"x": 1.0})
    s = System().add("est", est, {"method": 1, "sign_in_numerator": True, "gamma": 10})
    assert s.components == ["est"]


def test_input_and_record_errors(fmus):
    s = System().add("plant", fmus["Oscillator1DOF"])
    with pytest.raises(WiringError, match="number, a function of t or"):
        s.set_input("plant.f", "ten")
    with pytest.raises(WiringError, match="non-decreasing"):
        s.set_input("plant.f", ([0.0, 1.0, 0.5], [1.0, 2.0, 3.0]))
    with pytest.raises(WiringError, match="more than twice"):
        s.set_input("plant.f", ([0.0, 0.5, 0.5, 0.5, 1.0], [1.0, 2.0, 3.0, 4.0, 5.0]))
    with pytest.raises(WiringError, match="interpolation must be one of linear, hold, average, sample-of-hold"):
        s.set_input("plant.f", ([0.0, 1.0], [1.0, 2.0]), interpolation="cubic")
    s.set_input("plant.f", ([0.0, 0.5], [0.0, 1.0]))
    with pytest.raises(WiringError, match=r"t = 1.0 lies outside the sampled range \[0.0, 0.5\]"):
        s.run(1.0, 0.1)
    with pytest.raises(WiringError, match="did you mean 'x'"):
        s.run(0.5, 0.1, record=["plant.xx"])
    pe = _plant_estimator(fmus)
    with pytest.raises(WiringError, match="record its source 'plant.x'"):
        pe.run(0.1, 1e-3, record=["est.x"])
    with pytest.raises(WiringError, match="exactly once"):
        pe.run(0.1, 1e-3, ordering="gauss-seidel", order=["plant"])
    with pytest.raises(WiringError, match="applies to ordering='gauss-seidel' only"):
        pe.run(0.1, 1e-3, order=["plant", "est"])


def test_sampled_inputs_interpolate_and_record_choice(fmus):
    ts = np.linspace(0.0, 1.0, 11)
    values = ts ** 2
    sampled = System().add("g", fmus["Gain"], {"k": 1.0}).set_input("g.u", (ts, values))
    result = sampled.run(1.0, 0.025, record=["g.u", "g.y"])
    assert result.names == ["g.u", "g.y"]
    np.testing.assert_allclose(result["g.u"], np.interp(result.time, ts, values), rtol=0, atol=1e-15)
    np.testing.assert_allclose(result["g.y"][1:], result["g.u"][:-1], rtol=0, atol=1e-15)  # held input
    assert "g.k" not in result and len(result) == 41
    with pytest.raises(KeyError, match="did you mean 'g.y'"):
        result["g.yy"]


def test_csv_inputs_and_output(fmus, tmp_path):
    path = tmp_path / "force.csv"
    path.write_text("time,force,other\n0,0,1\n0.5,5,1\n1.0,5,1\n")
    from_csv = System().add("plant", fmus["Oscillator1DOF"]).inputs_from_csv(path, {"force": "plant.f"})
    direct = System().add("plant", fmus["Oscillator1DOF"]).set_input("plant.f", ([0, 0.5, 1.0], [0, 5, 5]))
    a, b = from_csv.run(1.0, 0.01), direct.run(1.0, 0.01)
    np.testing.assert_array_equal(a["plant.x"], b["plant.x"])
    assert a["plant.f"][25] == 2.5
    out = tmp_path / "out.csv"
    a.to_csv(out)
    with open(out, newline="") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["time", "plant.f", "plant.x", "plant.v"] and len(rows) == 102
    back = np.array(rows[1:], dtype=float)
    np.testing.assert_array_equal(back[:, 0], a.time)
    np.testing.assert_array_equal(back[:, 2], a["plant.x"])  # full precision


@pytest.mark.parametrize("text, match", [
    ("time,force\n0,1\n0.5,x\n", r"bad.csv, line 3, column 'force': 'x' is not a number"),
    ("time,force\n0,1\n1,2\n0.5,3\n", r"bad.csv, line 4, column 'time': time 0.5 does not increase"),
    ("time,force\n0,1\n1,2\n1,3\n1,4\n", r"bad.csv, line 5, column 'time': time 1.0 does not increase"),
    ("time,force\n0,1\n1,2\n", r"bad.csv: interpolation given for 'f', which is not one of the columns"),
    ("s,force\n0,1\n1,2\n", r"bad.csv, line 1: no time column 't' or 'time'"),
    ("t,forse\n0,1\n1,2\n", r"bad.csv, line 1: no column 'force'; did you mean 'forse'"),
    ("t,force\n0,1\n1\n", r"bad.csv, line 3: 1 fields, the header has 2"),
    ("t,force\n0,nan\n1,2\n", r"bad.csv, line 2, column 'force': 'nan' is not finite"),
    ("t,force\n0,1\n", r"at least 2 rows"),
])
def test_csv_errors_name_file_line_and_column(fmus, tmp_path, text, match):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(WiringError, match=match):
        System().add("plant", fmus["Oscillator1DOF"]).inputs_from_csv(path, {"force": "plant.f"},
                                                                       {"f": "hold"} if "interpolation" in match else None)


# ------------------------------------------------------------------------------ 6. plant -> estimator
@pytest.mark.parametrize("plant_version, est_version", [(2, 2), (3, 3), (2, 3)])
def test_open_loop_estimator_equals_identify(fmus, plant_version, est_version):
    system = (System().add("plant", fmus[f"Oscillator1DOF{_v(plant_version)}"])
              .add("est", fmus[f"DuffingEstimator1{_v(est_version)}"])
              .connect("plant.x", "est.x")
              .set_input("plant.f", Step(10.0)).set_input("est.f", Step(10.0)))
    result = system.run(0.25, 1e-3, progress=plant_version == 3)
    record = Record(t=result.time[:-1], f=result["plant.f"][:-1], x=result["plant.x"][:-1])
    expected = estimate(record, Duffing1())
    assert expected.identified[-1]
    # row k + 1 holds the estimate after sample k; C against Python at the record's one-ulp
    # spread (tests/rounding.py)
    identifier_spread(Duffing1(), record).assert_history(
        {name: result[f"est.{name}_hat"][1:] for name in Duffing1().parameters}, expected.history)
    np.testing.assert_array_equal(result["est.identified"][1:], expected.identified)
    assert result["est.identified"].dtype == bool


def test_python_fmu_string_parameter_and_its_logged_error(loop_fmus, tmp_path_factory):
    """A pythonfmu component: String parameters are set; its error reaches CosimError when
    its logging is on (and the message says how to turn it on when it is off)."""
    from duffid.fmu.python_estimator import build_python_fmu

    fmu = build_python_fmu("duffing1", tmp_path_factory.mktemp("python_fmu"))

    def system(method, logging):
        return (System().add("plant", loop_fmus["Oscillator1DOF"])
                .add("est", fmu, parameters={"method": method}, logging=logging)
                .connect("plant.x", "est.x").set_input("plant.f", 10.0).set_input("est.f", 10.0))

    result = system("robust", False).run(0.5, 1e-3)
    assert result["est.k_hat"][-1] == pytest.approx(1272.1, rel=1e-4)
    with pytest.raises(CosimError) as info:
        system("fast", True).run(0.1, 1e-3)
    assert "method must be 'robust' or 'paper'" in str(info.value)
    # with its logging off, FMI 2 cannot tell a failure from a request to stop: the run ends
    # early, says so and how to see why (and the pythonfmu estimator says why on stderr)
    ended = system("fast", False).run(0.1, 1e-3)
    assert len(ended) == 1 and "asked to end the simulation at t = 0.0" in ended.ended
    assert "logging=True" in ended.ended and np.isnan(ended["est.k_hat"][-1])
