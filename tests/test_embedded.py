"""The C estimator core bare-metal on a Cortex-M4F (QEMU mps2-an386) against the same program
on x86-64: benchmarks/embedded.py's functions over short records (its --quick).

The test program (tests/embedded/embedded_test.c) prints every output of every update as
exact bit patterns; the ARM build (arm-none-eabi-gcc, newlib, soft double) and the native
build (gcc, glibc) must report the same return codes, identified flags and statuses at
every sample, NaN where the other has NaN, and values within benchmarks/embedded.py's
TOLERANCE_ULPS (both use -ffp-contract=off: only libm may round differently, amplified by the
reported condition number). No heap call may happen (the link wraps malloc & co.), both
programs must exit 0, and the TCG plugin must see one instruction count per update. The
negative control builds the program with one malloc inside the first update's markers: both
builds must report it and exit 2 (through QEMU's semihosting exit).

Skipped, naming the Debian package, when arm-none-eabi-gcc, newlib or qemu-system-arm is
missing.
"""
from __future__ import annotations

import pytest

from benchmark_modules import load_benchmark

embedded = load_benchmark("embedded")

MISSING = embedded.missing_tools()
pytestmark = pytest.mark.skipif(bool(MISSING), reason="needs " + "; ".join(MISSING))

SAMPLES = embedded.QUICK_SAMPLES
MODELS = ["duffing1", "duffing2"]


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    build_dir = tmp_path_factory.mktemp("embedded")
    results, info, notes = embedded.run(MODELS, "robust", SAMPLES, ["double", "float"], build_dir,
                                        progress=lambda _: None)
    return results, info, notes


def test_every_supported_precision_ran(runs):
    results, info, notes = runs
    assert "double" in info["supported"]
    assert [(r.build.model, r.build.real) for r in results] == [(m, p) for m in MODELS for p in info["supported"]]
    for real in ("float",):
        if real not in info["supported"]:
            assert any(real in note for note in notes)


def test_arm_and_x86_agree(runs):
    for r in runs[0]:
        name = f"{r.build.model} {r.build.real}"
        assert r.arm.exit_code == 0 and r.arm.end == 0, name
        assert r.x86.exit_code == 0 and r.x86.end == 0, name
        assert len(r.arm.samples) == len(r.x86.samples) == SAMPLES, name
        c = r.comparison
        assert c.status_mismatches == 0, f"{name}: statuses differ first at sample {c.first_status_mismatch}"
        assert c.nan_mismatches == 0, name
        assert c.out_of_tolerance == 0, f"{name}: {c.max_scaled} (tolerance {c.tolerance})"
        assert all(s.rc == 0 for s in r.arm.samples), name
        if r.build.real == "double":  # the comparison covers published values, not only NaN
            assert any(1 in s.status for s in r.arm.samples), name


def test_no_heap_and_one_count_per_update(runs):
    for r in runs[0]:
        name = f"{r.build.model} {r.build.real}"
        assert r.arm.heap_calls == 0 and r.arm.heap_during == 0, name
        assert r.x86.heap_calls == 0, name
        assert not [f for f in r.profile.calls if embedded.HEAP.search(f)], name
        assert len(r.profile.updates) == SAMPLES and r.profile.unmatched == 0, name
        assert min(r.profile.updates) > 100, name
        assert r.arm.memory_size > 0 and 0 < r.arm.stack_used < 64 * 1024, name


def test_heap_guard_reports_a_heap_call(runs, tmp_path):
    """Negative control: one malloc between the first update's markers."""
    _, info, _ = runs
    build_dir = info["build_dir"]
    build = embedded.build_program(build_dir, build_dir / "record_duffing1", "duffing1", "robust", "double",
                                   extra=("-DEMBEDDED_HEAP_PROBE",), tag="_heap_probe")
    arm, profile = embedded.run_arm(build, build_dir / "insn_plugin.so")
    x86 = embedded.run_host(build)
    assert (arm.exit_code, arm.heap_during, arm.end) == (2, 1, 2)
    assert (x86.exit_code, x86.heap_during, x86.end) == (2, 1, 2)
    assert profile.calls.get("__wrap_malloc") == 1


def test_buffered_identifier_on_the_target(tmp_path_factory):
    """The paper's Figure 15 path (duffid_buffered.c over generated tables) on the same target:
    ARM = x86, no heap, fixed work between window ends, published windows."""
    build_dir = tmp_path_factory.mktemp("embedded_buffered")
    results, info, notes = embedded.run(["duffing1"], "buffered", 600, ["double", "float"], build_dir,
                                        progress=lambda _: None)
    assert [(r.build.model, r.build.real) for r in results] == [("duffing1", "double"), ("duffing1", "float")]
    for r in results:
        name = f"buffered {r.build.real}"
        assert r.arm.exit_code == 0 and r.x86.exit_code == 0, name
        c = r.comparison
        assert c.status_mismatches == 0 and c.nan_mismatches == 0 and c.out_of_tolerance == 0, name
        assert r.arm.heap_during == 0 and len(r.profile.updates) == 600, name
        assert any(1 in s.status for s in r.arm.samples), name   # a window was published
        if r.build.real == "float":
            assert not [f for f in r.profile.calls if embedded.SOFT_DOUBLE_CALLS.search(f)], name
