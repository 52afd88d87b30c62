"""One model registry (duffid.models.registry): every caller reads it, every model follows
the IdentifiableModel protocol."""
from __future__ import annotations

import pytest

from duffid.campaign.plants import PLANTS
from duffid.cli import common
from duffid.errors import InputError
from duffid.fmu import estimator_table
from duffid.identification import c_facts
from duffid.models.equation_model import EquationModel
from duffid.models.registry import (
    GENERATED_MODEL_CODE,
    MODEL_NAMES,
    PLANT_NAMES,
    REGISTRY,
    IdentifiableModel,
    model_from_name,
)


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_every_named_model_is_built_and_identifiable(name):
    model = model_from_name(name, 2)
    assert isinstance(model, IdentifiableModel)
    assert model.name == name or (name == "chain" and model.n_dof == 2)


def test_callers_read_the_registry():
    assert common.MODELS == MODEL_NAMES
    assert tuple(PLANTS) == PLANT_NAMES and all(PLANTS[n] is REGISTRY[n].cls for n in PLANTS)
    named = [n for n, e in REGISTRY.items() if e.fmu_name]
    assert list(estimator_table.C_FMU_NAMES) == named
    assert all(estimator_table.MODEL_CODES[n] == REGISTRY[n].c_code for n in named)
    assert all(len(estimator_table.INPUTS[n]) == REGISTRY[n].cls().n_dof + REGISTRY[n].cls().n_forces
               for n in named)
    codes = {f.macro: f.value for f in c_facts.MODEL_CODES}
    assert codes == {"DUFFID_DUFFING1": 1, "DUFFID_DUFFING2": 2, "DUFFID_GENERATED": GENERATED_MODEL_CODE}


def test_unknown_names_and_non_models_are_refused():
    with pytest.raises(InputError, match="unknown model 'duffing3'; choose one of duffing1, duffing2, chain, circuit"):
        model_from_name("duffing3")
    assert isinstance(EquationModel("m*der(x,2) + k*x = f", ["t", "f", "x"]), IdentifiableModel)
    assert not isinstance("duffing1", IdentifiableModel)
