"""Helpers shared by the FMU tests: run a record through an FMU with fmpy."""
from __future__ import annotations

import re
import subprocess
from pathlib import Path

import fmpy
import numpy as np


def input_signals(record, names):
    """fmpy input: the record's samples on fmpy's communication grid t0 + k dt."""
    sig = np.zeros(record.n_samples, dtype=[("time", float)] + [(name, float) for name in names])
    sig["time"] = np.arange(record.n_samples) * record.dt
    values = np.column_stack([record.x, record.f])
    for i, name in enumerate(names):
        sig[name] = values[:, i]
    return sig


def simulate_record(fmu, record, names, start_values=None):
    """Simulate ``fmu`` with the record as input, one communication step per sample.

    Never pass ``logger=`` to fmpy.simulate_fmu in tests: fmpy's native logger proxy keeps
    a pointer to that callback after it is freed, and a later FMU that logs crashes.
    """
    start = dict(start_values or {})
    if any(v.name == "sample_period" for v in fmpy.read_model_description(str(fmu)).modelVariables):
        start.setdefault("sample_period", record.dt)  # a discrete-time FMU: one step per sample
    return fmpy.simulate_fmu(str(fmu), start_time=0.0, stop_time=record.n_samples * record.dt,
                             output_interval=record.dt, input=input_signals(record, names),
                             start_values=start)


def step_samples(fmu, vr, record, inputs, outputs, first, n):
    """Feed samples ``first .. first + n - 1`` of ``record`` (motions, then forces, to the FMU
    variables ``inputs``) one ``doStep`` each; the values of ``outputs`` after every step."""
    values = np.column_stack([record.x, record.f])
    refs = [vr[name] for name in inputs]
    rows = []
    for i in range(first, first + n):
        fmu.setReal(refs, list(values[i]))
        fmu.doStep(currentCommunicationPoint=i * record.dt, communicationStepSize=record.dt)
        rows.append(fmu.getReal([vr[name] for name in outputs]))
    return np.array(rows)


def start_fmi2(path, tmp_path, messages, start=None, types=None, logging_on=False, name="instance"):
    """Instantiate an FMI 2 co-simulation FMU with our own logger callback, set start values
    (``types``: name -> "Integer", "Boolean" or "String"; others Real) and initialise at t = 0.

    Messages are appended to ``messages`` as (status, category, text). Never fmpy's
    ``logger=`` proxy: it dangles after the callback is freed.
    """
    from fmpy.fmi2 import FMU2Slave, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE

    unzipdir = fmpy.extract(str(path), str(tmp_path / f"unzipped_{len(list(tmp_path.iterdir()))}"))
    md = fmpy.read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir, modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName=name)

    def log(env, instance, status, category, message):
        messages.append((status, category.decode(), message.decode()))

    callbacks = fmi2CallbackFunctions()
    callbacks.logger = fmi2CallbackLoggerTYPE(log)
    fmu.instantiate(callbacks=callbacks, loggingOn=logging_on)
    fmu._duffid_callbacks = callbacks  # keep the ctypes callbacks alive as long as the instance
    fmu.setupExperiment(startTime=0.0)
    types = types or {}
    for var, value in (start or {}).items():
        if types.get(var) == "Integer":
            fmu.setInteger([vr[var]], [int(value)])
        elif types.get(var) == "Boolean":
            fmu.setBoolean([vr[var]], [bool(value)])
        elif types.get(var) == "String":
            fmu.setString([vr[var]], [str(value)])
        else:
            fmu.setReal([vr[var]], [float(value)])
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    return fmu, vr


#: Sanitizers of the fuzzing hosts (tests/c/fuzz_state.c, tests/c/fuzz_api.c) and of the FMUs'
#: code they load; a report ends the run (no recovery).
SANITIZE = ("-g", "-O1", "-fno-omit-frame-pointer", "-fsanitize=address,undefined,float-cast-overflow",
            "-fno-sanitize-recover=all")
#: A sanitizer report in a fuzzing host's output.
SANITIZER_REPORT = re.compile(r"ERROR: (Address|Leak|Undefined)Sanitizer|runtime error:")


def sanitizer_compiler(tmp: Path) -> str:
    """The C compiler, if it builds and runs a program with ASan and UBSan; else skip the test."""
    import pytest

    from duffid.cbuild import find_compiler
    from duffid.errors import CompilerNotFoundError

    try:
        cc = find_compiler()
    except CompilerNotFoundError as error:
        pytest.skip(str(error))
    probe = tmp / "probe.c"
    probe.write_text("#include <stdlib.h>\nint main(void) { char *p = malloc(4); p[0] = 1; free(p); return 0; }\n")
    built = subprocess.run([cc, *SANITIZE, str(probe), "-o", str(tmp / "probe")], check=False, capture_output=True,
                           text=True)
    if built.returncode != 0:
        pytest.skip(f"{cc} cannot build with -fsanitize=address,undefined (install libasan and libubsan, e.g. "
                    f"the Debian package gcc): {built.stderr.strip()[:200]}")
    ran = subprocess.run([str(tmp / "probe")], check=False, capture_output=True, text=True)
    if ran.returncode != 0:
        pytest.skip(f"programs built with AddressSanitizer do not run here: {ran.stderr.strip()[:200]}")
    return cc
