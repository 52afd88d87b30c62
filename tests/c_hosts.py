"""Running duffid's C FMUs in a host that is not Python, on every platform (shared by
tests/test_c_hosts.py and benchmarks/platforms.py).

The host is tests/c/fmi_host.c, one portable C file for FMI 2 and FMI 3 co-simulation. It
is compiled for this Linux machine (gcc), for 64-bit Windows (mingw-w64, static, run under
wine64) and for aarch64 Linux (run under qemu-aarch64 with the cross C library). Each of
:func:`standard_cases` (a plant, an estimator and a controller FMU, FMI 2 and 3) is run by
each host on the binary of its own platform inside the FMU, and compared with the linux64
result (:func:`compare`) and with fmpy (:func:`run_fmpy`).

Everything here is plain functions over :class:`Case` and :class:`Host`; the tests decide
what to assert, the benchmark what to print.
"""
from __future__ import annotations

import os
import shutil
import subprocess
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import fmpy
import numpy as np
from rounding import EPS, FINAL_SAMPLES, TRIALS, tolerance

from duffid.cbuild import (
    HOST_PLATFORM,
    PLATFORMS,
    Platform,
    fmu_binary_path,
    platform_compiler,
)

__all__ = [
    "HOST_FLAGS",
    "HOST_SOURCE",
    "HOST_TIMEOUT",
    "WINDOWS_SYSTEM_DLLS",
    "Case",
    "Host",
    "HostError",
    "binary_sizes",
    "build_case_fmus",
    "build_container_fmu",
    "compare",
    "compile_host",
    "container_case",
    "extract",
    "host_arguments",
    "hosts",
    "imported_dlls",
    "is_discrete",
    "perturbed_case",
    "rounding_tolerance",
    "run_fmpy",
    "run_host",
    "standard_cases",
    "unavailable",
]

#: The C source of the host.
HOST_SOURCE = Path(__file__).parent / "c" / "fmi_host.c"
#: The FMI 2 and FMI 3 headers (fmpy ships them).
FMI_HEADERS = Path(fmpy.__file__).parent / "c-code"
#: Compiler flags of the host on every platform (strict C99, warnings are errors).
HOST_FLAGS = ("-std=c99", "-O2", "-Wall", "-Wextra", "-Werror", "-pedantic")
#: DLLs every 64-bit Windows has; a win64 FMU binary may import these and nothing else.
WINDOWS_SYSTEM_DLLS = frozenset({"kernel32.dll", "msvcrt.dll", "ucrtbase.dll", "user32.dll", "advapi32.dll",
                                 "ntdll.dll", "ws2_32.dll", "shell32.dll", "ole32.dll"})
#: Seconds a host run may take (the longest case takes well under one, even under qemu or wine).
HOST_TIMEOUT = 120
#: Type letter of the host's variable names, by FMI type.
_TYPE_LETTER = {"Real": "r", "Float64": "r", "Integer": "i", "Int32": "i", "Boolean": "b"}
_WINE_SERVER = Path("/usr/lib/wine/wineserver")


class HostError(RuntimeError):
    """The host exited with an error (the message holds its command line and stderr)."""


@dataclass
class Case:
    """One run of an FMU: inputs sampled on the grid t_k = k * step, start values, outputs.

    Attributes
    ----------
    name : str
        For messages and tables, e.g. ``"plant FMI 2"``.
    fmu : Path
        The FMU file.
    step : float
        Communication step size (s).
    inputs : dict of str to ndarray
        Input name -> one value per step (its value at t_k, held or interpolated by fmpy
        between grid points, which the host never asks for).
    start : dict of str to float
        Start values set before initialisation (parameters).
    outputs : list of str
        Variables recorded after initialisation and after each step.
    """

    name: str
    fmu: Path
    step: float
    inputs: dict[str, np.ndarray]
    start: dict[str, float] = field(default_factory=dict)
    outputs: list[str] = field(default_factory=list)

    @property
    def steps(self) -> int:
        """Number of doStep calls (one per input sample; 0 without inputs)."""
        return len(next(iter(self.inputs.values()))) if self.inputs else 0

    @property
    def fmi_version(self) -> int:
        """2 or 3, from modelDescription.xml."""
        return int(self.model_description.fmiVersion[0])

    @cached_property
    def model_description(self):
        """fmpy's reading of the FMU's modelDescription.xml."""
        return fmpy.read_model_description(str(self.fmu))


