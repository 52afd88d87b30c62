"""The orchestrator's compiled inner loop (duffid.cosim.compiled_loop): the same trajectories,
failures and rows as the Python loop, bit for bit, and the cases it leaves to Python."""
from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np
import pytest

from duffid.control.controller_fmu import build_controller_fmu
from duffid.cosim import compiled_loop
from duffid.cosim.system import System
from duffid.errors import CosimError, WiringError
from duffid.fmu.estimator import build_estimator_fmu
from duffid.modelica.export import build_all

ESTIMATES = ("m_hat", "b_hat", "k_hat", "kp_hat")


@pytest.fixture(scope="module")
def fmus(tmp_path_factory) -> dict[str, Path]:
    """Plant, estimator and controller (1 DOF), FMI 2 (``Name``) and FMI 3 (``Name_fmi3``)."""
    out = tmp_path_factory.mktemp("compiled_loop_fmus")
    paths = list(build_all(out, ("Oscillator1DOF",)))
    paths += [build_estimator_fmu("duffing1", out, v) for v in (2, 3)]
    paths += [build_controller_fmu(1, out, v) for v in (2, 3)]
    return {p.stem: p for p in paths}


def _loop(fmus, versions: tuple[int, int, int], reference=0.005) -> System:
    """plant -> est, ctrl; est -> ctrl (estimates and the Boolean identified); ctrl -> plant, est."""
    name = {2: "", 3: "_fmi3"}
    s = (System().add("plant", fmus["Oscillator1DOF" + name[versions[0]]])
         .add("est", fmus["DuffingEstimator1" + name[versions[1]]])
         .add("ctrl", fmus["AdaptiveController1" + name[versions[2]]]))
    s.connect("plant.x", "est.x").connect("plant.x", "ctrl.x")
    for estimate in ESTIMATES:
        s.connect(f"est.{estimate}", f"ctrl.{estimate}")
    s.connect("est.identified", "ctrl.identified").connect("ctrl.f", "plant.f").connect("ctrl.f_sample", "est.f")
    if reference is not None:
        s.set_input("ctrl.r", reference)
    return s


def test_an_order_that_feeds_the_estimator_from_two_instants_is_refused(fmus):
    """The estimator FMUs read x and f as samples of one instant (duffid's SampledInputs
    annotation): the plant and controller FMUs do not declare it; a given order that gives the
    estimator x at t_k+1 with f at t_k is refused naming both inputs."""
    system = _loop(fmus, (2, 3, 2))
    assert [system._components[c].sampled_inputs for c in ("plant", "est", "ctrl")] == [False, True, False]
    assert system.gauss_seidel_order()[0] == ["est", "plant", "ctrl"]  # x and f at t_k
    with pytest.raises(WiringError, match=r"'est'.*est\.x would get values at t_k\+1 and est\.f at t_k"):
        system.run(0.01, 1e-3, ordering="gauss-seidel", order=["plant", "est", "ctrl"])
    # a measured force replayed into the estimator arrives at t_k: the estimator steps first
    replay = (System().add("plant", fmus["Oscillator1DOF"]).add("est", fmus["DuffingEstimator1"])
              .connect("plant.x", "est.x"))
    t = np.arange(11) * 1e-3
    replay.replay((t, np.sin(t)), "plant.f", ["est.f"])
    assert replay.gauss_seidel_order()[0] == ["est", "plant"]


def _same(a, b) -> None:
    assert a.names == b.names and len(a) == len(b)
    np.testing.assert_array_equal(a.time, b.time)
    for name in a.names:
        assert a[name].dtype == b[name].dtype
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)  # NaN == NaN here: bit for bit


