"""REPORT.json of a socket-fixture calibration (``pincal calibrate --fixture``).

The keys of a sensor calibration keep their meaning (:mod:`pincal.report.document`):
``level``, ``parameters``, ``identifiability``, ``chain``, ``sources``,
``tool`` (``parent_link``, ``points_m`` and ``xyz_m``: the ball centre in the
tip link; no ``rpy_rad``, a ball has no orientation the data could see),
``noise``, ``outliers``, ``fit``, ``notes``, ``urdf_sha256``. There is no
``registration``: no sensor. The ``fixture`` block adds:

* ``file``, ``sockets`` (name, ``xyz_m`` in the fixture frame), ``distances_mm``;
* ``ball_centre_m`` and ``ball_centre_std_m`` (tip link frame);
* ``placements``: per placement its ``rows``, each used socket's centre in the
  URDF root frame (``position_m``, ``std_m``) and what the data determine of
  its pose: ``line_direction`` for collinear sockets (``rotation_xyzw`` and
  ``translation_m`` are then null: the turn about the line is not determined),
  else the whole pose;
* ``training``: consistency and distortion (:mod:`pincal.fit.socket_metrics`)
  of the nominal model (``before``) and of the calibrated one (``after``) on
  the calibration placements;
* ``nominal``: the ball centre fitted with the nominal kinematics and the
  SHA-256 of the nominal URDF — what ``pincal evaluate --fixture`` needs for
  its "before";
* ``held_out_placements``: with two or more placements and a level other than
  ``registration``, each placement predicted by the level's calibration of the
  others and by the nominal model (:mod:`pincal.fit.placement_check`), else null.

``warnings`` holds the plausibility findings (that check's), as a sensor calibration's does.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any, cast

import numpy as np
from scipy.spatial.transform import Rotation

from pincal._version import __version__
from pincal.fit.fixture_calibration import FixtureCalibration
from pincal.fit.placement_check import PlacementCheck
from pincal.measurements.fixture import FixtureData
from pincal.model.chain import KinematicChain
from pincal.report.document import REPORT_VERSION, chain_summary, identifiability_report, parameters_report
from pincal.report.model import Sources
from pincal.report.model_fixture import FixturePlacement, FixtureReport, HeldOutPlacements, fixture_metrics_json
from pincal.report.reading import value_at
from pincal.report.record import ReportRecord

__all__ = ["TURN_NOT_DETERMINED", "fixture_report", "read_fixture_block"]

#: What the report says of a collinear placement's rotation.
TURN_NOT_DETERMINED = "the turn about the socket line: the sockets are collinear"


def fixture_report(
    result: FixtureCalibration,
    chain: KinematicChain,
    data: FixtureData,
    sources: Sources,
    notes: list[str],
    nominal_urdf_sha256: str,
    *,
    record: ReportRecord,
    held_out: PlacementCheck | None = None,
) -> FixtureReport:
    """Build the REPORT.json document of a socket-fixture calibration (``chain`` placed as calibrated);
    ``record``: its level choice, xacro arguments, the corrected URDF's SHA-256, the couplings and the
    plausibility findings (:func:`pincal.report.model.findings_json`), no row errors;
    ``held_out``: the leave-one-placement-out check."""
    fixture = data.fixture
    ball = result.ball.tolist()
    return {
        "pincal_version": __version__,
        "report_version": REPORT_VERSION,
        "method": None,
        "level": result.level,
        "model": "joint placements",
        "measurement": "socket fixture",
        "sources": sources,
        "chain": chain_summary(chain),
        "parameters": parameters_report(result),
        "identifiability": identifiability_report(result),
        "tool": {"parent_link": chain.tip_link, "points_m": [ball], "xyz_m": ball},
        "noise": {"sigma_pos_mm": result.rms_m * 1000.0, "sigma_rot_deg": None},
        "outliers": [{"file": file, "line": line, "robust_score": score, "by": "position"}
                     for file, line, score in result.outliers],
        "removed_lines": [],
        "fit": {
            "rows": {"calibration": result.n_rows},
            "rows_used": result.n_rows,
            "rms_point_error_mm": result.rms_m * math.sqrt(3.0) * 1000.0,
            "fit_seconds": result.fit_seconds,
            "total_seconds": result.total_seconds,
        },
        "fixture": {
            "file": sources.get("fixture"),
            "sockets": [{"name": n, "xyz_m": p.tolist()} for n, p in zip(fixture.names, fixture.points)],
            "distances_mm": [
                {"a": fixture.names[a], "b": fixture.names[b], "mm": fixture.distance(a, b) * 1000.0}
                for a in range(len(fixture.names)) for b in range(a + 1, len(fixture.names))
            ],
            "ball_centre_m": ball,
            "ball_centre_std_m": result.ball_std.tolist(),
            "placements": [_placement(p) for p in result.placements],
            "training": {"before": fixture_metrics_json(result.nominal_training),
                         "after": fixture_metrics_json(result.training)},
            "nominal": {"urdf_sha256": nominal_urdf_sha256, "ball_centre_m": result.nominal_ball.tolist(),
                        "rms_point_error_mm": result.nominal_rms_m * math.sqrt(3.0) * 1000.0},
            "held_out_placements": None if held_out is None else cast(HeldOutPlacements, held_out.as_dict()),
        },
        "notes": list(result.notes) + list(notes),
        "warnings": list(record.warnings),
        **record.level_choice,
        "xacro_args": record.xacro_args,
        "urdf_sha256": record.urdf_sha256,
        **(record.couplings or {}),
    }


def _placement(placement) -> FixturePlacement:
    collinear = placement.line_direction is not None
    return {
        "name": placement.name,
        "rows": placement.rows,
        "sockets": [{"name": n, "position_m": p.tolist(), "std_m": s.tolist()}
                    for n, p, s in zip(placement.sockets, placement.socket_positions, placement.socket_std)],
        "line_direction": placement.line_direction.tolist() if collinear else None,
        "rotation_xyzw": None if collinear else Rotation.from_matrix(placement.rotation).as_quat().tolist(),
        "translation_m": None if collinear else placement.translation.tolist(),
        "not_determined": TURN_NOT_DETERMINED if collinear else None,
    }


def read_fixture_block(
    document: Mapping[str, Any], source: str | Path
) -> tuple[str, np.ndarray, np.ndarray, str | None]:
    """Tip link, ball centre, nominal ball centre [m] and nominal URDF SHA-256 of a fixture report
    read from ``source`` (:func:`pincal.report.reading.load_report`).

    Raises:
        PincalError: a key missing or malformed, one line naming ``source`` and the key.
    """
    def centre(value: Any) -> np.ndarray:
        return np.asarray(value, dtype=float).reshape(3)

    return (str(value_at(document, "tool.parent_link", source)),
            value_at(document, "fixture.ball_centre_m", source, centre),
            value_at(document, "fixture.nominal.ball_centre_m", source, centre),
            value_at(document, "fixture.nominal.urdf_sha256", source, default=None))
