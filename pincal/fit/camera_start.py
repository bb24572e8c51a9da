"""A camera calibration's start from nothing: each image's board pose, then the mount and the world frame
by OpenCV's closed-form hand-eye calibration on the chain as it is (the nominal kinematics).

1. Each image's ``camera_T_board`` from its corners and the intrinsics: ``cv2.solvePnP`` (planar IPPE
   for the first guess, refined by Levenberg-Marquardt: OpenCV's ``SOLVEPNP_IPPE`` then ``solvePnPRefineLM``).
   An image whose corners lie on one line (one row of the board: a plane's pose is not determined by a line)
   gets no pose and is left out of steps 2 and 3; its corners still count in the fit that follows.
2. With the tip poses ``base_T_tip`` of the chain, the closed form: ``cv2.calibrateHandEye`` (AX = XB; methods
   TSAI, PARK, HORAUD, ANDREFF, DANIILIDIS) or ``cv2.calibrateRobotWorldHandEye`` (AX = ZB; SHAH, LI). Eye in
   hand is the form OpenCV documents; eye to hand is the same with the robot's poses inverted (the board on
   the gripper plays the camera, the camera the board).
3. Whatever the method leaves, the other of the mount M and the world frame W of each session
   (:mod:`pincal.model.camera_view`): the chordal mean of its per-image values (rotations projected back
   onto SO(3), Moakher 2002; translations averaged).

OpenCV is imported here only (opencv-python-headless, pinned below 5: OpenCV 5.0's Python bindings lack
``calibrateHandEye``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from pincal.errors import CalibrationError
from pincal.measurements.camera_csv import CornerSet
from pincal.model.camera_view import Arrangement, pose
from pincal.model.chain import KinematicChain
from pincal.model.pinhole import CameraIntrinsics
from pincal.residuals.camera import CameraEstimate

__all__ = ["HAND_EYE_METHODS", "ROBOT_WORLD_METHODS", "board_poses", "hand_eye_start"]

#: cv2.calibrateHandEye's methods (``cv2.CALIB_HAND_EYE_<NAME>``).
HAND_EYE_METHODS = ("TSAI", "PARK", "HORAUD", "ANDREFF", "DANIILIDIS")
#: cv2.calibrateRobotWorldHandEye's methods (``cv2.CALIB_ROBOT_WORLD_HAND_EYE_<NAME>``).
ROBOT_WORLD_METHODS = ("SHAH", "LI")

#: Corners a board pose needs: solvePnP's minimum for a planar target.
MIN_CORNERS = 4
#: Corners on one line: the second singular value of their spread below this fraction of the first (a row of a
#: board lies on a line to the rounding of its positions, ~1e-16 relative; any two rows span the square's side).
_COLLINEAR = 1e-9


def _cv2() -> Any:
    try:
        import cv2
    except ImportError:  # pragma: no cover - a dependency of pincal
        raise CalibrationError("a camera calibration needs OpenCV: pip install 'opencv-python-headless>=4.10,<5'"
                               ) from None
    return cv2


def board_poses(corners: CornerSet, intrinsics: CameraIntrinsics) -> np.ndarray:
    """Each image's ``camera_T_board`` (K, 4, 4) [m] from its corners (step 1 of the module docstring).

    Returns:
        The poses; NaN for an image whose corners lie on one line (step 1).

    Raises:
        CalibrationError: an image with fewer than :data:`MIN_CORNERS` corners, or one solvePnP cannot place.
    """
    cv2 = _cv2()
    out = np.empty((len(corners.images), 4, 4))
    matrix, distortion = intrinsics.matrix, np.asarray(intrinsics.distortion, dtype=float)
    for k, name in enumerate(corners.images):
        mine = corners.image_of == k
        if mine.sum() < MIN_CORNERS:
            raise CalibrationError(f"{corners.source}: image '{name}' shows {int(mine.sum())} corner(s); a board pose "
                                   f"needs {MIN_CORNERS}: delete its rows or take the image again")
        board = np.ascontiguousarray(corners.board_points[mine], dtype=float)
        pixels = np.ascontiguousarray(corners.pixels[mine], dtype=float)
        spread = np.linalg.svd(board - board.mean(axis=0), compute_uv=False)
        if spread[1] <= _COLLINEAR * spread[0]:  # one row of corners: no plane to place
            out[k] = np.nan
            continue
        found, rvec, tvec = cv2.solvePnP(board, pixels, matrix, distortion, flags=cv2.SOLVEPNP_IPPE)
        if not found:
            raise CalibrationError(f"{corners.source}: image '{name}': OpenCV's solvePnP cannot place the board; "
                                   "check the intrinsics or delete the image's rows")
        rvec, tvec = cv2.solvePnPRefineLM(board, pixels, matrix, distortion, rvec, tvec)
        out[k] = pose(cv2.Rodrigues(rvec)[0], np.ravel(tvec))
    return out


def _mean(transforms: np.ndarray) -> np.ndarray:
    """The chordal mean of (n, 4, 4) transforms (step 3)."""
    return pose(Rotation.from_matrix(transforms[:, :3, :3]).mean().as_matrix(), transforms[:, :3, 3].mean(axis=0))


def _split(transforms: np.ndarray) -> tuple[list[np.ndarray], list[np.ndarray]]:
    return list(transforms[:, :3, :3]), list(transforms[:, :3, 3:4])


def _closed_form(arrangement: Arrangement, tips: np.ndarray, views: np.ndarray, method: str
                 ) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Step 2: M and/or W (None for the one the method does not give), from ``tips`` = base_T_tip and
    ``views`` = camera_T_board (n, 4, 4) of one session's images."""
    cv2 = _cv2()
    inverse_tips = np.linalg.inv(tips)
    if method in HAND_EYE_METHODS:
        flag = getattr(cv2, f"CALIB_HAND_EYE_{method}")
        gripper = tips if arrangement == "eye_in_hand" else inverse_tips  # eye to hand: the poses inverted
        rotation, translation = cv2.calibrateHandEye(*_split(gripper), *_split(views), method=flag)
        found = pose(rotation, np.ravel(translation))  # eye in hand: tip_T_camera; eye to hand: base_T_camera
        return (found, None) if arrangement == "eye_in_hand" else (None, np.linalg.inv(found))
    if method not in ROBOT_WORLD_METHODS:
        raise CalibrationError(f"hand-eye method must be one of {HAND_EYE_METHODS + ROBOT_WORLD_METHODS}, "
                               f"got '{method}'")
    flag = getattr(cv2, f"CALIB_ROBOT_WORLD_HAND_EYE_{method}")
    # OpenCV's cTw = cTg gTb bTw: eye in hand, c the camera and w the board; eye to hand, c the board, w the camera
    seen = views if arrangement == "eye_in_hand" else np.linalg.inv(views)
    r_bw, t_bw, r_gc, t_gc = cv2.calibrateRobotWorldHandEye(*_split(seen), *_split(inverse_tips), method=flag)
    world_T_base, camera_T_gripper = pose(r_bw, np.ravel(t_bw)), pose(r_gc, np.ravel(t_gc))
    mount = np.linalg.inv(camera_T_gripper)
    return (mount, np.linalg.inv(world_T_base)) if arrangement == "eye_in_hand" else (mount, world_T_base)


