"""The case-file key table: the loader checks against it, and the reference and JSON Schema generated
from it are up to date and accept every shipped case."""
from __future__ import annotations

import copy
import json
from pathlib import Path

import jsonschema
import pytest
import yaml

import dynsens
from dynsens.case import schema
from dynsens.case_keys import SECTIONS, allowed

REPO = Path(__file__).resolve().parents[1]
CASES = sorted((REPO / "cases").glob("*.yaml"))


def test_generated_reference_and_schema_are_up_to_date() -> None:
    assert schema.main(["--check"]) == 0, "run: python -m dynsens.case.schema --write"


@pytest.fixture(scope="module")
def validator() -> jsonschema.Draft202012Validator:
    doc = json.loads(schema.SCHEMA_PATH.read_text(encoding="utf-8"))
    jsonschema.Draft202012Validator.check_schema(doc)
    return jsonschema.Draft202012Validator(doc)


@pytest.mark.parametrize("path", CASES, ids=[p.stem for p in CASES])
def test_every_shipped_case_satisfies_the_schema(path: Path, validator) -> None:
    errors = [f"{list(e.absolute_path)}: {e.message}" for e in validator.iter_errors(yaml.safe_load(path.read_text()))]
    assert not errors, errors


@pytest.mark.parametrize("where,key", [
    (("integrator",), "dtt"),
    (("model", "forces", 1), "bulk_modulud"),
    (("responses", 3), "rhoo"),
    (("model", "joints", 0), "axes"),
])
def test_a_misspelt_key_is_rejected_by_schema_and_loader(where, key, validator) -> None:
    raw = yaml.safe_load((REPO / "cases" / "tyrolean_weir.yaml").read_text())
    bad = copy.deepcopy(raw)
    node = bad
    for w in where:
        node = node[w]
    node[key] = 1.0
    assert any(key in e.message or key in str(list(e.absolute_path)) for e in validator.iter_errors(bad))
    with pytest.raises(dynsens.CaseError, match=key):
        dynsens.load_case_dict(bad)


@pytest.mark.parametrize("section,where", [
    ("integrator", ("integrator",)),
    ("multibody.hydraulic_cylinder", ("model", "forces", 1)),
    ("response.ks", ("responses", 3)),
    ("multibody.joint", ("model", "joints", 0)),
    ("model.multibody", ("model",)),
])
def test_the_loader_accepts_exactly_the_table_keys(section, where) -> None:
    # the loader's "allowed:" list for an unknown key is the table's section
    raw = yaml.safe_load((REPO / "cases" / "tyrolean_weir.yaml").read_text())
    node = raw
    for w in where:
        node = node[w]
    node["not_a_key"] = 1
    with pytest.raises(dynsens.CaseError) as exc:
        dynsens.load_case_dict(raw)
    line = next(ln for ln in str(exc.value).splitlines() if "not_a_key" in ln)
    listed = line.split("allowed: ", 1)[1].rstrip(")").split(", ")
    assert listed == sorted(set(allowed(section)))


def test_schema_rejects_a_missing_required_key(validator) -> None:
    raw = yaml.safe_load((REPO / "cases" / "sdof_step.yaml").read_text())
    del raw["integrator"]["dt"]
    assert any("'dt' is a required property" in e.message for e in validator.iter_errors(raw))


def test_every_section_documents_every_key() -> None:
    text = schema.REFERENCE_PATH.read_text(encoding="utf-8")
    for name, sec in SECTIONS.items():
        assert sec.title in text
        for k in sec.keys:
            assert k.doc and f"| `{k.name}` |" in text, (name, k.name)


@pytest.mark.parametrize("section,where", [
    ("design.family", ("design", "families", 0)),
    ("response.stress_ratio", ("responses", 1)),
    ("response.buckling_ratio", ("responses", 2)),
    ("structural.bar", ("model", "elements", 0)),
])
def test_the_sizing_loaders_accept_exactly_the_table_keys(section, where) -> None:
    # the sizing responses, design families and bar keys are checked against the same table
    raw = yaml.safe_load((REPO / "cases" / "tower_sizing.yaml").read_text())
    node = raw
    for w in where:
        node = node[w]
    if section == "structural.bar":
        node = next(el for el in raw["model"]["elements"] if el["type"] == "bar")
    node["not_a_key"] = 1
    with pytest.raises(dynsens.CaseError) as exc:
        dynsens.load_case_dict(raw)
    line = next(ln for ln in str(exc.value).splitlines() if "not_a_key" in ln)
    listed = line.split("allowed: ", 1)[1].rstrip(")").split(", ")
    assert listed == sorted(set(allowed(section)))
