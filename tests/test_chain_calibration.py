"""Calibration of arbitrary chains (TIAGo with its prismatic torso, Panda, UR5).

Simulated data: noise-free data must be fitted exactly (held-out prediction
error < 1e-8 m); noisy data must reach the noise-limited prediction. Plus the
Jacobian of the absolute residual, identifiability and outlier reports.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from conftest import assert_close, numeric_jacobian
from scipy.stats import chi2
from scipy.stats import t as student_t

from pincal.fit.chain_calibration import ChainFitOptions, calibrate_chain
from pincal.fit.pipeline import NOT_IDENTIFIABLE
from pincal.model.chain import KinematicChain
from pincal.model.parameter_sets import JointOffsets, PlacementErrors
from pincal.model.sensor import Registration
from pincal.residuals.base import KinematicsCache
from pincal.residuals.sensor import SensorResidual, TargetEstimate
from pincal.residuals.sensor_values import RowWeights
from pincal.robots import example_robot_data_urdf
from pincal.simulation.chain import simulate_chain
from pincal.simulation.paper import SimulationSettings

ROBOTS = {
    "tiago": ("tiago_description/robots/tiago.urdf", "wrist_ft_tool_link"),
    "panda": ("panda_description/urdf/panda.urdf", "panda_link8"),
    "ur5": ("ur_description/urdf/ur5_robot.urdf", "tool0"),
}
MARKERS = np.array([[0.05, 0.0, 0.07], [0.07, 0.0, -0.08], [0.16, 0.0, -0.05], [0.15, 0.01, 0.06]])


def _chain(name):
    relative, tip = ROBOTS[name]
    return KinematicChain.from_urdf(example_robot_data_urdf(relative), tip)


def _truth(params, rng, scale=1.0):
    """Placement errors of about 1 mm and 1 mrad per component."""
    if isinstance(params, PlacementErrors):
        return rng.normal(0.0, 1e-3 * scale, params.size)
    return rng.normal(0.0, 2e-3 * scale, params.size)


def _heldout_error(chain, result, experiment):
    """Truth-referenced held-out point errors of the calibrated model [m], (J, P)."""
    with chain.placed(result.chain_placements):
        poses = chain.poses(experiment.validation.q)
    world = poses.tool_positions[:, None, :] + np.einsum("kij,pj->kpi", poses.tool_rotations, result.target.points)
    predicted = result.target.registration.apply_points(world)
    return np.linalg.norm(predicted - experiment.validation.points, axis=2)


@pytest.mark.parametrize(
    "robot, level, points, with_rotation",
    [
        ("tiago", "full", MARKERS, False),   # prismatic torso + four markers of one rigid body
        ("tiago", "offsets", MARKERS[:1], False),
        ("panda", "full", MARKERS[:3], False),
        ("panda", "offsets", MARKERS[:1], True),
        ("ur5", "full", MARKERS[:1], True),  # full 6D pose measurements
        ("ur5", "offsets", MARKERS, False),
    ],
)
def test_noise_free_data_is_fitted_exactly(robot, level, points, with_rotation):
    chain = _chain(robot)
    params = (PlacementErrors if level == "full" else JointOffsets)(chain)
    rng = np.random.default_rng(5)
    settings = SimulationSettings(n_calibration=60, n_validation=30, seed=9, validation_noise=False)
    experiment = simulate_chain(params, _truth(params, rng), points, settings, with_rotation=with_rotation)
    result = calibrate_chain(chain, experiment.calibration, level)
    # noise-free: only the solver's tolerance (1e-12 relative) remains; 1e-8 m is
    # far above it and far below the ~1 mm placement errors simulated
    assert _heldout_error(chain, result, experiment).max() < 1e-8
    assert result.rank > 0 and result.selection.chosen == result.rank


@pytest.mark.parametrize("robot, points", [("panda", MARKERS[:3]), ("ur5", MARKERS[:2])])
def test_noisy_heldout_error_matches_noise_limited_prediction(robot, points):
    """Full level, sigma 0.1 mm, 8 seeds: the Monte Carlo RMS agrees with the linearised
    prediction within the Monte Carlo's own uncertainty.

    R = mean(observed MSE) / mean(predicted MSE) is a ratio estimator; its standard
    error is sd(observed − R predicted) / (sqrt(n) mean(predicted)), and that of
    sqrt(R) half of it relative. The bound is the two-sided 1% point of Student's
    t with n − 1 = 7 degrees of freedom times that standard error. At 0.1 mm the
    linearisation error is of order (0.1 mm / 1 m)² relative, negligible.
    """
    chain = _chain(robot)
    params = PlacementErrors(chain)
    truth = _truth(params, np.random.default_rng(1))
    observed, predicted = [], []
    for seed in range(8):
        settings = SimulationSettings(sigma_pos_mm=0.1, n_calibration=80, n_validation=40, seed=seed,
                                      validation_noise=False)
        experiment = simulate_chain(params, truth, points, settings)
        result = calibrate_chain(chain, experiment.calibration, "full", ChainFitOptions(selection="all"))
        observed.append(np.mean(_heldout_error(chain, result, experiment) ** 2))
        predicted.append(result.predicted_point_rms(chain, experiment.validation.q) ** 2)
    observed, predicted = np.array(observed), np.array(predicted)
    mse_ratio = observed.mean() / predicted.mean()
    mse_error = (observed - mse_ratio * predicted).std(ddof=1) / (np.sqrt(len(observed)) * predicted.mean())
    ratio, standard_error = np.sqrt(mse_ratio), mse_error / (2 * np.sqrt(mse_ratio))
    bound = student_t.ppf(0.995, len(observed) - 1) * standard_error
    assert abs(ratio - 1) <= bound, f"Monte Carlo / predicted held-out RMS = {ratio:.3f} ± {standard_error:.3f}"


def test_sensor_residual_jacobian_matches_finite_differences():
    chain = _chain("tiago")
    params = PlacementErrors(chain)
    rng = np.random.default_rng(3)
    vector = _truth(params, rng, scale=20.0)
    q = rng.uniform(-1, 1, (6, chain.n_joints)) * 0.3 + np.array([0.2] + [0.0] * 7)
    free = rng.permutation(params.size)[:20]
    cache = KinematicsCache(params, free, vector, q)
    start = TargetEstimate(
        Registration(pin.exp3(rng.normal(size=3)), rng.normal(size=3)), MARKERS, pin.exp3(rng.normal(size=3))
    )
    rotations = np.stack([pin.exp3(rng.normal(size=3)) for _ in q])
    objective = SensorResidual(cache, rng.normal(size=(6, 4, 3)), rotations, start,
                               RowWeights(position=rng.uniform(0.5, 2, 6), rotation=3.0))
    x = objective.start_vector() + rng.normal(0, 0.05, objective.n_free)
    # central differences, step 1e-6: truncation ~1e-12 × third derivatives of O(10),
    # rounding ~1e-16 × |r| ≈ 10 / 1e-6 = 1e-9; 1e-6 is far above both, far below O(1) entries
    assert_close(objective.jacobian(x), numeric_jacobian(objective.residual, x), 1e-6, "SensorResidual")


def test_identifiability_names_what_registration_and_target_absorb():
    """TIAGo offsets: the torso zero (a translation along z) and arm_1's zero (a turn about
    a vertical axis) are absorbed by the registration, arm_7's zero by the estimated target."""
    chain = _chain("tiago")
    params = JointOffsets(chain)
    settings = SimulationSettings(sigma_pos_mm=0.2, n_calibration=40, n_validation=10, seed=2)
    experiment = simulate_chain(params, _truth(params, np.random.default_rng(0)), MARKERS, settings)
    result = calibrate_chain(chain, experiment.calibration, "offsets")
    status = dict(zip((i.name for i in params.info), result.status))
    assert result.rank == 8 - 3  # eight joint zeros, three absorbed (below)
    for name in ("torso_lift_joint.offset", "arm_1_joint.offset", "arm_7_joint.offset"):
        assert status[name] == NOT_IDENTIFIABLE, name
    dropped = {params.info[d.index].name: d for d in result.dropped}
    assert any(n.startswith("registration") for n, _ in dropped["torso_lift_joint.offset"].absorbed_into)
    assert any(n.startswith("target") for n, _ in dropped["arm_7_joint.offset"].absorbed_into)
    assert np.all(np.isnan(result.std[[0, 1, 7]]))


