"""The C estimator core on a Cortex-M4F under QEMU: agreement with x86, instructions per
update, flash, RAM, and an x86 per-sample time against a QR-RLS floor.

Run: python benchmarks/embedded.py [--quick] [--samples N] [--models duffing1,duffing2]
         [--method robust|paper] [--precisions double,float] [--repeats 5] [--no-timing]
         [--no-accuracy | --accuracy-only] [--no-record-cache] [--core DIR] [--build DIR]

Two simulated records (generated here with duffid's simulator, written as a C header into the
build directory, never committed): a hardening 1-DOF plant (m 1.2 kg, b 3 N s/m, k 4500 N/m,
kp 4e7 N/m^3) and a 2-DOF chain, both under a band-limited random multisine force, 1 kHz,
60 dB displacement noise. For each model and each precision the core supports (double, and
float with -DDUFFID_REAL=float, detected by compiling a probe)
the test program tests/embedded/embedded_test.c is built twice from the same source:

- bare metal for QEMU's mps2-an386 (Cortex-M4F, arm-none-eabi-gcc -mcpu=cortex-m4
  -mfpu=fpv4-sp-d16 -mfloat-abi=hard -O2 -fno-math-errno -ffp-contract=off), run under qemu-system-arm
  with the TCG plugin tests/embedded/insn_plugin.c (instructions per update, and per block
  inside updates: the functions where the time goes);
- natively (gcc -O2 -ffp-contract=off).

Per build it prints: the ARM/x86 agreement (statuses and identified flags at every sample
must be identical; values are compared bit for bit and within TOLERANCE_ULPS, see there), the
instructions per update (mean over the steady state, i.e. after the first full window, and
over all samples; the worst and its sample), flash of the core (text + rodata + data): as
linked into the test program (its input sections that --gc-sections kept, from the linker
map: what a firmware carries), the libm/libc/libgcc members it pulls in, and its object files
before linking; RAM (duffid_memory_size, stack high-water mark from a painted stack), a check
list (heap calls, soft-double helpers, 64-bit division helpers, libm sqrt inside updates) and
the top functions by instructions inside updates (a translated block counts for the function
it starts in; calls are executions of a block at a function's entry).

x86 section: ns per sample of duffid_update (native build, median of --repeats runs, min-max)
against a floor measured in the same run: square-root RLS by Givens rotations of a 5x5
triangular factor (4 unknowns + right-hand side), 8 rows per sample, one back substitution
per sample (tests/embedded/qr_rls_floor.c), in double and float; the ratio duffid/floor.

Float against double (issue 28; needs only the host's C compiler): every record of
benchmarks/trust.py through CIdentifier(precision="double") and (precision="float"), robust
method, default options. Wherever the float build publishes a parameter and both builds
estimate over the same window (|window_float - window_double| < dt/2; after the automatic
window is fixed at different samples they estimate over different windows, a statistical, not
an arithmetic, difference) it must satisfy |v_float - current_double| <= uncertainty_float
|v_float| (current_double: the double build's solution at that sample, published or not;
uncertainty_float: the float build's stated uncertainty). Per record: parameter-samples
published by each build and compared, the largest ratio, the violations (ratio > 1), the
largest error of a float-published value against the truth; then the violations in all (the
exit status is 1 if any), the largest ratio and the share of the double build's published
parameter-samples the float build publishes too. Each record runs a second time with the
window fixed at the double build's automatic one, so that both builds estimate over the same
windows at every sample and every value the float build publishes is compared. The simulated
records are cached in
build/trust_records (keyed by the hash of trust.py, duffid's sources and the numerical
libraries' versions; simulating all of them takes about 3 minutes, the comparison seconds).

Needs the Debian packages gcc-arm-none-eabi, libnewlib-arm-none-eabi and qemu-system-arm.
"""
from __future__ import annotations

import argparse
import bisect
import math
import os
import re
import shutil
import statistics
import struct
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
EMBEDDED = ROOT / "tests" / "embedded"
#: The core's sources: fmus/estimator, or the directory in $DUFFID_EMBEDDED_CORE (another
#: version of the core, e.g. a checkout of an older commit's fmus/estimator).
CORE = Path(os.environ.get("DUFFID_EMBEDDED_CORE", ROOT / "fmus" / "estimator")).resolve()
CORE_FILES = ("duffid_estimator.c", "duffid_linalg.c")
#: The buffered identifier's module (method "buffered"); its tables are generated per record.
BUFFERED_FILES = ("duffid_buffered.c", "duffid_linalg.c")
BUFFERED_TABLES = "duffid_buffered_tables.c"
#: Samples per record of --quick (and of tests/test_embedded.py): past the first full window
#: of both models and the span of another, so that the double builds publish values.
QUICK_SAMPLES = 400


def core_sources(core: Path, method: str = "robust") -> tuple[Path, ...]:
    return tuple(core / name for name in (BUFFERED_FILES if method == "buffered" else CORE_FILES))

#: Compiler flags of the target build (Cortex-M4F, single-precision FPU, hard-float ABI).
ARM_FLAGS = ("-mcpu=cortex-m4", "-mfpu=fpv4-sp-d16", "-mfloat-abi=hard", "-mthumb", "-O2", "-fno-math-errno",
             "-ffp-contract=off", "-ffunction-sections", "-fdata-sections", "-std=c99",
             "-Wall", "-Wextra")
#: Compiler flags of the host build of the same program.
HOST_FLAGS = ("-O2", "-ffp-contract=off", "-std=c99", "-Wall", "-Wextra")
#: Every heap entry point is wrapped: a call is counted by the program and fails.
WRAP = "-Wl,--wrap=malloc,--wrap=calloc,--wrap=realloc,--wrap=free"
QEMU = ("qemu-system-arm", "-M", "mps2-an386", "-nographic", "-monitor", "none", "-serial", "none")
#: Seconds a QEMU run may take.
QEMU_TIMEOUT = 1800

#: The tools and the Debian package that provides each.
TOOLS = {"arm-none-eabi-gcc": "gcc-arm-none-eabi", "arm-none-eabi-nm": "binutils-arm-none-eabi",
         "arm-none-eabi-size": "binutils-arm-none-eabi", "qemu-system-arm": "qemu-system-arm",
         "gcc": "gcc"}

#: Agreement of values between the ARM and the x86 build of one precision. Both builds use
#: IEEE arithmetic without contraction (-ffp-contract=off), so every + - * / and sqrt is the
#: same; the libm functions (newlib's vs glibc's pow, exp, log, hypot) may differ by an ulp,
#: and such a difference is amplified by the conditioning of the least-squares problems. A
#: value agrees when it has the same bits, or both are NaN, or
#:     |a - b| <= TOLERANCE_ULPS * eps * max(1, condition) * max(|a|, |b|)
#: with eps the real type's machine epsilon and condition the larger of the two builds'
#: reported condition numbers at that sample (about 12x the largest seen with today's core).
#: The uncertainty (a relative standard error) is compared the same way while either value is
#: at most UNCERTAINTY_CAP (100 %); above it the fit is undetermined, its residual pure
#: rounding, and both must merely be above the cap. Statuses, identified flags, return codes
#: and NaN patterns must be identical.
TOLERANCE_ULPS = 1e6
EPS = {"double": 2.0**-52, "float": 2.0**-23}
TOLERANCE = {real: TOLERANCE_ULPS * eps for real, eps in EPS.items()}
UNCERTAINTY_CAP = 1.0

