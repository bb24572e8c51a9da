"""pincal.simulation.humanoid: TALOS's upper body measured by motion capture (pincal example talos, the
whole-robots walk-through, scripts/scenarios.py's two-arm row and scripts/benchmark.py --tree).

Small sets (20 + 10 rows): the rows' columns (the grippers' drivers, no followers), the held-out rows drawn after
the calibration rows, and the compliance: the markers move by millimetres, and not as the URDF's masses say.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pincal.model.tree_parameters import TreeParameters
from pincal.simulation.humanoid import HumanoidSettings, simulate_humanoid

SMALL = HumanoidSettings(rows=20, held_out_rows=10)


@pytest.fixture(scope="module")
def small():
    return simulate_humanoid(SMALL)


def test_the_rows_read_the_drivers_and_the_followers_follow_them(small):
    """20 tree joints; the rows carry 16 of them and the two gripper drivers off the chains (18 columns)."""
    tree = small.tree
    assert tree.n_joints == 20
    followers = [j for j in tree.joints if j.mimic is not None]
    assert [j.mimic.multiplier for j in followers] == [1.0, -1.0, 1.0, -1.0]
    assert small.calibration.joint_names[-2:] == ("gripper_left_joint", "gripper_right_joint")
    assert len(small.calibration.joint_names) == 18 and not set(small.calibration.joint_names) & {
        j.name for j in followers}
    assert small.calibration.points.shape == (20, 2, 3) and small.validation.points.shape == (10, 2, 3)
    assert set(small.validation.roles) == {"validation"} and set(small.calibration.roles) == {"calibration"}
    assert small.truth.size == TreeParameters(tree, "full").size == len(small.parameter_names)


def test_more_held_out_rows_leave_the_calibration_rows_as_they_were(small):
    more = simulate_humanoid(replace(SMALL, held_out_rows=15))
    assert np.array_equal(more.calibration.points, small.calibration.points)
    assert np.array_equal(more.truth, small.truth)
    assert np.array_equal(more.validation.q[:10], small.validation.q)


def test_the_compliance_moves_the_markers_by_millimetres_and_not_as_the_urdfs_masses_say(small):
    """The default joints give 1-15 mm at the markers (a rigid robot: none), and the payload the URDF lacks
    loads the shoulders beyond what the URDF's masses do."""
    rms, largest = small.deflection_mm
    assert 2.0 < rms < 8.0 and 5.0 < largest < 20.0
    assert simulate_humanoid(replace(SMALL, compliance=())).deflection_mm == (0.0, 0.0)
    light = simulate_humanoid(replace(SMALL, payload_kg=0.0, compliance=(("arm_left_2_joint", 1e-3),)))
    heavy = simulate_humanoid(replace(SMALL, compliance=(("arm_left_2_joint", 1e-3),)))
    assert heavy.deflection_mm[0] > 1.2 * light.deflection_mm[0]  # the 1 kg at each hand loads the shoulder


def test_the_lateral_compliance_bends_the_torso_as_the_model_of_a_lateral_compliance_does(small):
    """None by default (the example's rows as they were); TALOS_LATERAL moves the markers by millimetres, exactly
    as pincal.model.lateral bends the tree's chains under the URDF's masses (no payload, no noise, no errors)."""
    from pincal.model.effects import Effect
    from pincal.model.lateral import bend_angles
    from pincal.model.tree_effects import target_inputs, tree_inputs
    from pincal.simulation.humanoid import MOCAP, TALOS_LATERAL, with_followers

    assert SMALL.lateral == ()
    exact = replace(SMALL, rows=5, held_out_rows=1, compliance=(), lateral=TALOS_LATERAL, payload_kg=0.0,
                    sigma_pos_mm=0.0, deviation_mm=0.0, deviation_mrad=0.0)
    bent = simulate_humanoid(exact)
    assert 1.0 < bent.deflection_mm[0] < bent.deflection_mm[1] < 15.0
    tree, rows = bent.tree, with_followers(bent.tree, bent.calibration)
    inputs = tree_inputs(tree, rows)
    joint, c_u, c_v = TALOS_LATERAL[0]
    bends = [bend_angles([Effect("lateral", joint)], [np.array([c_u, c_v])], target_inputs(inputs, t),
                         t.chain.joint_names) for t in tree.targets]
    local = [np.array([exact.marker_m]) for _ in tree.targets]
    world = tree.target_points(rows.q, local, bends)
    assert np.allclose(world @ MOCAP.rotation.T + MOCAP.translation, rows.points, atol=1e-12, rtol=0.0)


def test_markers_off_the_fingers_and_no_held_out_rows_read_exactly_the_trees_joints():
    """scripts/benchmark.py --tree's rows: a marker on each gripper's base, 16 joints with no follower, every
    one a column in the tree's order, and no held-out rows."""
    data = simulate_humanoid(HumanoidSettings(targets=("gripper_left_base_link:1", "gripper_right_base_link:2"),
                                              rows=10, held_out_rows=0, compliance=(), payload_kg=0.0))
    assert data.tree.n_joints == 16 and data.calibration.joint_names == data.tree.joint_names
    assert data.calibration.points.shape == (10, 2, 3) and data.validation.n_rows == 0


def test_each_hands_orientation_is_its_bent_links_and_its_noise_the_stated_one(small):
    """With sigma_rot_deg each target's orientation (numbered by its point) is its link's frame in the sensor frame,
    bent as its points are; its noise per axis the stated one; the points as they were without it."""
    from pincal.model.effects import Effect
    from pincal.model.lateral import bend_angles
    from pincal.model.tree_effects import target_inputs, tree_inputs
    from pincal.simulation.humanoid import MOCAP, TALOS_LATERAL, with_followers

    assert SMALL.sigma_rot_deg is None and not small.calibration.target_rotations
    exact = replace(SMALL, rows=30, held_out_rows=1, compliance=(), lateral=TALOS_LATERAL, payload_kg=0.0,
                    sigma_pos_mm=0.0, deviation_mm=0.0, deviation_mrad=0.0, sigma_rot_deg=0.0)
    bent, noisy = simulate_humanoid(exact), simulate_humanoid(replace(exact, sigma_rot_deg=0.3))
    tree, rows = bent.tree, with_followers(bent.tree, bent.calibration)
    joint, c_u, c_v = TALOS_LATERAL[0]
    bends = [bend_angles([Effect("lateral", joint)], [np.array([c_u, c_v])], target_inputs(tree_inputs(tree, rows), t),
                         t.chain.joint_names) for t in tree.targets]
    hands = MOCAP.rotation @ tree.target_rotations(rows.q, [np.eye(3)] * 2, bends)
    assert sorted(rows.target_rotations) == [1, 2]  # gripper_left's point 1, gripper_right's point 2
    for t, number in enumerate((1, 2)):
        assert np.allclose(rows.target_rotations[number], hands[:, t], atol=1e-12, rtol=0.0)
        turns = np.swapaxes(hands[:, t], 1, 2) @ noisy.calibration.target_rotations[number]
        angles = np.degrees(np.linalg.norm(Rotation.from_matrix(turns).as_rotvec(), axis=1))
        assert 0.75 < np.sqrt(np.mean(angles**2)) / (np.sqrt(3.0) * 0.3) < 1.25  # 30 rows' RMS of 3 axes' noise
    assert np.array_equal(noisy.calibration.points, bent.calibration.points)
