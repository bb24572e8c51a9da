"""``pincal evaluate`` whole: the evaluation, its thresholds judged, ``--json`` and ``--html`` written.

:func:`evaluate_files` measures; :func:`evaluate_and_write` is the command: it refuses what it cannot
do before it writes anything — an ``--html`` path that is an input or the ``--json`` path (before the
evaluation), a threshold the errors cannot be judged by (a re-estimated registration with too few
degrees of freedom left, :meth:`Evaluation.threshold_problem`; ``max_rot_deg`` without orientations),
a ``--json`` path that is an input, a report the page cannot be made of — then writes each output whole
(:mod:`pincal.outputs`) and returns which thresholds the largest errors exceed. The socket fixture's
``evaluate --fixture`` writes its outputs the same way (:func:`pincal.workflows.fixture.evaluate_fixture_files`
through :func:`write_outputs`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from pincal.errors import PincalError
from pincal.outputs import write_text
from pincal.report.document import write_evaluation
from pincal.report.html import render_html
from pincal.report.model_evaluation import EvaluationJson
from pincal.report.model_fixture import FixtureEvaluationJson
from pincal.report.reading import PAGE_KINDS, load_report
from pincal.report.row_errors import EvaluatedRows, evaluation_document
from pincal.workflows.evaluation import Evaluation, evaluate_files
from pincal.workflows.paths import description_inputs, paths_in, refuse_overwrite
from pincal.workflows.settings import EvaluateSettings, expect

__all__ = ["EvaluateOutputs", "ThresholdFailure", "EvaluateRun", "evaluate_and_write", "write_outputs"]


@dataclass(frozen=True)
class EvaluateOutputs:
    """The files ``pincal evaluate`` writes besides printing: ``--json`` (:data:`EvaluationJson`) and ``--html``
    (the report's page with the evaluation beside it); None: not written."""

    json: Path | None = None
    html: Path | None = None

    def __post_init__(self) -> None:
        paths_in(self, "json", "html")


@dataclass(frozen=True)
class ThresholdFailure:
    """A threshold the largest error exceeds: ``error`` > ``threshold``, both in ``unit``."""

    quantity: Literal["position", "orientation"]
    error: float
    threshold: float
    unit: Literal["mm", "deg"]

    @property
    def text(self) -> str:
        """``max position error 1.2345 mm > 1.0 mm``: the line ``pincal evaluate`` prints after ``FAIL:``."""
        return f"max {self.quantity} error {self.error:.4f} {self.unit} > {self.threshold} {self.unit}"


@dataclass(frozen=True)
class EvaluateRun:
    """Outcome of :func:`evaluate_and_write`.

    Attributes:
        evaluation: the errors, sessions and notes (:func:`evaluate_files`).
        document: ``evaluate --json``'s document (written or not); its ``warnings`` are the evaluation's.
        failed: the thresholds of the settings the largest errors exceed, position first; empty: passed
            (or none given).
        written: the outputs written, ``--json`` first.
    """

    evaluation: Evaluation
    document: EvaluationJson
    failed: tuple[ThresholdFailure, ...]
    written: tuple[Path, ...]


def evaluate_and_write(
    urdf: str | Path, report_path: str | Path, data_path: str | Path, settings: EvaluateSettings | None = None,
    outputs: EvaluateOutputs | None = None,
) -> EvaluateRun:
    """``pincal evaluate URDF REPORT.json DATA``: :func:`evaluate_files`, then the thresholds of ``settings``
    (``max_pos_mm``, ``max_rot_deg``) judged and ``outputs`` written (module docstring for what is refused
    first). Neither input is ever overwritten.

    Raises:
        PincalError: an output that is an input (or ``--html`` the ``--json``), a threshold the errors cannot
            judge, and whatever :func:`evaluate_files` refuses; nothing is written then.
    """
    settings = EvaluateSettings() if settings is None else settings
    expect(settings, EvaluateSettings, "evaluate_and_write")
    outputs = EvaluateOutputs() if outputs is None else outputs
    inputs = [*description_inputs(urdf, settings.xacro_args), report_path, data_path]
    if outputs.html is not None:
        refuse_overwrite(outputs.html, *inputs, outputs=[o for o in (outputs.json,) if o is not None])
    evaluation = evaluate_files(urdf, report_path, data_path, settings)
    thresholds = [flag for flag, value in (("--max-pos-mm", settings.max_pos_mm),
                                           ("--max-rot-deg", settings.max_rot_deg)) if value is not None]
    problem = evaluation.threshold_problem() if thresholds else None
    if problem:
        raise PincalError(f"{data_path}: {thresholds[0]}: {problem}")
    if settings.max_rot_deg is not None and evaluation.errors.rotation is None:
        raise PincalError(f"{data_path}: --max-rot-deg needs orientation columns qx,qy,qz,qw")
    if outputs.json is not None:
        refuse_overwrite(outputs.json, *inputs)
    document = evaluation.as_dict()  # evaluate --json; the page shows its warnings as such
    shown = None
    if outputs.html is not None:
        shown = evaluation_document(str(urdf), str(data_path), evaluation.errors, document,
                                    EvaluatedRows(evaluation.lines, evaluation.files, evaluation.row_sessions))
    written = write_outputs(outputs, document, report_path, shown)
    return EvaluateRun(evaluation, document, _failed(evaluation, settings), written)


def write_outputs(outputs: EvaluateOutputs, document: EvaluationJson | FixtureEvaluationJson,
                  report_path: str | Path, shown: Mapping[str, Any] | None) -> tuple[Path, ...]:
    """Write ``document`` to ``outputs.json`` and the page of ``report_path`` with ``shown`` (the evaluation
    beside it) to ``outputs.html``; the page is made before either is written, so a report it cannot be
    made of leaves both unwritten. Returns the paths written, in that order."""
    page = None
    if outputs.html is not None:
        report_path = Path(report_path)
        page = render_html(dict(load_report(report_path, PAGE_KINDS)),
                           evaluation=None if shown is None else dict(shown), base=report_path.parent,
                           source=report_path)
    written: list[Path] = []
    if outputs.json is not None:
        write_evaluation(outputs.json, document)
        written.append(outputs.json)
    if outputs.html is not None and page is not None:
        write_text(outputs.html, page)
        written.append(outputs.html)
    return tuple(written)


def _failed(evaluation: Evaluation, settings: EvaluateSettings) -> tuple[ThresholdFailure, ...]:
    """The thresholds of ``settings`` that ``evaluation``'s largest errors exceed, position first."""
    errors, failed = evaluation.errors, []
    if settings.max_pos_mm is not None and errors.position.max > settings.max_pos_mm:
        failed.append(ThresholdFailure("position", errors.position.max, settings.max_pos_mm, "mm"))
    rotation = errors.rotation
    if settings.max_rot_deg is not None and rotation is not None and rotation.max > settings.max_rot_deg:
        failed.append(ThresholdFailure("orientation", rotation.max, settings.max_rot_deg, "deg"))
    return tuple(failed)