MODELS = {"duffing1": "DUFFID_DUFFING1", "duffing2": "DUFFID_DUFFING2"}
METHODS = {"robust": "DUFFID_ROBUST", "paper": "DUFFID_PAPER", "buffered": "2"}
REAL_C = {"double": "double", "float": "float"}

# Library functions, by name (libgcc's ARM EABI helpers, newlib's libm). A helper's *calls*
# are the entries of the names the compiler calls (__aeabi_*); its *code* includes the
# internal routines those call (__cmpdf2 under __aeabi_dcmpeq, __udivmoddi4 under
# __aeabi_uldivmod).
SOFT_DOUBLE_CALLS = re.compile(r"^__aeabi_(d(add|sub|rsub|mul|div|neg|cmp(eq|lt|le|ge|gt|un))|"
                               r"u?[il]2d|f2d|d2(u?iz|u?lz|f))$")
SOFT_DOUBLE_CODE = re.compile(r"^__aeabi_(c?d|c?dr|u?[il]2d|f2d|d2)|^__(add|sub|mul|div|neg)df3$|"
                              r"^__(cmp|eq|ne|lt|le|gt|ge|un|unord)df2$|^__(fix|fixuns)df|^__float(un)?[sd]idf$|"
                              r"^__(extendsfdf2|truncdfsf2)$")
LONG_DIVISION_CALLS = re.compile(r"^__aeabi_u?ldivmod$")
LONG_DIVISION_CODE = re.compile(r"^__aeabi_u?ldivmod$|^__(u?divdi3|u?moddi3|u?divmoddi4)$|^__gnu_[su]?ldivmod")
# Software square roots: newlib's sqrt/sqrtf (and hypot) compute them in __ieee754_sqrt[f].
SQRT_CALLS = re.compile(r"^__ieee754_sqrtf?$")
SQRT_FALLBACK = re.compile(r"^sqrtf?$")
HEAP = re.compile(r"^(__wrap_|__real_|_)?(malloc|calloc|realloc|free)(_r)?$")


class Unavailable(RuntimeError):
    """A tool the benchmark needs is missing (the message names its Debian package)."""


def missing_tools() -> list[str]:
    """'tool (Debian package)' for every missing tool, [] when all are there."""
    missing = [f"{tool} (Debian package {package})" for tool, package in TOOLS.items()
               if shutil.which(tool) is None]
    if shutil.which("arm-none-eabi-gcc") is not None:
        libc = subprocess.run(["arm-none-eabi-gcc", *ARM_FLAGS[:4], "-print-file-name=libc.a"],
                              capture_output=True, text=True).stdout.strip()
        if not Path(libc).is_absolute() or not Path(libc).exists():
            missing.append("newlib's libc.a for Cortex-M4F (Debian package libnewlib-arm-none-eabi)")
    return missing


def _run(cmd: list[str], **kwargs) -> subprocess.CompletedProcess:
    result = subprocess.run(cmd, capture_output=True, text=True, **kwargs)
    if result.returncode != 0 and kwargs.get("check_rc", True):
        raise RuntimeError(f"command failed ({result.returncode}): {' '.join(map(str, cmd))}\n"
                           f"{result.stdout[-3000:]}\n{result.stderr[-3000:]}")
    return result


# ---------------------------------------------------------------------------------- records

@dataclass
class RecordData:
    name: str
    x: np.ndarray       # (n, n_dof)
    f: np.ndarray       # (n, n_forces)
    dt: float
    truth: dict[str, float]


def make_record(model: str, samples: int | None, seconds: float = 3.0, change: bool = False) -> RecordData:
    """The record of ``model`` (duffing1: a hardening 1-DOF plant; duffing2: a 2-DOF chain),
    band-limited random force, 1 kHz, 60 dB displacement noise; ``samples`` samples (default
    ``seconds`` s). With ``change``, the (first) stiffness steps by +25 % at a third of the
    record: after the change test's flag, its estimator works with a line in time (the cost of
    a plant that changes)."""
    from duffid import Duffing1, Duffing2, Multisine, measure, simulate

    dt = 1e-3
    n = int(round(seconds / dt)) + 1 if samples is None else int(samples)
    duration = (n - 1) * dt
    if model == "duffing1":
        plant = Duffing1(m=1.2, b=3.0, k=4500.0, kp=4e7)
        force = Multisine(20.0, 2.0, 25.0, 1.5, phases="random", seed=3)
    else:
        plant = Duffing2(m1=1.0, b1=2.0, k1=3000.0, kp1=2e7, m2=0.6, b2=1.5, k2=1800.0, kp2=1e7)
        force = Multisine(15.0, 2.0, 30.0, 1.5, phases="random", seed=5)
    stiffness = "k" if model == "duffing1" else "k1"
    changes = [(duration / 3, type(plant)(**{**plant.parameters, stiffness: 1.25 * plant.parameters[stiffness]}))]
    record = simulate(plant, force, duration, dt, changes=changes if change else ())
    record = measure(record, pulses_per_cm=None, snr_db=60.0, seed=17)
    return RecordData(model, np.asarray(record.x)[:n], np.asarray(record.f)[:n], dt, dict(plant.parameters))


def write_record_header(path: Path, record: RecordData) -> None:
    """The record as C: sizes, dt and the values as hexadecimal double literals (exact)."""
    def values(a: np.ndarray) -> str:
        flat = [float(v).hex() for v in np.ravel(a)]
        return ", \\\n    ".join(", ".join(flat[i:i + 6]) for i in range(0, len(flat), 6))

    n, n_dof = record.x.shape
    path.write_text(
        f"/* generated by benchmarks/embedded.py: record {record.name}, {n} samples */\n"
        f"#define RECORD_N {n}L\n#define RECORD_NDOF {n_dof}\n#define RECORD_NFORCES {record.f.shape[1]}\n"
        f"#define RECORD_DT {float(record.dt).hex()}\n"
        f"#define RECORD_X \\\n    {values(record.x)}\n#define RECORD_F \\\n    {values(record.f)}\n")


def write_buffered_tables(path: Path, model: str, dt: float) -> None:
    """The buffered identifier's C tables for ``model`` at ``dt`` (BufferedIdentifier's defaults:
    Legendre, 24 functions, a 0.25 s window, Gauss quadrature)."""
    from duffid import Duffing1, Duffing2
    from duffid.identification.buffered import BufferedIdentifier
    from duffid.identification.c_buffered import tables_source

    plant = Duffing1() if model == "duffing1" else Duffing2()
    path.write_text(tables_source(BufferedIdentifier(plant, dt, "legendre"), plant))


# ----------------------------------------------------------------------------------- builds

@dataclass
class Build:
    model: str
    method: str
    real: str
    elf: Path
    host: Path
    core_objects: list[Path]


def core_supports(real: str, build_dir: Path, core: Path = CORE) -> bool:
    """Whether the core's API uses ``real`` with -DDUFFID_REAL=<real> (double: always)."""
    if real == "double":
        return True
    probe = build_dir / f"probe_{real}.c"
    probe.write_text('#include "duffid_estimator.h"\n'
                     "typedef char real_is_%s[sizeof(((duffid_output *)0)->condition) == sizeof(%s) ? 1 : -1];\n"
                     % (real, real))
    result = subprocess.run(["gcc", "-std=c99", f"-DDUFFID_REAL={real}", "-DDUFFID_NO_STDIO", f"-I{core}",
                             "-fsyntax-only", str(probe), *map(str, core_sources(core))],
                            capture_output=True, text=True)
    return result.returncode == 0


