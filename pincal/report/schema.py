"""``docs/report.schema.json``: the JSON Schema of REPORT.json, generated from its typed model.

``python -m pincal.report.schema > docs/report.schema.json`` writes it (a test checks the
committed file is what this prints). The top level accepts any of the six kinds of
REPORT.json (:data:`REPORT_KINDS`); ``$defs`` holds every object of
the model, among them ``EvaluationJson`` / ``FixtureEvaluationJson`` (``pincal evaluate
--json``) and ``PlanJson`` (PLAN.json, :mod:`pincal.planning.files`), which a document
is checked against with ``{"$ref": "#/$defs/PlanJson"}``.

The classes are TypedDicts (:mod:`pincal.report.model`); this module maps their
annotations to JSON Schema: ``str``, ``int``, ``float`` (any number), ``bool``,
``None`` (null), ``Literal`` (enum), ``list[X]``, ``dict[str, X]``, unions,
``Annotated[X, (KEYWORD, VALUE), ...]`` (X's schema with those keywords) and ``Any`` (anything).
Each TypedDict is an object of exactly its keys (``additionalProperties: false``),
its required keys those not declared in a ``total=False`` class; its docstring is
its ``description``.
"""

from __future__ import annotations

import inspect
import json
import types
import typing
from typing import Any, Literal, Union, get_args, get_origin, get_type_hints

from pincal.planning.files import PlanJson
from pincal.report.model import CalibrationReport, PaperReport
from pincal.report.model_camera import CameraEvaluationJson, CameraReport
from pincal.report.model_diagnosis import DiagnosisReport
from pincal.report.model_evaluation import EvaluationJson
from pincal.report.model_fixture import FixtureEvaluationJson, FixtureReport
from pincal.report.model_tree import TreeEvaluationJson, TreeReport

__all__ = ["REPORT_KINDS", "SCHEMA_ID", "OTHER_DOCUMENTS", "json_schema", "schema_text"]

#: The kinds of REPORT.json, the schema's top level.
REPORT_KINDS: tuple[type, ...] = (CalibrationReport, DiagnosisReport, PaperReport, FixtureReport, TreeReport,
                                  CameraReport)
SCHEMA_ID = "https://pincal.invalid/report.schema.json"
#: Documents described in ``$defs`` besides the kinds of REPORT.json.
OTHER_DOCUMENTS: tuple[type, ...] = (EvaluationJson, FixtureEvaluationJson, TreeEvaluationJson, PlanJson,
                                     CameraEvaluationJson)

_SCALARS: dict[Any, str] = {str: "string", int: "integer", float: "number", bool: "boolean", type(None): "null"}


def _is_typeddict(annotation: Any) -> bool:
    return isinstance(annotation, type) and typing.is_typeddict(annotation)


class _Generator:
    def __init__(self) -> None:
        self.defs: dict[str, dict[str, Any]] = {}

    def object(self, cls: type) -> dict[str, Any]:
        """``{"$ref": ...}`` to ``cls``'s definition, made on first use."""
        name = cls.__name__
        if name not in self.defs:
            self.defs[name] = {}  # reserved: a class may refer to itself
            hints = get_type_hints(cls, include_extras=True)
            required = cls.__required_keys__  # type: ignore[attr-defined]
            definition: dict[str, Any] = {"type": "object"}
            doc = inspect.getdoc(cls)
            if doc and cls.__doc__ is not None and "__doc__" in cls.__dict__:
                definition["description"] = " ".join(doc.split())
            definition["properties"] = {key: self.schema(hint) for key, hint in hints.items()}
            definition["required"] = [key for key in hints if key in required]
            definition["additionalProperties"] = False
            self.defs[name] = definition
        return {"$ref": f"#/$defs/{name}"}

    def schema(self, annotation: Any) -> dict[str, Any]:
        """The JSON Schema of one annotation."""
        origin, args = get_origin(annotation), get_args(annotation)
        if origin is typing.Annotated:
            keywords = {k: list(v) if isinstance(v, tuple) else v for k, v in annotation.__metadata__}
            return {**self.schema(args[0]), **keywords}
        if annotation is Any:
            return {}
        if annotation is None or (isinstance(annotation, type) and annotation in _SCALARS):
            return {"type": _SCALARS[type(None) if annotation is None else annotation]}
        if _is_typeddict(annotation):
            return self.object(annotation)
        if origin is Literal:
            return {"const": args[0]} if len(args) == 1 else {"enum": list(args)}
        if origin is list:
            return {"type": "array", "items": self.schema(args[0])}
        if origin is dict:
            if args[0] is not str:
                raise TypeError(f"JSON object keys are strings, not {args[0]!r}")
            return {"type": "object", "additionalProperties": self.schema(args[1])}
        if origin in (Union, types.UnionType):
            members = [self.schema(a) for a in args]
            if all(set(m) == {"type"} and isinstance(m["type"], str) for m in members):
                return {"type": [m["type"] for m in members]}
            return {"anyOf": members}
        raise TypeError(f"no JSON Schema for the annotation {annotation!r}")


def json_schema() -> dict[str, Any]:
    """The JSON Schema of REPORT.json, with ``evaluate --json`` and PLAN.json in ``$defs``."""
    generator = _Generator()
    kinds = [generator.object(kind) for kind in REPORT_KINDS]
    for document in OTHER_DOCUMENTS:
        generator.object(document)
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "$id": SCHEMA_ID,
        "title": "pincal REPORT.json",
        "description": "What pincal calibrate and diagnose write with the corrected URDF: one of "
                       + ", ".join(kind.__name__ for kind in REPORT_KINDS) + ". Generated from "
                       "pincal.report.model by 'python -m pincal.report.schema'; $defs also describes "
                       + ", ".join(d.__name__ for d in OTHER_DOCUMENTS) + " (pincal evaluate --json, PLAN.json).",
        "oneOf": kinds,
        "$defs": dict(sorted(generator.defs.items())),
    }


def schema_text() -> str:
    """The schema as ``docs/report.schema.json`` holds it."""
    return json.dumps(json_schema(), indent=2, ensure_ascii=False) + "\n"


if __name__ == "__main__":
    print(schema_text(), end="")
