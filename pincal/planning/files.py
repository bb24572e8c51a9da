"""PLAN.csv and PLAN.json, the files of ``pincal plan`` (its workflow: :mod:`pincal.workflows.preparation`).

PLAN.csv has one row per chosen configuration in visiting order: the joint
columns (CSV v1 names, rad or m), then ``priority`` (1 = the configuration
that helps most; measure in priority order if you may stop early) and
``candidate`` (the line of the candidate file, or the index of the drawn
sample). Add the measured columns (``x,y,z`` …) and it is a CSV v1 file for
``pincal calibrate``.
"""

from __future__ import annotations

import csv
import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Protocol, TypedDict, cast

import numpy as np

from pincal._version import __version__
from pincal.errors import PincalError
from pincal.measurements.couplings import CouplingJson
from pincal.measurements.data import JointMimic
from pincal.model.chain import KinematicChain, xyz_rpy_from_pose
from pincal.model.tree import KinematicTree
from pincal.outputs import file_sha256, replacing, write_text
from pincal.planning.candidates import JointRange, JointRangeJson
from pincal.planning.collisions import Clearance, CollisionCheck
from pincal.planning.design import CRITERIA, TargetPrediction

if TYPE_CHECKING:  # annotations only: the REPORT.json loader reads PLAN.json without the planner's imports
    from pincal.planning.planner import Plan

__all__ = [
    "PLAN_VERSION", "PlanSources", "PlanChain", "PlanTarget", "TargetErrorsJson", "TargetPredictionJson",
    "PlanPriorScale", "PlanTool", "PlanSettingsJson", "PlanCriterion", "SrdfJson",
    "PredictionJson", "RandomPrediction", "PlanPredicted", "PlanIdentifiability", "ClearanceJson", "PlanCandidates",
    "BalanceJson", "PlanOrder", "Addition", "PlanJson", "CandidatePool", "PlannedRows", "write_plan_csv",
    "write_plan_json", "plan_document",
]

PLAN_VERSION = 1


# PLAN.json's typed model (its JSON Schema: pincal.report.schema, in docs/report.schema.json);
# non-finite numbers are written as null, so a computed number may be null.
_Vector3 = Annotated[list[float], ("minItems", 3), ("maxItems", 3)]  # keywords of the schema


class _PlanSourcesKeys(TypedDict):
    urdf: str
    candidates: str | None
    existing: str | list[str] | None
    workspace: str | None
    xacro_args: dict[str, str]


class PlanSources(_PlanSourcesKeys, total=False):
    """The files the plan was made from (null: not given), and the ``--coupling`` its joint values were
    read and are written with (only when given: PLAN.csv holds the controller's readings)."""

    couplings: list[CouplingJson]


class _PlanChainKeys(TypedDict):
    root_link: str
    tip_link: str
    joints: list[str]


class PlanTarget(TypedDict):
    """One target of several (``--tip-link LINK:POINTS``): its tip link, its point numbers (1 is ``x1,y1,z1``) and
    its chain's joints."""

    tip_link: str
    points: list[int]
    joints: list[str]


class PlanChain(_PlanChainKeys, total=False):
    """The chain planned for: its root, its tip link and its joints (PLAN.csv's columns but for followers). With
    several ``--tip-link``: the tree's joints, ``tip_link`` the first target's, and ``targets`` each target."""

    targets: list[PlanTarget]


class PlanPriorScale(TypedDict):
    translation_mm: float
    rotation_deg: float
    joint_zero_deg: float


class PlanTool(TypedDict):
    xyz_m: _Vector3
    rpy_rad: _Vector3


class PlanSettingsJson(TypedDict):
    """The settings the plan was made with."""

    count: int
    level: str
    measure: str
    criterion: str
    select: str
    prior_scale: PlanPriorScale | None
    sigma_pos_mm: float | None
    sigma_rot_deg: float | None
    sigma_source: str
    tool: PlanTool | None
    target_points_m: list[_Vector3]
    seed: int | None
    sample: int | None


class PlanCriterion(TypedDict):
    name: str
    definition: str
    value: float | None


class PredictionJson(TypedDict):
    """Expected errors against the truth over the workspace sample (:class:`pincal.planning.design.Prediction`)."""

    mean_position_mm: float | None
    max_position_mm: float | None
    mean_rotation_deg: float | None
    max_rotation_deg: float | None
    condition: float | None