def _defines(model: str, method: str, real: str) -> list[str]:
    flags = [f"-DEMBEDDED_MODEL={MODELS[model]}", f"-DEMBEDDED_METHOD={METHODS[method]}", "-DDUFFID_NO_STDIO"]
    if method == "buffered":
        flags.append("-DEMBEDDED_BUFFERED")
    if real != "double":
        flags.append(f"-DDUFFID_REAL={REAL_C[real]}")
    return flags


def build_program(build_dir: Path, record_dir: Path, model: str, method: str, real: str,
                  core: Path = CORE, extra: tuple[str, ...] = (), tag: str = "") -> Build:
    """The test program for the target (ELF) and the host (executable); ``extra`` flags
    (e.g. -DEMBEDDED_HEAP_PROBE) go to both."""
    out = build_dir / f"{model}_{method}_{real}{tag}"
    out.mkdir(parents=True, exist_ok=True)
    defines = [*_defines(model, method, real), *extra]
    includes = [f"-I{core}", f"-I{EMBEDDED}", f"-I{record_dir}"]
    objects = []
    sources = core_sources(core, method)
    if method == "buffered":
        sources = (*sources, record_dir / BUFFERED_TABLES)
    for source in (*sources, EMBEDDED / "embedded_test.c", EMBEDDED / "startup.c"):
        obj = out / (source.stem + ".o")
        _run(["arm-none-eabi-gcc", *ARM_FLAGS, *defines, *includes, "-c", str(source), "-o", str(obj)])
        objects.append(obj)
    elf = out / "embedded_test.elf"
    _run(["arm-none-eabi-gcc", *ARM_FLAGS, "-nostartfiles", "-T", str(EMBEDDED / "an386.ld"),
          "-Wl,--gc-sections", WRAP, f"-Wl,-Map={out / 'embedded_test.map'}", "-o", str(elf),
          *map(str, objects), "-lm", "-lc", "-lgcc"])
    host = out / "embedded_test_x86"
    _run(["gcc", *HOST_FLAGS, *defines, *includes, WRAP, "-o", str(host), str(EMBEDDED / "embedded_test.c"),
          *map(str, sources), "-lm"])
    return Build(model, method, real, elf, host, objects[:len(sources)])


def build_plugin(build_dir: Path) -> Path:
    plugin = build_dir / "insn_plugin.so"
    _run(["gcc", "-std=c11", "-O2", "-Wall", "-Wextra", "-Werror", "-fPIC", "-shared", "-fvisibility=hidden",
          "-o", str(plugin), str(EMBEDDED / "insn_plugin.c")])
    return plugin


def build_floor(build_dir: Path, record_dir: Path, real: str) -> Path:
    exe = build_dir / f"qr_rls_floor_{real}"
    _run(["gcc", *HOST_FLAGS, f"-DFLOOR_REAL={REAL_C[real]}", f"-I{record_dir}", "-o", str(exe),
          str(EMBEDDED / "qr_rls_floor.c"), "-lm"])
    return exe


# --------------------------------------------------------------------------------- outputs

@dataclass
class Sample:
    rc: int
    identified: int
    status: tuple[int, ...]
    values: list[str]           # hex bit patterns: parameters, current, condition, uncertainty, window


@dataclass
class Output:
    samples: list[Sample]
    memory_size: int = -1
    heap_calls: int = -1
    heap_during: int = -1
    stack_used: int = -1
    end: int = -1
    exit_code: int = -1
    real_bytes: int = 8
    n_parameters: int = 0
    init_failed: str = ""          # "RC message" when duffid_init failed

    def value(self, i: int, j: int) -> float:
        fmt = ">d" if self.real_bytes == 8 else ">f"
        return struct.unpack(fmt, bytes.fromhex(self.samples[i].values[j]))[0]

    def window(self, i: int) -> float:
        return self.value(i, len(self.samples[i].values) - 1)

    def condition(self, i: int) -> float:
        return self.value(i, len(self.samples[i].values) - 3)


def parse_output(text: str, exit_code: int) -> Output:
    out = Output([], exit_code=exit_code)
    for line in text.splitlines():
        words = line.split()
        if not words:
            continue
        if words[0] == "S":
            status = tuple(int(s) for s in words[4].split(","))
            values = [v for group in words[5:] for v in group.split(",")]
            out.samples.append(Sample(int(words[2]), int(words[3]), status, values))
            out.n_parameters = len(status)
        elif words[0] == "info":
            fields = dict(w.split("=") for w in words[1:])
            out.real_bytes = int(fields["real_bytes"])
        elif words[0] == "init_failed":
            out.init_failed = " ".join(words[1:])
        elif words[0] == "memory_size":
            out.memory_size = int(words[1])
        elif words[0] == "heap_calls":
            out.heap_calls, out.heap_during = int(words[1]), int(words[2])
        elif words[0] == "stack_used":
            out.stack_used = int(words[1])
        elif words[0] == "end":
            out.end = int(words[1])
    return out


def _preferred(names: list[str]) -> str:
    """One name for symbols at one address: the EABI name the compiler calls, else the first."""
    return sorted(names, key=lambda n: (not n.startswith("__aeabi_"), n.startswith("__"), n))[0]


def nm_symbols(elf: Path) -> tuple[int, int, list[tuple[int, int, str]]]:
    """(begin marker, end marker, sorted (address, end address, name) of the code symbols, one
    per address; a symbol without a size (libgcc's assembler) extends to the next one)."""
    text = _run(["arm-none-eabi-nm", "-S", "--defined-only", str(elf)]).stdout
    by_address: dict[int, list[str]] = {}
    sizes: dict[int, int] = {}
    for line in text.splitlines():
        words = line.split()
        if len(words) == 4 and words[2] in "tTwW":
            address, size, name = int(words[0], 16) & ~1, int(words[1], 16), words[3]
        elif len(words) == 3 and words[1] in "tTwW":
            address, size, name = int(words[0], 16) & ~1, 0, words[2]
        else:
            continue
        if name.startswith("$"):
            continue
        by_address.setdefault(address, []).append(name)
        sizes[address] = max(sizes.get(address, 0), size)
    addresses = sorted(by_address)
    functions = []
    for i, address in enumerate(addresses):
        following = addresses[i + 1] if i + 1 < len(addresses) else address + max(sizes[address], 2)
        end_address = address + sizes[address] if sizes[address] else following
        functions.append((address, end_address, _preferred(by_address[address])))
    names = {name: address for address, names_ in by_address.items() for name in names_}
    return names.get("embedded_mark_begin", -1), names.get("embedded_mark_end", -1), functions


@dataclass
class Profile:
    updates: list[int]
    total: int
    unmatched: int
    instructions: dict[str, int] = field(default_factory=dict)   # per function, inside updates
    calls: dict[str, int] = field(default_factory=dict)          # entries, inside updates