def test_outlier_rows_are_reported_and_removed_only_when_asked():
    chain = _chain("panda")
    params = JointOffsets(chain)
    settings = SimulationSettings(sigma_pos_mm=0.1, n_calibration=50, n_validation=10, seed=4)
    experiment = simulate_chain(params, _truth(params, np.random.default_rng(2)), MARKERS[:1], settings)
    data = experiment.calibration
    points = np.array(data.points)
    points[7, 0, :] += 0.01  # one row 10 mm off
    bad = type(data)(joint_names=data.joint_names, q=data.q, points=points, rotations=None,
                     roles=data.roles, lines=data.lines, extra={}, source="sim.csv")
    kept = calibrate_chain(chain, bad, "offsets")
    assert [line for line, _ in kept.outliers] == [int(data.lines[7])]
    assert kept.removed_lines == () and len(kept.rows_used) == 50
    cleaned = calibrate_chain(chain, bad, "offsets", ChainFitOptions(reject_outliers=True))
    assert cleaned.removed_lines == (int(data.lines[7]),) and len(cleaned.rows_used) == 49
    # Without the bad row only noise is left: n rows × 3 components, sigma 0.1 mm,
    # p <= identifiable offsets + registration 6 + target point 3 unknowns, so
    # n rms² / sigma² is chi-square with 3n − p degrees of freedom. With the
    # bad row it cannot be: 10 mm in one of 50 rows is 1.4 mm RMS, of which the
    # fit absorbs only that row's small leverage share.
    sigma, n = 1e-4, len(cleaned.rows_used)
    dof = 3 * n - (cleaned.rank + 6 + 3)
    low, high = sigma * np.sqrt(chi2.ppf([0.001, 0.999], dof) / n)
    assert low <= cleaned.rms_m <= high, (low, cleaned.rms_m, high)
    assert kept.rms_m > high


