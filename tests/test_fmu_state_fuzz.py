"""Corrupted FMU states cannot hurt the host: a fuzz test under ASan and UBSan.

tests/c/fuzz_state.c loads an FMU binary, runs it over realistic inputs, serializes its state
and sets corrupted copies of it (random bytes with the checksum left as it is, random bytes
with the checksum resealed, an int32 sweep over every 4-byte offset, resealed). The FMUs'
own C sources (from the FMU's ``sources/`` folder, plus the glue's FMI 3 functions) and the
harness are compiled with ``-fsanitize=address,undefined,float-cast-overflow
-fno-sanitize-recover=all``, so any out-of-bounds access, use of freed memory, leak or
undefined behaviour ends a case as a sanitizer report.

Asserted for the estimators, the controllers and a plant, each mode: no crash, no hang, no
sanitizer report; a rejected state is logged and leaves the instance as it was (its outputs
right after and after the following steps equal, bit for bit, those of an instance that was
never given a corrupted state); an accepted state gives outputs in their ranges (or a refused
step with a logged error). A control test removes the controller's state checks and expects
the harness to count crashes and inconsistent states.
"""
from __future__ import annotations

import math
import re
import shutil
import subprocess
import sys
import zipfile
from dataclasses import dataclass
from pathlib import Path

import fmpy
import numpy as np
import pytest
from fmu_helpers import SANITIZE, SANITIZER_REPORT, sanitizer_compiler

from duffid import Duffing1, Duffing2, Step, measure, simulate
from duffid.assets import fmu_sources
from duffid.fmu.package import fmi_include_dir
from duffid.identification.engine import STATUSES

pytestmark = pytest.mark.slow

HARNESS = Path(__file__).parent / "c" / "fuzz_state.c"
#: Cases per FMU of each random mode.
CASES = 1000
#: Cases of the sweep: every (4-byte offset, value) pair of the plant's and the controllers'
#: states; the estimators' states (66 and 90 kB, mostly their sample buffers) get every offset
#: with the 16 values rotating (the full sweeps, 250,759 and 349,915 cases, are run by
#: ``fuzz_state ... --mode sweep --cases 0``; see the report of issue 16).
SWEEP_CASES = 24000
#: Values of the sweep (tests/c/fuzz_state.c, SWEEP_VALUES).
SWEEP_VALUES = 16
#: Steps after the state was set, checked against the untouched instance.
STEPS = 3
DT = 1e-3


@dataclass(frozen=True)
class FuzzTarget:
    """An FMU of the fuzz test (one of duffid.control.closed_loop.FMUS) and its warm-up: the
    steps before its state is saved (the estimators have published estimates by then, the
    controllers have switched to control)."""

    name: str
    warmup: int


TARGETS = {
    "DuffingEstimator1": FuzzTarget("DuffingEstimator1", warmup=200),
    "DuffingEstimator2": FuzzTarget("DuffingEstimator2", warmup=700),
    "AdaptiveController1": FuzzTarget("AdaptiveController1", warmup=450),
    "AdaptiveController2": FuzzTarget("AdaptiveController2", warmup=450),
    "Oscillator1DOF": FuzzTarget("Oscillator1DOF", warmup=100),
    "DuffingEstimator2Equation": FuzzTarget("DuffingEstimator2Equation", warmup=700),
}
#: Equation FMUs among the targets (duffid.fmu.estimator.build_equation_fmu, the generic core on
#: the generated model): the Duffing2 chain typed as the user's own 2-DOF equations, inputs x1,
#: x2 and f1 (fed the Duffing2 record as DuffingEstimator2).
EQUATION_TARGETS = {"DuffingEstimator2Equation": (
    "m1*der(x1,2) + b1*der(x1) + k1*x1 + kp1*x1^3 - k2*(x2-x1) - kp2*(x2-x1)^3 = f1; "
    "m2*der(x2,2) + b2*der(x2) + k2*(x2-x1) + kp2*(x2-x1)^3 = 0", ("t", "f1", "x1", "x2"))}
#: (FMU, mode, FMI version): every mode through the FMI 2 functions; the FMI 3 functions (the
#: same glue underneath) with the resealed random corruptions.
RUNS = [(name, mode, 2) for name in TARGETS for mode in ("random", "random-sealed", "sweep")] + \
       [(name, "random-sealed", 3) for name in TARGETS]


