"""Linearised (Cramér–Rao) predictions of pincal.paper.noise_limit.

The linearisation is checked against finite differences of the whole
estimator (every stage re-run on perturbed data) and against the estimator's
answer to a whole noise draw; the propagation to the test poses against a
forward model written here in numpy; the ML covariance against the Cramér–Rao
bound of that independent model; the mean-norm quadrature against closed forms
and sampling; and the predicted mean errors against a Monte Carlo run of the
methods on the same configurations.
"""

from __future__ import annotations

import functools
from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest
from scipy.spatial.transform import Rotation

from pincal.errors import CalibrationError
from pincal.fit.gaussian_norm import mean_norm
from pincal.fit.metrics import pose_errors
from pincal.model.chain import KinematicChain
from pincal.model.dh.table import KUKA_LWR4_DH, TABLE2_LARGE, TABLE2_SMALL
from pincal.paper.methods import calibrate_paper
from pincal.paper.ml_estimator import calibrate_ml
from pincal.paper.noise_limit import predicted_errors
from pincal.robots import KUKA_FLANGE_LINK, kuka_lwr4plus_urdf
from pincal.simulation.paper import SimulationSettings, simulate_experiment

SMALL = SimulationSettings(seed=4, n_cpa=10, n_calibration=60, n_validation=10)


@functools.cache
def _small(method):
    """The noise-free SMALL experiment (Table 2's large deviations) and the prediction of ``method`` for it at
    σ_p = 0.05 mm, σ_a = 0.1 deg: the same numbers for every test that checks that prediction, made once
    (ML's takes ~0.4 s). Read only."""
    chain = KinematicChain.from_urdf(kuka_lwr4plus_urdf(), KUKA_FLANGE_LINK)
    experiment = simulate_experiment(chain, KUKA_LWR4_DH, TABLE2_LARGE, SMALL)
    return experiment, predicted_errors(chain, experiment, method, 0.05, 0.1)


def _calibrate(chain, data, method, sigma=(0.05, 0.1), nominal=None):
    if method == "ml":
        return calibrate_ml(chain, data, *sigma, nominal=nominal)
    return calibrate_paper(chain, data, method, nominal=nominal)


def test_mean_norm_matches_closed_forms_and_sampling():
    assert abs(mean_norm(np.eye(3) * 4.0) - 2.0 * 2.0 * np.sqrt(2.0 / np.pi)) < 1e-12  # chi_3 mean
    assert abs(mean_norm(np.diag([1.0, 0.0, 0.0])) - np.sqrt(2.0 / np.pi)) < 2e-3  # half-normal
    a = np.random.default_rng(0).normal(size=(3, 3))
    covariance = a @ a.T + np.diag([0.0, 0.1, 2.0])
    samples = np.random.default_rng(1).multivariate_normal(np.zeros(3), covariance, 400_000)
    sampled = np.linalg.norm(samples, axis=1).mean()
    assert abs(mean_norm(covariance) / sampled - 1) < 4e-3  # sampling sd ~ 1e-3


@pytest.mark.parametrize("method", [1, 2, 3, "ml"])
def test_linearisation_matches_finite_differences_of_the_whole_estimator(kuka_urdf, method):
    """Perturb single noise components of the data and re-run every stage of the method.

    The change of the DH vector and of both registrations (left rotation φ and
    τ) must equal the predicted column of d(parameters)/d(noise): CPA points,
    calibration positions and calibration orientations, through all stages.
    """
    experiment, prediction = _small(method)
    chain = KinematicChain.from_urdf(kuka_urdf, KUKA_FLANGE_LINK, tool=experiment.tool)
    data = experiment.calibration
    truth = experiment.registration

    def estimate(row, component, h):
        points, rotations = data.points.copy(), data.rotations.copy()
        if component < 3:
            points[row, 0, component] += h
        else:
            rotations[row] = pin.exp3(h * np.eye(3)[component - 3]) @ rotations[row]
        result = _calibrate(chain, replace(data, points=points, rotations=rotations), method, nominal=experiment.truth)
        parts = [result.table.to_vector()]
        for registration in (result.registration_position, result.registration_orientation):
            parts += [pin.log3(registration.rotation @ truth.rotation.T), registration.translation]
        return np.concatenate(parts)

    cpa, calibration = np.flatnonzero(data.roles == "cpa"), np.flatnonzero(data.roles == "calibration")
    for row, component in [(cpa[3], 0), (cpa[45], 2), (calibration[5], 1), (calibration[40], 3), (calibration[7], 5)]:
        numeric = (estimate(row, component, 1e-6) - estimate(row, component, -1e-6)) / 2e-6
        column = prediction.sensitivity[:, 6 * row + component]
        scale = max(np.abs(numeric).max(), 1e-3)
        assert np.abs(column - numeric).max() / scale < 1e-4, (row, component)


