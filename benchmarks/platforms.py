"""duffid's C FMUs in a C host on every platform: Linux, Windows under wine64, aarch64 under qemu.

Run: python benchmarks/platforms.py [--out DIR] [--platforms linux64,win64,aarch64-linux]

The host is tests/c/fmi_host.c (one portable C file, FMI 2 and FMI 3), compiled by
tests/c_hosts.py for each platform whose compiler and runner are installed; the FMUs are built
by duffid's own builders with binaries for those platforms. Three tables:

1. FMU x FMI version x platform -> whether the host runs it, the number of steps, and the
   largest absolute and relative difference of any output to the linux64 host's result
   (for linux64 itself: to fmpy's result on the same binary), with the largest ratio to the
   tolerance tests/test_c_hosts.py applies (SAFETY times the output's one-ulp spread).
2. The size of each FMU's binary per platform.
3. The DLLs a win64 binary imports (x86_64-w64-mingw32-objdump -p), each marked as a Windows
   system DLL or not.

A platform that cannot be built or run here is listed with the Debian package to install.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import zipfile
from pathlib import Path

import fmpy
import numpy as np
from tqdm import tqdm

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from c_hosts import (
    WINDOWS_SYSTEM_DLLS,
    HostError,
    binary_sizes,
    build_case_fmus,
    compare,
    hosts,
    imported_dlls,
    is_discrete,
    rounding_tolerance,
    run_fmpy,
    run_host,
    standard_cases,
)

from duffid.cbuild import HOST_PLATFORM, PLATFORMS, fmu_binary_path, resolve_platforms


def _row(cells: list[str], widths: list[int]) -> str:
    return "  ".join(c.ljust(w) for c, w in zip(cells, widths)).rstrip()


def _table(header: list[str], rows: list[list[str]]) -> str:
    widths = [max(len(r[i]) for r in [header, *rows]) for i in range(len(header))]
    return "\n".join([_row(header, widths), _row(["-" * w for w in widths], widths),
                      *(_row(r, widths) for r in rows)])


def _worst_ratio(case, result, reference, tolerance) -> float:
    worst = 0.0
    for name in case.outputs:
        if is_discrete(case, name):
            continue
        want, have = reference[name], result[name]
        with np.errstate(all="ignore"):
            relative = np.where((have == want) | np.isnan(want), 0.0, np.abs(have - want) / np.abs(want))
        worst = max(worst, float(np.nanmax(relative / tolerance[name], initial=0.0)))
    return worst


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=None, help="folder for the FMUs, hosts and runs (default: a "
                                                              "temporary one)")
    parser.add_argument("--platforms", default="all", help="comma-separated platforms (default all)")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="duffid-platforms-") as tmp:
        out = args.out or Path(tmp)
        out.mkdir(parents=True, exist_ok=True)
        names = [n.strip() for n in args.platforms.split(",") if n.strip()]
        platforms, skipped = resolve_platforms(names)
        requested = [p for p in PLATFORMS.values() if "all" in names or p.name in names]
        for line in skipped:
            print(f"platforms: {line}", file=sys.stderr)
        print("building the FMUs ...", file=sys.stderr)
        fmus = build_case_fmus(out / "fmus", platforms)
        cases = standard_cases(fmus)
        work = out / "runs"
        rows: list[list[str]] = []
        details: list[str] = []
        with hosts(out / "hosts", requested) as found:
            linux = found.get(HOST_PLATFORM.name)
            if isinstance(linux, str) or linux is None:
                print(f"platforms: no linux64 host ({linux}); nothing to compare with", file=sys.stderr)
                return 1
            jobs = [(case, name) for case in cases for name in found]
            references, tolerances = {}, {}
            for case, name in tqdm(jobs, desc="runs", unit="run", file=sys.stderr):
                host = found[name]
                fmu_name = case.fmu.name
                if isinstance(host, str):
                    rows.append([fmu_name, str(case.fmi_version), name, "no", host, "", "", "", ""])
                    continue
                try:
                    result = run_host(host, case, work)
                except HostError as error:
                    rows.append([fmu_name, str(case.fmi_version), name, "FAILED", str(error).splitlines()[-1],
                                 "", "", "", ""])
                    continue
                if name == HOST_PLATFORM.name:
                    references[case.name] = result
                    tolerances[case.name] = rounding_tolerance(linux, case, work, result)
                    reference, against = run_fmpy(case), "fmpy"
                else:
                    reference, against = references[case.name], HOST_PLATFORM.name
                diffs = compare(result, reference)
                absolute = max(d[0] for d in diffs.values())
                worst = max(diffs, key=lambda n: diffs[n][1])
                relative = diffs[worst][1]
                ratio = _worst_ratio(case, result, reference, tolerances[case.name])
                if absolute > 0:
                    details.append(f"  {fmu_name} on {name}: " + ", ".join(
                        f"{n} {d[1]:.2g}" for n, d in diffs.items() if d[1] > 0))
                rows.append([fmu_name, str(case.fmi_version), name, "yes", str(len(result["time"]) - 1), against,
                             "0 (bit-identical)" if absolute == 0 else f"{absolute:.3g}",
                             "0" if relative == 0 else f"{relative:.3g} ({worst})", f"{ratio:.3g}"])
        print("\n1. The C host on each platform: FMU x FMI version x platform -> runs, steps, largest difference "
              "of any output (time included) to linux64 (linux64: to fmpy)\n")
        print(_table(["FMU", "FMI", "platform", "runs", "steps", "compared with", "max |diff|", "max rel diff (output)",
                      "of tolerance"], rows))

        if details:
            print("\n   largest relative difference of each output that differs:")
            print("\n".join(details))

        print("\n2. Binary sizes (bytes) per platform\n")
        size_rows = []
        for fmu in fmus.values():
            sizes = binary_sizes(fmu)
            size_rows.append([fmu.name, *(str(sizes.get(p.name, "-")) for p in PLATFORMS.values())])
        print(_table(["FMU", *PLATFORMS], size_rows))

        if "win64" in {p.name for p in platforms}:
            imports = {}
            for fmu in fmus.values():
                md = fmpy.read_model_description(str(fmu))
                inside = fmu_binary_path(md.coSimulation.modelIdentifier, int(md.fmiVersion[0]), PLATFORMS["win64"])
                dll = out / f"{fmu.stem}.dll"
                with zipfile.ZipFile(fmu) as z:
                    dll.write_bytes(z.read(inside))
                imports[f"{fmu.name}:{inside}"] = imported_dlls(dll)
            first = next(iter(imports))
            print(f"\n3. DLLs imported by {first} (x86_64-w64-mingw32-objdump -p)\n")
            for name in imports[first]:
                kind = "Windows system DLL" if name.lower() in WINDOWS_SYSTEM_DLLS else "NOT a Windows system DLL"
                print(f"  {name:16s} {kind}")
            foreign = {n: [d for d in ds if d.lower() not in WINDOWS_SYSTEM_DLLS] for n, ds in imports.items()}
            foreign = {n: ds for n, ds in foreign.items() if ds}
            print(f"\n  non-system imports: {foreign}" if foreign else
                  f"\n  each of the {len(imports)} win64 binaries imports Windows system DLLs only: "
                  f"{', '.join(sorted({d for ds in imports.values() for d in ds}))}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
