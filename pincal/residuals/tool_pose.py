"""The paper's pose residual: the chain's tool measured in 6D, the registration unknown (eq 20–22)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from pincal.errors import CalibrationError
from pincal.model.sensor import Registration
from pincal.residuals.base import KinematicsCache
from pincal.residuals.sensor import SensorResidual, TargetEstimate
from pincal.residuals.sensor_values import FittedBlocks, RowWeights

__all__ = ["tool_pose_residual"]


def tool_pose_residual(
    cache: KinematicsCache,
    sensor_points: npt.ArrayLike,
    sensor_rotations: npt.ArrayLike,
    registration: Registration,
    sigma_position_m: float = 1.0,
    sigma_rotation_rad: float = 1.0,
) -> SensorResidual:
    """Noise-scaled pose residual of the chain's tool with the registration unknown.

    The measured frame is the chain's tool (the TCP: one zero target point,
    R_T = I, neither fitted), so row k's residual is

        [ (Omega t_k + tau − g_k) / sigma_p ,  log(G_kᵀ Omega R_k) / sigma_a ]

    with unknowns x = [the cache's free parameters, phi (3), tau (3)] and
    Omega = Omega_0 exp(phi). With the sensor's noise as sigma_p, sigma_a the
    least-squares solution is the maximum-likelihood estimate (eq 20–22);
    ``start_vector()`` is the cache's base with Omega_0 and tau of ``registration``.

    Args:
        cache: kinematics of the K measured rows.
        sensor_points: measured tool positions g_k [m], (K, 3) or (K, 1, 3).
        sensor_rotations: measured tool orientations G_k, (K, 3, 3).
        registration: sensor_T_base to start from (phi = 0).
        sigma_position_m: sigma_p, the position noise per axis [m].
        sigma_rotation_rad: sigma_a, the orientation noise per component [rad].

    Raises:
        CalibrationError: mismatched shapes or a non-positive sigma.
    """
    k = len(cache.q)
    points = np.asarray(sensor_points, dtype=float)
    rotations = np.asarray(sensor_rotations, dtype=float)
    if points.shape not in ((k, 3), (k, 1, 3)) or rotations.shape != (k, 3, 3):
        raise CalibrationError(
            f"tool pose residual: expected points ({k}, 3) and rotations ({k}, 3, 3), "
            f"got {points.shape} and {rotations.shape}"
        )
    if not (sigma_position_m > 0 and sigma_rotation_rad > 0):
        raise CalibrationError(
            f"noise scales must be positive, got sigma_p={sigma_position_m} m, "
            f"sigma_a={sigma_rotation_rad} rad"
        )
    start = TargetEstimate(registration, np.zeros((1, 3)), np.eye(3))
    return SensorResidual(
        cache,
        points.reshape(k, 1, 3),
        rotations,
        start,
        RowWeights(1.0 / sigma_position_m, 1.0 / sigma_rotation_rad),
        FittedBlocks(points=False, rotation=False),
    )