def _draw_estimate(chain, experiment, method, z, sigma):
    """Parameters [DH vector, Registration 1 (φ, τ), Registration 2 (φ, τ)] the method estimates
    from the noise-free rows plus the noise ``z`` (K, 6): g + ζ and G → exp(ξ) G, as in the
    columns of ``PredictedErrors.sensitivity``; φ is the left rotation from the true registration."""
    data, truth = experiment.calibration, experiment.registration
    points = data.points + z[:, None, :3]
    rotations = Rotation.from_rotvec(z[:, 3:]).as_matrix() @ data.rotations
    result = _calibrate(chain, replace(data, points=points, rotations=rotations), method, sigma, experiment.truth)
    parts = [result.table.to_vector()]
    for registration in (result.registration_position, result.registration_orientation):
        parts += [pin.log3(registration.rotation @ truth.rotation.T), registration.translation]
    return np.concatenate(parts)


@pytest.mark.parametrize("method", [1, 2, 3, "ml"])
def test_estimator_answers_a_noise_draw_linearly_with_the_predicted_slope(kuka_urdf, method):
    """Run the whole estimator on one draw of noise on every row (CPA and calibration,
    positions and orientations) scaled by s, and compare its change with sensitivity @ (s z).

    If the sensitivity is the estimator's derivative, Taylor's theorem makes the misfit
    second order: relative to the change it is c·s, so it falls tenfold from s = 0.1 to
    s = 0.01. A sensitivity off by a relative δ in any direction the draw excites leaves a
    misfit ≈ δ at every s instead. The misfit at s = 0.01 must also stay below 1e-4, the
    accuracy the finite-difference test above asks of single columns. (Here c ≈ 7e-4 for
    Methods 1-3 and 4e-5 for ML at σ_p = 0.05 mm, σ_a = 0.1 deg.)
    """
    sigma = (0.05, 0.1)
    experiment, prediction = _small(method)  # noise-free rows
    chain = KinematicChain.from_urdf(kuka_urdf, KUKA_FLANGE_LINK, tool=experiment.tool)
    n_rows = experiment.calibration.n_rows
    z = np.random.default_rng(7).normal(size=(n_rows, 6)) * np.repeat([sigma[0] / 1000, np.radians(sigma[1])], 3)
    start = _draw_estimate(chain, experiment, method, np.zeros_like(z), sigma)
    misfit = {}
    for s in (0.01, 0.1):
        change = _draw_estimate(chain, experiment, method, s * z, sigma) - start
        linear = prediction.sensitivity @ (s * z).ravel()
        misfit[s] = np.abs(change - linear).max() / np.abs(linear).max()
    assert misfit[0.01] < 1e-4, misfit
    assert 8 < misfit[0.1] / misfit[0.01] < 12, misfit  # second order: tenfold for a tenfold s


def _tool_poses(vector, q, tool):
    """base_T_tool (K, 4, 4) of the DH table ``vector`` = [α, ε, r, d] at readings ``q`` (K, N):
    F_1 ··· F_N F_T with F_n = Rz(θ_n + ε_n) Tz(d_n) Tx(r_n) Rx(α_n) (eq 2, 4-5), in numpy."""
    alpha, epsilon, r, d = np.asarray(vector, dtype=float).reshape(4, -1)
    pose = np.broadcast_to(np.eye(4), (len(q), 4, 4))
    for n in range(alpha.size):
        c, s = np.cos(q[:, n] + epsilon[n]), np.sin(q[:, n] + epsilon[n])
        ca, sa = np.cos(alpha[n]), np.sin(alpha[n])
        link = np.zeros((len(q), 4, 4))
        link[:, 0] = np.stack([c, -s * ca, s * sa, r[n] * c], axis=1)
        link[:, 1] = np.stack([s, c * ca, -c * sa, r[n] * s], axis=1)
        link[:, 2, 1:] = sa, ca, d[n]
        link[:, 3, 3] = 1.0
        pose = pose @ link
    return pose @ tool


