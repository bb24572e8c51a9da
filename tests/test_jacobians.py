"""Every analytic Jacobian against central finite differences of Pinocchio FK.

Step 1e-6 (rad or m), tolerance 1e-7 relative to the column scale: central
differences have O(h²) ≈ 1e-12 truncation error, so a wrong sign, frame or
factor shows up many orders above the tolerance.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from conftest import assert_close, numeric_jacobian

from pincal.model.dh.parameters import DHParameterSet
from pincal.model.dh.table import KUKA_LWR4_DH, TABLE2_LARGE
from pincal.residuals.base import KinematicsCache
from pincal.residuals.distance import DistanceResidual
from pincal.residuals.full_pose import FullPoseResidual
from pincal.residuals.rotation import RotationResidual

STEP = 1e-6
TOL = 1e-7


def _random_q(chain, rng, k):
    lower = np.array([j.lower for j in chain.joints])
    upper = np.array([j.upper for j in chain.joints])
    return rng.uniform(lower, upper, (k, chain.n_joints))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_sensitivity_matches_finite_differences_for_every_dh_parameter(kuka_chain, seed):
    rng = np.random.default_rng(seed)
    kuka_chain.set_tool(pin.SE3.Random().homogeneous)
    params = DHParameterSet(kuka_chain)
    vector = TABLE2_LARGE.apply(KUKA_LWR4_DH).to_vector()
    q = _random_q(kuka_chain, rng, 5)
    cache = KinematicsCache(params, np.arange(params.size), vector, q)
    poses, sens = cache.evaluate(vector)

    def tool(v):
        params.apply(v)
        return kuka_chain.poses(q)

    reference = tool(vector)
    assert_close(poses.tool_positions, reference.tool_positions, 1e-14, "TCP")
    assert_close(poses.tool_rotations, reference.tool_rotations, 1e-14, "R")
    numeric_position = numeric_jacobian(lambda v: tool(v).tool_positions, vector)  # (K, 3, n)
    assert_close(sens.point_velocity(poses.tool_positions).transpose(0, 2, 1), numeric_position, TOL, "dTCP")
    # a point off the TCP, rigidly attached to the tool
    offset = np.array([0.1, -0.05, 0.2])

    def marker(v):
        t = tool(v)
        return t.tool_positions + t.tool_rotations @ offset

    numeric_marker = numeric_jacobian(marker, vector)
    assert_close(sens.point_velocity(marker(vector)).transpose(0, 2, 1), numeric_marker, TOL, "dmarker")
    # angular: R(v + h e_i) R(v)^T ≈ exp(h w_i) in the world frame
    numeric_angular = np.empty((len(q), 3, vector.size))
    for i in range(vector.size):
        dv = np.zeros_like(vector)
        dv[i] = STEP
        plus, minus = tool(vector + dv).tool_rotations, tool(vector - dv).tool_rotations
        for k in range(len(q)):
            base = reference.tool_rotations[k].T
            numeric_angular[k, :, i] = (pin.log3(plus[k] @ base) - pin.log3(minus[k] @ base)) / (2 * STEP)
    assert_close(sens.angular.transpose(0, 2, 1), numeric_angular, TOL, "dR")


def test_epsilon_columns_equal_pinocchio_joint_jacobian(kuka_chain):
    """Zero-offset columns are Pinocchio's joint Jacobian columns of the TCP."""
    rng = np.random.default_rng(7)
    kuka_chain.set_tool(pin.SE3.Random().homogeneous)
    params = DHParameterSet(kuka_chain)
    vector = params.nominal.to_vector()
    q = _random_q(kuka_chain, rng, 3)
    cache = KinematicsCache(params, params.indices("epsilon"), vector, q)
    poses, sens = cache.evaluate(vector[cache.free])
    model, data = kuka_chain.model, kuka_chain.data
    tool_frame = model.addFrame(
        pin.Frame("tcp", kuka_chain.joint_ids[-1], 0,
                  model.frames[kuka_chain.tip_frame_id].placement * pin.SE3(kuka_chain.tool), pin.FrameType.OP_FRAME)
    )
    data = model.createData()
    for k in range(len(q)):
        jac = pin.computeFrameJacobian(model, data, q[k], tool_frame, pin.LOCAL_WORLD_ALIGNED)
        assert_close(sens.linear[k].T, jac[:3], 1e-12, "linear")
        assert_close(sens.angular[k].T, jac[3:], 1e-12, "angular")


