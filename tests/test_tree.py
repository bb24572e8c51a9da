"""Several targets on several chains of one URDF: the tree, its shared parameters, its residual and its fit."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from conftest import assert_close, numeric_jacobian
from tree_robot import two_arm_urdf

from pincal.errors import ModelError, PincalError
from pincal.fit.chain_calibration import ChainFitOptions
from pincal.fit.tree_calibration import calibrate_tree, initial_tree_target, tree_rows
from pincal.measurements.data import MeasurementSet
from pincal.model.tree import KinematicTree, parse_targets
from pincal.model.tree_parameters import TreeParameters
from pincal.residuals.sensor_values import RowWeights
from pincal.residuals.tree import TreeResidual

LOCAL = [np.array([[0.01, 0.0, 0.02]]), np.array([[0.0, 0.01, 0.0], [0.03, -0.01, 0.01]])]  # points in the tip links
OCCLUDED = ((3, 1), (7, 0))  # (row, point - 1) not seen


@pytest.fixture(scope="module")
def model():
    return pin.buildModelFromXML(two_arm_urdf())


@pytest.fixture(scope="module")
def simulated(model):
    """Noise-free rows of the two-arm robot with perturbed joint placements (full level), two points occluded."""
    tree = KinematicTree(model, parse_targets(["left_marker:1", "right_marker:2,3"]))
    params = TreeParameters(tree, "full")
    rng = np.random.default_rng(1)
    truth = rng.normal(0.0, 1e-3, params.size)
    q = rng.uniform(-1.2, 1.2, (40, tree.n_joints))
    with tree.placed(params.placements(truth)):
        world = tree.target_points(q, LOCAL)
    rotation, translation = pin.rpy.rpyToMatrix(0.1, -0.2, 0.3), np.array([1.0, 0.5, -0.2])
    sensed = world @ rotation.T + translation
    measured = sensed.copy()
    for row, point in OCCLUDED:
        measured[row, point] = np.nan
    data = MeasurementSet(tree.joint_names, q, measured, None, np.full(len(q), "calibration", dtype=object),
                          np.arange(2, len(q) + 2))
    return tree, params, truth, data, sensed


def test_shared_joints_are_one_joint_and_one_set_of_parameters(model):
    tree = KinematicTree(model, parse_targets(["left_marker:1", "right_marker:2"]))
    assert tree.joint_names[:2] == ("torso_1", "torso_2")
    assert tree.n_joints == 10 and tree.other_branch_joints == ("head_1",)
    assert [t.columns.tolist() for t in tree.targets] == [[0, 1, 2, 3, 4, 5], [0, 1, 6, 7, 8, 9]]
    params = TreeParameters(tree, "full")
    names = [i.name for i in params.info]
    assert len(names) == len(set(names)) == 6 * 10 + 6 * 2  # each joint's placement once, a tip per target
    torso = [names.index(f"torso_{j}.{a}") for j in (1, 2) for a in ("tx", "ty", "tz", "rx", "ry", "rz")]
    assert params.index[0][:12].tolist() == params.index[1][:12].tolist() == torso  # both chains read the same
    offsets = TreeParameters(tree, "offsets")
    assert [i.name for i in offsets.info][:3] == ["torso_1.offset", "torso_2.offset", "arm_left_1.offset"]


@pytest.mark.parametrize(("values", "message"), [
    (["left_marker", "right_marker:2"], "each names the points"),
    (["left_marker:1", "right_marker:1"], "point 1 is given to both"),
    (["left_marker:1", "left_marker:2"], "given twice"),
    (["left_marker:0"], "distinct numbers"),
    (["left_marker:a"], "distinct numbers"),
])
def test_tip_link_values_are_refused_with_one_line(values, message):
    with pytest.raises(PincalError, match=message):
        parse_targets(values)


def test_a_tip_link_on_another_targets_chain_is_refused(model):
    with pytest.raises(ModelError, match="'arm_left_2_link' lies on the chain to 'left_marker'"):
        KinematicTree(model, parse_targets(["left_marker:1", "arm_left_2_link:2"]))


def test_tree_jacobian_matches_finite_differences(simulated):
    tree, params, truth, data, _ = simulated
    data = data.select(np.arange(12))  # the occluded rows among them
    rows = tree_rows(tree, data)
    start = initial_tree_target(tree, data, rows)
    free = np.arange(params.size)
    objective = TreeResidual(tree, params, free, truth, rows, start, RowWeights(1000.0))
    x = objective.start_vector() + np.random.default_rng(2).normal(0.0, 1e-3, objective.n_params)
    jacobian = objective.jacobian(x)
    assert jacobian.shape == (3 * (3 * 12 - len(OCCLUDED)), objective.n_params)
    assert_close(jacobian, numeric_jacobian(objective.residual, x), 1e-5, "tree Jacobian")
    # a left-arm parameter does not move a right-hand point: zero in those entries
    left = [i for i, info in enumerate(params.info) if info.joint == "arm_left_3"]
    row_of, point_of = objective.observations()
    right = np.repeat(point_of > 0, 3)
    assert np.all(jacobian[right][:, left] == 0.0) and np.any(jacobian[~right][:, left] != 0.0)


def test_noise_free_rows_give_the_truth_and_occlusion_drops_only_its_point(simulated):
    tree, params, truth, data, sensed = simulated
    result = calibrate_tree(tree, data, "full", ChainFitOptions(selection="all"))
    assert result.rank == 34  # 72 parameters; the registration and the estimated points absorb the others
    assert result.rms_m < 1e-12
    with tree.placed(result.tree_placements):
        fitted = tree.target_points(data.q, [result.target.points[[0]], result.target.points[[1, 2]]])
    registration = result.target.registration
    assert_close(registration.apply_points(fitted), sensed, 1e-12, "every point, the occluded ones too")
    assert np.isnan(result.point_errors[3, 1]) and np.isnan(result.point_errors[7, 0])
    assert np.isfinite(result.point_errors[3, [0, 2]]).all() and np.isfinite(result.point_errors[7, 1:]).all()
    assert result.status.count("calibrated") == 34


def test_several_targets_refuse_what_they_do_not_take_yet(simulated):
    tree, _, _, data, _ = simulated
    with pytest.raises(PincalError, match="--select press is not yet supported"):
        calibrate_tree(tree, data, "full", ChainFitOptions(selection="press"))
    with pytest.raises(PincalError, match="give each point 1..3 to one --tip-link"):
        calibrate_tree(KinematicTree(tree.targets[0].chain.model, parse_targets(["left_marker:1"])), data, "full")


def test_a_partly_empty_point_and_a_point_never_seen_are_refused(simulated):
    tree, _, _, data, _ = simulated
    points = data.points.copy()
    points[5, 2, 1] = np.nan  # y3 empty, x3 and z3 given
    with pytest.raises(PincalError, match="line 7: point 3 has some of x3,y3,z3 empty"):
        tree_rows(tree, MeasurementSet(data.joint_names, data.q, points, None, data.roles, data.lines))
    points = data.points.copy()
    points[:, 0] = np.nan
    with pytest.raises(PincalError, match="point 1 is not seen in any calibration row"):
        calibrate_tree(tree, MeasurementSet(data.joint_names, data.q, points, None, data.roles, data.lines), "full")


def test_two_sessions_are_registered_each_once_for_every_target(simulated):
    tree, _, _, data, sensed = simulated
    moved = pin.rpy.rpyToMatrix(-0.3, 0.1, 0.2)  # the sensor moved between the sessions
    points = data.points.copy()
    points[20:] = points[20:] @ moved.T + np.array([0.2, -0.1, 0.05])
    sessions = np.array(["a"] * 20 + ["b"] * 20, dtype=object)
    two = MeasurementSet(data.joint_names, data.q, points, None, data.roles, data.lines, sessions=sessions)
    result = calibrate_tree(tree, two, "offsets", ChainFitOptions(selection="all"))
    assert result.session_names == ("a", "b") and len(result.target.registrations) == 2
    first, second = result.target.registrations
    assert_close(second.rotation, moved @ first.rotation, 2e-3, "the second session's sensor turned by 'moved'")


def test_the_predicted_point_error_propagates_the_fits_covariance(simulated):
    """At the calibration rows themselves, the propagated covariance sums to σ² × the unknowns (the trace of the
    hat matrix of a least-squares fit): e² K P = σ² p, p = kept + 6 (registration) + 3 P (points), σ the noise
    the fit estimated (at level full the simulated one; at level registration the geometry it lacks too)."""
    tree, _, _, data, sensed = simulated
    sigma = 1e-4
    noisy = sensed + np.random.default_rng(2).normal(0.0, sigma, sensed.shape)
    rows = MeasurementSet(data.joint_names, data.q, noisy, None, data.roles, data.lines)
    for level in ("full", "registration"):
        result = calibrate_tree(tree, rows, level, ChainFitOptions(selection="all"))
        expected = result.sigma_pos_m * np.sqrt((result.kept.size + 6 + 3 * 3) / (data.n_rows * 3))
        assert 0.8 < result.predicted_point_rms(tree, data.q) / expected < 1.25, level
        if level == "full":
            assert 0.8 < result.sigma_pos_m / sigma < 1.25


def test_level_auto_on_a_tree_chooses_the_level_the_rows_support(model):
    """--level auto on several targets: rows of a robot whose only errors are joint offsets choose offsets, not the
    full level the rows fit no better on held-out sessions (one-standard-error rule, simplest first)."""
    from pincal.fit.tree_level_choice import choose_tree_level

    tree = KinematicTree(model, parse_targets(["left_marker:1", "right_marker:2"]))
    offsets = TreeParameters(tree, "offsets")
    rng = np.random.default_rng(3)
    q = rng.uniform(-1.2, 1.2, (24, tree.n_joints))
    with tree.placed(offsets.placements(rng.normal(0.0, 5e-3, offsets.size))):
        world = tree.target_points(q, [LOCAL[0], LOCAL[1][:1]])
    sensed = world @ pin.rpy.rpyToMatrix(0.1, -0.2, 0.3).T + np.array([1.0, 0.5, -0.2])
    data = MeasurementSet(tree.joint_names, q, sensed + rng.normal(0.0, 1e-4, sensed.shape), None,
                          np.full(len(q), "calibration", dtype=object), np.arange(2, len(q) + 2),
                          sessions=np.array(["a"] * 12 + ["b"] * 12, dtype=object))
    choice = choose_tree_level(tree, data, ChainFitOptions(selection="aic"))
    assert choice.scheme == "leave-one-session-out" and choice.chosen == "offsets"
    registration, offset, full = (s.cv_error_mm for s in choice.scores)
    assert offset < 0.3 < 1.0 < registration and full > offset  # 0.1 mm noise per axis; 5 mrad offsets
