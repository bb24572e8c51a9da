"""REPORT.json ``row_errors``: the error of every measured row, by file line.

One entry per set of rows (the calibration rows, the held-out rows of
``diagnose --validation``, the rows ``evaluate`` was run on)::

    {"set": "calibration", "file": "data.csv", "lines": [2, 3, ...],
     "files": ["data.csv", ...], "sessions": ["data", ...],
     "models": [{"model": "nominal geometry", "errors": {...eq 24 summary...},
                 "position_mm": [...], "orientation_deg": [...] | null}, ...],
     "point_position_mm": [[...], ...] | null, "robust_score": [...]}

``file`` names the set's file(s) (several joined by " + "); ``files`` and
``sessions`` give each row's own file (its ``lines`` count in it) and session
(one registration each), so rows of several files with equal line numbers
stay apart.

``models`` runs from the nominal geometry to the reported model (last); each
row's ``position_mm`` is the RMS distance of its target points from the model
[mm] (eq 24's q_jp, RMS over p), ``orientation_deg`` eq 24's η_j [deg].
``point_position_mm`` (J, P) gives every point of the reported model when a
target has several, and ``robust_score`` the row's (e − median) / (1.4826 MAD)
of the reported model's ``position_mm`` (:mod:`pincal.fit.outliers`; rows above
:data:`~pincal.fit.outliers.OUTLIER_THRESHOLD` are what ``calibrate`` flags).

The "nominal geometry" model is the URDF as given, with the registration (and
the estimated target) fitted to the calibration rows alone: the error a
calibration starts from.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from pincal.fit.metrics import PoseErrors, pose_errors
from pincal.fit.outliers import robust_scores
from pincal.fit.registration import register_orientations, register_points
from pincal.fit.sessions import session_pose_errors, session_rows
from pincal.measurements.data import MeasurementSet, default_session_name
from pincal.report.model import RowErrorModel, RowErrorSet, errors_json
from pincal.report.model_evaluation import EvaluationJson

if TYPE_CHECKING:
    from pincal.diagnosis.diagnose import Diagnosis
    from pincal.fit.chain_calibration import ChainCalibration
    from pincal.model.chain import KinematicChain

__all__ = [
    "NOMINAL", "CALIBRATED", "WITH_EFFECTS", "row_error_set", "chain_row_errors", "paper_row_errors",
    "diagnosis_row_errors", "EvaluatedRows", "evaluation_document",
]

NOMINAL = "nominal geometry"
CALIBRATED = "calibrated geometry"
WITH_EFFECTS = "geometry and effects"


def _model(name: str, errors: PoseErrors) -> RowErrorModel:
    per_row = np.sqrt(np.mean(errors.position_m**2, axis=1)) * 1000.0
    rotation = None if errors.rotation_rad is None else np.degrees(errors.rotation_rad).tolist()
    return {"model": name, "errors": errors_json(errors), "position_mm": per_row.tolist(), "orientation_deg": rotation}


def row_error_set(
    name: str, source: str, lines: Sequence[int] | np.ndarray, models: Sequence[tuple[str, PoseErrors]],
    files: Sequence[str] | np.ndarray | None = None, sessions: Sequence[str] | np.ndarray | None = None,
) -> RowErrorSet:
    """One ``row_errors`` entry: ``models`` as (name, errors of every row), the reported model last;
    ``files`` / ``sessions``: each row's file and session (default: ``source`` and its stem)."""
    final = models[-1][1]
    per_row = np.sqrt(np.mean(final.position_m**2, axis=1))
    count = len(lines)
    return {
        "set": name,
        "file": source,
        "lines": [int(line) for line in lines],
        "files": [str(f) for f in files] if files is not None else [str(source)] * count,
        "sessions": ([str(n) for n in sessions] if sessions is not None
                     else [default_session_name(str(source))] * count),
        "models": [_model(label, errors) for label, errors in models],
        "point_position_mm": (final.position_m * 1000.0).tolist() if final.position_m.shape[1] > 1 else None,
        "robust_score": robust_scores(per_row).tolist(),
    }


def chain_row_errors(
    chain: KinematicChain,
    nominal_placements,
    rows: MeasurementSet,
    calibration: ChainCalibration,
    errors: PoseErrors,
    source: str,
) -> list[RowErrorSet]:
    """``row_errors`` of ``calibrate --level registration|offsets|full``: the rows used in the
    fit, nominal geometry (with the registration and target of the fit's first stage,
    ``calibration.start``) against the calibrated model's ``errors``."""
    nominal = _nominal_chain_errors(chain, nominal_placements, rows, calibration)
    models = [(CALIBRATED, errors)] if nominal is None else [(NOMINAL, nominal), (CALIBRATED, errors)]
    return [row_error_set("calibration", source, rows.lines, models, rows.files, rows.sessions)]


