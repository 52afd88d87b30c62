"""Campaigns on Dask: a real scheduler and two workers as separate processes on localhost,
a local cluster, a worker killed mid-campaign, --resume after an interrupt, failing tasks
and spec errors."""
from __future__ import annotations

import contextlib
import json
import math
import os
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from dask.utils import parse_timedelta
from distributed import Client, get_worker

from duffid import Duffing1, Step, identify, measure, simulate
from duffid.analysis.nonlinearity import analyse, sweep_record
from duffid.campaign import load_spec, read_results, run_campaign
from duffid.campaign.runner import WORKER_CONFIG
from duffid.campaign.systems import configured_system
from duffid.cli import main
from duffid.errors import ConfigError

ESTIMATES = ("m_hat", "b_hat", "k_hat", "kp_hat", "identified")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextlib.contextmanager
def dask_processes(n_workers: int = 2):
    """``dask scheduler`` and ``n_workers`` ``dask worker`` processes (one thread each, no
    nanny: a killed worker stays dead); yields (address, worker processes); always killed."""
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    procs = []
    try:
        procs.append(subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                                       "--port", str(port), "--no-dashboard"], stdout=subprocess.DEVNULL,
                                      stderr=subprocess.DEVNULL, start_new_session=True))
        workers = []
        for _ in range(n_workers):
            workers.append(subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address,
                                             "--nthreads", "1", "--no-nanny", "--no-dashboard"],
                                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                            start_new_session=True))
        procs.extend(workers)
        with Client(address, timeout=60) as client:
            client.wait_for_workers(n_workers, timeout=120)
        yield address, workers
    finally:
        for p in reversed(procs):  # workers first; SIGTERM lets a worker close (and clean up)
            with contextlib.suppress(ProcessLookupError):
                os.killpg(p.pid, signal.SIGTERM)
        for p in procs:
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(p.pid, signal.SIGKILL)
                p.wait(timeout=30)


@pytest.fixture(scope="module")
def cluster():
    with dask_processes(2) as (address, _):
        yield address


def _write(folder: Path, name: str, text: str) -> Path:
    path = folder / name
    path.write_text(text)
    return path


IDENTIFICATION = """
[campaign]
kind = "identification"
seeds = [3, 7]
[task]
model = "duffing1"
excitation = "step:10"
t_end = 2.0
dt = 1e-3
snr_db = 40
engine = "c"
[factors]
check = [false, true]
"""

NONLINEARITY = """
[campaign]
kind = "nonlinearity"
[task]
model = "duffing1"
f_max = 10.0
[factors]
"plant.kp" = [0.0, -1237000.0]
amplitude = { from = 0.5, to = 6.0, count = 2 }
"""


def _loop_config(fmus) -> dict:
    return {
        "components": {"plant": {"fmu": str(fmus["Oscillator1DOF"])},
                       "estimator": {"fmu": str(fmus["DuffingEstimator1"])},
                       "controller": {"fmu": str(fmus["AdaptiveController1"]), "parameters": {"force_limit": 25.0}}},
        "connections": [["plant.x", "estimator.x"], ["plant.x", "controller.x"], ["controller.f", "plant.f"],
                        ["controller.f_sample", "estimator.f"],
                        *[[f"estimator.{name}", f"controller.{name}"] for name in ESTIMATES]],
        "inputs": {"controller.r": 0.006},
        "run": {"stop_time": 1.0, "step": 0.001, "record": ["plant.x", "controller.f", "estimator.m_hat"]},
    }


COSIM = """
[campaign]
kind = "cosim"
[task]
system = "loop.json"
[factors]
"plant.m" = [2.024, 3.036]
"controller.force_limit" = [25.0, 5.0]   # 5 N is below the excitation: the controller refuses it
[metrics]
tracking = { function = "rms", variable = "plant.x", reference = 0.006, t_from = 0.8 }
force = { function = "peak", variable = "controller.f" }
m_hat = { function = "final", variable = "estimator.m_hat" }
"""


