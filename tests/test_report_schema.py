"""docs/report.schema.json: generated from the typed model, strict, and what the docs list.

Every JSON document the other tests write is validated against it as it is written
(tests/conftest.py, ``_validate_written_documents``); here: the committed file is the
generated one, the generator's mapping, the schema's strictness on a real report, and
the agreement of docs/report-json.md with the schema's top-level keys.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Annotated, Any, Literal, TypedDict, get_args, get_type_hints

import jsonschema
import pytest
from conftest import SCHEMA_PATH, report_kind, validate_document

from pincal.cli import main
from pincal.model.effects import EFFECT_TYPES
from pincal.model.parameter_sets import CHAIN_LEVELS
from pincal.report.model import ChainLevel, PaperMethod
from pincal.report.model_diagnosis import EffectJson
from pincal.report.schema import REPORT_KINDS, _Generator, json_schema, schema_text
from pincal.robots import KUKA_FLANGE_LINK

DOCS = Path(__file__).resolve().parents[1] / "docs"


def test_committed_schema_is_the_generated_one():
    assert SCHEMA_PATH.read_text(encoding="utf-8") == schema_text(), (
        "docs/report.schema.json is stale: python -m pincal.report.schema > docs/report.schema.json")


def test_schema_is_a_valid_draft_2020_12_schema():
    jsonschema.Draft202012Validator.check_schema(json_schema())


def test_enumerations_are_those_of_the_code():
    assert get_args(get_type_hints(EffectJson)["type"]) == EFFECT_TYPES
    assert dict(get_args(ChainLevel)[1:])["enum"] == tuple(CHAIN_LEVELS)
    assert dict(get_args(PaperMethod)[1:])["enum"] == (1, 2, 3)


class _Inner(TypedDict):
    """An inner object."""

    x: float


class _ToyKeys(TypedDict):
    name: str
    count: int
    flag: bool
    kind: Literal["a", "b"]
    one: Literal[1]
    maybe: float | None
    either: str | list[str]
    inner: _Inner | None
    table: dict[str, int]
    vector: Annotated[list[float], ("minItems", 3), ("maxItems", 3)]
    level: Annotated[str, ("enum", ("x", "y"))]
    anything: Any


class _Toy(_ToyKeys, total=False):
    """A toy document."""

    extra: list[_Inner]


def test_generator_maps_each_annotation():
    generator = _Generator()
    assert generator.object(_Toy) == {"$ref": "#/$defs/_Toy"}
    toy = generator.defs["_Toy"]
    assert toy["description"] == "A toy document."
    assert toy["additionalProperties"] is False
    assert toy["required"] == list(_ToyKeys.__annotations__)  # "extra" is optional
    assert toy["properties"] == {
        "name": {"type": "string"},
        "count": {"type": "integer"},
        "flag": {"type": "boolean"},
        "kind": {"enum": ["a", "b"]},
        "one": {"const": 1},
        "maybe": {"type": ["number", "null"]},
        "either": {"anyOf": [{"type": "string"}, {"type": "array", "items": {"type": "string"}}]},
        "inner": {"anyOf": [{"$ref": "#/$defs/_Inner"}, {"type": "null"}]},
        "table": {"type": "object", "additionalProperties": {"type": "integer"}},
        "vector": {"type": "array", "items": {"type": "number"}, "minItems": 3, "maxItems": 3},
        "level": {"type": "string", "enum": ["x", "y"]},
        "anything": {},
        "extra": {"type": "array", "items": {"$ref": "#/$defs/_Inner"}},
    }
    assert generator.defs["_Inner"]["required"] == ["x"]


def test_generator_refuses_what_json_cannot_hold():
    with pytest.raises(TypeError, match="no JSON Schema"):
        _Generator().schema(set[int])
    with pytest.raises(TypeError, match="keys are strings"):
        _Generator().schema(dict[int, str])


@pytest.fixture(scope="module")
def written_report(tmp_path_factory, kuka_urdf):
    """A REPORT.json of calibrate --level registration on simulated rows (validated as written)."""
    out = tmp_path_factory.mktemp("schema")
    assert main(["simulate", "--out", str(out / "sim"), "--deviations", "small", "--seed", "5"]) == 0
    assert main(["calibrate", str(kuka_urdf), str(out / "sim" / "calibration.csv"),
                 "--tip-link", KUKA_FLANGE_LINK, "--level", "registration",
                 "--out", str(out / "c.urdf"), "--report", str(out / "REPORT.json")]) == 0
    return json.loads((out / "REPORT.json").read_text())


def test_a_written_report_is_valid_and_of_one_kind(written_report):
    validate_document(written_report)
    assert report_kind(written_report) == "CalibrationReport"
    schema = json_schema()
    matching = [kind.__name__ for kind in REPORT_KINDS
                if jsonschema.Draft202012Validator({"$ref": f"#/$defs/{kind.__name__}", "$defs": schema["$defs"]})
                .is_valid(written_report)]
    assert matching == ["CalibrationReport"]


def test_a_report_valid_as_two_kinds_fails(written_report, monkeypatch):
    """The suite's check of the schema's oneOf (conftest.validate_document: every other kind must refuse a
    report) fails when another kind would accept it: here a kind that is the CalibrationReport again."""
    import conftest

    monkeypatch.setitem(conftest._validators, "Twin", conftest._validator("CalibrationReport"))
    monkeypatch.setattr(conftest, "report_kinds", lambda: ["CalibrationReport", "Twin"])
    with pytest.raises(jsonschema.ValidationError, match="valid as CalibrationReport and as .'Twin'."):
        validate_document(written_report)
    monkeypatch.setattr(conftest, "report_kinds", lambda: ["CalibrationReport", "PaperReport"])
    validate_document(written_report)


@pytest.fixture(scope="module")
def generated_schema():
    """A validator of the schema the typed model generates (its own validity: test_schema_is_a_valid_draft...)."""
    return jsonschema.Draft202012Validator(json_schema())


#: Values an integer leaf refuses: a string, and the ones a loose type check lets through (a bool is an int in
#: Python, 1.5 a number); tests/conftest.py checks such leaves in place rather than through jsonschema's descent.
NOT_INTEGERS = {"retype": "12", "retype-bool": True, "retype-float": 1.5, "retype-null": None}


@pytest.mark.parametrize("change", ["rename", "drop", *NOT_INTEGERS, "add", "nested"])
def test_a_renamed_missing_or_mistyped_key_fails(written_report, generated_schema, change):
    report = json.loads(json.dumps(written_report))
    if change == "rename":
        report["removed_file"] = report.pop("removed_files")
    elif change == "drop":
        del report["urdf_sha256"]
    elif change in NOT_INTEGERS:
        report["fit"]["rows_used"] = NOT_INTEGERS[change]
    elif change == "add":
        report["tool"]["points"] = report["tool"]["points_m"]
    else:
        del report["sessions"][0]["registration"]["orientation"]
    with pytest.raises(jsonschema.ValidationError):
        validate_document(report)
    assert generated_schema.is_valid(written_report)
    assert not generated_schema.is_valid(report)  # no error message walked: which key, validate_document says


def _documented_keys() -> set[str]:
    text = (DOCS / "report-json.md").read_text(encoding="utf-8")
    return {match.split(".")[0] for match in re.findall(r"^\| `([a-z0-9_.]+)` \|", text, flags=re.M)}


def test_reference_page_lists_exactly_the_top_level_keys_of_the_schema():
    schema = json_schema()
    keys = set().union(*(schema["$defs"][kind.__name__]["properties"] for kind in REPORT_KINDS))
    documented = _documented_keys()
    assert documented - keys == set(), "documented in docs/report-json.md but not in the schema"
    assert keys - documented == set(), "in the schema but not documented in docs/report-json.md"
