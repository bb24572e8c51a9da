"""The analytic CPA derivatives (pincal.paper.cpa.circle_axis_derivative, twist_gradients)
against the central finite differences that pincal.paper.noise_limit used before them.

The noise limit once differentiated the plane normal of every joint's arc by
central differences of :func:`circle_axis` with a step h = 1e-6 m on each point coordinate
(2 × 3K circle fits per arc), and the twists of eq 9 by central differences of
:func:`twists_from_axes` with h = 1e-6 on each axis component. ``_central_differences``
below is that loop. Central differences differ from the derivative by a truncation
error h²/6 · f‴ and a rounding error ~ε_mach · |f| / h. The normal turns by ~h · |f′|
for a step h and its higher derivatives grow like powers of |f′| (each divides by the
arc's in-plane spread), so the truncation is ~(h · |f′|)² relative: 1e-10 for a well
spread arc (|f′| ~ 10 m⁻¹), but 2.5e-7 for three nearly collinear points (|f′| ~ 760 m⁻¹;
it falls 100-fold for h = 1e-7 m, so the analytic value is the right one). The rounding,
with |b| = 1 and the fit's own rounding ~10 ε_mach, is ~1e-15 / 1e-6 = 1e-9 absolute
against |f′| ≥ 0.1 m⁻¹ here, ≤ 1e-8 relative. The tolerance is therefore
(1e-7 + (h · max|f′|)²) of the largest entry: a factor ≥ 10 above the rounding and
≥ 2 above the truncation.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pincal.errors import CalibrationError
from pincal.model.dh.parameters import DHParameterSet
from pincal.model.dh.table import KUKA_LWR4_DH, TABLE2_LARGE
from pincal.paper.cpa import (
    circle_axis,
    circle_axis_derivative,
    twist_gradients,
    twists_from_axes,
)
from pincal.paper.methods import FROM_CPA, calibrate_paper, cpa_groups
from pincal.paper.noise_limit import predicted_errors
from pincal.simulation.paper import SimulationSettings, simulate_experiment

STEP = 1e-6  # the finite-difference step noise_limit used [m] (axes: [1])
RELATIVE = 1e-7  # of the largest derivative entry: rounding (module docstring)
SETTINGS = settings(max_examples=60, deadline=None, derandomize=True)


def _tolerance(reference: np.ndarray) -> float:
    """Absolute tolerance for central differences ``reference``: rounding + truncation (docstring)."""
    largest = np.abs(reference).max()
    return largest * (RELATIVE + (STEP * largest) ** 2)


def _central_differences(function, x: np.ndarray, step: float = STEP) -> np.ndarray:
    """d function / d x by central differences, one coordinate of ``x`` at a time: (*out, *x.shape)."""
    columns = []
    for index in np.ndindex(x.shape):
        delta = np.zeros_like(x)
        delta[index] = step
        columns.append((function(x + delta) - function(x - delta)) / (2.0 * step))
    return np.moveaxis(np.array(columns), 0, -1).reshape(*np.shape(columns[0]), *x.shape)


def _arc(rng: np.random.Generator, k: int, out_of_plane_m: float) -> tuple[np.ndarray, np.ndarray]:
    """K points rotated about a random axis (radius 0.05–0.8 m, span >= 0.8 rad), plus
    Gaussian scatter of ``out_of_plane_m`` so the out-of-plane offsets h_k are not all 0."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    offset = rng.normal(size=3)
    offset -= axis * (axis @ offset)
    offset *= rng.uniform(0.05, 0.8) / np.linalg.norm(offset)
    angles = np.sort(rng.uniform(-1.5, 1.5, k))
    angles = angles[0] + (angles - angles[0]) * max(1.0, 0.8 / np.ptp(angles))
    centre = rng.uniform(-1, 1, 3)
    points = np.array([centre + pin.exp3(q * axis) @ offset for q in angles])
    return points + rng.normal(scale=out_of_plane_m, size=points.shape), angles


@SETTINGS
@given(seed=st.integers(0, 2**32 - 1), k=st.integers(3, 12), scatter=st.sampled_from([0.0, 1e-4, 2e-3]))
def test_axis_derivative_equals_the_central_differences_it_replaced(seed, k, scatter):
    points, angles = _arc(np.random.default_rng(seed), k, scatter)
    axis, derivative = circle_axis_derivative(points, angles)
    assert np.array_equal(axis, circle_axis(points, angles))  # the fit itself is untouched
    reference = _central_differences(lambda p: circle_axis(p, angles), points)  # (3, K, 3)
    assert derivative.shape == reference.shape == (3, k, 3)
    np.testing.assert_allclose(derivative, reference, rtol=0, atol=_tolerance(reference))
    np.testing.assert_allclose(axis @ derivative.reshape(3, -1), 0.0, atol=1e-12)  # stays a unit vector


