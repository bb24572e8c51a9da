"""Where a camera sees a board's corners: the chain, the camera's mount and the board, composed (eqs C1, C2).

Two arrangements, by what the chain carries (its tip link, a link attached by a fixed joint):

* **eye to hand** -- the board on the chain (the mount M = ``tip_T_board``), the camera fixed in the world
  (W = ``camera_T_base``): a corner b of the board [m] is at
  ``y = t_k + R_k (R_M b + t_M)`` in the base frame and at ``p = R_W y + t_W`` in the camera's (C1);
* **eye in hand** -- the camera on the chain (M = ``tip_T_camera``), the board fixed in the world
  (W = ``base_T_board``): ``y = R_W b + t_W`` and ``p = R_Mᵀ (R_kᵀ (y − t_k) − t_M)`` (C2);

with (t_k, R_k) the tip link's pose in the base frame at configuration k and p in the camera's optical frame
(x right, y down, z ahead: OpenCV's and ROS's ``*_optical_frame``), which :func:`pincal.model.pinhole.project`
turns into pixels. W is the part a registration plays for a point sensor; M is calibrated with the kinematics.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

__all__ = ["Arrangement", "ARRANGEMENTS", "pose", "camera_points"]

#: Where the camera is: on the chain (``eye_in_hand``, the board fixed) or fixed (``eye_to_hand``, the board on it).
Arrangement = Literal["eye_in_hand", "eye_to_hand"]
ARRANGEMENTS: tuple[Arrangement, ...] = ("eye_in_hand", "eye_to_hand")


def pose(rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
    """The homogeneous transform (4, 4) of ``rotation`` (3, 3) and ``translation`` (3,) [m]."""
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = rotation, translation
    return out


def camera_points(arrangement: Arrangement, tips: tuple[np.ndarray, np.ndarray], worlds: np.ndarray,
                  mount: np.ndarray, board: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eq C1 or C2 for M corners at once.

    Args:
        arrangement: ``eye_to_hand`` (C1) or ``eye_in_hand`` (C2).
        tips: each corner's tip rotation R_k (M, 3, 3) and position t_k (M, 3) [m].
        worlds: each corner's world frame W (M, 4, 4) [m] (its image's session's).
        mount: M (4, 4) [m].
        board: the corners on the board (M, 3) [m].

    Returns:
        y, each corner in the base frame (M, 3) [m], and p, in the camera's optical frame (M, 3) [m].
    """
    rotations, positions = tips
    w_rot, w_pos = worlds[:, :3, :3], worlds[:, :3, 3]
    m_rot, m_pos = mount[:3, :3], mount[:3, 3]
    if arrangement == "eye_to_hand":  # eq C1
        y = positions + np.einsum("mij,mj->mi", rotations, board @ m_rot.T + m_pos)
        return y, np.einsum("mij,mj->mi", w_rot, y) + w_pos
    y = np.einsum("mij,mj->mi", w_rot, board) + w_pos  # eq C2
    return y, (np.einsum("mji,mj->mi", rotations, y - positions) - m_pos) @ m_rot