def _input_rows(name: str, inputs: list[str], n: int) -> np.ndarray:
    """Realistic inputs, one row per step: simulated records for the estimators; for the
    controllers a measured response with estimates published after 0.3 s (the plant's
    true values, NaN before); for the plant a step plus a sine of force."""
    t = np.arange(n) * DT
    if name.startswith("DuffingEstimator"):
        model, force = (Duffing1(), Step(14.0)) if name.endswith("1") else (Duffing2(), Step(6.0))
        record = measure(simulate(model, force, n * DT, DT))
        # enable: a short pause in the middle (the window restarts after it); reset: once, late
        columns = {**{f"x{i + 1}": record.x[:n, i] for i in range(record.x.shape[1])}, "f": record.f[:n, 0],
                   "f1": record.f[:n, 0], "enable": ((t < 0.4 * t[-1]) | (t > 0.45 * t[-1])).astype(float),
                   "reset": (np.arange(n) == int(0.9 * n)).astype(float)}
        columns.setdefault("x", columns["x1"])
        return np.column_stack([columns[v] for v in inputs])
    if name.startswith("AdaptiveController"):
        model = Duffing1() if name.endswith("1") else Duffing2()
        record = simulate(model, Step(10.0), n * DT, DT)
        known = t >= 0.3
        columns = {"r": np.where(t >= 0.35, 5e-3, 0.0), "r_dot": np.zeros(n), "r_ddot": np.zeros(n),
                   "identified": known.astype(float)}
        for i in range(record.x.shape[1]):
            columns[f"x{i + 1}" if record.x.shape[1] > 1 else "x"] = record.x[:n, i]
        for key, value in model.parameters.items():
            columns[f"{key}_hat"] = np.where(known, value, math.nan)
        return np.column_stack([columns[v] for v in inputs])
    return np.column_stack([10.0 + 5.0 * np.sin(2 * np.pi * 7.0 * t) for _ in inputs])


def _output_range(name: str, var, start: dict[str, float]) -> tuple[float, float, bool]:
    """(lo, hi, NaN allowed) of an output: what a host may rely on."""
    big = sys.float_info.max
    if var.type == "Boolean":
        return 0.0, 1.0, False
    if name.startswith("DuffingEstimator"):
        if var.name.endswith("_status"):
            return 0.0, float(len(STATUSES) - 1), False
        if var.name == "outliers":
            return 0.0, 2.0**31 - 1, False
        if var.name in ("condition", "uncertainty", "residual") or var.name.endswith("_std_error"):
            return 0.0, math.inf, True
        if var.name == "window_length":
            return 0.0, big, True
        return -big, big, True  # estimates: NaN until published
    if name.startswith("AdaptiveController"):
        if var.name in ("f", "f_sample"):
            return -start["force_limit"], start["force_limit"], False
        if var.name == "phase":
            return 0.0, 1.0, False
        if var.name == "switch_time":
            return 0.0, big, True
        return -big, big, True  # x_ref, v_hat, used: NaN before the switch
    return -big, big, False  # plants: finite outputs


def _write_spec(path: Path, fmu: Path, target: FuzzTarget) -> None:
    """The harness's spec of ``fmu`` (see tests/c/fuzz_state.c): identity, sample period,
    inputs and their rows, outputs and their ranges, from its modelDescription.xml."""
    md = fmpy.read_model_description(str(fmu))
    code = {"Real": "R", "Float64": "R", "Integer": "I", "Int32": "I", "Boolean": "B"}
    start = {v.name: float(v.start) if v.start not in (None, "") and v.type == "Real" else math.nan
             for v in md.modelVariables}
    lines = [f"identifier {md.coSimulation.modelIdentifier}", f"token {md.guid}", f"dt {DT!r}",
             f"warmup {target.warmup}", f"steps {STEPS}"]
    if "sample_period" in start:
        lines.append(f"param {next(v.valueReference for v in md.modelVariables if v.name == 'sample_period')} "
                     f"R {DT!r}")
    inputs = [v for v in md.modelVariables if v.causality == "input"]
    lines += [f"input {v.valueReference} {code[v.type]}" for v in inputs]
    for v in md.modelVariables:
        if v.causality == "output":
            lo, hi, nan_ok = _output_range(target.name, v, start)
            lines.append(f"output {v.valueReference} {code[v.type]} {lo!r} {hi!r} {int(nan_ok)} {v.name}")
    rows = _input_rows(target.name, [v.name for v in inputs], target.warmup + STEPS)
    lines += ["row " + " ".join(repr(float(x)) for x in row) for row in rows]
    path.write_text("\n".join(lines) + "\n")


@pytest.fixture(scope="module")
def fuzz_build(tmp_path_factory, loop_fmus):
    """The harness and each target FMU's sanitized binary (FMI 2 and 3 functions) and spec."""
    tmp = tmp_path_factory.mktemp("fuzz_state")
    cc = sanitizer_compiler(tmp)
    include = fmi_include_dir()
    exe = tmp / "fuzz_state"
    subprocess.run([cc, "-std=gnu99", "-Wall", "-Wextra", "-Werror", *SANITIZE, f"-I{include}",
                    f"-I{fmu_sources('common')}", str(HARNESS), "-o", str(exe), "-ldl", "-lm"], check=True)
    from duffid.fmu.estimator import build_equation_fmu

    fmus = {name: build_equation_fmu(text, tmp / "equations", name=name, columns=columns, backend="c")
            for name, (text, columns) in EQUATION_TARGETS.items()}
    fmus.update({name: loop_fmus[name] for name in TARGETS if name not in fmus})
    built = {}
    for name, target in TARGETS.items():
        folder = tmp / name
        with zipfile.ZipFile(fmus[name]) as archive:
            archive.extractall(folder)
        sources = folder / "sources"
        shutil.copy(fmu_sources("common") / "fmi3_functions.c", sources / "fmi3_functions.c")
        library = folder / f"{name}.so"
        subprocess.run([cc, "-std=gnu99", "-shared", "-fPIC", "-ffp-contract=off", *SANITIZE,
                        f"-I{sources}", f"-I{include}", *map(str, sorted(sources.glob("*.c"))), "-o", str(library),
                        "-lm"], check=True)
        spec = folder / "spec.txt"
        _write_spec(spec, fmus[name], target)
        built[name] = (library, spec)
    return exe, built


