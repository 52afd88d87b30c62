"""The portable C core (fmus/estimator) against the Python OnlineIdentifier.

Tolerances follow from each record, not from one machine (see tests/rounding.py): the
Python identifier is rerun with every input sample perturbed by one ulp, and C is compared
with Python at ``rounding.SAFETY`` times the largest change that caused:
- the estimate history per parameter, over the samples where the system is not singular to
  rounding (condition below ``history_cond``; in the first few samples of the paper method
  both are noise);
- the final estimates, at the spread of the final estimates;
- the condition figure likewise (relative), the uncertainty figure in absolute terms (on
  noise-free records it is itself near rounding level, so a relative figure says nothing).
Measured spreads: 1-DOF ~1e-12 relative (so the comparison is stricter than 1e-9); 2-DOF
chain up to ~5e-7 for kp2 over the history and ~2e-9 at the end (kp2 carries ~1e-6 of the
force balance), ~3e-8 for the other parameters; uncertainty up to ~3e-5 absolute.
"""
from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from rounding import identifier_spread, tolerance

from duffid import Chain, Duffing1, Duffing2, Multisine, OnlineIdentifier, Record, Step, measure, simulate
from duffid.cbuild import find_compiler
from duffid.errors import BuildError, CompilerNotFoundError
from duffid.identification.batch import estimate
from duffid.identification.c_core import CFLAGS, CIdentifier, build_library, source_dir
from duffid.identification.options import to_c

pytestmark = pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None,
                                reason="no C compiler")

ROOT = Path(__file__).resolve().parents[1]


def _run(ident, record):
    return [ident.update(x, f) for x, f in zip(record.x, record.f)]


def _history(estimates):
    names = list(estimates[0].parameters)
    return names, np.array([[e.parameters[k] for k in names] for e in estimates])


def _outputs(estimates):
    """Samples x (parameters, condition, uncertainty) of a list of estimates."""
    names = list(estimates[0].parameters)
    return np.array([[e.parameters[k] for k in names] + [e.condition, e.uncertainty] for e in estimates])


def _relative(a, b):
    with np.errstate(all="ignore"):
        return np.where(a == b, 0.0, np.abs(a - b) / np.abs(a))


def _assert_equivalent(py, c, spread, *, history_cond=1e10):
    """C estimates ``c`` equal Python's ``py`` sample by sample (see the module notes).

    ``spread`` is ``rounding.identifier_spread`` of the Python run. Estimates are compared
    where the Python condition number is at most ``history_cond``.
    """
    assert len(py) == len(c)
    assert [e.identified for e in py] == [e.identified for e in c]
    assert [e.status for e in py] == [e.status for e in c]
    assert [e.window for e in py] == [e.window for e in c]
    assert [e.t for e in py] == [e.t for e in c]
    names, P = _history(py)
    names_c, C = _history(c)
    assert names == names_c == list(spread.names)
    cond = np.array([e.condition for e in py])
    meaningful = cond <= history_cond
    assert np.array_equal(np.isnan(P)[meaningful], np.isnan(C)[meaningful])
    both = np.isfinite(P) & np.isfinite(C) & meaningful[:, None]
    worst = np.where(both, _relative(P, C), 0.0).max(axis=0)
    tol = spread.history_tolerance(meaningful)
    assert np.all(worst <= tol), {k: (w, t) for k, w, t in zip(names, worst, tol)}
    final = np.isfinite(P[-1])
    assert np.array_equal(final, np.isfinite(C[-1]))
    rel = _relative(P[-1], C[-1])[final]
    assert np.all(rel <= spread.final_tolerance()[final]), dict(zip(np.array(names)[final], rel))
    # condition and uncertainty once a window can be identified (n >= 8); before that the
    # fit through a handful of samples is exact and its residual is rounding noise
    cc = np.array([e.condition for e in c])
    up = np.array([e.uncertainty for e in py])
    uc = np.array([e.uncertainty for e in c])
    late = np.arange(len(py)) >= 8
    assert np.array_equal(np.isinf(cond[late]), np.isinf(cc[late]))
    ok = late & np.isfinite(cond) & (cond <= 1e10)
    assert np.all(_relative(cond[ok], cc[ok]) <= tolerance(spread.condition[ok].max(initial=0.0)))
    assert np.array_equal(np.isnan(up[late]), np.isnan(uc[late]))
    ok = late & np.isfinite(up) & np.isfinite(uc)
    assert np.all(np.abs(uc[ok] - up[ok]) <= tolerance(spread.uncertainty[ok].max(initial=0.0)))


