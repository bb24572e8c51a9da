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

__all__ = [
    "MIN_RADIUS_TO_SCATTER", "MAX_OFF_PLANE", "DEGENERATE", "NO_TURN", "CircleFit", "fit_circle", "circle_axis",
    "circle_axis_derivative", "twists_from_axes", "twist_gradients",
]

#: The arc radius must exceed this multiple of the RMS distance of the points from the
#: fitted circle in its plane, otherwise the point is (nearly) on the joint axis.
MIN_RADIUS_TO_SCATTER = 10.0
#: Largest ratio of the points' spread off the fitted plane to their second in-plane spread
#: (smallest to middle singular value): a single joint's arc is off its plane by the sensor
#: noise only (<= 0.15 mm in the paper's study) against in-plane spreads of centimetres, a
#: ratio below 0.01; at 1/2 the plane, and so the axis, is no longer set by the arc (at 1 it
#: may turn freely, and the axis derivative, 1 / (s_2^2 - s_3^2), has no bound).
MAX_OFF_PLANE = 0.5
#: Singular values of the centred arc points below this fraction of the largest count as
#: zero (the points coincide or are collinear): 1e-9 of a 1 m arc is 1 nm,
#: three orders below a laser tracker's ~1 µm resolution and seven above rounding
#: (~1e-16 of the coordinates), so only degenerate geometry, never a measured arc, trips it.
DEGENERATE = 1e-9
#: Largest |Σ (p_k − c) × (p_{k+1} − c) · b| taken as "no turn", as a fraction of r²: the
#: rounding of those cross products (~1e-16 r² each) over a few hundred points, with margin.
NO_TURN = 1e-12


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
            steps of π or more, collinear points, points off a plane
            (:data:`MAX_OFF_PLANE`: the arc's plane, and so its axis, is undetermined;
            also what noise around a point on the axis looks like), or an arc radius
            too small relative to the scatter (the measured point is on the joint axis).
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
    if s[0] / np.sqrt(len(p)) <= DEGENERATE * max(1.0, np.abs(p).max()):
        raise CalibrationError("all points coincide: the measured point is on the joint axis (arc radius 0)")
    if s[1] <= DEGENERATE * s[0]:
        raise CalibrationError("points are collinear (rank < 2): the arc plane is undetermined")
    if s[2] >= MAX_OFF_PLANE * s[1]:
        rms = s[1:] / np.sqrt(len(p)) * 1e3
        raise CalibrationError(
            f"the points do not lie on a plane arc: their RMS distance from the best plane ({rms[1]:.3g} mm) "
            f"is {rms[1] / rms[0]:.2f} of their spread across the arc ({rms[0]:.3g} mm), so the axis "
            "direction is undetermined; move only this joint, through a larger angle, with the measured "
            "point away from the joint axis"
        )
    uv = (p - centroid) @ vt[:2].T  # in-plane coordinates
    a = np.column_stack([2.0 * uv, np.ones(len(p))])
    (cu, cv, c0), *_ = np.linalg.lstsq(a, (uv**2).sum(axis=1), rcond=None)
    radius = float(np.sqrt(max(c0 + cu**2 + cv**2, 0.0)))
    center = centroid + cu * vt[0] + cv * vt[1]
    out_of_plane = (p - centroid) @ vt[2]
    radial = np.hypot(uv[:, 0] - cu, uv[:, 1] - cv) - radius
    scatter = float(np.sqrt(np.mean(radial**2)))  # in the plane: the spread off it has its own check above
    if radius <= MIN_RADIUS_TO_SCATTER * scatter:
        raise CalibrationError(
            f"arc radius {radius:.3g} m is too small relative to the scatter {scatter:.3g} m: "
            "the measured point is (nearly) on the joint axis"
        )
    r = p - center
    turn = np.cross(r[:-1], r[1:]).sum(axis=0) @ vt[2]
    if abs(turn) <= NO_TURN * radius**2:
        raise CalibrationError("joint angles do not change: the arc direction is undetermined")
    axis = vt[2] * np.sign(turn)
    return CircleFit(axis, center, radius, float(np.sqrt(np.mean(out_of_plane**2))))


def circle_axis(points, angles) -> np.ndarray:
    """Unit axis b_n of a joint from its arc points, right-handed with increasing angle.

    See :func:`fit_circle` for arguments and errors.
    """
    return fit_circle(points, angles).axis


