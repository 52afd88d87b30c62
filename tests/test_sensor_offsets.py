"""Sensor offsets (issue 13 item 6): a displacement-sensor offset x0 (x_meas = x + x0) and a
force bias are identified on request (``offsets=`` / ``--offset KIND``), reported with their
standard errors, and x0 is never published when the record cannot separate it from a force
bias (a linear plant)."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from duffid import Chain, Duffing1, Duffing2, DuffingCircuit, Multisine, Record, identify, measure, simulate
from duffid.cli import build_parser, main
from duffid.identification.trust import DISPLACEMENT_OFFSET, OFFSETS, displacement_offset_values, term_shares

#: A hardening plant of another scale than the paper's (12.6 Hz, 0.4 kg).
PLANT = Duffing1(m=0.4, b=1.5, k=2.5e3, kp=4e7)
X0 = 2.5e-4   # displacement sensor offset [m]
BIAS = 0.3    # force sensor bias [N]: the sensor reads f + BIAS (c1 = +BIAS)


def _record(plant, *, seed=3):
    """1 s at 1 kHz under a random multisine (1-20 Hz, 4 N), 50 dB noise; and the exact one."""
    exact = simulate(plant, Multisine(4.0, 1.0, 20.0, 0.5, phases="random", seed=seed), 1.0, 1e-3)
    return exact, measure(exact, pulses_per_cm=None, snr_db=50, seed=seed + 10)


@pytest.fixture(scope="module")
def records():
    exact, measured = _record(PLANT)
    return exact, measured, Record(measured.t, measured.f, measured.x + X0, source="x0.csv")


@pytest.fixture(scope="module")
def with_x0(records):
    return identify(records[2], Duffing1(), offsets="displacement")


def _within(result, truth, tolerance):
    """Each value published, within ``tolerance`` and within 3 stated standard errors."""
    a = result.assessment
    for name, value in truth.items():
        assert a.status[name] == "published", (name, a.status, a.notes)
        error = abs(result.parameters[name] - value)
        assert error <= tolerance * abs(value), (name, result.parameters[name], value)
        assert error <= 3 * a.uncertainty[name] * abs(result.parameters[name]), (name, a.uncertainty[name])


def test_the_test_plant_is_visibly_nonlinear(records):
    exact = records[0]
    share = term_shares(PLANT, PLANT.canonical_parameters(), exact.x, exact.f, exact.dt)["k1_3"]
    assert share > 0.05


def test_mapping_back_from_the_measured_coordinate():
    """a3 = kp, a2 = -3 kp x0, a1 = k + 3 kp x0^2, a0 = c1 - k x0 - kp x0^3, inverted exactly."""
    m, b, k, kp, x0, c = 0.4, 1.5, 2.5e3, 4e7, 2.5e-4, 0.3
    extended = {"m1": m, "b1": b, "k1_1": k + 3 * kp * x0**2, "k1_2": -3 * kp * x0, "k1_3": kp,
                "c1": c - k * x0 - kp * x0**3}
    got = displacement_offset_values(Duffing1(offset=True), extended)
    assert list(got) == ["m", "b", "k", "kp", "c1", DISPLACEMENT_OFFSET]
    for name, value in {"m": m, "b": b, "k": k, "kp": kp, "c1": c, "x0": x0}.items():
        assert got[name] == pytest.approx(value, rel=1e-12), name
    circuit = displacement_offset_values(DuffingCircuit(offset=True), extended)  # q_meas = q + q0
    assert circuit["C"] == pytest.approx(1 / k, rel=1e-12) and circuit["a"] == kp and circuit["x0"] == pytest.approx(x0)
    undefined = displacement_offset_values(Duffing1(offset=True), {**extended, "k1_3": 0.0})
    assert all(math.isnan(v) for v in undefined.values())


def test_by_default_a_displacement_offset_publishes_nothing(records):
    result = identify(records[2], Duffing1())
    assert all(math.isnan(v) for v in result.parameters.values()) and not result.is_identified
    notes = " ".join(result.assessment.notes)
    assert "does not reproduce the record" in notes and "sensor offsets (--offset)" in notes


def test_displacement_offset_identified_with_the_physical_values(with_x0):
    result = with_x0
    assert result.model == "duffing1"
    assert list(result.parameters) == ["m", "b", "k", "kp", "x0"]  # the force bias is not a parameter here
    _within(result, PLANT.parameters, 0.01)
    _within(result, {"x0": X0}, 0.03)
    assert result.is_identified
    offsets = result.assessment.fit["offsets"]
    assert offsets["x0"]["value"] == result.parameters["x0"] and offsets["x0"]["status"] == "published"
    assert offsets["x0"]["standard_error"] == pytest.approx(result.assessment.uncertainty["x0"] * X0, rel=0.05)
    # no force bias in this record: the constant force found is zero within its standard error
    assert abs(offsets["c1"]["value"]) <= 3 * offsets["c1"]["standard_error"]
    assert not any("also shows a constant force" in n for n in result.assessment.notes)
    data = json.loads(result.to_json())
    assert data["parameters"]["x0"] == result.parameters["x0"] and data["status"]["x0"] == "published"
    assert data["fit"]["offsets"]["x0"]["standard_error"] > 0
    assert len(result.history["x0"]) == len(result.t)


@pytest.fixture(scope="module")
def biased_both(records):
    measured = records[1]
    return Record(measured.t, measured.f + BIAS, measured.x + X0)


def test_force_bias_and_displacement_offset_together(biased_both):
    result = identify(biased_both, Duffing1(), offsets="both")
    assert list(result.parameters) == ["m", "b", "k", "kp", "c1", "x0"]
    _within(result, PLANT.parameters, 0.01)
    _within(result, {"x0": X0, "c1": BIAS}, 0.03)


def test_a_force_bias_found_with_offset_displacement_is_said(biased_both):
    shown = identify(biased_both, Duffing1(), offsets="displacement")  # estimated and said, not listed
    assert "c1" not in shown.parameters and shown.assessment.status["x0"] == "published"
    _within(shown, PLANT.parameters, 0.01)
    c1 = shown.assessment.fit["offsets"]["c1"]["value"]
    assert c1 == pytest.approx(BIAS, rel=0.03)
    assert any(f"also shows a constant force c1 = {c1:.4g}" in n for n in shown.assessment.notes)


def test_a_zero_offset_is_published_as_zero(records):
    """No offset in the record: x0 is zero within its standard error, which is small against
    the motion, so it is published (a relative error of a zero means nothing)."""
    result = identify(records[1], Duffing1(), offsets="displacement")
    _within(result, PLANT.parameters, 0.01)
    x0 = result.assessment.fit["offsets"]["x0"]
    assert x0["status"] == "published" and abs(x0["value"]) <= 3 * x0["standard_error"]
    assert x0["standard_error"] <= 0.01 * np.std(records[1].x)


def test_a_bare_force_offset_does_not_publish_values_a_displacement_offset_moves(records):
    result = identify(records[2], Duffing1(), offsets="force")
    a = result.assessment
    assert not result.is_identified
    assert any("identify with --offset displacement" in n for n in a.notes)
    for name, value in PLANT.parameters.items():  # what is published is right
        if a.status[name] == "published":
            assert abs(result.parameters[name] - value) <= 0.01 * value


def test_a_linear_plant_cannot_separate_x0_from_a_force_bias():
    plant = Duffing1(m=0.4, b=1.5, k=2.5e3, kp=0.0)
    _, measured = _record(plant)
    record = Record(measured.t, measured.f, measured.x + X0)
    for kind in ("displacement", "both"):
        result = identify(record, Duffing1(), offsets=kind)
        a = result.assessment
        assert math.isnan(result.parameters["x0"]) and a.status["x0"] == "not excited"
        assert any("x0 is not published" in n and "cannot separate the two" in n and "combined constant force c1" in n
                   for n in a.notes), a.notes
        _within(result, {"m": 0.4, "b": 1.5, "k": 2.5e3}, 0.01)
        # the combined constant force: c1 = bias - k x0 = -k x0 here
        assert a.fit["offsets"]["c1"]["value"] == pytest.approx(-2.5e3 * X0, rel=0.01)
        assert ("c1" in result.parameters) == (kind == "both")


def test_the_circuit_maps_onto_the_same_chain():
    """L q'' + R q' + q/C + a q^3 = u with a charge offset q0 (the x column): C = 1/k."""
    plant = DuffingCircuit()
    exact = simulate(plant, Multisine(10.0, 1.0, 20.0, 0.3, phases="random", seed=2), 0.6, 5e-4)
    measured = measure(exact, pulses_per_cm=None, snr_db=50, seed=1)
    result = identify(Record(measured.t, measured.f, measured.x + 5e-4), DuffingCircuit(), offsets="displacement")
    assert list(result.parameters) == ["L", "R", "C", "a", "x0"]
    _within(result, plant.parameters, 0.01)
    _within(result, {"x0": 5e-4}, 0.03)