ONE_DOF_CASES = [
    ("A", "robust", {}),
    ("A", "robust", {"window": 0.1}),
    ("A", "paper", {}),
    ("A", "paper", {"sign_in_numerator": True}),
    ("B", "robust", {}),
    ("B", "robust", {"window": 0.3}),
    ("B", "robust", {"forgetting": 0.5}),
    ("B", "robust", {"rows": "bernstein", "max_window": 0.5}),
    ("B", "robust", {"rows": "paper", "n_rows": 6, "window_periods": 1.0}),
    ("B", "paper", {"quadrature": "adams3", "gamma": 5.0}),
    ("B", "paper", {"sign_in_numerator": True}),
]


@pytest.mark.parametrize("case, method, options", ONE_DOF_CASES,
                         ids=[f"{c}-{m}-{'-'.join(f'{k}={v}' for k, v in o.items()) or 'default'}"
                              for c, m, o in ONE_DOF_CASES])
def test_one_dof_equals_python(case_a, case_b_exact, case, method, options):
    record = case_a if case == "A" else measure(case_b_exact, snr_db=40, seed=3)
    py = _run(OnlineIdentifier(Duffing1(), record.dt, method, **options), record)
    c = _run(CIdentifier(Duffing1(), record.dt, method, **options), record)
    _assert_equivalent(py, c, identifier_spread(Duffing1(), record, method, **options))
    assert any("published" in e.status.values() for e in py)  # the cases exercise the published path


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_case_b_seeds_equal_python(case_b_exact, seed):
    record = measure(case_b_exact, snr_db=40, seed=seed)
    _assert_equivalent(_run(OnlineIdentifier(Duffing1(), record.dt), record),
                       _run(CIdentifier(Duffing1(), record.dt), record), identifier_spread(Duffing1(), record))


TWO_DOF_CASES = [
    (6.0, "robust", {}),
    (10.0, "robust", {}),
    (10.0, "robust", {"window": 0.3, "forgetting": 0.5}),
    (6.0, "paper", {}),
    (10.0, "paper", {"sign_in_numerator": True}),
]


@pytest.mark.parametrize("step, method, options", TWO_DOF_CASES)
def test_two_dof_equals_python(two_dof_exact, step, method, options):
    from duffid import simulate
    record = two_dof_exact if step == 6.0 else simulate(Duffing2(), Step(step), 1.0, 1e-3)
    py = _run(OnlineIdentifier(Duffing2(), record.dt, method, **options), record)
    c = _run(CIdentifier(Duffing2(), record.dt, method, **options), record)
    _assert_equivalent(py, c, identifier_spread(Duffing2(), record, method, **options), history_cond=1e8)
    assert any("published" in e.status.values() for e in py)


def test_offset_models_equal_python(case_b_exact):
    from duffid import Chirp, simulate
    signal = Step(3.0) + Chirp(3.0, 1.0, 10.0, 2.0)
    record = measure(simulate(Duffing1(), signal, 1.0, 1e-3), snr_db=40, seed=2)
    model = Duffing1(offset=True)
    py = _run(OnlineIdentifier(model, record.dt), record)
    c = _run(CIdentifier(model, record.dt), record)
    # c1 is zero here: compare every parameter in its own units, at the absolute spread
    names, P = _history(py)
    _, C = _history(c)
    assert [e.identified for e in py] == [e.identified for e in c]
    assert np.array_equal(np.isnan(P), np.isnan(C))
    spread = identifier_spread(model, record)
    worst = np.nanmax(np.abs(P - C), axis=0, initial=0.0)
    tol = tolerance(spread.parameters_absolute.max(axis=0))
    assert np.all(worst <= tol), dict(zip(names, zip(worst, tol)))


def test_identify_record_matches_identify(case_a):
    expected = estimate(case_a, Duffing1())
    result = CIdentifier(Duffing1(), case_a.dt).identify_record(case_a)
    assert result.model == "duffing1" and result.method == "robust"
    assert result.t_identified == expected.t_identified
    assert np.array_equal(result.identified, expected.identified)
    identifier_spread(Duffing1(), case_a).assert_final(result.parameters, expected.parameters)
    # the solution at the last sample (input of duffid.identification.trust), from one batch call in C
    identifier_spread(Duffing1(), case_a).assert_estimates(result.estimates, expected.estimates)
    assert np.all(np.isfinite(list(result.estimates.values())))
    assert result.options == expected.options


