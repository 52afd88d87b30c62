"""Regressors derived symbolically with CasADi: cross-checks with the hand-derived ones."""
from __future__ import annotations

import shutil
import subprocess

import casadi as ca
import numpy as np
import pytest
from rounding import assert_close, final_spread, identifier_spread

from duffid import Duffing1, Duffing2, Record, measure
from duffid.errors import InputError
from duffid.identification.batch import estimate
from duffid.identification.buffered import velocity_signs
from duffid.identification.engine import Integrators, OnlineIdentifier
from duffid.identification.equation import identify_equation
from duffid.models.chain import Chain
from duffid.models.equation import EquationError, derive, parse_equations

DUFFING1 = "m*der(x,2) + b*der(x) + k*x + kp*x^3 = f"
DUFFING2 = ("m1*der(x1,2) + b1*der(x1) + k1*x1 + kp1*x1^3 + b2*(der(x1)-der(x2)) + k2*(x1-x2) "
            "- kp2*(x2-x1)^3 = f1; "
            "b2_m2*(der(x2)-der(x1)) + k2_m2*(x2-x1) + kp2_m2*(x2-x1)^3 = -der(x2,2)")
CHAIN3 = Chain(masses=(2.0, 1.5, 1.0), damping=(3.0, 2.0, 1.5),
               stiffness=({1: 2000.0, 3: -5e5}, {1: 1500.0, 3: 2e5}, {1: 1000.0, 3: 1e5}),
               coulomb=(0.8, 0.5, 0.3))
CHAIN3_TEXT = (
    "m1*der(x1,2) + b1*der(x1) + k1_1*x1 + k1_3*x1^3 + fc1*sign(der(x1)) - b2*(der(x2)-der(x1)) "
    "- k2_1*(x2-x1) - k2_3*(x2-x1)^3 = f1;"
    "b2_m2*(der(x2)-der(x1)) + k2_1_m2*(x2-x1) + k2_3_m2*(x2-x1)^3 + fc2_m2*sign(der(x2)) "
    "- b3_m2*(der(x3)-der(x2)) - k3_1_m2*(x3-x2) - k3_3_m2*(x3-x2)^3 = -der(x2,2);"
    "b3_m3*(der(x3)-der(x2)) + k3_1_m3*(x3-x2) + k3_3_m3*(x3-x2)^3 + fc3_m3*sign(der(x3)) = -der(x3,2)")


def _test_signals(n_dof: int, n: int = 300, dt: float = 1e-3) -> Record:
    """Smooth test signals (not a model's response): sines with several frequencies."""
    t = np.arange(n) * dt
    x = np.stack([0.01 * np.sin((17 + 9 * i) * t + i) + 0.004 * np.cos((41 + 5 * i) * t) + 0.002 * i
                  for i in range(n_dof)], axis=1)
    f = 5.0 + 2.0 * np.sin(30 * t)
    return Record(t=t, f=f, x=x)


def _hand_rows(model, record):
    """The hand-derived rows of eqs. (16)-(17): the paper method's integrators and assembly."""
    ident = OnlineIdentifier(model, record.dt, "paper")
    out = []
    for n, (x, f) in enumerate(zip(record.x, record.f)):
        g = ident._channels.evaluate(np.atleast_1d(x), np.atleast_1d(f))
        tau = n * record.dt
        u = np.concatenate([g, tau * g, tau**2 * g])
        rows = []
        for st, (integ, _) in zip(ident._states, ident._paper):
            y = integ.push(u)
            rows.append(st.assembly(ident._paper_rows(y, len(st.equation.unknowns))))
        out.append(rows)
    return out


def _derived_rows(regressor, record):
    sgn = velocity_signs(record.x)
    bank = Integrators(len(regressor.bank), regressor.depth, record.dt, "adams3")
    out = []
    for n in range(record.n_samples):
        u = np.asarray(regressor.bank_function(record.x[n], record.f[n], record.t[n], sgn[n], n * record.dt))
        out.append(regressor.rows(bank.push(u.ravel())))
    return out


@pytest.mark.parametrize("model, text", [(Duffing1(), DUFFING1), (Duffing2(), DUFFING2), (CHAIN3, CHAIN3_TEXT)],
                         ids=["duffing1", "duffing2", "chain3-coulomb"])
def test_derived_regressors_equal_the_hand_derived_ones(model, text):
    record = _test_signals(model.n_dof)
    regressor = derive(text, record.column_names)
    assert [len(u) for u in regressor.unknowns] == [len(eq.unknowns) for eq in model.equations()]
    hand, derived = _hand_rows(model, record), _derived_rows(regressor, record)
    for e in range(model.n_dof):
        A_hand = np.array([h[e][0] for h in hand])
        A_sym = np.array([d[e][0] for d in derived])
        D_hand = np.array([h[e][1] for h in hand])
        D_sym = np.array([d[e][1] for d in derived])
        scale = np.abs(A_hand).max(axis=(0, 1))  # per unknown, over all samples and rows
        assert np.all(np.abs(A_sym - A_hand) <= 1e-12 * scale)
        assert np.all(np.abs(D_sym - D_hand) <= 1e-12 * np.abs(D_hand).max())


