"""Shared fixtures: simulated records of the paper's cases (cached per session)."""
from __future__ import annotations

import pytest

from duffid import Duffing1, Duffing2, Step, measure, simulate


@pytest.fixture(scope="session")
def case_a_exact():
    """Paper case A: 1-DOF, 14 N step, 0.25 s, 1 ms, noise-free."""
    return simulate(Duffing1(), Step(14.0), 0.25, 1e-3)


@pytest.fixture(scope="session")
def case_a(case_a_exact):
    """Case A quantised by the paper's encoder."""
    return measure(case_a_exact)


@pytest.fixture(scope="session")
def case_b_exact():
    """Case B: 1-DOF, 10 N step, 2 s, 1 ms, noise-free (noise added per test)."""
    return simulate(Duffing1(), Step(10.0), 2.0, 1e-3)


@pytest.fixture(scope="session")
def two_dof_exact():
    """2-DOF chain of Table 3 (m1 2.53, b1 5, b2 4), 6 N step on DOF 1, 1 s, noise-free."""
    return simulate(Duffing2(), Step(6.0), 1.0, 1e-3)


@pytest.fixture(scope="session")
def loop_fmus(tmp_path_factory):
    """The FMUs of the closed loops (duffid.control.closed_loop.ensure_fmus), built once."""
    from duffid.control.closed_loop import ensure_fmus

    return ensure_fmus(tmp_path_factory.mktemp("loop_fmus"))


@pytest.fixture
def freed(monkeypatch):
    """Names of the instances whose freeInstance was called (FMI 2 and 3)."""
    from fmpy.fmi2 import FMU2Slave
    from fmpy.fmi3 import FMU3Slave

    names: list[str] = []
    for cls in (FMU2Slave, FMU3Slave):
        def tracking(self, real=cls.freeInstance):
            names.append(self.instanceName)
            return real(self)

        monkeypatch.setattr(cls, "freeInstance", tracking)
    return names