def hand_eye_start(chain: KinematicChain, corners: CornerSet, arrangement: Arrangement,
                   intrinsics: CameraIntrinsics, method: str = "TSAI") -> tuple[CameraEstimate, tuple[str, ...]]:
    """The mount and each session's world frame from the chain as it is (its tip: the link carrying the
    camera or the board; its tool: the identity) and OpenCV's closed form ``method`` on the largest
    session's images (steps 1-3 of the module docstring).

    Returns:
        The estimate (the intrinsics given) and the session names, in the order of its world frames.

    Raises:
        CalibrationError: fewer than 3 images in the largest session (a hand-eye calibration needs two
            motions), an image that cannot be placed, an unknown method.
    """
    names, session_index = np.unique(corners.sessions.astype(str), return_inverse=True)
    views = board_poses(corners, intrinsics)
    placed = np.all(np.isfinite(views), axis=(1, 2))  # not an image of one row of corners
    counts = np.bincount(session_index[placed], minlength=len(names))
    largest = np.flatnonzero((session_index == np.argmax(counts)) & placed)
    if len(largest) < 3 or np.any(counts == 0):
        raise CalibrationError(f"{corners.source}: {len(largest)} image(s) with the board placed in the largest "
                               "session (an image of one row of corners places none); the hand-eye start needs at "
                               "least 3 (two motions), and a board placed in every session")
    rotations, positions = chain.tool_poses(corners.q)
    tips = np.array([pose(r, t) for r, t in zip(rotations, positions)])
    mount, world = _closed_form(arrangement, tips[largest], views[largest], method)
    if mount is None:  # eye to hand with AX = XB: M of each image from W, averaged
        assert world is not None  # the closed form gives one of them at least
        mount = _mean(np.linalg.inv(tips[largest]) @ np.linalg.inv(world) @ views[largest])
    tips, views, session_index = tips[placed], views[placed], session_index[placed]
    if arrangement == "eye_in_hand":
        per_image = tips @ mount @ views  # base_T_board of each image
    else:
        per_image = views @ np.linalg.inv(tips @ mount)  # camera_T_base of each image
    worlds = np.array([_mean(per_image[session_index == s]) for s in range(len(names))])
    return CameraEstimate(arrangement, worlds, mount, intrinsics), tuple(str(n) for n in names)