class RandomPrediction(PredictionJson):
    """The same for random choices: the median over ``draws``."""

    draws: int
    singular_draws: int
    statistic: str


class TargetErrorsJson(TypedDict):
    """A target's expected position errors over the workspace sample and its points [mm]."""

    mean_position_mm: float
    max_position_mm: float


class TargetPredictionJson(TypedDict):
    """One target's share of the prediction (several ``--tip-link``): the plan's, and the median of the random
    choices' (null: not determined)."""

    tip_link: str
    points: list[int]
    plan: TargetErrorsJson | None
    random: TargetErrorsJson | None


class _PlanPredictedKeys(TypedDict):
    what: str
    workspace_configurations: int
    plan: PredictionJson | None
    random: RandomPrediction | None
    plan_over_random_mean_position: float | None
    recorded_only: PredictionJson | None


class PlanPredicted(_PlanPredictedKeys, total=False):
    """The predicted errors; with several ``--tip-link``, ``targets``: each target's."""

    targets: list[TargetPredictionJson]


class PlanIdentifiability(TypedDict):
    identifiable: list[str]
    not_identifiable: list[str]
    estimated_parameters: int
    kinematic_parameters: int
    condition_number: float | None


class _ClearanceKeys(TypedDict):
    min_distance_m: float
    refused: int
    refused_in_collision: int
    refused_too_close: int
    pairs_checked: int
    pairs_ignored_at_zero: list[str]


class SrdfJson(TypedDict):
    """The SRDF given (``--srdf``), how many pairs of moving links its ``disable_collisions`` left unchecked, and
    how many it disables as "Never" in collision that were checked still."""

    file: str
    pairs_disabled: int
    never_pairs_checked: int


class ClearanceJson(_ClearanceKeys, total=False):
    """The collision check of the candidates (:class:`pincal.planning.collisions.Clearance`); ``srdf`` with
    ``--srdf`` (then ``pairs_ignored_at_zero`` is empty)."""

    srdf: SrdfJson


class _PlanCandidatesKeys(TypedDict):
    count: int
    usable: int
    clearance: ClearanceJson | None


class PlanCandidates(_PlanCandidatesKeys, total=False):
    """The candidates: how many, how many the collision check left (``collision_check``: how they were
    checked; ``clearance``: its counts, null when not checked), and the range of each joint they were drawn
    from or span (``joint_ranges``, deg or mm). ``plan`` writes every key; a PLAN.json of an earlier
    version lacks the last two."""

    collision_check: CollisionCheck
    joint_ranges: list[JointRangeJson]


class BalanceJson(TypedDict):
    """Approach directions of one joint over the plan (:class:`pincal.planning.ordering.Balance`)."""

    joint: str
    from_below: int
    from_above: int
    kept: int
    balance: float | None
    correlation: float | None


class PlanOrder(TypedDict):
    method: str
    alternate: list[str]
    travel_s: float | None
    approach_balance: list[BalanceJson]


class Addition(TypedDict):
    priority: int
    candidate: int
    predicted_mean_mm: float | None
    gain_mm: float | None


class PlanJson(TypedDict):
    """PLAN.json, written by ``pincal plan`` beside PLAN.csv."""

    pincal_version: str
    plan_version: int
    sources: PlanSources
    plan_csv_sha256: str | None
    chain: PlanChain
    settings: PlanSettingsJson
    criterion: PlanCriterion
    predicted: PlanPredicted
    identifiability: PlanIdentifiability
    candidates: PlanCandidates
    order: PlanOrder
    additions: list[Addition]
    exchange_swaps: int
    seconds: float
    notes: list[str]


def _finite(value):
    """The document with non-finite numbers as null (strict JSON)."""
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    if isinstance(value, float) and not np.isfinite(value):
        return None
    return value


class PlannedRows(Protocol):
    """What PLAN.csv holds of a plan (:class:`pincal.planning.planner.Plan`, a camera's
    :class:`pincal.planning.camera_plan.CameraPlan`): the configurations in visiting order (N, n_joints)
    [rad or m], each one's priority (N,) and its index into the candidates (N,)."""

    @property
    def q(self) -> np.ndarray: ...

    @property
    def priority(self) -> np.ndarray: ...

    @property
    def candidates(self) -> np.ndarray: ...