def _reading_jacobian(experiment, q, columns, h=1e-6):
    """d(sensor reading)/dp by central differences, (K, 6, len(columns)), for p = [DH vector, φ, τ].

    The reading of row k is g = Ω t + τ [m] and the rotation vector of G G₀ᵀ [rad] with
    G = Ω R (eq 20-21 without noise), Ω = exp(φ) Ω₀ (φ a left rotation of the true
    registration, the prediction's convention), at p₀ = [truth, 0, τ₀]: the sensor's noise
    ζ and ξ (G → exp(ξ) G) add to exactly these coordinates.
    """
    registration = experiment.registration
    p0 = np.concatenate([experiment.truth.to_vector(), np.zeros(3), registration.translation])
    n_dh = p0.size - 6

    def reading(p):
        pose = _tool_poses(p[:n_dh], q, experiment.tool)
        omega = Rotation.from_rotvec(p[n_dh : n_dh + 3]).as_matrix() @ registration.rotation
        return pose[:, :3, 3] @ omega.T + p[n_dh + 3 :], omega @ pose[:, :3, :3]

    _, rotations0 = reading(p0)
    jac = np.zeros((len(q), 6, len(columns)))
    for i, column in enumerate(columns):
        step = np.zeros_like(p0)
        step[column] = h
        (g_plus, r_plus), (g_minus, r_minus) = reading(p0 + step), reading(p0 - step)
        jac[:, :3, i] = (g_plus - g_minus) / (2 * h)
        turn = Rotation.from_matrix(r_plus @ rotations0.transpose(0, 2, 1)).as_rotvec()
        back = Rotation.from_matrix(r_minus @ rotations0.transpose(0, 2, 1)).as_rotvec()
        jac[:, 3:, i] = (turn - back) / (2 * h)
    return jac


def _noise_scale(sigma_pos_mm, sigma_rot_deg, n_rows):
    """Standard deviation of each noise component (eq 20-22), row by row: σ_p [m] per axis, σ_a [rad] per component."""
    return np.tile(np.repeat([sigma_pos_mm / 1000.0, np.radians(sigma_rot_deg)], 3), n_rows)


@pytest.mark.parametrize("method", [1, 2, 3, "ml"])
def test_predicted_test_pose_errors_follow_from_an_independent_forward_model(method):
    """Propagate the sensitivity to the J test poses with a forward model of our own.

    C_j = G_j S Σ_z Sᵀ G_jᵀ, with G_j the numpy DH model's finite-difference derivative of
    test pose j's reading (position through Registration 1, orientation through
    Registration 2; Method 1 and ML have one registration, copied into both), S the
    sensitivity (checked against the estimator itself above) and Σ_z built here from
    σ_p ≠ σ_a. E‖e_j‖ for e_j ~ N(0, C_j) is ``mean_norm`` (checked against closed forms
    and sampling above). Tolerance 1e-6: finite differences with h = 1e-6 are accurate
    to ~1e-9.
    """
    sigma_pos_mm, sigma_rot_deg = 0.05, 0.1
    experiment, prediction = _small(method)
    n_dh = experiment.truth.to_vector().size
    jac = _reading_jacobian(experiment, experiment.validation.q, np.arange(n_dh + 6))
    scaled = prediction.sensitivity * _noise_scale(sigma_pos_mm, sigma_rot_deg, experiment.calibration.n_rows)
    registration = {"position": np.arange(n_dh, n_dh + 6), "orientation": np.arange(n_dh + 6, n_dh + 12)}
    expected = {}
    for which, part in (("position", slice(0, 3)), ("orientation", slice(3, 6))):
        effect = jac[:, part, :] @ scaled[np.concatenate([np.arange(n_dh), registration[which]])]  # (J, 3, 6K)
        expected[which] = mean_norm(effect @ effect.transpose(0, 2, 1))
    np.testing.assert_allclose(prediction.position_per_pose_mm, 1000.0 * expected["position"], rtol=1e-6)
    np.testing.assert_allclose(prediction.rotation_per_pose_deg, np.degrees(expected["orientation"]), rtol=1e-6)
    assert prediction.position_mm == pytest.approx(1000.0 * expected["position"].mean(), rel=1e-6)
    assert prediction.rotation_deg == pytest.approx(np.degrees(expected["orientation"].mean()), rel=1e-6)


