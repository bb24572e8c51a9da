"""REPORT.json: what a calibration found, in a form scripts can rely on.

The builders here return the typed model of :mod:`pincal.report.model` (its JSON
Schema: ``docs/report.schema.json``, :mod:`pincal.report.schema`).

Keys promised to users (never renamed, only extended):

* ``method``; ``parameters``: list of {name, joint, unit, nominal, calibrated,
  std, status} — ``calibrated`` and ``std`` are null for parameters the data
  cannot determine, and ``status`` says why;
* ``registration.position``: Registration 1 as ``rotation_xyzw`` and
  ``translation_m``, mapping URDF-root coordinates to sensor coordinates
  (g ≈ Omega t + tau); ``registration.orientation``: Registration 2 likewise;
* ``tool``: ``parent_link``, ``xyz_m``, ``rpy_rad`` (pose of the target in the
  parent link) and, for estimated targets, ``points_m`` (the target's points in
  the parent link frame, in marker-column order);
* levels registration/offsets/full add ``level``, ``identifiability`` (rank,
  condition number, the selection criterion and its value, what was dropped and
  what absorbs it, correlated pairs), ``noise``, ``outliers``;
* ``fit``: stages, row counts and the errors (eq 24) on the calibration rows;
* ``urdf_sha256``: SHA-256 of the corrected URDF written with the report (the
  bytes written; of a URDF withheld for a gross misfit, the bytes ``--force``
  writes: :mod:`pincal.workflows.verdict`), so ``pincal evaluate`` can tell the pair
  apart from a URDF of another run;
* ``xacro_args``: ``{NAME: VALUE}`` the ``.xacro`` URDF was expanded with
  (``--xacro-arg``; ``{}`` for a URDF file or the xacro's defaults);
* ``row_errors``: the error of every row by file line, nominal geometry to the
  reported model, for the calibration (and held-out) rows
  (:mod:`pincal.report.row_errors`); ``chain.joint_kinds`` (levels other than
  dh): revolute, continuous or prismatic, per joint;
* ``sessions`` (levels other than dh): one entry per session — ``name``,
  ``file``, ``rows``, its ``registration`` (keys as the top-level one) and
  ``calibration_errors`` (:mod:`pincal.report.sessions`); with several
  sessions the top-level ``registration`` is the first session's.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from pincal._version import __version__
from pincal.fit.metrics import PoseErrors
from pincal.fit.registration_hold import rotation_reason
from pincal.fit.target_hold import held_reason
from pincal.measurements.couplings import ReadingCoupling, couplings_from_report
from pincal.measurements.data import MimicJson
from pincal.model.chain import ChainJoint, pose_from_xyz_rpy, xyz_rpy_from_pose
from pincal.model.dh.parameters import DHParameterSet
from pincal.model.sensor import Registration
from pincal.outputs import write_text
from pincal.report.model import (
    CalibrationReport,
    ChainHead,
    ChainJson,
    FitRows,
    Identifiability,
    NotDetermined,
    PaperReport,
    Parameter,
    PriorScale,
    SelectionJson,
    SessionEntry,
    Sources,
    errors_json,
    registration_pair,
)
from pincal.report.model_camera import CameraEvaluationJson, CameraReport
from pincal.report.model_diagnosis import DiagnosisReport
from pincal.report.model_evaluation import EvaluationJson
from pincal.report.model_fixture import FixtureEvaluationJson, FixtureReport
from pincal.report.model_tree import TreeEvaluationJson, TreeReport
from pincal.report.reading import load_report, value_at
from pincal.report.record import ReportRecord

if TYPE_CHECKING:
    from pincal.fit.chain_calibration import ChainCalibration
    from pincal.model.chain import KinematicChain
    from pincal.paper.methods import PaperCalibration

__all__ = [
    "REPORT_VERSION", "paper_report", "fit_rows", "chain_summary", "parameters_report", "identifiability_report",
    "not_determined_report", "selection_report", "write_report", "write_evaluation", "ReportModel", "read_report",
    "chain_head", "chain_report", "mimics_json",
]


REPORT_VERSION = 1


def _number(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def paper_report(
    result: PaperCalibration,
    params: DHParameterSet,
    tool_pose: np.ndarray,
    calibration_errors: PoseErrors,
    n_rows: FitRows,
    sources: Sources,
    notes: list[str],
    *,
    record: ReportRecord,
) -> PaperReport:
    """Build the REPORT.json document of a paper-method calibration; the tool's parent link is the chain's tip
    (``params.chain.tip_link``), ``record`` gives ``row_errors``, ``urdf_sha256`` and ``xacro_args``."""
    # imported here: `pincal calibrate --level full` does not load the paper's methods
    from pincal.paper.methods import CALIBRATED, FROM_CPA

    nominal = result.nominal.to_vector()
    calibrated = result.table.to_vector()
    parameters: list[Parameter] = []
    for i, info in enumerate(params.info):
        determined = result.status[i] in (CALIBRATED, FROM_CPA)
        parameters.append(
            {
                "name": info.name,
                "joint": info.joint,
                "unit": info.unit,
                "nominal": float(nominal[i]),
                "calibrated": float(calibrated[i]) if determined else None,
                "std": _number(result.std[i]) if determined else None,
                "status": result.status[i],
            }
        )
    xyz, rpy = xyz_rpy_from_pose(tool_pose)
    return {
        "pincal_version": __version__,
        "report_version": REPORT_VERSION,
        "method": int(result.method),  # calibrate runs Methods 1-3 (the study alone runs "ml")
        "weight_mm2_per_deg2": result.weight,
        "model": "dh",
        "sources": sources,
        "chain": {
            "root_link": params.chain.root_link,
            "tip_link": params.chain.tip_link,
            "joints": list(params.chain.joint_names),
        },
        "parameters": parameters,
        "registration": registration_pair(result.registration_position, result.registration_orientation),
        "tool": {"parent_link": params.chain.tip_link, "xyz_m": xyz.tolist(), "rpy_rad": rpy.tolist()},
        "fit": {
            "rows": n_rows,
            "stages": [
                {
                    "error_function": stage.name,
                    "parameters": list(stage.parameters),
                    "rms": stage.rms,
                    "unit": stage.unit,
                    "evaluations": stage.n_evaluations,
                    "jacobian_condition": stage.condition,
                }
                for stage in result.stages
            ],
            "calibration_errors": errors_json(calibration_errors),
        },
        "notes": list(result.notes) + list(notes),
        "row_errors": record.row_errors,
        "urdf_sha256": record.urdf_sha256,
        "xacro_args": record.xacro_args,
    }


def fit_rows(roles: np.ndarray) -> FitRows:
    """REPORT.json ``fit.rows``: the rows of each role (``roles``: each row's)."""
    return {"cpa": int(np.sum(roles == "cpa")), "calibration": int(np.sum(roles == "calibration")),
            "validation": int(np.sum(roles == "validation"))}


def chain_summary(chain: KinematicChain) -> ChainJson:
    """REPORT.json ``chain``: root and tip links, the joints and their kinds, and those that follow another."""
    out: ChainJson = {"root_link": chain.root_link, "tip_link": chain.tip_link, "joints": list(chain.joint_names),
                      "joint_kinds": [spec.kind for spec in chain.joint_specs]}
    mimics = mimics_json(chain.joints)
    if mimics:
        out["mimics"] = mimics
    return out


def mimics_json(joints: Sequence[ChainJoint]) -> list[MimicJson]:
    """REPORT.json ``chain.mimics``: each of ``joints`` that follows another (URDF ``<mimic>``, eq M1)."""
    return [{"joint": j.name, "driver": j.mimic.driver, "multiplier": j.mimic.multiplier, "offset": j.mimic.offset}
            for j in joints if j.mimic is not None]


def parameters_report(result) -> list[Parameter]:
    """REPORT.json ``parameters`` of a placement-level fit (sensor or fixture): each parameter's
    nominal (0) and calibrated value and std in its unit, None where the data cannot determine it."""
    params = result.params
    out: list[Parameter] = []
    for i in range(params.size if params is not None else 0):
        info = params.info[i]
        determined = result.status[i] == "calibrated"
        out.append({
            "name": info.name,
            "joint": info.joint,
            "unit": info.unit,
            "nominal": 0.0,
            "calibrated": float(result.vector[i]) if determined else None,
            "std": _number(result.std[i]) if determined else None,
            "status": result.status[i],
        })
    return out


def identifiability_report(result) -> Identifiability:
    """REPORT.json ``identifiability`` of a placement-level fit: rank, condition number, selection,
    the dropped parameters with what absorbs them, and the strongly correlated pairs."""
    params = result.params
    names = {i: params.info[i].name for i in range(params.size)} if params is not None else {}
    out: Identifiability = {
        "rank": result.rank,
        "jacobian_condition": result.condition,
        "selection": selection_report(result.selection),
        "dropped": [
            {
                "name": names[d.index],
                "reason": d.reason,
                "absorbed_into": [{"name": n, "coefficient": c} for n, c in d.absorbed_into],
            }
            for d in result.dropped
        ],
        "correlated_pairs": [{"a": a, "b": b, "correlation": c} for a, b, c in result.correlated],
        "not_determined": not_determined_report(result),
    }
    rotations = getattr(result, "held_rotations", ())
    if rotations:  # present only when a registration rotation was held (pincal.fit.registration_hold)
        out["not_determined_rotations"] = [
            {"name": f"registration[{h.session}].rotation" if h.session else "registration.rotation",
             "axis": [float(v) for v in h.axis], "frame": h.frame, "seen": h.seen,
             "rule": "nearest_tool_rotation" if h.orientations else "levelled",
             "reason": rotation_reason(h)} for h in rotations]
    return out


def not_determined_report(result) -> list[NotDetermined]:
    """REPORT.json ``identifiability.not_determined``: each direction of an always-estimated unknown
    (the target's position) the data leave free, held at a stated value (:mod:`pincal.fit.target_hold`)."""
    return [{"name": "target.position", "direction": [float(v) for v in h.direction],
             "turn_deg": float(np.degrees(h.turn_rad)), "held_at_m": h.value_m,
             "std_m_when_estimated": _number(h.std_m),
             "reason": held_reason(h)} for h in getattr(result, "held", ())]


def selection_report(selection) -> SelectionJson | None:
    """REPORT.json ``identifiability.selection`` of a :class:`pincal.fit.identifiability.Selection`
    (None without one); a criterion value that is undefined (e.g. PRESS with a row of leverage 1) is null."""
    if selection is None:
        return None
    prior_scale: PriorScale | None = getattr(selection, "prior_scale", None) or None
    out: SelectionJson = {
        "criterion": selection.criterion,
        "kept": selection.chosen,
        "value": _number(selection.scores[selection.sizes.index(selection.chosen)]),
        "candidates": [{"kept": n, "value": _number(v)} for n, v in zip(selection.sizes, selection.scores)],
        # the candidates fitted nonlinearly; the others' values are linearised (pincal/fit/selection.py)
        "refitted": list(selection.refitted),
    }
    if prior_scale:
        out["prior_scale"] = prior_scale
    return out


def write_report(path: str | Path,
                 report: CalibrationReport | DiagnosisReport | PaperReport | FixtureReport | TreeReport
                 | CameraReport) -> None:
    """Write ``report`` as indented JSON."""
    write_text(path, json.dumps(report, indent=2) + "\n")


def write_evaluation(path: str | Path, document: EvaluationJson | FixtureEvaluationJson | TreeEvaluationJson
                     | CameraEvaluationJson) -> None:
    """Write ``pincal evaluate --json``'s document as indented JSON."""
    write_text(path, json.dumps(document, indent=2) + "\n")


@dataclass(frozen=True)
class ReportModel:
    """What ``pincal evaluate`` needs from a REPORT.json.

    Attributes:
        tool_parent: link carrying the target.
        points: target points in ``tool_parent``'s frame [m], (P, 3): ``tool.points_m``,
            or the origin ``tool.xyz_m`` of a single-point tool.
        rotation: the measured target frame's rotation in ``tool_parent`` (``tool.rpy_rad``).
        registration_position: Registration 1.
        registration_orientation: Registration 2.
        effects: ``effects`` and what applying them needs (``payload_kg``,
            ``time_column``, ``time_reference_s``, ``time_spans_s``, and a thermal effect's
            ``temperature_column``, ``temperature_range_c``, pause steps' ``pauses``, ``pause_spans_s``);
            empty without effects.
        urdf_sha256: SHA-256 (hex) of the corrected URDF written with the
            report (``urdf_sha256``); None in reports older than the key.
        sessions: (name, Registration 1, Registration 2) of each session
            (``sessions``); empty in reports without the key (one session).
        noise: the noise scales the fit estimated (``noise``: ``sigma_pos_mm``,
            ``sigma_rot_deg``); empty if not reported.
        session_files: the file(s) each session's rows were read from, as given to
            calibrate (``sessions[].file``), in the order of ``sessions``.
        not_determined: the reasons of ``identifiability.not_determined`` (a target held where the
            calibration rows could not place it); empty when everything was determined.
        held_rotations: the reasons of ``identifiability.not_determined_rotations`` (a registration
            rotation held: calibration rows on one line); empty when none was.
        couplings: joint readings taken against another joint (REPORT.json ``couplings``,
            :mod:`pincal.measurements.couplings`), corrected in every row evaluated.
        nominal_urdf: the URDF the calibration started from (``sources.urdf``, as it was given), or None.
        corrected_urdf: the URDF written with the report (``sources.corrected_urdf``), or None.
        calibration_rms_mm: the RMS position error on the calibration rows [mm] (eq 24, every target point;
            with a diagnosis's effects, ``diagnosis.calibration_errors``, else ``fit.calibration_errors``), or None.
    """

    tool_parent: str
    points: np.ndarray
    rotation: np.ndarray
    registration_position: Registration
    registration_orientation: Registration
    effects: dict = field(default_factory=dict)
    urdf_sha256: str | None = None
    sessions: tuple[tuple[str, Registration, Registration], ...] = ()
    noise: dict = field(default_factory=dict)
    session_files: tuple[tuple[str, ...], ...] = ()
    not_determined: tuple[str, ...] = ()
    held_rotations: tuple[str, ...] = ()
    couplings: tuple[ReadingCoupling, ...] = ()
    nominal_urdf: str | None = None
    corrected_urdf: str | None = None
    calibration_rms_mm: float | None = None


def _first_present(*values: float | None) -> float | None:
    """The first value that is not None (0.0 is a value)."""
    return next((value for value in values if value is not None), None)


def _rms_mm(errors: Any) -> float | None:
    """``position.rms_mm`` of a set of eq 24 errors (None: not recorded)."""
    return None if errors is None else float(errors["position"]["rms_mm"])


def _points(value: Any) -> np.ndarray:
    """``tool.points_m``: the target's points [m] in the parent link, (P, 3)."""
    points = np.asarray(value, dtype=float)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError("a list of [x, y, z] expected")
    return points


def _vector3(value: Any) -> list[float]:
    if np.shape(value) != (3,):
        raise ValueError("3 numbers expected")
    return [float(v) for v in value]


def _sha256(digest: Any) -> str | None:
    if digest is not None and not (isinstance(digest, str) and re.fullmatch(r"[0-9a-f]{64}", digest)):
        raise ValueError("64 hexadecimal digits expected")
    return digest


def _registrations(pair: dict[str, Any]) -> tuple[Registration, Registration]:
    """Registrations 1 and 2 of a ``registration`` object (2 is 1 where absent)."""
    return Registration.from_dict(pair["position"]), Registration.from_dict(pair.get("orientation", pair["position"]))


def _session(entry: dict[str, Any]) -> tuple[str, Registration, Registration]:
    return (str(entry["name"]), *_registrations(entry["registration"]))


def _reasons(entries: Any) -> tuple[str, ...]:
    """The ``reason`` of each entry of a list of held unknowns (``identifiability.not_determined...``)."""
    return tuple(str(entry.get("reason", "")) for entry in entries or ())


def _session_files(entry: dict[str, Any]) -> tuple[str, ...]:
    files = entry.get("file")
    return tuple(str(f) for f in (files if isinstance(files, list) else [files]) if f is not None)


def read_report(path: str | Path) -> ReportModel:
    """Read the target and registrations of a REPORT.json of calibrate or diagnose
    (:func:`pincal.report.reading.load_report`; one line naming the file and key if malformed)."""
    doc = cast(dict[str, Any], load_report(
        path, accept=("calibration", "diagnosis", "paper"), hint="pass the REPORT.json written by 'pincal calibrate'",
        hints={"fixture": "evaluate it with --fixture FIXTURE.csv"}))
    position = value_at(doc, "registration.position", path, Registration.from_dict)
    pose = pose_from_xyz_rpy(value_at(doc, "tool.xyz_m", path, _vector3, default=[0.0, 0.0, 0.0]),
                             value_at(doc, "tool.rpy_rad", path, _vector3, default=[0.0, 0.0, 0.0]))
    points = value_at(doc, "tool.points_m", path, _points, default=None)
    effect_keys = ("effects", "payload_kg", "time_column", "time_reference_s", "time_spans_s", "approach_context",
                   "temperature_column", "temperature_range_c", "pauses", "pause_spans_s")
    return ReportModel(
        tool_parent=str(value_at(doc, "tool.parent_link", path)),
        points=pose[None, :3, 3] if points is None else points,
        rotation=pose[:3, :3],
        registration_position=position,
        registration_orientation=value_at(doc, "registration.orientation", path, Registration.from_dict,
                                          default=position),
        effects={k: doc[k] for k in effect_keys if k in doc},
        urdf_sha256=value_at(doc, "urdf_sha256", path, _sha256, default=None),
        sessions=tuple(value_at(doc, "sessions", path, lambda entries: [_session(e) for e in entries or ()], ())),
        noise=dict(value_at(doc, "noise", path, default=None) or {}),
        session_files=tuple(value_at(doc, "sessions", path, lambda entries: [_session_files(e) for e in entries or ()],
                                  ())),
        not_determined=value_at(doc, "identifiability.not_determined", path, _reasons, ()),
        held_rotations=value_at(doc, "identifiability.not_determined_rotations", path, _reasons, ()),
        couplings=couplings_from_report(doc.get("couplings"), str(path)),
        nominal_urdf=value_at(doc, "sources.urdf", path, default=None),
        corrected_urdf=value_at(doc, "sources.corrected_urdf", path, default=None),
        calibration_rms_mm=_first_present(value_at(doc, "diagnosis.calibration_errors", path, _rms_mm, default=None),
                                          value_at(doc, "fit.calibration_errors", path, _rms_mm, default=None)),
    )


def chain_head(
    result: ChainCalibration,
    chain: KinematicChain,
    tool_parent: str,
    calibration_errors: PoseErrors,
    n_rows: FitRows,
    sources: Sources,
    notes: list[str],
) -> ChainHead:
    """The keys a calibration at level registration/offsets/full and a diagnosis share, up to ``notes``
    (``chain`` placed as calibrated)."""
    tool = chain.tool
    points = result.target.points @ tool[:3, :3].T + tool[:3, 3]  # in the parent link frame
    rotation = tool[:3, :3] @ result.target.rotation
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = rotation, points[0]
    xyz, rpy = xyz_rpy_from_pose(pose)
    return {
        "pincal_version": __version__,
        "report_version": REPORT_VERSION,
        "method": None,
        "level": result.level,
        "model": "joint placements",
        "sources": sources,
        "chain": chain_summary(chain),
        "parameters": parameters_report(result),
        "identifiability": identifiability_report(result),
        "registration": registration_pair(result.target.registration, result.target.registration),
        "tool": {
            "parent_link": tool_parent,
            "points_m": points.tolist(),
            "xyz_m": xyz.tolist(),
            "rpy_rad": rpy.tolist(),
        },
        "noise": {
            "sigma_pos_mm": result.sigma_pos_m * 1000.0,
            "sigma_rot_deg": None if result.sigma_rot_rad is None else float(np.degrees(result.sigma_rot_rad)),
        },
        "outliers": [{"line": line, "robust_score": score, "file": file, "by": by}
                     for (line, score), file, by in zip(result.outliers,
                                                        result.outlier_files or [None] * len(result.outliers),
                                                        result.outlier_errors())],
        "removed_lines": list(result.removed_lines),
        "removed_files": list(result.removed_files),
        "fit": {
            "rows": n_rows,
            "rows_used": len(result.rows_used),
            "rms_point_error_mm": result.rms_m * 1000.0,
            "fit_seconds": result.fit_seconds,
            "total_seconds": result.total_seconds,
            "calibration_errors": errors_json(calibration_errors),
        },
        "notes": list(result.notes) + list(notes),
    }


def chain_report(head: ChainHead, *, sessions: list[SessionEntry], record: ReportRecord) -> CalibrationReport:
    """Build the REPORT.json document of a calibration at level registration/offsets/full from its
    :func:`chain_head`, its ``sessions`` and what ``record`` says of the run."""
    return {
        **head,
        "warnings": record.warnings,
        "sessions": sessions,
        "row_errors": record.row_errors,
        **record.level_choice,
        "urdf_sha256": record.urdf_sha256,
        "xacro_args": record.xacro_args,
        **(record.couplings or {}),
    }
