"""The typed model of REPORT.json and of ``pincal evaluate --json``: one TypedDict per object.

A REPORT.json is one of six kinds, told apart by its keys: :class:`CalibrationReport`
(``calibrate --level registration|offsets|full|auto``), :class:`PaperReport` (``calibrate --level dh``),
:class:`~pincal.report.model_diagnosis.DiagnosisReport` (``diagnose``: the calibration's keys and the
effects), :class:`~pincal.report.model_fixture.FixtureReport` (``calibrate --fixture``),
:class:`~pincal.report.model_tree.TreeReport` (several ``--tip-link``) and ``model_camera.CameraReport``
(``--camera-link``). Their builders return them, so mypy checks every key they write; :mod:`pincal.report.schema`
turns these (and PLAN.json's, :mod:`pincal.planning.files`) into ``docs/report.schema.json``, which the tests
validate every document they write against.

The keys and their values are promises to users' scripts: never renamed, only
extended. A class's keys are required unless it lists them in a ``total=False``
subclass (present only in some reports). Types are those of JSON: ``float`` is any
number, ``X | None`` may be null. ``Vector3``/``Quaternion`` are lists of 3/4 numbers.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Annotated, Literal, TypedDict, cast

from pincal.measurements.couplings import CouplingJson
from pincal.measurements.data import MimicJson
from pincal.report.model_level_choice import Fold, LevelChoiceJson, LevelChoicePart, LevelScore, level_choice_part

if TYPE_CHECKING:
    from collections.abc import Sequence

    from pincal.fit.metrics import PoseErrors
    from pincal.fit.plausibility import Finding as PlausibilityFinding
    from pincal.measurements.couplings import ReadingCoupling
    from pincal.model.sensor import Registration

__all__ = [
    "Vector3", "Quaternion", "Sha256", "ChainLevel", "PaperMethod", "JointKind", "PositionStats", "OrientationStats",
    "PoseErrorsJson", "RegistrationJson", "RegistrationPair", "Sources", "PaperChain", "ChainJson", "Parameter",
    "PriorScaleEstimate", "PriorScale", "SelectionCandidate", "SelectionJson", "Absorption", "Dropped",
    "CorrelatedPair", "NotDetermined", "NotDeterminedRotation", "Identifiability", "PaperTool", "Tool", "Noise",
    "Outlier", "FitRows", "Stage", "PaperFit", "FixtureFit",
    "ChainFit", "Finding", "SessionEntry", "RowErrorModel", "RowErrorSet", "Fold", "LevelScore", "LevelChoiceJson",
    "LevelChoicePart", "level_choice_part",  # pincal.report.model_level_choice's, where they have always been
    "TimeSpanJson", "RunHead", "ChainHead", "CalibrationReport", "PaperReport",
    "errors_json", "registration_json", "registration_pair", "findings_json",
    "CouplingJson", "CouplingsPart", "couplings_part",
]

# Annotated's (keyword, value) pairs are JSON Schema keywords of the type (pincal.report.schema)
Vector3 = Annotated[list[float], ("minItems", 3), ("maxItems", 3)]
Quaternion = Annotated[list[float], ("minItems", 4), ("maxItems", 4)]
Sha256 = Annotated[str, ("pattern", "^[0-9a-f]{64}$")]
# str in Python (the fits hold them as str), an enum in the schema
ChainLevel = Annotated[str, ("enum", ("registration", "offsets", "full"))]
PaperMethod = Annotated[int, ("enum", (1, 2, 3))]
JointKind = Annotated[str, ("enum", ("revolute", "continuous", "prismatic"))]


# --- errors (eq 24) and registrations -----------------------------------------------------------


class PositionStats(TypedDict):
    """Mean, RMS and maximum of position errors [mm]."""

    mean_mm: float
    rms_mm: float
    max_mm: float


class OrientationStats(TypedDict):
    """Mean, RMS and maximum of orientation errors [deg]."""

    mean_deg: float
    rms_deg: float
    max_deg: float


class _PoseErrorsKeys(TypedDict):
    rows: int
    position: PositionStats


class PoseErrorsJson(_PoseErrorsKeys, total=False):
    """Eq 24 on a set of rows (:meth:`pincal.fit.metrics.PoseErrors.as_dict`): ``position_per_point``
    with several target points, ``orientation`` with 6D data."""

    position_per_point: list[PositionStats]
    orientation: OrientationStats


class RegistrationJson(TypedDict):
    """A registration sensor_T_base: g ≈ Omega t + tau (:meth:`pincal.model.sensor.Registration.as_dict`)."""

    rotation_xyzw: Quaternion
    translation_m: Vector3


class RegistrationPair(TypedDict):
    """Registration 1 (``position``) and Registration 2 (``orientation``)."""

    position: RegistrationJson
    orientation: RegistrationJson


# --- the sections of a report ---------------------------------------------------------------------


class _SourcesKeys(TypedDict):
    urdf: str
    data: str | list[str]
    corrected_urdf: str


class Sources(_SourcesKeys, total=False):
    """The files the report was made from: ``validation`` (diagnose), ``fixture`` (socket fixture);
    ``corrected_urdf_withheld``: True when the URDF was withheld (:mod:`pincal.workflows.verdict`)."""

    validation: str | None
    fixture: str
    corrected_urdf_withheld: bool


class _ChainKeys(TypedDict):
    root_link: str
    tip_link: str
    joints: list[str]


class PaperChain(_ChainKeys):
    """The calibrated chain: root and tip links and its joints."""


class _ChainJointKeys(_ChainKeys):
    joint_kinds: list[JointKind]


class ChainJson(_ChainJointKeys, total=False):
    """The calibrated chain: root and tip links, its joints and their kinds; ``mimics``: those that follow another."""

    mimics: list[MimicJson]


class Parameter(TypedDict):
    """One kinematic parameter; ``calibrated`` and ``std`` are null where the data cannot determine it
    (``status`` says why)."""

    name: str
    joint: str
    unit: str
    nominal: float
    calibrated: float | None
    std: float | None
    status: str


class _PriorScaleKeys(TypedDict):
    translation_mm: float
    rotation_deg: float


class PriorScaleEstimate(_PriorScaleKeys):
    """The prior's scales estimated from the rows (empirical Bayes, :mod:`pincal.fit.prior_scales`)."""

    joint_zero_deg: float


