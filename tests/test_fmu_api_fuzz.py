"""The FMI API cannot be misused into a crash: a fuzzing host in C under ASan and UBSan.

tests/c/fuzz_api.c loads an FMU binary and makes random FMI calls from a seeded PRNG in every
state (illegal call sequences, NULL pointers, unknown value references and wrong types, NaN/Inf
values, bad steps, FMU state calls with bad arguments, Model Exchange functions on a
co-simulation instance), judged against the FMI state machine; then a reset and a valid run
that must equal a fresh instance's bit for bit; then instantiate/run/free cycles (20,000 in a plain build, whose memory and file descriptors are
measured; 200 under the sanitizers). The
FMUs' own C sources and the host are compiled with ``-fsanitize=address,undefined``, so any
out-of-bounds access, use after free, leak (LeakSanitizer at exit) or undefined behaviour ends
the run as a sanitizer report.

Targets: every C FMU duffid builds (the plants, estimators and controllers, FMI 2 and FMI 3, and
the closed-loop container, FMI 2). Asserted per run: no crash, no hang, no sanitizer report, no
illegal call accepted (each refused with Error or Discard and a logged message), every function
called in every state the run can reach, the valid run after the fuzzing equal to a fresh
instance's, and memory and file descriptors flat over the cycles. ``pytest -s`` prints the table.
"""
from __future__ import annotations

import re
import shutil
import subprocess
import zipfile
from pathlib import Path

import fmpy
import pytest
from fmu_helpers import SANITIZE, SANITIZER_REPORT, sanitizer_compiler

from duffid.assets import fmu_sources
from duffid.fmu.package import fmi_include_dir

pytestmark = pytest.mark.slow

HOST = Path(__file__).parent / "c" / "fuzz_api.c"
#: Random calls per run; instantiate/run/free cycles of the sanitized run (LeakSanitizer checks
#: at exit) and of the plain build, whose resident memory is measured (the sanitizers' quarantine
#: holds freed memory back, so their RSS grows by design).
CALLS = 20000
SANITIZED_CYCLES = 200
CYCLES = 20000
#: Resident memory of the plain build may grow by this much between the first tenth of the
#: cycles and the end: the allocator's 64 kB steps; a leak of 16 bytes per cycle would add
#: 281 kB over the 18,000 cycles measured. Measured: 0 to 72 kB.
RSS_GROWTH_KB = 256
_CAUSALITY = {"parameter", "calculatedParameter", "input", "output", "local", "independent"}
_TABLE: list[str] = []


def _write_spec(path: Path, fmu: Path, folder: Path) -> None:
    """The host's spec of ``fmu`` (see tests/c/fuzz_api.c) from its modelDescription.xml."""
    md = fmpy.read_model_description(str(fmu))
    code = {"Real": "R", "Float64": "R", "Integer": "I", "Int32": "I", "Boolean": "B"}
    start = {v.name: v.start for v in md.modelVariables}
    dt = float(start.get("sample_period") or md.defaultExperiment.stepSize or 1e-3)
    resources = folder / "resources"
    lines = [f"identifier {md.coSimulation.modelIdentifier}", f"token {md.guid}",
             f"resources {resources.as_uri()} {resources}/", f"dt {dt!r}",
             f"fmu_state {int(bool(md.coSimulation.canGetAndSetFMUstate))}"]
    for v in md.modelVariables:
        assert v.causality in _CAUSALITY and v.type in code, (v.name, v.causality, v.type)
        value = v.start if v.start not in (None, "") else "nan"
        value = {"true": "1", "false": "0"}.get(str(value).lower(), value)
        # inputs that may hold NaN: the controllers' estimates ("not yet estimated")
        non_finite = int(v.causality == "input" and v.name.endswith("_hat"))
        settable = int(v.initial in ("exact", "approx") and v.causality not in ("parameter", "input", "independent"))
        lines.append(f"var {v.valueReference} {code[v.type]} {v.causality} {v.variability or 'continuous'} "
                     f"{non_finite} {settable} {value} {v.name}")
    path.write_text("\n".join(lines) + "\n")


@pytest.fixture(scope="module")
def targets(loop_fmus, tmp_path_factory) -> dict[str, tuple[Path, Path, Path, tuple[int, ...]]]:
    """Every C FMU duffid builds: (sanitized binary, spec, host, FMI versions) by name."""
    from duffid.control.closed_loop import build_closed_loop_fmu, closed_loop_case

    tmp = tmp_path_factory.mktemp("fuzz_api")
    cc = sanitizer_compiler(tmp)
    include = fmi_include_dir()
    host, plain_host = tmp / "fuzz_api", tmp / "fuzz_api_plain"
    for exe, flags in ((host, SANITIZE), (plain_host, ("-O2",))):
        subprocess.run([cc, "-std=gnu99", "-Wall", "-Wextra", "-Werror", *flags, f"-I{include}", str(HOST), "-o",
                        str(exe), "-ldl", "-lm"], check=True)
    fmus = dict(loop_fmus)
    fmus["ClosedLoop1DOF"] = build_closed_loop_fmu(tmp, loop_fmus, closed_loop_case())
    built = {}
    for name, fmu in fmus.items():
        folder = tmp / name
        with zipfile.ZipFile(fmu) as archive:
            archive.extractall(folder)
        sources = folder / "sources"
        container = (sources / "duffid_container.c").exists()
        if not container:  # the same glue serves FMI 3 (the FMI 3 FMUs are built from the same sources)
            shutil.copy(fmu_sources("common") / "fmi3_functions.c", sources / "fmi3_functions.c")
        libraries = (folder / f"{name}_sanitized.so", folder / f"{name}_plain.so")
        for library, flags in zip(libraries, (SANITIZE, ("-O2",))):
            subprocess.run([cc, "-std=gnu99", "-shared", "-fPIC", "-ffp-contract=off", *flags, f"-I{sources}",
                            f"-I{include}", *map(str, sorted(sources.glob("*.c"))), "-o", str(library), "-lm",
                            "-ldl"], check=True)
        spec = folder / "spec.txt"
        _write_spec(spec, fmu, folder)
        built[name] = (libraries, spec, (host, plain_host), (2,) if container else (2, 3))
    return built


