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
