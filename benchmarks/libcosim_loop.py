"""The plant <-> estimator <-> controller loop run by libcosim (libcosimpy), for benchmarks/cosim.py.

Runs in its own virtual environment (libcosimpy only; duffid is not importable there), so it
takes everything as one JSON argument: {"fmus": {"plant": path, ...}, "connections":
[[type, source slave, source vr, target slave, target vr], ...], "initial": [[slave, vr, value]],
"observe": [slave, vr], "step": h, "n": steps, "repeats": r}. Prints one JSON line:
{"seconds": [per run, set-up included], "x": [[t, value] of the observed Real per step]}
(its last line: libcosim writes its log to standard output too).
"""
from __future__ import annotations

import json
import sys
import time


def run(spec: dict) -> tuple[float, list[float]]:
    from libcosimpy.CosimEnums import CosimVariableType
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimObserver import CosimObserver
    from libcosimpy.CosimSlave import CosimLocalSlave

    start = time.perf_counter()
    h_ns = round(spec["step"] * 1e9)
    execution = CosimExecution.from_step_size(step_size=h_ns)
    index = {}
    for name, path in spec["fmus"].items():
        index[name] = execution.add_local_slave(local_slave=CosimLocalSlave(fmu_path=path, instance_name=name))
    for kind, src, src_vr, dst, dst_vr in spec["connections"]:
        connect = execution.connect_real_variables if kind == "Real" else execution.connect_boolean_variables
        connect(index[src], src_vr, index[dst], dst_vr)
    for name, vr, value in spec["initial"]:
        execution.real_initial_value(index[name], vr, value)
    observer = CosimObserver.create_time_series(buffer_size=spec["n"] + 10)
    execution.add_observer(observer=observer)
    slave, vr = spec["observe"]
    observer.start_time_series(index[slave], vr, CosimVariableType.REAL)
    if not execution.simulate_until(target_time=spec["n"] * h_ns):
        raise SystemExit("libcosim: the simulation failed")
    seconds = time.perf_counter() - start
    times, _, values = observer.time_series_real_samples(index[slave], vr, from_step=0, sample_count=spec["n"] + 1)
    return seconds, [[t * 1e-9, v] for t, v in zip(times, values)]


def main() -> None:
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level

    log_output_level(CosimLogLevel.ERROR)
    spec = json.loads(sys.argv[1])
    seconds, x = [], []
    for _ in range(spec["repeats"]):
        s, x = run(spec)
        seconds.append(s)
    print(json.dumps({"seconds": seconds, "x": x}))  # the last line (libcosim's log goes to stdout too)


if __name__ == "__main__":
    main()