_RESULT = re.compile(r"^RESULT (.*)$", re.MULTILINE)
_TABLE: list[str] = []


def _fuzz(exe: Path, library: Path, spec: Path, mode: str, fmi: int, cases: int) -> tuple[dict[str, int], str]:
    """Run the harness; its counts (RESULT line) and its whole output."""
    done = subprocess.run([str(exe), str(library), str(spec), "--fmi", str(fmi), "--mode", mode, "--cases",
                           str(cases), "--seed", "16", "--timeout", "20"], check=False, capture_output=True,
                          text=True, timeout=900)
    output = done.stdout + done.stderr
    assert done.returncode == 0, output[-4000:]
    found = _RESULT.search(done.stdout)
    assert found, output[-4000:]
    counts = {key: (value if key == "mode" else int(value))
              for key, value in (item.split("=") for item in found.group(1).split())}
    return counts, output


@pytest.mark.parametrize("name,mode,fmi", RUNS, ids=[f"{n}-{m}-fmi{f}" for n, m, f in RUNS])
def test_corrupted_states_cannot_hurt_the_host(fuzz_build, name, mode, fmi):
    exe, built = fuzz_build
    library, spec = built[name]
    counts, output = _fuzz(exe, library, spec, mode, fmi, SWEEP_CASES if mode == "sweep" else CASES)
    _TABLE.append(f"| {name} | {fmi} | {mode} | {counts['state_bytes']} | {counts['cases']} | "
                  f"{counts['rejected']} | {counts['accepted_consistent']} | {counts['accepted_inconsistent']} | "
                  f"{counts['crashes']} | {counts['hangs']} |")
    print(f"\n{name} FMI {fmi} {mode}: " + " ".join(f"{k}={v}" for k, v in counts.items()))
    assert not SANITIZER_REPORT.search(output), output[-4000:]
    assert counts["crashes"] == 0 and counts["hangs"] == 0 and counts["sanitizer"] == 0, output[-4000:]
    # every case ran (the sweep skips only writes that change nothing, e.g. into the checksum
    # field that resealing rewrites)
    planned = min(SWEEP_CASES, counts["state_bytes"] // 4 * SWEEP_VALUES) if mode == "sweep" else CASES
    assert counts["cases"] + counts["skipped"] == planned and counts["cases"] >= 1000, output[-4000:]
    # a rejected state is logged and leaves the instance as it was
    assert counts["rejected_changed"] == 0 and counts["rejected_silent"] == 0, output[-4000:]
    assert counts["accepted_inconsistent"] == 0, output[-4000:]
    if mode == "random":  # the checksum catches every corruption it covers
        assert counts["rejected"] == CASES, output[-4000:]
    else:  # the invariant checks reject part of what passes a resealed checksum
        assert counts["rejected"] > 0, output[-4000:]


def test_the_harness_catches_an_unchecked_state(fuzz_build, tmp_path):
    """With its state checks removed, the controller FMU crashes under the sweep (an index
    from the corrupted state: a sanitizer report) and accepts inconsistent states: the harness
    counts both, so zero counts above are not for want of detection."""
    exe, built = fuzz_build
    library, spec = built["AdaptiveController1"]
    sources = tmp_path / "sources"
    shutil.copytree(library.parent / "sources", sources)
    model = sources / "fmu_model_controller.c"
    text, n = re.subn(r"(static int check_state\([^)]*\)\n\{)", r"\1\n    if (size > 0) return 0; /* unchecked */",
                      model.read_text())
    assert n == 1
    model.write_text(text)
    broken = tmp_path / "broken.so"
    subprocess.run([sanitizer_compiler(tmp_path), "-std=gnu99", "-shared", "-fPIC", "-w", *SANITIZE,
                    f"-I{sources}", f"-I{fmi_include_dir()}", *map(str, sorted(sources.glob("*.c"))), "-o",
                    str(broken), "-lm"], check=True)
    counts, output = _fuzz(exe, broken, spec, "sweep", 2, SWEEP_CASES)
    assert counts["crashes"] > 0 and counts["sanitizer"] > 0 and SANITIZER_REPORT.search(output), output[-4000:]
    assert counts["accepted_inconsistent"] > 0, output[-4000:]


def teardown_module(module):
    """Print the counts table (pytest -s shows it)."""
    if _TABLE:
        print("\n| FMU | FMI | mode | state bytes | cases | rejected | accepted, consistent | "
              "accepted, inconsistent | crashes | hangs |\n|---|---|---|---|---|---|---|---|---|---|")
        print("\n".join(_TABLE))