def _memory_size(precision, model, method="robust", dt=1e-3, library=None, **fields):
    import ctypes

    from duffid.identification.c_core import config_type, load_library
    lib = load_library(library, precision)
    config = config_type(precision)()
    assert lib.duffid_default_config(ctypes.byref(config), model, {"robust": 0, "paper": 1}[method], dt) == 0
    for name, value in fields.items():
        setattr(config, name, value)
    return lib.duffid_memory_size(ctypes.byref(config))


def test_memory_is_sized_to_the_model_and_the_window():
    """One block sized from the model's own counts and the window, not the core's maxima:
    the 1-DOF robust estimator with a 1 s window at 1 kHz takes 38 KB in float (issue 28's
    32 KB before the rows' noise, row_noise, added the moments of its two channels, and the
    batch means, engine.BATCH_WINDOWS, their scores: 0.4 KB); a longer
    window adds its ring buffer (the raw sample: x, f and the noisy x, 4 bytes each, and a
    byte of force-jump flags), the 2-DOF model more."""
    one = _memory_size("float", 1)
    assert one <= 38 * 1024
    assert _memory_size("float", 1, max_window=2.0) - one == pytest.approx(1000 * (3 * 4 + 1), abs=64)
    assert _memory_size("double", 1, max_window=2.0) - _memory_size("double", 1) == pytest.approx(
        1000 * (3 * 8 + 1), abs=64)
    assert one < _memory_size("float", 2) < 2 * one + 4096
    assert _memory_size("double", 1, "paper") < 16 * 1024  # no ring buffer


def test_interface_reset_and_errors(case_a):
    ident = CIdentifier("duffing1", case_a.dt)
    assert ident.parameter_names == ("m", "b", "k", "kp")
    first = _run(ident, case_a)
    with pytest.raises(ValueError, match="not finite"):
        ident.update(np.nan, 1.0)
    with pytest.raises(ValueError, match="displacement"):
        ident.update([1.0, 2.0], 1.0)
    ident.reset()
    again = _run(ident, case_a)
    np.testing.assert_equal(again[-1].parameters, first[-1].parameters)
    # a rejected sample leaves the state unchanged
    ident.reset()
    for i, (x, f) in enumerate(zip(case_a.x, case_a.f)):
        if i == 20:
            with pytest.raises(ValueError):
                ident.update(x, np.inf)
        last = ident.update(x, f)
    np.testing.assert_equal(vars(last), vars(first[-1]))
    ident.close()
    with pytest.raises(ValueError, match="closed"):
        ident.update(0.0, 0.0)


def test_options_are_validated_like_python():
    with pytest.raises(TypeError, match="no option"):
        CIdentifier(Duffing1(), 1e-3, windw=0.1)
    with pytest.raises(ValueError, match="window"):
        CIdentifier(Duffing1(), 1e-3, window=-1.0)
    with pytest.raises(ValueError, match="unknown method"):
        CIdentifier(Duffing1(), 1e-3, method="legendre")
    with pytest.raises(ValueError, match="dt"):
        CIdentifier(Duffing1(), 0.0)
    with pytest.raises(ValueError, match="n_rows must be at most 17"):
        CIdentifier(Duffing1(), 1e-3, n_rows=18)
    with pytest.raises(ValueError, match="at most 6 displacements"):
        CIdentifier(Chain(masses=(1.0,) * 7, damping=(1.0,) * 7, stiffness=({1: 1.0},) * 7), 1e-3)
    with pytest.raises(ValueError, match="needs a model"):
        CIdentifier(42, 1e-3)


def test_missing_compiler_is_a_clear_error(monkeypatch, tmp_path):
    monkeypatch.setenv("CC", str(tmp_path / "no-such-cc"))
    with pytest.raises(CompilerNotFoundError, match="C compiler"):
        find_compiler()
    with pytest.raises(CompilerNotFoundError):
        build_library(tmp_path, force=True)