def write_plan_csv(path: str | Path, plan: PlannedRows, chain: KinematicChain | KinematicTree, labels: np.ndarray,
                   unread: Sequence[str] = ()) -> str:
    """PLAN.csv: joint columns, ``priority`` and ``candidate``, one row per configuration in visiting order; a
    joint the chain's joints follow from off the chain (URDF ``<mimic>``, eq M1) has a column after the chain's,
    the value the controller commands: (q_follower − offset) / multiplier. ``unread``: chain joints without
    a reading (a ``--coupling`` that ``follows``), given no column: the controller has none for them, and a
    file without the column is what makes calibrate decide they follow.

    Returns:
        The SHA-256 (hex) of the bytes written, for PLAN.json's ``plan_csv_sha256``.
    """
    drivers: dict[str, tuple[int, JointMimic]] = {}
    for i, joint in enumerate(chain.joints):  # a driver of several followers: the first one's value
        if joint.mimic is not None and joint.mimic.driver not in chain.joint_names:
            drivers.setdefault(joint.mimic.driver, (i, joint.mimic))
    digest: list[str] = []
    try:
        with replacing(path, "w", newline="", verify=lambda written: digest.append(file_sha256(written))) as handle:
            writer = csv.writer(handle, lineterminator="\n")
            kept = [n for n, name in enumerate(chain.joint_names) if name not in unread]
            writer.writerow([*(chain.joint_names[n] for n in kept), *drivers, "priority", "candidate"])
            for q, rank, index in zip(plan.q, plan.priority, plan.candidates):
                commanded = [repr(float((q[i] - mimic.offset) / mimic.multiplier)) for i, mimic in drivers.values()]
                writer.writerow([*(repr(float(q[n])) for n in kept), *commanded, int(rank), int(labels[index])])
    except OSError as exc:
        raise PincalError(f"{path}: cannot write the plan ({exc.strerror or exc})") from None
    return digest[-1]


def write_plan_json(path: str | Path, document: PlanJson) -> None:
    """PLAN.json: ``document`` as strict JSON (non-finite numbers as null)."""
    try:
        write_text(path, json.dumps(_finite(document), indent=2) + "\n")
    except OSError as exc:
        raise PincalError(f"{path}: cannot write the plan report ({exc.strerror or exc})") from None


def _chain_json(chain: KinematicChain | KinematicTree) -> PlanChain:
    """PLAN.json ``chain``: one chain's, or a tree's joints with each target (the first one's tip link)."""
    if isinstance(chain, KinematicChain):
        return {"root_link": chain.root_link, "tip_link": chain.tip_link, "joints": list(chain.joint_names)}
    first = chain.targets[0].chain
    return {"root_link": first.root_link, "tip_link": first.tip_link, "joints": list(chain.joint_names),
            "targets": [{"tip_link": t.link, "points": list(t.spec.points), "joints": list(t.chain.joint_names)}
                        for t in chain.targets]}


def _target_json(target: TargetPrediction) -> TargetPredictionJson:
    def errors(values: tuple[float, float] | None) -> TargetErrorsJson | None:
        return None if values is None else {"mean_position_mm": values[0], "max_position_mm": values[1]}

    return {"tip_link": target.link, "points": list(target.points), "plan": errors(target.plan),
            "random": errors(target.random)}


def _prediction(prediction) -> PredictionJson | None:
    return None if prediction is None else cast(PredictionJson, prediction.as_dict())


@dataclass(frozen=True)
class CandidatePool:
    """The candidates a plan chose from, as PLAN.json describes them.

    Attributes:
        labels: each candidate's line in its file, or its index in the sample, (K,).
        ranges: each joint's range of the candidates (:func:`pincal.planning.candidates.joint_ranges`).
        collision_check: how they were checked for collisions.
        clearance: the check's outcome (None when not checked).
        sample: how many were drawn (None: read from a file).
    """

    labels: np.ndarray
    ranges: tuple[JointRange, ...]
    collision_check: CollisionCheck
    clearance: Clearance | None = None
    sample: int | None = None


