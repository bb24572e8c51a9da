"""A humanoid's upper body measured by motion capture: TALOS's two arms on its shared torso.

The robot is TALOS as example-robot-data ships it (``talos_data/robots/talos_full_v2.urdf``, PAL
Robotics): a 2-joint torso (yaw, pitch) carrying two 7-joint arms, each ending in a gripper whose
fingers follow ``gripper_*_joint`` by ``<mimic>`` (a parallelogram: the inner link by +1, the
fingertip by -1, so the fingertip keeps its attitude as the gripper opens). A marker on one fingertip
of each gripper (:data:`TALOS_TARGETS`) puts 20 joints on the two chains: the torso's 2 (shared), 7 per
arm and, per gripper, the 2 finger joints that follow its ``gripper_*_joint`` — a joint off both chains
whose reading the rows carry, the followers having no column (eq M1 of :mod:`pincal.measurements.mimics`).

The true robot of :func:`simulate_humanoid` differs from the URDF the way a real one does:

* every placement of the tree's ``full`` parameters off by N(0, ``deviation_mm``) and
  N(0, ``deviation_mrad``) (:class:`pincal.model.tree_parameters.TreeParameters`);
* joints that give under their gravity load: actual = reading + c · τ(q) (the sign convention of
  :mod:`pincal.model.effects`: τ the torque that holds the links, so a joint that sags has c < 0),
  τ computed with the *true* masses, the URDF's plus ``payload_kg`` at each marker (a hand's tool and
  cables the URDF does not have) — so the URDF's masses cannot explain the deflection, and a diagnosis
  must take the masses as unknown (``--masses unknown``) — on the URDF's geometry (the placement errors
  move TALOS's torso pitch torque by at most 0.27 N·m at 0.5 mm / 0.5 mrad, against its 42 N·m RMS); a joint that
  others follow by ``<mimic>`` holds their torques too, by virtual work (τ_driver + multiplier · τ_follower),
  and moves them with it;
* joints that bend under the same masses' gravity moments about the two axes orthogonal to their own
  (``lateral``: right after the joint's motion the chain turns about u by c_u · M_u(q), then about v by
  c_v · M_v(q), eq L1 of :mod:`pincal.model.lateral`; none by default);
* a motion-capture system 1.14 m away (an arbitrary registration) measuring each marker with
  N(0, ``sigma_pos_mm``) per axis, and with ``sigma_rot_deg`` each marker's link as a rigid body: its orientation
  in the sensor frame (columns ``qxN,qyN,qzN,qwN``, N the target's first point) turned by N(0, ``sigma_rot_deg``)
  per axis — the link's frame as the true robot has it, bent by ``lateral`` too.

Calibration and held-out rows are drawn alike (uniform over each joint's range, clipped to
±``joint_range_rad``); the held-out rows are drawn after every value of the calibration rows, so a
different number of them leaves the calibration rows as they were. ``HumanoidSettings.urdf`` simulates another
robot the same way, its ``<inertial>`` the true masses (tests/torso_robot.py: two arms on a four-joint torso whose
coupled joints follow one driver, for a user's URDF without inertias). Units: metres, radians, N·m.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pinocchio as pin
from scipy.spatial.transform import Rotation

from pincal.measurements.data import MeasurementSet
from pincal.model.description import RobotDescription, read_description
from pincal.model.mass_moments import lateral_axes
from pincal.model.sensor import Registration
from pincal.model.tree import KinematicTree, parse_targets
from pincal.model.tree_parameters import TreeParameters
from pincal.robots import example_robot_data_urdf

__all__ = ["TALOS_URDF", "TALOS_TARGETS", "TALOS_COMPLIANCE", "TALOS_LATERAL", "HumanoidSettings", "HumanoidData",
           "talos_description", "simulate_humanoid", "with_followers"]

#: TALOS's description in example-robot-data (its path under the package's robots folder).
TALOS_URDF = "talos_data/robots/talos_full_v2.urdf"
#: A marker on the first fingertip of each gripper: point 1 on the left hand, point 2 on the right.
TALOS_TARGETS = ("gripper_left_fingertip_1_link:1", "gripper_right_fingertip_1_link:2")
#: The joints that give under their load and by how much [rad/(N·m)]: the torso's pitch and each
#: shoulder's, sagging (c < 0). Chosen so that the markers move by the size of the errors a published
#: calibration of an elastic humanoid upper body (two hand markers, ceiling motion capture) removed with
#: joint and lateral compliances, 10.5 -> 3.1 mm mean: here 4.9 mm RMS, 13.6 mm at most at the defaults
#: (:attr:`HumanoidData.deflection_mm`; the torso's ~40 N·m and the shoulders' ~18 N·m RMS loads).
TALOS_COMPLIANCE = (("torso_2_joint", -1e-4), ("arm_left_2_joint", -2e-4), ("arm_right_2_joint", -2e-4))
#: The joints that bend about their lateral axes and by how much [rad/(N·m)] (:attr:`HumanoidSettings.lateral`):
#: the torso's pitch joint, bending about its roll (u) and yaw (v) axes under both arms, sagging (c < 0). With
#: :data:`TALOS_COMPLIANCE` the markers move by 5.9 mm RMS, 14.1 mm at most at the defaults (5.7 and 13.8 mm on
#: 60 rows): the 5-15 mm the published elastic upper body's joint and lateral compliances removed (above).
TALOS_LATERAL = (("torso_2_joint", -1.5e-4, -1e-4),)
#: sensor_T_base of the simulated motion capture: an arbitrary pose 1.14 m from the robot's base link.
MOCAP = Registration(rotation=pin.rpy.rpyToMatrix(0.1, -0.2, 0.3), translation=np.array([1.0, 0.5, -0.2]))


@dataclass(frozen=True)
class HumanoidSettings:
    """What :func:`simulate_humanoid` simulates (defaults: the docs' walk-through).

    Attributes:
        targets: ``LINK:POINTS`` per marker's link (as ``--tip-link``); one marker per target.
        rows / held_out_rows: calibration rows and held-out rows (role ``validation``).
        sigma_pos_mm: the motion capture's noise per axis [mm] (0.1-0.2 mm for a ceiling system).
        sigma_rot_deg: each target's orientation measured too, with this noise per axis [deg] (a motion-capture
            rigid body's: ~0.1 deg); None: its points only.
        deviation_mm / deviation_mrad: std of the true placement errors [mm, mrad].
        compliance: (joint, c [rad/(N·m)]) of the true robot; empty: a rigid robot.
        lateral: (joint, c_u, c_v [rad/(N·m)]) of the true robot's lateral compliances (eq L1 of
            :mod:`pincal.model.lateral`, its u and v axes :func:`pincal.model.mass_moments.lateral_axes`); empty:
            none (e.g. :data:`TALOS_LATERAL`).
        payload_kg: an unmodelled mass at each marker [kg] (it loads the compliant joints).
        marker_m: each marker in its link [m].
        joint_range_rad: the postures' joints within their limits and within ± this [rad].
        seed: of every random draw.
        urdf: another robot's URDF file, the simulated robot's (its ``<inertial>`` the true masses); None: TALOS's.
    """

    targets: tuple[str, ...] = TALOS_TARGETS
    rows: int = 150
    held_out_rows: int = 60
    sigma_pos_mm: float = 0.15
    deviation_mm: float = 1.0
    deviation_mrad: float = 1.0
    compliance: tuple[tuple[str, float], ...] = TALOS_COMPLIANCE
    lateral: tuple[tuple[str, float, float], ...] = ()
    payload_kg: float = 1.0
    marker_m: tuple[float, float, float] = (0.0, 0.0, -0.02)
    joint_range_rad: float = 1.5
    seed: int = 0
    urdf: str | None = None
    sigma_rot_deg: float | None = None


@dataclass(frozen=True)
class HumanoidData:
    """What :func:`simulate_humanoid` returns.

    Attributes:
        tree: the nominal tree (the URDF's), whose joints the rows' ``q`` follow.
        calibration / validation: the rows; their columns are the tree's joints that follow none
            and the drivers off the tree (``gripper_*_joint``), points ``x1,y1,z1 ...`` in the sensor frame.
        truth: the true placement errors, :class:`TreeParameters` ``full`` of ``tree`` [m, rad].
        parameter_names: their names (``arm_left_2_joint.tx`` ...).
        registration: the true sensor_T_base.
        deflection_mm: RMS and largest marker displacement the compliance causes [mm].
    """

    tree: KinematicTree
    calibration: MeasurementSet
    validation: MeasurementSet
    truth: np.ndarray
    parameter_names: tuple[str, ...]
    registration: Registration
    deflection_mm: tuple[float, float]


def talos_description() -> RobotDescription:
    """TALOS's URDF from example-robot-data, read and checked."""
    return read_description(example_robot_data_urdf(TALOS_URDF))


def simulate_humanoid(settings: HumanoidSettings | None = None) -> HumanoidData:
    """TALOS's upper body measured by motion capture, a marker on each gripper (module docstring)."""
    settings = HumanoidSettings() if settings is None else settings
    description = talos_description() if settings.urdf is None else read_description(settings.urdf)
    tree = KinematicTree.from_description(description, parse_targets(list(settings.targets)))
    params = TreeParameters(tree, "full")
    rng = np.random.default_rng(settings.seed)
    followers = {j.name: j.mimic for j in tree.joints if j.mimic is not None}
    read = [n for n in tree.joint_names if n not in followers]
    drivers = sorted({m.driver for m in followers.values()} - set(tree.joint_names))
    model = pin.buildModelFromXML(description.text)
    columns = [*read, *drivers]
    q_read = _postures(model, columns, settings, rng, settings.rows)
    metres = np.array([info.unit == "m" for info in params.info])
    truth = rng.normal(0.0, 1.0, params.size) * np.where(metres, settings.deviation_mm, settings.deviation_mrad) * 1e-3
    loaded = _with_payload(model, tree, settings)
    sets, moved = [], []
    for role, count in (("calibration", settings.rows), ("validation", settings.held_out_rows)):
        q = q_read if role == "calibration" else _postures(model, columns, settings, rng, count)
        full = _tree_angles(tree, columns, q)
        actual = full + _deflection(loaded, tree, full, settings.compliance)
        bends = _bends(loaded, tree, full, settings.lateral)
        local = [np.tile(settings.marker_m, (len(t.spec.points), 1)) for t in tree.targets]
        with tree.placed(params.placements(truth)):
            world = tree.target_points(actual, local, bends)
            moved.append(np.linalg.norm(world - tree.target_points(full, local), axis=2).ravel())
            hands = MOCAP.rotation @ tree.target_rotations(actual, [np.eye(3)] * len(tree.targets), bends)
        sensed = (world @ MOCAP.rotation.T + MOCAP.translation
                  + rng.normal(0.0, settings.sigma_pos_mm * 1e-3, world.shape))
        sets.append(MeasurementSet(tuple(columns), q, sensed, None, np.full(count, role, dtype=object),
                                   np.arange(2, count + 2), target_rotations=_turned(tree, hands, settings, rng)))
    shift = np.concatenate(moved) * 1e3
    return HumanoidData(tree, sets[0], sets[1], truth, tuple(i.name for i in params.info), MOCAP,
                        (float(np.sqrt(np.mean(shift**2))), float(shift.max())))


def _turned(tree: KinematicTree, hands: np.ndarray, settings: HumanoidSettings, rng: np.random.Generator
            ) -> dict[int, np.ndarray]:
    """Each target's measured orientation (its first point's number → (K, 3, 3)): its true frame in the sensor
    frame ``hands`` (K, T, 3, 3) turned by N(0, ``sigma_rot_deg``) per axis; {} without ``sigma_rot_deg``."""
    if settings.sigma_rot_deg is None:
        return {}
    tilt = rng.normal(0.0, np.radians(settings.sigma_rot_deg), (*hands.shape[:2], 3))
    return {t.spec.points[0]: Rotation.from_rotvec(tilt[:, i]).as_matrix() @ hands[:, i]
            for i, t in enumerate(tree.targets)}


def with_followers(tree: KinematicTree, data: MeasurementSet) -> MeasurementSet:
    """``data`` with a column for every joint of ``tree``, in its order, each follower's computed from its
    driver (eq M1): the rows as the measurement reader gives them to a tree's fit."""
    return replace(data, joint_names=tree.joint_names, q=_tree_angles(tree, list(data.joint_names), data.q))


def _postures(model: pin.Model, columns: list[str], settings: HumanoidSettings, rng: np.random.Generator,
              count: int) -> np.ndarray:
    """Readings (count, len(columns)) uniform within each joint's limits and ±joint_range_rad [rad]."""
    ids = [model.getJointId(n) for n in columns]
    lower = np.array([model.lowerPositionLimit[model.joints[j].idx_q] for j in ids])
    upper = np.array([model.upperPositionLimit[model.joints[j].idx_q] for j in ids])
    bound = settings.joint_range_rad
    return rng.uniform(np.maximum(lower, -bound), np.minimum(upper, bound), (count, len(columns)))


def _tree_angles(tree: KinematicTree, columns: list[str], q: np.ndarray) -> np.ndarray:
    """Every tree joint's angle (K, N): the readings, and each follower from its driver (eq M1)."""
    out = np.empty((len(q), tree.n_joints))
    for i, joint in enumerate(tree.joints):
        if joint.mimic is None:
            out[:, i] = q[:, columns.index(joint.name)]
        else:
            out[:, i] = joint.mimic.multiplier * q[:, columns.index(joint.mimic.driver)] + joint.mimic.offset
    return out


def _with_payload(model: pin.Model, tree: KinematicTree, settings: HumanoidSettings) -> pin.Model:
    """A copy of ``model`` with ``payload_kg`` at each marker: the true robot's masses."""
    loaded = model.copy()
    for target in tree.targets:
        frame = loaded.frames[loaded.getFrameId(target.link, pin.FrameType.BODY)]
        payload = pin.Inertia(settings.payload_kg, np.asarray(settings.marker_m, dtype=float), np.zeros((3, 3)))
        loaded.inertias[frame.parentJoint] = loaded.inertias[frame.parentJoint] + frame.placement.act(payload)
    return loaded


def _deflection(model: pin.Model, tree: KinematicTree, angles: np.ndarray,
                compliance: tuple[tuple[str, float], ...]) -> np.ndarray:
    """Each tree joint's shift c · τ(q) (K, N) [rad]: τ the gravity torque of ``model`` (Pinocchio's
    ``computeGeneralizedGravity``) with the tree's joints at ``angles`` and every other joint at zero; a joint that
    others follow (eq M1) holds theirs too, by virtual work: τ_driver + multiplier · τ_follower."""
    shifts = np.zeros_like(angles)
    if not compliance:
        return shifts
    data = model.createData()
    q_index = [model.joints[model.getJointId(n)].idx_q for n in tree.joint_names]
    v_index = {n: model.joints[model.getJointId(n)].idx_v for n in tree.joint_names}
    followers = {name: [(v_index[j.name], j.mimic.multiplier) for j in tree.joints
                        if j.mimic is not None and j.mimic.driver == name] for name, _ in compliance}
    configuration = pin.neutral(model)
    for k, row in enumerate(angles):
        configuration[q_index] = row
        torque = pin.computeGeneralizedGravity(model, data, configuration)
        for name, value in compliance:
            held = torque[v_index[name]] + sum(m * torque[v] for v, m in followers[name])
            shifts[k, tree.joint_names.index(name)] = value * held
    for i, joint in enumerate(tree.joints):  # a follower moves with its driver's shift (eq M1)
        if joint.mimic is not None and joint.mimic.driver in tree.joint_names:
            shifts[:, i] += joint.mimic.multiplier * shifts[:, tree.joint_names.index(joint.mimic.driver)]
    return shifts


def _bends(model: pin.Model, tree: KinematicTree, angles: np.ndarray,
           lateral: tuple[tuple[str, float, float], ...]) -> list[np.ndarray | None] | None:
    """Each target's chain joints' lateral deflections (K, 2 N_t) [rad] (eq L1 of :mod:`pincal.model.lateral`):
    (c_u M_u, c_v M_v) of each of ``lateral``'s joints, M its gravity moment about its lateral axes (eq M3: the
    wrench Pinocchio's ``rnea`` at rest leaves in ``data.f``) under ``model``'s masses, the tree's joints at
    ``angles`` and every other joint at zero; None without ``lateral``."""
    if not lateral:
        return None
    data = model.createData()
    q_index = [model.joints[model.getJointId(n)].idx_q for n in tree.joint_names]
    configuration, zero = pin.neutral(model), np.zeros(model.nv)
    deflections = {name: np.zeros((len(angles), 2)) for name, _, _ in lateral}
    axes = {name: lateral_axes(np.asarray(tree.joints[tree.joint_names.index(name)].axis, dtype=float))
            for name, _, _ in lateral}
    for k, row in enumerate(angles):
        configuration[q_index] = row
        pin.rnea(model, data, configuration, zero, zero)
        for name, c_u, c_v in lateral:
            moments = axes[name] @ data.f[model.getJointId(name)].angular  # (M_u, M_v) [N·m]
            deflections[name][k] = np.array([c_u, c_v]) * moments
    out: list[np.ndarray | None] = []
    for target in tree.targets:
        names = list(target.chain.joint_names)
        bends = np.zeros((len(angles), 2 * len(names)))
        for name, value in deflections.items():
            if name in names:
                j = names.index(name)
                bends[:, 2 * j : 2 * j + 2] = value
        out.append(bends)
    return out