@dataclass(frozen=True)
class Host:
    """The host compiled for one platform, and how to run it on this machine."""

    platform: Platform
    executable: Path
    environment: Mapping[str, str] = field(repr=False)

    def native_path(self, path: Path) -> str:
        """``path`` as the host sees it (wine maps the Linux root to drive Z:)."""
        path = Path(path).resolve()
        return "Z:" + str(path).replace("/", "\\") if self.platform.suffix == ".dll" else str(path)

    def command(self, arguments: Sequence[str]) -> list[str]:
        """The command line that runs the host with ``arguments`` on this machine."""
        return [*self.platform.runner, str(self.executable), *arguments]


def unavailable(platform: Platform) -> str | None:
    """Why the host cannot be built or run for ``platform`` here (naming the Debian package to
    install), or None."""
    if platform_compiler(platform) is None:
        return f"{platform.compiler} not found or cannot compile (install the Debian package {platform.package})"
    if platform.runner and shutil.which(platform.runner[0]) is None:
        return f"{platform.runner[0]} not found (install the Debian package {platform.runner_package})"
    return None


def compile_host(platform: Platform, out_dir: Path) -> Path:
    """Compile tests/c/fmi_host.c for ``platform`` into ``out_dir``; the executable's path.

    Windows: ``-static`` (the C runtime inside, nothing to install under wine). aarch64: linked
    dynamically against the cross C library, which qemu-aarch64 finds with ``-L``.
    """
    compiler = platform_compiler(platform)
    if compiler is None:
        raise HostError(f"cannot build the {platform.name} host: {unavailable(platform)}")
    windows = platform.suffix == ".dll"
    exe = Path(out_dir) / f"fmi_host_{platform.name}{'.exe' if windows else ''}"
    exe.parent.mkdir(parents=True, exist_ok=True)
    command = [compiler, *HOST_FLAGS, f"-I{FMI_HEADERS}", str(HOST_SOURCE), "-o", str(exe),
               *(["-static"] if windows else ["-ldl"]), "-lm"]
    done = subprocess.run(command, check=False, capture_output=True, text=True)
    if done.returncode != 0:
        raise HostError(f"compiling the {platform.name} host failed:\n{' '.join(command)}\n{done.stderr}")
    return exe