# ---------------------------------------------------------------------------- through --scheduler
def test_identification_campaign_on_a_dask_cluster_equals_the_serial_runs(cluster, tmp_path, capsys):
    spec = _write(tmp_path, "ident.toml", IDENTIFICATION)
    out = tmp_path / "ident.parquet"
    assert main(["campaign", str(spec), "-o", str(out), "--scheduler", cluster, "--no-progress"]) == 0
    printed = capsys.readouterr().out
    assert "4 task(s) on 2 worker(s)" in printed and "median |error|" in printed
    table = pq.read_table(out)
    rows = {r["task"]: r for r in table.to_pylist()}
    assert list(rows) == [t.id for t in load_spec(spec).tasks]        # the spec's order
    assert len({r["worker"] for r in rows.values()}) >= 1
    plant = Duffing1()
    exact = simulate(plant, Step(10.0), 2.0, 1e-3)
    for seed in (3, 7):
        record = measure(exact, snr_db=40, seed=seed)
        bare = identify(record, plant, check=False, engine="c")
        row = rows[f"check=False seed={seed}"]
        for p, v in plant.parameters.items():
            assert row[f"estimate_{p}"] == bare.parameters[p]               # the same computation
            assert row[f"error_{p}"] == pytest.approx(100 * (bare.parameters[p] - v) / v, rel=1e-12)
        checked = identify(record, plant, engine="c")
        row = rows[f"check=True seed={seed}"]
        assert {p: row[f"status_{p}"] for p in plant.parameters} == checked.assessment.status
        assert row["published"] == sum(s == "published" for s in checked.assessment.status.values())
        assert all(row[f"estimate_{p}"] == checked.assessment.values[p] for p in plant.parameters)


def test_nonlinearity_campaign_on_a_dask_cluster(cluster, tmp_path):
    spec = _write(tmp_path, "eta.toml", NONLINEARITY)
    out = tmp_path / "eta.parquet"
    plots = tmp_path / "plots"
    assert main(["campaign", str(spec), "-o", str(out), "--scheduler", cluster, "--no-progress",
                 "--plots", str(plots)]) == 0
    rows = {(r["plant.kp"], r["amplitude"]): r for r in pq.read_table(out).to_pylist()}
    assert len(rows) == 4
    for (kp, amplitude), row in rows.items():
        expected = analyse(sweep_record(Duffing1(kp=kp), amplitude))
        assert row["eta"] == expected.eta and row["distortion_db"] == expected.distortion_db
        assert row["verdict"] == expected.verdict
    assert (plots / "eta_eta.png").stat().st_size > 0


def test_cosim_campaign_on_a_dask_cluster_records_a_failing_task_and_goes_on(cluster, loop_fmus, tmp_path, capsys):
    (tmp_path / "loop.json").write_text(json.dumps(_loop_config(loop_fmus)))
    spec = _write(tmp_path, "loop_campaign.toml", COSIM)
    out = tmp_path / "loop.parquet"
    assert main(["campaign", str(spec), "-o", str(out), "--scheduler", cluster, "--no-progress"]) == 1
    printed = capsys.readouterr().out
    assert "2 failed" in printed and "failed: plant.m=2.024 controller.force_limit=5" in printed
    rows = {(r["plant.m"], r["controller.force_limit"]): r for r in pq.read_table(out).to_pylist()}
    assert len(rows) == 4
    for m in (2.024, 3.036):
        failed = rows[(m, 5.0)]
        assert failed["status"] == "failed" and "CosimError" in failed["error"] and "controller" in failed["error"]
        ok = rows[(m, 25.0)]
        assert ok["status"] == "ok" and ok["error"] is None
        direct = configured_system(tmp_path / "loop.json", {"plant.m": m, "controller.force_limit": 25.0}).run()
        assert ok["m_hat"] == direct["estimator.m_hat"][-1]
        assert ok["force"] == np.max(np.abs(direct["controller.f"]))
        assert ok["tracking"] == pytest.approx(np.sqrt(np.mean((direct["plant.x"][direct.time >= 0.8 - 1e-12]
                                                                - 0.006) ** 2)), rel=1e-12)
        assert ok["m_hat"] == pytest.approx(m, rel=0.02)            # the estimator sees the swept mass


