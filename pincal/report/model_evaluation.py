"""The typed model of ``pincal evaluate --json`` (sensor rows): eq 24 on the evaluated rows, per
session, and how a report's drift was applied (:mod:`pincal.report.model` has the shared parts)."""

from __future__ import annotations

from typing import Literal, TypedDict

from pincal.report.model import Finding, PoseErrorsJson, RegistrationPair, TimeSpanJson, Vector3
from pincal.report.model_diagnosis import PauseJson, TemperatureRangeJson

__all__ = ["EvaluatedSession", "DriftUse", "ThermalUse", "PauseStepUse", "EvaluationBefore", "EvaluationJson"]


class EvaluatedSession(TypedDict):
    """One evaluated session: where its registration came from and its errors."""

    name: str
    rows: int
    registration_source: str
    registration_reestimated: bool
    residuals: int
    registration_dof: int | None
    registration: RegistrationPair
    errors: PoseErrorsJson


class DriftUse(TypedDict):
    """How the report's drift was applied to the evaluated rows."""

    velocity_m_per_s: Vector3
    time_column: str | None
    time_reference_s: float
    time_spans_s: list[TimeSpanJson] | None
    rows_applied: int
    rows_held: int
    max_gap_s: float | None
    held_rule: str


class ThermalUse(TypedDict):
    """How the report's thermal expansion was applied: rows inside the fitted temperature range [°C] at their
    own temperature, rows outside it held at the nearer end (never extrapolated)."""

    alpha_per_k: float
    temperature_column: str
    temperature_range_c: TemperatureRangeJson
    rows_applied: int
    rows_held: int
    held_rule: str


class _PauseStepKeys(TypedDict):
    pauses: list[PauseJson]
    rows_in_span: int
    rows_outside: int
    rule: str


class PauseStepUse(_PauseStepKeys, total=False):
    """How the report's pause steps were applied: a row takes the steps of the pauses of its session before
    it (``rows_in_span``: inside the fitted rows' time span of that session; ``rows_outside``: outside it, the
    nearest segment's; ``rows_stepped``: the rows that take at least one step, after a pause — absent from
    files of pincal before it was added)."""

    rows_stepped: int


class _EvaluationKeys(PoseErrorsJson):
    skipped_cpa_rows: int
    sessions: list[EvaluatedSession]
    drift: DriftUse | None


class EvaluationBefore(TypedDict):
    """evaluate's "before": the URDF the calibration started from on the evaluated rows, its registration
    and target fitted to these rows (not the calibration's: the HTML's "nominal geometry" of the calibration
    rows is registered to those)."""

    position_rms_mm: float
    urdf: str
    registration: Literal["fitted to the evaluated rows"]


class EvaluationJson(_EvaluationKeys, total=False):
    """``pincal evaluate --json``: eq 24 on the evaluated rows, per session, and the drift's use
    (``thermal`` and ``pause_steps``: where the report has them; ``warnings``: the evaluated error against
    the calibration's, :func:`pincal.fit.plausibility.check_evaluation` — absent from files of pincal before
    it was added; ``before``: where the nominal URDF is readable, :class:`EvaluationBefore`)."""

    thermal: ThermalUse
    pause_steps: PauseStepUse
    warnings: list[Finding]
    before: EvaluationBefore
