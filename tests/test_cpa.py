"""Tests of pincal.paper.cpa (circle point analysis, eq 9)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pincal.errors import CalibrationError
from pincal.paper.cpa import circle_axis, fit_circle, twists_from_axes

SETTINGS = settings(max_examples=40, deadline=None, derandomize=True)
seeds = st.integers(0, 2**32 - 1)


def unit(v):
    return v / np.linalg.norm(v)


def arc(rng, k):
    """Points rotated about a random axis u through a random point a at increasing angles."""
    u = unit(rng.normal(size=3))
    a = rng.uniform(-1, 1, 3)
    offset = rng.uniform(-1, 1, 3)
    offset -= u * (u @ offset)
    offset = unit(offset) * rng.uniform(0.05, 0.8) + u * rng.uniform(-0.3, 0.3)
    angles = np.sort(rng.uniform(-1.5, 1.5, k))
    angles = angles[0] + (angles - angles[0]) * max(1.0, 0.8 / np.ptp(angles))  # span >= 0.8 rad
    points = np.array([a + pin.exp3(q * u) @ offset for q in angles])
    center = a + u * (u @ offset)
    return points, angles, u, center, np.linalg.norm(offset - u * (u @ offset))


@SETTINGS
@given(seed=seeds, k=st.integers(3, 12))
def test_axis_recovered_with_right_hand_sign(seed, k):
    rng = np.random.default_rng(seed)
    points, angles, u, center, radius = arc(rng, k)
    np.testing.assert_allclose(circle_axis(points, angles), u, atol=1e-12)
    fit = fit_circle(points, angles)
    np.testing.assert_allclose(fit.center, center, atol=1e-10)
    assert fit.radius == pytest.approx(radius, abs=1e-10)
    assert fit.rms_out_of_plane < 1e-12
    perm = rng.permutation(k)  # input order does not matter, only the angles do
    np.testing.assert_allclose(circle_axis(points[perm], angles[perm]), u, atol=1e-12)
    np.testing.assert_allclose(circle_axis(points, angles[::-1]), -u, atol=1e-12)  # reversed order flips
    np.testing.assert_allclose(circle_axis(points, -angles), -u, atol=1e-12)


def test_fit_circle_noise_and_out_of_plane_rms():
    """Points pushed alternately +-h along the axis, and by up to h radially (in the
    plane: not part of the out-of-plane RMS). The true plane leaves exactly h,
    so the best plane cannot leave more. To first order in h / (in-plane spread)
    the best plane is the least-squares regression of the offsets on the in-plane
    coordinates (true plane, noise-free points): its residual and slope give the
    fit's RMS and tilt, with relative errors of second order, below h / spread."""
    rng = np.random.default_rng(3)
    points, angles, u, center, radius = arc(rng, 40)
    h = 1e-4
    signs = np.where(np.arange(40) % 2 == 0, 1.0, -1.0)  # alternating offsets along the axis
    outward = np.array([unit(v) for v in points - center])
    radial = h * np.array([1.0, 0.0, -1.0])[np.arange(40) % 3]
    fit = fit_circle(points + h * signs[:, None] * u + radial[:, None] * outward, angles)
    assert fit.rms_out_of_plane <= h * (1 + 1e-12)
    e1 = unit(np.cross(u, [1.0, 0.0, 0.0] if abs(u[0]) < 0.9 else [0.0, 1.0, 0.0]))
    in_plane = np.column_stack([(points - center) @ e1, (points - center) @ np.cross(u, e1), np.ones(40)])
    slope, *_ = np.linalg.lstsq(in_plane, h * signs, rcond=None)
    residual = h * signs - in_plane @ slope
    spread = np.linalg.svd(in_plane[:, :2] - in_plane[:, :2].mean(axis=0), compute_uv=False)[-1] / np.sqrt(40)
    second_order = h / spread  # 3e-3 here
    assert fit.rms_out_of_plane == pytest.approx(np.sqrt(np.mean(residual**2)), rel=second_order)
    tilt = np.arctan2(np.linalg.norm(np.cross(fit.axis, u)), fit.axis @ u)
    assert tilt == pytest.approx(np.hypot(*slope[:2]), rel=second_order)


