"""One schema for the estimator options (duffid.identification.options): the C header is
generated from it, and the C core, the ctypes struct, the FMUs (C and pythonfmu) and the CLI
take their options, defaults and ranges from it. Validation is written once per language
from the same table; here the two are run against each other."""
from __future__ import annotations

import ctypes
import math
import shutil
import xml.etree.ElementTree as ET
import zipfile

import pytest

from duffid.errors import InputError, OptionError
from duffid.identification import options as schema
from duffid.identification.c_core import CConfig, load_library, source_dir
from duffid.identification.engine import OnlineIdentifier
from duffid.models.chain import Duffing1

needs_cc = pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None, reason="no C compiler")
_C_METHODS = {"robust": 0, "paper": 1}


def test_the_c_header_is_generated_from_the_schema():
    assert (source_dir() / schema.C_HEADER_NAME).read_text() == schema.c_header(), \
        "fmus/estimator/duffid_options.h is stale: run `make generated`"


def test_every_option_is_declared_once():
    names = [o.name for o in schema.OPTIONS]
    assert len(names) == len(set(names))
    for o in schema.OPTIONS:
        assert set(o.methods) <= set(schema.ONLINE_METHODS), o.name
        assert o.description, o.name
        if o.kind == "choice":
            assert o.default in o.choices


def test_the_c_choice_codes_are_the_schema_indices():
    header = (source_dir() / "duffid_estimator.h").read_text()
    for o, prefix in ((next(o for o in schema.OPTIONS if o.name == "rows"), "DUFFID_ROWS_"),
                      (next(o for o in schema.OPTIONS if o.name == "quadrature"), "DUFFID_")):
        for code, value in enumerate(o.choices):
            assert f"#define {prefix}{value.upper()} {code}" in header


@needs_cc
@pytest.mark.parametrize("method", schema.ONLINE_METHODS)
def test_the_c_defaults_are_the_python_defaults(method):
    lib = load_library()
    cfg = CConfig()
    assert lib.duffid_default_config(ctypes.byref(cfg), 1, _C_METHODS[method], 1e-3) == 0
    for name, value in schema.default_options(method).items():
        if name == "nominal":
            assert list(cfg.nominal) == [0.0] * len(cfg.nominal)
            continue
        assert getattr(cfg, name) == schema.to_c(name, value), name


def _c_accepts(method: str, name: str, code: float) -> tuple[bool, str]:
    lib = load_library()
    cfg = CConfig()
    lib.duffid_default_config(ctypes.byref(cfg), 1, _C_METHODS[method], 1e-3)
    setattr(cfg, name, code)
    msg = ctypes.create_string_buffer(256)
    return lib.duffid_check_config(ctypes.byref(cfg), msg, len(msg)) == 0, msg.value.decode()


_PROBES = {"real": [-1.0, -1e-300, 0.0, 1e-3, 0.5, 2.0, 1e9, math.inf, -math.inf, math.nan],
           "count": [-2, -1, 0, 1, 5, 12],
           "choice": [-1, 0, 1, 2, 3],
           "bool": [-1, 0, 1, 2]}


@needs_cc
@pytest.mark.parametrize("option", [o for o in schema.OPTIONS if o.kind != "prior"], ids=lambda o: o.name)
def test_python_and_c_accept_the_same_values(option):
    """Every probe value, coded for C as to_c codes it: C accepts it exactly when Python
    accepts its decoded value (the C core's fixed capacities aside)."""
    for method in option.methods:
        for code in _PROBES[option.kind]:
            c_ok, message = _c_accepts(method, option.name, code)
            try:
                value = schema.from_c(option, code)
                schema.check_options(method, {option.name: value})
                py_ok = True
            except InputError:
                py_ok = False
            if not c_ok and ("in the C core" in message or "exceeds" in message):
                continue  # the C core's fixed capacity (n_rows <= 12, the window's samples)
            assert c_ok == py_ok, (method, option.name, code, message)
            if not c_ok:
                assert option.name in message and option.valid_values(c=True) in message


