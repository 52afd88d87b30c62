"""duffid's C FMUs in a host that is not Python, on Linux, Windows (wine64) and aarch64 (qemu).

tests/c/fmi_host.c is compiled for each platform (tests/c_hosts.py) and runs a plant, an
estimator and a controller FMU, FMI 2 and FMI 3, each on the binary of its own platform
inside the FMU, over the same inputs (c_hosts.standard_cases).

Tolerances. The FMUs are the same C source built with ``-ffp-contract=off`` (no fused
multiply-adds), so every +, -, *, / and sqrt rounds alike on every platform; what may differ
is the C library's other functions (pow, exp, log, hypot, sin, fmod): glibc on linux64 and
aarch64, mingw-w64's on Windows, each within an ulp or so of the exact value. A difference
of a few ulps in an intermediate result moves an output as much as the computation's own
conditioning says, and that is measured, not guessed: the linux64 host reruns each case with
every Real input sample perturbed by one ulp (tests/rounding.py's method), and each Real
output at each row must agree within rounding.SAFETY (30) times the largest relative change
seen within 50 rows (rounding.tolerance; at least rounding.FLOOR, ~1.4e-14). Integer and
Boolean outputs (statuses, identified, phase, saturated), the NaN patterns and the time
column must be equal exactly.

Exact equality where it holds: the linux64 host and fmpy run the same binary on the same
machine with the same calls, so their results are compared bit for bit. Measured on the
development machine (benchmarks/platforms.py prints it): the plant and the controller are
bit-identical on all three platforms; the estimator (pow, exp, log, hypot in its kernels and
QR) differs on aarch64 by ~1e-13 relative in the estimates and on win64 by ~1e-11 (4e-8 in
its uncertainty figure, a relative error that is itself near rounding level), at most 0.06
of the tolerance. Bit-identical results are reported there, not asserted here: they rest on
two C libraries agreeing to the last bit, which a library update may change.
"""
from __future__ import annotations

import dataclasses
import subprocess
import zipfile

import numpy as np
import pytest

fmpy = pytest.importorskip("fmpy")

from c_hosts import (
    WINDOWS_SYSTEM_DLLS,
    Case,
    HostError,
    build_case_fmus,
    build_container_fmu,
    compile_host,
    container_case,
    host_arguments,
    hosts,
    imported_dlls,
    is_discrete,
    rounding_tolerance,
    run_fmpy,
    run_host,
    standard_cases,
    unavailable,
)

from duffid.cbuild import HOST_PLATFORM, PLATFORMS, fmu_binary_path, resolve_platforms

KINDS = ("plant", "estimator", "controller")
OTHER_PLATFORMS = [name for name, p in PLATFORMS.items() if not p.is_host]


def _case_id(kind: str, version: int) -> str:
    return f"{kind} FMI {version}"


@pytest.fixture(scope="session")
def case_fmus(tmp_path_factory):
    """The plant, estimator and controller FMUs (FMI 2 and 3) with binaries for every
    platform whose compiler is installed, built once by duffid's own builders."""
    platforms, _ = resolve_platforms(None)
    return build_case_fmus(tmp_path_factory.mktemp("c_host_fmus"), platforms)


@pytest.fixture(scope="session")
def cases(case_fmus):
    return {case.name: case for case in standard_cases(case_fmus)}


@pytest.fixture(scope="session")
def work(tmp_path_factory):
    return tmp_path_factory.mktemp("c_host_runs")


@pytest.fixture(scope="session")
def c_hosts(tmp_path_factory):
    """The host for every platform (or why not), one wine prefix for the session."""
    with hosts(tmp_path_factory.mktemp("c_hosts")) as found:
        yield found


@pytest.fixture(scope="session")
def linux_results(c_hosts, cases, work):
    return {name: run_host(c_hosts[HOST_PLATFORM.name], case, work) for name, case in cases.items()}