def parse_profile(path: Path, functions: list[tuple[int, int, str]]) -> Profile:
    updates: list[int] = []
    profile = Profile(updates, 0, 0)
    starts = [f[0] for f in functions]
    for line in path.read_text().splitlines():
        words = line.split()
        if words[0] == "update":
            updates.append(int(words[2]))
        elif words[0] == "block":
            vaddr, n, execs = int(words[1], 16) & ~1, int(words[2]), int(words[3])
            k = bisect.bisect_right(starts, vaddr) - 1
            name = "?"
            if k >= 0 and vaddr < functions[k][1]:
                name = functions[k][2]
            profile.instructions[name] = profile.instructions.get(name, 0) + n * execs
            if k >= 0 and vaddr == functions[k][0]:
                profile.calls[name] = profile.calls.get(name, 0) + execs
        elif words[0] == "total":
            profile.total = int(words[1])
        elif words[0] == "unmatched":
            profile.unmatched = int(words[1])
    return profile


def run_arm(build: Build, plugin: Path) -> tuple[Output, Profile]:
    begin, end, functions = nm_symbols(build.elf)
    if begin < 0 or end < 0:
        raise RuntimeError(f"{build.elf}: marker functions not found")
    semi = build.elf.with_suffix(".out")
    prof = build.elf.with_suffix(".plugin")
    for p in (semi, prof):
        p.unlink(missing_ok=True)
    result = subprocess.run(
        [*QEMU, "-chardev", f"file,id=semi,path={semi}", "-semihosting-config", "enable=on,target=native,chardev=semi",
         "-plugin", f"{plugin},begin={begin:#x},end={end:#x},out={prof}", "-kernel", str(build.elf)],
        capture_output=True, text=True, timeout=QEMU_TIMEOUT)
    if not semi.exists() or not prof.exists():
        raise RuntimeError(f"qemu produced no output (exit {result.returncode}): {result.stderr[-2000:]}")
    return parse_output(semi.read_text(), result.returncode), parse_profile(prof, functions)


def run_host(build: Build) -> Output:
    result = subprocess.run([str(build.host)], capture_output=True, text=True, timeout=600)
    return parse_output(result.stdout, result.returncode)


# ------------------------------------------------------------------------------- comparison

@dataclass
class Comparison:
    samples: int
    status_mismatches: int          # samples whose rc, identified or statuses differ
    first_status_mismatch: int      # -1: none
    values: int                     # values compared
    bit_identical: int              # same bits, or both NaN
    nan_mismatches: int
    out_of_tolerance: int
    first_difference: int           # sample of the first value that is not bit-identical, -1: none
    max_scaled: dict[str, float]    # per group: largest |a-b| / (eps max(1, condition) max(|a|,|b|))
    tolerance: float                # TOLERANCE_ULPS

    @property
    def ok(self) -> bool:
        return (self.samples > 0 and self.status_mismatches == 0 and self.nan_mismatches == 0
                and self.out_of_tolerance == 0)


GROUPS = ("estimates", "condition", "uncertainty", "window")


def compare(a: Output, b: Output, real: str) -> Comparison:
    """ARM output ``a`` against x86 output ``b`` (see TOLERANCE_ULPS)."""
    eps = EPS[real]
    n = min(len(a.samples), len(b.samples))
    status_mismatch, first_status, values, identical, nan_mm, out_tol, first_diff = 0, -1, 0, 0, 0, 0, -1
    worst = dict.fromkeys(GROUPS, 0.0)
    if len(a.samples) != len(b.samples):
        status_mismatch += abs(len(a.samples) - len(b.samples))
    for i in range(n):
        sa, sb = a.samples[i], b.samples[i]
        if (sa.rc, sa.identified, sa.status) != (sb.rc, sb.identified, sb.status):
            status_mismatch += 1
            first_status = i if first_status < 0 else first_status
        condition = max([1.0, *(abs(c) for c in (a.condition(i), b.condition(i)) if math.isfinite(c))])
        m = len(sa.values)
        for j in range(m):
            group = GROUPS[0] if j < m - 3 else GROUPS[j - (m - 3) + 1]
            values += 1
            if sa.values[j] == sb.values[j]:
                identical += 1
                continue
            first_diff = i if first_diff < 0 else first_diff
            x, y = a.value(i, j), b.value(i, j)
            if math.isnan(x) or math.isnan(y):
                if math.isnan(x) and math.isnan(y):
                    identical += 1      # both NaN (a NaN's bits may differ between the targets)
                else:
                    nan_mm += 1
                continue
            if group == "uncertainty" and min(x, y) > UNCERTAINTY_CAP:
                continue
            if math.isinf(x) or math.isinf(y):
                out_tol += 1
                continue
            scale = max(abs(x), abs(y))
            scaled = abs(x - y) / (eps * condition * scale)
            worst[group] = max(worst[group], scaled)
            if scaled > TOLERANCE_ULPS:
                out_tol += 1
    return Comparison(n, status_mismatch, first_status, values, identical, nan_mm, out_tol, first_diff, worst,
                      TOLERANCE_ULPS)


# ------------------------------------------------------------------------------------ sizes

def object_sizes(objects: list[Path]) -> dict[str, int]:
    """Bytes of text (code + rodata), data and bss of the core's object files."""
    text = _run(["arm-none-eabi-size", "-A", *map(str, objects)]).stdout
    sizes = {"text": 0, "rodata": 0, "data": 0, "bss": 0}
    for line in text.splitlines():
        words = line.split()
        if len(words) < 2 or not words[1].isdigit():
            continue
        name, size = words[0], int(words[1])
        for key in ("text", "rodata", "data", "bss"):
            if name == f".{key}" or name.startswith(f".{key}."):
                sizes[key] += size
    return sizes


#: An input section in the memory map of a linker map file: its name (on the line before when
#: it is long), address, size and file ("archive(member)" for a library member).
_MAP_SECTION = re.compile(r"^ (\.\S+)?\s+0x([0-9a-f]+)\s+0x([0-9a-f]+)\s+(\S.*)$")
_MAP_NAME = re.compile(r"^ (\.\S+)$")


def linked_sizes(map_file: Path, objects: list[Path]) -> tuple[dict[str, int], dict[str, int]]:
    """Bytes of text, rodata, data and bss as linked.

    Parameters
    ----------
    map_file : Path
        The linker's map file (-Wl,-Map) of the program.
    objects : list of Path
        The core's object files, as they were given to the linker.

    Returns
    -------
    core, library : dict
        ``{"text", "rodata", "data", "bss"}`` bytes of the core's and of the library code
        linked for the core.

    Notes
    -----
    The core's: its objects' input sections that --gc-sections kept, read from the linker map
    file (what a firmware linking the core carries). The library's: the input sections of the
    libm, libc and libgcc members the core pulled in (the map's "Archive member included to
    satisfy reference by" list: members the core's objects referenced, and the members those
    referenced in turn; a member the program would need anyway counts for the core when the
    core's objects, linked first, referenced it first).
    """
    lines = map_file.read_text().splitlines()
    core = {str(o) for o in objects} | {str(o.resolve()) for o in objects}
    try:
        start = lines.index("Linker script and memory map")
    except ValueError:
        raise RuntimeError(f"{map_file}: no memory map") from None
    pulled: set[str] = set()
    member = None
    for line in lines[:start]:
        if line and not line[0].isspace():
            member = line.strip() if "(" in line else None
        elif member is not None and line.strip():
            referrer = line.strip().rsplit(" (", 1)[0]
            if referrer in core or referrer in pulled:
                pulled.add(member)
            member = None
    sizes = {"text": 0, "rodata": 0, "data": 0, "bss": 0}
    library = dict(sizes)
    name = None
    for line in lines[start:]:
        named = _MAP_NAME.match(line)
        if named:
            name = named.group(1)
            continue
        match = _MAP_SECTION.match(line)
        section, name = (match.group(1) or name) if match else None, None
        if match is None or section is None:
            continue
        size, where = int(match.group(3), 16), match.group(4).strip()
        target = sizes if where in core else library if where in pulled else None
        if target is None:
            continue
        for key in target:
            if section == f".{key}" or section.startswith(f".{key}."):
                target[key] += size
    return sizes, library