@pytest.mark.parametrize("versions", [(2, 2, 2), (3, 3, 3), (3, 2, 3), (2, 3, 2)])
@pytest.mark.parametrize("ordering", ["jacobi", "gauss-seidel"])
def test_compiled_loop_equals_python_loop_bit_for_bit(fmus, versions, ordering):
    """Real, Integer and Boolean values, FMI 2 and 3 mixed (FMI 3 Booleans are bytes: converted both
    ways), every output recorded."""
    system = _loop(fmus, versions)
    compiled = system.run(3.0, 1e-3, ordering=ordering)
    python = system.run(3.0, 1e-3, ordering=ordering, loop="python")
    if ordering == "gauss-seidel":  # the estimator's x and f from one instant (t_k): it steps first
        assert compiled.order == ["est", "plant", "ctrl"]
    assert (compiled.loop, python.loop) == ("compiled", "python")
    _same(compiled, python)
    assert compiled["est.identified"].dtype == bool and compiled["est.identified"][-1]
    assert abs(compiled["plant.x"][-1] - 0.005) < 1e-4  # the loop works: the plant follows r


def test_sampled_inputs_and_a_recorded_subset(fmus):
    """Input tables (sampled and interpolated on the grid) and recorded subsets (gathered rows)."""
    t = np.linspace(0.0, 2.0, 41)
    system = _loop(fmus, (2, 2, 3), reference=None).set_input("ctrl.r", (t, 0.004 + 0.002 * np.sin(3 * t)))
    record = ["est.k_hat", "plant.x", "ctrl.r", "est.identified", "ctrl.phase"]
    for ordering in ("jacobi", "gauss-seidel"):
        compiled = system.run(2.0, 1e-3, ordering=ordering, record=record)
        python = system.run(2.0, 1e-3, ordering=ordering, record=record, loop="python")
        assert compiled.loop == "compiled"
        _same(compiled, python)
        np.testing.assert_allclose(compiled["ctrl.r"], np.interp(compiled.time, t, 0.004 + 0.002 * np.sin(3 * t)),
                                   rtol=1e-12)


@pytest.mark.parametrize("version", [2, 3])
def test_failures_are_the_same_in_both_loops(fmus, version):
    """A non-finite sampled input (the estimator refuses it: set fails) and a Discard from doStep
    (the plant's integrator gives up): the same failure, time, messages and rows."""
    name = "" if version == 2 else "_fmi3"
    t = np.linspace(0.0, 1.0, 1001)
    force = np.where(t < 0.5, 10.0, np.nan)
    nan_input = (System().add("plant", fmus["Oscillator1DOF" + name]).add("est", fmus["DuffingEstimator1" + name])
                 .connect("plant.x", "est.x").set_input("plant.f", 10.0).set_input("est.f", (t, force)))
    discard = System().add("plant", fmus["Oscillator1DOF" + name]).set_input("plant.f", 20.0)
    for system in (nan_input, discard):
        errors = {}
        for loop in ("compiled", "python"):
            with pytest.raises(CosimError) as info:
                system.run(1.0, 1e-3, loop=loop)
            errors[loop] = info.value
        a, b = errors["compiled"], errors["python"]
        assert a.result.loop == "compiled" and b.result.loop == "python"
        assert (a.failure.component, a.failure.function, a.failure.status, a.failure.time) == \
               (b.failure.component, b.failure.function, b.failure.status, b.failure.time)
        assert a.failure.messages == b.failure.messages
        _same(a.result, b.result)
    assert errors["compiled"].failure.function.endswith("DoStep")


def test_the_cases_left_to_python(fmus):
    """An input that is a Python function runs the Python loop (auto), and loop='compiled' says why not."""
    system = System().add("plant", fmus["Oscillator1DOF"]).set_input("plant.f", lambda t: 1.0)
    assert system.run(0.01, 1e-3).loop == "python"
    with pytest.raises(WiringError, match="plant.f is a Python function"):
        system.run(0.01, 1e-3, loop="compiled")
    with pytest.raises(WiringError, match="loop must be one of"):
        system.run(0.01, 1e-3, loop="C")


# --------------------------------------------------------------- the C loop alone, with fake FMI functions
_SET = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p)
_STEP2 = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_int)