def test_identify_equation_paper_matches_identify(case_b_exact):
    record = measure(case_b_exact, snr_db=40, seed=2).slice(0.0, 1.0)
    by_text = identify_equation(record, DUFFING1, "paper", check=False)
    by_model = estimate(record, Duffing1(), "paper")
    assert by_text.model == "equation" and by_text.method == "paper"
    # two derivations of the same numbers: equal at a multiple of the one-ulp spread
    # (tests/rounding.py; ~1e-12 relative here) where the system is not singular to rounding
    spread = identifier_spread(Duffing1(), record, "paper")
    spread.assert_history(by_text.history, by_model.history, rows=by_model.condition <= 1e8)
    assert by_text.t_identified == by_model.t_identified
    data = by_text.to_dict()
    assert set(data) == set(by_model.to_dict()) and set(data["parameters"]) == {"m", "b", "k", "kp"}


def test_identify_equation_paper_matches_identify_on_the_coulomb_chain():
    record = _test_signals(3, n=400)  # any signals: both sides must compute the same numbers
    by_text = identify_equation(record, CHAIN3_TEXT, "paper", check=False).parameters
    p = estimate(record, CHAIN3, "paper").parameters
    tol = dict(zip(CHAIN3.parameters, identifier_spread(CHAIN3, record, "paper").final_tolerance()))
    names = ("m1", "b1", "k1_1", "k1_3", "fc1", "b2", "k2_1", "k2_3")
    assert_close(by_text, {k: p[k] for k in names}, tol)
    assert_close(by_text, {"k2_1_m2": p["k2_1"] / p["m2"]}, {"k2_1_m2": tol["k2_1"] + tol["m2"]})


def test_identify_equation_two_dof_paper_gives_the_ratios(two_dof_exact):
    by_text = identify_equation(two_dof_exact, DUFFING2, "paper", check=False).parameters
    p = estimate(two_dof_exact, Duffing2(), "paper").parameters
    # at a multiple of the one-ulp spread (tests/rounding.py): kp2 carries ~1e-6 of the force
    # balance (sub-millimetre deflection cubed), its spread is ~1e-10, the others' ~1e-12
    tol = dict(zip(Duffing2().parameters, identifier_spread(Duffing2(), two_dof_exact, "paper").final_tolerance()))
    assert_close(by_text, {k: p[k] for k in ("m1", "b1", "k1", "kp1", "b2", "k2", "kp2")}, tol)
    # identify() reports m2 = k2 / (k2/m2), with k2 from the first equation: k2/m2 round-trips
    assert_close(by_text, {"k2_m2": p["k2"] / p["m2"]}, {"k2_m2": tol["k2"] + tol["m2"]})


@pytest.mark.parametrize("method", ["legendre", "block-pulse"])
def test_identify_equation_buffered_matches_identify(case_a, method):
    by_text = identify_equation(case_a, DUFFING1, method, check=False)
    by_model = estimate(case_a, Duffing1(), method)
    tol = final_spread(lambda rec: estimate(rec, Duffing1(), method).parameters, case_a)
    assert_close(by_text.parameters, by_model.parameters, tol)
    assert by_text.method == method and by_text.options["equation"] == DUFFING1


def test_joint_equations_identify_the_unforced_mass(two_dof_exact):
    text = ("m1*der(x1,2) + b1*der(x1) + k1*x1 + kp1*x1^3 + b2*(der(x1)-der(x2)) + k2*(x1-x2) "
            "- kp2*(x2-x1)^3 = f1; m2*der(x2,2) + b2*(der(x2)-der(x1)) + k2*(x2-x1) + kp2*(x2-x1)^3 = 0")
    result = identify_equation(two_dof_exact, text, "legendre", check=False, window=0.5)
    for name, value in Duffing2().parameters.items():
        assert result.parameters[name] == pytest.approx(value, rel=5e-4)
    with pytest.raises(InputError, match="paper method solves each equation alone"):
        identify_equation(two_dof_exact, text, "paper", check=False)
    with pytest.raises(EquationError, match="scale is free"):
        identify_equation(two_dof_exact, "m2*der(x2,2) + b2*(der(x2)-der(x1)) + k2*(x2-x1) = 0; "
                                         "m1*der(x1,2) + k1*x1 = f1", "paper")


def test_polynomial_times_velocity_is_integrated_by_parts_exactly():
    regressor = derive("m*der(x,2) + b*der(x) + c*x^2*der(x) + k*x + kp*x^3 = f")
    assert regressor.parameters == ("m", "b", "c", "k", "kp")
    assert "G = 0.333333*x^3" in regressor.channels
    G = regressor.channel_function(0.2, 1.0, 0.0, 1.0)
    assert float(G[regressor.channels.index("G = 0.333333*x^3")]) == pytest.approx(0.2**3 / 3, rel=1e-15)
    labels = {b.input_label for b in regressor.bank}
    assert {"x", "tau*(x)", "tau^2*(x)", "tau^2*(f)", "tau^2*(x^3)", "tau*(G = 0.333333*x^3)"} <= labels
    # identification with the extra term finds c = 0 on the Duffing plant
    record = _duffing_record()
    result = identify_equation(record, "m*der(x,2) + b*der(x) + c*x^2*der(x) + k*x + kp*x^3 = f", "legendre",
                               check=False)
    assert abs(result.parameters["c"]) * 0.01**2 < 1e-3 * Duffing1().parameters["b"]
    assert result.parameters["m"] == pytest.approx(2.53, rel=1e-4)


