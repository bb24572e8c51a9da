"""File-level workflows of the commands that come before a calibration: urdf-from-dh and plan.

Each function takes paths and options, checks the outputs
(:func:`pincal.workflows.paths.refuse_overwrite`), does the whole job and returns
what happened; :mod:`pincal.cli.commands` prints it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from pincal.errors import PincalError
from pincal.fit.plausibility import tip_link_findings
from pincal.measurements.couplings import ReadingCoupling, corrected_angles, readings_of
from pincal.measurements.csv_v1 import file_columns, read_sessions
from pincal.model.chain import KinematicChain
from pincal.model.description import xacro_arguments
from pincal.model.dh.conversion import DHUrdf, urdf_from_dh_table
from pincal.planning.candidates import DEFAULT_SAMPLE, read_candidates, sample_candidates
from pincal.planning.collisions import Clearance, check_clearance
from pincal.planning.files import PlanJson, PlanSources, plan_document, write_plan_csv, write_plan_json
from pincal.planning.planner import Plan, PlanSettings, plan_measurements
from pincal.progress import Progress, Stages
from pincal.workflows.paths import description_inputs, input_paths, refuse_overwrite

__all__ = ["urdf_from_dh_file", "PlanRun", "plan_files"]

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


@dataclass(frozen=True)
class PlanRun:
    """Outcome of :func:`plan_files`: the plan, the PLAN.json document, the clearance check and notes."""

    plan: Plan
    document: PlanJson
    clearance: Clearance | None
    n_candidates: int
    notes: list[str]


def plan_files(
    urdf: str | Path,
    tip_link: str,
    settings: PlanSettings,
    out_csv: str | Path,
    out_json: str | Path,
    tool_pose: np.ndarray | None = None,
    candidates_path: str | Path | None = None,
    sample: int = DEFAULT_SAMPLE,
    existing_path: str | Path | Sequence[str | Path] | None = None,
    couplings: Sequence[ReadingCoupling] = (),
    workspace_path: str | Path | None = None,
    min_distance: float | None = None,
    xacro_args: Sequence[tuple[str, str]] = (),
    progress: Progress | None = None,
    package_dirs: Mapping[str, Path] | None = None,
) -> PlanRun:
    """Plan ``settings.count`` measurements of the chain ``urdf`` → ``tip_link``; write PLAN.csv and PLAN.json.

    ``settings.tool_known`` must say whether ``tool_pose`` is given. Level ``dh``
    plans for the paper's DH parameters with the target known, so it needs
    ``tool_pose``. A ``.xacro`` ``urdf`` is expanded in memory with ``xacro_args``. ``package_dirs``
    (NAME → folder, ``--package-dir``) locates ``package://`` collision meshes (:mod:`pincal.model.packages`).
    ``couplings`` (``--coupling``): joints the controller reads against another; the candidate, existing and
    workspace files are corrected by eq C1 (:mod:`pincal.measurements.couplings`), PLAN.csv is written in
    the controller's readings (its inverse) and PLAN.json records them (``sources.couplings``).
    ``progress(done, total)`` counts the clearance checks, then the search's steps
    (:func:`pincal.planning.planner.plan_measurements`).

    Raises:
        PincalError: an output path that is an input, the other output or a
            folder; ``dh`` without a tool; any problem of the inputs or the plan.
    """
    if settings.level == "dh" and tool_pose is None:
        raise PincalError(
            "--level dh plans for the paper's DH parameters with the target known: give --tool X,Y,Z,ROLL,PITCH,YAW "
            "(as calibrate --level dh needs), or plan --level registration|offsets|full"
        )
    urdf = Path(urdf)
    existing_paths = [] if existing_path is None else input_paths(existing_path)
    inputs = [*description_inputs(urdf, xacro_args),  # a xacro's included files are inputs too
              *(Path(p) for p in (candidates_path, *existing_paths, workspace_path) if p is not None)]
    refuse_overwrite(out_csv, *inputs)
    refuse_overwrite(out_json, *inputs, outputs=[out_csv])
    chain = KinematicChain.from_urdf(urdf, tip_link, tool=tool_pose, xacro_args=xacro_args)
    names = chain.joint_names
    notes: list[str] = []
    if candidates_path is not None:  # a file holds the controller's readings (eq C1 with --coupling)
        candidates, labels = read_candidates(candidates_path, chain)
        candidates = corrected_angles(candidates, couplings, names)
    else:
        candidates = sample_candidates(chain, sample, settings.seed)
        labels = np.arange(len(candidates))
    # no calibration to judge here: whether the target moved with them is for calibrate to say (a note)
    files = [] if candidates_path is None else [candidates_path]
    existing = None
    if existing_paths:  # several files: sessions, one registration each; the plan continues the last
        existing, read_notes = read_sessions(existing_paths, chain.joint_specs, couplings, chain.other_branch_joints)
        notes += read_notes
        files += existing_paths
    notes += [finding.message for finding in tip_link_findings(chain, file_columns(files, names))]
    workspace = (corrected_angles(read_candidates(workspace_path, chain)[0], couplings, names)
                 if workspace_path is not None else None)
    stages = Stages(progress)
    clearance = (check_clearance(urdf, chain, candidates, min_distance, xacro_args=xacro_args, progress=stages.next(),
                                 package_dirs=package_dirs)
                 if min_distance is not None else None)
    plan = plan_measurements(chain, candidates, settings, existing=existing, workspace=workspace,
                             allowed=None if clearance is None else clearance.allowed, progress=stages.next())
    sources: PlanSources = {"urdf": str(urdf), "candidates": _text(candidates_path),
                            "existing": _existing_source(existing_paths), "workspace": _text(workspace_path),
                            "xacro_args": dict(xacro_arguments(xacro_args))}
    if couplings:  # PLAN.csv in the controller's joint space: what it reads and is commanded in
        sources["couplings"] = [c.as_dict() for c in couplings]
    digest = write_plan_csv(out_csv, replace(plan, q=readings_of(plan.q, couplings, names)), chain, labels)
    document = plan_document(plan, chain, plan.settings, sources, labels, len(candidates), clearance, tool_pose,
                             sample if candidates_path is None else None, plan_csv_sha256=digest)
    write_plan_json(out_json, document)
    return PlanRun(plan, document, clearance, len(candidates), notes + list(plan.notes))


def _existing_source(paths: list[Path]) -> str | list[str] | None:
    """PLAN.json ``sources.existing``: the file, or the files of several sessions."""
    return None if not paths else str(paths[0]) if len(paths) == 1 else [str(p) for p in paths]


def _text(path: str | Path | None) -> str | None:
    return None if path is None else str(path)