def _host(c_hosts, name):
    host = c_hosts[name]
    if isinstance(host, str):
        pytest.skip(f"no {name} host: {host}")
    return host


def test_host_usage_errors_exit_2_with_a_message(tmp_path):
    exe = compile_host(HOST_PLATFORM, tmp_path)
    for arguments, message in [([], "expected 6 arguments"),
                               (["d", "4", "b", "t", "0.001", "1"], "VERSION must be 2 or 3, got '4'"),
                               (["d", "2", "b", "t", "0", "1"], "STEP must be positive"),
                               (["d", "2", "b", "t", "0.001", "-1"], "STEPS must be a count"),
                               (["-p", "r5", "d", "2", "b", "t", "0.001", "1"], "-p needs VAR=VALUE, got 'r5'"),
                               (["-o", "x5", "d", "2", "b", "t", "0.001", "1"], "variable 'x5' must start with r"),
                               (["-i", "r1", "d", "2", "b", "t", "0.001", "1"], "-i needs the input CSV of -c"),
                               (["-p", "r1=abc", "d", "2", "b", "t", "0.001", "1"], "-p r1=abc: 'abc' is not a number")]:
        done = subprocess.run([str(exe), *arguments], check=False, capture_output=True, text=True)
        assert done.returncode == 2, arguments
        assert message in done.stderr and "usage:" in done.stderr, (arguments, done.stderr)
    done = subprocess.run([str(exe), "d", "2", str(tmp_path / "none.so"), "t", "0.001", "1"], check=False,
                          capture_output=True, text=True)
    assert done.returncode == 1 and "dlopen(" in done.stderr and "none.so" in done.stderr


def test_a_missing_compiler_or_runner_names_the_debian_package(tmp_path):
    no_compiler = dataclasses.replace(PLATFORMS["win64"], compiler="no-such-mingw-gcc")
    assert unavailable(no_compiler) == ("no-such-mingw-gcc not found or cannot compile "
                                        "(install the Debian package gcc-mingw-w64-x86-64)")
    no_runner = dataclasses.replace(PLATFORMS["aarch64-linux"], compiler=HOST_PLATFORM.compiler,
                                    runner=("no-such-qemu-aarch64",))
    if unavailable(no_runner) is not None and "compile" in unavailable(no_runner):
        pytest.skip(f"no {HOST_PLATFORM.compiler} on PATH")
    assert unavailable(no_runner) == "no-such-qemu-aarch64 not found (install the Debian package qemu-user)"
    with hosts(tmp_path, [no_compiler]) as found:
        assert found == {"win64": unavailable(no_compiler)}


@pytest.mark.slow
@pytest.mark.parametrize("version", (2, 3))
@pytest.mark.parametrize("kind", KINDS)
def test_linux64_host_equals_fmpy(cases, linux_results, kind, version):
    """Same binary, same machine, same calls (fmpy's communication points t0 + k h, inputs set
    in initialisation mode and before each step, its default-experiment tolerance): the C host
    and fmpy agree bit for bit, NaNs included."""
    name = _case_id(kind, version)
    expected = run_fmpy(cases[name])
    got = linux_results[name]
    assert set(got) == set(expected)
    for var, values in expected.items():
        np.testing.assert_array_equal(got[var], values, err_msg=f"{name}: {var}")


#: An estimator whose condition number is above this is singular to rounding (its continuous
#: outputs are rounding noise there), as are its first MIN_ROWS samples (a fit through a handful
#: of samples is exact): as in tests/test_estimator_c.py, they are compared by their NaN
#: patterns only.
SINGULAR_CONDITION = 1e10
MIN_ROWS = 8


def _compared_rows(reference) -> np.ndarray | None:
    """Rows whose continuous outputs are compared (None: all; an estimator: see SINGULAR_CONDITION)."""
    condition = reference.get("condition")
    if condition is None:
        return None
    return (np.arange(len(condition)) >= MIN_ROWS) & (np.asarray(condition) <= SINGULAR_CONDITION)


