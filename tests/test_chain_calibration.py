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

from pincal.fit.chain_calibration import NOT_IDENTIFIABLE, calibrate_chain
from pincal.model.chain import KinematicChain
from pincal.model.parameter_sets import JointOffsets, PlacementErrors
from pincal.model.sensor import Registration
from pincal.residuals.base import KinematicsCache
from pincal.residuals.sensor import SensorResidual, TargetEstimate
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
    assert _heldout_error(chain, result, experiment).max() < 1e-8
    assert result.rank > 0 and result.selection.chosen == result.rank


@pytest.mark.parametrize("robot, points", [("panda", MARKERS[:3]), ("ur5", MARKERS[:2])])
def test_noisy_heldout_error_matches_noise_limited_prediction(robot, points):
    """Full level, sigma 0.1 mm, 8 seeds: Monte Carlo RMS within 10% of the linearised prediction."""
    chain = _chain(robot)
    params = PlacementErrors(chain)
    truth = _truth(params, np.random.default_rng(1))
    observed, predicted = [], []
    for seed in range(8):
        settings = SimulationSettings(sigma_pos_mm=0.1, n_calibration=80, n_validation=40, seed=seed,
                                      validation_noise=False)
        experiment = simulate_chain(params, truth, points, settings)
        result = calibrate_chain(chain, experiment.calibration, "full", selection="all")
        observed.append(np.mean(_heldout_error(chain, result, experiment) ** 2))
        predicted.append(result.predicted_point_rms(chain, experiment.validation.q) ** 2)
    ratio = np.sqrt(np.mean(observed)) / np.sqrt(np.mean(predicted))
    assert 0.9 <= ratio <= 1.1, f"Monte Carlo / predicted held-out RMS = {ratio:.3f}"


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
                               position_weight=rng.uniform(0.5, 2, 6), rotation_weight=3.0)
    x = objective.start_vector() + rng.normal(0, 0.05, objective.n_free)
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
    assert result.rank == 5
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
    cleaned = calibrate_chain(chain, bad, "offsets", reject_outliers=True)
    assert cleaned.removed_lines == (int(data.lines[7]),) and len(cleaned.rows_used) == 49
    assert cleaned.rms_m < 0.5 * kept.rms_m
