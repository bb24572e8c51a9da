"""File-level workflows of the commands that come before a calibration: urdf-from-dh and plan.

Each function takes paths and options, checks the outputs
(:func:`pincal.cli.paths.refuse_overwrite`), does the whole job and returns
what happened; :mod:`pincal.cli.commands` prints it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pincal.cli.paths import refuse_overwrite
from pincal.errors import PincalError
from pincal.measurements.csv_v1 import read_measurements
from pincal.model.chain import KinematicChain
from pincal.model.urdf_from_dh import DHUrdf, urdf_from_dh_table
from pincal.planning.candidates import DEFAULT_SAMPLE, read_candidates, sample_candidates
from pincal.planning.collisions import Clearance, check_clearance
from pincal.planning.files import plan_document, write_plan_csv, write_plan_json
from pincal.planning.planner import Plan, PlanSettings, plan_measurements

# --- urdf-from-dh ------------------------------------------------------------------------


def urdf_from_dh_file(
    table_path: str | Path,
    convention: str,
    out_urdf: str | Path,
    name: str | None = None,
    degrees: bool = False,
    flange: np.ndarray | None = None,
) -> DHUrdf:
    """Write the URDF of a DH table (:func:`pincal.model.urdf_from_dh.urdf_from_dh_table`) after
    checking the output path (never the table; its folder is created if missing); the URDF is written
    only if its kinematics equal the DH product (:data:`pincal.model.urdf_from_dh.FK_TOLERANCE`).

    ``flange`` is the pose (4, 4) [m] of the flange in the last DH frame (identity if None).
    """
    refuse_overwrite(out_urdf, table_path)
    return urdf_from_dh_table(table_path, convention, out_urdf, name=name, degrees=degrees, flange=flange)


# --- plan --------------------------------------------------------------------------------


@dataclass(frozen=True)
class PlanRun:
    """Outcome of :func:`plan_files`: the plan, the PLAN.json document, the clearance check and notes."""

    plan: Plan
    document: dict
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
    existing_path: str | Path | None = None,
    workspace_path: str | Path | None = None,
    min_distance: float | None = None,
) -> PlanRun:
    """Plan ``settings.count`` measurements of the chain ``urdf`` → ``tip_link``; write PLAN.csv and PLAN.json.

    ``settings.tool_known`` must say whether ``tool_pose`` is given. Level ``dh``
    plans for the paper's DH parameters with the target known, so it needs
    ``tool_pose``.

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
    inputs = [Path(p) for p in (urdf, candidates_path, existing_path, workspace_path) if p is not None]
    refuse_overwrite(out_csv, *inputs)
    refuse_overwrite(out_json, *inputs, outputs=[out_csv])
    chain = KinematicChain.from_urdf(urdf, tip_link, tool=tool_pose)
    notes: list[str] = []
    if candidates_path is not None:
        candidates, labels = read_candidates(candidates_path, chain)
    else:
        candidates = sample_candidates(chain, sample, settings.seed)
        labels = np.arange(len(candidates))
    existing = None
    if existing_path is not None:
        existing, read_notes = read_measurements(existing_path, chain.joint_specs)
        notes += read_notes
    workspace = read_candidates(workspace_path, chain)[0] if workspace_path is not None else None
    clearance = check_clearance(urdf, chain, candidates, min_distance) if min_distance is not None else None
    plan = plan_measurements(chain, candidates, settings, existing=existing, workspace=workspace,
                             allowed=None if clearance is None else clearance.allowed)
    sources = {"urdf": str(urdf), "candidates": _text(candidates_path), "existing": _text(existing_path),
               "workspace": _text(workspace_path)}
    digest = write_plan_csv(out_csv, plan, chain, labels)
    document = plan_document(plan, chain, plan.settings, sources, labels, len(candidates), clearance, tool_pose,
                             sample if candidates_path is None else None, plan_csv_sha256=digest)
    write_plan_json(out_json, document)
    return PlanRun(plan, document, clearance, len(candidates), notes + list(plan.notes))


def _text(path) -> str | None:
    return None if path is None else str(path)