# ----------------------------------------------------------------------------------- timing

def time_runs(commands: dict[str, list[str]], repeats: int) -> dict[str, list[float]]:
    """ns per sample of each command (its `time` line), interleaved over ``repeats`` rounds."""
    times: dict[str, list[float]] = {name: [] for name in commands}
    for _ in range(repeats):
        for name, cmd in commands.items():
            out = _run(cmd).stdout
            match = re.search(r"^time ([0-9.eE+-]+)", out, re.M)
            if match is None:
                raise RuntimeError(f"{name}: no time line in {out[:200]!r}")
            times[name].append(float(match.group(1)))
    return times


# ---------------------------------------------------------------------------------- running

@dataclass
class Result:
    build: Build
    arm: Output
    x86: Output
    profile: Profile
    comparison: Comparison
    sizes: dict[str, int]           # the core's object files
    dt: float
    seconds: float
    linked: dict[str, int] = field(default_factory=dict)    # the core as linked into the program
    library: dict[str, int] = field(default_factory=dict)   # library members linked for the core


def refused(result: "Result") -> bool:
    """Both builds' duffid_init refused the configuration alike (e.g. a method the core does
    not offer in single precision): not a disagreement, nothing to measure."""
    return bool(result.arm.init_failed) and result.arm.init_failed == result.x86.init_failed \
        and result.arm.exit_code == result.x86.exit_code == 3


def steady_start(out: Output, dt: float) -> int:
    """First sample after the first full window (the window reported at the end); the number
    of samples when the window grows to the end (the record is shorter than the first
    window, or a method whose window always grows)."""
    if not out.samples:
        return 0
    window = out.window(len(out.samples) - 1)
    if not math.isfinite(window) or window <= 0:
        return 0
    start = int(math.ceil(window / dt - 1e-9))
    return len(out.samples) if start >= len(out.samples) - 1 else start


def run(models: list[str], method: str = "robust", samples: int | None = None,
        precisions: list[str] | None = None, build_dir: Path | None = None,
        progress=print, core: Path = CORE, change: bool = False) -> tuple[list[Result], dict, list[str]]:
    """Build and run everything; (results, records, notes)."""
    missing = missing_tools()
    if missing:
        raise Unavailable("missing: " + ", ".join(missing))
    notes: list[str] = []
    build_dir = Path(tempfile.mkdtemp(prefix="duffid_embedded_")) if build_dir is None else build_dir
    build_dir.mkdir(parents=True, exist_ok=True)
    precisions = precisions or ["double", "float"]
    supported = []
    for real in precisions:
        if core_supports(real, build_dir, core):
            supported.append(real)
        else:
            notes.append(f"{real}: the core does not support -DDUFFID_REAL={real} yet (probe failed to compile "
                         "with a float API); skipped")
    progress(f"building the TCG plugin in {build_dir}")
    plugin = build_plugin(build_dir)
    records = {}
    results = []
    for model in models:
        progress(f"simulating the {model} record")
        record = make_record(model, samples, change=change)
        records[model] = record
        record_dir = build_dir / f"record_{model}"
        record_dir.mkdir(exist_ok=True)
        write_record_header(record_dir / "embedded_record.h", record)
        if method == "buffered":
            from duffid.errors import InputError
            try:
                write_buffered_tables(record_dir / BUFFERED_TABLES, model, record.dt)
            except InputError as exc:
                notes.append(f"{model} buffered: {exc}; skipped")
                continue
        for real in supported:
            progress(f"building {model} {method} {real} (arm-none-eabi-gcc, gcc)")
            build = build_program(build_dir, record_dir, model, method, real, core)
            progress(f"running {model} {method} {real} on qemu-system-arm mps2-an386 ({len(record.x)} samples)")
            start = time.perf_counter()
            arm, profile = run_arm(build, plugin)
            seconds = time.perf_counter() - start
            progress(f"running {model} {method} {real} natively")
            x86 = run_host(build)
            linked, library = linked_sizes(build.elf.with_suffix(".map"), build.core_objects)
            results.append(Result(build, arm, x86, profile, compare(arm, x86, real), object_sizes(build.core_objects),
                                  record.dt, seconds, linked, library))
    return results, {"records": records, "build_dir": build_dir, "supported": supported}, notes


def host_timing(models: list[str], method: str, supported: list[str], build_dir: Path, repeats: int,
                progress=print, requested: tuple[str, ...] = ("double", "float"),
                skip: frozenset[tuple[str, str]] = frozenset()) -> list[list[str]]:
    """Rows: build, ns/sample median (min-max), floor, ratio; builds in ``skip`` ((model,
    real) the core refused) are listed without a time."""
    rows = []
    for model in models:
        record_dir = build_dir / f"record_{model}"
        floors = {real: build_floor(build_dir / f"record_{model}", record_dir, real) for real in ("double", "float")}
        commands = {}
        timed = [real for real in supported if (model, real) not in skip]
        for real in timed:
            exe = build_dir / f"{model}_{method}_{real}" / "embedded_test_x86"
            commands[f"duffid {real}"] = [str(exe), "time"]
        for real, exe in floors.items():
            commands[f"floor {real}"] = [str(exe)]
        progress(f"timing {model} on x86: {', '.join(commands)} x {repeats}, interleaved")
        times = time_runs(commands, repeats)
        for real in timed:
            d = times[f"duffid {real}"]
            fl = times[f"floor {real}"]
            ratios = [a / b for a, b in zip(d, fl)]
            rows.append([f"{model} {method} {real}", _spread(d), f"floor {real}", _spread(fl),
                         f"{statistics.median(d) / statistics.median(fl):.1f} ({min(ratios):.1f}-{max(ratios):.1f})"])
        for real in ("double", "float"):
            if real not in timed:
                fl = times[f"floor {real}"]
                why = ("refused by the core" if (model, real) in skip else
                       "n/a (the core has no such build)" if real in requested else "not requested")
                rows.append([f"{model} {method} {real}", why, f"floor {real}", _spread(fl), "-"])
    return rows


def _spread(values: list[float]) -> str:
    return f"{statistics.median(values):.0f} ({min(values):.0f}-{max(values):.0f})"


# ------------------------------------------------------------------ float against double

#: Simulated records of benchmarks/trust.py, cached by the hash of everything that makes them
#: (see trust_record): the simulations take minutes, the two builds' runs seconds.
RECORD_CACHE = ROOT / "build" / "trust_records"


def trust_module():
    """benchmarks/trust.py (the battery of realistic records), imported from this folder."""
    folder = str(Path(__file__).resolve().parent)
    if folder not in sys.path:
        sys.path.insert(0, folder)
    import trust
    return trust