def test_axis_derivative_refuses_what_the_fit_refuses():
    points, angles = _arc(np.random.default_rng(0), 6, 0.0)
    with pytest.raises(CalibrationError, match="collinear"):
        circle_axis_derivative(points[:, :1] * [1.0, 2.0, 3.0], angles)


def test_points_off_a_plane_are_refused():
    """A long box with a square cross-section (the two smallest singular values equal, 0.02 m):
    the plane normal may turn freely between them, so neither the axis nor its derivative
    (1 / (s3^2 - s2^2)) exists; and a short arc whose sagitta is within the noise."""
    square = 0.01 * np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0]] * 2)
    points = np.column_stack([np.repeat([-0.5, 0.5], 4), square])
    angles = 0.3 * np.arange(8)
    for function in (circle_axis, circle_axis_derivative):
        with pytest.raises(CalibrationError, match="do not lie on a plane"):
            function(points, angles)
    rng = np.random.default_rng(5)
    angles = np.linspace(0.0, 0.02, 12)  # 1.1 deg of a 0.3 m arc: sagitta 15 um, noise 50 um
    arc = 0.3 * np.column_stack([np.cos(angles), np.sin(angles), np.zeros(12)])
    with pytest.raises(CalibrationError, match="do not lie on a plane"):
        circle_axis(arc + rng.normal(scale=5e-5, size=arc.shape), angles)
    circle_axis(arc + rng.normal(scale=5e-8, size=arc.shape), angles)  # 50 nm: the plane holds


@SETTINGS
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(2, 7))
def test_twist_gradients_equal_central_differences(seed, n):
    rng = np.random.default_rng(seed)
    axes = rng.normal(size=(n, 3)) * rng.uniform(0.5, 2.0, (n, 1))  # any length, as eq 9 allows
    nominal = rng.choice([-1.0, 0.0, 1.0], n) * rng.uniform(0.1, 3.0, n)
    gradients = twist_gradients(axes, nominal)  # (n − 1, 2, 3)
    reference = _central_differences(lambda b: twists_from_axes(b, nominal), axes)  # (n, n, 3)
    for i in range(n - 1):
        expected = np.stack([reference[i, i], reference[i, i + 1]])
        np.testing.assert_allclose(gradients[i], expected, rtol=0, atol=_tolerance(expected) + RELATIVE)
        if nominal[i] == 0:
            assert not gradients[i].any()  # eq 9 gives the constant 0


def test_noise_limit_twist_rows_equal_the_finite_difference_loop(kuka_chain):
    """The CPA twists' rows of the noise limit's sensitivity (Method 1: no later stage frees a
    CPA twist) against the loop it replaced, on noise-free simulated rows of the KUKA LWR 4+."""
    experiment = simulate_experiment(
        kuka_chain, KUKA_LWR4_DH, TABLE2_LARGE, SimulationSettings(seed=4, n_cpa=10, n_calibration=60, n_validation=10)
    )
    sensitivity = predicted_errors(kuka_chain, experiment, 1, 1.0, 1.0).sensitivity
    data = experiment.calibration
    result = calibrate_paper(kuka_chain, data, 1, nominal=experiment.truth)
    alpha = DHParameterSet(kuka_chain, result.nominal).indices("alpha")
    estimated = [i for i, j in enumerate(alpha) if result.status[j] == FROM_CPA]
    assert len(estimated) == 6
    cpa = np.flatnonzero(data.roles == "cpa")
    q, points = data.q[cpa], data.points[cpa, 0]
    axes, d_axes = {}, {}
    for joint, rows in cpa_groups(q).items():
        axes[joint] = circle_axis(points[rows], q[rows, joint])
        angles = q[rows, joint]
        arc = _central_differences(lambda p, angles=angles: circle_axis(p, angles), points[rows])  # (3, K, 3)
        d_axes[joint] = np.zeros((3, sensitivity.shape[1]))
        d_axes[joint][:, (6 * cpa[rows][:, None] + np.arange(3)).ravel()] = arc.reshape(3, -1)
    nominal = result.nominal.alpha
    for i in estimated:
        pair = np.stack([axes[i], axes[i + 1]])
        signs = nominal[i : i + 2]
        grad = _central_differences(lambda b, signs=signs: twists_from_axes(b, signs)[0], pair)  # (2, 3)
        expected = grad[0] @ d_axes[i] + grad[1] @ d_axes[i + 1]
        np.testing.assert_allclose(sensitivity[alpha[i]], expected, rtol=0, atol=_tolerance(expected))
