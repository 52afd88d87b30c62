"""Every public function that takes ``**kwargs`` refuses a keyword it does not know, naming it
(python-control's habit). The meta-test finds those functions in every module's ``__all__``;
each needs a probe here, so a new one cannot slip through untested."""
from __future__ import annotations

import importlib
import inspect
import pkgutil

import pytest

import duffid
from duffid import Duffing1, Multisine, Record, measure, simulate
from duffid.errors import DuffidError

BOGUS = "definitely_not_an_option"


def _functions_with_kwargs() -> list[str]:
    found = set()
    for info in pkgutil.walk_packages(duffid.__path__, "duffid."):
        if info.name.endswith("__main__"):
            continue
        module = importlib.import_module(info.name)
        for name in getattr(module, "__all__", []):
            obj = getattr(module, name, None)
            if inspect.isfunction(obj):
                candidates = [(name, obj)]
            elif inspect.isclass(obj) and not getattr(obj, "_is_protocol", False):  # Protocols are not built
                candidates = [(f"{name}.{k}", v) for k, v in vars(obj).items()
                              if inspect.isfunction(v) and (not k.startswith("_") or k == "__init__")]
            else:
                continue
            for qualname, fn in candidates:
                keywords = any(p.kind is p.VAR_KEYWORD for p in inspect.signature(fn).parameters.values())
                if fn.__module__.startswith("duffid") and keywords:
                    found.add(f"{fn.__module__}.{qualname}")
    return sorted(found)


@pytest.fixture(scope="module")
def record():
    rec = simulate(Duffing1(m=0.4, b=1.5, k=2.5e3, kp=5e7), Multisine(8.0, 2.0, 30.0, 0.6, phases="random", seed=1),
                   0.6, 1e-3)
    return measure(rec, pulses_per_cm=None, snr_db=60.0, seed=2)


def _probes(record):
    from duffid.analysis.nonlinearity import amplitude_sweep
    from duffid.analysis.share import nonlinear_shares
    from duffid.control.adaptive import AdaptiveController, controller_parameters
    from duffid.control.design import design
    from duffid.identification.batch import estimate
    from duffid.identification.buffered import BufferedIdentifier, identify_buffered
    from duffid.identification.c_buffered import CBufferedIdentifier
    from duffid.identification.c_core import CIdentifier
    from duffid.identification.changes import find_changes, identify_segments
    from duffid.identification.discover import discover
    from duffid.identification.dispatch import final_estimates
    from duffid.identification.engine import OnlineIdentifier
    from duffid.identification.equation import identify_equation
    from duffid.identification.motion_online import run_motion_online
    from duffid.identification.refine import refine
    from duffid.identification.trust import identify, run_estimator
    from duffid.models.chain import Chain

    plant = Duffing1()
    controller = design(record.dt)
    return {
        "duffid.analysis.nonlinearity.amplitude_sweep": lambda: amplitude_sweep([1.0], plant, **{BOGUS: 1}),
        "duffid.analysis.share.nonlinear_shares": lambda: nonlinear_shares(record, plant, **{BOGUS: 1}),
        "duffid.control.adaptive.AdaptiveController.__init__": lambda: AdaptiveController(1, controller, **{BOGUS: 1}),
        "duffid.control.adaptive.controller_parameters": lambda: controller_parameters(controller, **{BOGUS: 1}),
        "duffid.identification.batch.estimate": lambda: estimate(record, plant, "robust", **{BOGUS: 1}),
        "duffid.identification.buffered.BufferedIdentifier.__init__":
            lambda: BufferedIdentifier(plant, record.dt, "legendre", **{BOGUS: 1}),
        "duffid.identification.buffered.identify_buffered":
            lambda: identify_buffered(record, plant, "legendre", **{BOGUS: 1}),
        "duffid.identification.c_buffered.CBufferedIdentifier.__init__":
            lambda: CBufferedIdentifier(plant, record.dt, "legendre", **{BOGUS: 1}),
        "duffid.identification.c_core.CIdentifier.__init__": lambda: CIdentifier(plant, record.dt, **{BOGUS: 1}),
        "duffid.identification.changes.find_changes": lambda: find_changes(record, plant, **{BOGUS: 1}),
        "duffid.identification.changes.identify_segments": lambda: identify_segments(record, plant, **{BOGUS: 1}),
        "duffid.identification.engine.OnlineIdentifier.__init__":
            lambda: OnlineIdentifier(plant, record.dt, **{BOGUS: 1}),
        "duffid.identification.equation.identify_equation":
            lambda: identify_equation(record, "m*der(x,2) + b*der(x) + k*x + kp*x^3 = f", **{BOGUS: 1}),
        "duffid.identification.motion_online.run_motion_online":
            lambda: run_motion_online(Record(record.t, record.f, record.x, source="r", motion="a"), plant,
                                      **{BOGUS: 1}),
        "duffid.identification.refine.refine":
            lambda: refine(record, plant, dict(plant.parameters), **{BOGUS: 1}),
        "duffid.identification.trust.identify": lambda: identify(record, plant, **{BOGUS: 1}),
        "duffid.identification.dispatch.run_estimator": lambda: run_estimator(record, plant, **{BOGUS: 1}),
        "duffid.identification.dispatch.final_estimates": lambda: final_estimates(record, plant, **{BOGUS: 1}),
        "duffid.identification.discover.discover": lambda: discover(record, "duffing1", **{BOGUS: 1}),
        "duffid.models.chain.Chain.with_parameters": lambda: Chain.with_parameters(plant, **{BOGUS: 1.0}),
    }


def test_every_kwargs_function_has_a_probe(record):
    missing = sorted(set(_functions_with_kwargs()) - set(_probes(record)))
    assert not missing, f"public functions taking **kwargs without an unknown-keyword test here: {missing}"


@pytest.mark.parametrize("name", _functions_with_kwargs())
def test_an_unknown_keyword_is_refused_by_name(record, name):
    probe = _probes(record).get(name)
    if probe is None:
        pytest.fail(f"{name} has no probe")
    with pytest.raises((DuffidError, TypeError, ValueError)) as info:
        probe()
    assert BOGUS in str(info.value), f"{name}: the error does not name the keyword: {info.value}"
