"""The JSON Schema of the project file: generated from the models, shipped, named by the configs."""

from __future__ import annotations

import json

import pytest
from jsonschema import Draft202012Validator

from hycosim.core.schema import project_json_schema
from hycosim.cli.commands.project import SCHEMA_FILE
from tests.helpers import REPO, hycosim

CONFIGS = sorted((REPO / "hycosim").glob("**/configs/*.json"))


def test_the_shipped_schema_is_the_models_and_hycosim_schema_prints_it():
    assert json.loads(SCHEMA_FILE.read_text()) == project_json_schema(), \
        "hycosim/project.schema.json is out of date: run hycosim schema -o hycosim/project.schema.json"
    res = hycosim("schema")
    assert res.returncode == 0 and json.loads(res.stdout) == project_json_schema()
    Draft202012Validator.check_schema(project_json_schema())


@pytest.mark.parametrize("config", CONFIGS, ids=[c.name for c in CONFIGS])
def test_every_shipped_config_names_the_schema_and_meets_it(config):
    doc = json.loads(config.read_text())
    assert (config.parent / doc["$schema"]).resolve() == SCHEMA_FILE
    errors = [e.message for e in Draft202012Validator(project_json_schema()).iter_errors(doc)]
    assert errors == []


def test_the_schema_refuses_what_the_loader_refuses():
    """Not a schema that takes anything: a misspelt key, a wrong type, a bad port name fail it."""
    validator = Draft202012Validator(project_json_schema())
    good = json.loads((REPO / "hycosim" / "configs" / "default.json").read_text())
    assert validator.is_valid(good)
    for change in ({"nodeNum": "two"}, {"coSimulation": {"stepSize": -1}}, {"stopTime": 3},
                   {"nodeLists": [{**good["nodeLists"][0], "input": ["9lives"]}]},
                   {"nodeLists": [{**good["nodeLists"][0], "UID": -1}]}):
        assert not validator.is_valid({**good, **change}), change