def test_python_rejects_out_of_range_values_naming_the_option():
    with pytest.raises(InputError, match=r"option window must be 'auto' or a positive number of seconds"):
        OnlineIdentifier(Duffing1(), 1e-3, "robust", window=-1.0)
    with pytest.raises(InputError, match=r"option rows must be 'integrals' or 'bernstein' or 'paper'"):
        OnlineIdentifier(Duffing1(), 1e-3, "robust", rows="legendre")
    with pytest.raises(InputError, match=r"option n_rows must be None \(default\) or an integer >= 1"):
        OnlineIdentifier(Duffing1(), 1e-3, "robust", n_rows=0)
    with pytest.raises(OptionError, match="has no option"):
        OnlineIdentifier(Duffing1(), 1e-3, "paper", window=0.2)


def test_coding_round_trips():
    for o in schema.OPTIONS:
        if o.kind == "prior":
            continue
        assert schema.from_c(o, schema.to_c(o, o.default)) == o.default, o.name


def test_the_cli_has_a_flag_for_every_online_option():
    from duffid.cli import build_parser

    identify = build_parser()._subparsers._group_actions[0].choices["identify"]  # noqa: SLF001
    flags = {s for a in identify._actions for s in a.option_strings}  # noqa: SLF001
    for o in schema.OPTIONS:
        if o.kind != "prior":
            assert "--" + o.name.replace("_", "-") in flags, o.name


@needs_cc
def test_the_estimator_fmu_parameters_are_the_schema(tmp_path):
    from duffid.fmu.estimator import build_estimator_fmu

    fmu = build_estimator_fmu("duffing1", tmp_path)
    root = ET.fromstring(zipfile.ZipFile(fmu).read("modelDescription.xml"))
    parameters = [v for v in root.iter("ScalarVariable") if v.get("causality") == "parameter"]
    names = [v.get("name") for v in parameters]
    expected = ["method", *(o.name for o in schema.fmu_parameters())]
    assert names[:len(expected)] == expected
    for v in parameters[1:len(expected)]:
        o = next(o for o in schema.OPTIONS if o.name == v.get("name"))
        start = next(iter(v)).get("start")
        assert float(start if start not in ("true", "false") else start == "true") == float(o.c_default), o.name
        assert v.get("description") == o.coded_description


def test_the_python_fmu_parameters_are_the_schema():
    from duffid.fmu.python_estimator import _option_parameters  # noqa: PLC2701 (the table under test)

    table = _option_parameters()
    assert list(table) == [o.name for o in schema.fmu_parameters()]


def test_buffered_options_come_from_the_schema():
    from duffid import Duffing1
    from duffid.identification.buffered import BufferedIdentifier

    for method in schema.BUFFERED_METHODS:
        ident = BufferedIdentifier(Duffing1(), 1e-3, method, n_terms=16)
        defaults = schema.default_options(method)
        assert {k: v for k, v in ident.options.items() if k != "n_terms"} == \
            {k: v for k, v in defaults.items() if k != "n_terms"}
    with pytest.raises(OptionError, match="no option"):
        BufferedIdentifier(Duffing1(), 1e-3, "legendre", window_periods=2.0)
    with pytest.raises(ValueError, match="window"):
        BufferedIdentifier(Duffing1(), 1e-3, "legendre", window=0.0)


def test_shared_flags_state_every_family_and_check_per_method():
    import argparse

    parser = argparse.ArgumentParser()
    schema.add_shared_arguments(parser, ("window", "max_uncertainty"), schema.ONLINE_METHODS + schema.BUFFERED_METHODS)
    schema.add_arguments(parser, "legendre", ("n_terms",))
    helps = {a.dest: a.help for a in parser._actions}
    for method in ("robust", "legendre"):
        for name in ("window", "max_uncertainty"):
            option = next(o for o in schema.options_of(method) if o.name == name)
            assert f"default {option.default_text or option.default}" in helps[name]
    args = parser.parse_args(["--window", "auto", "--terms", "12"])
    assert schema.options_from_arguments(args, "robust")["window"] == "auto"
    assert args.n_terms == 12
    with pytest.raises(InputError, match="--window auto: the legendre method takes"):
        schema.options_from_arguments(args, "legendre")


def test_the_assessment_threshold_is_the_schema_default():
    from duffid.identification.trust import ASSESSMENT_UNCERTAINTY

    assert ASSESSMENT_UNCERTAINTY == schema.default_options("robust")["max_uncertainty"]