def test_ml_prediction_is_the_cramer_rao_bound_of_an_independent_model():
    """The ML covariance against (JᵀΣ⁻¹J)⁻¹ built without pincal's residuals or Jacobians.

    J: finite differences of the numpy DH model's readings of every CPA and calibration
    row with respect to the ML unknowns (every DH parameter but the registration's gauge
    ε_1 and d_1, then φ and τ); Σ: σ_p = 0.05 mm per axis and σ_a = 0.1 deg per component
    (unequal, so a swapped or mis-scaled σ shows). The bound must be the predicted
    covariance of the DH parameters with either registration (the ML estimator has one),
    and, propagated to the test poses by the same model, give the predicted mean errors.
    Tolerance 1e-6: finite differences with h = 1e-6 are accurate to ~1e-9.
    """
    sigma_pos_mm, sigma_rot_deg = 0.05, 0.1
    experiment, prediction = _small("ml")
    n_joints = experiment.truth.n_joints
    n_dh = 4 * n_joints
    gauge = [n_joints, 3 * n_joints]  # ε_1 and d_1 in the flat [α, ε, r, d] vector
    free = np.array([i for i in range(n_dh + 6) if i not in gauge])
    jac = _reading_jacobian(experiment, experiment.calibration.q, free).reshape(-1, free.size)
    weighted = jac / _noise_scale(sigma_pos_mm, sigma_rot_deg, experiment.calibration.n_rows)[:, None]
    bound = np.linalg.inv(weighted.T @ weighted)

    covariance = prediction.covariance
    second = np.concatenate([free[free < n_dh], free[free >= n_dh] + 6])  # DH and Registration 2
    for index in (free, second):
        assert np.abs(covariance[np.ix_(index, index)] - bound).max() < 1e-6 * np.abs(bound).max()
    assert not covariance[gauge].any() and not covariance[:, gauge].any()
    assert prediction.parameter_names[n_dh] == "registration_position_phi_x"

    test = _reading_jacobian(experiment, experiment.validation.q, free)
    errors = test @ bound @ test.transpose(0, 2, 1)  # (J, 6, 6): covariance of each test pose's error
    np.testing.assert_allclose(prediction.position_per_pose_mm, 1000.0 * mean_norm(errors[:, :3, :3]), rtol=1e-6)
    np.testing.assert_allclose(prediction.rotation_per_pose_deg, np.degrees(mean_norm(errors[:, 3:, 3:])), rtol=1e-6)


def test_chain_is_restored_and_bad_arguments_are_refused(kuka_chain):
    experiment = simulate_experiment(kuka_chain, KUKA_LWR4_DH, TABLE2_SMALL, SMALL)
    placements, tool = kuka_chain.placements(), kuka_chain.tool
    predicted_errors(kuka_chain, experiment, 2, 0.05, 0.05)
    assert all(np.array_equal(a, b) for a, b in zip(placements, kuka_chain.placements()))
    assert np.array_equal(tool, kuka_chain.tool)
    with pytest.raises(CalibrationError, match="method must be one of"):
        predicted_errors(kuka_chain, experiment, 4, 0.05, 0.05)
    with pytest.raises(CalibrationError, match="both sigmas"):
        predicted_errors(kuka_chain, experiment, "ml", 0.05, 0.0)


def _add_noise(data, sigma_pos_mm, sigma_rot_deg, rng):
    """Eq 20–22: g + zeta, R_ZYX(xi) G, with per-component Gaussian zeta and xi."""
    points = data.points + rng.normal(0.0, sigma_pos_mm / 1000.0, data.points.shape)
    noise = Rotation.from_euler("ZYX", rng.normal(0.0, np.radians(sigma_rot_deg), (data.n_rows, 3)))
    return replace(data, points=points, rotations=noise.as_matrix() @ data.rotations)


@pytest.mark.parametrize("method, draws", [(1, 100), (2, 100), ("ml", 30)])
def test_monte_carlo_errors_match_the_prediction(kuka_urdf, kuka_chain, method, draws):
    """Paper experiment (Section 7 sizes), sigma = 0.05 mm / 0.05 deg, fixed configurations.

    The mean over noise draws of the truth-referenced held-out errors must be
    within 15% of the prediction. One draw's mean error over the 50 poses
    scatters by ~45% (Methods 1, 2) or ~15-30% (ML) around its expectation, so
    100 and 30 draws put 15% at ~3 standard errors. Measured with 200 draws:
    MC/prediction = 1.03, 1.01 (position) and 1.00, 1.01 (orientation) for
    Methods 1, 2; 0.99 and 1.02 for ML.
    """
    experiment = simulate_experiment(kuka_chain, KUKA_LWR4_DH, TABLE2_LARGE, SimulationSettings(seed=1))
    prediction = predicted_errors(kuka_chain, experiment, method, 0.05, 0.05)
    chain = KinematicChain.from_urdf(kuka_urdf, KUKA_FLANGE_LINK, tool=experiment.tool)
    rng = np.random.default_rng(100)
    errors = []
    for _ in range(draws):
        data = _add_noise(experiment.calibration, 0.05, 0.05, rng)
        result = _calibrate(chain, data, method, sigma=(0.05, 0.05), nominal=KUKA_LWR4_DH)
        with chain.placed(result.chain_placements):
            held_out = pose_errors(
                chain, experiment.validation, result.registration_position, result.registration_orientation
            )
        errors.append((held_out.position.mean, held_out.rotation.mean))
    position, rotation = np.mean(errors, axis=0)
    assert abs(position / prediction.position_mm - 1) < 0.15, (position, prediction.position_mm)
    assert abs(rotation / prediction.rotation_deg - 1) < 0.15, (rotation, prediction.rotation_deg)