def test_models_that_cannot_carry_a_displacement_offset_say_so(records):
    with pytest.raises(ValueError, match="one-DOF models with a linear and a cubic spring"):
        identify(records[2], Duffing2(), offsets="displacement")
    chain = Chain(masses=(1.0,), damping=(1.0,), stiffness=({1: 1.0, 2: 0.0, 3: 1.0},), orders=(1, 2, 3))
    with pytest.raises(ValueError, match="use --offset force"):
        identify(records[2], chain, offsets="both")
    with pytest.raises(ValueError, match="offsets must be one of force, displacement, both"):
        identify(records[2], Duffing1(), offsets="x")


def test_cli_offset_flag():
    parser = build_parser()
    assert parser.parse_args(["identify", "r.csv", "--offset"]).offset == "force"  # as before
    assert parser.parse_args(["identify", "r.csv"]).offset is None
    assert parser.parse_args(["identify", "r.csv", "--offset", "both"]).offset == "both"
    assert tuple(OFFSETS) == ("force", "displacement", "both")
    assert main(["simulate", "--offset", "displacement", "-o", "never.csv"]) == 2


@pytest.fixture(scope="module")
def csv_file(tmp_path_factory, records):
    path = tmp_path_factory.mktemp("offsets") / "rec.csv"
    records[2].to_csv(path)
    return path


