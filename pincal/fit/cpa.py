"""Circle point analysis (Franaszek & Marvel 2022, Sec. 3).

While only joint n moves, a point fixed to the tool traces a circle arc about the
joint axis. A plane fitted to the arc gives the axis direction b_n (oriented by the
right-hand rule with the joint angle), and the angles between consecutive axes give
the link twists (eq 9). Lengths in metres, angles in radians.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pincal.errors import CalibrationError

#: The arc radius must exceed this multiple of the RMS distance of the points from the
#: fitted circle, otherwise the point is (nearly) on the joint axis.
MIN_RADIUS_TO_SCATTER = 10.0


@dataclass(frozen=True)
class CircleFit:
    """A circle fitted to the points of one joint's arc."""

    axis: np.ndarray  # (3,) unit normal b_n, right-handed with increasing joint angle
    center: np.ndarray  # (3,) circle centre, a point on the joint axis [m]
    radius: float  # [m]
    rms_out_of_plane: float  # RMS distance of the points from the fitted plane [m]


def fit_circle(points, angles) -> CircleFit:
    """Fit a circle to points measured while a single revolute joint moves.

    The plane comes from the SVD of the centred points, the centre and radius from a
    linear least-squares (Kåsa) circle fit in that plane. The normal is oriented so
    that a positive rotation about it moves the points in the order of increasing
    angle: its sign is that of Σ (p_k − c) × (p_{k+1} − c) over the points sorted by
    angle, which requires consecutive angle steps below π.

    Args:
        points: (K, 3) measured positions [m], K >= 3.
        angles: (K,) joint angles [rad] at which they were measured.

    Raises:
        CalibrationError: fewer than 3 points, mismatched shapes, NaN, consecutive
            steps of π or more, collinear points, or an arc radius too small
            relative to the scatter (the measured point is on the joint axis).
    """
    p = np.asarray(points, dtype=float)
    q = np.asarray(angles, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3 or q.shape != (len(p),):
        raise CalibrationError(f"points must be (K, 3) and angles (K,), got {p.shape} and {q.shape}")
    if len(p) < 3:
        raise CalibrationError(f"a circle fit needs at least 3 points, got {len(p)}")
    if not (np.all(np.isfinite(p)) and np.all(np.isfinite(q))):
        raise CalibrationError("points or angles contain NaN or infinite values")
    order = np.argsort(q, kind="stable")
    p, q = p[order], q[order]
    if np.any(np.diff(q) >= np.pi):
        raise CalibrationError("consecutive joint angles differ by π or more: arc direction is ambiguous")
    centroid = p.mean(axis=0)
    _, s, vt = np.linalg.svd(p - centroid)
    if s[0] / np.sqrt(len(p)) <= 1e-9 * max(1.0, np.abs(p).max()):
        raise CalibrationError("all points coincide: the measured point is on the joint axis (arc radius 0)")
    if s[1] <= 1e-9 * s[0]:
        raise CalibrationError("points are collinear (rank < 2): the arc plane is undetermined")
    uv = (p - centroid) @ vt[:2].T  # in-plane coordinates
    a = np.column_stack([2.0 * uv, np.ones(len(p))])
    (cu, cv, c0), *_ = np.linalg.lstsq(a, (uv**2).sum(axis=1), rcond=None)
    radius = float(np.sqrt(max(c0 + cu**2 + cv**2, 0.0)))
    center = centroid + cu * vt[0] + cv * vt[1]
    out_of_plane = (p - centroid) @ vt[2]
    radial = np.hypot(uv[:, 0] - cu, uv[:, 1] - cv) - radius
    scatter = float(np.sqrt(np.mean(out_of_plane**2 + radial**2)))
    if radius <= MIN_RADIUS_TO_SCATTER * scatter:
        raise CalibrationError(
            f"arc radius {radius:.3g} m is too small relative to the scatter {scatter:.3g} m: "
            "the measured point is (nearly) on the joint axis"
        )
    r = p - center
    turn = np.cross(r[:-1], r[1:]).sum(axis=0) @ vt[2]
    if abs(turn) <= 1e-12 * radius**2:
        raise CalibrationError("joint angles do not change: the arc direction is undetermined")
    axis = vt[2] * np.sign(turn)
    return CircleFit(axis, center, radius, float(np.sqrt(np.mean(out_of_plane**2))))


def circle_axis(points, angles) -> np.ndarray:
    """Unit axis b_n of a joint from its arc points, right-handed with increasing angle.

    See :func:`fit_circle` for arguments and errors.
    """
    return fit_circle(points, angles).axis


def twists_from_axes(axes, nominal_alpha) -> np.ndarray:
    """Link twists from consecutive joint axes, eq 9.

    α̃_n = sign(α_{0,n}) · arccos(b̃_n · b̃_{n+1}) for n = 1..N−1; the angle is computed
    as atan2(‖b_n × b_{n+1}‖, b_n · b_{n+1}), equal to the arccos but accurate near 0
    and π. α_N is not determined by CPA and keeps its nominal value. Where the nominal
    twist is 0 (parallel axes) eq 9 gives 0: the sign of a small twist is not
    observable from the axis directions alone.

    Args:
        axes: (N, 3) joint axis directions b_n (any non-zero length), right-handed.
        nominal_alpha: (N,) nominal twists α_{0,n} [rad].

    Returns:
        (N,) estimated twists α̃ [rad].

    Raises:
        CalibrationError: mismatched shapes, NaN or a zero axis.
    """
    b = np.asarray(axes, dtype=float)
    alpha0 = np.asarray(nominal_alpha, dtype=float)
    if b.ndim != 2 or b.shape[1] != 3 or len(b) == 0 or alpha0.shape != (len(b),):
        raise CalibrationError(f"axes must be (N, 3) and nominal_alpha (N,), N >= 1, got {b.shape} and {alpha0.shape}")
    if not (np.all(np.isfinite(b)) and np.all(np.isfinite(alpha0))):
        raise CalibrationError("axes or nominal_alpha contain NaN or infinite values")
    norms = np.linalg.norm(b, axis=1)
    if np.any(norms < 1e-12):
        raise CalibrationError(f"axis {int(np.argmin(norms)) + 1} has zero length")
    angle = np.arctan2(np.linalg.norm(np.cross(b[:-1], b[1:]), axis=1), np.sum(b[:-1] * b[1:], axis=1))
    return np.append(np.sign(alpha0[:-1]) * angle, alpha0[-1])
