"""Where a camera sees a ChArUco board well enough to calibrate from: the view of each configuration
judged, and configurations drawn that aim the camera at the board.

A configuration's image is usable (:func:`board_views`, :meth:`ViewLimits.usable`) when

* the whole board is in front of the camera and inside the image: its four outer corners and every inner
  corner project within the image (a ChArUco corner is interpolated from the markers beside it, so a
  board cut by the image's edge loses the corners next to the cut);
* its printed face is turned to the camera, its normal within
  :data:`pincal.simulation.camera_scene.MAX_VIEW_ANGLE_DEG` of the optical axis;
* neighbouring corners are at least :meth:`ViewLimits.min_spacing_px` apart, the size below which OpenCV's
  ArUco detector drops the markers.

:func:`aimed_configurations` draws board poses in the camera's frame inside those limits (the board's
centre near the optical axis, its distance between the one that fits the board in the image and the one of
the spacing floor, tilted up to the angle limit about a random axis, rolled at random), turns each into the
pose of the chain's tip link (eye in hand: the camera's; eye to hand: the board's) through the world frame W
and the mount M (:mod:`pincal.model.camera_view`) and solves the inverse kinematics from the given seeds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from pincal.errors import PincalError
from pincal.measurements.charuco import CharucoSpec
from pincal.model.camera_view import camera_points, pose
from pincal.model.chain import KinematicChain
from pincal.planning.candidates import LIMIT_SLACK
from pincal.residuals.camera import CameraEstimate
from pincal.simulation.camera_scene import MAX_VIEW_ANGLE_DEG, board_corners
from pincal.simulation.cells import inverse_kinematics
from pincal.simulation.sensor import sampling_limits

__all__ = ["MAX_VIEW_ANGLE_DEG", "MIN_MARKER_PERIMETER_RATE", "ViewLimits", "BoardViews", "board_views",
           "aimed_configurations"]

#: OpenCV's ArUco detector keeps a marker whose perimeter is at least this fraction of the image's larger side
#: (``cv::aruco::DetectorParameters::minMarkerPerimeterRate``, default 0.03): smaller markers are not found,
#: and neither are the ChArUco corners beside them.
MIN_MARKER_PERIMETER_RATE = 0.03


@dataclass(frozen=True)
class ViewLimits:
    """What makes an image of the board usable (the module docstring).

    Attributes:
        max_angle_deg: the largest angle between the board's normal and the optical axis [deg].
        min_marker_perimeter_rate: a marker's smallest perimeter as a fraction of the image's larger side.
    """

    max_angle_deg: float = MAX_VIEW_ANGLE_DEG
    min_marker_perimeter_rate: float = MIN_MARKER_PERIMETER_RATE

    def __post_init__(self) -> None:
        if not 0.0 < self.max_angle_deg < 90.0:
            raise PincalError(f"the largest view angle must be between 0 and 90 degrees, got {self.max_angle_deg}")
        if not self.min_marker_perimeter_rate > 0.0:
            raise PincalError(f"the marker perimeter rate must be positive, got {self.min_marker_perimeter_rate}")

    def min_spacing_px(self, board: CharucoSpec, width: int, height: int) -> float:
        """The smallest distance between neighbouring corners [px]: a square whose marker (``marker/square`` of
        it) has the detector's smallest perimeter, ``rate · max(width, height) / 4`` per side."""
        return self.min_marker_perimeter_rate * max(width, height) / 4.0 * board.square / board.marker

    def usable(self, views: BoardViews, board: CharucoSpec, width: int, height: int) -> np.ndarray:
        """Which views (K,) meet every limit."""
        return (views.inside & (views.angle_deg <= self.max_angle_deg)
                & (views.spacing_px >= self.min_spacing_px(board, width, height)))


@dataclass(frozen=True)
class BoardViews:
    """The board as the camera sees it at K configurations.

    Attributes:
        pixels: each inner corner's pixel (K, P, 2) [px], by OpenCV id (NaN behind the camera).
        inside: the whole board ahead of the camera and within the image (K,).
        angle_deg: the angle between the board's normal and the optical axis (K,) [deg]; above 90 the board
            shows its back.
        spacing_px: the smallest distance between neighbouring corners (K,) [px].
        distance_m: the board's centre's distance from the camera (K,) [m].
    """

    pixels: np.ndarray
    inside: np.ndarray
    angle_deg: np.ndarray
    spacing_px: np.ndarray
    distance_m: np.ndarray


def _outline(board: CharucoSpec) -> np.ndarray:
    """The board's four outer corners (4, 3) [m] in its frame."""
    w, h = board.cols * board.square, board.rows * board.square
    return np.array([[0.0, 0.0, 0.0], [w, 0.0, 0.0], [w, h, 0.0], [0.0, h, 0.0]])