def test_a_row_whose_orientation_alone_is_off_is_flagged_by_it_and_removed_when_asked():
    """6D rows (0.1 mm, 0.05°) with one row's measured orientation turned by 2° about its x axis — a rigid body
    whose markers were matched the wrong way round —, its position right. Scored with the positions, it would
    hide: its position error is the others', and it inflates the orientation noise scale instead."""
    chain = _chain("panda")
    params = JointOffsets(chain)
    settings = SimulationSettings(sigma_pos_mm=0.1, sigma_rot_deg=0.05, n_calibration=50, n_validation=10, seed=4)
    experiment = simulate_chain(params, _truth(params, np.random.default_rng(2)), MARKERS[:1], settings,
                                with_rotation=True)
    data = experiment.calibration
    rotations = np.array(data.rotations)
    rotations[7] = rotations[7] @ pin.exp3(np.array([np.radians(2.0), 0.0, 0.0]))
    bad = type(data)(joint_names=data.joint_names, q=data.q, points=data.points, rotations=rotations,
                     roles=data.roles, lines=data.lines, extra={}, source="sim.csv")
    kept = calibrate_chain(chain, bad, "offsets")
    assert [line for line, _ in kept.outliers] == [int(data.lines[7])]
    assert kept.outlier_errors() == ("orientation",)
    clean = calibrate_chain(chain, data, "offsets")
    assert clean.outliers == () and clean.outlier_errors() == ()
    cleaned = calibrate_chain(chain, bad, "offsets", ChainFitOptions(reject_outliers=True))
    assert cleaned.removed_lines == (int(data.lines[7]),) and cleaned.outliers == ()
    # 2° in one row of 50 puts the per-component scale near sqrt(0.05² + 2²/150) ≈ 0.17°, over three times the
    # noise's 0.05° (sigma_a per angle); without the row it is back at the noise: estimated from ~150 components,
    # it varies by about 1/sqrt(2·150) ≈ 6 %, so 20 % is over three of those
    assert np.degrees(kept.sigma_rot_rad) > 2 * 0.05
    assert np.degrees(cleaned.sigma_rot_rad) == pytest.approx(0.05, rel=0.2)