def _record_key(case) -> str:
    """Hash of the case, trust.py, duffid's sources and the numerical libraries' versions."""
    import hashlib

    import duffid
    import scipy

    trust = trust_module()
    digest = hashlib.sha256(repr(case).encode())
    digest.update(Path(trust.__file__).read_bytes())
    for source in sorted(Path(duffid.__file__).resolve().parent.rglob("*.py")):
        digest.update(source.read_bytes())
    digest.update(f"{np.__version__} {scipy.__version__} {sys.version}".encode())
    return digest.hexdigest()[:24]


def trust_record(case, cache: Path | None = RECORD_CACHE
                 ) -> tuple[np.ndarray, np.ndarray, float, dict[str, float], object]:
    """The record of a benchmarks/trust.py case, with its truth and the model to identify.

    Parameters
    ----------
    case : trust.Case
        One of ``trust.CASES``.
    cache : Path or None
        Directory of simulated records: read from it when the same sources made the record
        before, written to it otherwise; None: always simulate, write nothing.

    Returns
    -------
    x, f : ndarray
        Displacements (samples, n_dof) and forces (samples, n_forces), as ``trust.make_record``
        gives them (noise, offsets and other modifications included).
    dt : float
        Sampling period [s].
    truth : dict
        The plant's true parameters.
    model
        The model trust.py identifies the record with (``trust.CLASSES``: the class's default
        instance, whose values are not used).
    """
    import json

    trust = trust_module()
    plant = trust.PLANTS[case.plant][0]
    model = trust.CLASSES[type(plant)]
    path = None if cache is None else cache / f"{_record_key(case)}.npz"
    if path is not None and path.exists():
        with np.load(path) as data:
            return data["x"], data["f"], float(data["dt"]), json.loads(str(data["truth"])), model
    record, plant, truth = trust.make_record(case)
    x, f = np.asarray(record.x, dtype=float), np.asarray(record.f, dtype=float)
    dt = float(record.t[1] - record.t[0])
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        partial = path.with_suffix(f".{os.getpid()}.npz")
        np.savez(partial, x=x, f=f, dt=dt, truth=json.dumps(truth))
        os.replace(partial, path)
    return x, f, dt, truth, model


def _simulate_case(name: str, cache: Path | None) -> str:
    """Fill the record cache for the case ``name`` (a worker of accuracy's process pool)."""
    case = next(c for c in trust_module().CASES if c.name == name)
    trust_record(case, cache)
    return name


def run_precisions(model, dt: float, x: np.ndarray, f: np.ndarray,
                   **options: Any) -> tuple[tuple[str, ...], dict[str, np.ndarray]]:
    """(parameter names, {precision: outputs of CIdentifier.run}) of the double and the float
    build (x86, ctypes, the robust method with its default options or ``options``)."""
    from duffid.identification.c_core import CIdentifier

    outputs = {}
    for precision in ("double", "float"):
        with CIdentifier(model, dt, precision=precision, **options) as ident:
            outputs[precision] = ident.run(x, f)
            names = ident.parameter_names
    return names, outputs


@dataclass
class Accuracy:
    """The float build against the double build over one record (counts of parameter-samples:
    one parameter at one sample)."""
    record: str
    names: tuple[str, ...]
    samples: int
    published_double: int
    published_float: int
    published_both: int         # published by both builds at that sample, whatever the windows
    compared: int               # published by the float build, both builds over the same window
    max_ratio: float            # largest |v_float - current_double| / (uncertainty_float |v_float|); NaN: none
    violations: int             # compared parameter-samples with that ratio above 1
    max_truth_error: float      # largest |v_float - truth| / |truth| of a float-published value; NaN: none
    worst: tuple[int, str] = (-1, "")   # (sample, parameter) of max_ratio


def float_accuracy(name: str, names: tuple[str, ...], outputs: dict[str, np.ndarray], dt: float,
                   truth: dict[str, float]) -> Accuracy:
    """Issue 28's requirement on one record: every value the float build publishes is within
    its stated uncertainty of the double build's.

    Parameters
    ----------
    name : str
        The record's name (for the report).
    names : tuple of str
        The parameters, in the outputs' order.
    outputs : dict
        ``{"double": rows, "float": rows}``: the structured arrays of ``CIdentifier.run`` of
        both builds over the same record (see :func:`run_precisions`).
    dt : float
        Sampling period [s].
    truth : dict
        True parameters (for the error of the float build's published values).

    Returns
    -------
    Accuracy

    Notes
    -----
    Compared: every sample where the float build publishes a parameter and both builds
    estimate over the same window (|window_float - window_double| < dt/2; once the automatic
    window is fixed at different samples they estimate over different windows, a statistical,
    not an arithmetic, difference). The ratio is |v_float - current_double| / (uncertainty_float
    |v_float|) with current_double the double build's solution at that sample (published or
    not) and uncertainty_float the float build's stated uncertainty (its largest relative
    standard error); a ratio above 1 is a violation.
    """
    from duffid.identification.engine import STATUSES

    published = STATUSES.index("published")
    d, fl = outputs["double"], outputs["float"]
    k = len(names)
    pub_d = d["status"][:, :k] == published
    pub_f = fl["status"][:, :k] == published
    same = np.abs(fl["window"].astype(float) - d["window"].astype(float)) < dt / 2
    compared = pub_f & same[:, None]
    v = fl["parameters"][:, :k].astype(float)
    with np.errstate(all="ignore"):
        ratio = np.abs(v - d["current"][:, :k].astype(float)) / (fl["uncertainty"].astype(float)[:, None] * np.abs(v))
        true = np.array([truth[n] for n in names], dtype=float)
        error = np.abs(v - true) / np.abs(true)
    # A NaN ratio where the float build publishes (a NaN/inf value or uncertainty) is a violation.
    ratio = np.where(compared & ~np.isfinite(ratio), np.inf, ratio)
    worst = (-1, "")
    max_ratio = math.nan
    if compared.any():
        i, j = np.unravel_index(np.argmax(np.where(compared, ratio, -1.0)), ratio.shape)
        worst, max_ratio = (int(i), names[j]), float(ratio[i, j])
    return Accuracy(name, tuple(names), len(d), int(pub_d.sum()), int(pub_f.sum()), int((pub_d & pub_f).sum()),
                    int(compared.sum()), max_ratio, int((ratio[compared] > 1).sum()),
                    float(np.max(error[pub_f])) if pub_f.any() else math.nan, worst)


def accuracy(names: list[str] | None = None, cache: Path | None = RECORD_CACHE, progress=print,
             workers: int | None = None) -> list[Accuracy]:
    """The float build against the double build on the records of benchmarks/trust.py.

    Parameters
    ----------
    names : list of str, optional
        The records (``trust.CASES`` names); default all.
    cache : Path or None
        Directory of simulated records (see :func:`trust_record`); the records not in it are
        simulated first, in ``workers`` processes (default: one per CPU). None: simulate each
        record in this process, cache nothing.
    progress : callable
        Called with a line of progress.
    workers : int, optional
        Processes that simulate the missing records.

    Returns
    -------
    list of Accuracy
        One per record, in ``trust.CASES`` order.
    """
    from concurrent.futures import ProcessPoolExecutor

    trust = trust_module()
    cases = [c for c in trust.CASES if names is None or c.name in names]
    if names is not None and len(cases) != len(set(names)):
        raise ValueError(f"unknown records: {sorted(set(names) - {c.name for c in cases})}")
    missing = [c.name for c in cases if cache is None or not (cache / f"{_record_key(c)}.npz").exists()]
    if missing and cache is not None:
        workers = min(len(missing), workers or os.cpu_count() or 1)
        progress(f"simulating {len(missing)} records of benchmarks/trust.py ({workers} processes; "
                 f"cached in {cache})")
        if workers > 1:
            with ProcessPoolExecutor(workers) as pool:
                list(pool.map(_simulate_case, missing, [cache] * len(missing)))
        else:
            for name in missing:
                _simulate_case(name, cache)
    rows = []
    for case in cases:
        x, f, dt, truth, model = trust_record(case, cache)
        names_, outputs = run_precisions(model, dt, x, f)
        rows.append(float_accuracy(case.name, names_, outputs, dt, truth))
        # the same with the window fixed at the double build's automatic one: both builds then
        # estimate over the same windows at every sample, so every value the float build
        # publishes is compared
        window = float(outputs["double"]["window"][-1])
        if window > 0:
            names_, outputs = run_precisions(model, dt, x, f, window=window)
            rows.append(float_accuracy(f"{case.name} (window {window:.4g} s)", names_, outputs, dt, truth))
    return rows


