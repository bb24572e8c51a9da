"""File-level workflows of the commands that come before a calibration: urdf-from-dh and plan.

Each function takes paths and options (plan: a :class:`PlanSettings` and a :class:`PlanInputs`
value), checks the outputs (:func:`pincal.workflows.paths.refuse_overwrite`), does the whole job and
returns what happened; :mod:`pincal.cli.commands` prints it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from pincal.errors import ModelError, PincalError, expect_value
from pincal.fit.plausibility import tip_link_findings
from pincal.measurements.couplings import ReadingCoupling, corrected_angles, readings_of
from pincal.measurements.csv_v1 import file_columns, read_sessions
from pincal.model.chain import KinematicChain
from pincal.model.description import xacro_arguments
from pincal.model.dh.conversion import DHUrdf, urdf_from_dh_table
from pincal.model.tree import KinematicTree, TargetSpec
from pincal.planning.candidates import DEFAULT_SAMPLE, JointRange, joint_ranges, read_candidates, sample_candidates
from pincal.planning.collisions import Clearance, CollisionCheck, check_clearance, has_collision_geometry
from pincal.planning.files import (
    CandidatePool,
    PlanJson,
    PlanSources,
    plan_document,
    write_plan_csv,
    write_plan_json,
)
from pincal.planning.planner import Plan, PlanSettings, plan_measurements
from pincal.planning.tree_plan import plan_tree_measurements
from pincal.progress import Progress, Stages
from pincal.workflows.paths import description_inputs, input_paths, refuse_overwrite
from pincal.workflows.settings import follow_couplings

__all__ = ["urdf_from_dh_file", "PlanInputs", "PlanRun", "plan_files", "refuse_srdf_unchecked"]

# --- urdf-from-dh ------------------------------------------------------------------------


def urdf_from_dh_file(
    table_path: str | Path,
    convention: str,
    out_urdf: str | Path,
    name: str | None = None,
    degrees: bool = False,
    flange: np.ndarray | None = None,
) -> DHUrdf:
    """Write the URDF of a DH table (:func:`pincal.model.dh.conversion.urdf_from_dh_table`) after
    checking the output path (never the table; its folder is created if missing); the URDF is written
    only if its kinematics equal the DH product (:data:`pincal.model.dh.conversion.FK_TOLERANCE`).

    ``flange`` is the pose (4, 4) [m] of the flange in the last DH frame (identity if None).
    """
    refuse_overwrite(out_urdf, table_path)
    return urdf_from_dh_table(table_path, convention, out_urdf, name=name, degrees=degrees, flange=flange)


# --- plan --------------------------------------------------------------------------------


def refuse_srdf_unchecked(srdf: str | Path | None, collision_check: bool) -> None:
    """PincalError for ``--srdf`` beside ``--no-collision-check`` (a plan's, a camera's plan's)."""
    if srdf is not None and not collision_check:
        raise PincalError("--srdf says which link pairs the collision check skips, and --no-collision-check "
                          "skips the check: give one of them")


@dataclass(frozen=True)
class PlanInputs:
    """What ``pincal plan`` reads beside the URDF, and how it checks the candidates (its flags).

    Attributes:
        tool_pose: the known target pose in the tip link (4, 4) [m] (``--tool``; None: estimated).
        candidates_path: the candidate file (``--candidates``; None: ``sample`` are drawn within the limits).
        sample: how many candidates are drawn (``--sample``), seeded by the settings' seed.
        existing_path: measurements already recorded, a file or one per session (``--existing``).
        couplings: joints the controller reads against another (``--coupling``, eq C1).
        workspace_path: configurations where accuracy matters (``--workspace``).
        min_distance_m: refuse candidates with two links closer than this [m] (``--min-distance``);
            None: refuse those in self-collision, where the URDF has collision geometry.
        collision_check: False: no collision check at all (``--no-collision-check``; not with
            ``min_distance_m``).
        xacro_args: ``NAME:=VALUE`` pairs a ``.xacro`` URDF is expanded with (``--xacro-arg``).
        package_dirs: NAME → the folder of ROS package NAME, for ``package://`` collision meshes
            (``--package-dir``, :mod:`pincal.model.packages`).
        srdf: the robot's SRDF (``--srdf``): its ``disable_collisions`` pairs (except those disabled as "Never" in
            collision) are the ones not checked, instead of those in contact at the zero configuration
            (:mod:`pincal.planning.collisions`).

    Raises:
        PincalError: ``min_distance_m`` or ``srdf`` with ``collision_check`` False, ``srdf`` with
            ``min_distance_m``, or a negative ``min_distance_m``.
    """

    tool_pose: np.ndarray | None = None
    candidates_path: str | Path | None = None
    sample: int = DEFAULT_SAMPLE
    existing_path: str | Path | Sequence[str | Path] | None = None
    couplings: Sequence[ReadingCoupling] = ()
    workspace_path: str | Path | None = None
    min_distance_m: float | None = None
    collision_check: bool = True
    xacro_args: Sequence[tuple[str, str]] = ()
    package_dirs: Mapping[str, Path] | None = None
    srdf: str | Path | None = None

    def __post_init__(self) -> None:
        if self.min_distance_m is not None and not self.collision_check:
            raise PincalError("--min-distance asks for the collision check that --no-collision-check skips: "
                              "give one of them")
        refuse_srdf_unchecked(self.srdf, self.collision_check)
        if self.srdf is not None and self.min_distance_m is not None:
            raise PincalError("--srdf lists the link pairs that may touch, not those that may come closer than "
                              "--min-distance: give --srdf for the self-collision check, or --min-distance without it")
        if self.min_distance_m is not None and not self.min_distance_m >= 0.0:
            raise PincalError(f"--min-distance {self.min_distance_m}: give a clearance of 0 m or more")

    @property
    def check(self) -> CollisionCheck:
        """The collision check asked for (before the URDF is read: it may have no collision geometry)."""
        return "off" if not self.collision_check else "self-collision" if self.min_distance_m is None \
            else "min-distance"


@dataclass(frozen=True)
class PlanRun:
    """Outcome of :func:`plan_files`: the plan, the PLAN.json document, the clearance check and notes.

    ``clearance`` is None when the candidates were not checked (``collision_check`` says why),
    ``ranges`` each joint's range of the candidates."""

    plan: Plan
    document: PlanJson
    clearance: Clearance | None
    n_candidates: int
    notes: list[str]
    collision_check: CollisionCheck = "off"
    ranges: tuple[JointRange, ...] = ()


def plan_files(
    urdf: str | Path,
    tip_link: str | Sequence[TargetSpec],
    settings: PlanSettings,
    out_csv: str | Path,
    out_json: str | Path,
    inputs: PlanInputs = PlanInputs(),
    progress: Progress | None = None,
) -> PlanRun:
    """Plan ``settings.count`` measurements of the chain ``urdf`` → ``tip_link``; write PLAN.csv and PLAN.json.

    ``tip_link`` may be several targets (:func:`pincal.model.tree.parse_targets` of ``--tip-link LINK:POINTS``
    values): the plan is then the tree's (:func:`pincal.planning.tree_plan.plan_tree_measurements`), its candidates
    every joint of the targets' chains, PLAN.csv a column for each but the joints that follow another
    (``<mimic>``), PLAN.json each target's prediction; ``--coupling`` as for one chain (below); ``--tool`` and
    ``--level dh`` are refused.

    ``settings.tool_known`` must say whether ``inputs.tool_pose`` is given. Level ``dh``
    plans for the paper's DH parameters with the target known, so it needs
    ``inputs.tool_pose``. A ``.xacro`` ``urdf`` is expanded in memory with ``inputs.xacro_args``.
    The candidates are checked for self-collision where the URDF has collision geometry (a note says
    when it has none), for a clearance with ``inputs.min_distance_m``, not at all without
    ``inputs.collision_check`` (:mod:`pincal.planning.collisions`).
    ``inputs.couplings`` (``--coupling``): joints the controller reads against another; the candidate, existing
    and workspace files are corrected by eq C1 (:mod:`pincal.measurements.couplings`), PLAN.csv is written in
    the controller's readings (its inverse) and PLAN.json records them (``sources.couplings``). A coupling on a
    joint the ``--existing`` files (else the candidate file) have no column for ``follows`` its driver
    (:func:`pincal.workflows.settings.follow_couplings`): drawn and read candidates compute it from the driver,
    and PLAN.csv has no column for it (none is read). Without either file, a coupling is a reading.
    ``progress(done, total)`` counts the collision checks, then the search's steps
    (:func:`pincal.planning.planner.plan_measurements`).

    Raises:
        PincalError: an output path that is an input, the other output or a
            folder; ``dh`` without a tool; any problem of the inputs or the plan.
    """
    expect_value(settings, PlanSettings, "plan_files")
    expect_value(inputs, PlanInputs, "plan_files")
    tool_pose, candidates_path, workspace_path = inputs.tool_pose, inputs.candidates_path, inputs.workspace_path
    couplings, xacro_args = inputs.couplings, inputs.xacro_args
    if not isinstance(tip_link, str):  # several targets: what their plan does not take, before what dh needs
        _refused_for_tree(settings, inputs)
    if settings.level == "dh" and tool_pose is None:
        raise PincalError(
            "--level dh plans for the paper's DH parameters with the target known: give --tool X,Y,Z,ROLL,PITCH,YAW "
            "(as calibrate --level dh needs), or plan --level registration|offsets|full"
        )
    urdf = Path(urdf)
    existing_paths = [] if inputs.existing_path is None else input_paths(inputs.existing_path)
    sources_in = [*description_inputs(urdf, xacro_args),  # a xacro's included files are inputs too
                  *(Path(p) for p in (candidates_path, *existing_paths, workspace_path) if p is not None)]
    refuse_overwrite(out_csv, *sources_in)
    refuse_overwrite(out_json, *sources_in, outputs=[out_csv])
    chain: KinematicChain | KinematicTree = (
        KinematicChain.from_urdf(urdf, tip_link, tool=tool_pose, xacro_args=xacro_args) if isinstance(tip_link, str)
        else KinematicTree.from_urdf(urdf, tip_link, xacro_args=xacro_args))
    # a joint without a column in the recorded rows (else the candidate file) follows its driver (eq M1)
    told: list[str | Path] = [*existing_paths] or ([candidates_path] if candidates_path is not None else [])
    couplings = follow_couplings(chain, couplings, told)
    names = chain.joint_names
    notes: list[str] = []
    if candidates_path is not None:  # a file holds the controller's readings (eq C1 with --coupling)
        readings, labels = read_candidates(candidates_path, chain)
        candidates = corrected_angles(readings, couplings, names)
        ranges = joint_ranges(chain, readings)  # the file's span as written: PLAN.csv's space too
    else:
        candidates = sample_candidates(chain, inputs.sample, settings.seed)
        labels = np.arange(len(candidates))
        ranges = joint_ranges(chain)
        notes += _turn_notes(ranges)
    # no calibration to judge here: whether the target moved with them is for calibrate to say (a note)
    files = [] if candidates_path is None else [candidates_path]
    existing = None
    if existing_paths:  # several files: sessions, one registration each; the plan continues the last
        existing, read_notes = read_sessions(existing_paths, chain.joint_specs, couplings, chain.other_branch_joints,
                                             occlusion=isinstance(chain, KinematicTree))
        notes += read_notes
        files += existing_paths
        if existing.target_rotations:  # the tree's plan designs for the targets' points
            notes.append(f"{existing.source}: the targets' orientation columns qxN,qyN,qzN,qwN are not counted in "
                         "the plan's information (it plans the points; calibrate fits them)")
    if isinstance(chain, KinematicChain):
        notes += [finding.message for finding in tip_link_findings(chain, file_columns(files, names))]
    workspace = (corrected_angles(read_candidates(workspace_path, chain)[0], couplings, names)
                 if workspace_path is not None else None)
    stages = Stages(progress)
    check = inputs.check
    if check == "self-collision" and not has_collision_geometry(urdf, xacro_args):
        check = "no collision geometry"
        notes.append(f"{urdf.name} has no <collision> geometry: the candidates are not checked for "
                     "self-collision (check the plan's postures before the robot moves)")
    clearance = _clearance(urdf, chain, candidates, check, inputs, stages.next()) if check in (
        "self-collision", "min-distance") else None
    if clearance is not None and clearance.pairs_checked == 0:  # geometry on one link, or on links fixed together
        why = (f"{Path(clearance.srdf).name} disables all {clearance.pairs_disabled} pair(s) of links that move "
               "relative to each other" if clearance.srdf is not None else
               "no two links that move relative to each other both have <collision> geometry "
               f"({len(clearance.pairs_ignored)} pair(s) ignored at the zero configuration)")
        notes.append(f"{urdf.name}: {why}: the candidates are in effect not checked for collision (check the plan's "
                     "postures before the robot moves)")
    if clearance is not None and clearance.unrelated_ignored:  # separate limbs, yet touching at zero
        notes.append(f"{urdf.name}: {clearance.unrelated_note()}")
    if inputs.srdf is not None and check == "no collision geometry":
        notes.append(f"--srdf {inputs.srdf} is not used: nothing is checked for collision")
    allowed = None if clearance is None else clearance.allowed
    plan = (plan_measurements(chain, candidates, settings, existing, workspace, allowed, stages.next())
            if isinstance(chain, KinematicChain)
            else plan_tree_measurements(chain, candidates, settings, existing, workspace, allowed, stages.next()))
    sources: PlanSources = {"urdf": str(urdf), "candidates": _text(candidates_path),
                            "existing": _existing_source(existing_paths), "workspace": _text(workspace_path),
                            "xacro_args": dict(xacro_arguments(xacro_args))}
    if couplings:  # PLAN.csv in the controller's joint space: what it reads and is commanded in
        sources["couplings"] = [c.as_dict() for c in couplings]
    unread = list(dict.fromkeys([c.joint for c in couplings if c.follows]  # a tree's followers include them
                                + list(chain.followers if isinstance(chain, KinematicTree) else ())))
    digest = write_plan_csv(out_csv, replace(plan, q=readings_of(plan.q, couplings, names)), chain, labels,
                            unread=unread)
    pool = CandidatePool(labels, ranges, check, clearance, inputs.sample if candidates_path is None else None)
    document = plan_document(plan, chain, sources, pool, tool_pose, plan_csv_sha256=digest, notes=notes)
    write_plan_json(out_json, document)
    return PlanRun(plan, document, clearance, len(candidates), notes + list(plan.notes), check, ranges)


def _refused_for_tree(settings: PlanSettings, inputs: PlanInputs) -> None:
    """What a tree's plan does not take: one line each."""
    for refused, flag in ((inputs.tool_pose is not None, "--tool"), (settings.level == "dh", "--level dh")):
        if refused:
            raise PincalError(f"several --tip-link: plan {flag} is not supported; leave it out (each target's points "
                              "are estimated, as calibrate with several --tip-link does)")


def _clearance(urdf: Path, chain: KinematicChain | KinematicTree, candidates: np.ndarray, check: CollisionCheck,
               inputs: PlanInputs, progress: Progress | None) -> Clearance:
    """The collision check of the candidates: for self-collision (a clearance of 0), or ``--min-distance``."""
    try:
        return check_clearance(urdf, chain, candidates, inputs.min_distance_m or 0.0, xacro_args=inputs.xacro_args,
                               progress=progress, package_dirs=inputs.package_dirs, srdf=inputs.srdf)
    except ModelError as exc:
        if check != "self-collision" or inputs.srdf is not None:  # asked for: the error as it is
            raise
        # checked by default, not asked for: say how to plan without it
        raise ModelError(f"{exc}; or plan --no-collision-check without the self-collision check") from None


#: A revolute joint whose URDF range is wider than one turn [deg] is drawn over the same posture at several
#: readings (a UR5's ±360°), which a note points out; ranges within 1° of one turn are one turn written with
#: a rounded π (URDFs give ±3.1416, 6.2832).
_ONE_TURN_DEG = 360.0
_ROUNDING_DEG = 1.0


def _turn_notes(ranges: tuple[JointRange, ...]) -> list[str]:
    """A note naming the joints drawn over more than one turn (their URDF ranges)."""
    wide = [r for r in ranges if r.kind == "revolute" and r.upper - r.lower > _ONE_TURN_DEG + _ROUNDING_DEG]
    if not wide:
        return []
    widest = max(r.upper - r.lower for r in wide)
    return [f"{', '.join(r.joint for r in wide)}: URDF ranges wider than one turn (up to {widest:.0f} deg), drawn "
            "whole, so a posture recurs at several readings; give --candidates to choose among postures you "
            "would command"]


def _existing_source(paths: list[Path]) -> str | list[str] | None:
    """PLAN.json ``sources.existing``: the file, or the files of several sessions."""
    return None if not paths else str(paths[0]) if len(paths) == 1 else [str(p) for p in paths]


def _text(path: str | Path | None) -> str | None:
    return None if path is None else str(path)
