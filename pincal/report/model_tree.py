"""The typed model of REPORT.json of ``calibrate`` with several ``--tip-link LINK:POINTS`` (a tree): the
chains' joints once, each target with its link, points, supporting joints and errors
(:mod:`pincal.report.model` has the shared parts)."""

from __future__ import annotations

from typing import TypedDict

from pincal.measurements.data import MimicJson
from pincal.report.model import (
    Finding,
    Identifiability,
    JointKind,
    Noise,
    Parameter,
    PositionStats,
    RegistrationPair,
    RunHead,
    Sha256,
    Vector3,
)

__all__ = ["TreeChainJson", "TargetErrors", "TargetJson", "TreeSessionJson", "TreeReport"]


class _TreeChainKeys(TypedDict):
    root_link: str
    joints: list[str]
    joint_kinds: list[JointKind]


class TreeChainJson(_TreeChainKeys, total=False):
    """The calibrated tree: its root link, and every joint of the targets' chains once (those shared by
    several, e.g. a torso's, first), with their kinds; ``mimics``: those that follow another (as one chain's)."""

    mimics: list[MimicJson]


class TargetErrors(TypedDict):
    """A target's points on a set of rows, each point where it was seen (eq 24's position error): ``seen``
    (row, point) pairs, their errors over all of them and per point (in the order of ``points``)."""

    seen: int
    position: PositionStats
    position_per_point: list[PositionStats]


class TargetJson(TypedDict):
    """One ``--tip-link LINK:POINTS``: the link, the numbers of the points it carries (1 is ``x1,y1,z1``),
    the joints of the chain root → link, each point in the link as calibrated [m], and the calibration rows'
    errors of the nominal model (registered to them) and of the calibrated one."""

    tip_link: str
    points: list[int]
    joints: list[str]
    points_m: list[Vector3]
    nominal_errors: TargetErrors
    calibration_errors: TargetErrors


class TreeSessionJson(TypedDict):
    """One session: its calibration rows and its registration (one for every target)."""

    name: str
    rows: int
    registration: RegistrationPair


class TreeReport(RunHead):
    """REPORT.json of ``calibrate`` with several ``--tip-link LINK:POINTS``: one calibration of every target,
    the joints shared by several chains fitted once (``parameters``: one entry each), one registration per
    session (``registration``: the first session's; every one under ``sessions``)."""

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