def _duffing_record():
    from duffid import Step, simulate
    return simulate(Duffing1(), Step(10.0), 0.25, 1e-3)


@pytest.mark.parametrize("text, message", [
    ("m*x*der(x,2) + k*x = f", "der\\(x,2\\) may only be multiplied.*'m\\*x\\*der\\(x,2\\)'"),
    ("m*der(x,2) + b*der(x)^2 + k*x = f", "polynomial in the displacements.*'b\\*der\\(x\\)\\^2'"),
    ("m*der(x,2) + b*abs(der(x)) + k*x = f", "'b\\*abs\\(der\\(x\\)\\)'"),
    ("m*der(x,2) + b*sin(t)*der(x) + k*x = f", "'b\\*sin\\(t\\)\\*der\\(x\\)'"),
    ("m*der(x,2) + m*k*x = f", "not linear.*'m\\*k\\*x'"),
    ("m*der(x,2) + k*der(f) = x", "der\\(\\) applies to a displacement column"),
    ("m*der(x,3) + k*x = f", "order must be 1 or 2"),
    ("m*der(x,2) + k*tanh(x) = f", "unknown function 'tanh'"),
    ("m*der(x,2) + k*x = f; __import__('os')", "unexpected character"),
    ("m*der(x,2) + k*x", "expected '='"),
    ("m*der(x,2) + (k*x = f", "expected '\\)'"),
    ("m*der(x,2) + k*x - k*x = f", "parameter 'k' has no effect"),
    ("m*der(x,2) + k*x1 = f", "'x1' is not a column: columns are t, f, x;"),
    ("m*der(x,2) + k*x = F", "'F' is not a column: columns are t, f, x \\(names are case-sensitive: did you mean 'f'"),
])
def test_bad_equations_are_rejected_with_the_term_named(text, message):
    with pytest.raises(EquationError, match=message):
        derive(text)


def test_non_gradient_velocity_factors_are_rejected():
    with pytest.raises(EquationError, match="not the gradient.*'c\\*x1\\*der\\(x2\\)'"):
        derive("m*der(x1,2) + c*x1*der(x2) + k*x1 = f1", ["t", "f1", "x1", "x2"])
    # the same term plus its partner is d/dt (x1 x2): accepted
    derive("m*der(x1,2) + c*(x1*der(x2) + x2*der(x1)) + k*x1 = f1", ["t", "f1", "x1", "x2"])


def test_identify_equation_errors(case_a):
    with pytest.raises(ValueError, match="unknown method 'newton'"):
        identify_equation(case_a, DUFFING1, "newton")
    with pytest.raises(TypeError, match="no option.*gama"):
        identify_equation(case_a, DUFFING1, gama=1.0)
    with pytest.raises(EquationError, match="no term without a parameter"):
        identify_equation(case_a, "m*der(x,2) + k*x = 0")
    with pytest.raises(EquationError, match="der\\(\\) applies to a displacement column \\(x\\)"):
        identify_equation(case_a, "m*der(x1,2) = f")


def test_parse_equations_gives_casadi_residuals():
    residuals, params, signals = parse_equations("m*der(x,2) + k*x = 2*f", ["t", "f", "x"])
    m, k = params[0]
    value = ca.Function("r", [m, k, signals.ddx[0], signals.x[0], signals.f[0]], [residuals[0]])
    assert float(value(2.0, 3.0, 0.5, 0.1, 4.0)) == pytest.approx(2 * 0.5 + 3 * 0.1 - 8.0)


@pytest.mark.skipif(shutil.which("gcc") is None, reason="needs gcc")
def test_generated_c_evaluates_the_same_rows(tmp_path):
    regressor = derive(DUFFING2, ["t", "f1", "x1", "x2"])
    source = regressor.generate_c(tmp_path)
    library = tmp_path / "libregressor.so"
    subprocess.run(["gcc", "-shared", "-fPIC", "-O2", "-o", str(library), str(source)], check=True)
    rng = np.random.default_rng(0)
    Y = rng.normal(size=(regressor.depth + 1, len(regressor.bank)))
    compiled = ca.external("duffid_rows", str(library))
    for a, b in zip(compiled(Y), regressor.rows_function(Y)):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-14, atol=1e-14)
    channels = ca.external("duffid_channels", str(library))
    args = ([0.01, 0.02], [3.0], 0.5, [1.0, -1.0])
    np.testing.assert_allclose(np.asarray(channels(*args)), np.asarray(regressor.channel_function(*args)),
                               rtol=1e-15)