@contextmanager
def hosts(out_dir: Path, platforms: Sequence[Platform] | None = None) -> Iterator[dict[str, Host | str]]:
    """Build the host for each platform (default: every one of :data:`PLATFORMS`).

    Yields a dict by platform name: the :class:`Host`, or for a platform that cannot be built or
    run here, the reason (naming the Debian package). For Windows it makes a wine prefix in
    ``out_dir`` and keeps one wineserver for it until the context ends (then stopped).
    """
    out_dir = Path(out_dir)
    found: dict[str, Host | str] = {}
    wine_env: dict[str, str] | None = None
    try:
        for platform in platforms or [HOST_PLATFORM, *(p for p in PLATFORMS.values() if not p.is_host)]:
            reason = unavailable(platform)
            if reason is not None:
                found[platform.name] = reason
                continue
            env = dict(os.environ)
            if platform.suffix == ".dll":
                env.update(WINEPREFIX=str(out_dir / "wineprefix"), WINEDEBUG="-all", WINEDLLOVERRIDES="mscoree,mshtml=")
                (out_dir / "wineprefix").mkdir(parents=True, exist_ok=True)
                server = _wine_server()
                # no pipes: the wineserver and wine's services outlive these commands and would hold them
                quiet = {"stdin": subprocess.DEVNULL, "stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
                # one server for every run, stopped at the end (and by itself 30 s after the last
                # run should this process die first)
                if server is not None and subprocess.run([server, "-p30"], env=env, check=False, **quiet).returncode == 0:
                    wine_env = env
                boot = subprocess.run([*platform.runner, "wineboot", "--init"], env=env, check=False, **quiet)
                if boot.returncode != 0:
                    found[platform.name] = f"wineboot failed with exit status {boot.returncode} in {env['WINEPREFIX']}"
                    continue
            found[platform.name] = Host(platform, compile_host(platform, out_dir), env)
        yield found
    finally:
        server = _wine_server()
        if wine_env is not None and server is not None:
            subprocess.run([server, "-k"], env=wine_env, check=False, capture_output=True)


def _wine_server() -> str | None:
    return str(_WINE_SERVER) if _WINE_SERVER.exists() else shutil.which("wineserver")


def extract(fmu: Path, out_dir: Path) -> Path:
    """The FMU unzipped into ``out_dir/<file stem>`` (once; reused when already there)."""
    folder = Path(out_dir) / Path(fmu).stem
    if not (folder / "modelDescription.xml").exists():
        fmpy.extract(str(fmu), str(folder))
    return folder


def _spec(variables: Mapping[str, object], name: str, fmu: Path) -> str:
    if name not in variables:
        raise KeyError(f"{Path(fmu).name} has no variable {name!r}")
    var = variables[name]
    if var.type not in _TYPE_LETTER:
        raise ValueError(f"{Path(fmu).name}: {name} has type {var.type}, which the host does not handle")
    return f"{_TYPE_LETTER[var.type]}{var.valueReference}"


def host_arguments(host: Host, case: Case, work_dir: Path) -> list[str]:
    """The host's arguments for ``case`` on the binary of the host's platform (the last one is
    the number of steps).

    The tolerance passed to the FMU is its default experiment's (as fmpy does); the inputs are
    written to ``inputs.csv`` in a folder of ``work_dir`` with ``repr`` (shortest round-trip
    decimal).
    """
    md = case.model_description
    variables = {v.name: v for v in md.modelVariables}
    folder = extract(case.fmu, work_dir)
    binary = folder / fmu_binary_path(md.coSimulation.modelIdentifier, case.fmi_version, host.platform)
    token = md.guid if case.fmi_version == 2 else md.instantiationToken
    work = Path(work_dir) / f"{case.fmu.stem}_{host.platform.name}"
    work.mkdir(parents=True, exist_ok=True)
    arguments: list[str] = []
    for name, value in case.start.items():
        arguments += ["-p", f"{_spec(variables, name, case.fmu)}={float(value)!r}"]
    names = list(case.inputs)
    if names:
        csv = work / "inputs.csv"
        columns = np.column_stack([np.asarray(case.inputs[n], dtype=float) for n in names])
        csv.write_text(",".join(names) + "\n" + "".join(",".join(repr(float(v)) for v in row) + "\n"
                                                       for row in columns))
        arguments += ["-c", host.native_path(csv)]
    for name in names:
        arguments += ["-i", _spec(variables, name, case.fmu)]
    for name in case.outputs:
        arguments += ["-o", _spec(variables, name, case.fmu)]
    experiment = md.defaultExperiment
    if experiment is not None and experiment.tolerance is not None:
        arguments += ["-r", repr(float(experiment.tolerance))]
    return [*arguments, host.native_path(folder), str(case.fmi_version), host.native_path(binary), token,
            repr(float(case.step)), str(case.steps)]


def run_host(host: Host, case: Case, work_dir: Path) -> dict[str, np.ndarray]:
    """Run ``case`` in ``host`` (:func:`host_arguments`): ``time`` and each output, one row
    after initialisation and one after each step.

    Raises
    ------
    HostError
        If the host exits with an error (naming the FMI call that failed).
    """
    command = host.command(host_arguments(host, case, work_dir))
    try:
        done = subprocess.run(command, check=False, capture_output=True, text=True, env=dict(host.environment),
                              timeout=HOST_TIMEOUT)
    except subprocess.TimeoutExpired as error:
        raise HostError(f"{case.name} on {host.platform.name}: no answer within {HOST_TIMEOUT} s:\n"
                        f"{' '.join(command)}") from error
    if done.returncode != 0:
        raise HostError(f"{case.name} on {host.platform.name}: the host exited with {done.returncode}:\n"
                        f"{' '.join(command)}\n{done.stderr.strip()}")
    lines = done.stdout.splitlines()
    header = lines[0].split(",")
    values = np.array([[float(v) for v in line.split(",")] for line in lines[1:]], ndmin=2)
    labels = dict(zip(header[1:], case.outputs))
    return {"time": values[:, 0], **{labels[h]: values[:, j] for j, h in enumerate(header[1:], start=1)}}


def run_fmpy(case: Case) -> dict[str, np.ndarray]:
    """Run ``case`` through fmpy.simulate_fmu on this machine's binary: ``time`` and each output."""
    md = case.model_description
    types = {v.name: v.type for v in md.modelVariables}
    dtype = [("time", float)] + [(n, bool if types[n] == "Boolean" else
                                  np.int32 if types[n] in ("Integer", "Int32") else float) for n in case.inputs]
    signals = np.zeros(case.steps, dtype=dtype)
    signals["time"] = np.arange(case.steps) * case.step
    for name, values in case.inputs.items():
        signals[name] = values
    start = {n: (bool(v) if types[n] == "Boolean" else int(v) if types[n] in ("Integer", "Int32") else v)
             for n, v in case.start.items()}
    result = fmpy.simulate_fmu(str(case.fmu), start_time=0.0, stop_time=case.steps * case.step,
                               output_interval=case.step, input=signals, start_values=start,
                               output=list(case.outputs))
    return {name: np.asarray(result[name], dtype=float) for name in ["time", *case.outputs]}


def compare(result: Mapping[str, np.ndarray], reference: Mapping[str, np.ndarray]) -> dict[str, tuple[float, float]]:
    """Per variable: (largest absolute, largest relative) difference of ``result`` to ``reference``.

    Values that are equal, or NaN in both, differ by 0; a NaN in one only, or a different number
    of rows, is an infinite difference.
    """
    out = {}
    for name, want in reference.items():
        got = np.asarray(result[name], dtype=float)
        want = np.asarray(want, dtype=float)
        if got.shape != want.shape or not np.array_equal(np.isnan(got), np.isnan(want)):
            out[name] = (np.inf, np.inf)
            continue
        with np.errstate(all="ignore"):
            same = (got == want) | np.isnan(want)
            absolute = np.where(same, 0.0, np.abs(got - want))
            relative = np.where(same, 0.0, absolute / np.abs(want))
        out[name] = (float(absolute.max(initial=0.0)), float(relative.max(initial=0.0)))
    return out


def perturbed_case(case: Case, seed: int) -> Case:
    """``case`` with every Real input sample scaled by (1 + eps * N(0, 1)): a one-ulp
    perturbation, to measure how far rounding moves the outputs (tests/rounding.py)."""
    rng = np.random.default_rng(seed)
    types = {v.name: v.type for v in case.model_description.modelVariables}
    inputs = {n: (np.asarray(v, float) * (1.0 + EPS * rng.standard_normal(len(v))) if types[n] in ("Real", "Float64")
                  else v) for n, v in case.inputs.items()}
    return Case(f"{case.name} (perturbed {seed})", case.fmu, case.step, inputs, dict(case.start), list(case.outputs))


def is_discrete(case: Case, name: str) -> bool:
    """Whether ``name`` is an Integer or Boolean variable of the case's FMU (compared exactly)."""
    return {v.name: v.type for v in case.model_description.modelVariables}[name] in ("Integer", "Int32", "Boolean")


def rounding_tolerance(host: Host, case: Case, work_dir: Path, reference: Mapping[str, np.ndarray],
                       window: int = FINAL_SAMPLES, rows: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Relative tolerance of each Real output at each row, from the computation's own conditioning.

    The case is rerun by ``host`` :data:`rounding.TRIALS` times with every Real input sample
    perturbed by one ulp (:func:`perturbed_case`); the spread of an output at a row is the
    largest relative change (0 where equal or NaN in both, infinite where a 0 becomes nonzero),
    then its largest value over ``window`` rows either side (the sensitivity varies slowly in
    time; a few trials can miss it at one row), and the tolerance :func:`rounding.tolerance`
    of that (:data:`rounding.SAFETY` times it, at least :data:`rounding.FLOOR`). ``rows`` (a
    boolean mask) keeps the spread of those rows only (the others' outputs are not compared).
    """
    spread = {name: np.zeros(len(values)) for name, values in reference.items()
              if name != "time" and not is_discrete(case, name)}
    with np.errstate(divide="ignore", invalid="ignore"):
        for seed in range(TRIALS):
            other = run_host(host, perturbed_case(case, seed), work_dir)
            for name, largest in spread.items():
                base, got = np.asarray(reference[name]), np.asarray(other[name])
                same = (got == base) | (np.isnan(base) & np.isnan(got))
                change = np.where(same | np.isnan(got) | np.isnan(base), 0.0, np.abs(got - base) / np.abs(base))
                spread[name] = np.fmax(largest, change)
    out = {}
    for name, values in spread.items():
        if rows is not None:
            values = np.where(rows, values, 0.0)
        padded = np.pad(values, window, mode="edge")
        out[name] = tolerance(np.lib.stride_tricks.sliding_window_view(padded, 2 * window + 1).max(axis=1))
    return out


def build_case_fmus(out_dir: Path, platforms: Sequence[Platform]) -> dict[tuple[str, int], Path]:
    """The FMUs of :func:`standard_cases` with binaries for ``platforms``, by (kind, FMI version):
    the Modelica plant Oscillator1DOF, DuffingEstimator1 and AdaptiveController1, each FMI 2 and 3,
    built by duffid's own builders."""
    from duffid.control.controller_fmu import build_controller_fmu
    from duffid.fmu.estimator import build_estimator_fmu
    from duffid.modelica.export import build_all

    out_dir = Path(out_dir)
    plant2, plant3 = build_all(out_dir, ("Oscillator1DOF",), platforms)
    fmus = {("plant", 2): plant2, ("plant", 3): plant3}
    for version in (2, 3):
        fmus["estimator", version] = build_estimator_fmu("duffing1", out_dir, version, platforms=platforms)
        fmus["controller", version] = build_controller_fmu(1, out_dir, version, platforms=platforms)
    return fmus


def build_container_fmu(fmus: Mapping[tuple[str, int], Path], out_dir: Path) -> Path:
    """The FMI 2 plant and the FMI 3 estimator of :func:`build_case_fmus` in one container FMU
    (duffid's runtime, with binaries for every platform they have): input ``f`` drives both,
    the plant's x is connected to the estimator; outputs x, k_hat and identified."""
    from duffid.cosim.system import System

    system = (System().add("plant", fmus["plant", 2]).add("estimator", fmus["estimator", 3], {"sample_period": 1e-3})
              .connect("plant.x", "estimator.x"))
    return system.export_container(Path(out_dir) / "PlantEstimator.fmu", inputs={"f": ["plant.f", "estimator.f"]},
                                   outputs={"x": "plant.x", "k_hat": "estimator.k_hat",
                                            "identified": "estimator.identified"}, step=1e-3)


def container_case(fmu: Path) -> Case:
    """The container of :func:`build_container_fmu` under a 10 N step for 0.5 s at 1 ms (the
    estimator publishes its first estimate within it)."""
    return Case("container FMI 2", fmu, 1e-3, {"f": np.full(500, 10.0)}, {}, ["x", "k_hat", "identified"])


def standard_cases(fmus: Mapping[tuple[str, int], Path]) -> list[Case]:
    """The same inputs for each FMU kind and FMI version (fixed, deterministic):

    - plant (Oscillator1DOF, its embedded Dormand-Prince integrator): a force of 4 N plus a
      10 N, 5 Hz sine, 0.5 s at 1 ms; outputs x, v;
    - estimator (DuffingEstimator1): the paper's 1-DOF plant under a 10 N step, 1 s at 1 ms,
      encoder quantised (every estimate is published within the record), ``sample_period`` =
      1 ms; every output;
    - controller (AdaptiveController1): chirp excitation, reference 5 mm, the first 0.4 s of
      that record's x and the plant's true parameters as estimates, identified from 0.1 s, at
      1 ms (it switches to control at 0.2 s); every output.
    """
    from duffid import Duffing1, Step, measure, simulate

    dt = 1e-3
    record = measure(simulate(Duffing1(), Step(10.0), 1.0, dt))
    t_plant = np.arange(500) * dt
    t_ctrl = np.arange(400) * dt
    x_ctrl = record.x[:400, 0]
    truth = Duffing1().parameters
    cases = []

    def outputs(fmu: Path) -> list[str]:
        return [v.name for v in fmpy.read_model_description(str(fmu)).modelVariables if v.causality == "output"]

    for version in (2, 3):

        cases.append(Case(f"plant FMI {version}", fmus["plant", version], dt,
                          {"f": 4.0 + 10.0 * np.sin(2 * np.pi * 5.0 * t_plant)}, {}, ["x", "v"]))
        cases.append(Case(f"estimator FMI {version}", fmus["estimator", version], dt,
                          {"x": np.ravel(record.x), "f": np.ravel(record.f)},
                          {"sample_period": dt}, outputs(fmus["estimator", version])))
        inputs = {"r": np.full(400, 0.005), "r_dot": np.zeros(400), "r_ddot": np.zeros(400), "x": np.ravel(x_ctrl),
                  **{f"{p}_hat": np.full(400, float(v)) for p, v in truth.items()},
                  "identified": (t_ctrl >= 0.1).astype(float)}
        cases.append(Case(f"controller FMI {version}", fmus["controller", version], dt, inputs,
                          {"excitation": 1, "sample_period": dt}, outputs(fmus["controller", version])))
    return cases


def imported_dlls(dll: Path) -> list[str]:
    """The DLL names a Windows binary imports (``x86_64-w64-mingw32-objdump -p``)."""
    objdump = shutil.which("x86_64-w64-mingw32-objdump")
    if objdump is None:
        raise HostError("x86_64-w64-mingw32-objdump not found (install the Debian package binutils-mingw-w64-x86-64)")
    done = subprocess.run([objdump, "-p", str(dll)], capture_output=True, text=True, check=True)
    return [line.split("DLL Name:", 1)[1].strip() for line in done.stdout.splitlines() if "DLL Name:" in line]


def binary_sizes(fmu: Path) -> dict[str, int]:
    """Size in bytes of the FMU's binary for each platform it carries, by platform name."""
    import zipfile

    md = fmpy.read_model_description(str(fmu))
    version = int(md.fmiVersion[0])
    with zipfile.ZipFile(fmu) as z:
        infos = {i.filename: i.file_size for i in z.infolist()}
    return {p.name: infos[path] for p in PLATFORMS.values()
            if (path := fmu_binary_path(md.coSimulation.modelIdentifier, version, p)) in infos}
