"""A two-arm upper body on a four-joint torso whose 4th joint is coupled, from a URDF without inertias (tests of
compliance without a mass model, tests/test_torso_compliance.py).

The torso keeps the upper body upright: q4 = −(q2 + q3). A URDF ``<mimic>`` follows one joint, so two drivers
cannot be written; the closest form that keeps the relation exact in every row is a parallel linkage: torso_3
follows torso_2 (+1) and torso_4 follows torso_2 (−2), so q4 = −2 q2 = −(q2 + q3) and only torso_1 (yaw) and
torso_2 (pitch) have columns. Each arm has four joints and a marker link at its hand (``hand_r``, ``hand_l``).

The user's URDF (``inertias=False``) has no ``<inertial>`` at all, as a model from a DH table; the simulated
robot (``inertias=True``) has the masses below, which only the truth knows.
"""

from __future__ import annotations

#: ``--tip-link`` of each hand: CSV point 1 on the right hand, point 2 on the left
TARGETS = ("hand_r:1", "hand_l:2")

_JOINT = ('  <joint name="{0}" type="{1}"><parent link="{2}"/><child link="{3}"/>'
          '<origin xyz="{4}" rpy="{5}"/><axis xyz="{6}"/>{7}</joint>\n')
_INERTIAL = ('<inertial><origin xyz="{1}"/><mass value="{0}"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" '
             'izz="0.01"/></inertial>')
#: (joint, type, parent, child, xyz, rpy, axis, (lower, upper) [rad], <mimic> or "")
JOINTS = [
    ("torso_1", "revolute", "base_link", "torso_1_link", "0 0 0.3", "0 0 0", "0 0 1", (-1.2, 1.2), ""),
    ("torso_2", "revolute", "torso_1_link", "torso_2_link", "0.02 0 0.25", "0 0 0", "0 1 0", (-0.5, 0.5), ""),
    ("torso_3", "revolute", "torso_2_link", "torso_3_link", "0 0 0.2", "0 0 0", "0 1 0", (-0.5, 0.5),
     '<mimic joint="torso_2" multiplier="1"/>'),
    ("torso_4", "revolute", "torso_3_link", "torso_4_link", "0 0.01 0.2", "0 0 0", "0 1 0", (-1.0, 1.0),
     '<mimic joint="torso_2" multiplier="-2"/>'),
    *[(f"arm_{side}_{i}", "revolute", f"arm_{side}_{i - 1}_link" if i > 1 else "torso_4_link", f"arm_{side}_{i}_link",
       xyz, rpy, axis, (-1.2, 1.2), "")
      for side, sign in (("r", -1), ("l", 1))
      for i, xyz, rpy, axis in (
          (1, f"0.01 {sign * 0.2} 0.2", "0.05 0 0", "0 1 0"),
          (2, f"0 {sign * 0.05} 0", "0 0 0.02", "1 0 0"),
          (3, "0 0 -0.3", "0 0.03 0", "0 0 1"),
          (4, "0.01 0 -0.25", "0 0 0", "0 1 0"))],
    ("hand_r_joint", "fixed", "arm_r_4_link", "hand_r", "-0.01 0.02 -0.12", "0 0 0", "1 0 0", None, ""),
    ("hand_l_joint", "fixed", "arm_l_4_link", "hand_l", "0.02 0.01 -0.1", "0 0 0", "1 0 0", None, ""),
]
#: the simulated robot's masses [kg] and centres of mass in each link [m]: a torso of 4-10 kg links, arms of
#: 2.5 to 0.5 kg links hanging down their upper arm and forearm, a hand of 0.4 kg
MASSES = {"torso_1_link": (4.0, "0.01 0 0.12"), "torso_2_link": (3.0, "0 0 0.1"), "torso_3_link": (3.0, "0 0 0.1"),
          "torso_4_link": (10.0, "-0.02 0 0.2"),
          **{f"arm_{side}_{i}_link": (mass, com) for side in "rl"
             for i, mass, com in ((1, 2.5, "0 0 0"), (2, 2.0, "0 0 -0.15"), (3, 1.5, "0.01 0 -0.12"),
                                  (4, 0.5, "0 0 -0.06"))},
          "hand_r": (0.4, "0 0 -0.03"), "hand_l": (0.4, "0 0 -0.03")}


def torso_urdf(inertias: bool = False) -> str:
    """The URDF text: without any ``<inertial>`` (the user's), or with :data:`MASSES` (the simulated robot's)."""
    links = ["base_link"] + [j[3] for j in JOINTS]
    body = "".join(f'  <link name="{name}">' + (_INERTIAL.format(*MASSES[name]) if inertias and name in MASSES
                                                 else "") + "</link>\n" for name in links)
    for name, kind, parent, child, xyz, rpy, axis, limits, mimic in JOINTS:
        limit = "" if limits is None else f'<limit lower="{limits[0]}" upper="{limits[1]}" effort="50" velocity="1"/>'
        body += _JOINT.format(name, kind, parent, child, xyz, rpy, axis, limit + mimic)
    return f'<?xml version="1.0"?>\n<robot name="torso4">\n{body}</robot>\n'
