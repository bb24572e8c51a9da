"""Images of a ChArUco board seen by a simulated camera: OpenCV's pinhole model with its distortion.

Each pixel of the image is traced back to the board: undistorted (``cv2.undistortPointsIter``), its
ray cut with the board's plane, and the board's picture (``CharucoBoard.generateImage``, blurred to
band-limit it) sampled there. The inverse map is computed on a grid of every :data:`GRID_PX` pixels and
interpolated by a bicubic spline: it is smooth, and the grid takes 0.06 s per 640x480 image where
every pixel took 0.4 s. The corners of such an image project, by ``cv2.projectPoints`` with the same
camera, within 0.2 px of where OpenCV's detector finds them (tests/test_detect.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.interpolate import RectBivariateSpline

from pincal.measurements.charuco import CharucoSpec
from pincal.measurements.images import opencv_board

__all__ = ["GRID_PX", "BoardView", "render_board"]

#: Pixels between the nodes of the inverse map's grid (16 px: the corners moved < 0.02 px RMS from 8 px).
GRID_PX = 16
#: The board's picture: its pixels per image pixel at the closest view (4: the blur below band-limits it).
_OVERSAMPLE = 4.0
#: Gaussian blur of the board's picture [its pixels]: half the oversampling, against aliasing of its edges.
_BLUR = 2.0


@dataclass(frozen=True)
class BoardView:
    """A camera looking at a board.

    Attributes:
        camera_matrix: OpenCV's K, ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` [px] (3, 3).
        distortion: OpenCV's ``(k1, k2, p1, p2, k3)`` (5,).
        size: the image's (width, height) [px].
        rvec: the board's rotation in the camera frame, a rotation vector [rad] (3,) (``cv2.Rodrigues``).
        tvec: the board's origin in the camera frame [m] (3,).
    """

    camera_matrix: np.ndarray
    distortion: np.ndarray
    size: tuple[int, int]
    rvec: np.ndarray
    tvec: np.ndarray

    def project(self, points: npt.ArrayLike) -> np.ndarray:
        """Board-frame points (M, 3) [m] as pixels (M, 2), ``cv2.projectPoints``."""
        import cv2

        pixels, _ = cv2.projectPoints(np.asarray(points, dtype=float).reshape(-1, 1, 3), self.rvec, self.tvec,
                                      self.camera_matrix, self.distortion)
        return np.asarray(pixels).reshape(-1, 2)


def render_board(spec: CharucoSpec, view: BoardView, noise: float, rng: np.random.Generator) -> np.ndarray:
    """The image (H, W) uint8 of board ``spec`` seen as ``view`` says, with Gaussian noise of ``noise``
    grey levels; outside the board, white."""
    import cv2

    width, height = view.size
    focal = float(view.camera_matrix[0, 0])
    # a whole number of the picture's pixels per square, or generateImage rounds the squares' edges
    square_px = math.ceil(_OVERSAMPLE * focal * spec.square / max(float(view.tvec[2]), 1e-3))
    picture = opencv_board(spec).generateImage((spec.cols * square_px, spec.rows * square_px), marginSize=0)
    per_metre = square_px / spec.square  # the picture's pixels per metre
    picture = cv2.GaussianBlur(picture, (0, 0), _BLUR)
    grid_u = np.arange(0, width + GRID_PX, GRID_PX, dtype=float)
    grid_v = np.arange(0, height + GRID_PX, GRID_PX, dtype=float)
    u, v = np.meshgrid(grid_u, grid_v)
    pixels = np.stack([u.ravel(), v.ravel()], axis=1).reshape(-1, 1, 2)
    stop = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-12)
    identity = np.eye(3)  # R and P: the rays in normalised coordinates of the same camera frame
    rays = cv2.undistortPointsIter(pixels, view.camera_matrix, view.distortion, identity, identity, stop).reshape(-1, 2)
    rotation, _ = cv2.Rodrigues(np.asarray(view.rvec, dtype=float))
    directions = np.column_stack([rays, np.ones(len(rays))]) @ rotation  # board frame: R^T d
    origin = rotation.T @ np.asarray(view.tvec, dtype=float)  # R^T t: on the board, p = s R^T d - R^T t, p_z = 0
    on_board = (origin[2] / directions[:, 2])[:, None] * directions - origin
    rows, cols = np.arange(height), np.arange(width)
    # the picture's pixel i covers [i, i + 1) / per_metre: its centre is at (i + 0.5) / per_metre
    map_x = RectBivariateSpline(grid_v, grid_u, (on_board[:, 0] * per_metre - 0.5).reshape(u.shape))(rows, cols)
    map_y = RectBivariateSpline(grid_v, grid_u, (on_board[:, 1] * per_metre - 0.5).reshape(u.shape))(rows, cols)
    image = cv2.remap(picture, map_x.astype(np.float32), map_y.astype(np.float32), cv2.INTER_LINEAR,
                      borderMode=cv2.BORDER_CONSTANT, borderValue=255)
    noisy = image + rng.normal(0.0, noise, image.shape)
    return np.clip(np.rint(noisy), 0, 255).astype(np.uint8)
