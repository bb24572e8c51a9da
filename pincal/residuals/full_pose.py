"""Err_full: distances and relative rotations in one cost (Method 3).

Eq 18 of Franaszek & Marvel (2022): Err_full = Err_pos + w Err_rot. The
residual stacks the distance residuals in millimetres and the rotation
residuals in degrees times sqrt(w), so ``w`` is in mm²/deg²: w = 1 weighs a
1 mm distance error like a 1° rotation error. The paper shows the result
depends on w — the scaling problem pincal's Method 2 avoids.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from pincal.errors import CalibrationError
from pincal.residuals.base import KinematicsCache, Objective
from pincal.residuals.distance import DistanceResidual
from pincal.residuals.rotation import RotationResidual

__all__ = ["MM_PER_M", "DEG_PER_RAD", "FullPoseResidual"]

MM_PER_M = 1000.0
DEG_PER_RAD = 180.0 / np.pi


class FullPoseResidual(Objective):
    """Eq 18 on the calibration rows; ``weight`` = w [mm²/deg²]."""

    def __init__(
        self,
        cache: KinematicsCache,
        sensor_points: npt.ArrayLike,
        sensor_rotations: npt.ArrayLike,
        weight: float = 1.0,
    ) -> None:
        if not weight > 0:
            raise CalibrationError(f"Method 3 weight w must be positive, got {weight}")
        super().__init__(cache)
        self.position = DistanceResidual(cache, sensor_points)
        self.rotation = RotationResidual(cache, sensor_rotations)
        self._rot_scale = np.sqrt(weight) * DEG_PER_RAD

    def residual(self, x: npt.ArrayLike) -> np.ndarray:
        return np.concatenate(
            [MM_PER_M * self.position.residual(x), self._rot_scale * self.rotation.residual(x)]
        )

    def jacobian(self, x: npt.ArrayLike) -> np.ndarray:
        return np.vstack(
            [MM_PER_M * self.position.jacobian(x), self._rot_scale * self.rotation.jacobian(x)]
        )
