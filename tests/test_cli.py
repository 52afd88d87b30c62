"""The ``duffid`` command line."""
from __future__ import annotations

import json

import numpy as np
import pytest

from duffid import Duffing1
from duffid.cli import main


def _run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def case_a_csv(tmp_path_factory, request):
    case_a = request.getfixturevalue("case_a")
    path = tmp_path_factory.mktemp("cli") / "case_a.csv"
    case_a.to_csv(path)
    return path


def test_identify_json_shape(capsys, case_a_csv):
    code, out, _ = _run(capsys, "identify", str(case_a_csv), "--model", "duffing1", "--json")
    assert code == 0
    data = json.loads(out)
    assert data["model"] == "duffing1" and data["method"] == "robust"
    assert set(data["parameters"]) == {"m", "b", "k", "kp"}
    assert data["t_identified"] > 0
    for name, value in Duffing1().parameters.items():
        assert data["parameters"][name] == pytest.approx(value, rel=2e-3)


def test_identify_jobs_give_the_same_result_and_bad_counts_are_refused(capsys, case_a_csv):
    """--jobs N: the checks' runs on N threads, the JSON the same for 1 and 2 (bit for bit)."""
    outs = []
    for jobs in ("1", "2"):
        code, out, _ = _run(capsys, "identify", str(case_a_csv), "--model", "duffing1", "--jobs", jobs, "--json")
        assert code == 0
        outs.append(json.loads(out))
    assert outs[0]["parameters"] == outs[1]["parameters"]
    assert outs[0] == outs[1]
    for bad, why in (("0", "must be at least 1"), ("two", "is not a whole number")):
        with pytest.raises(SystemExit):
            main(["identify", str(case_a_csv), "--model", "duffing1", "--jobs", bad])
        assert f"--jobs: {bad!r} {why}" in capsys.readouterr().err


def test_identify_paper_table_and_plot(capsys, case_a_csv, tmp_path):
    png = tmp_path / "est.png"
    code, out, _ = _run(capsys, "identify", str(case_a_csv), "--method", "paper", "--gamma", "10", "--plot", str(png))
    assert code == 0 and "kp" in out and "identified" in out
    assert png.stat().st_size > 1000


def test_simulate_then_identify_two_dof(capsys, tmp_path):
    csv = tmp_path / "two.csv"
    code, out, _ = _run(capsys, "simulate", "--model", "duffing2", "--excitation", "step:6", "--t-end", "1",
                        "--param", "b2=4", "-o", str(csv))
    assert code == 0 and csv.read_text().splitlines()[0] == "t,f1,x1,x2"
    code, out, _ = _run(capsys, "identify", str(csv), "--model", "duffing2", "--json")
    data = json.loads(out)
    assert list(data["parameters"]) == ["m1", "b1", "k1", "kp1", "b2", "k2", "kp2", "m2"]
    assert data["parameters"]["m2"] == pytest.approx(2.754, rel=1e-3)


def test_circuit_json_uses_electrical_names(capsys, tmp_path):
    csv = tmp_path / "circuit.csv"
    assert _run(capsys, "simulate", "--model", "circuit", "--excitation", "chirp:1,0,30,2", "--t-end", "2",
                "--dt", "1e-4", "-o", str(csv))[0] == 0
    code, out, _ = _run(capsys, "identify", str(csv), "--model", "circuit", "--json")
    assert set(json.loads(out)["parameters"]) == {"L", "R", "C", "a"}