def board_views(chain: KinematicChain, camera: CameraEstimate, board: CharucoSpec, q: np.ndarray) -> BoardViews:
    """The board seen at configurations ``q`` (K, N) through ``camera``'s first world frame, its mount and
    intrinsics (eqs C1/C2 of :mod:`pincal.model.camera_view`, then eqs P1-P3 of :mod:`pincal.model.pinhole`)."""
    from pincal.model.pinhole import project

    q = np.atleast_2d(np.asarray(q, dtype=float))
    corners = board_corners(board)
    points = np.concatenate([corners, _outline(board), corners.mean(axis=0, keepdims=True)])  # (P + 5, 3)
    k, n = len(q), len(points)
    rotations, positions = chain.tool_poses(q)
    rows = np.repeat(np.arange(k), n)
    worlds = np.broadcast_to(camera.worlds[0], (k * n, 4, 4))
    _, p = camera_points(camera.arrangement, (rotations[rows], positions[rows]), worlds, camera.mount,
                         np.tile(points, (k, 1)))
    p = p.reshape(k, n, 3)
    intrinsics = camera.intrinsics
    pixels = project(intrinsics, p.reshape(-1, 3)).reshape(k, n, 2)
    size = np.array([intrinsics.width, intrinsics.height], dtype=float)
    with np.errstate(invalid="ignore"):
        inside = np.all((pixels[:, :-1] >= 0.0) & (pixels[:, :-1] <= size - 1.0), axis=(1, 2))
    inside &= np.all(p[:, :-1, 2] > 0.0, axis=1)
    x_axis, y_axis = p[:, len(corners) + 1] - p[:, len(corners)], p[:, len(corners) + 3] - p[:, len(corners)]
    normal = np.cross(x_axis, y_axis)  # the board's z axis in the camera frame: away from the camera when facing it
    cosine = normal[:, 2] / np.linalg.norm(normal, axis=1)
    grid = pixels[:, : len(corners)].reshape(k, board.rows - 1, board.cols - 1, 2)
    along = np.linalg.norm(np.diff(grid, axis=2), axis=3).reshape(k, -1)
    across = np.linalg.norm(np.diff(grid, axis=1), axis=3).reshape(k, -1)
    spacing = np.concatenate([along, across], axis=1)
    spacing = np.where(np.isnan(spacing), 0.0, spacing).min(axis=1)
    return BoardViews(pixels=pixels[:, : len(corners)], inside=inside,
                      angle_deg=np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0))), spacing_px=spacing,
                      distance_m=np.linalg.norm(p[:, -1], axis=1))


def _board_poses(camera: CameraEstimate, board: CharucoSpec, limits: ViewLimits, count: int,
                 rng: np.random.Generator) -> np.ndarray:
    """``count`` poses ``camera_T_board`` (count, 4, 4) [m] inside the limits (the module docstring)."""
    intrinsics = camera.intrinsics
    outline = _outline(board)
    centre = outline.mean(axis=0)
    focal = min(intrinsics.fx, intrinsics.fy)
    diagonal = float(np.linalg.norm(outline[2]))
    nearest = focal * diagonal / min(intrinsics.width, intrinsics.height)  # the board's diagonal fills the image
    farthest = focal * board.square / limits.min_spacing_px(board, intrinsics.width, intrinsics.height)
    distance = rng.uniform(nearest, max(nearest, min(farthest, 3.0 * nearest)), count)
    tilt = np.radians(limits.max_angle_deg) * np.sqrt(rng.uniform(0.0, 1.0, count))  # uniform over the cone
    heading = rng.uniform(0.0, 2.0 * np.pi, count)
    roll = rng.uniform(-np.pi, np.pi, count)
    # the centre within a tenth of the half field of view of the optical axis
    offset = 0.1 * rng.uniform(-1.0, 1.0, (count, 2)) * np.array([intrinsics.width, intrinsics.height]) / (2 * focal)
    out = np.empty((count, 4, 4))
    for i in range(count):
        axis = np.array([np.cos(heading[i]), np.sin(heading[i]), 0.0])
        rotation = pin.exp3(tilt[i] * axis) @ pin.exp3(np.array([0.0, 0.0, roll[i]]))
        target = distance[i] * np.array([offset[i, 0], offset[i, 1], 1.0])
        out[i] = pose(rotation, target - rotation @ centre)
    return out


def aimed_configurations(chain: KinematicChain, camera: CameraEstimate, board: CharucoSpec, seeds: np.ndarray,
                         count: int, rng: np.random.Generator, limits: ViewLimits = ViewLimits()) -> np.ndarray:
    """Configurations (≤ count, N) that put the board at ``count`` drawn poses in the camera's view, each by
    the inverse kinematics from a seed of ``seeds`` (S, N) taken in turn; poses the chain cannot reach from
    its seed, or reaches outside the joint limits, are left out (check the rest with :func:`board_views`).

    The tip link's pose: eye in hand ``W · camera_T_board⁻¹ · M⁻¹`` (W = base_T_board, M = tip_T_camera);
    eye to hand ``W⁻¹ · camera_T_board · M⁻¹`` (W = camera_T_base, M = tip_T_board)."""
    seeds = np.atleast_2d(np.asarray(seeds, dtype=float))
    lower, upper = sampling_limits(chain)
    world, inverse_mount = camera.worlds[0], np.linalg.inv(camera.mount)
    found = []
    for i, view in enumerate(_board_poses(camera, board, limits, count, rng)):
        if camera.arrangement == "eye_in_hand":
            tip = world @ np.linalg.inv(view) @ inverse_mount
        else:
            tip = np.linalg.inv(world) @ view @ inverse_mount
        try:
            q = inverse_kinematics(chain, tip[:3, :3], tip[:3, 3], seeds[i % len(seeds)])
        except PincalError:  # out of reach from this seed
            continue
        wrapped = np.where(np.isfinite(upper - lower) & (upper - lower >= 2 * np.pi - 1e-9),
                           (q + np.pi) % (2 * np.pi) - np.pi, q)  # one turn: the sampling range's
        if np.all((wrapped >= lower - LIMIT_SLACK) & (wrapped <= upper + LIMIT_SLACK)):
            found.append(np.clip(wrapped, lower, upper))
    return np.array(found).reshape(-1, chain.n_joints)
