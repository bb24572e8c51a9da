"""The typed model of ``diagnose``'s REPORT.json: the effects and the diagnosis (:mod:`pincal.report.model`)."""

from __future__ import annotations

from typing import Literal, TypedDict

from pincal.report.model import CouplingJson, PoseErrorsJson, TimeSpanJson, Vector3, _CalibrationKeys
from pincal.report.model_level_choice import LevelChoiceJson

__all__ = [
    "EffectJson", "CandidateJson", "BeforeAfter", "DiagnosisStep", "DiagnosisJson", "ApproachContext",
    "DiagnosisReport", "TimeSpansPart",
    "TargetChangeJson", "TemperatureRangeJson", "PauseJson", "ConditionsPart",
]


class _EffectKeys(TypedDict):
    type: Literal["compliance", "encoder_scale", "cyclic", "backlash", "coupling", "drift", "sensor_scale",
                  "pause_step", "thermal", "lateral"]
    joint: str | None


class _TargetChangeKeys(TypedDict):
    rms_mm: float
    max_mm: float


class TargetChangeJson(_TargetChangeKeys, total=False):
    """How far an effect moves the target over the calibration rows (:class:`pincal.diagnosis.verdicts.TargetChange`):
    each point's distance [mm], and the target's turn [mrad] with 6D rows."""

    rms_mrad: float
    max_mrad: float


class EffectJson(_EffectKeys, total=False):
    """An effect (:func:`pincal.model.effects.effect_to_dict`): ``cyclic`` has ``harmonic``, ``sin``,
    ``cos``; the others ``value`` (drift: [vx, vy, vz] m/s; thermal: α [1/K]; pause_step: the step
    [dx, dy, dz] m of the registration's translation after its ``pause``); ``backlash`` its ``source``; ``coupling``
    its ``driver`` (the joint whose reading it adds, × value), a ``compliance`` the ``driver`` whose gravity
    torque it follows when not its own joint's, and, in the final model's ``effects``, the ``advice``
    diagnose prints for a coupling or a compliance (its sign convention and stiffness, with its own
    torque); ``*std`` when estimated; ``target_change`` in the final model's ``effects``. A compliance of
    unknown masses (``--masses unknown``, or a URDF without inertias) has ``moments`` (``PARAMETER:LINK`` whose
    loads it follows, :mod:`pincal.model.mass_moments`), one ``value`` and ``std`` per moment [rad, or m for a
    prismatic joint], and in the final model's ``effects`` the ``combinations`` each value stands for, in words."""

    harmonic: int
    sin: float
    cos: float
    sin_std: float
    cos_std: float
    value: float | Vector3 | list[float]
    std: float | Vector3 | list[float]
    source: str | None
    driver: str
    target_change: TargetChangeJson
    advice: str
    pause: int
    moments: list[str]
    combinations: list[str]


class CandidateJson(EffectJson, total=False):
    """A candidate effect of a diagnosis step: the effect's keys and its evidence."""

    delta_bic: float
    heldout_rms_mm: float | None
    verdict: str


class BeforeAfter(TypedDict):
    before: PoseErrorsJson | None
    after: PoseErrorsJson | None


class _DiagnosisStepKeys(TypedDict):
    effect: EffectJson
    delta_bic: float
    calibration: BeforeAfter
    heldout: BeforeAfter
    candidates: list[CandidateJson]


class DiagnosisStep(_DiagnosisStepKeys, total=False):
    """An adopted effect, its ΔBIC, the errors before and after, and the candidates of the step; a coupling
    found to be a joint read against another has its ``convention`` (the readings corrected by it, the
    geometry calibrated again: the report's ``couplings`` hold it, the effect's value is exactly ±1)."""

    convention: CouplingJson


class DiagnosisJson(TypedDict):
    """The diagnosis: the rule, the steps, what was left unexplained, the final errors, the plots."""

    criterion: str
    steps: list[DiagnosisStep]
    last_candidates: list[CandidateJson]
    unexplained: str | None
    calibration_errors: PoseErrorsJson | None
    heldout_errors: PoseErrorsJson | None
    notes: list[str]
    plots: list[str]


class ApproachContext(TypedDict):
    """The motion approach flanks were taken from (time [s], joint readings [rad or m]): the calibration rows,
    then the held-out rows among them or within half an hour in time (those that set their flanks)."""

    time_s: list[float]
    q: list[list[float]]


class _DiagnosisKeys(_CalibrationKeys):
    effects: list[EffectJson]
    payload_kg: float
    time_column: str | None
    time_reference_s: float | None
    approach_context: ApproachContext | None
    diagnosis: DiagnosisJson


class TemperatureRangeJson(TypedDict):
    """The temperatures [°C] of the rows a thermal expansion was fitted on: ``mean`` is T_ref; evaluate holds
    a row outside [min, max] at the nearer end (:class:`pincal.model.thermal.TemperatureRange`)."""

    min: float
    max: float
    mean: float


class PauseJson(TypedDict):
    """A pause in one session's rows: the last row's time before it and the first after it [s]
    (:class:`pincal.model.thermal.Pause`); a ``pause_step`` applies from ``after_s`` on."""

    pause: int
    session: str
    before_s: float
    after_s: float


class ConditionsPart(TypedDict, total=False):
    """What evaluate needs of an adopted thermal effect (``temperature_column``, ``temperature_range_c``) and of
    adopted pause steps (``pause_s``, ``pauses``; ``pause_spans_s``: the fitted rows' time span of each session
    with a pause, outside which a row takes its nearest segment)."""

    temperature_column: str
    temperature_range_c: TemperatureRangeJson
    pause_s: float
    pauses: list[PauseJson]
    pause_spans_s: list[TimeSpanJson]


class DiagnosisReport(_DiagnosisKeys, ConditionsPart, total=False):
    """REPORT.json of ``diagnose``: the calibration's keys, the effects and the diagnosis
    (``time_spans_s``: with an adopted drift; ``level_choice``: ``--level auto``; ``couplings``: ``--coupling``;
    :class:`ConditionsPart`: with an adopted thermal effect or pause step)."""

    time_spans_s: list[TimeSpanJson]
    level_choice: LevelChoiceJson
    couplings: list[CouplingJson]


class TimeSpansPart(TypedDict, total=False):
    """``time_spans_s`` where a diagnosis report has it (an adopted drift), to unpack into it."""

    time_spans_s: list[TimeSpanJson]