def test_bad_file_errors_name_the_file(capsys, tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("t,f,x\n0,1,0\n0.001,1,nan\n0.002,1,0\n")
    code, _, err = _run(capsys, "identify", str(bad))
    assert code == 2 and "bad.csv" in err and "line 3" in err
    code, _, err = _run(capsys, "identify", str(tmp_path / "missing.csv"))
    assert code == 2 and "missing.csv" in err
    code, _, err = _run(capsys, "simulate", "--param", "q=1", "-o", str(tmp_path / "x.csv"))
    assert code == 2 and "unknown parameter" in err


def test_unknown_excitation_is_rejected(capsys, tmp_path):
    code, _, err = _run(capsys, "simulate", "--excitation", "ramp:3", "-o", str(tmp_path / "x.csv"))
    assert code == 2 and "ramp" in err


@pytest.mark.slow
def test_paper_cases_json(capsys, tmp_path):
    code, out, _ = _run(capsys, "paper-cases", "--out", str(tmp_path), "--json")
    data = json.loads(out)
    assert code == 0 and set(data) == {"duffing1", "duffing2"}
    assert np.isfinite(data["duffing1"]["robust"]["parameters"]["kp"])
    assert (tmp_path / "duffing1_robust_estimates.png").exists()
    assert (tmp_path / "duffing2_robust_theta2.png").exists()


def test_identify_buffered_method(capsys, tmp_path, request):
    csv = tmp_path / "b.csv"
    request.getfixturevalue("case_b_exact").to_csv(csv)
    code, out, _ = _run(capsys, "identify", str(csv), "--method", "legendre", "--window", "0.5",
                        "--terms", "48", "--accumulate", "--json")
    data = json.loads(out)
    assert code == 0 and data["method"] == "legendre"
    for name, value in Duffing1().parameters.items():
        assert data["parameters"][name] == pytest.approx(value, rel=1e-3)
    code, _, err = _run(capsys, "identify", str(csv), "--method", "legendre", "--window", "auto")
    assert code == 2 and "--window auto" in err and "legendre" in err


def test_identify_equation_json(capsys, case_a_csv):
    code, out, _ = _run(capsys, "identify", str(case_a_csv), "--equation",
                        "mass*der(x,2) + c*der(x) + k*x + k3*x^3 = f", "--json")
    data = json.loads(out)
    assert code == 0 and data["model"] == "equation"
    assert set(data["parameters"]) == {"mass", "c", "k", "k3"}
    assert data["parameters"]["mass"] == pytest.approx(2.53, rel=2e-3)
    code, _, err = _run(capsys, "identify", str(case_a_csv), "--equation", "m*der(x)*der(x) + k*x = f")
    assert code == 2 and "der(x)" in err



def test_a_model_name_is_a_shortcut_for_its_equations(capsys, tmp_path):
    """--equation duffing1 is the model's equation text: the same estimator on one mass (equal
    values); --model prints the equation it stands for; with two masses the equation route
    solves one joint block, a different estimator of the same parameters (both published
    values agree within their stated uncertainties); the circuit has no linear equation in C."""
    csv = tmp_path / "d1.csv"
    assert main(["simulate", "--param", "m=0.4", "--param", "b=1.5", "--param", "k=900", "--param", "kp=2e7",
                 "--excitation", "chirp:3,1,30,4", "--t-end", "4", "--snr-db", "50", "--seed", "1", "-o", str(csv)]) == 0
    capsys.readouterr()
    code, out, _ = _run(capsys, "identify", str(csv), "--model", "duffing1", "--json")
    named = json.loads(out)
    code, out, _ = _run(capsys, "identify", str(csv), "--equation", "duffing1", "--json")
    shortcut = json.loads(out)
    assert code == 0 and shortcut["options"]["equation"] == "m*der(x,2) + b*der(x) + k*x + kp*x^3 = f"
    assert shortcut["status"] == named["status"]
    for name, value in named["parameters"].items():
        assert value is not None and shortcut["parameters"][name] == pytest.approx(value, rel=1e-9)
    code, out, _ = _run(capsys, "identify", str(csv), "--model", "duffing1")
    assert code == 0 and "  equation: m*der(x,2) + b*der(x) + k*x + kp*x^3 = f" in out
    code, _, err = _run(capsys, "identify", str(csv), "--equation", "circuit")
    assert code == 2 and "--equation: circuit: its parameter C enters the equation as 1/C" in err

    two = tmp_path / "two.csv"
    assert main(["simulate", "--model", "duffing2", "--excitation", "chirp:8,1,20,4", "--t-end", "4",
                 "--snr-db", "50", "--seed", "2", "-o", str(two)]) == 0
    capsys.readouterr()
    results = []
    for argv in (["--model", "duffing2"], ["--equation", "duffing2"]):
        code, out, _ = _run(capsys, "identify", str(two), *argv, "--json")
        assert code == 0
        results.append(json.loads(out))
    assert results[1]["options"]["equation"].count(";") == 1
    compared = 0
    for name, value in results[0]["parameters"].items():
        other = results[1]["parameters"][name]
        if value is not None and other is not None:
            spread = np.hypot(results[0]["uncertainty"][name], results[1]["uncertainty"][name]) * abs(value)
            assert abs(value - other) <= 4 * spread, (name, value, other)
            compared += 1
    assert compared >= 6

# ---------------------------------------------------------------------- duffid nonlinearity (issue 18)
@pytest.fixture(scope="module")
def nonlinearity_files(tmp_path_factory):
    """A linear plant under a random force (no ring-down), and linear and hardening sweeps at 0.3 and 1 N."""
    from duffid import simulate
    from duffid.analysis.nonlinearity import sweep_record
    from duffid.data.signals import Multisine

    folder = tmp_path_factory.mktemp("nonlinearity")
    linear = Duffing1(kp=0.0)
    simulate(linear, Multisine(1.0, 0.5, 10.0, 32.0, phases="random", seed=1), 32.0, 2e-3,
             rtol=1e-8, atol=1e-12).to_csv(folder / "random.csv")
    peak = np.max(np.abs(sweep_record(linear, 1.0, rate=1.0).x))
    hard = Duffing1(kp=0.4 * 1272.1 / peak**2)
    for name, plant in (("linear", linear), ("hard", hard)):
        for a in (0.3, 1.0):
            sweep_record(plant, a, rate=1.0).to_csv(folder / f"{name}_{a}N.csv")
    return folder


def test_nonlinearity_random_force_cannot_tell_in_words(capsys, nonlinearity_files):
    code, out, err = _run(capsys, "nonlinearity", str(nonlinearity_files / "random.csv"))
    assert code == 0 and "Warning" not in err and "warn" not in err.lower()
    assert "h1" in out and "cannot tell" in out and "a random force linearises the plant" in out
    assert "thresholds (set by the simulation study of benchmarks/nonlinearity.py)" in out


def test_nonlinearity_sweep_estimator_leakage_message(capsys, nonlinearity_files):
    code, out, err = _run(capsys, "nonlinearity", str(nonlinearity_files / "random.csv"), "--estimator", "sweep")
    assert code == 0 and not err
    assert "the response has not decayed at the end" in out and "append a ring-down or use --estimator h1" in out


def test_nonlinearity_groups_by_plant_and_orders_by_amplitude(capsys, nonlinearity_files, tmp_path):
    files = [str(nonlinearity_files / n) for n in ("hard_1.0N.csv", "linear_0.3N.csv", "hard_0.3N.csv", "linear_1.0N.csv")]
    png = tmp_path / "eta.png"
    code, out, _ = _run(capsys, "nonlinearity", *files, "--json", "--plot", str(png))
    assert code == 0 and png.stat().st_size > 1000
    rows = json.loads(out)
    assert [r["group"].endswith("hard_#N.csv") for r in rows] == [True, False, True, False]
    hard, linear = rows[0]["group_verdict"], rows[1]["group_verdict"]
    assert hard["verdict"] == "nonlinear" and linear["verdict"] == "dominantly linear"
    assert rows[0]["verdict"] == "nonlinear" and rows[0]["reasons"] and rows[0]["estimator"] == "sweep"
    assert rows[0]["thresholds"]["D_NONLINEAR_DB"] < 0
    code, out, _ = _run(capsys, "nonlinearity", *files, "--group", "a,b,a,b")
    assert code == 0 and "plant a (2 records, amplitudes 0.3-1)" in out and "plant b" in out


def test_nonlinearity_group_option_errors(capsys, nonlinearity_files):
    files = [str(nonlinearity_files / n) for n in ("hard_1.0N.csv", "linear_0.3N.csv")]
    code, _, err = _run(capsys, "nonlinearity", *files, "--group", "a")
    assert code == 2 and "--group needs one non-empty label per file" in err
    code, _, err = _run(capsys, "nonlinearity", *files, "--segments", "1")
    assert code == 2 and "--segments" in err


def test_nonlinearity_model_gives_the_nonlinear_share(capsys, nonlinearity_files):
    code, out, _ = _run(capsys, "nonlinearity", str(nonlinearity_files / "hard_1.0N.csv"), "--model", "duffing1")
    assert code == 0 and "nonlinear share of the restoring force kp x^2/k = +" in out and "(hardening)" in out
    code, out, _ = _run(capsys, "nonlinearity", str(nonlinearity_files / "linear_0.3N.csv"), "--model", "duffing1",
                        "--json")
    (share,) = json.loads(out)["shares"]
    assert share["share"] is None and share["reason"].startswith("the nonlinear share cannot be given: kp is")


def test_nonlinearity_stepped_rejects_single_record_options(capsys, nonlinearity_files):
    files = [str(nonlinearity_files / n) for n in ("hard_1.0N.csv", "linear_0.3N.csv")]
    code, _, err = _run(capsys, "nonlinearity", *files, "--stepped", "--estimator", "h1")
    assert code == 2 and "--estimator applies to single records" in err
    code, _, err = _run(capsys, "nonlinearity", *files, "--stepped", "--group", "a,a")
    assert code == 2 and "--group applies to separate records" in err


def test_ctrl_c_is_a_message_and_status_130_not_a_traceback(monkeypatch, capsys):
    """Ctrl-C outside a co-simulation run (which keeps its rows): one line, exit status 130."""
    from duffid.cli import COMMANDS

    def interrupted(args):
        raise KeyboardInterrupt

    monkeypatch.setattr(COMMANDS["simulate"], "run", interrupted)
    assert main(["simulate", "-o", "x.csv"]) == 130
    assert capsys.readouterr().err.strip() == "duffid simulate: interrupted"
