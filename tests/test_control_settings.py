"""One schema for the adaptive controller's parameters (duffid.control.settings): the C header is
generated from it, the C check and the FMU read their parameters from it, and the Python check
and the C FMU reject the same values (run against each other here)."""
from __future__ import annotations

import math
import shutil

import pytest

pytest.importorskip("control")
from fmpy.fmi1 import FMICallException  # noqa: E402
from fmu_helpers import start_fmi2  # noqa: E402

from duffid.assets import fmu_sources  # noqa: E402
from duffid.control import settings as schema  # noqa: E402
from duffid.control.adaptive import SETTINGS, check_parameters, controller_parameters  # noqa: E402
from duffid.control.controller_fmu import TYPES, build_controller_fmu, controller_variables  # noqa: E402
from duffid.control.design import design  # noqa: E402
from duffid.errors import InputError  # noqa: E402

H = 1e-3


def test_the_c_header_is_generated_from_the_schema():
    assert (fmu_sources("controller") / schema.C_HEADER_NAME).read_text() == schema.c_header(), \
        "fmus/controller/duffid_ctrl_params.h is stale: run `make generated`"


def test_settings_and_fmu_parameters_come_from_the_schema():
    assert SETTINGS == schema.SETTINGS
    assert set(SETTINGS) == {p.setting for p in schema.PARAMETERS if p.setting} | {"nominal"}
    table, _ = controller_variables(1)
    parameters = [v for v in table if v.causality == "parameter"]
    names = [v.name for v in parameters]
    scalar = [p.name for p in schema.PARAMETERS]
    assert [n for n in names if not n.endswith("_nominal")] == scalar
    for v in parameters:
        p = next((p for p in schema.PARAMETERS if p.name == v.name), None)
        if p is not None:
            assert v.description == p.description and v.unit == p.unit, p.name
            assert TYPES.get(p.name, "Float64") == {"real": "Float64", "code": "Integer", "count": "Integer",
                                                   "bool": "Boolean"}[p.kind]
    defaults = controller_parameters(design(H))
    for p in schema.PARAMETERS:
        if p.setting is not None:
            assert defaults[p.name] == schema.coded(p.setting, p.default), p.name


_PROBES = {"real": [-1.0, 0.0, 0.5, math.inf, math.nan], "code": [-1, 0, 1, 2],
           "count": [2, 3, 64, 65], "bool": [False, True]}


@pytest.fixture(scope="module")
def fmu(tmp_path_factory):
    if shutil.which("gcc") is None and shutil.which("cc") is None:
        pytest.skip("no C compiler")
    return build_controller_fmu(1, tmp_path_factory.mktemp("ctrl"))


@pytest.mark.parametrize("parameter", schema.PARAMETERS, ids=lambda p: p.name)
def test_python_and_c_reject_the_same_values(fmu, tmp_path, parameter):
    base = controller_parameters(design(H), excitation_amplitude=0.5, force_limit=20.0)
    for value in _PROBES[parameter.kind]:
        params = {**base, parameter.name: value}
        if parameter.name == "force_limit" and 0.0 < value < 0.5:
            continue  # the excitation limit, not the parameter's own rule
        try:
            check_parameters(params, 1)
            python_ok = True
        except InputError as exc:
            python_ok = False
            assert f"parameter {parameter.name} " in str(exc)
        messages: list = []
        try:
            instance, _ = start_fmi2(fmu, tmp_path, messages, params, TYPES, name="ctrl")
            instance.terminate()
            instance.freeInstance()
            c_ok = True
        except FMICallException:
            c_ok = False
        assert c_ok == python_ok, (parameter.name, value, messages)
        if not c_ok and math.isfinite(float(value)):
            assert any(parameter.name in text and parameter.rule_text in text for _, _, text in messages), messages