def test_cli_a_bare_offset_before_the_file_still_means_a_force_bias(csv_file, capsys):
    assert main(["identify", "--offset", str(csv_file), "--model", "duffing1", "--method", "paper"]) == 0
    out = capsys.readouterr().out
    assert "      c1 " in out and "x0" not in out.split("offsets")[0]


def test_cli_refuses_x0_for_a_two_dof_model(csv_file, capsys):
    assert main(["identify", str(csv_file), "--model", "duffing2", "--offset", "displacement"]) == 2
    assert "one-DOF models with a linear and a cubic spring" in capsys.readouterr().err


@pytest.fixture(scope="module")
def cli_json(csv_file):
    import contextlib
    import io

    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["identify", str(csv_file), "--model", "duffing1", "--offset", "displacement", "--json"]) == 0
    return json.loads(out.getvalue())


def test_cli_json_reports_x0(cli_json):
    x0 = cli_json["parameters"]["x0"]
    assert cli_json["status"]["x0"] == "published" and abs(x0 - X0) <= 0.03 * X0
    assert cli_json["identified"] is True and "c1" not in cli_json["parameters"]
    assert cli_json["fit"]["offsets"]["x0"]["value"] == x0


def test_cli_text_says_what_the_json_says(csv_file, cli_json, capsys):
    assert main(["identify", str(csv_file), "--model", "duffing1", "--offset", "displacement"]) == 0
    text = capsys.readouterr().out
    assert "identified: yes" in text
    x0 = cli_json["parameters"]["x0"]
    row = next(line.split() for line in text.splitlines() if line.split()[:1] == ["x0"])
    assert float(row[1]) == pytest.approx(x0, rel=1e-5) and row[2] == "published"
    error = cli_json["fit"]["offsets"]["x0"]["standard_error"]
    assert "offsets (what the sensors read at zero force and displacement)" in text
    assert f"x0 = {x0:.6g} (standard error {error:.2g}) published" in text
    c1 = cli_json["fit"]["offsets"]["c1"]
    assert f"c1 = {c1['value']:.6g} (standard error {c1['standard_error']:.2g}) {c1['status']}" in text


def test_a_small_displacement_offset_by_default_leaves_no_value_beyond_its_errors():
    """An offset of 2 % of the displacement's RMS, whose simulation misses the record by about
    2.5 % (8 times the noise, inside SIMULATION_TOLERANCE): the algebraic m and k were 0.6-1 %
    off at 24-53 stated errors. The output-error cross-check fits the sensor's offset, names it
    and gives every value the difference from its own as the stated error."""
    m, fn, zeta = 1.0, 20.0, 0.1
    k = m * (2 * np.pi * fn) ** 2
    plant = Duffing1(m=m, b=2 * zeta * np.sqrt(k * m), k=k, kp=7.4e7)
    exact = simulate(plant, Multisine(20.0, 2.0, 30.0, 4.0, phases="random", seed=1), 4.0, 1 / 600)
    measured = measure(exact, pulses_per_cm=None, snr_db=50, seed=11)
    offset = 0.02 * float(np.sqrt(np.mean(exact.x**2)))
    result = identify(Record(measured.t, measured.f, measured.x + offset, source="offset.csv"), Duffing1())
    a, truth = result.assessment, plant.parameters
    assert any(s == "published" for s in a.status.values()), a.notes
    for name, value in result.parameters.items():
        if math.isfinite(value):
            assert abs(value - truth[name]) <= 3 * a.uncertainty[name] * abs(value), (name, value, truth[name], a.uncertainty)
    notes = " ".join(a.notes)
    assert "displacement-sensor offset" in notes and "--offset displacement" in notes, notes
