"""REPORT.json: what a calibration found, in a form scripts can rely on.

Keys promised to users (never renamed, only extended):

* ``method``; ``parameters``: list of {name, joint, unit, nominal, calibrated,
  std, status} — ``calibrated`` and ``std`` are null for parameters the data
  cannot determine, and ``status`` says why;
* ``registration.position``: Registration 1 as ``rotation_xyzw`` and
  ``translation_m``, mapping URDF-root coordinates to sensor coordinates
  (g ≈ Omega t + tau); ``registration.orientation``: Registration 2 likewise;
* ``tool``: ``parent_link``, ``xyz_m``, ``rpy_rad`` (pose of the target in the
  parent link);
* ``fit``: stages, row counts and the errors (eq 24) on the calibration rows.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from . import __version__
from .chain import pose_from_xyz_rpy, xyz_rpy_from_pose
from .dh_parameters import DHParameterSet
from .errors import PincalError
from .metrics import PoseErrors
from .paper_methods import CALIBRATED, FROM_CPA, PaperCalibration
from .registration import Registration

REPORT_VERSION = 1


def _number(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def paper_report(
    result: PaperCalibration,
    params: DHParameterSet,
    tool_parent: str,
    tool_pose: np.ndarray,
    calibration_errors: PoseErrors,
    n_rows: dict[str, int],
    sources: dict[str, str],
    notes: list[str],
) -> dict[str, Any]:
    """Build the REPORT.json document of a paper-method calibration."""
    nominal = result.nominal.to_vector()
    calibrated = result.table.to_vector()
    parameters = []
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
        "method": result.method,
        "weight_mm2_per_deg2": result.weight,
        "model": "dh",
        "sources": sources,
        "chain": {
            "root_link": params.chain.root_link,
            "tip_link": params.chain.tip_link,
            "joints": list(params.chain.joint_names),
        },
        "parameters": parameters,
        "registration": {
            "position": result.registration_position.as_dict(),
            "orientation": result.registration_orientation.as_dict(),
        },
        "tool": {"parent_link": tool_parent, "xyz_m": xyz.tolist(), "rpy_rad": rpy.tolist()},
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
            "calibration_errors": calibration_errors.as_dict(),
        },
        "notes": list(result.notes) + list(notes),
    }


def write_report(path: str | Path, report: dict[str, Any]) -> None:
    """Write ``report`` as indented JSON."""
    Path(path).write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")


@dataclass(frozen=True)
class ReportModel:
    """What ``pincal evaluate`` needs from a REPORT.json.

    Attributes:
        tool_parent: link carrying the tool.
        tool_pose: ``parent_T_tool`` (4, 4) [m].
        registration_position: Registration 1.
        registration_orientation: Registration 2.
    """

    tool_parent: str
    tool_pose: np.ndarray
    registration_position: Registration
    registration_orientation: Registration


def read_report(path: str | Path) -> ReportModel:
    """Read the tool and registrations of a REPORT.json (one clear error if malformed)."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise PincalError(f"{path}: no such report file") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise PincalError(f"{path}: not a readable JSON report ({exc})") from None
    try:
        tool = doc["tool"]
        registration = doc["registration"]
        return ReportModel(
            tool_parent=str(tool["parent_link"]),
            tool_pose=pose_from_xyz_rpy(tool["xyz_m"], tool["rpy_rad"]),
            registration_position=Registration.from_dict(registration["position"]),
            registration_orientation=Registration.from_dict(
                registration.get("orientation", registration["position"])
            ),
        )
    except (KeyError, TypeError, ValueError, PincalError) as exc:
        raise PincalError(
            f"{path}: not a pincal report (missing or bad key {exc}); "
            "pass the REPORT.json written by 'pincal calibrate'"
        ) from None
