"""Facts shared by Python and C have one home: generated headers are current, hand-written C
enumerations equal the Python tables that write the FMUs' variable tables."""
from __future__ import annotations

import re

import pytest

from duffid.assets import fmu_sources
from duffid.fmu.c_model import TYPE_CODES
from duffid.fmu.variables import CAUSALITY_CODES, VARIABILITY_CODES
from duffid.identification import c_core, c_facts, engine
from duffid.identification.c_core import source_dir


def test_the_facts_header_is_generated_from_c_facts():
    assert (source_dir() / c_facts.C_HEADER_NAME).read_text() == c_facts.c_header(), \
        "fmus/estimator/duffid_facts.h is stale: run `make generated`"


def test_no_c_source_restates_a_fact():
    """Every macro of duffid_facts.h is defined there only (no copy in the other sources)."""
    macros = [f.macro for f in (*c_facts.LIMITS.values(), *c_facts.RETURN_CODES.values(), *c_facts.MODEL_CODES,
                                *c_facts.PUBLICATION)]
    for path in sorted(source_dir().glob("*.[ch]")):
        if path.name == c_facts.C_HEADER_NAME:
            continue
        text = path.read_text()
        restated = [m for m in macros if re.search(rf"#\s*define\s+{m}\b", text)]
        assert not restated, f"{path.name} defines {restated}: they belong to {c_facts.C_HEADER_NAME}"


def test_the_binding_reads_the_facts():
    assert c_core._MAX_PARAMS == c_facts.limit("max_params")
    assert c_core._LIMITS["name"][1] == c_facts.limit("name_size") - 1
    assert c_core._ERR_SAMPLE == c_facts.return_code("err_sample")
    assert [f.value for f in c_facts.PUBLICATION[:len(engine.STATUSES)]] == list(range(len(engine.STATUSES)))


def _enum(text: str, prefix: str) -> dict[str, int]:
    return {name: int(value) for name, value in re.findall(rf"\b{prefix}_([A-Z0-9_]+)\s*=\s*(\d+)", text)}


def _camel(name: str) -> str:
    head, *rest = name.lower().split("_")
    return head + "".join(part.capitalize() for part in rest)


@pytest.mark.parametrize("prefix, table", [("CAUSALITY", CAUSALITY_CODES), ("VARIABILITY", VARIABILITY_CODES)])
def test_fmu_model_codes_equal_the_python_tables(prefix, table):
    header = (fmu_sources("common") / "fmu_model.h").read_text()
    assert {_camel(k): v for k, v in _enum(header, prefix).items()} == table


def test_fmu_model_type_codes_equal_the_python_table():
    header = (fmu_sources("common") / "fmu_model.h").read_text()
    c_types = _enum(header, "VARTYPE")
    assert c_types == {"FLOAT64": TYPE_CODES["Float64"], "INTEGER": TYPE_CODES["Integer"],
                       "BOOLEAN": TYPE_CODES["Boolean"]}
