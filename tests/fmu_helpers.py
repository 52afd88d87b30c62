"""Helpers shared by the FMU tests: run a record through an FMU with fmpy."""
from __future__ import annotations

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
    return fmpy.simulate_fmu(str(fmu), start_time=0.0, stop_time=record.n_samples * record.dt,
                             output_interval=record.dt, input=input_signals(record, names),
                             start_values=start_values or {})
