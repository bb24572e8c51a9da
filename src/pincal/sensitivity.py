"""First-order effect of model parameters on the tool pose, from Pinocchio's kinematics.

Every kinematic parameter pincal identifies moves the chain by a twist applied
in one joint frame: a DH link offset d_n is a translation along that frame's z
axis, a zero offset a rotation about the joint axis, and so on. Given the joint
frames computed by Pinocchio (:class:`pincal.chain.ChainPoses`) and, per
parameter, the frame index and the local twist ``xi = (v, w)``, the world twist
is the adjoint ``Ad(base_T_frame) xi`` (Murray, Li & Sastry 1994, eq 2.58):

    w_world = R w,        v_world = R v + p x (R w)

and a point x attached downstream moves with ``v_world + w_world x x``. The
columns for zero offsets are exactly Pinocchio's joint Jacobian columns
(``pin.computeJointJacobians``); the tests check every column against finite
differences of Pinocchio forward kinematics.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from .chain import ChainPoses


@dataclass(frozen=True)
class Sensitivity:
    """World twists of the tool caused by unit parameter changes.

    Attributes:
        angular: world angular velocity per parameter [rad/unit], (K, n_par, 3).
        linear: world linear velocity of the point at the world origin [m/unit], (K, n_par, 3).
    """

    angular: np.ndarray
    linear: np.ndarray

    def point_velocity(self, points: npt.ArrayLike) -> np.ndarray:
        """d(point)/d(parameter) for world points (K, 3) → (K, n_par, 3)."""
        points = np.asarray(points, dtype=float)
        return self.linear + np.cross(self.angular, points[:, None, :])


def sensitivity(
    poses: ChainPoses, frame_index: npt.ArrayLike, local_twists: npt.ArrayLike
) -> Sensitivity:
    """Transport local parameter twists to world twists at K configurations.

    Args:
        poses: joint frames of K configurations (after each joint's motion).
        frame_index: for each parameter, the chain joint whose frame carries its
            twist, shape (n_par,).
        local_twists: twist per parameter in that frame, ``(v, w)`` with v in
            [m/unit] and w in [rad/unit], shape (n_par, 6).
    """
    index = np.asarray(frame_index, dtype=int)
    twists = np.asarray(local_twists, dtype=float)
    rot = poses.joint_rotations[:, index]  # (K, n_par, 3, 3)
    pos = poses.joint_positions[:, index]  # (K, n_par, 3)
    angular = np.einsum("knij,nj->kni", rot, twists[:, 3:])
    linear = np.einsum("knij,nj->kni", rot, twists[:, :3]) + np.cross(pos, angular)
    return Sensitivity(angular=angular, linear=linear)
