"""duffid: online algebraic identification of Duffing-type nonlinear oscillators.

The short public API::

    from duffid import Duffing1, simulate, measure, Step, identify, OnlineIdentifier
    record = measure(simulate(Duffing1(), Step(10.0), t_end=2.0, dt=1e-3), snr_db=40)
    result = identify(record, Duffing1())          # robust method by default
    result.parameters                              # {'m': ..., 'b': ..., 'k': ..., 'kp': ...}

Co-simulation of FMUs (:class:`System`, :mod:`duffid.cosim`), the adaptive controller
(:class:`AdaptiveController`, :func:`design`, :mod:`duffid.control`) and the closed loops
of the main job (:mod:`duffid.closed_loop`, :mod:`duffid.demo`).
"""
from .control import AdaptiveController, design
from .cosim import CosimError, System
from .identification import METHODS, Estimate, Identification, OnlineIdentifier
from .models import Chain, Duffing1, Duffing2, DuffingCircuit, model_from_name
from .record import Record, RecordError
from .signals import Chirp, Multisine, Step, from_spec
from .simulation import SimulationError, measure, simulate
from .trust import identify

__version__ = "0.1.0"

__all__ = [
    "Chain", "Duffing1", "Duffing2", "DuffingCircuit", "model_from_name",
    "Record", "RecordError",
    "Step", "Chirp", "Multisine", "from_spec",
    "simulate", "measure", "SimulationError",
    "OnlineIdentifier", "identify", "Identification", "Estimate", "METHODS",
    "System", "CosimError", "AdaptiveController", "design",
    "__version__",
]