def _mismatches(c_hosts, case: Case, work, reference, got) -> dict[str, str]:
    """The outputs of ``got`` that differ from the linux64 ``reference`` beyond the conditioning
    of each output (discrete ones and NaN patterns: at all; an estimator's continuous outputs
    where it is not singular to rounding), with where."""
    rows = _compared_rows(reference)
    tolerance = rounding_tolerance(c_hosts[HOST_PLATFORM.name], case, work, reference, rows=rows)
    bad = {}
    for var in case.outputs:
        want, have = reference[var], got[var]
        assert have.shape == want.shape, f"{case.name}: {var} has {have.shape} rows, linux64 {want.shape}"
        if is_discrete(case, var):
            if not np.array_equal(have, want):
                bad[var] = f"differs at rows {np.flatnonzero(have != want)[:5]}"
            continue
        if not np.array_equal(np.isnan(have), np.isnan(want)):
            bad[var] = f"NaN at other rows: {np.flatnonzero(np.isnan(have) != np.isnan(want))[:5]}"
            continue
        compared = np.ones(len(want), bool) if rows is None else rows
        assert np.isfinite(tolerance[var][compared]).all(), f"{case.name}: the one-ulp spread of {var} is not finite"
        with np.errstate(all="ignore"):
            relative = np.where((have == want) | np.isnan(want) | ~compared, 0.0, np.abs(have - want) / np.abs(want))
        ratio = relative / tolerance[var]
        if not ratio.max() <= 1.0:
            row = int(np.argmax(ratio))
            bad[var] = (f"row {row}: {have[row]!r} vs {want[row]!r}, relative {relative[row]:.3g} "
                        f"> tolerance {tolerance[var][row]:.3g}")
    return bad


@pytest.mark.slow
@pytest.mark.parametrize("version", (2, 3))
@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("platform", OTHER_PLATFORMS)
def test_every_platform_matches_linux64(c_hosts, cases, linux_results, work, platform, kind, version):
    """Windows (wine64) and aarch64 (qemu) give the linux64 results within the conditioning of
    each output (module docstring); discrete outputs, NaN patterns and times exactly."""
    host = _host(c_hosts, platform)
    name = _case_id(kind, version)
    case = cases[name]
    reference = linux_results[name]
    got = run_host(host, case, work)
    np.testing.assert_array_equal(got["time"], reference["time"])
    bad = _mismatches(c_hosts, case, work, reference, got)
    assert not bad, f"{name} on {platform}: {bad}"


@pytest.fixture(scope="session")
def container(case_fmus, tmp_path_factory):
    """The case of duffid's container FMU (c_hosts.build_container_fmu)."""
    return container_case(build_container_fmu(case_fmus, tmp_path_factory.mktemp("container")))


@pytest.mark.slow
@pytest.mark.parametrize("platform", list(PLATFORMS))
def test_container_in_every_host(c_hosts, case_fmus, container, work, platform):
    """duffid's container FMU (an FMI 2 plant and an FMI 3 estimator loaded by its runtime from
    its resources) has a binary for every platform its components have; in the C host it equals
    fmpy bit for bit on linux64, and linux64 within the conditioning of each output elsewhere."""
    with zipfile.ZipFile(container.fmu) as z:
        folders = {n.split("/")[1] for n in z.namelist() if n.startswith("binaries/") and n.count("/") == 2}
    with zipfile.ZipFile(case_fmus["plant", 2]) as z:
        assert folders == {n.split("/")[1] for n in z.namelist() if n.startswith("binaries/") and n.count("/") == 2}
    host = _host(c_hosts, platform)
    reference = run_host(c_hosts[HOST_PLATFORM.name], container, work)
    assert reference["identified"][-1] == 1.0 and np.isnan(reference["k_hat"][0])
    if host.platform.is_host:
        expected = run_fmpy(container)
        assert set(expected) == set(reference)
        for var, values in expected.items():
            np.testing.assert_array_equal(reference[var], values, err_msg=var)
        return
    got = run_host(host, container, work)
    np.testing.assert_array_equal(got["time"], reference["time"])
    bad = _mismatches(c_hosts, container, work, reference, got)
    assert not bad, f"container on {platform}: {bad}"


