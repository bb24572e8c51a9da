"""Err_rot: relative rotations between pairs of measured and model orientations.

Eq 14–17 of Franaszek & Marvel (2022): for pairs (k, k' = k + K/2),

    D_k = G_k R_k^-1 R_k' G_k'^-1,    r_k = log(D_k)  (Pinocchio's SO(3) log, :mod:`pincal.residuals.so3`)

so that ||r_k|| = psi_k, the angle of D_k (eq 15), and the sum of squares is
sum psi_k^2. Independent of the registration rotation and of every length
parameter. Residuals in radians.

Jacobian: a world-frame perturbation dw_k of R_k gives
d log(D_k) = Jlog3(D_k) G_k' R_k'^T (dw_k' - dw_k).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from pincal.residuals.base import KinematicsCache, Objective, pair_indices
from pincal.residuals.so3 import jlog3, log3

__all__ = ["RotationResidual"]


class RotationResidual(Objective):
    """Eq 14–17 on the calibration rows.

    Args:
        cache: kinematics of the K calibration rows (K, N joint readings).
        sensor_rotations: measured target orientations G_k in the sensor frame (K, 3, 3).
    """

    def __init__(
        self,
        cache: KinematicsCache,
        sensor_rotations: npt.ArrayLike,
    ) -> None:
        super().__init__(cache)
        self.first, self.second = pair_indices(len(cache.q))
        self.measured = np.asarray(sensor_rotations, dtype=float)

    def _relative(self, x: npt.ArrayLike) -> np.ndarray:
        poses, _ = self.cache.evaluate(x)
        g1, g2 = self.measured[self.first], self.measured[self.second]
        r1, r2 = poses.tool_rotations[self.first], poses.tool_rotations[self.second]
        # D_k = G_k R_k^T R_k' G_k'^T (eq 14)
        return g1 @ r1.transpose(0, 2, 1) @ r2 @ g2.transpose(0, 2, 1)

    def residual(self, x: npt.ArrayLike) -> np.ndarray:
        return log3(self._relative(x)).reshape(-1)

    def jacobian(self, x: npt.ArrayLike) -> np.ndarray:
        relative = self._relative(x)
        poses, sens = self.cache.evaluate(x)
        g2 = self.measured[self.second]
        r2 = poses.tool_rotations[self.second]
        left = jlog3(relative) @ g2 @ r2.transpose(0, 2, 1)
        delta = sens.angular[self.second] - sens.angular[self.first]  # (P, n_free, 3)
        jac = np.einsum("pij,pnj->pin", left, delta)
        return jac.reshape(-1, self.n_free)