def test_build_errors_carry_the_compiler_output(tmp_path, monkeypatch):
    broken = tmp_path / "src"
    shutil.copytree(source_dir(), broken)
    (broken / "duffid_linalg.c").write_text("this is not C\n")
    monkeypatch.setenv("DUFFID_C_SOURCES", str(broken))
    with pytest.raises(BuildError, match="duffid_linalg.c"):
        build_library(tmp_path / "build")


def test_library_is_cached_by_source_hash(tmp_path):
    first = build_library(tmp_path)
    assert first.parent == tmp_path and build_library(tmp_path) == first
    assert [p.name for p in tmp_path.iterdir()] == [first.name]  # no temporary files left


def _compile(args, tmp_path):
    cc = find_compiler()
    proc = subprocess.run([cc, *args], capture_output=True, text=True, cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_core_is_clean_under_strict_warnings(tmp_path):
    src = source_dir()
    flags = ["-std=c99", "-O2", "-Wall", "-Wextra", "-Werror", "-pedantic", "-Wconversion", "-Wsign-conversion",
             "-Wshadow", "-Wdouble-promotion", "-Wvla", "-Wstrict-prototypes", "-Wmissing-prototypes",
             "-fsyntax-only"]
    _compile([*flags, str(src / "duffid_estimator.c"), str(src / "duffid_linalg.c")], tmp_path)
    _compile([*flags, "-DDUFFID_NO_STDIO", str(src / "duffid_estimator.c")], tmp_path)


@pytest.fixture(scope="module")
def c_program(tmp_path_factory):
    """tests/c/test_estimator.c linked statically with the core."""
    out = tmp_path_factory.mktemp("cprog")
    exe = out / ("test_estimator.exe" if sys.platform == "win32" else "test_estimator")
    src = source_dir()
    flags = [f for f in CFLAGS if f not in ("-fPIC", "-shared")]
    _compile([*flags, f"-I{src}", "-o", str(exe), str(ROOT / "tests" / "c" / "test_estimator.c"),
              str(src / "duffid_estimator.c"), str(src / "duffid_linalg.c"), "-lm"], out)
    return exe


def test_c_selftest(c_program):
    proc = subprocess.run([str(c_program), "selftest"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert "selftest ok" in proc.stdout


@pytest.mark.parametrize("model_name, method, options", [
    ("duffing1", "robust", {}),
    ("duffing1", "paper", {"sign_in_numerator": True}),
    ("duffing2", "robust", {"forgetting": 0.5}),
])
def test_c_program_on_a_csv_record(c_program, tmp_path, case_a, two_dof_exact, model_name, method, options):
    record: Record = case_a if model_name == "duffing1" else two_dof_exact
    path = tmp_path / "record.csv"
    record.to_csv(path)
    args = [str(c_program), "run", model_name, method, str(path), f"dt={record.dt!r}"]
    args += [f"{k}={to_c(k, v)!r}" for k, v in options.items()]
    proc = subprocess.run(args, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert "mean update time" in proc.stderr
    rows = np.array([[float(v) for v in line.split(",")] for line in proc.stdout.splitlines()])
    model = Duffing1() if model_name == "duffing1" else Duffing2()
    py = _run(OnlineIdentifier(model, record.dt, method, **options), record)
    assert rows.shape == (record.n_samples, 6 + len(model.parameters))
    assert np.array_equal(rows[:, 2].astype(bool), [e.identified for e in py])
    names, P = _history(py)
    C = rows[:, 6:]
    assert np.array_equal(np.isnan(P[-1]), np.isnan(C[-1]))
    identifier_spread(model, record, method, **options).assert_final(dict(zip(names, C[-1])), dict(zip(names, P[-1])))
    # and bit for bit what the ctypes binding reports (same sources, same flags)
    c = _run(CIdentifier(model, record.dt, method, **options), record)
    _, Cb = _history(c)
    assert np.array_equal(C, Cb, equal_nan=True)


def test_outliers_are_excluded_as_in_python(case_b_exact):
    clean = measure(case_b_exact, snr_db=40, seed=3)
    x = clean.x.copy()
    x[700, 0], x[1200, 0], x[-1, 0] = 1.0, 0.0, 2.0   # the last one is never confirmed: processed as measured
    x[1500:1502, 0] = 0.0                              # a glitch of two samples
    x[-6:-4, 0] = -1.0                                 # ... and one that the sample after it confirms
    record = Record(clean.t, clean.f, x, source="glitched")
    py = estimate(record, Duffing1())
    with CIdentifier(Duffing1(), record.dt) as ident:
        c = ident.identify_record(record)
    assert c.outliers == py.outliers and [o["value"] for o in py.outliers] == [1.0, 0.0, 0.0, 0.0, -1.0, -1.0]
    assert np.array_equal(c.identified, py.identified) and c.status == py.status
    spread = identifier_spread(Duffing1(), record)
    spread.assert_final(c.parameters, py.parameters)


@pytest.mark.parametrize("window", [0.05, 0.6, 30.0])  # 30 s: the record ends in a growing window
def test_deferred_solutions_give_the_last_samples_solution_bit_for_bit(case_b_exact, window):
    """duffid_defer_solutions (identify's re-runs): full windows only accumulate their rows,
    and flush solves once; the final solution is the one every sample's solve reaches, bit
    for bit, with glitches held at the end and a hold in the middle; refused where every
    sample's solution is needed."""
    clean = measure(case_b_exact, snr_db=40, seed=3)
    x = clean.x.copy()
    x[1500:1502, 0] = 0.0  # a glitch of two samples
    x[-1, 0] = 2.0         # a suspect sample held at the end
    options = {"window": window, "change_threshold": None}

    def final(defer: bool) -> dict:
        with CIdentifier(Duffing1(), clean.dt, **options) as ident:
            assert ident.defer_solutions(defer) or not defer
            half = len(x) // 2
            ident.consume(x[:half], clean.f[:half])
            ident.hold()
            ident.consume(x[half:], clean.f[half:])
            out = ident.flush()
            assert out is not None  # the held sample (and the postponed solve)
            return out.current

    deferred, every = final(True), final(False)
    assert deferred == every  # the solution (the statuses rest on one publication: not compared)
    assert np.isfinite(list(deferred.values())).all()
    with CIdentifier(Duffing1(), clean.dt) as ident:  # the change test is on by default
        assert not ident.defer_solutions()
    with CIdentifier(Duffing1(), clean.dt, window="auto", change_threshold=None) as ident:
        assert not ident.defer_solutions()  # the automatic window is fixed by the statuses
    with CIdentifier(Duffing1(), clean.dt, method="paper") as ident:
        assert not ident.defer_solutions()


def test_deferred_solutions_cannot_be_turned_back_into_per_sample_ones():
    """A deferred run skips what per-sample solutions need (the alternating sums of the
    half-rate rows): after deferred samples, turning it off is refused, and solves as flush
    does; before the first sample (or after a reset) it is allowed."""
    record = measure(simulate(Duffing1(), Multisine(8.0, 0.5, 10.0, 2.0, phases="random", seed=2), 2.0, 1e-3),
                     snr_db=50, seed=4)
    options = {"window": 0.3, "change_threshold": None}
    with CIdentifier(Duffing1(), record.dt, **options) as ident:
        every = ident.run(record.x, record.f)[-1]
    with CIdentifier(Duffing1(), record.dt, **options) as ident:
        assert ident.defer_solutions(True)
        assert ident.defer_solutions(False)  # no sample yet
        assert ident.defer_solutions(True)
        ident.consume(record.x, record.f)
        assert not ident.defer_solutions(False)
        solved = ident.latest()
        assert list(solved.current.values()) == list(every["current"][:4])
        ident.reset()
        assert ident.defer_solutions(False)  # afresh


def test_a_row_stride_takes_every_sth_full_windows_rows(case_b_exact):
    """duffid_defer_solutions(est, s): only every s-th full window adds its rows, the first
    full one first. A stride longer than the record keeps that one alone: its solution is the
    per-sample run's at the first full window, bit for bit; strides between give solutions of
    the same samples within a few of their stated errors; a stride changed after the first
    sample, or out of range, is refused."""
    record = measure(case_b_exact, snr_db=50, seed=7)
    options = {"window": 0.4, "change_threshold": None}
    with CIdentifier(Duffing1(), record.dt, **options) as ident:
        every = ident.run(record.x, record.f)
    first_full = int(np.argmax(every["window"] >= every["window"][-1]))
    assert 0 < first_full < len(record.t) - 1

    def final(stride: int) -> dict:
        with CIdentifier(Duffing1(), record.dt, **options) as ident:
            assert ident.defer_solutions(True, stride)
            ident.consume(record.x, record.f)
            return ident.flush().current

    alone = final(len(record.t))
    assert list(alone.values()) == list(every["current"][first_full][:4])
    full = final(1)
    assert list(full.values()) == list(every["current"][-1][:4])
    errors = every["std_errors"][-1][:4]  # absolute, of the published values
    assert np.isfinite(errors).all()
    for stride in (2, 5, 17):
        strided = final(stride)
        assert strided != full
        for (name, value), error in zip(strided.items(), errors):
            assert abs(value - full[name]) < 3 * error, (stride, name)
    with CIdentifier(Duffing1(), record.dt, **options) as ident:
        assert ident.defer_solutions(True, 4)
        ident.consume(record.x[:10], record.f[:10])
        assert not ident.defer_solutions(True, 5)  # the run's stride is fixed
        assert ident.defer_solutions(True, 4)
        with pytest.raises(ValueError, match="row_stride"):
            ident.defer_solutions(True, 0)


def test_identify_strides_the_replicates_rows_without_changing_their_spread(monkeypatch):
    """The noisy replicates take the rows of BOOTSTRAP_ROWS_PER_WINDOW windows per window
    length (a stride > 1 for this record): the same values and statuses, each stated error
    within the spread of eight replicates of the one with every sample's rows (the same
    noise draws), and a deferred run of the strided estimator on the record itself as the
    replicates' centre."""
    from duffid import Multisine, identify
    from duffid.identification import trust

    record = measure(simulate(Duffing1(), Multisine(8.0, 0.5, 10.0, 4.0, phases="random", seed=3), 8.0, 1e-3),
                     snr_db=40, seed=8)
    strides = []
    original = trust._Estimation.row_stride
    monkeypatch.setattr(trust._Estimation, "row_stride", lambda self: strides.append(original(self)) or strides[-1])
    strided = identify(record, Duffing1(), jobs=1)
    assert max(strides) > 1
    monkeypatch.setattr(trust._Estimation, "row_stride", lambda self: 1)
    every = identify(record, Duffing1(), jobs=1)
    assert strided.parameters == every.parameters
    assert strided.assessment.status == every.assessment.status
    for name, error in every.assessment.uncertainty.items():
        assert 0.9 < strided.assessment.uncertainty[name] / error < 1.1, name


def test_identify_is_the_same_with_deferred_solutions(case_b_exact, monkeypatch):
    """identify's re-runs (noisy copies, half rate, offsets) solve once per run: the same
    assessment, bit for bit, as with a solve at every sample."""
    from duffid import identify

    from duffid.identification import trust

    record = measure(case_b_exact, snr_db=40, seed=5)
    granted = []
    original = CIdentifier.defer_solutions
    monkeypatch.setattr(trust, "BOOTSTRAP_ROWS_PER_WINDOW", 10**9)  # every sample's rows (no stride)
    monkeypatch.setattr(CIdentifier, "defer_solutions",
                        lambda self, defer=True, row_stride=1: granted.append(original(self, defer, row_stride))
                        or granted[-1])
    deferred = identify(record, Duffing1(), jobs=1)
    assert sum(granted) >= 10  # 8 noisy copies, half the rate, the force offset at least
    monkeypatch.setattr(CIdentifier, "defer_solutions", lambda self, defer=True, row_stride=1: False)
    every = identify(record, Duffing1(), jobs=1)
    assert deferred.parameters == every.parameters
    assert deferred.assessment.values == every.assessment.values
    assert deferred.assessment.uncertainty == every.assessment.uncertainty


def test_the_c_constants_are_pythons():
    """Status codes and the trust and outlier constants: one fact, two languages (the C side
    generated from Python into duffid_facts.h, included by every header of the core)."""
    import re

    from duffid.identification import engine as ident
    header = (source_dir() / "duffid_facts.h").read_text()
    defines = dict(re.findall(r"^#define (DUFFID_\w+) (\S+)", header, flags=re.M))
    assert [int(defines[f"DUFFID_STATUS_{name.upper().replace(' ', '_')}"]) for name in ident.STATUSES] == \
        list(range(len(ident.STATUSES)))
    for name in ("MIN_SHARE", "LOSS_FACTOR", "GROWTH_STEADY", "OUTLIER_SIGMAS", "OUTLIER_RANGE", "OUTLIER_MEMORY"):
        assert float(defines[f"DUFFID_{name}"]) == getattr(ident, name), name