def _nominal_chain_errors(chain, nominal_placements, rows, calibration) -> PoseErrors | None:
    start = calibration.start
    if start is None:
        return None
    sessions = session_rows(rows, calibration.session_names)  # each row in its session's registration
    with chain.placed(nominal_placements):
        return session_pose_errors(chain, rows, sessions, start.registrations, points=start.points,
                                   target_rotation=start.rotation)


def paper_row_errors(
    chain: KinematicChain, nominal_placements, rows: MeasurementSet, errors: PoseErrors, source: str
) -> list[RowErrorSet]:
    """``row_errors`` of the paper's methods: the calibration rows, the nominal DH model
    registered to them (Registrations 1 and 2, as the paper's methods register) against
    the calibrated model's ``errors``."""

    with chain.placed(nominal_placements):
        poses = chain.poses(rows.q)
        measured = rows.points[:, 0, :]
        registration = register_points(poses.tool_positions, measured)
        orientation = registration
        if rows.rotations is not None:
            orientation = register_orientations(poses.tool_rotations, rows.rotations, poses.tool_positions, measured)
        before = pose_errors(chain, rows, registration, orientation)
    return [row_error_set("calibration", source, rows.lines, [(NOMINAL, before), (CALIBRATED, errors)],
                          rows.files, rows.sessions)]


def diagnosis_row_errors(
    chain: KinematicChain,
    nominal_placements,
    data: MeasurementSet,
    heldout: MeasurementSet | None,
    calibration: ChainCalibration,
    diagnosis: Diagnosis,
    sources: tuple[str, str | None],
) -> list[RowErrorSet]:
    """``row_errors`` of ``diagnose``: calibration (and held-out) rows under the nominal
    geometry, the geometric calibration and the final model with its effects."""
    rows = data.select(calibration.used_index)
    first = diagnosis.steps[0] if diagnosis.steps else None
    sets: list[RowErrorSet] = []
    for name, measured, geometric, final, source in (
        ("calibration", rows, first.calibration_before if first else None, diagnosis.calibration_errors, sources[0]),
        ("held-out", heldout, first.heldout_before if first else None, diagnosis.heldout_errors, sources[1]),
    ):
        if measured is None or final is None:
            continue
        models = []
        nominal = _nominal_chain_errors(chain, nominal_placements, measured, calibration)
        if nominal is not None:
            models.append((NOMINAL, nominal))
        models.append((CALIBRATED, geometric if geometric is not None else final))
        if geometric is not None:
            models.append((WITH_EFFECTS, final))
        # the held-out rows come with their file's name (sources[1])
        sets.append(row_error_set(name, cast(str, source), measured.lines, models, measured.files,
                                  measured.sessions))
    return sets


@dataclass(frozen=True)
class EvaluatedRows:
    """The rows ``evaluate`` was run on, one entry each: its file line, file and session (in the data)."""

    lines: Sequence[int] = ()
    files: Sequence[str] | None = None
    sessions: Sequence[str] | None = None


def evaluation_document(
    urdf: str, data: str, errors: PoseErrors, document: EvaluationJson, rows: EvaluatedRows | None = None,
) -> dict[str, Any]:
    """What ``evaluate --html`` shows beside the report: the evaluated files, the eq 24
    summary (as ``evaluate --json`` writes it), the evaluated ``rows`` by file line (and
    each row's file and session), and from ``document`` (``evaluate --json``'s): ``sessions``, each
    evaluated session's entry (its registration's source, ``registration_reestimated``,
    ``residuals`` and ``registration_dof``); ``drift``: how the report's drift was applied, or None;
    ``thermal`` / ``pause_steps``: how its thermal expansion and pause steps were, where applied;
    ``warnings``: its plausibility findings; ``before``: the nominal URDF on these rows, registered to
    them, where known; ``skipped_cpa_rows``."""
    before, thermal, pause_steps = document.get("before"), document.get("thermal"), document.get("pause_steps")
    rows = EvaluatedRows() if rows is None else rows
    lines = rows.lines
    return {
        "warnings": list(document.get("warnings", [])),
        **({} if before is None else {"before": before}),
        "drift": document["drift"],
        **({} if thermal is None else {"thermal": thermal}),
        **({} if pause_steps is None else {"pause_steps": pause_steps}),
        "urdf": urdf,
        "data": data,
        "errors": {**errors.as_dict(), "skipped_cpa_rows": document["skipped_cpa_rows"]},
        "sessions": list(document["sessions"]),
        "row_errors": ([row_error_set("evaluated", data, lines, [("reported model", errors)], rows.files,
                                      rows.sessions)] if len(lines) else []),
    }
