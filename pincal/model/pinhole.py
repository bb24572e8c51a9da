"""A camera's projection: OpenCV's pinhole model with its five distortion coefficients, and its derivatives.

A point ``P = (X, Y, Z)`` in the camera's optical frame (x right, y down, z along the optical axis:
OpenCV's and ROS's ``*_optical_frame`` convention) [m] is seen at the pixel ``(u, v)`` [px]:

* ``x' = X / Z``, ``y' = Y / Z`` and ``r² = x'² + y'²`` (eq P1);
* ``x'' = x' (1 + k1 r² + k2 r⁴ + k3 r⁶) + 2 p1 x' y' + p2 (r² + 2 x'²)`` and
  ``y'' = y' (1 + k1 r² + k2 r⁴ + k3 r⁶) + p1 (r² + 2 y'²) + 2 p2 x' y'`` (eq P2, radial then tangential);
* ``u = fx x'' + cx``, ``v = fy y'' + cy`` (eq P3).

This is ``cv2.projectPoints`` with ``distCoeffs = (k1, k2, p1, p2, k3)``; :func:`project` evaluates it for
many points at once with numpy and :func:`projection_jacobians` gives its analytic derivatives with respect
to the point and to the nine intrinsics (``fx, fy, cx, cy, k1, k2, p1, p2, k3``, in that order), which a
fit chains with the kinematic derivatives of the point.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from pincal.errors import ModelError

__all__ = ["INTRINSIC_NAMES", "CameraIntrinsics", "project", "projection_jacobians"]

#: The intrinsics in the order of :meth:`CameraIntrinsics.vector` and of :func:`projection_jacobians`'s columns.
INTRINSIC_NAMES = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class CameraIntrinsics:
    """A camera's intrinsics as OpenCV and ROS camera_info give them.

    Attributes:
        fx, fy: focal lengths [px].
        cx, cy: principal point [px] (the image's top-left pixel's centre is (0, 0)).
        distortion: ``(k1, k2, p1, p2, k3)`` (dimensionless; eq P2).
        width, height: the image size [px] the intrinsics were estimated for.
    """

    fx: float
    fy: float
    cx: float
    cy: float
    distortion: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)
    width: int = 0
    height: int = 0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.fx) and np.isfinite(self.fy) and self.fx > 0 and self.fy > 0):
            raise ModelError(f"camera focal lengths must be positive pixels (fx={self.fx}, fy={self.fy})")
        if len(self.distortion) != 5:
            raise ModelError(f"camera distortion: give the five coefficients k1, k2, p1, p2, k3 "
                             f"(got {len(self.distortion)})")

    @property
    def matrix(self) -> FloatArray:
        """OpenCV's camera matrix ``K`` (3, 3)."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def vector(self) -> FloatArray:
        """``(fx, fy, cx, cy, k1, k2, p1, p2, k3)`` (:data:`INTRINSIC_NAMES`)."""
        return np.array([self.fx, self.fy, self.cx, self.cy, *self.distortion], dtype=float)

    def with_vector(self, values: npt.ArrayLike) -> CameraIntrinsics:
        """These intrinsics with the nine values of :meth:`vector` replaced (the image size kept)."""
        v = np.asarray(values, dtype=float)
        if v.shape != (len(INTRINSIC_NAMES),):
            raise ModelError(f"camera intrinsics: {len(INTRINSIC_NAMES)} values expected, got shape {v.shape}")
        k1, k2, p1, p2, k3 = (float(x) for x in v[4:])
        return CameraIntrinsics(float(v[0]), float(v[1]), float(v[2]), float(v[3]), (k1, k2, p1, p2, k3),
                                self.width, self.height)