def _default_signals() -> None:
    """The campaign's own handling of Ctrl-C and SIGTERM, whatever this test process ignores (a
    child inherits an ignored SIGINT, and Python then installs no KeyboardInterrupt)."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_DFL)


@pytest.mark.parametrize("interrupt", [signal.SIGINT, signal.SIGTERM])
def test_resume_after_an_interrupt_runs_only_what_is_missing(cluster, tmp_path, interrupt):
    spec = _write(tmp_path, "many.toml", IDENTIFICATION.replace("seeds = [3, 7]", "seeds = 6")
                  .replace('engine = "c"', 'engine = "python"\ncheck = false')
                  .replace("check = [false, true]", 'method = ["paper", "robust"]'))
    out = tmp_path / "many.parquet"
    parts = tmp_path / "many.parquet.parts"
    proc = subprocess.Popen([sys.executable, "-m", "duffid", "campaign", str(spec), "-o", str(out),
                             "--scheduler", cluster, "--no-progress"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd=tmp_path, preexec_fn=_default_signals)
    try:
        deadline = time.monotonic() + 120
        while not any(parts.glob("part-*.parquet")) and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        proc.send_signal(interrupt)
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, stderr
    assert "interrupted" in stderr and "--resume" in stderr
    first = pq.read_table(out).column("task").to_pylist()
    assert 0 < len(first) < 12 and not parts.exists()
    done = run_campaign(spec, out, scheduler=cluster, resume=True, progress=False)
    assert done.skipped == len(first) and done.ran == 12 - len(first) and done.failed == 0
    ids = done.table.column("task").to_pylist()
    assert sorted(ids) == sorted(t.id for t in load_spec(spec).tasks)
    assert set(done.table.column("status").to_pylist()) == {"ok"}
    with pytest.raises(Exception, match="already there"):
        run_campaign(spec, out, scheduler=cluster, progress=False)


# ---------------------------------------------------------------------------- local cluster
def worker_settings(result) -> dict[str, float]:
    """A cosim metric that reports, instead of a score, what the event loop of the worker
    running the task does while the task runs (:data:`duffid.campaign.runner.WORKER_CONFIG`)."""
    callbacks = get_worker().periodic_callbacks
    return {"profiling": float("profile" in callbacks and callbacks["profile"].is_running()),
            "tick_ms": float(callbacks["tick"].callback_time),
            "monitor_ms": float(callbacks["monitor"].callback_time),
            "memory_ms": float(callbacks["memory_monitor"].callback_time)}


def test_local_cluster_run_and_worker_folders_removed(tmp_path, loop_fmus):
    (tmp_path / "loop.json").write_text(json.dumps(_loop_config(loop_fmus)))
    spec = _write(tmp_path, "loop_campaign.toml", COSIM.replace("[25.0, 5.0]", "[25.0]")
                  + f'settings = {{ function = "{__name__}:worker_settings" }}\n')
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                          text=True, check=True)
    stale = Path(tempfile.mkdtemp(prefix=f"duffid-campaign-{int(dead.stdout)}-"))   # a killed worker's
    (stale / "Oscillator1DOF").mkdir()
    before = set(Path(tempfile.gettempdir()).glob("duffid-campaign-*"))
    done = run_campaign(spec, tmp_path / "local.parquet", workers=2, progress=False)
    assert not stale.exists()                                         # removed by the next worker
    assert done.workers == 2 and done.ran == 2 and done.failed == 0
    assert read_results(tmp_path / "local.parquet").num_rows == 2
    # the workers run with WORKER_CONFIG: no sampling of the task's stack, fewer wake-ups
    every = {"tick_ms": "distributed.admin.tick.interval", "monitor_ms": "distributed.admin.system-monitor.interval",
             "memory_ms": "distributed.worker.memory.monitor-interval"}
    assert done.table.column("settings.profiling").to_pylist() == [0.0, 0.0]
    for column, key in every.items():
        assert done.table.column(f"settings.{column}").to_pylist() == [1000 * parse_timedelta(WORKER_CONFIG[key])] * 2
    pids = {int(w.rsplit(":", 1)[1]) for w in done.table.column("worker").to_pylist()}
    assert os.getpid() not in pids                                    # run in worker processes
    left = {p for p in set(Path(tempfile.gettempdir()).glob("duffid-campaign-*")) - before
            if int(p.name.split("-")[2]) in pids}
    assert not left, f"worker folders not removed: {left}"


# ---------------------------------------------------------------------------- a worker killed
@pytest.mark.slow
def test_a_worker_killed_mid_campaign_its_tasks_run_again_elsewhere(tmp_path):
    spec = _write(tmp_path, "kill.toml", IDENTIFICATION.replace("seeds = [3, 7]", "seeds = 8")
                  .replace('engine = "c"', 'engine = "python"\ncheck = false')
                  .replace("check = [false, true]", 'method = ["paper", "robust"]'))
    with dask_processes(2) as (address, workers):
        victim = workers[1]
        outcome = {}

        def run() -> None:
            outcome["run"] = run_campaign(spec, tmp_path / "kill.parquet", scheduler=address, progress=False)

        thread = threading.Thread(target=run)
        with Client(address, timeout=30) as monitor:
            victim_address = next(addr for addr, pid in monitor.run(os.getpid).items() if pid == victim.pid)
            thread.start()
            deadline = time.monotonic() + 120
            while not monitor.processing().get(victim_address) and time.monotonic() < deadline:
                time.sleep(0.02)
            running = list(monitor.processing().get(victim_address, []))
            os.killpg(victim.pid, signal.SIGKILL)
            victim.wait(timeout=30)
            thread.join(timeout=300)
    assert running, "the victim never ran a task"
    done = outcome["run"]
    assert done.ran == 16 and done.failed == 0
    rows = done.table.to_pylist()
    tasks = load_spec(spec).tasks
    assert sorted(r["task"] for r in rows) == sorted(t.id for t in tasks)
    lost = {tasks[int(str(key).rsplit("-", 1)[1])].id for key in running}   # keys end with the task's index
    workers = {r["task"]: r["worker"] for r in rows}
    assert any(not workers[t].endswith(f":{victim.pid}") for t in lost)     # run again by the survivor
    # every value equals the serial computation, whichever worker ran it
    plant = Duffing1()
    exact = simulate(plant, Step(10.0), 2.0, 1e-3)
    row = next(r for r in rows if r["task"] == "method=robust seed=5")
    assert row["estimate_m"] == identify(measure(exact, snr_db=40, seed=5), plant, check=False,
                                         engine="python").parameters["m"]


# ---------------------------------------------------------------------------- spec errors
@pytest.mark.parametrize("text, message", [
    ('[campaign]\nkind = "fit"\n', "campaign.kind: must be one of identification"),
    ('[campaign]\nkind = "identification"\n[task]\nmodel = "duffing1"\nexcitation = "step:10"\nt_end = 1.0\n'
     'dt = 1e-3\nmethod = "fast"\n', "task.method: must be one of"),
    ('[campaign]\nkind = "identification"\n[task]\nmodel = "duffing1"\nexcitation = "stp:10"\nt_end = 1.0\n'
     'dt = 1e-3\n', "task.excitation:"),
    ('[campaign]\nkind = "identification"\n[task]\nmodel = "duffing1"\nt_end = 1.0\ndt = 1e-3\n',
     "task.excitation: missing"),
    ('[campaign]\nkind = "nonlinearity"\n[task]\nmodel = "duffing1"\nrate = -1\n[factors]\namplitude = [1.0]\n',
     "task.rate: must be a finite positive number"),
    ('[campaign]\nkind = "nonlinearity"\n[task]\nmodel = "duffing1"\n[factors]\namplitude = [1.0]\n'
     '"plant.q" = [1.0]\n', 'factors."plant.q": plant.q: duffing1 has no parameter'),
    ('[campaign]\nkind = "nonlinearity"\nseeds = 0\n[task]\nmodel = "duffing1"\namplitude = 1.0\n',
     "campaign.seeds: must be a count"),
    ('[campaign]\nkind = "nonlinearity"\n[task]\nmodel = "duffing1"\namplitude = 1.0\nwindow = 2\n',
     "task.window: unknown key for nonlinearity tasks"),
    ('[campaign]\nkind = "nonlinearity"\n[task]\nmodel = "duffing1"\n[factors]\namplitude = []\n',
     "factors.amplitude: must be a non-empty list"),
    ('[campaign]\nkind = "nonlinearity"\n[task]\nmodel = "duffing1"\n[factors]\n'
     'amplitude = { from = 1, to = 2, count = 0 }\n', "factors.amplitude: a range is"),
    ('[campaign]\nkind = "cosim"\n[task]\nsystem = "nowhere.json"\n', "task.system: no such file"),
    ('[campaign]\nkind = "identification"\n[task]\nmodel = "duffing1"\n[oops]\n', "unknown table(s) ['oops']"),
    ('[campaign\n', "not valid TOML"),
    ('[campaign]\nkind = "identification"\n[task]\nmodel = "duffing1"\nexcitation = "step:10"\nt_end = 1.0\n'
     'dt = 1e-3\noptions = { windw = 0.5 }\n', "task.options:"),
    ('[campaign]\nkind = "identification"\n[task]\nmodel = "duffing1"\nequation = "m*der(x,2) + k*x = f"\n'
     'excitation = "step:10"\nt_end = 1.0\ndt = 1e-3\n', "model (a name) or equation (a text), not both"),
    ('[campaign]\nkind = "identification"\n[task]\nexcitation = "step:10"\nt_end = 1.0\ndt = 1e-3\n',
     "neither is there"),
    ('[campaign]\nkind = "identification"\n[task]\nequation = "m*der(x,2) + k*abs(der(x))*der(x) = f"\n'
     'excitation = "step:10"\nt_end = 1.0\ndt = 1e-3\n', "task.equation: must be an equation duffid can identify"),
    ('[campaign]\nkind = "identification"\n[task]\nequation = "m*der(x,2) + k*x = f"\nplant = { q = 1.0 }\n'
     'excitation = "step:10"\nt_end = 1.0\ndt = 1e-3\n', "plant.q: the equation has no parameter 'q'"),
])
def test_spec_errors_name_the_file_and_the_key(tmp_path, text, message):
    spec = _write(tmp_path, "bad.toml", text)
    with pytest.raises(ConfigError) as info:
        load_spec(spec)
    assert str(info.value).startswith(f"{spec}: ") and message in str(info.value)


def test_cosim_spec_errors_name_the_parameter_and_the_metric(tmp_path, loop_fmus):
    (tmp_path / "loop.json").write_text(json.dumps(_loop_config(loop_fmus)))
    spec = _write(tmp_path, "c.toml", COSIM.replace('"plant.m"', '"plant.mass"'))
    with pytest.raises(Exception, match=r'factors\."plant\.mass": .*mass'):
        load_spec(spec)
    spec = _write(tmp_path, "c.toml", COSIM.replace('function = "peak"', 'function = "nowhere:peak"'))
    with pytest.raises(ConfigError, match="metrics.force: metric function 'nowhere:peak': cannot import"):
        load_spec(spec)


def test_existing_results_are_not_overwritten_and_a_foreign_file_is_refused(tmp_path, capsys):
    spec = _write(tmp_path, "eta.toml", NONLINEARITY.replace("count = 2", "count = 1"))
    out = tmp_path / "eta.parquet"
    assert main(["campaign", str(spec), "-o", str(out), "--workers", "1", "--no-progress"]) == 0
    assert main(["campaign", str(spec), "-o", str(out), "--workers", "1", "--no-progress"]) == 2
    assert "already there: --resume continues" in capsys.readouterr().err
    other = _write(tmp_path, "other.toml", NONLINEARITY.replace("[0.0, -1237000.0]", "[-1.0]"))
    assert main(["campaign", str(other), "-o", str(out), "--resume", "--no-progress"]) == 2
    assert "holds results of another campaign" in capsys.readouterr().err
    assert math.isfinite(pq.read_table(out).column("eta").to_pylist()[0])


def test_the_worker_settings_as_environment_variables_are_what_dask_reads(monkeypatch):
    """worker_environment() (for workers started by hand; the README lists them) gives
    WORKER_CONFIG back through Dask's own reading of the environment."""
    import dask

    from duffid.campaign.runner import WORKER_CONFIG, worker_environment

    for name, value in worker_environment().items():
        monkeypatch.setenv(name, value)
    env = dask.config.collect_env()
    for key, value in WORKER_CONFIG.items():
        node = env
        for part in key.split("."):
            node = node[part.replace("-", "_")] if part.replace("-", "_") in node else node[part]
        assert node == value, key
    readme = (Path(__file__).resolve().parent.parent / "docs" / "guide" / "campaigns.md").read_text()
    assert " ".join(f"{k}={v}" for k, v in worker_environment().items()) in readme


