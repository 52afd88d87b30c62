"""duffid: online algebraic identification of Duffing-type nonlinear oscillators.

The short public API::

    from duffid import Duffing1, simulate, measure, Step, identify, OnlineIdentifier
    record = measure(simulate(Duffing1(), Step(10.0), t_end=2.0, dt=1e-3), snr_db=40)
    result = identify(record, Duffing1())          # robust method by default
    result.parameters                              # {'m': ..., 'b': ..., 'k': ..., 'kp': ...}

Co-simulation of FMUs (:class:`System`, :mod:`duffid.cosim.system`), the adaptive controller
(:class:`AdaptiveController`, :func:`design`, :mod:`duffid.control.adaptive`) and the closed loops
of the main job (:mod:`duffid.control.closed_loop`, :mod:`duffid.apps.demo`).
"""
from .control.adaptive import AdaptiveController
from .control.design import design
from .cosim.system import System
from .data.record import Record
from .data.signals import Chirp, Multisine, Step, from_spec
from .errors import CosimError, RecordError, SimulationError
from .identification.discover import discover
from .identification.engine import METHODS, Estimate, Identification, OnlineIdentifier
from .identification.motion_online import OnlineMotionIdentifier
from .identification.trust import identify
from .models.chain import Chain, Duffing1, Duffing2, DuffingCircuit
from .models.registry import model_from_name
from .models.simulation import measure, simulate

__version__ = "0.1.0"

__all__ = [
    "Chain", "Duffing1", "Duffing2", "DuffingCircuit", "model_from_name",
    "Record", "RecordError",
    "Step", "Chirp", "Multisine", "from_spec",
    "simulate", "measure", "SimulationError",
    "OnlineIdentifier", "OnlineMotionIdentifier", "identify", "discover", "Identification", "Estimate", "METHODS",
    "System", "CosimError", "AdaptiveController", "design",
    "__version__",
]