def plan_document(
    plan: Plan,
    chain: KinematicChain | KinematicTree,
    sources: PlanSources,
    pool: CandidatePool,
    tool_pose: np.ndarray | None,
    plan_csv_sha256: str | None = None,
    notes: Sequence[str] = (),
) -> PlanJson:
    """The PLAN.json document of ``plan`` (its settings: ``plan.settings``) chosen from ``pool``;
    ``plan_csv_sha256`` names the PLAN.csv it describes (its bytes' SHA-256); ``notes``: the run's notes
    before the planner's (the files read, the ranges drawn, the collision check), as the console says them."""
    settings, labels, clearance = plan.settings, pool.labels, pool.clearance
    n_candidates = len(labels)
    ratio = None
    if plan.prediction is not None and plan.random is not None and np.isfinite(plan.random.mean_position_mm):
        ratio = plan.prediction.mean_position_mm / plan.random.mean_position_mm
    tool: PlanTool | None = None
    if tool_pose is not None:
        xyz, rpy = xyz_rpy_from_pose(tool_pose)
        tool = {"xyz_m": xyz.tolist(), "rpy_rad": rpy.tolist()}
    kinematic = len(plan.identifiable)
    assert settings.sensor is not None  # a plan's settings name the sensor (pincal.planning.planner.plan)
    predicted: PlanPredicted = {
        "what": "linearised noise limit of the model calibrated on these configurations (all identifiable "
                "parameters estimated" + ("" if settings.prior is None else ", with the prior of "
                                          "settings.prior_scale") + "): expected error against the truth "
                "over the workspace sample",
        "workspace_configurations": plan.workspace_size,
        "plan": _prediction(plan.prediction),
        "random": None if plan.random is None else {**cast(PredictionJson, plan.random.as_dict()),
                                                    "draws": settings.random_draws,
                                                    "singular_draws": plan.random_singular,
                                                    "statistic": "median over draws"},
        "plan_over_random_mean_position": ratio,
        "recorded_only": _prediction(plan.recorded),
    }
    if plan.targets:  # several --tip-link: each target's share
        predicted["targets"] = [_target_json(t) for t in plan.targets]
    return {
        "pincal_version": __version__,
        "plan_version": PLAN_VERSION,
        "sources": sources,
        "plan_csv_sha256": plan_csv_sha256,
        "chain": _chain_json(chain),
        "settings": {
            "count": settings.count,
            "level": settings.level,
            "measure": settings.sensor.label,
            "criterion": settings.criterion,
            "select": str(settings.selection),
            "prior_scale": None if settings.prior is None else cast(PlanPriorScale, settings.prior.as_dict()),
            "sigma_pos_mm": plan.sigma_pos_mm,
            "sigma_rot_deg": plan.sigma_rot_deg,
            "sigma_source": plan.sigma_source,
            "tool": tool,
            "target_points_m": plan.target_points.tolist(),
            "seed": settings.seed,
            "sample": pool.sample,
        },
        "criterion": {"name": plan.criterion, "definition": CRITERIA[plan.criterion], "value": plan.criterion_value},
        "predicted": predicted,
        "identifiability": {
            "identifiable": list(plan.identifiable),
            "not_identifiable": list(plan.not_identifiable),
            "estimated_parameters": len(plan.estimated),
            "kinematic_parameters": kinematic,
            "condition_number": None if plan.prediction is None else plan.prediction.condition,
        },
        "candidates": {
            "count": n_candidates,
            "usable": n_candidates if clearance is None else int(clearance.allowed.sum()),
            "clearance": None if clearance is None else cast(ClearanceJson, clearance.as_dict()),
            "collision_check": pool.collision_check,
            "joint_ranges": [r.as_dict() for r in pool.ranges],
        },
        "order": {
            "method": "balanced approach directions" if settings.alternate else "short travel",
            "alternate": list(settings.alternate),
            "travel_s": plan.travel_s,
            "approach_balance": [cast(BalanceJson, b.as_dict()) for b in plan.balance],
        },
        "additions": [
            {"priority": i + 1, "candidate": int(labels[a.candidate]),
             "predicted_mean_mm": a.predicted_mean_mm, "gain_mm": a.gain_mm}
            for i, a in enumerate(plan.additions)
        ],
        "exchange_swaps": plan.swaps,
        "seconds": plan.seconds,
        "notes": [*notes, *plan.notes],
    }