def _normalised(points: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``x'``, ``y'`` (eq P1) and ``1/Z`` of points (M, 3) in the optical frame [m]."""
    z = points[:, 2]
    inverse = 1.0 / z
    return points[:, 0] * inverse, points[:, 1] * inverse, inverse


def project(intrinsics: CameraIntrinsics, points: npt.ArrayLike) -> FloatArray:
    """Pixels (M, 2) [px] of points (M, 3) in the camera's optical frame [m] (eqs P1-P3).

    A point at or behind the camera (``Z <= 0``) has no image: its pixel is NaN.
    """
    p = np.atleast_2d(np.asarray(points, dtype=float))
    ahead = p[:, 2] > 0.0
    safe = np.where(ahead[:, None], p, np.array([0.0, 0.0, 1.0]))
    x, y, _ = _normalised(safe)
    k1, k2, p1, p2, k3 = intrinsics.distortion
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    uv = np.stack([intrinsics.fx * xd + intrinsics.cx, intrinsics.fy * yd + intrinsics.cy], axis=1)
    uv[~ahead] = np.nan
    return uv


def projection_jacobians(intrinsics: CameraIntrinsics, points: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
    """The derivatives of :func:`project` at points (M, 3) [m] in the optical frame: with respect to the
    point, (M, 2, 3) [px/m], and to the intrinsics in :data:`INTRINSIC_NAMES`' order, (M, 2, 9)
    ([px/px] for fx, fy, cx, cy; [px] for the distortion coefficients). Points at or behind the camera
    give NaN rows."""
    p = np.atleast_2d(np.asarray(points, dtype=float))
    ahead = p[:, 2] > 0.0
    safe = np.where(ahead[:, None], p, np.array([0.0, 0.0, 1.0]))
    x, y, inverse = _normalised(safe)
    k1, k2, p1, p2, k3 = intrinsics.distortion
    fx, fy = intrinsics.fx, intrinsics.fy
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    d_radial = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)  # d radial / d r²
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    # eq P2 differentiated in x', y' (d r²/dx' = 2x', d r²/dy' = 2y')
    dxd_dx = radial + 2.0 * x * x * d_radial + 2.0 * p1 * y + 6.0 * p2 * x
    dxd_dy = 2.0 * x * y * d_radial + 2.0 * p1 * x + 2.0 * p2 * y
    dyd_dx = 2.0 * x * y * d_radial + 2.0 * p1 * x + 2.0 * p2 * y
    dyd_dy = radial + 2.0 * y * y * d_radial + 6.0 * p1 * y + 2.0 * p2 * x
    # eq P1: d(x', y')/d(X, Y, Z) = [[1/Z, 0, -x'/Z], [0, 1/Z, -y'/Z]]
    m = len(p)
    normalised = np.zeros((m, 2, 3))
    normalised[:, 0, 0] = inverse
    normalised[:, 0, 2] = -x * inverse
    normalised[:, 1, 1] = inverse
    normalised[:, 1, 2] = -y * inverse
    distorted = np.empty((m, 2, 2))
    distorted[:, 0, 0], distorted[:, 0, 1] = fx * dxd_dx, fx * dxd_dy
    distorted[:, 1, 0], distorted[:, 1, 1] = fy * dyd_dx, fy * dyd_dy
    d_point = distorted @ normalised
    d_intrinsics = np.zeros((m, 2, len(INTRINSIC_NAMES)))
    d_intrinsics[:, 0, 0] = xd
    d_intrinsics[:, 1, 1] = yd
    d_intrinsics[:, 0, 2] = 1.0
    d_intrinsics[:, 1, 3] = 1.0
    for column, (dx, dy) in enumerate(((x * r2, y * r2), (x * r2 ** 2, y * r2 ** 2),
                                       (2.0 * x * y, r2 + 2.0 * y * y), (r2 + 2.0 * x * x, 2.0 * x * y),
                                       (x * r2 ** 3, y * r2 ** 3)), start=4):  # k1, k2, p1, p2, k3
        d_intrinsics[:, 0, column] = fx * dx
        d_intrinsics[:, 1, column] = fy * dy
    d_point[~ahead] = np.nan
    d_intrinsics[~ahead] = np.nan
    return d_point, d_intrinsics