def test_point_on_axis_is_rejected():
    u = unit(np.array([0.2, -0.5, 0.8]))
    a = np.array([0.3, 0.1, -0.2])
    angles = np.linspace(0.0, 2.0, 8)
    on_axis = np.array([a + pin.exp3(q * u) @ (0.4 * u) for q in angles])
    with pytest.raises(CalibrationError, match="on the joint axis"):
        circle_axis(on_axis, angles)
    noisy = on_axis + np.random.default_rng(0).normal(0, 1e-4, on_axis.shape)
    with pytest.raises(CalibrationError, match="on the joint axis"):
        circle_axis(noisy, angles)
    tiny = np.array([a + pin.exp3(q * u) @ (0.4 * u + 2e-4 * unit(np.cross(u, [1, 0, 0]))) for q in angles])
    with pytest.raises(CalibrationError, match="radius .* too small"):
        circle_axis(tiny + np.random.default_rng(1).normal(0, 1e-4, tiny.shape), angles)


@pytest.mark.parametrize(
    "points, angles, match",
    [
        (np.eye(3)[:2], [0.0, 1.0], "at least 3"),
        (np.eye(3), [0.0, 1.0], "angles"),
        (np.ones((4, 2)), np.arange(4.0), "points must be"),
        (np.outer(np.arange(4.0), [1.0, 2.0, 3.0]), np.arange(4.0) * 0.1, "collinear"),
        (np.eye(3) * [1, np.nan, 1], [0.0, 0.1, 0.2], "NaN"),
        (np.eye(3), [0.0, 0.1, 4.0], "π or more"),
    ],
)
def test_circle_errors(points, angles, match):
    with pytest.raises(CalibrationError, match=match):
        circle_axis(points, angles)


@pytest.mark.parametrize("alpha", [1e-6, 0.3, np.pi / 2, 2.9, np.pi - 1e-6])  # extremes: arccos would lose 1e-10
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_twist_of_two_axes(alpha, sign):
    b1 = np.array([0.0, 0.0, 1.0])
    b2 = pin.exp3(np.array([sign * alpha, 0.0, 0.0])) @ b1
    nominal = np.array([sign * (alpha + 0.05), 0.7])
    np.testing.assert_allclose(twists_from_axes([b1, b2], nominal), [sign * alpha, 0.7], atol=1e-12)
    # the axes' own orientation does not enter, only the nominal sign (eq 9)
    np.testing.assert_allclose(twists_from_axes([b1, b2], -nominal), [-sign * alpha, -0.7], atol=1e-12)


@SETTINGS
@given(seed=seeds, n=st.integers(2, 7))
def test_twists_of_a_dh_chain(seed, n):
    rng = np.random.default_rng(seed)
    alpha = rng.uniform(0.05, 3.0, n) * rng.choice([-1.0, 1.0], n)
    frame = pin.exp3(rng.normal(size=3))
    axes = [frame[:, 2]]
    for k in range(n - 1):  # F_n = F_{n-1} Rz(theta) Rx(alpha_n): axis b_{n+1} is its z column
        frame = frame @ pin.exp3(np.array([0, 0, rng.uniform(-3, 3)])) @ pin.exp3(np.array([alpha[k], 0, 0]))
        axes.append(frame[:, 2])
    scaled = np.array(axes) * rng.uniform(0.5, 2.0, (n, 1))  # axes need not be unit length
    nominal = alpha + rng.uniform(-0.04, 0.04, n)
    expected = np.append(alpha[:-1], nominal[-1])
    np.testing.assert_allclose(twists_from_axes(scaled, nominal), expected, atol=1e-12)


def test_zero_nominal_twist_keeps_zero():
    axes = [[0.0, 0.0, 1.0], [0.0, np.sin(0.01), np.cos(0.01)]]
    np.testing.assert_allclose(twists_from_axes(axes, [0.0, 0.2]), [0.0, 0.2])


@pytest.mark.parametrize(
    "axes, nominal, match",
    [
        (np.eye(3), [0.0, 0.0], "nominal_alpha"),
        (np.zeros((0, 3)), [], "N >= 1"),
        ([[0, 0, 1.0], [0, 0, 0]], [0.1, 0.0], "zero length"),
        ([[0, 0, 1.0], [0, np.nan, 1]], [0.1, 0.0], "NaN"),
    ],
)
def test_twist_errors(axes, nominal, match):
    with pytest.raises(CalibrationError, match=match):
        twists_from_axes(axes, nominal)
