"""The typed model of REPORT.json of ``calibrate`` and ``diagnose`` with several ``--tip-link LINK:POINTS`` (a
tree): the chains' joints once, each target with its link, points, supporting joints and errors; ``diagnose``'s
effects and search (:mod:`pincal.report.model` has the shared parts)."""

from __future__ import annotations

from typing import TypedDict

from pincal.measurements.data import MimicJson
from pincal.report.model import (
    CouplingsPart,
    Finding,
    Identifiability,
    JointKind,
    Noise,
    OrientationStats,
    Parameter,
    PositionStats,
    Quaternion,
    RegistrationPair,
    RunHead,
    Sha256,
    Vector3,
)
from pincal.report.model_diagnosis import CandidateJson, EffectJson
from pincal.report.model_level_choice import LevelChoicePart

__all__ = ["TreeChainJson", "TargetErrors", "TargetJson", "TreeSessionJson", "TreeCandidateJson", "TreeBeforeAfter",
           "TreeStepJson", "TreeDiagnosisJson", "TreeReport", "TreeEvaluationTarget", "TreeEvaluationJson"]


class _TreeChainKeys(TypedDict):
    root_link: str
    joints: list[str]
    joint_kinds: list[JointKind]


class TreeChainJson(_TreeChainKeys, total=False):
    """The calibrated tree: its root link, and every joint of the targets' chains once (those shared by
    several, e.g. a torso's, first), with their kinds; ``mimics``: those that follow another (as one chain's)."""

    mimics: list[MimicJson]


class _TargetErrorsKeys(TypedDict):
    seen: int
    position: PositionStats
    position_per_point: list[PositionStats]


class TargetErrors(_TargetErrorsKeys, total=False):
    """A target's points on a set of rows, each point where it was seen (eq 24's position error): ``seen``
    (row, point) pairs, their errors over all of them and per point (in the order of ``points``). A target whose
    orientation is measured (``qxN,qyN,qzN,qwN``) adds the rows where it was seen (``orientation_seen``) and eq 24's
    orientation error on them [deg] (``orientation``; absent when seen in none)."""

    orientation_seen: int
    orientation: OrientationStats


class _TargetKeys(TypedDict):
    tip_link: str
    points: list[int]
    joints: list[str]
    points_m: list[Vector3]
    nominal_errors: TargetErrors
    calibration_errors: TargetErrors


class TargetJson(_TargetKeys, total=False):
    """One ``--tip-link LINK:POINTS``: the link, the numbers of the points it carries (1 is ``x1,y1,z1``),
    the joints of the chain root → link, each point in the link as calibrated [m], and the calibration rows'
    errors of the nominal model (registered to them) and of the calibrated one; a target whose orientation is
    measured (``qxN,qyN,qzN,qwN``, N one of its points) adds its frame's rotation in the link as calibrated
    (``rotation_xyzw``, as one chain's target rotation). ``diagnose`` adds the
    calibration rows' errors of the geometric calibration its effects were added to (``geometry_errors``;
    ``calibration_errors`` are then the final model's, with its effects), and with ``--validation`` the held-out
    rows' errors of both (``validation_geometry_errors``, ``validation_errors``)."""

    rotation_xyzw: Quaternion
    geometry_errors: TargetErrors
    validation_geometry_errors: TargetErrors | None
    validation_errors: TargetErrors | None


class TreeSessionJson(TypedDict):
    """One session: its calibration rows and its registration (one for every target)."""

    name: str
    rows: int
    registration: RegistrationPair


class TreeCandidateJson(CandidateJson, total=False):
    """A candidate effect of a step of ``diagnose`` on a tree: the effect's keys (its values when fitted in
    full), its ΔBIC against the step's model (of its full fit; of the linearised test when ``screened``), its
    verdict in words."""

    screened: bool


class TreeBeforeAfter(TypedDict):
    """Every target's points on a set of rows before and after a step (``seen`` pairs, ``position``: mean, RMS
    and max [mm] over every seen point, ``position_per_point``) and, where the rows measure orientations, every
    measured orientation's (``orientation_seen``, ``orientation`` [deg])."""

    before: TargetErrors
    after: TargetErrors


class TreeStepJson(TypedDict):
    """An effect ``diagnose`` adopted on a tree: the effect (its values and standard deviations), its ΔBIC,
    every seen point's errors (and measured orientation's) on the calibration rows before and after it, and on
    the held-out rows (None without ``--validation``), the step's candidates, best first."""

    effect: EffectJson
    delta_bic: float
    calibration: TreeBeforeAfter
    heldout: TreeBeforeAfter | None
    candidates: list[TreeCandidateJson]


class TreeDiagnosisJson(TypedDict):
    """``diagnose``'s search on a tree: the adoption rule in words, where the loads come from (``masses``:
    ``urdf`` or ``unknown``), the adopted steps, the candidates of the step that adopted nothing, and those
    the rows cannot test."""

    criterion: str
    masses: str
    steps: list[TreeStepJson]
    last_candidates: list[TreeCandidateJson]
    untestable: list[str]


class _TreeDiagnosisKeys(TypedDict, total=False):
    effects: list[EffectJson]
    diagnosis: TreeDiagnosisJson


class TreeReport(RunHead, _TreeDiagnosisKeys, LevelChoicePart, CouplingsPart):
    """REPORT.json of ``calibrate`` with several ``--tip-link LINK:POINTS``: one calibration of every target,
    the joints shared by several chains fitted once (``parameters``: one entry each), one registration per
    session (``registration``: the first session's; every one under ``sessions``). ``diagnose``'s adds the
    effects of the final model (``effects``, as in effects.yaml; ``parameters`` and ``targets`` are the final
    model's) and its search (``diagnosis``). ``level_choice``: ``--level auto``'s; ``couplings``: ``--coupling``
    given, as the run decided them (as one chain's)."""

    chain: TreeChainJson
    targets: list[TargetJson]
    parameters: list[Parameter]
    identifiability: Identifiability
    registration: RegistrationPair
    sessions: list[TreeSessionJson]
    noise: Noise
    notes: list[str]
    warnings: list[Finding]
    urdf_sha256: Sha256
    xacro_args: dict[str, str]


class TreeEvaluationTarget(TypedDict):
    """One target of ``evaluate --json`` of a tree's report: its link, its points, and their errors on the
    evaluated rows (None: none of its points seen there)."""

    tip_link: str
    points: list[int]
    errors: TargetErrors | None


class _TreeEvaluationKeys(TypedDict):
    rows: int
    registrations: list[str]
    evaluated_targets: list[TreeEvaluationTarget]
    max_mm: float
    notes: list[str]


class TreeEvaluationJson(_TreeEvaluationKeys, total=False):
    """``pincal evaluate --json`` of a REPORT.json of several ``--tip-link``: how many rows were evaluated, how
    each session was registered, each target's errors (``evaluated_targets``), the largest error of any point
    [mm] (what ``--max-pos-mm`` judges), and the notes; with a target's orientation evaluated, the largest
    orientation error of any target [deg] (``max_deg``, what ``--max-rot-deg`` judges)."""

    max_deg: float
