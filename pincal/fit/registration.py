"""Registration of the sensor frame to the robot base (Franaszek & Marvel 2022, Sec. 4).

Sensor coordinates ``g`` and robot-base (URDF root) coordinates ``t`` are related by
``g ≈ Ω t + τ``. Registration 1 takes Ω from 3D points by the SVD method of Arun,
Huang & Blostein (1987); Registration 2 takes Ω as the Riemannian (geodesic L2) mean
(Moakher 2002) of the relative rotations ``G_k R_k^T``. Points on one line fix Ω only up to a
rotation about it: :func:`register_line` states which. All take τ from eq 19,
``τ = ḡ − Ω t̄``. Lengths in metres.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pinocchio as pin
from scipy.spatial.transform import Rotation

from pincal.errors import CalibrationError
from pincal.model.sensor import Registration, checked_array, checked_rotations

__all__ = ["VERTICAL_LINE", "register_points", "mean_rotation", "register_orientations", "register_line"]

#: A line whose sensed direction is within this sine of the sensor's z axis is vertical for
#: :func:`register_line`: turning about it moves base z's image across the sensor's z by less, which
#: leaves the rotation to rounding (1e-6: a line off vertical by a micrometre per metre).
VERTICAL_LINE = 1e-6


def _weights(weights: npt.ArrayLike | None, k: int) -> np.ndarray:
    if weights is None:
        return np.full(k, 1.0 / k)
    w = np.asarray(weights, dtype=float)
    if w.shape != (k,) or not np.all(np.isfinite(w)) or np.any(w < 0) or w.sum() <= 0:
        raise CalibrationError(f"weights must be {k} finite non-negative numbers with a positive sum")
    return w / w.sum()


def _project_to_so3(m: np.ndarray) -> np.ndarray:
    """Closest proper rotation (Frobenius) to ``m``: U diag(1, 1, det(U V^T)) V^T."""
    u, _, vt = np.linalg.svd(m)
    return u @ np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt)) or 1.0]) @ vt


def _translation(rotation: np.ndarray, robot_points: np.ndarray, sensor_points: np.ndarray, w: np.ndarray
                 ) -> np.ndarray:
    """Eq 19: τ = ḡ − Ω t̄ with (weighted) centroids ḡ, t̄ [m]."""
    return w @ sensor_points - rotation @ (w @ robot_points)


def register_points(robot_points: npt.ArrayLike, sensor_points: npt.ArrayLike,
                    weights: npt.ArrayLike | None = None) -> Registration:
    """Registration 1: Ω by the SVD method of Arun et al. (1987), τ by eq 19.

    Args:
        robot_points: (K, 3) points t_k in robot-base coordinates [m], K >= 3.
        sensor_points: (K, 3) the same points g_k measured by the sensor [m].
        weights: optional (K,) non-negative weights (used for centroids and Ω).

    Returns:
        The proper rotation Ω and τ minimising Σ w_k ‖g_k − Ω t_k − τ‖². If the
        unconstrained optimum is a reflection (det = −1) the best proper rotation is
        returned (Arun's det correction).

    Raises:
        CalibrationError: fewer than 3 points, mismatched shapes, NaN, bad weights,
            or a collinear point set (rank < 2) that leaves Ω undetermined.
    """
    t = checked_array(robot_points, (3,), "robot_points", 3)
    g = checked_array(sensor_points, (3,), "sensor_points", 3)
    if len(t) != len(g):
        raise CalibrationError(f"robot_points ({len(t)}) and sensor_points ({len(g)}) differ in number")
    w = _weights(weights, len(t))
    tc, gc = t - w @ t, g - w @ g
    for pts, name in ((tc, "robot_points"), (gc, "sensor_points")):
        s = np.linalg.svd(pts * np.sqrt(w)[:, None], compute_uv=False)
        if s[1] <= 1e-9 * max(s[0], 1e-300):
            raise CalibrationError(
                f"{name}: the {len(pts)} points are collinear or coincident (rank < 2), so the registration's "
                "rotation about their line is undetermined; measure 3 or more points not on one line, or add "
                "orientations (Registration 2)")
    u, _, vt = np.linalg.svd((tc * w[:, None]).T @ gc)  # H = Σ w t_k g_k^T = U S V^T
    d = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
    rotation = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return Registration(rotation, _translation(rotation, t, g, w))


def mean_rotation(rotations: npt.ArrayLike, weights: npt.ArrayLike | None = None, tol: float = 1e-14,
                  max_iter: int = 100) -> np.ndarray:
    """Riemannian (geodesic L2) mean of rotations, Moakher (2002).

    Minimises Σ w_k ‖log(Ω^T M_k)‖² by the fixed-point iteration
    Ω ← Ω exp(Σ w_k log(Ω^T M_k)), started at the projected arithmetic mean.

    Args:
        rotations: (K, 3, 3) proper rotations M_k, K >= 1.
        weights: optional (K,) non-negative weights.
        tol: stop when the update angle [rad] is below this.
        max_iter: iteration limit.

    Returns:
        (3, 3) proper rotation Ω.

    Raises:
        CalibrationError: bad input, or no convergence (rotations too dispersed).
    """
    m = checked_rotations(rotations, "rotations")
    w = _weights(weights, len(m))
    omega = _project_to_so3(np.einsum("k,kij->ij", w, m))
    step = np.inf
    for _ in range(max_iter):
        delta = w @ Rotation.from_matrix(omega.T @ m).as_rotvec()  # Σ w_k log(Ωᵀ M_k), batched
        omega = _project_to_so3(omega @ pin.exp3(delta))
        previous, step = step, float(np.linalg.norm(delta))
        if step <= tol or (step < 1e-12 and step >= previous):  # converged to rounding level
            return omega
    raise CalibrationError(f"mean rotation did not converge in {max_iter} iterations (last step {step:.3g} rad)")


def register_orientations(robot_rotations: npt.ArrayLike, sensor_rotations: npt.ArrayLike | None,
                          robot_points: npt.ArrayLike, sensor_points: npt.ArrayLike) -> Registration:
    """Registration 2: Ω = Riemannian mean of G_k R_k^T (Moakher 2002), τ by eq 19.

    Args:
        robot_rotations: (K, 3, 3) model orientations R_k in the robot base.
        sensor_rotations: (K, 3, 3) measured orientations G_k in the sensor frame (None, rows
            without orientations, is refused as of the wrong shape).
        robot_points: (L, 3) points t_l in robot-base coordinates [m], L >= 1:
            the orientations fix Ω, so eq 19 needs only the points' centroid (one
            6D row registers a session, where Registration 1 needs 3 points not on
            one line).
        sensor_points: (L, 3) the same points g_l measured by the sensor [m].

    Raises:
        CalibrationError: mismatched shapes or counts, no point, NaN,
            non-rotation matrices.
    """
    r = checked_rotations(robot_rotations, "robot_rotations")
    g_rot = checked_rotations(sensor_rotations, "sensor_rotations")
    if len(r) != len(g_rot):
        raise CalibrationError(f"robot_rotations ({len(r)}) and sensor_rotations ({len(g_rot)}) differ in number")
    t = checked_array(robot_points, (3,), "robot_points", 1)
    g = checked_array(sensor_points, (3,), "sensor_points", 1)
    if len(t) != len(g):
        raise CalibrationError(f"robot_points ({len(t)}) and sensor_points ({len(g)}) differ in number")
    rotation = mean_rotation(g_rot @ r.transpose(0, 2, 1))
    return Registration(rotation, _translation(rotation, t, g, np.full(len(t), 1.0 / len(t))))


def register_line(robot_points: npt.ArrayLike, sensor_points: npt.ArrayLike,
                  reference: npt.ArrayLike | None = None) -> Registration:
    """Ω and τ of points on one line, which leave Ω's rotation about it free: Ω is one of the rotations
    that turn the robot points' line onto the sensed points' (l, l_g: the lines' directions, the
    principal axes of the centred points, l_g signed so that the points run along it in the same order),
    chosen by a stated rule; τ by eq 19.

    * With a ``reference`` rotation: the one nearest it — ``reference`` turned by the smallest rotation
      taking ``reference`` l onto l_g. With a Registration 2 taken with the target's rotation as the
      tool's, the target's rotation then comes out the nearest the tool's own (the smallest angle) that
      agrees with the line; the rule is the sensor frame's: moving the sensor moves Ω with it.
    * Without (points only): the one whose image of the robot base's z axis is nearest the sensor's z
      axis — a levelled sensor beside a robot standing on the floor — so turning the sensor about its
      vertical moves Ω with it; for a vertical line, which leaves that free too, the one nearest the
      identity.

    Args:
        robot_points: (K, 3) points t_k in robot-base coordinates [m], K >= 2, not all one.
        sensor_points: (K, 3) the same points g_k measured by the sensor [m].
        reference: (3, 3) the rotation to stay nearest, or None.

    Raises:
        CalibrationError: fewer than 2 points, mismatched shapes, NaN, or coincident points.
    """
    t = checked_array(robot_points, (3,), "robot_points", 2)
    g = checked_array(sensor_points, (3,), "sensor_points", 2)
    if len(t) != len(g):
        raise CalibrationError(f"robot_points ({len(t)}) and sensor_points ({len(g)}) differ in number")
    tc, gc = t - t.mean(axis=0), g - g.mean(axis=0)
    _, spread, vt = np.linalg.svd(tc, full_matrices=False)
    along = gc.T @ (tc @ vt[0])  # Σ s_k (g_k − ḡ): the sensed line's direction, with the robot line's sign
    if spread[0] <= 0.0 or not np.linalg.norm(along) > 0.0:
        raise CalibrationError(f"the {len(t)} points coincide, so neither the registration's rotation nor a line "
                               "is defined; measure the target at 3 or more positions not on one line")
    line = along / np.linalg.norm(along)
    start = np.eye(3) if reference is None else checked_rotations(np.asarray(reference)[None], "reference")[0]
    turn, _ = Rotation.align_vectors(line[None, :], (start @ vt[0])[None, :])
    rotation = turn.as_matrix() @ start
    if reference is None:  # then about the line: base z's image the nearest sensor z
        up = rotation[:, 2] - (rotation[:, 2] @ line) * line  # its part across the line, turned by α about it
        cos, sin = up[2], np.cross(line, up)[2]  # e_z · (cos α up + sin α line × up)
        if np.hypot(cos, sin) > VERTICAL_LINE * np.linalg.norm(up):
            rotation = Rotation.from_rotvec(np.arctan2(sin, cos) * line).as_matrix() @ rotation
    return Registration(rotation, _translation(rotation, t, g, np.full(len(t), 1.0 / len(t))))
