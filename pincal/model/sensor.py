"""The sensor's pose relative to the robot base: sensor_T_base, g = Ω t + τ [m] (Franaszek & Marvel 2022, eq 19–21)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import pinocchio as pin
from scipy.spatial.transform import Rotation

from pincal.errors import CalibrationError

__all__ = ["ROTATION_TOLERANCE", "checked_array", "checked_rotations", "Registration"]

ROTATION_TOLERANCE = 1e-6  # max |R^T R - I| accepted for a rotation matrix


def checked_array(x: npt.ArrayLike | None, shape_tail: tuple[int, ...], name: str, min_count: int = 0) -> np.ndarray:
    a = np.asarray(x, dtype=float)
    if a.ndim != 1 + len(shape_tail) or a.shape[1:] != shape_tail:
        raise CalibrationError(f"{name} must have shape (K, {', '.join(map(str, shape_tail))}), got {a.shape}")
    if len(a) < min_count:
        raise CalibrationError(f"{name}: need at least {min_count}, got {len(a)}")
    if not np.all(np.isfinite(a)):
        raise CalibrationError(f"{name} contains NaN or infinite values")
    return a


def checked_rotations(x: npt.ArrayLike | None, name: str, min_count: int = 1) -> np.ndarray:
    r = checked_array(x, (3, 3), name, min_count)
    if np.abs(r.transpose(0, 2, 1) @ r - np.eye(3)).max() > ROTATION_TOLERANCE or np.any(np.linalg.det(r) < 0):
        raise CalibrationError(f"{name} contains a matrix that is not a proper rotation")
    return r


@dataclass(frozen=True)
class Registration:
    """sensor_T_base: maps URDF-root (robot base) coordinates to sensor coordinates, g ≈ rotation @ t + translation."""

    rotation: np.ndarray  # (3,3) proper rotation Ω
    translation: np.ndarray  # (3,) τ [m]

    def __post_init__(self) -> None:
        rot = checked_rotations(np.reshape(self.rotation, (1, 3, 3)), "rotation")[0].copy()
        tr = checked_array(np.reshape(self.translation, (1, 3)), (3,), "translation")[0].copy()
        rot.flags.writeable = tr.flags.writeable = False
        object.__setattr__(self, "rotation", rot)
        object.__setattr__(self, "translation", tr)

    def turned(self, step: np.ndarray, translation: np.ndarray) -> Registration:
        """This registration's rotation turned by ``step`` φ [rad] (3,), Ω exp(φ), with ``translation`` τ [m] (3,):
        a fit's registration at its parameter vector (eq 20). Ω is a proper rotation and so is exp(φ), so only the
        shapes and finiteness are checked here, not :meth:`__post_init__`'s orthogonality and determinant: a fit
        builds one per residual evaluation. Anything else (a non-finite value, another shape) takes the checking
        constructor, and its error."""
        rotation, translation = self.rotation @ pin.exp3(step), np.array(translation, dtype=float)
        if translation.shape != (3,) or not (np.isfinite(rotation).all() and np.isfinite(translation).all()):
            return Registration(rotation, translation)
        rotation.flags.writeable = translation.flags.writeable = False
        registration = object.__new__(Registration)
        object.__setattr__(registration, "rotation", rotation)
        object.__setattr__(registration, "translation", translation)
        return registration

    def apply_points(self, points: npt.ArrayLike) -> np.ndarray:
        """Map robot-base points (..., 3) [m] to sensor coordinates: Ω t + τ."""
        return np.asarray(points, dtype=float) @ self.rotation.T + self.translation

    def apply_rotations(self, rotations: npt.ArrayLike) -> np.ndarray:
        """Map robot-base orientations (..., 3, 3) to sensor orientations: Ω R."""
        return self.rotation @ np.asarray(rotations, dtype=float)

    def as_dict(self) -> dict[str, list[float]]:
        """JSON-ready form: ``{"rotation_xyzw": [x, y, z, w], "translation_m": [x, y, z]}``."""
        quat = Rotation.from_matrix(self.rotation).as_quat()  # scalar-last
        return {"rotation_xyzw": [float(v) for v in quat], "translation_m": [float(v) for v in self.translation]}

    @classmethod
    def from_dict(cls, d: Any) -> Registration:
        """Inverse of :meth:`as_dict`."""
        try:
            quat = np.asarray(d["rotation_xyzw"], dtype=float)
            translation = np.asarray(d["translation_m"], dtype=float)
        except (KeyError, TypeError, ValueError) as exc:
            raise CalibrationError(f"registration needs numeric 'rotation_xyzw' and 'translation_m': {exc}") from None
        if quat.shape != (4,) or not np.all(np.isfinite(quat)) or np.linalg.norm(quat) < 1e-9:
            raise CalibrationError(f"rotation_xyzw must be 4 finite numbers, not all zero, got {quat.tolist()}")
        return cls(Rotation.from_quat(quat).as_matrix(), translation)