@pytest.mark.slow
@pytest.mark.parametrize("platform", list(PLATFORMS))
def test_numbers_round_trip_through_every_host(c_hosts, cases, work, platform):
    """The host reads and prints doubles exactly on every platform (glibc, mingw-w64's own
    correctly rounded strtod and printf): values set with -p are read back bit for bit."""
    host = _host(c_hosts, platform)
    values = {"r": 0.1, "r_dot": 1 / 3, "r_ddot": -2.2250738585072014e-308, "x": 5e-324,
              "m_hat": 1.7976931348623157e308, "b_hat": -123456789.12345679, "k_hat": 1e-300, "kp_hat": -1237000.0}
    controller = cases[_case_id("controller", 2)]
    case = Case("round trip", controller.fmu, 1e-3, {}, values, list(values))
    got = run_host(host, case, work)
    assert {name: got[name][0] for name in values} == values
    assert got["time"].tolist() == [0.0]


@pytest.mark.slow
@pytest.mark.parametrize("version", (2, 3))
def test_the_host_names_what_failed(c_hosts, cases, work, tmp_path, version):
    """A wrong token, a communication step the estimator refuses and a short input file each
    stop the host with status 1 and a message naming the FMI call or the file."""
    host = c_hosts[HOST_PLATFORM.name]
    case = cases[_case_id("estimator", version)]
    call = "fmi2Instantiate" if version == 2 else "fmi3InstantiateCoSimulation"
    with pytest.raises(HostError, match=f"{call} returned NULL"):
        run_host(host, _with_token(case, "{00000000-0000-0000-0000-000000000000}", tmp_path), work)
    wrong_step = Case(case.name, case.fmu, case.step, case.inputs, {"sample_period": 2e-3}, case.outputs)
    with pytest.raises(HostError, match=f"fmi{version}DoStep at t = 0 returned (Error|Discard)") as failed:
        run_host(host, wrong_step, work)
    assert "sample_period 0.002" in str(failed.value)  # the FMU's own message, on stderr
    arguments = host_arguments(host, case, work)
    arguments[-1] = str(case.steps + 5)
    done = subprocess.run(host.command(arguments), check=False, capture_output=True, text=True)
    assert done.returncode == 1
    assert f"inputs.csv has {case.steps} data rows; {case.steps + 5} steps need {case.steps + 5}" in done.stderr


def _with_token(case: Case, token: str, out_dir) -> Case:
    """``case`` on a copy of its FMU whose modelDescription.xml carries ``token``."""
    md = fmpy.read_model_description(str(case.fmu))
    old = md.guid if md.fmiVersion.startswith("2") else md.instantiationToken
    path = out_dir / case.fmu.name
    with zipfile.ZipFile(case.fmu) as src, zipfile.ZipFile(path, "w") as dst:
        for info in src.infolist():
            data = src.read(info)
            dst.writestr(info, data.replace(old.encode(), token.encode()) if info.filename == "modelDescription.xml"
                         else data)
    return Case(case.name, path, case.step, case.inputs, case.start, case.outputs)


