"""The typed model of a socket-fixture REPORT.json and of ``evaluate --fixture --json`` (:mod:`pincal.report.model`)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Literal, TypedDict, cast

from pincal.report.model import (
    ChainJson,
    ChainLevel,
    CouplingJson,
    Finding,
    FixtureFit,
    Identifiability,
    Noise,
    Outlier,
    Parameter,
    Quaternion,
    Sha256,
    Sources,
    Vector3,
)
from pincal.report.model_level_choice import LevelChoiceJson

if TYPE_CHECKING:
    from pincal.fit.socket_metrics import FixtureMetrics

__all__ = [
    "FixtureTool", "Socket", "SocketDistance", "PlacedSocket", "FixturePlacement", "SocketPairDistance",
    "PlacementMetrics", "FixtureMetricsJson", "FixtureTraining", "FixtureNominal", "PlacementPredictionJson",
    "HeldOutPlacements", "FixtureBlock", "FixtureReport", "FixtureEvaluationJson", "fixture_metrics_json",
]


class FixtureTool(TypedDict):
    """The ball centre in the tip link (a ball has no orientation the data could see)."""

    parent_link: str
    points_m: list[Vector3]
    xyz_m: Vector3


class Socket(TypedDict):
    name: str
    xyz_m: Vector3


class SocketDistance(TypedDict):
    a: str
    b: str
    mm: float


class PlacedSocket(TypedDict):
    name: str
    position_m: Vector3
    std_m: Vector3


class FixturePlacement(TypedDict):
    """A placement of the fixture: its rows, sockets in the URDF root frame and what the data determine
    of its pose (collinear sockets: ``line_direction``, the rest null)."""

    name: str
    rows: int
    sockets: list[PlacedSocket]
    line_direction: Vector3 | None
    rotation_xyzw: Quaternion | None
    translation_m: Vector3 | None
    not_determined: str | None


class SocketPairDistance(TypedDict):
    a: str
    b: str
    computed_mm: float
    fixture_mm: float


class PlacementMetrics(TypedDict):
    placement: str
    rows: int
    consistency_mm: float
    distortion_mm: float
    socket_distances: list[SocketPairDistance]


class FixtureMetricsJson(TypedDict):
    """Consistency and distortion (:mod:`pincal.fit.socket_metrics`)."""

    consistency_mm: float
    distortion_mm: float
    placements: list[PlacementMetrics]


class FixtureTraining(TypedDict):
    before: FixtureMetricsJson
    after: FixtureMetricsJson


class FixtureNominal(TypedDict):
    """The nominal model's ball centre and the SHA-256 of the nominal URDF (evaluate's "before")."""

    urdf_sha256: Sha256
    ball_centre_m: Vector3
    rms_point_error_mm: float


class PlacementPredictionJson(TypedDict):
    """A placement predicted by models fitted without it (:class:`pincal.fit.placement_check.PlacementPrediction`):
    its RMS ball-to-socket distance with only its own pose refitted, nominal and calibrated [mm]."""

    placement: str
    rows: int
    nominal_mm: float | None
    calibrated_mm: float | None
    ratio: float | None
    bound: float
    worse: bool
    failure: str | None


class HeldOutPlacements(TypedDict):
    """Leave-one-placement-out of the calibration (:mod:`pincal.fit.placement_check`)."""

    scheme: Literal["leave-one-placement-out"]
    level: ChainLevel
    error: str
    rule: str
    placements: list[PlacementPredictionJson]


class FixtureBlock(TypedDict):
    """The sockets, ball centre, placements, consistency and distortion (:mod:`pincal.report.fixture`)."""

    file: str | None
    sockets: list[Socket]
    distances_mm: list[SocketDistance]
    ball_centre_m: Vector3
    ball_centre_std_m: Vector3
    placements: list[FixturePlacement]
    training: FixtureTraining
    nominal: FixtureNominal
    held_out_placements: HeldOutPlacements | None


class _FixtureKeys(TypedDict):
    pincal_version: str
    report_version: int
    method: None
    level: ChainLevel
    model: Literal["joint placements"]
    measurement: Literal["socket fixture"]
    sources: Sources
    chain: ChainJson
    parameters: list[Parameter]
    identifiability: Identifiability
    tool: FixtureTool
    noise: Noise
    outliers: list[Outlier]
    removed_lines: list[int]
    fit: FixtureFit
    fixture: FixtureBlock
    notes: list[str]
    warnings: list[Finding]
    xacro_args: dict[str, str]
    urdf_sha256: Sha256


class FixtureReport(_FixtureKeys, total=False):
    """REPORT.json of ``calibrate --fixture`` (no ``registration``: no sensor; ``level_choice``: auto;
    ``couplings``: ``--coupling``, the readings corrected by eq C1 before the fit and by ``evaluate --fixture``)."""

    level_choice: LevelChoiceJson
    couplings: list[CouplingJson]


class FixtureEvaluationJson(TypedDict):
    """``pincal evaluate --fixture --json``: consistency and distortion after (and before) calibration; each
    placement the calibration has not seen predicted by the corrected and the nominal URDF
    (``held_out_placements``, :mod:`pincal.fit.placement_check`) and the plausibility ``warnings``."""

    after: FixtureMetricsJson
    before: FixtureMetricsJson | None
    not_held_out: list[str]
    notes: list[str]
    held_out_placements: list[PlacementPredictionJson]
    warnings: list[Finding]


def fixture_metrics_json(metrics: FixtureMetrics) -> FixtureMetricsJson:
    """Consistency and distortion."""
    return cast(FixtureMetricsJson, metrics.as_dict())
