"""Err_pos: distances between pairs of TCP positions against measured distances.

Eq 10–11 of Franaszek & Marvel (2022): for pairs (k, k' = k + K/2),

    r_k = L_k - h_k,   L_k = ||t_k - t_k'||,   h_k = ||g_k - g_k'||

with t the model TCP in the robot base frame and g the measured point in the
sensor frame. Independent of the registration; insensitive to d_1 and eps_1.
Residuals in metres.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from pincal.residuals.base import KinematicsCache, Objective, pair_indices

__all__ = ["DistanceResidual"]


class DistanceResidual(Objective):
    """Eq 10–11 on the calibration rows.

    Args:
        cache: kinematics of the K calibration rows (K, N joint readings).
        sensor_points: measured TCP positions in the sensor frame (K, 3) [m].
    """

    def __init__(
        self,
        cache: KinematicsCache,
        sensor_points: npt.ArrayLike,
    ) -> None:
        super().__init__(cache)
        self.first, self.second = pair_indices(len(cache.q))
        g = np.asarray(sensor_points, dtype=float)
        self.measured = np.linalg.norm(g[self.first] - g[self.second], axis=1)  # h_k

    def _differences(self, x: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        poses, _ = self.cache.evaluate(x)
        diff = poses.tool_positions[self.first] - poses.tool_positions[self.second]
        return diff, np.linalg.norm(diff, axis=1)

    def residual(self, x: npt.ArrayLike) -> np.ndarray:
        _, length = self._differences(x)
        return length - self.measured

    def jacobian(self, x: npt.ArrayLike) -> np.ndarray:
        diff, length = self._differences(x)
        _, sens = self.cache.evaluate(x)
        velocity = sens.linear  # (K, n_free, 3): the TCP is the tool frame origin
        unit = diff / length[:, None]
        return np.einsum(
            "ki,kni->kn", unit, velocity[self.first] - velocity[self.second]
        )
