"""``duffid discover``: the terms a record asks for, on records of an independent simulator
(benchmarks/discover.py: scipy's DOP853, not duffid's), the CLI and its JSON, bad input, and
the Silverbox record when ../shared holds it."""
from __future__ import annotations

import json
import math

import pytest

from duffid.cli import main
from duffid.errors import InputError
from duffid.identification.discover import (
    NOISE_FIT,
    TERM_NAMES,
    discover,
    residual_shape,
)
from duffid.identification.equation import identify_equation
from duffid.models.equation_model import EquationModel

from benchmark_modules import load_benchmark

bench = load_benchmark("discover")

BASE_TEXT = "m*der(x,2) + b*der(x) + k*x + kp*x^3 = f"


def record_with(*terms: str, snr: float = 50.0, seed: int = 1, duration: float = 10.0):
    return bench.simulate_record(tuple(terms), snr, seed=seed, duration=duration)


@pytest.fixture(scope="module")
def plain():
    return record_with()


@pytest.fixture(scope="module")
def quadratic():
    return record_with("x^2")


def truth_of(terms: tuple[str, ...]) -> dict[str, float]:
    return dict(bench.BASE) | {TERM_NAMES[t]: bench.TERMS[t][0] for t in terms}


def test_plain_record_gets_nothing(plain):
    found = discover(plain, "duffing1", progress=False)
    assert found.best.added == ()
    assert found.best.explained
    assert found.best.identification.assessment.identified
    assert "nothing to add" in found.notes[0]
    assert found.residual is None
    assert [c.verdict for c in found.candidates] == ["base"]


def test_quadratic_stiffness_is_found_with_its_value(quadratic):
    found = discover(quadratic, BASE_TEXT, progress=False)
    assert found.best.added == ("x^2",)
    result = found.best.identification
    truth = truth_of(("x^2",))
    for name, value in result.parameters.items():
        assert result.assessment.status[name] == "published"
        stated = result.assessment.uncertainty[name]
        assert abs(value / truth[name] - 1) <= max(4 * stated, 1e-3), name  # within its stated error
    assert found.best.fit["simulation_nrmse"] <= NOISE_FIT * found.best.fit["noise_nrmse"]
    assert found.candidates[0].verdict == "base" and found.candidates[-1].verdict == "accepted"
    # the screening ranked it first, far ahead
    first = found.screening[0][1]
    assert first[0][0] == "x^2" and first[0][1] < 0.1
    assert any("x^3: already in the base" in note for note in found.notes)


def test_chosen_equation_feeds_identify_unchanged(quadratic):
    found = discover(quadratic, "duffing1", progress=False)
    again = identify_equation(quadratic, found.best.equation, refine=False)
    assert again.parameters == pytest.approx(found.best.identification.parameters, rel=1e-12)


@pytest.mark.parametrize("terms", [("sign(der(x))",), ("x^2*der(x)",)])
def test_velocity_terms_are_found(terms):
    found = discover(record_with(*terms), "duffing1", progress=False)
    assert set(found.best.added) == set(terms)


def test_user_library_and_its_errors(quadratic):
    found = discover(quadratic, "duffing1", library=("x^4", "x^2"), progress=False)
    assert found.best.added == ("x^2",)
    assert found.best.coefficients == ("k2",)
    with pytest.raises(InputError, match=r"abs\(der\(x\)\)\*der\(x\).*cannot be identified"):
        discover(quadratic, "duffing1", library=("abs(der(x))*der(x)",), progress=False)
    with pytest.raises(InputError, match="empty term"):
        discover(quadratic, "duffing1", library=("x^2", " "), progress=False)


