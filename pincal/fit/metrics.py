"""Accuracy of a calibrated model on measured rows (eq 24).

For each row j and target point p: the position error q_jp = ‖Omega_1 x_jp +
tau_1 − g_jp‖ through Registration 1, with x_jp the point in the robot base
frame; and the orientation error eta_j, the angle of G_j⁻¹ Omega_2 R_j R_T,
through Registration 2 (Franaszek & Marvel 2022, eq 24; R_T is the target's
rotation in the tool frame, identity for a known tool).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import pinocchio as pin

from pincal.measurements.data import MeasurementSet
from pincal.model.chain import KinematicChain, points_in_base
from pincal.model.effects import sensed_points
from pincal.model.lateral import bent_tool_poses
from pincal.model.sensor import Registration
from pincal.model.thermal import RowConditions

__all__ = ["ErrorSummary", "PoseErrors", "RowCorrections", "pose_errors"]


@dataclass(frozen=True)
class ErrorSummary:
    """Mean, RMS and maximum of errors, in reporting units (mm or deg)."""

    mean: float
    rms: float
    max: float
    unit: str

    @classmethod
    def of(cls, values: np.ndarray, unit: str) -> ErrorSummary:
        values = np.asarray(values, dtype=float).ravel()
        return cls(
            mean=float(values.mean()),
            rms=float(np.sqrt(np.mean(values**2))),
            max=float(values.max()),
            unit=unit,
        )

    def as_dict(self) -> dict[str, float]:
        return {f"mean_{self.unit}": self.mean, f"rms_{self.unit}": self.rms, f"max_{self.unit}": self.max}


@dataclass(frozen=True)
class PoseErrors:
    """Per-row errors of eq 24.

    Attributes:
        position_m: q_jp [m], (J, P): one column per target point.
        rotation_rad: eta_j [rad], (J,), or None without orientation data (the held-out test of several
            targets: (J, T), one per target, NaN where not seen).
    """

    position_m: np.ndarray
    rotation_rad: np.ndarray | None

    @property
    def n_rows(self) -> int:
        return int(self.position_m.shape[0])

    @property
    def position(self) -> ErrorSummary:
        """Over all rows and points [mm]."""
        return ErrorSummary.of(self.position_m * 1000.0, "mm")

    def point(self, index: int) -> ErrorSummary:
        """Over all rows, for target point ``index`` (0-based) [mm]."""
        return ErrorSummary.of(self.position_m[:, index] * 1000.0, "mm")

    @property
    def rotation(self) -> ErrorSummary | None:
        if self.rotation_rad is None:
            return None
        return ErrorSummary.of(np.degrees(self.rotation_rad), "deg")

    def as_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"rows": self.n_rows, "position": self.position.as_dict()}
        if self.position_m.shape[1] > 1:
            out["position_per_point"] = [self.point(p).as_dict() for p in range(self.position_m.shape[1])]
        if self.rotation is not None:
            out["orientation"] = self.rotation.as_dict()
        return out


@dataclass(frozen=True)
class RowCorrections:
    """What a report's effects change in the model of each row (:mod:`pincal.model.effects`): a value.

    Attributes:
        q: joint values to use instead of the readings (the readings corrected by effects), (K, N).
        sensor_scale / drift: sensor effects: the model point is (1 + s)(Omega x + tau + drift_k),
            ``drift`` the offset of each row [m], (K, 3).
        conditions: each row's thermal expansion and pause step (eq T1–T2 of :mod:`pincal.model.thermal`).
        bends: the joints' lateral deflections (K, 2N) [rad] (eq L1 of :mod:`pincal.model.lateral`), or None.
    """

    q: np.ndarray | None = None
    sensor_scale: float = 0.0
    drift: np.ndarray | None = None
    conditions: RowConditions | None = None
    bends: np.ndarray | None = None

    def select(self, rows: np.ndarray) -> RowCorrections:
        """The corrections of the rows ``rows`` (indices) alone."""
        return RowCorrections(None if self.q is None else np.asarray(self.q)[rows], self.sensor_scale,
                              None if self.drift is None else np.asarray(self.drift)[rows],
                              None if self.conditions is None else self.conditions.select(rows),
                              None if self.bends is None else np.asarray(self.bends)[rows])

    def tool_poses(self, chain: KinematicChain, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``chain.tool_poses`` (rotations, positions) at these corrections' joint values (``q`` without), its joints
        deflected by ``bends`` if any."""
        q = q if self.q is None else np.asarray(self.q, dtype=float)
        if self.bends is None:
            return chain.tool_poses(q)
        poses = bent_tool_poses(chain, q, self.bends)
        return poses.tool_rotations, poses.tool_positions


def pose_errors(
    chain: KinematicChain,
    data: MeasurementSet,
    registration_position: Registration,
    registration_orientation: Registration,
    points: npt.ArrayLike | None = None,
    target_rotation: npt.ArrayLike | None = None,
    corrections: RowCorrections = RowCorrections(),
    tool_poses: tuple[np.ndarray, np.ndarray] | None = None,
) -> PoseErrors:
    """Eq 24 on every row of ``data``.

    Args:
        chain: the calibrated chain; its tool frame carries the target.
        data: measured rows.
        registration_position / registration_orientation: Registrations 1 and 2.
        points: target points in the tool frame [m], (P, 3); default: the tool origin.
        target_rotation: R_T, the target's rotation in the tool frame (default identity).
        corrections: the rows' joint values and sensor terms as a report's effects correct them
            (default: none).
        tool_poses: ``chain.tool_poses`` of the rows' joint values when the caller has
            them (errors of one chain through several registrations share them); ``corrections.q``
            is then not used.
    """
    drift, conditions = corrections.drift, corrections.conditions
    if tool_poses is None:
        tool_poses = corrections.tool_poses(chain, data.q)
    tool_rotations, tool_positions = tool_poses
    points = np.zeros((1, 3)) if points is None else np.atleast_2d(np.asarray(points, dtype=float))
    world = points_in_base(tool_positions, tool_rotations, points)
    if conditions is not None:
        world, drift = conditions.world(world), conditions.offsets(drift)
    predicted = sensed_points(registration_position, world, corrections.sensor_scale, drift)
    position = np.linalg.norm(predicted - data.points, axis=2)
    rotation = None
    if data.rotations is not None:
        target = np.eye(3) if target_rotation is None else np.asarray(target_rotation, dtype=float)
        model = registration_orientation.apply_rotations(tool_rotations @ target)
        relative = data.rotations.transpose(0, 2, 1) @ model  # G_j^-1 Omega R_j R_T
        # |log3|: np.linalg.norm's arithmetic (the square root of the dot product) without its overhead
        rotation = np.array([math.sqrt(v.dot(v)) for v in map(pin.log3, relative)])
    return PoseErrors(position_m=position, rotation_rad=rotation)