def _objectives(chain, rng):
    params = DHParameterSet(chain)
    chain.set_tool(pin.SE3.Random().homogeneous)
    truth = TABLE2_LARGE.apply(KUKA_LWR4_DH)
    q = _random_q(chain, rng, 12)
    params.apply(truth.to_vector())
    poses = chain.poses(q)
    points = poses.tool_positions + rng.normal(0, 1e-3, (12, 3))
    rotations = np.stack([pin.exp3(rng.normal(0, 0.01, 3)) @ r for r in poses.tool_rotations])
    free = rng.permutation(params.size)[:15]
    cache = KinematicsCache(params, free, KUKA_LWR4_DH.to_vector(), q)
    yield "distance", DistanceResidual(cache, points), cache
    yield "rotation", RotationResidual(cache, rotations), cache
    yield "full", FullPoseResidual(cache, points, rotations, weight=3.0), cache


@pytest.mark.parametrize("seed", [0, 1])
def test_objective_jacobians_match_finite_differences(kuka_chain, seed):
    rng = np.random.default_rng(seed)
    for name, objective, cache in _objectives(kuka_chain, rng):
        x = cache.base[cache.free] + rng.normal(0, 0.01, cache.free.size)
        analytic = objective.jacobian(x)
        numeric = numeric_jacobian(objective.residual, x)
        scale = max(1.0, np.abs(numeric).max())
        assert_close(analytic / scale, numeric / scale, TOL, name)


def test_batched_so3_log_and_jacobian_are_pinocchios():
    """pincal.residuals.so3 gives pin.log3 / pin.Jlog3 of each matrix of a stack, bit for bit (the
    study's numbers depend on it, tests/test_study_reference.py): random angles, small ones
    (both sides of Pinocchio's Taylor branches) and angles up to pi."""
    from pincal.residuals.so3 import jlog3, log3

    rng = np.random.default_rng(11)
    axes = rng.normal(size=(60, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    taylor = np.finfo(float).eps ** (1.0 / 3.0)
    angles = np.concatenate([rng.uniform(0, 3, 20), [0.0, 1e-9, 0.5 * taylor, 2 * taylor, 1e-2, 1.0],
                             np.pi - np.array([1e-2, 1e-5, 0.0]), rng.uniform(3, np.pi, 31)])
    rotations = np.stack([pin.exp3(a * axis) for a, axis in zip(angles, axes)])
    assert np.array_equal(log3(rotations), np.stack([pin.log3(r) for r in rotations]))
    assert np.array_equal(jlog3(rotations), np.stack([pin.Jlog3(r) for r in rotations]))
    assert log3(rotations[:0]).shape == (0, 3) and jlog3(rotations[:0]).shape == (0, 3, 3)
    # Pinocchio's angle comes from the trace: within 4e-11 of the exact value near pi (measured
    # 3.5e-11 between 3 and pi - 1e-3), within 1e-15 below 0.1 rad, where residuals live
    below_pi = angles < np.pi
    assert_close(log3(rotations[below_pi]), (angles[:, None] * axes)[below_pi], 1e-10, "log3 vs angle · axis")
    assert_close(np.stack([pin.exp3(v) for v in log3(rotations)]), rotations, 1e-10, "exp3(log3(R))")  # pi too
    small = angles < 0.1
    assert_close(log3(rotations[small]), (angles[:, None] * axes)[small], 1e-15, "log3 of small angles")
    # away from pi (where log3 is not differentiable): against central differences of log3
    # (Pinocchio's Jlog3 is within 1.5e-9 of them here)
    for rotation in rotations[(angles < 3.0) & (angles > 1e-3)]:
        numeric = numeric_jacobian(lambda d: log3((rotation @ pin.exp3(d))[None])[0], np.zeros(3))
        assert_close(jlog3(rotation[None])[0], numeric, 1e-8, "Jlog3 vs differences")



@pytest.mark.parametrize("urdf, tip", [("ur_description/urdf/ur5_robot.urdf", "tool0"),
                                       ("tiago_description/robots/tiago.urdf", "wrist_ft_tool_link")])
def test_tool_poses_are_the_tool_part_of_poses_bit_for_bit(urdf, tip):
    """KinematicChain.tool_poses skips copying the joint frames; its numbers are poses()'s exactly
    (the study's reference numbers depend on it), with perturbed placements and a tool."""
    from pincal.model.chain import KinematicChain
    from pincal.model.parameter_sets import PlacementErrors
    from pincal.robots import example_robot_data_urdf
    from pincal.simulation.sensor import random_configurations

    chain = KinematicChain.from_urdf(example_robot_data_urdf(urdf), tip)
    rng = np.random.default_rng(8)
    params = PlacementErrors(chain)
    params.apply(rng.normal(0.0, 1e-3, params.size))
    chain.set_tool(pin.SE3(pin.exp3(rng.normal(size=3)), rng.normal(size=3) * 0.1).homogeneous)
    q = random_configurations(chain, rng, 20)
    rotations, positions = chain.tool_poses(q)
    poses = chain.poses(q)
    assert np.array_equal(rotations, poses.tool_rotations) and np.array_equal(positions, poses.tool_positions)