def accuracy_report(rows: list[Accuracy]) -> str:
    """The table and the summary of the float-against-double section."""
    def number(v: float, fmt: str) -> str:
        return "-" if math.isnan(v) else format(v, fmt)

    table = _table(
        ["record", "parameters", "published: double", "float", "compared: float, same window", "largest ratio",
         "ratio > 1", "float error vs truth, largest"],
        [[r.record, ",".join(r.names), _fmt(r.published_double), _fmt(r.published_float), _fmt(r.compared),
          number(r.max_ratio, ".3g"), str(r.violations), number(100 * r.max_truth_error, ".3g") + (" %" if
          not math.isnan(r.max_truth_error) else "")] for r in rows])
    violations = sum(r.violations for r in rows)
    ratios = [r.max_ratio for r in rows if not math.isnan(r.max_ratio)]
    worst = max(rows, key=lambda r: -1.0 if math.isnan(r.max_ratio) else r.max_ratio)
    double = sum(r.published_double for r in rows)
    both = sum(r.published_both for r in rows)
    summary = [
        f"violations in all (ratio > 1, must be 0): {violations} of {_fmt(sum(r.compared for r in rows))} "
        f"compared parameter-samples",
        "largest ratio: " + (f"{max(ratios):.3g} ({worst.record}, {worst.worst[1]} at sample {worst.worst[0]})"
                             if ratios else "- (nothing compared)"),
        f"the float build also publishes {100 * both / max(double, 1):.1f} % of the double build's published "
        f"parameter-samples ({_fmt(both)} of {_fmt(double)})",
    ]
    return "\n".join([table, *summary])


# ----------------------------------------------------------------------------------- output

def _table(header: list[str], rows: list[list[str]]) -> str:
    widths = [max(len(str(r[i])) for r in [header, *rows]) for i in range(len(header))]
    line = lambda cells: "  ".join(str(c).ljust(w) for c, w in zip(cells, widths)).rstrip()  # noqa: E731
    return "\n".join([line(header), line(["-" * w for w in widths]), *(line(r) for r in rows)])


def _fmt(n: float) -> str:
    return f"{n:,.0f}"


def report(result: Result, top: int = 10) -> str:
    b, arm, x86, prof, cmp_ = result.build, result.arm, result.x86, result.profile, result.comparison
    if refused(result):
        return f"== {b.model} {b.method} {b.real}: refused by the core on both targets (duffid_init {arm.init_failed})"
    lines = [f"== {b.model} {b.method} {b.real}: {len(arm.samples)} samples, "
             f"QEMU run {result.seconds:.1f} s, {prof.total / 1e6:.0f} M instructions in all"]
    agree = "yes" if cmp_.ok else "NO"
    first = "none" if cmp_.first_difference < 0 else f"sample {cmp_.first_difference}"
    lines.append(_table(["ARM vs x86", "value"], [
        ["exit codes (ARM, x86)", f"{arm.exit_code}, {x86.exit_code}"],
        *([["duffid_init failed (ARM / x86)", f"{arm.init_failed or '-'} / {x86.init_failed or '-'}"]]
          if arm.init_failed or x86.init_failed else []),
        ["samples (ARM, x86)", f"{len(arm.samples)}, {len(x86.samples)}"],
        ["status/identified mismatches", str(cmp_.status_mismatches)],
        ["values bit-identical (or both NaN)",
         f"{cmp_.bit_identical} of {cmp_.values} ({100 * cmp_.bit_identical / max(cmp_.values, 1):.2f} %)"],
        ["first value not bit-identical", first],
        ["NaN pattern mismatches", str(cmp_.nan_mismatches)],
        *([f"largest |a-b| / (eps max(1,cond) max|a|,|b|): {group}", f"{cmp_.max_scaled[group]:.3g}"]
          for group in GROUPS),
        ["tolerance of that ratio (TOLERANCE_ULPS)", f"{cmp_.tolerance:g}"],
        ["values beyond tolerance", str(cmp_.out_of_tolerance)],
        ["agree", agree],
    ]))
    updates = prof.updates
    steady = steady_start(arm, result.dt)
    rows = []
    if updates:
        worst = max(range(len(updates)), key=updates.__getitem__)
        steady_part = updates[steady:] if steady < len(updates) else []
        steady_label = f"samples >= {steady}" if steady < len(updates) else "after the first window"
        rows += [["instructions per update, mean (all samples)", _fmt(statistics.mean(updates))],
                 [f"instructions per update, mean (steady state, {steady_label})",
                  _fmt(statistics.mean(steady_part)) if steady_part else "n/a (the window grows to the end)"],
                 ["instructions per update, worst", f"{_fmt(updates[worst])} (sample {worst})"],
                 ["updates counted / markers out of order", f"{len(updates)} / {prof.unmatched}"]]
    def flash(s: dict[str, int]) -> str:
        total = s["text"] + s["rodata"] + s["data"]
        return f"{total:,} B (text {s['text']:,}, rodata {s['rodata']:,}, data {s['data']:,}, bss {s['bss']:,})"

    rows += [["flash of the core as linked (its sections kept by --gc-sections)", flash(result.linked)],
             ["  + library code linked for the core (libm, libc, libgcc)", flash(result.library)],
             ["flash of the core's object files (before linking)", flash(result.sizes)],
             ["RAM per estimator (duffid_memory_size, ARM / x86-64)", f"{arm.memory_size:,} B / {x86.memory_size:,} B"],
             ["stack high-water mark (updates and printing, below main)", f"{arm.stack_used:,} B"]]
    lines.append(_table(["cost on the Cortex-M4F", "value"], rows))

    def calls(pattern: re.Pattern) -> tuple[int, list[str]]:
        names = sorted(n for n in prof.calls if pattern.search(n))
        return sum(prof.calls[n] for n in names), names

    def code(pattern: re.Pattern) -> int:
        return sum(n for name, n in prof.instructions.items() if pattern.search(name))

    n_upd = max(len(updates), 1)
    total_inside = sum(prof.instructions.values()) or 1

    def per(c: int) -> str:
        return f"{c:,} ({c / n_upd:,.1f} per update)"

    def share(pattern: re.Pattern) -> str:
        return f"{100 * code(pattern) / total_inside:.1f} % of the instructions"

    soft_calls, _ = calls(SOFT_DOUBLE_CALLS)
    div_calls, _ = calls(LONG_DIVISION_CALLS)
    sqrt_calls, sqrt_names = calls(SQRT_CALLS)
    if not sqrt_names:
        sqrt_calls, sqrt_names = calls(SQRT_FALLBACK)
    heap_calls, heap_names = calls(HEAP)
    check = [
        ["heap calls during updates (program's wrappers / plugin)",
         f"{arm.heap_during} / {heap_calls}" + (" (" + ", ".join(heap_names) + ")" if heap_names else ""),
         "ok" if arm.heap_during == 0 and heap_calls == 0 and arm.heap_calls == 0 else "FAIL"],
        ["soft-double helper calls inside updates (__aeabi_d*, *2d)",
         f"{per(soft_calls)}; {share(SOFT_DOUBLE_CODE)}", "ok" if soft_calls == 0 else "soft double"],
        ["64-bit division helpers inside updates (__aeabi_ldivmod/uldivmod)",
         f"{per(div_calls)}; {share(LONG_DIVISION_CODE)}", "ok" if div_calls == 0 else "present"],
        ["software square roots inside updates (vsqrt.f32 could do float ones)",
         per(sqrt_calls) + (" in " + ", ".join(sqrt_names) if sqrt_names else ""),
         "ok" if sqrt_calls == 0 else "present"],
    ]
    lines.append(_table(["check", "count", "verdict"], check))
    top_rows = []
    for name, n in sorted(prof.instructions.items(), key=lambda kv: -kv[1])[:top]:
        calls = prof.calls.get(name, 0)
        top_rows.append([name, f"{100 * n / total_inside:.1f} %", _fmt(n / n_upd), f"{calls / n_upd:,.1f}"])
    lines.append(_table(["function (inside updates)", "share", "instr/update", "calls/update"], top_rows))
    soft_names = sorted(n for n in prof.instructions if SOFT_DOUBLE_CODE.search(n))
    if soft_names:
        lines.append("soft-double code seen: " + ", ".join(soft_names))
    return "\n\n".join(lines)