def test_solver_linear_algebra_without_blas_threads_matches_lapack():
    """thin_qr, triangular_factor and condition_number (pincal.fit.solver) against
    numpy's LAPACK, from well conditioned to the 1e12 refusal threshold and beyond."""
    from pincal.fit.solver import condition_number, thin_qr, triangular_factor

    rng = np.random.default_rng(5)
    for decades in (0, 4, 8, 11, 14):
        a = rng.normal(size=(300, 40)) @ np.diag(np.logspace(0, decades, 40)) @ np.linalg.qr(rng.normal(size=(40, 40)))[0]
        lapack = np.linalg.svd(a, compute_uv=False)
        ours = np.linalg.svd(triangular_factor(a), compute_uv=False)
        # backward stable: singular values to ~1e-15 of the largest (absolute)
        assert_close(ours / lapack[0], lapack / lapack[0], 1e-13, f"singular values, 1e{decades}")
        expected = lapack[0] / lapack[-1]
        assert abs(condition_number(a) / expected - 1) < 1e-15 * expected * 10 + 1e-9, decades
        if decades <= 8:
            q, r = thin_qr(a)
            assert_close(q @ r, a, 1e-14 * np.abs(a).max(), "QR = A")
            assert_close(q.T @ q, np.eye(40), 1e-15 * 10 ** decades * 10, "QᵀQ = I")
    singular = rng.normal(size=(50, 6))
    singular[:, 3] = singular[:, 1]
    assert condition_number(singular) > 1e12



def test_kinematics_cache_reuses_only_results_of_equal_inputs():
    """KinematicsCache keeps its last two results (a fit's caller asks again at the solution after
    MINPACK's rejected last step): equal x, q and tool give the stored result; any change,
    even to q's or the tool's values in place, computes afresh."""
    chain = _chain("tiago")
    params = PlacementErrors(chain)
    rng = np.random.default_rng(4)
    q = rng.uniform(-1, 1, (5, chain.n_joints)) * 0.3
    free = np.arange(12)
    cache = KinematicsCache(params, free, np.zeros(params.size), q)
    x1, x2, x3 = (rng.normal(0, 1e-3, 12) for _ in range(3))
    first = cache.evaluate(x1)
    second = cache.evaluate(x2)
    assert cache.evaluate(x1.copy()) is first and cache.evaluate(x2) is second
    assert cache.evaluate(x3) is not first  # x1 was the older of the two kept: x3 replaces it
    assert cache.evaluate(x1) is not first
    again = cache.evaluate(x1)
    moved = q.copy()
    moved[0, 0] += 1e-9
    assert cache.evaluate(x1, moved) is not again
    shifted = cache.evaluate(x1, moved)
    moved[0, 0] -= 1e-9  # back to q's values, in the same array
    assert cache.evaluate(x1, moved) is not shifted
    assert np.array_equal(cache.evaluate(x1)[0].tool_positions, first[0].tool_positions)
    tool = chain.tool
    chain.set_tool(tool @ pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.01])).homogeneous)
    assert not np.array_equal(cache.evaluate(x1)[0].tool_positions, first[0].tool_positions)