class PriorScale(_PriorScaleKeys, total=False):
    """The prior of ``--select prior``: the σ a fit used for a translation [mm], a rotation [deg] and a
    revolute joint's zero [deg]; whether they are the rows' estimate and why; with an estimate, its
    scales, ln of its Bayes factor over the default scales and its cross-validated error over theirs."""

    joint_zero_deg: float
    estimated: bool
    reason: str
    estimate: PriorScaleEstimate
    log_bayes_factor: float | None
    cv_ratio: float | None
    cv_standard_error: float | None


class SelectionCandidate(TypedDict):
    kept: int
    value: float | None


class _SelectionKeys(TypedDict):
    criterion: str
    kept: int
    value: float | None
    candidates: list[SelectionCandidate]
    refitted: list[int]


class SelectionJson(_SelectionKeys, total=False):
    """How many parameters were kept and by which criterion (``prior_scale`` with ``--select prior``)."""

    prior_scale: PriorScale


class Absorption(TypedDict):
    name: str
    coefficient: float


class Dropped(TypedDict):
    """A parameter the data cannot determine, and the kept ones that absorb it."""

    name: str
    reason: str
    absorbed_into: list[Absorption]


class CorrelatedPair(TypedDict):
    a: str
    b: str
    correlation: float


class NotDetermined(TypedDict):
    """A direction of the target's position the data leave free, held at a stated value."""

    name: str
    direction: Vector3
    turn_deg: float
    held_at_m: float
    std_m_when_estimated: float | None
    reason: str


class NotDeterminedRotation(TypedDict):
    """A rotation of a session's registration the data leave free (rows on one line), held by a stated rule:
    ``nearest_tool_rotation`` (the target's rotation on the tool the nearest the tool frame's) or
    ``levelled`` (the robot base's z axis turned the nearest the sensor's z axis)."""

    name: str
    axis: Vector3
    frame: str
    seen: float
    rule: Literal["nearest_tool_rotation", "levelled"]
    reason: str


class _IdentifiabilityKeys(TypedDict):
    rank: int
    jacobian_condition: float
    selection: SelectionJson | None
    dropped: list[Dropped]
    correlated_pairs: list[CorrelatedPair]
    not_determined: list[NotDetermined]


class Identifiability(_IdentifiabilityKeys, total=False):
    """Rank, condition number, selection, dropped parameters, correlated pairs, held directions (and
    ``not_determined_rotations`` when a registration rotation was held)."""

    not_determined_rotations: list[NotDeterminedRotation]


class PaperTool(TypedDict):
    """The known tool: its parent link and pose in it."""

    parent_link: str
    xyz_m: Vector3
    rpy_rad: Vector3


class Tool(TypedDict):
    """The estimated target: its points in the parent link frame (marker-column order) and the pose
    of its frame."""

    parent_link: str
    points_m: list[Vector3]
    xyz_m: Vector3
    rpy_rad: Vector3


class Noise(TypedDict):
    """The noise scales the fit estimated (``sigma_rot_deg`` null without orientation data)."""

    sigma_pos_mm: float
    sigma_rot_deg: float | None


class _OutlierKeys(TypedDict):
    line: int
    robust_score: float
    file: str | None


class Outlier(_OutlierKeys, total=False):
    """A row flagged as an outlier, by file and line; ``by``: the error that flags it, the RMS distance of its
    points (``position``) or its orientation's angle (``orientation``, 6D rows) — absent from files written
    before pincal flagged orientations."""

    by: Literal["position", "orientation"]


class _FitRowsKeys(TypedDict):
    calibration: int


class FitRows(_FitRowsKeys, total=False):
    """Rows of each role read."""

    cpa: int
    validation: int