def embedded_section(args, models: list[str], precisions: list[str], samples: int | None) -> int:
    """The Cortex-M4F section (and the x86 timing): prints its tables; 1 when a build fails."""
    temporary = args.build is None
    build_dir = Path(tempfile.mkdtemp(prefix="duffid_embedded_")) if temporary else args.build
    try:
        try:
            results, info, notes = run(models, args.method, samples, precisions, build_dir,
                                       core=args.core.resolve(), change=args.change)
        except Unavailable as exc:
            print(f"embedded benchmark not run: {exc}")
            return 0
        print()
        print(f"core: {args.core.resolve()}; ARM: arm-none-eabi-gcc {' '.join(ARM_FLAGS[:6])}; "
              f"x86: gcc {' '.join(HOST_FLAGS[:2])}")
        print(f"agreement: statuses, identified flags, return codes and NaN patterns identical; values "
              f"|a-b| <= {TOLERANCE_ULPS:g} eps max(1, condition) max(|a|,|b|) (uncertainty: while <= "
              f"{UNCERTAINTY_CAP:g}); steady state: samples after the first full window")
        for note in notes:
            print("note:", note)
        for result in results:
            print()
            print(report(result, args.top))
        if not args.no_timing:
            repeats = 3 if args.quick else args.repeats
            print()
            rows = host_timing(models, args.method, info["supported"], build_dir, repeats,
                               requested=tuple(precisions),
                               skip=frozenset((r.build.model, r.build.real) for r in results if refused(r)))
            print(f"x86-64 ns per sample (gcc -O2 -ffp-contract=off, median of {repeats} runs, min-max); "
                  "floor: square-root RLS by Givens rotations, 4 unknowns + rhs, 8 rows + back substitution per sample")
            print(_table(["build", "duffid_update ns", "floor", "floor ns", "duffid / floor"], rows))
        failed = [r for r in results if not refused(r) and
                  (not r.comparison.ok or r.arm.exit_code != 0 or r.x86.exit_code != 0)]
        print()
        print("all builds agree and exit 0" if not failed else
              "FAILED: " + ", ".join(f"{r.build.model} {r.build.real}" for r in failed))
        return 1 if failed else 0
    finally:
        if temporary:
            shutil.rmtree(build_dir, ignore_errors=True)


def accuracy_section(cache: Path | None) -> int:
    """The float build against the double build on benchmarks/trust.py's records: prints the
    table and the summary; 1 when a value the float build publishes is off (a violation)."""
    start = time.perf_counter()
    rows = accuracy(cache=cache)
    print()
    print("float build against double build (x86, ctypes, robust method, default options) on the "
          "records of benchmarks/trust.py")
    print("counts are parameter-samples (one parameter at one sample); compared: published by the float "
          "build while both builds estimate over the same window (|window difference| < dt/2); ratio: "
          "|v_float - current_double| / (uncertainty_float |v_float|), must be <= 1; error vs truth: "
          "largest |v_float - true| / |true| of a value the float build published")
    print(accuracy_report(rows))
    print(f"({time.perf_counter() - start:.0f} s)")
    return 1 if any(r.violations for r in rows) else 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help=f"short records ({QUICK_SAMPLES} samples, 1-DOF and 2-DOF)")
    parser.add_argument("--samples", type=int, default=None, help="samples per record (default 3 s = 3001)")
    parser.add_argument("--models", default="duffing1,duffing2", help="duffing1,duffing2")
    parser.add_argument("--method", default="robust", choices=sorted(METHODS))
    parser.add_argument("--precisions", default="double,float", help="double,float")
    parser.add_argument("--change", action="store_true",
                        help="the stiffness steps +25 %% at a third of each record (lines after the change test's flag)")
    parser.add_argument("--repeats", type=int, default=5, help="x86 timing runs (median, min-max)")
    parser.add_argument("--top", type=int, default=10, help="functions listed per build")
    parser.add_argument("--no-timing", action="store_true", help="skip the x86 timing section")
    accuracy_flags = parser.add_mutually_exclusive_group()
    accuracy_flags.add_argument("--no-accuracy", action="store_true",
                                help="skip the float-against-double section (benchmarks/trust.py's records)")
    accuracy_flags.add_argument("--accuracy-only", action="store_true",
                                help="run only the float-against-double section")
    parser.add_argument("--no-record-cache", action="store_true",
                        help=f"simulate trust.py's records again (default: cached in {RECORD_CACHE})")
    parser.add_argument("--core", type=Path, default=CORE,
                        help="directory of the core's sources (default fmus/estimator, or $DUFFID_EMBEDDED_CORE)")
    parser.add_argument("--build", type=Path, default=None, help="build directory (default: a temporary one)")
    args = parser.parse_args(argv)
    samples = args.samples if args.samples is not None else (QUICK_SAMPLES if args.quick else None)
    models = [m.strip() for m in args.models.split(",") if m.strip()]
    for m in models:
        if m not in MODELS:
            parser.error(f"unknown model {m!r}")
    precisions = [p.strip() for p in args.precisions.split(",") if p.strip()]
    failed = 0
    if not args.accuracy_only:
        failed |= embedded_section(args, models, precisions, samples)
    if not args.no_accuracy:
        failed |= accuracy_section(None if args.no_record_cache else RECORD_CACHE)
    return failed


if __name__ == "__main__":
    sys.exit(main())