class _Fake:
    """An FMI 2 'component' y = y + u*h in Python, with a doStep that returns ``status`` at step ``at``."""

    def __init__(self, at: int = -1, status: int = 0) -> None:
        self.u, self.y, self.at, self.status, self.k = 0.0, 0.0, at, status, 0
        self.set = _SET(self._set)
        self.get = _SET(self._get)
        self.step = _STEP2(self._step)
        self.handle = ctypes.c_void_p(1)

    def _set(self, c, vr, n, value):
        self.u = ctypes.cast(value, ctypes.POINTER(ctypes.c_double))[0]
        return 0

    def _get(self, c, vr, n, value):
        ctypes.cast(value, ctypes.POINTER(ctypes.c_double))[0] = self.y
        return 0

    def _step(self, c, t, h, no_prior):
        k, self.k = self.k, self.k + 1
        self.y += self.u * h
        return self.status if k == self.at else 0


def _fake_loop(fake: _Fake, n: int, on_step):
    lib = compiled_loop.load()
    g = np.zeros(1)
    table = np.arange(n + 1, dtype=np.float64)[:, None]  # u_k = k
    buf = np.zeros(1)
    rec = np.zeros((n + 1, 1))
    vrs = (ctypes.c_uint * 1)(0)
    size = ctypes.c_size_t(1)
    u_ptr = buf.ctypes.data_as(ctypes.POINTER(ctypes.c_double))
    y_ptr = ctypes.cast(g.ctypes.data, ctypes.POINTER(ctypes.c_double))
    u_source = np.array([0.0, 0.0])  # gathered: g_u[0] -> buf
    sets = [(u_source, np.array([1]), buf, fake.set, (fake.handle, vrs, size, u_ptr), 0, "fmi2SetReal")]
    steps = [(fake.step, (fake.handle,), 0, "fmi2DoStep", ctypes.c_bool(False), None, None)]
    gets = [(fake.get, (fake.handle, vrs, size, y_ptr), 0, "fmi2GetReal")]
    moves = [(u_source[1:], table, None, 0, table.strides[0]), (rec, g, None, rec.strides[0], 0)]
    grid = np.arange(n + 1) * 0.5
    loop = compiled_loop.CompiledLoop(lib, grid, 0.5, [(sets, steps, gets, [])], moves, on_step)
    return loop, rec, (g, buf, u_source, table, vrs, u_ptr, y_ptr)


def test_c_loop_runs_ends_and_aborts_as_told():
    if compiled_loop.load() is None:
        pytest.skip("no C compiler")
    n = 6
    fake = _Fake()
    loop, rec, keep = _fake_loop(fake, n, lambda op, status, k: pytest.fail("no callback expected"))
    assert loop.run(0, 3) == compiled_loop.DONE and loop.run(3, n) == compiled_loop.DONE
    assert loop.failed_step.value == n
    # u_k = k (table row k set before step k... row k+1 moved after it), y_{k+1} = y_k + 0.5 u_k
    expected = np.concatenate([[0.0], np.cumsum(0.5 * np.arange(n))])
    np.testing.assert_array_equal(rec[:, 0], expected)
    calls = []

    def ends(op, status, k):
        calls.append((op, status, k))
        return compiled_loop.STEP_ENDED

    fake = _Fake(at=2, status=2)
    loop, rec, keep = _fake_loop(fake, n, ends)
    assert loop.run(0, n) == compiled_loop.ENDED and loop.failed_step.value == 2 and calls == [(0, 2, 2)]
    assert rec[3, 0] == expected[3] and rec[4, 0] == 0.0  # the ending step completed and recorded, no more

    def fails(op, status, k):
        raise ZeroDivisionError("from the callback")

    fake = _Fake(at=1, status=3)
    loop, rec, keep = _fake_loop(fake, n, fails)
    with pytest.raises(ZeroDivisionError, match="from the callback"):
        loop.run(0, n)
    assert loop.failed_step.value == 1 and loop.failed_op.value == 0 and loop.failed_status.value == 3
