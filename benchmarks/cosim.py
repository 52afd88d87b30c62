"""Benchmark of the co-simulation orchestrator (duffid.cosim.system): macro steps per second.

Run: python benchmarks/cosim.py [--stop-time 10] [--repeats 5] [--fmus DIR]

The closed loop Oscillator1DOF <-> DuffingEstimator1 <-> AdaptiveController1 (FMI 2.0 C
FMUs, 1 ms communication step, reference r = 5 mm held) is run by

  a. the orchestrator, Jacobi and Gauss-Seidel (every output recorded), with its compiled
     inner loop (C, the default) and with its Python loop (loop="python");
  b. the same graph exported as one container FMU (duffid.cosim.container: duffid's own
     runtime, whose doStep runs the Jacobi steps in C over the components' function
     pointers), run by the orchestrator as a one-component system and by a bare fmpy
     FMU2Slave loop;
  c. a plain hand-written fmpy loop: FMU2Slave getReal/getBoolean/setReal/setBoolean/
     doStep through fmpy's normal methods (Jacobi, the same values recorded);

  d. libcosim (libcosimpy, the Open Simulation Platform's C++ co-simulation library), the same
     connections, in its own virtual environment (created on first use under
     ~/.cache/duffid/bench-libcosim, or --libcosim-venv; skipped with a message where
     libcosimpy cannot be installed);

and, as the floor, the three doStep calls alone (raw function pointers, no exchange).
Each figure is the median of --repeats runs of the whole run (extraction,
instantiation, initialisation and clean-up included), with its ratio to the plain fmpy
loop measured in the same run. The last lines check that the variants agree.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from duffid.control.closed_loop import ensure_fmus
from duffid.cosim.system import System

H = 1e-3
R = 0.005
ESTIMATES = ("m_hat", "b_hat", "k_hat", "kp_hat")


def build(out: Path) -> dict[str, Path]:
    """The three FMI 2 FMUs (built into ``out`` unless current there)."""
    fmus = ensure_fmus(out)
    return {"plant": fmus["Oscillator1DOF"], "est": fmus["DuffingEstimator1"], "ctrl": fmus["AdaptiveController1"]}


def loop_system(fmus: dict[str, Path], with_r: bool = True) -> System:
    """plant -> est, ctrl; est -> ctrl (estimates, identified); ctrl.f -> plant; ctrl.f_sample -> est."""
    s = System().add("plant", fmus["plant"]).add("est", fmus["est"]).add("ctrl", fmus["ctrl"])
    s.connect("plant.x", "est.x").connect("plant.x", "ctrl.x")
    for name in ESTIMATES:
        s.connect(f"est.{name}", f"ctrl.{name}")
    s.connect("est.identified", "ctrl.identified").connect("ctrl.f", "plant.f").connect("ctrl.f_sample", "est.f")
    if with_r:
        s.set_input("ctrl.r", R)
    return s


def _slave(path: Path, name: str, tmp: str):
    """A started FMU2Slave with our own logger callbacks (never fmpy's logger proxy)."""
    import fmpy
    from fmpy.fmi2 import FMU2Slave, defaultCallbacks, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE

    md = fmpy.read_model_description(str(path))
    slave = FMU2Slave(guid=md.guid, unzipDirectory=fmpy.extract(str(path), f"{tmp}/{name}"),
                      modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
    callbacks = fmi2CallbackFunctions()
    callbacks.logger = fmi2CallbackLoggerTYPE(lambda *args: None)
    callbacks.allocateMemory = defaultCallbacks.allocateMemory
    callbacks.freeMemory = defaultCallbacks.freeMemory
    slave.instantiate(callbacks=callbacks)
    slave._bench_callbacks = callbacks
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    return slave, {v.name: v.valueReference for v in md.modelVariables}


def plain_fmpy(fmus: dict[str, Path], n: int) -> np.ndarray:
    """The hand-written Jacobi loop with fmpy's normal methods; returns plant.x."""
    with tempfile.TemporaryDirectory() as tmp:
        (plant, pv), (est, ev), (ctrl, cv) = (_slave(fmus[k], k, tmp) for k in ("plant", "est", "ctrl"))
        ctrl.setReal([cv["r"]], [R])
        est_vrs = [ev[name] for name in ESTIMATES] + [ev["condition"], ev["uncertainty"], ev["window_length"]]
        ctrl_in = [cv["x"]] + [cv[name] for name in ESTIMATES]
        ctrl_out = [cv[name] for name in ("f", "f_sample", "x_ref", "v_hat", "switch_time", "m_used", "b_used", "k_used",
                                          "kp_used")]
        xs = np.empty(n + 1)
        rows = []
        x, v = plant.getReal([pv["x"], pv["v"]])
        estimates = est.getReal(est_vrs)
        identified = est.getBoolean([ev["identified"]])
        outputs = ctrl.getReal(ctrl_out)
        xs[0] = x
        for k in range(n):
            t = k * H
            plant.setReal([pv["f"]], [outputs[0]])
            est.setReal([ev["x"], ev["f"]], [x, outputs[1]])
            ctrl.setReal(ctrl_in, [x] + estimates[:4])
            ctrl.setBoolean([cv["identified"]], identified)
            plant.doStep(t, H)
            est.doStep(t, H)
            ctrl.doStep(t, H)
            x, v = plant.getReal([pv["x"], pv["v"]])
            estimates = est.getReal(est_vrs)
            identified = est.getBoolean([ev["identified"]])
            outputs = ctrl.getReal(ctrl_out)
            phase = ctrl.getInteger([cv["phase"]])
            saturated = ctrl.getBoolean([cv["saturated"]])
            rows.append((x, v, estimates, identified, outputs, phase, saturated))
            xs[k + 1] = x
        for slave in (plant, est, ctrl):
            slave.terminate()
            slave.freeInstance()
    return xs


def steps_only(fmus: dict[str, Path], n: int) -> None:
    """The three doStep calls alone (raw function pointers): the FMUs' own cost."""
    with tempfile.TemporaryDirectory() as tmp:
        slaves = [_slave(fmus[k], k, tmp)[0] for k in ("plant", "est", "ctrl")]
        calls = [(s._functions["fmi2DoStep"], s.component) for s in slaves]
        for k in range(n):
            t = k * H
            for f, c in calls:
                f(c, t, H, 1)
        for slave in slaves:
            slave.terminate()
            slave.freeInstance()


def container_bare(path: Path, n: int) -> np.ndarray:
    """The container FMU with fmpy's normal methods: doStep, then getReal of its outputs."""
    with tempfile.TemporaryDirectory() as tmp:
        slave, vr = _slave(path, "container", tmp)
        slave.setReal([vr["r"]], [R])
        out = [vr[name] for name in ("x", "f", "k_hat")]
        xs = np.empty(n + 1)
        xs[0] = slave.getReal(out)[0]
        for k in range(n):
            slave.doStep(k * H, H)
            xs[k + 1] = slave.getReal(out)[0]
        slave.terminate()
        slave.freeInstance()
    return xs


def libcosim_venv(folder: Path) -> Path | str:
    """The Python of a virtual environment with libcosimpy (created on first use), or why not."""
    python = folder / "bin" / "python"
    if python.is_file():
        return python
    done = subprocess.run([sys.executable, "-m", "venv", str(folder)], capture_output=True, text=True)
    if done.returncode == 0:
        done = subprocess.run([str(python), "-m", "pip", "install", "--quiet", "libcosimpy"], capture_output=True,
                              text=True)
    if done.returncode != 0:
        return (done.stdout + done.stderr).strip().splitlines()[-1] if (done.stdout + done.stderr).strip() else "failed"
    return python


def libcosim(python: Path, fmus: dict[str, Path], n: int, repeats: int) -> tuple[float, np.ndarray]:
    """Steps/s (median of ``repeats`` runs, set-up included) of the loop in libcosim, and plant.x on
    the grid (NaN where libcosim recorded no sample)."""
    import fmpy

    vr = {k: {v.name: v.valueReference for v in fmpy.read_model_description(str(p)).modelVariables}
          for k, p in fmus.items()}
    wires = [("Real", "plant", "x", "est", "x"), ("Real", "plant", "x", "ctrl", "x")]
    wires += [("Real", "est", e, "ctrl", e) for e in ESTIMATES]
    wires += [("Boolean", "est", "identified", "ctrl", "identified"), ("Real", "ctrl", "f", "plant", "f"),
              ("Real", "ctrl", "f_sample", "est", "f")]
    spec = {"fmus": {k: str(p) for k, p in fmus.items()},
            "connections": [[kind, a, vr[a][x], b, vr[b][y]] for kind, a, x, b, y in wires],
            "initial": [["ctrl", vr["ctrl"]["r"], R]], "observe": ["plant", vr["plant"]["x"]], "step": H, "n": n,
            "repeats": repeats}
    script = Path(__file__).with_name("libcosim_loop.py")
    done = subprocess.run([str(python), str(script), json.dumps(spec)], capture_output=True, text=True, check=True)
    out = json.loads(done.stdout.strip().splitlines()[-1])
    x = np.full(n + 1, np.nan)
    samples = np.array(out["x"])
    x[np.rint(samples[:, 0] / H).astype(int)] = samples[:, 1]
    return n / statistics.median(out["seconds"]), x


def _median_rate(run, n: int, repeats: int) -> tuple[float, object]:
    times, value = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        value = run()
        times.append(time.perf_counter() - start)
    return n / statistics.median(times), value


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--stop-time", type=float, default=10.0, help="simulated time [s] (default 10)")
    parser.add_argument("--repeats", type=int, default=5, help="runs per figure (default 5)")
    parser.add_argument("--fmus", type=Path, default=None, help="folder to build/reuse the FMUs in")
    parser.add_argument("--libcosim-venv", type=Path,
                        default=Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "duffid"
                        / "bench-libcosim", help="virtual environment with libcosimpy (created if missing)")
    args = parser.parse_args()
    n = round(args.stop_time / H)
    with tempfile.TemporaryDirectory() as work:
        fmus = build(args.fmus or Path(work) / "fmus")
        container = loop_system(fmus, with_r=False).export_container(
            Path(work) / "Loop.fmu", inputs={"r": ["ctrl.r"]},
            outputs={"x": "plant.x", "f": "ctrl.f", "k_hat": "est.k_hat", "identified": "est.identified"}, step=H)
        system = loop_system(fmus)
        one = System().add("loop", container).set_input("loop.r", R)
        runs = {
            "plain fmpy loop (FMU2Slave methods)": lambda: plain_fmpy(fmus, n),
            "orchestrator, Jacobi, Python loop": lambda: system.run(n * H, H, loop="python"),
            "orchestrator, Gauss-Seidel, Python loop": lambda: system.run(n * H, H, ordering="gauss-seidel",
                                                                          loop="python"),
            "orchestrator, Jacobi, compiled loop": lambda: system.run(n * H, H, loop="compiled"),
            "orchestrator, Gauss-Seidel, compiled loop": lambda: system.run(n * H, H, ordering="gauss-seidel",
                                                                            loop="compiled"),
            "container FMU, orchestrator": lambda: one.run(n * H, H),
            "container FMU, bare FMU2Slave loop": lambda: container_bare(container, n),
            "3 x doStep alone (floor, no exchange)": lambda: steps_only(fmus, n),
        }
        rates, values = {}, {}
        for label, run in runs.items():
            rates[label], values[label] = _median_rate(run, n, args.repeats)
        python = libcosim_venv(args.libcosim_venv)
        if isinstance(python, Path):
            rates["libcosim (libcosimpy)"], values["libcosim (libcosimpy)"] = libcosim(python, fmus, n, args.repeats)
        else:
            print(f"libcosim skipped: libcosimpy could not be installed in {args.libcosim_venv} ({python})")
    base = rates["plain fmpy loop (FMU2Slave methods)"]
    print(f"\nCo-simulation of plant <-> estimator <-> controller (FMI 2.0 C FMUs), {n} macro steps of 1 ms, "
          f"median of {args.repeats} runs (set-up included)")
    print(f"{'':<44}{'steps/s':>12}{'us/step':>10}{'ratio':>8}")
    for label, rate in rates.items():
        print(f"{label:<44}{rate:>12,.0f}{1e6 / rate:>10.2f}{rate / base:>8.2f}")
    python_loop = rates["orchestrator, Jacobi, Python loop"]
    print(f"\ncompiled loop / Python loop (Jacobi): {rates['orchestrator, Jacobi, compiled loop'] / python_loop:.2f}; "
          f"Gauss-Seidel: {rates['orchestrator, Gauss-Seidel, compiled loop'] / rates['orchestrator, Gauss-Seidel, Python loop']:.2f}")
    for ordering in ("Jacobi", "Gauss-Seidel"):
        a, b = values[f"orchestrator, {ordering}, compiled loop"], values[f"orchestrator, {ordering}, Python loop"]
        same = all(np.array_equal(a[name], b[name], equal_nan=True) for name in a.names)
        print(f"{ordering}: compiled and Python loops {'identical, bit for bit' if same else 'DIFFER'} over "
              f"{len(a.names)} recorded variables; max |dx| {np.max(np.abs(a['plant.x'] - b['plant.x'])):.1e} m")
    plain = values["plain fmpy loop (FMU2Slave methods)"]
    jacobi = values["orchestrator, Jacobi, compiled loop"]["plant.x"]
    if "libcosim (libcosimpy)" in rates:
        x = values["libcosim (libcosimpy)"]
        seen = np.isfinite(x)
        print(f"compiled loop / libcosim: {rates['orchestrator, Jacobi, compiled loop'] / rates['libcosim (libcosimpy)']:.2f}; "
              f"libcosim vs orchestrator Jacobi: max |dx| {np.max(np.abs(x[seen] - jacobi[seen])):.1e} m over "
              f"{np.count_nonzero(seen)} of {len(x)} points")
    inner = values["container FMU, orchestrator"]["loop.x"]
    bare = values["container FMU, bare FMU2Slave loop"]
    print(f"\nagreement: max |x| difference, orchestrator Jacobi vs plain loop {np.max(np.abs(jacobi - plain)):.1e} m, "
          f"container vs orchestrator {np.max(np.abs(inner - jacobi)):.1e} m, bare container loop vs orchestrator "
          f"{np.max(np.abs(bare - jacobi)):.1e} m; final x = {jacobi[-1]:.6f} m (r = {R} m)")


if __name__ == "__main__":
    main()