RUNS = [(name, fmi) for name in ("Oscillator1DOF", "Oscillator2DOF", "DuffingCircuit", "DuffingEstimator1",
                                 "DuffingEstimator2", "AdaptiveController1", "AdaptiveController2")
        for fmi in (2, 3)] + [("ClosedLoop1DOF", 2)]


def _run(host: Path, library: Path, spec: Path, fmi: int, cycles: int) -> tuple[bool, dict[str, str], str]:
    """The host's run: (crashed, its RESULT counts, its output)."""
    done = subprocess.run([str(host), str(library), str(spec), "--fmi", str(fmi), "--calls", str(CALLS), "--cycles",
                           str(cycles), "--seed", "17", "--timeout", "600"], check=False, capture_output=True,
                          text=True, timeout=900)
    found = re.search(r"^RESULT (.*)$", done.stdout, re.MULTILINE)
    counts = dict(item.split("=") for item in found.group(1).split()) if found else {}
    return done.returncode != 0, counts, done.stdout + done.stderr


@pytest.mark.parametrize("name,fmi", RUNS, ids=[f"{n}-fmi{f}" for n, f in RUNS])
def test_the_fmi_api_cannot_be_misused_into_a_crash(targets, name, fmi):
    (library, plain_library), spec, (host, plain_host), versions = targets[name]
    assert fmi in versions
    crashed, counts, output = _run(host, library, spec, fmi, SANITIZED_CYCLES)
    plain_crashed, plain, plain_output = _run(plain_host, plain_library, spec, fmi, CYCLES)
    leak_kb = int(plain.get("rss_kb_end", 0)) - int(plain.get("rss_kb_warm", 0))
    fd_growth = int(plain.get("fds_end", 0)) - int(plain.get("fds_warm", 0))
    _TABLE.append(f"| {name} | {fmi} | {counts.get('calls', '-')} | {counts.get('refused', '-')} / "
                  f"{counts.get('illegal', '-')} | {int(crashed)} | {leak_kb} kB, {fd_growth} fds | "
                  f"{counts.get('coverage', '-')} | {counts.get('violations', '-')} |")
    print(f"\n{name} FMI {fmi}: " + " ".join(f"{k}={v}" for k, v in counts.items()) + f" (plain: {leak_kb} kB, "
          f"{fd_growth} fds over {CYCLES} cycles)")
    assert not crashed and not SANITIZER_REPORT.search(output), output[-4000:]
    assert not plain_crashed and plain == {**counts, **{k: plain[k] for k in plain if k.startswith(("rss", "fds"))},
                                           "cycles": str(CYCLES)}, (plain, counts, plain_output[-2000:])
    assert int(counts["violations"]) == 0 and int(counts["silent"]) == 0, output[-4000:]
    assert int(counts["refused"]) == int(counts["illegal"]) > 1000, counts
    visited, possible = map(int, counts["coverage"].split("/"))
    assert visited == possible, counts  # every function in every state the run reached
    assert counts["valid_after"] == "1", counts  # reset, then a valid run equals a fresh instance's
    assert leak_kb < RSS_GROWTH_KB and fd_growth == 0, plain  # memory and descriptors flat


def test_the_host_catches_a_missing_check(targets, tmp_path):
    """With the glue's check of the step size removed (a zero or negative step accepted), the
    host reports illegal doSteps accepted: zero violations above are not for want of detection."""
    (library, _), spec, (host, _), _ = targets["Oscillator1DOF"]
    sources = tmp_path / "sources"
    shutil.copytree(library.parent / "sources", sources)
    glue = sources / "fmu_instance.c"
    text, n = re.subn(r"if \(!isfinite\(h\) \|\| !\(h > 0\.0\)\) \{", "if (!isfinite(h)) {", glue.read_text())
    assert n == 1
    glue.write_text(text)
    broken = tmp_path / "broken.so"
    subprocess.run([sanitizer_compiler(tmp_path), "-std=gnu99", "-shared", "-fPIC", "-w", *SANITIZE, f"-I{sources}",
                    f"-I{fmi_include_dir()}", *map(str, sorted(sources.glob("*.c"))), "-o", str(broken), "-lm"],
                   check=True)
    crashed, counts, output = _run(host, broken, spec, 2, 10)
    assert not crashed and int(counts["violations"]) > 0 and "illegal call accepted: doStep" in output, output[-2000:]


def teardown_module(module):
    """Print the table (pytest -s shows it)."""
    if _TABLE:
        print("\n| FMU | FMI | calls | refused / illegal | crashes | leaks (RSS, fds over the cycles) | "
              "coverage | violations |\n|---|---|---|---|---|---|---|---|")
        print("\n".join(_TABLE))