def circle_axis_derivative(points, angles) -> tuple[np.ndarray, np.ndarray]:
    """The axis of :func:`circle_axis` and its first derivative with respect to the points.

    The axis b is ± the right-singular vector v₃ of the centred points X = P − 1 p̄ᵀ
    (K, 3) with the smallest singular value, i.e. the eigenvector of M = XᵀX = Σ_i s_i² v_i v_iᵀ
    for λ₃ = s₃². First-order perturbation of a simple eigenvalue's eigenvector of a
    symmetric matrix (e.g. Golub & Van Loan, Matrix Computations, 4th ed., Sec. 8.1.2):

        db = Σ_{i=1,2} v_i (v_iᵀ dM b) / (s₃² − s_i²).

    With Xᵀ1 = 0 the centroid's change drops out of dM b = dPᵀ X b + Xᵀ dP b, so moving
    point k along coordinate c gives dM b = e_c h_k + x_k b_c with h = X b (the
    out-of-plane offsets [m]) and x_k the k-th centred point:

        ∂b/∂p_{kc} = Σ_{i=1,2} v_i (v_{ic} h_k + (x_k · v_i) b_c) / (s₃² − s_i²).

    The sign of b (right-hand rule, set by :func:`fit_circle`) is locally constant, and
    the formula is linear in b, so it holds for either sign. This is the limit that
    central finite differences of :func:`circle_axis` with step h approach with an
    error O(h²) (truncation) plus O(ε_mach/h) (rounding).

    Args:
        points: (K, 3) arc points [m], as for :func:`fit_circle`.
        angles: (K,) joint angles [rad].

    Returns:
        The unit axis b, (3,), bit-identical to :func:`circle_axis`, and
        ∂b/∂p, (3, K, 3) [1/m]: entry [a, k, c] is ∂b_a/∂p_{kc} for ``points[k, c]``.

    Raises:
        CalibrationError: as :func:`fit_circle` (whose plane check keeps the two
            smallest singular values apart, so the derivative exists).
    """
    axis = circle_axis(points, angles)
    centred = np.asarray(points, dtype=float)
    centred = centred - centred.mean(axis=0)
    _, s, vt = np.linalg.svd(centred)  # fit_circle refused s_3 >= s_2 / 2: the gaps below are >= 0.75 s_2^2
    offsets = centred @ axis  # h, (K,)
    in_plane = centred @ vt[:2].T  # x_k · v_i, (K, 2)
    gap = s[2] ** 2 - s[:2] ** 2  # s₃² − s_i², (2,)
    coefficient = (vt[:2, None, :] * offsets[None, :, None] + in_plane.T[:, :, None] * axis) / gap[:, None, None]
    return axis, np.einsum("ia,ikc->akc", vt[:2], coefficient)


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


def twist_gradients(axes, nominal_alpha) -> np.ndarray:
    """First derivatives of the twists of :func:`twists_from_axes` (eq 9) with respect to the axes.

    α̃_n = sign(α_{0,n}) · ∠(b_n, b_{n+1}) depends on the directions only; with unit
    b̂ = b/‖b‖, cos α = b̂_n · b̂_{n+1} and sin α = ‖b̂_n × b̂_{n+1}‖, differentiating
    cos α gives

        ∂α/∂b_n = −(b̂_{n+1} − cos α b̂_n) / (‖b_n‖ sin α),

    and symmetrically for b_{n+1}. Where the nominal twist is 0 (eq 9 gives the constant
    0) or the axes are parallel (the angle has a kink, |·|, and no derivative; its
    central differences are 0) the gradient is 0.

    Args:
        axes: (N, 3) joint axis directions b_n, as for :func:`twists_from_axes`.
        nominal_alpha: (N,) nominal twists α_{0,n} [rad].

    Returns:
        (N − 1, 2, 3) [rad per unit of b]: [n, 0] is ∂α̃_n/∂b_n and [n, 1] is
        ∂α̃_n/∂b_{n+1}; α_N keeps its nominal value and has no gradient.

    Raises:
        CalibrationError: as :func:`twists_from_axes`.
    """
    twists_from_axes(axes, nominal_alpha)  # validates
    b = np.asarray(axes, dtype=float)
    norms = np.linalg.norm(b, axis=1)
    unit = b / norms[:, None]
    first, second = unit[:-1], unit[1:]
    cos = np.sum(first * second, axis=1)
    sin = np.linalg.norm(np.cross(first, second), axis=1)
    sign = np.sign(np.asarray(nominal_alpha, dtype=float)[:-1])
    scale = np.divide(-sign, sin, out=np.zeros_like(sin), where=(sign != 0) & (sin > 1e-12))
    return np.stack(
        [
            (second - cos[:, None] * first) * (scale / norms[:-1])[:, None],
            (first - cos[:, None] * second) * (scale / norms[1:])[:, None],
        ],
        axis=1,
    )
