"""Reading back what pincal wrote: REPORT.json, ``pincal evaluate --json`` and PLAN.json.

One loader for every reader (``evaluate``, ``evaluate --fixture``, ``report`` and the
``--html`` pages): :func:`load_report` reads the file, tells its kind from its keys
(:func:`document_kind`) and returns it as the typed model of :mod:`pincal.report.model`
(:data:`Document`); :func:`value_at` reads one value of it by its dotted key. Whatever is
wrong is one line naming the file and, for a value, the key: no such file, a folder, not
JSON (with its line and column), another kind of document than the reader takes, a key
missing or a value of the wrong form.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Collection, Mapping
from pathlib import Path
from typing import Any, TypeVar, cast

from pincal.errors import PincalError
from pincal.planning.files import PlanJson
from pincal.report.model import CalibrationReport, PaperReport
from pincal.report.model_camera import CameraEvaluationJson, CameraReport
from pincal.report.model_diagnosis import DiagnosisReport
from pincal.report.model_evaluation import EvaluationJson
from pincal.report.model_fixture import FixtureEvaluationJson, FixtureReport
from pincal.report.model_tree import TreeEvaluationJson, TreeReport

__all__ = [
    "KINDS", "REPORT_KINDS", "PAGE_KINDS", "ReportDocument", "Document", "document_kind", "load_report", "value_at",
]

ReportDocument = CalibrationReport | DiagnosisReport | PaperReport | FixtureReport | TreeReport | CameraReport
Document = ReportDocument | EvaluationJson | FixtureEvaluationJson | PlanJson | CameraEvaluationJson

#: Each kind of document pincal writes: its typed model and what it is called in a message.
KINDS: dict[str, tuple[type, str]] = {
    "calibration": (CalibrationReport, "a calibration's REPORT.json"),
    "diagnosis": (DiagnosisReport, "a diagnosis' REPORT.json"),
    "paper": (PaperReport, "a paper method's REPORT.json (--level dh)"),
    "fixture": (FixtureReport, "a socket-fixture calibration's REPORT.json"),
    "tree": (TreeReport, "a REPORT.json of several --tip-link, which this command does not take yet (calibrate "
                         "and diagnose write it; each target's errors are in it)"),
    "evaluation": (EvaluationJson, "the file of 'pincal evaluate --json'"),
    "fixture evaluation": (FixtureEvaluationJson, "the file of 'pincal evaluate --fixture --json'"),
    "plan": (PlanJson, "a PLAN.json"),
    "camera": (CameraReport, "a camera's REPORT.json (calibrate --camera-link)"),
    "camera evaluation": (CameraEvaluationJson, "the file of 'pincal evaluate --json' of a camera's report"),
    "tree evaluation": (TreeEvaluationJson, "the file of 'pincal evaluate --json' of a tree's report (targets)"),
}
#: The kinds of REPORT.json (the schema's top level, :data:`pincal.report.schema.REPORT_KINDS`).
REPORT_KINDS = ("calibration", "diagnosis", "paper", "fixture", "tree", "camera")
#: The kinds :func:`pincal.report.html.render_html` lays out as a page.
PAGE_KINDS = ("calibration", "diagnosis", "paper", "fixture", "tree", "evaluation", "plan", "camera")

_T = TypeVar("_T")
_MISSING: Any = object()


def document_kind(document: Any) -> str | None:
    """The kind (a key of :data:`KINDS`) of a JSON document, told by the keys only it has; None
    for anything else. A socket-fixture calibration's REPORT.json has ``fixture``, any other
    ``parameters``: a camera's ``measurement`` ``"camera"``, a diagnosis' also ``diagnosis``, a paper method's
    ``model`` ``"dh"``, one of several
    ``--tip-link`` ``targets``."""
    if not isinstance(document, dict):
        return None
    if "plan_version" in document:
        return "plan"
    if "fixture" in document:
        return "fixture"
    if document.get("measurement") == "camera" and "camera" in document:
        return "camera"
    if "targets" in document and "parameters" in document:
        return "tree"
    if "parameters" in document:
        if "diagnosis" in document:
            return "diagnosis"
        return "paper" if document.get("model") == "dh" else "calibration"
    if "position" in document:
        return "evaluation"
    if "after" in document and "not_held_out" in document:
        return "fixture evaluation"
    if "reprojection" in document and "world" in document:
        return "camera evaluation"
    if "evaluated_targets" in document:
        return "tree evaluation"
    return None


def _read_json(path: Path) -> Any:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise PincalError(f"{path}: no such report file") from None
    except IsADirectoryError:
        raise PincalError(f"{path}: is a directory; give the REPORT.json file") from None
    except json.JSONDecodeError as exc:
        raise PincalError(f"{path}: not a readable JSON report ({exc.msg} at line {exc.lineno}, "
                          f"column {exc.colno})") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise PincalError(f"{path}: not a readable JSON report ({exc})") from None


def load_report(
    path: str | Path,
    accept: Collection[str] = tuple(KINDS),
    hint: str = "pass the REPORT.json of calibrate or diagnose, or the PLAN.json of plan",
    hints: Mapping[str, str] | None = None,
) -> Document:
    """The document at ``path``, one of the ``accept`` kinds (keys of :data:`KINDS`).

    Args:
        path: the file.
        accept: the kinds the caller reads.
        hint: what to do instead, the end of the message for a file of another kind.
        hints: what to do instead for a given other kind (it replaces ``hint``).

    Raises:
        PincalError: one line naming the file: missing, a folder, not JSON, not a pincal
            document, or a kind not in ``accept`` (named, with the hint).
    """
    path = Path(path)
    document = _read_json(path)
    kind = document_kind(document)
    if kind in accept:
        return cast(Document, document)
    if kind is None:
        what = ("not a pincal report (no 'parameters', nor the 'position' errors of 'pincal evaluate --json', "
                "nor a PLAN.json's 'plan_version')")
    else:
        what = f"is {KINDS[kind][1]}"
    if kind == "tree" and kind not in (hints or {}):  # its description says what to do
        raise PincalError(f"{path}: {what}")
    raise PincalError(f"{path}: {what}; {(hints or {}).get(kind or '', hint)}")


def value_at(
    document: Mapping[str, Any],
    key: str,
    source: str | Path,
    convert: Callable[[Any], _T] | None = None,
    default: Any = _MISSING,
) -> _T | Any:
    """The value of ``document`` at the dotted ``key`` (``"registration.position"``), through
    ``convert`` when given; ``default`` when a key on the way is missing (if given).

    Raises:
        PincalError: one line naming ``source`` (the file) and the key: missing (without a
            default), or a value ``convert`` refuses (a ``KeyError``, ``TypeError`` or ``ValueError``
            ``AttributeError`` or a :class:`PincalError` without the file it raises, whose text ends
            the line).
    """
    value: Any = document
    for depth, part in enumerate(parts := key.split(".")):
        if not isinstance(value, Mapping):
            where = ".".join(parts[:depth])
            raise PincalError(f"{source}: key '{where}' is not an object (got {type(value).__name__}); "
                              "pass a REPORT.json as pincal wrote it")
        if part not in value:
            if default is not _MISSING:
                return default
            raise PincalError(f"{source}: no key '{key}'; pass a REPORT.json as pincal wrote it")
        value = value[part]
    if convert is None:
        return value
    try:
        return convert(value)
    except (KeyError, TypeError, ValueError, AttributeError, PincalError) as exc:
        detail = f"no key {exc}" if isinstance(exc, KeyError) else str(exc)
        raise PincalError(f"{source}: key '{key}' has an unexpected form ({detail}); "
                          "pass a REPORT.json as pincal wrote it") from None