def test_residual_shape_names_what_is_missing():
    """A friction loop, an asymmetric spring and a stiffness that changed halfway, described
    from the base plant's values; nothing on a record the base describes."""
    from duffid import Duffing1, Multisine, measure, simulate

    model = EquationModel(BASE_TEXT)
    base = dict(bench.BASE)
    loop = residual_shape(record_with("sign(der(x))"), model, base)
    assert loop["shape"] == "hysteresis" and loop["explained"] > 0.5
    assert "direction of motion" in loop["words"]
    asymmetric = residual_shape(record_with("x^2"), model, base)
    assert asymmetric["shape"] == "asymmetry" and asymmetric["explained"] > 0.5
    nothing = residual_shape(record_with(), model, base)
    assert nothing["shape"] == "unstructured"
    assert len(nothing["x"]) == len(nothing["residual"]) <= 4000
    plant = Duffing1()
    stiffer = Duffing1(**(plant.parameters | {"k": 1.1 * plant.parameters["k"]}))
    drifted = measure(simulate(plant, Multisine(8.0, 0.5, 10.0, 20.0, phases="random", seed=1), t_end=20.0,
                               dt=1e-3, changes=[(10.0, stiffer)]), snr_db=50, seed=2)
    changed = residual_shape(drifted, EquationModel(BASE_TEXT), plant.parameters)
    assert changed["shape"] == "time variation"


def test_cli_json_and_table(tmp_path, quadratic, capsys):
    path = tmp_path / "rig.csv"
    quadratic.to_csv(path)
    plot = tmp_path / "residual.png"
    assert main(["discover", str(path), "--json", "--plot", str(plot)]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out) >= {"base", "best", "candidates", "notes", "screening"}
    assert out["base"] == BASE_TEXT.replace("der(x,2)", "der(x,2)")
    best = out["best"]
    assert best["added"] == ["x^2"]
    assert set(best) >= {"equation", "added", "fit", "parameters", "status", "uncertainty", "units"}
    assert best["units"]["k2"] == "N/m2" and best["units"]["kp"] == "N/m3"
    assert all(best["status"][k] == "published" for k in best["parameters"])
    assert plot.stat().st_size > 10_000
    assert main(["discover", str(path), "--base", BASE_TEXT, "--library", "default; x^4"]) == 0
    text = capsys.readouterr().out
    assert "best: m*der(x,2) + b*der(x) + k*x + kp*x^3 + k2*x^2 = f" in text
    assert "x^4" in text  # screened
    assert "units (the record's in SI, m and N): m kg, b N.s/m, k N/m, kp N/m3, k2 N/m2" in text
    assert main(["discover", str(path), "--library", "abs(der(x))*der(x)"]) == 2
    assert "abs(der(x))*der(x)" in capsys.readouterr().err


def test_max_terms_zero_only_checks_the_base(quadratic):
    found = discover(quadratic, "duffing1", max_terms=0, progress=False)
    assert found.best.added == ()
    assert found.residual is not None and found.residual["shape"] == "asymmetry"
    with pytest.raises(InputError, match="--max-terms"):
        discover(quadratic, "duffing1", max_terms=-1)


def test_two_dof_base_places_terms_per_equation():
    from duffid import Duffing2, Multisine, measure, simulate

    record = measure(simulate(Duffing2(), Multisine(5.0, 0.5, 12.0, 10.0, phases="random", seed=1), t_end=10.0,
                              dt=1e-3), snr_db=50, seed=1)
    found = discover(record, "duffing2", progress=False)
    assert found.best.added == ()
    labels = [term for term, _ in found.screening[0][1]]
    assert "x2^2" in labels and "1 (equation 2)" in labels and "1 (equation 1)" in labels


