"""Accuracy of a calibrated model on measured rows (eq 24).

For each row j: the position error q_j = ‖Omega_1 t_j + tau_1 − g_j‖ through
Registration 1 and the orientation error eta_j, the angle of
G_j⁻¹ Omega_2 R_j, through Registration 2 (Franaszek & Marvel 2022, eq 24).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from .chain import KinematicChain
from .measurements import MeasurementSet
from .registration import Registration


@dataclass(frozen=True)
class ErrorSummary:
    """Mean, RMS and maximum of per-row errors, in reporting units (mm or deg)."""

    mean: float
    rms: float
    max: float
    unit: str

    @classmethod
    def of(cls, values: np.ndarray, unit: str) -> "ErrorSummary":
        values = np.asarray(values, dtype=float)
        return cls(
            mean=float(values.mean()),
            rms=float(np.sqrt(np.mean(values**2))),
            max=float(values.max()),
            unit=unit,
        )

    def as_dict(self) -> dict:
        return {f"mean_{self.unit}": self.mean, f"rms_{self.unit}": self.rms, f"max_{self.unit}": self.max}


@dataclass(frozen=True)
class PoseErrors:
    """Per-row errors of eq 24.

    Attributes:
        position_m: q_j [m], (J,).
        rotation_rad: eta_j [rad], (J,), or None without orientation data.
    """

    position_m: np.ndarray
    rotation_rad: np.ndarray | None

    @property
    def position(self) -> ErrorSummary:
        return ErrorSummary.of(self.position_m * 1000.0, "mm")

    @property
    def rotation(self) -> ErrorSummary | None:
        if self.rotation_rad is None:
            return None
        return ErrorSummary.of(np.degrees(self.rotation_rad), "deg")

    def as_dict(self) -> dict:
        out = {"rows": int(self.position_m.size), "position": self.position.as_dict()}
        if self.rotation is not None:
            out["orientation"] = self.rotation.as_dict()
        return out


def pose_errors(
    chain: KinematicChain,
    data: MeasurementSet,
    registration_position: Registration,
    registration_orientation: Registration,
) -> PoseErrors:
    """Eq 24 on every row of ``data`` (first target point; the chain's tool is the TCP)."""
    poses = chain.poses(data.q)
    predicted = registration_position.apply_points(poses.tool_positions)
    position = np.linalg.norm(predicted - data.points[:, 0, :], axis=1)
    rotation = None
    if data.rotations is not None:
        model = registration_orientation.apply_rotations(poses.tool_rotations)
        relative = data.rotations.transpose(0, 2, 1) @ model  # G_j^-1 Omega R_j
        rotation = np.array([np.linalg.norm(pin.log3(r)) for r in relative])
    return PoseErrors(position_m=position, rotation_rad=rotation)
