"""A small two-arm robot on a two-joint torso, for the tests of several targets (tests/test_tree*.py)."""

from __future__ import annotations

_LINK = '  <link name="{0}"><inertial><mass value="1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" ' \
        'izz="0.01"/></inertial></link>\n'
_JOINT = ('  <joint name="{0}" type="{1}"><parent link="{2}"/><child link="{3}"/>'
          '<origin xyz="{4}" rpy="{5}"/><axis xyz="{6}"/>{7}</joint>\n')
_LIMIT = '<limit lower="-2.5" upper="2.5" effort="10" velocity="1"/>'

#: (joint, type, parent, child, xyz, rpy, axis)
JOINTS = [
    ("torso_1", "revolute", "base_link", "torso_1_link", "0 0 0.3", "0 0 0", "0 0 1"),
    ("torso_2", "revolute", "torso_1_link", "torso_2_link", "0.02 0 0.25", "0 0 0", "0 1 0"),
    ("head_1", "revolute", "torso_2_link", "head_link", "0 0 0.3", "0 0 0", "0 0 1"),
    *[(f"arm_{side}_{i}", "revolute", f"arm_{side}_{i - 1}_link" if i > 1 else "torso_2_link", f"arm_{side}_{i}_link",
       xyz, rpy, axis)
      for side, sign in (("left", 1), ("right", -1))
      for i, xyz, rpy, axis in (
          (1, f"0.01 {sign * 0.2} 0.2", "0.05 0 0", "0 1 0"),
          (2, f"0 {sign * 0.05} 0", "0 0 0.02", "1 0 0"),
          (3, "0 0 -0.3", "0 0.03 0", "0 0 1"),
          (4, "0.01 0 -0.25", "0 0 0", "0 1 0"))],
    ("left_marker_joint", "fixed", "arm_left_4_link", "left_marker", "0.02 0.01 -0.1", "0 0 0", "1 0 0"),
    ("right_marker_joint", "fixed", "arm_right_4_link", "right_marker", "-0.01 0.02 -0.12", "0 0 0", "1 0 0"),
]


def two_arm_urdf() -> str:
    """The URDF text: torso_1, torso_2 shared; head_1 on a third branch; four joints per arm; a fixed marker link
    at each hand."""
    links = ["base_link"] + [j[3] for j in JOINTS]
    body = "".join(_LINK.format(n) for n in links)
    body += "".join(_JOINT.format(name, kind, parent, child, xyz, rpy, axis, _LIMIT if kind != "fixed" else "")
                    for name, kind, parent, child, xyz, rpy, axis in JOINTS)
    return f'<?xml version="1.0"?>\n<robot name="two_arms">\n{body}</robot>\n'


def compliant_rows(tree, params, truth, compliance, n_rows, rng, sigma_m=1e-4, local=None, backlash=0.0,  # noqa: PLR0913
                   lateral=None):
    """Rows (q (K, N), sensed points (K, P, 3) [m]) of ``tree`` at the placement errors ``truth`` with a joint
    compliance on torso_2 of ``compliance`` [rad/(N·m)] under the gravity torque of everything it carries (the
    URDF's inertias) and a backlash of ``backlash`` [rad] on the flank torso_2 approached from (rows in order),
    sensed with a registration and Gaussian noise ``sigma_m`` per axis; ``local``: each target's points in its tip
    link (default: one point each); ``lateral``: (joint, c_u, c_v) [rad/(N·m)], that joint bent about its lateral
    axes by the gravity moments about them (eq L1 of pincal.model.lateral), or None."""
    import numpy as np
    import pinocchio as pin

    from pincal.measurements.data import MeasurementSet
    from pincal.model.effects import Effect, approach_flank, gravity_torques
    from pincal.model.lateral import bend_angles
    from pincal.model.tree_effects import TreeBody, target_inputs, tree_inputs

    local = [np.array([[0.01, 0.0, 0.02]]), np.array([[0.0, 0.01, 0.0]])] if local is None else local
    q = rng.uniform(-1.2, 1.2, (n_rows, tree.n_joints))
    actual = q.copy()
    with tree.placed(params.placements(truth)):  # the loads of the true geometry, as a robot's
        actual[:, 1] += compliance * gravity_torques(TreeBody(tree), q)[:, 1]  # torso_2 at its reading + c tau
        actual[:, 1] += backlash * approach_flank(q[:, 1], np.arange(n_rows))
        bends = None
        if lateral is not None:  # at the readings' moments, as the tree's effect inputs have them
            rows = MeasurementSet(tree.joint_names, q, np.zeros((n_rows, 1, 3)), None,
                                  np.full(n_rows, "calibration", dtype=object), np.arange(n_rows))
            inputs = tree_inputs(tree, rows)
            bends = [bend_angles([Effect("lateral", lateral[0])], [np.array(lateral[1:])], target_inputs(inputs, t),
                                 t.chain.joint_names) for t in tree.targets]
        world = tree.target_points(actual, local, bends)
    sensed = world @ pin.rpy.rpyToMatrix(0.1, -0.2, 0.3).T + np.array([1.0, 0.5, -0.2])
    return q, sensed + rng.normal(0.0, sigma_m, sensed.shape)