@pytest.mark.slow
def test_two_dof_chain_missing_a_quadratic_spring_on_the_first_mass():
    from duffid import Duffing2, Multisine, measure, simulate

    text = Duffing2().equation_text().replace("kp1*x1^3", "kp1*x1^3 + q*x1^2", 1)
    plant = EquationModel(text, ("t", "f1", "x1", "x2"), values=Duffing2().parameters | {"q": -4e4})
    record = measure(simulate(plant, Multisine(5.0, 0.5, 12.0, 20.0, phases="random", seed=1), t_end=20.0,
                              dt=1e-3), snr_db=50, seed=1)
    found = discover(record, "duffing2", progress=False)
    assert found.best.added == ("x1^2",) and found.best.coefficients == ("k2_eq1",)
    value = found.best.identification.parameters["k2_eq1"]
    assert value == pytest.approx(-4e4, rel=5 * found.best.identification.assessment.uncertainty["k2_eq1"])


@pytest.mark.slow
@pytest.mark.parametrize("snr", [40.0, 60.0])
@pytest.mark.parametrize("terms", [(), ("x^2",), ("x^5",), ("abs(x)*x",), ("x^2*der(x)",), ("sign(der(x))",),
                                   ("1",), ("x^2", "sign(der(x))"), ("x^5", "x^2*der(x)")])
def test_every_term_alone_and_in_pairs(terms, snr):
    found = discover(record_with(*terms, snr=snr, duration=20.0), "duffing1", progress=False)
    assert set(found.best.added) == set(terms), [c.verdict for c in found.candidates]


@pytest.mark.slow
def test_silverbox_finds_its_offset_and_says_why_not_the_quadratic():
    from duffid.analysis.silverbox import default_data_dir, load_silverbox

    if not (default_data_dir() / "SNLS80mV.mat").is_file():
        pytest.skip("the Silverbox data are not beside the repository")
    found = discover(load_silverbox().training, "duffing1", progress=False)
    assert found.best.added == ("1",)
    # the quadratic term screens second at the first step
    assert [term for term, _ in found.screening[0][1]][:2] == ["1", "x^2"]
    assert math.isfinite(found.best.fit["simulation_nrmse"])


@pytest.mark.slow
def test_refine_publishes_what_the_algebraic_estimate_left_undetermined():
    record = record_with("sign(der(x))", duration=20.0)
    plain = discover(record, "duffing1", progress=False)
    refined = discover(record, "duffing1", refine=True, progress=False)
    assert refined.best.added == plain.best.added == ("sign(der(x))",)
    published = [k for k, s in refined.best.identification.assessment.status.items() if s == "published"]
    before = [k for k, s in plain.best.identification.assessment.status.items() if s == "published"]
    assert set(before) <= set(published)
    if set(before) != set(plain.best.identification.parameters):
        assert any("refines them by output error" in note for note in plain.notes)


def test_base_of_another_size_is_refused(quadratic):
    with pytest.raises(InputError, match="the base duffing2 has 2 masses, the record 1 displacement"):
        discover(quadratic, "duffing2", progress=False)


@pytest.mark.slow
def test_hysteresis_outside_the_library_adds_no_term():
    """A Bouc-Wen element: no library term describes it; none is taken, and the notes say so."""
    found = discover(bench.bouc_wen_record(), "duffing1", progress=False)
    assert found.best.added == ()
    assert found.residual is not None
    assert any("no library term is supported" in note for note in found.notes)


def test_displacement_offset_shows_as_quadratic_and_constant_with_its_size():
    from duffid import Record

    record = record_with()
    shifted = Record(record.t, record.f, record.x + 0.002, source="a displacement sensor 2 mm off")
    found = discover(shifted, "duffing1", progress=False)
    assert set(found.best.added) == {"x^2", "1"}
    note = next(n for n in found.notes if "displacement-sensor offset" in n)
    implied = float(note.split("(3 kp) = ")[1].split(" m")[0])
    assert implied == pytest.approx(0.002, rel=0.02)


def test_a_record_too_short_to_screen_says_so_and_its_json_is_strict():
    found = discover(record_with("x^2", duration=0.3), "duffing1", progress=False)
    assert found.best.added == ()
    assert any("too short to screen terms" in note for note in found.notes)
    json.loads(json.dumps(found.to_dict(), allow_nan=False))