@pytest.mark.slow
@pytest.mark.skipif(unavailable(PLATFORMS["win64"]) is not None, reason="needs the Debian package gcc-mingw-w64-x86-64")
def test_win64_binaries_import_only_windows_dlls(case_fmus, tmp_path):
    """Static runtime linking: each win64 FMU binary imports Windows' own DLLs only (no
    libgcc_s, libwinpthread or other mingw DLL a user would have to install)."""
    for (kind, version), fmu in case_fmus.items():
        md = fmpy.read_model_description(str(fmu))
        inside = fmu_binary_path(md.coSimulation.modelIdentifier, version, PLATFORMS["win64"])
        with zipfile.ZipFile(fmu) as z:
            dll = tmp_path / f"{kind}{version}.dll"
            dll.write_bytes(z.read(inside))
        dlls = imported_dlls(dll)
        assert dlls, f"{fmu.name}: objdump found no imports in {inside}"
        assert {d.lower() for d in dlls} <= WINDOWS_SYSTEM_DLLS, f"{fmu.name}: {inside} imports {dlls}"


#: An equation FMU of the user's own model: a 2-DOF chain with a cubic coupling and a force on
#: each mass (two displacement and two force inputs), the generic C core on its generated model.
EQUATION = ("m1*der(x1,2) + b1*der(x1) + k1*x1 + k2*(x1-x2) + kc*(x1-x2)^3 = f1; "
            "m2*der(x2,2) + b2*der(x2) + k2*(x2-x1) + kc*(x2-x1)^3 = f2")
EQUATION_COLUMNS = ("t", "f1", "f2", "x1", "x2")


@pytest.fixture(scope="session")
def equation_cases(tmp_path_factory):
    """The equation FMU (FMI 2 and 3, binaries for every platform whose compiler is installed)
    over a 1 s record sampled at 1 ms (every parameter published within it), by FMI version."""
    from duffid import Chirp, Step, measure, simulate
    from duffid.fmu.estimator import build_equation_fmu
    from duffid.models.equation_model import EquationModel

    platforms, _ = resolve_platforms(None)
    out = tmp_path_factory.mktemp("equation_fmu")
    model = EquationModel(EQUATION, EQUATION_COLUMNS,
                          values=dict(m1=1.1, b1=2.0, k1=1500.0, k2=800.0, kc=2e6, m2=0.7, b2=1.0))
    record = measure(simulate(model, [Chirp(5.0, 2.0, 20.0, 1.0), Step(3.0) + Chirp(2.0, 3.0, 25.0, 1.0)], 1.0,
                              1e-3), snr_db=60, seed=4)
    inputs = {"x1": record.x[:, 0], "x2": record.x[:, 1], "f1": record.f[:, 0], "f2": record.f[:, 1]}
    cases = {}
    for version in (2, 3):
        fmu = build_equation_fmu(EQUATION, out, name="TwoForces", columns=EQUATION_COLUMNS, fmi_version=version,
                                 backend="c", platforms=platforms)
        outputs = [v.name for v in fmpy.read_model_description(str(fmu)).modelVariables if v.causality == "output"]
        cases[version] = Case(f"equation FMI {version}", fmu, record.dt, inputs, {"sample_period": record.dt},
                              outputs)
    return cases


@pytest.mark.slow
@pytest.mark.parametrize("version", (2, 3))
@pytest.mark.parametrize("platform", list(PLATFORMS))
def test_equation_fmu_in_every_host(c_hosts, equation_cases, work, platform, version):
    """The C host sets two displacement and two force inputs per step: on linux64 it equals fmpy
    bit for bit (every estimate published by the end), elsewhere linux64 within the conditioning
    of each output; discrete outputs, NaN patterns and times exactly."""
    host = _host(c_hosts, platform)
    case = equation_cases[version]
    reference = run_host(c_hosts[HOST_PLATFORM.name], case, work)
    assert reference["identified"][-1] == 1.0 and np.isnan(reference["kc_hat"][0])
    if host.platform.is_host:
        expected = run_fmpy(case)
        assert set(expected) == set(reference)
        for var, values in expected.items():
            np.testing.assert_array_equal(reference[var], values, err_msg=f"{case.name}: {var}")
        return
    got = run_host(host, case, work)
    np.testing.assert_array_equal(got["time"], reference["time"])
    bad = _mismatches(c_hosts, case, work, reference, got)
    assert not bad, f"{case.name} on {platform}: {bad}"
