"""The camera's projection (pincal.model.pinhole): OpenCV's model, its derivatives exact.

The pixels are those of ``cv2.projectPoints`` (the same model, computed independently), and the analytic
derivatives match both OpenCV's own Jacobian (its columns for the translation, focal lengths, principal
point and distortion) and central differences.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from pincal.errors import ModelError
from pincal.model.pinhole import INTRINSIC_NAMES, CameraIntrinsics, project, projection_jacobians

#: A 1280x960 camera with the distortion of a typical wide-angle lens (OpenCV's sample calibrations have
#: |k1| ~ 0.1-0.3, tangential terms ~ 1e-3).
CAMERA = CameraIntrinsics(1100.0, 1095.0, 641.5, 478.2, (-0.21, 0.12, 1.5e-3, -8e-4, -0.03), 1280, 960)


def _points(seed: int, count: int = 200) -> np.ndarray:
    """Points 0.3-1.5 m ahead of the camera, within its field of view and beyond the corners."""
    rng = np.random.default_rng(seed)
    z = rng.uniform(0.3, 1.5, count)
    return np.stack([rng.uniform(-0.7, 0.7, count) * z, rng.uniform(-0.55, 0.55, count) * z, z], axis=1)


def _opencv(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    uv, jacobian = cv2.projectPoints(points.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), CAMERA.matrix,
                                     np.array(CAMERA.distortion))
    return uv.reshape(-1, 2), jacobian


def test_pixels_are_opencvs():
    points = _points(1)
    uv, _ = _opencv(points)
    # both in double precision: agreement to ~1e-12 relative of ~1000 px
    assert np.max(np.abs(project(CAMERA, points) - uv)) < 1e-8


def test_derivatives_are_opencvs_jacobian():
    """cv2.projectPoints' Jacobian, 2M x 15: rvec (3), tvec (3), fx fy (2), cx cy (2), k1 k2 p1 p2 k3 (5).
    With no rotation and no translation, d/d tvec is d/d point."""
    points = _points(2)
    _, jacobian = _opencv(points)
    d_point, d_intrinsics = projection_jacobians(CAMERA, points)
    theirs = jacobian.reshape(len(points), 2, -1)
    assert np.allclose(d_point, theirs[:, :, 3:6], rtol=1e-9, atol=1e-6)
    assert np.allclose(d_intrinsics, theirs[:, :, 6:15], rtol=1e-9, atol=1e-9)


def test_derivatives_are_central_differences():
    """Central differences, step 1e-6 m on the point (~1 m away) and 1e-6 relative on the intrinsics:
    truncation ~ step² x third derivative, rounding ~ 1e-16 x 1000 px / 1e-6 = 1e-7 px; a wrong term is
    off by O(1) px per unit."""
    points = _points(3, 40)
    d_point, d_intrinsics = projection_jacobians(CAMERA, points)
    step = 1e-6
    for axis in range(3):
        delta = np.zeros(3)
        delta[axis] = step
        numeric = (project(CAMERA, points + delta) - project(CAMERA, points - delta)) / (2 * step)
        assert np.allclose(d_point[:, :, axis], numeric, rtol=1e-6, atol=1e-3), axis
    values = CAMERA.vector()
    for column, name in enumerate(INTRINSIC_NAMES):
        h = step * max(1.0, abs(values[column]))
        up, down = values.copy(), values.copy()
        up[column] += h
        down[column] -= h
        numeric = (project(CAMERA.with_vector(up), points) - project(CAMERA.with_vector(down), points)) / (2 * h)
        assert np.allclose(d_intrinsics[:, :, column], numeric, rtol=1e-6, atol=1e-4), name


def test_a_point_behind_the_camera_has_no_pixel():
    uv = project(CAMERA, [[0.1, 0.1, 1.0], [0.1, 0.1, 0.0], [0.1, 0.1, -1.0]])
    assert np.isfinite(uv[0]).all() and np.isnan(uv[1:]).all()
    d_point, d_intrinsics = projection_jacobians(CAMERA, [[0.1, 0.1, -1.0]])
    assert np.isnan(d_point).all() and np.isnan(d_intrinsics).all()


def test_intrinsics_round_trip_and_bad_values_are_refused():
    assert CAMERA.with_vector(CAMERA.vector()) == CAMERA
    with pytest.raises(ModelError, match="focal lengths must be positive"):
        CameraIntrinsics(0.0, 1.0, 0.0, 0.0)
    with pytest.raises(ModelError, match="give the five coefficients"):
        CameraIntrinsics(1.0, 1.0, 0.0, 0.0, (0.1, 0.2))  # type: ignore[arg-type]