class Stage(TypedDict):
    """One least-squares stage of a paper method."""

    error_function: str
    parameters: list[str]
    rms: float
    unit: str
    evaluations: int
    jacobian_condition: float


class PaperFit(TypedDict):
    """Row counts, the stages and eq 24 on the calibration rows."""

    rows: FitRows
    stages: list[Stage]
    calibration_errors: PoseErrorsJson


class FixtureFit(TypedDict):
    """Row counts, RMS point error and timings of a fixture fit."""

    rows: FitRows
    rows_used: int
    rms_point_error_mm: float
    fit_seconds: float
    total_seconds: float


class ChainFit(FixtureFit):
    """Row counts, RMS point error, timings and eq 24 on the calibration rows."""

    calibration_errors: PoseErrorsJson


class Finding(TypedDict):
    """A plausibility warning (:mod:`pincal.fit.plausibility`)."""

    code: str
    message: str


class SessionEntry(TypedDict):
    """One session: its file(s), rows, registration and errors (:mod:`pincal.report.sessions`)."""

    name: str
    file: str | list[str]
    rows: int
    registration: RegistrationPair
    calibration_errors: PoseErrorsJson | None


class RowErrorModel(TypedDict):
    """One model's errors on a set of rows: eq 24 summary, each row's ``position_mm`` and ``orientation_deg``."""

    model: str
    errors: PoseErrorsJson
    position_mm: list[float]
    orientation_deg: list[float] | None


class RowErrorSet(TypedDict):
    """The error of every row of a set by file line (:mod:`pincal.report.row_errors`)."""

    set: str
    file: str
    lines: list[int]
    files: list[str]
    sessions: list[str]
    models: list[RowErrorModel]
    point_position_mm: list[list[float]] | None
    robust_score: list[float]


class TimeSpanJson(TypedDict):
    """The times [s] of one session's rows a drift was fitted on."""

    session: str
    first: float
    last: float
    mean: float


# --- the four kinds of REPORT.json ----------------------------------------------------------------


class RunHead(TypedDict):
    pincal_version: str
    report_version: int
    method: None
    level: ChainLevel
    model: Literal["joint placements"]
    sources: Sources


class ChainHead(RunHead):
    chain: ChainJson
    parameters: list[Parameter]
    identifiability: Identifiability
    registration: RegistrationPair
    tool: Tool
    noise: Noise
    outliers: list[Outlier]
    removed_lines: list[int]
    removed_files: list[str | None]
    fit: ChainFit
    notes: list[str]


class _CalibrationKeys(ChainHead):
    warnings: list[Finding]
    sessions: list[SessionEntry]
    row_errors: list[RowErrorSet]
    urdf_sha256: Sha256
    xacro_args: dict[str, str]


class CalibrationReport(_CalibrationKeys, total=False):
    """REPORT.json of ``calibrate --level registration|offsets|full|auto`` (``level_choice``: auto;
    ``couplings``: ``--coupling`` given)."""

    level_choice: LevelChoiceJson
    couplings: list[CouplingJson]


class PaperReport(TypedDict):
    """REPORT.json of ``calibrate --level dh``: Method 1, 2 or 3 of Franaszek & Marvel (2022)."""

    pincal_version: str
    report_version: int
    method: PaperMethod
    weight_mm2_per_deg2: float | None
    model: Literal["dh"]
    sources: Sources
    chain: PaperChain
    parameters: list[Parameter]
    registration: RegistrationPair
    tool: PaperTool
    fit: PaperFit
    notes: list[str]
    row_errors: list[RowErrorSet]
    urdf_sha256: Sha256
    xacro_args: dict[str, str]


class CouplingsPart(TypedDict, total=False):
    """``couplings`` where a report has them (``--coupling`` given), to unpack into a report."""

    couplings: list[CouplingJson]


# The lower layers' ``as_dict()`` forms, as the model's types: their keys are the model's
# (the tests validate every document written against the schema).


def errors_json(errors: PoseErrors) -> PoseErrorsJson:
    """Eq 24's summary of ``errors``."""
    return cast(PoseErrorsJson, errors.as_dict())


def registration_json(registration: Registration) -> RegistrationJson:
    """``rotation_xyzw`` and ``translation_m`` of ``registration``."""
    return cast(RegistrationJson, registration.as_dict())


def registration_pair(position: Registration, orientation: Registration) -> RegistrationPair:
    """Registrations 1 and 2 (one estimate serves both outside the paper's methods)."""
    return {"position": registration_json(position), "orientation": registration_json(orientation)}


def couplings_part(couplings: Sequence[ReadingCoupling]) -> CouplingsPart:
    """``{"couplings": [...]}`` of ``--coupling``, ``{}`` without (the report as before)."""
    return {"couplings": [c.as_dict() for c in couplings]} if couplings else {}


def findings_json(findings: list[PlausibilityFinding]) -> list[Finding]:
    """``warnings``: the plausibility findings."""
    return [cast(Finding, f.as_dict()) for f in findings]