def test_a_scheduler_address_where_nothing_listens_fails_at_once(tmp_path, capsys):
    spec = _write(tmp_path, "eta.toml", NONLINEARITY.replace("count = 2", "count = 1"))
    with socket.socket() as s:                       # a port that was free a moment ago
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    assert main(["campaign", str(spec), "-o", str(tmp_path / "eta.parquet"), "--scheduler",
                 f"tcp://127.0.0.1:{port}", "--no-progress"]) == 2
    err = capsys.readouterr().err                     # the probe's message, not Dask's after 30 s
    assert f"cannot reach the Dask scheduler at tcp://127.0.0.1:{port}: nothing listens there" in err
    assert main(["campaign", str(spec), "-o", str(tmp_path / "eta.parquet"), "--scheduler",
                 "tcp://127.0.0.1:notaport", "--no-progress"]) == 2
    assert "the port is not a number" in capsys.readouterr().err


# ---------------------------------------------------------------------------- the example specs
EXAMPLES = Path(__file__).resolve().parent.parent / "examples" / "campaigns"


@pytest.mark.parametrize("name", ["case_b.toml", "eta_vs_amplitude.toml", "eta_vs_amplitude_2dof.toml"])
def test_example_specs_load(name):
    spec = load_spec(EXAMPLES / name)
    assert spec.tasks and len({t.id for t in spec.tasks}) == len(spec.tasks)


def test_the_cosim_example_spec_runs_with_the_demo_fmus(tmp_path, loop_fmus):
    from duffid.campaign.tasks import run_task

    folder = tmp_path / "examples" / "campaigns"
    folder.mkdir(parents=True)
    for name in ("closed_loop.toml", "closed_loop_mass.toml"):
        (folder / name).write_bytes((EXAMPLES / name).read_bytes())
    (tmp_path / "build" / "fmus").mkdir(parents=True)
    for name, path in loop_fmus.items():
        (tmp_path / "build" / "fmus" / path.name).write_bytes(path.read_bytes())
    spec = load_spec(folder / "closed_loop_mass.toml")
    assert len(spec.tasks) == 10 and spec.tasks[0].settings["plant.m"] == 2.024
    row = run_task(spec.tasks[0])
    assert row["status"] == "ok", row["error"]
    assert row["m_hat"] == pytest.approx(2.024, rel=0.02) and row["tracking_rms"] < 1e-4


@pytest.mark.parametrize("suffix", [".csv", ".mat"])
def test_identification_task_reads_a_record_in_any_format(tmp_path, suffix):
    """task.record is read by Record.read: the format comes from the extension."""
    from duffid import Multisine
    from duffid.campaign.spec import Task
    from duffid.campaign.tasks import run_task

    plant = Duffing1(m=0.4, b=1.5, k=2.5e3, kp=5e7)
    record = measure(simulate(plant, Multisine(8.0, 2.0, 30.0, 1.5, phases="random", seed=1), 3.0, 1e-3),
                     pulses_per_cm=None, snr_db=60.0, seed=2)
    path = tmp_path / f"record{suffix}"
    record.to_csv(path) if suffix == ".csv" else record.to_mat(path)
    settings = {"model": "duffing1", "record": str(path), "method": "robust", "check": False, "engine": "c",
                **{f"plant.{k}": v for k, v in plant.parameters.items()}}
    row = run_task(Task(id="t", kind="identification", settings=settings, factors={}))
    assert row["status"] == "ok", row["error"]
    assert abs(row["error_k"]) < 1.0  # percent


def test_an_equation_campaign_simulates_and_identifies_the_equation(tmp_path):
    """The equation duffid discover chose, run as a campaign unchanged (one task, serially)."""
    from duffid.campaign.tasks import run_task

    spec = _write(tmp_path, "equation.toml", '[campaign]\nkind = "identification"\n[task]\n'
                  'equation = "m*der(x,2) + b*der(x) + k*x + kp*x^3 + k2*x^2 = f"\n'
                  'plant = { m = 1.5, b = 3.1, k = 4000.0, kp = 3.2e7, k2 = 8e4 }\n'
                  'excitation = "multisine:10,1,20,20"\nt_end = 10.0\ndt = 1e-3\nsnr_db = 50\nquantise = false\n')
    task = load_spec(spec).tasks[0]
    row = run_task(task)
    assert row["published"] == 5
    assert all(abs(row[f"error_{k}"]) < 0.5 for k in ("m", "b", "k", "kp", "k2"))
