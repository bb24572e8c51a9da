"""A serial kinematic chain of a URDF, evaluated with Pinocchio.

:class:`KinematicChain` holds a Pinocchio model reduced to the joints between the
URDF root and a tip link (every other joint locked at its neutral value), the
tool (a fixed transform from the tip link to the measured target), and nothing
else. Calibration changes the chain's joint placements in place
(:meth:`KinematicChain.set_placements`); the model is never rebuilt inside a
cost function.

Frames are named by what they map: ``base_T_tip`` maps tip-link coordinates to
URDF-root coordinates. Units: metres and radians.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt
import pinocchio as pin

from pincal.errors import ModelError, did_you_mean
from pincal.measurements.couplings import ReadingCoupling
from pincal.measurements.data import JointMimic, JointSpec
from pincal.measurements.mimics import followers
from pincal.model.description import RobotDescription, read_description
from pincal.model.urdf_elements import joint_mimics

__all__ = ["ChainJoint", "ChainPoses", "KinematicChain", "points_in_base", "pose_from_xyz_rpy", "xyz_rpy_from_pose",
           "reduced_model"]

_KINDS = {
    "JointModelRX": "revolute",
    "JointModelRY": "revolute",
    "JointModelRZ": "revolute",
    "JointModelRevoluteUnaligned": "revolute",
    "JointModelRUBX": "continuous",
    "JointModelRUBY": "continuous",
    "JointModelRUBZ": "continuous",
    "JointModelRevoluteUnboundedUnaligned": "continuous",
    "JointModelPX": "prismatic",
    "JointModelPY": "prismatic",
    "JointModelPZ": "prismatic",
    "JointModelPrismaticUnaligned": "prismatic",
}

_AXES = {"X": (1.0, 0.0, 0.0), "Y": (0.0, 1.0, 0.0), "Z": (0.0, 0.0, 1.0)}


@dataclass(frozen=True)
class ChainJoint:
    """One actuated joint of the chain.

    Attributes:
        name: URDF joint name.
        kind: ``revolute``, ``continuous`` or ``prismatic``.
        axis: unit joint axis in the joint frame, shape (3,).
        lower: lower position limit [rad or m] (``-inf`` if none).
        upper: upper position limit [rad or m] (``inf`` if none).
        mimic: how it follows another joint (URDF ``<mimic>``, eq M1 of
            :mod:`pincal.measurements.mimics`), None for a joint read from the data.
    """

    name: str
    kind: str
    axis: np.ndarray
    lower: float
    upper: float
    mimic: JointMimic | None = None

    @property
    def spec(self) -> JointSpec:
        """The measurement reader's view of this joint."""
        return JointSpec(self.name, self.kind, self.lower, self.upper, self.mimic)


@dataclass(frozen=True)
class ChainPoses:
    """Forward kinematics of K configurations.

    Attributes:
        joint_rotations: world rotation of each joint frame after its motion, (K, N, 3, 3).
        joint_positions: world position of each joint frame origin [m], (K, N, 3).
        tool_rotations: world rotation of the tool frame, (K, 3, 3).
        tool_positions: world position of the tool frame origin (the TCP) [m], (K, 3).
    """

    joint_rotations: np.ndarray
    joint_positions: np.ndarray
    tool_rotations: np.ndarray
    tool_positions: np.ndarray


def _joint_axis(joint: pin.JointModel) -> np.ndarray:
    short = joint.shortname()
    if short[-1] in _AXES and not short.endswith("Unaligned"):
        return np.array(_AXES[short[-1]])
    return np.asarray(joint.extract().axis, dtype=float).copy()


class KinematicChain:
    """The joints from a URDF's root to a tip link, with a tool on the tip.

    Args:
        model: Pinocchio model of the whole URDF.
        tip_link: name of the link (Pinocchio body frame) at the end of the chain.
        tool: ``tip_T_tool`` as a 4x4 homogeneous matrix [m] (identity if None).
        source: where the model came from, for messages.
        mimics: the URDF's ``<mimic>`` joints (:func:`pincal.model.urdf_elements.joint_mimics`): those on
            the chain follow their driver (:attr:`ChainJoint.mimic`, :meth:`followed`). Pinocchio builds
            each as an ordinary joint (``buildModelFromXML``'s default, ``mimic=False``), so its placement
            and zero are parameters like any joint's and its angle is given, not derived, in ``q``.
    """

    def __init__(
        self,
        model: pin.Model,
        tip_link: str,
        tool: npt.ArrayLike | None = None,
        source: str = "<model>",
        mimics: Mapping[str, JointMimic] | None = None,
    ) -> None:
        body = pin.FrameType.BODY
        if not model.existFrame(tip_link, body):
            link, colon, _ = tip_link.rpartition(":")
            if colon and model.existFrame(link, body):  # LINK:POINTS, which names points of several targets
                raise ModelError(f"{source}: no link named '{tip_link}'; a single --tip-link takes LINK only "
                                 f"(LINK:POINTS is for several --tip-link): --tip-link {link}")
            links = sorted(f.name for f in model.frames if f.type == body)
            raise ModelError(f"{source}: no link named '{tip_link}'; {did_you_mean(tip_link, links, 'links')}")
        full_tip = model.frames[model.getFrameId(tip_link, body)]
        support = [j for j in model.supports[full_tip.parentJoint] if j != 0]
        if not support:
            raise ModelError(
                f"{source}: no joint between the root and '{tip_link}'; give a --tip-link further down the chain"
            )
        for jid in support:
            if model.joints[jid].shortname() not in _KINDS:
                raise ModelError(
                    f"{source}: joint '{model.names[jid]}' on the chain to '{tip_link}' is a "
                    f"{model.joints[jid].shortname()}; pincal calibrates revolute, continuous "
                    "and prismatic joints only"
                )
        chain_names = [model.names[j] for j in support]
        for name in chain_names:  # a follower's driver: another movable joint of the URDF
            driver = (mimics or {}).get(name)
            if driver is not None and (driver.driver == name or not model.existJointName(driver.driver)):
                raise ModelError(f"{source}: joint '{name}': <mimic joint=\"{driver.driver}\"> names no other "
                                 "movable joint of the URDF; name the joint it follows")
        #: the URDF's movable joints off the chain: below the tip link (joint -> its child link), and the others
        self.beyond_tip_joints, self.other_branch_joints = _off_chain(model, full_tip, support)
        locked = [j for j in range(1, model.njoints) if j not in support]
        if locked:
            model = reduced_model(model, locked)
        self.model: pin.Model = model
        self.data: pin.Data = model.createData()
        self.source = source
        self.tip_link = tip_link
        self.joint_ids = tuple(model.getJointId(n) for n in chain_names)
        self.tip_frame_id = model.getFrameId(tip_link, body)
        if model.nv != len(chain_names):  # (nq may exceed it: a continuous joint takes cos, sin)
            raise ModelError(f"{source}: the chain to '{tip_link}' is not a simple serial chain")
        joints = []
        for jid, name in zip(self.joint_ids, chain_names):
            jm = model.joints[jid]
            kind = _KINDS[jm.shortname()]
            lower = float(model.lowerPositionLimit[jm.idx_q]) if kind != "continuous" else -np.inf
            upper = float(model.upperPositionLimit[jm.idx_q]) if kind != "continuous" else np.inf
            joints.append(ChainJoint(name, kind, _joint_axis(jm), lower, upper, (mimics or {}).get(name)))
        self.joints: tuple[ChainJoint, ...] = tuple(joints)
        self._tool = np.eye(4) if tool is None else _checked_transform(tool, "tool")
        self._continuous = [j.kind == "continuous" for j in self.joints]

    @classmethod
    def from_urdf(
        cls,
        urdf_path: str | os.PathLike[str],
        tip_link: str,
        tool: npt.ArrayLike | None = None,
        xacro_args: Mapping[str, str] | Iterable[tuple[str, str]] | None = None,
    ) -> KinematicChain:
        """Load ``urdf_path`` with Pinocchio and take the chain from its root to ``tip_link``.

        A ``*.xacro`` file is expanded in memory with ``xacro_args``
        (:func:`pincal.model.description.read_description`, which also checks the tree).
        """
        return cls.from_description(read_description(urdf_path, xacro_args), tip_link, tool)

    @classmethod
    def from_description(cls, description: RobotDescription, tip_link: str, tool: npt.ArrayLike | None = None
                         ) -> KinematicChain:
        """The chain of a robot description already read (:func:`pincal.model.description.read_description`),
        as :meth:`from_urdf`: for a caller that also reads the description's XML, which is then parsed once."""
        try:
            model = pin.buildModelFromXML(description.text)
        except Exception as exc:  # Pinocchio raises plain RuntimeError/ValueError
            reason = " ".join(str(exc).split())
            raise ModelError(f"{description.source}: Pinocchio cannot read this URDF ({reason})") from None
        return cls(model, tip_link, tool=tool, source=description.source,
                   mimics=joint_mimics(description.root()))

    # --- names and sizes -------------------------------------------------

    @property
    def n_joints(self) -> int:
        return len(self.joints)

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints)

    @property
    def joint_specs(self) -> list[JointSpec]:
        return [j.spec for j in self.joints]

    @property
    def joint_kinds(self) -> dict[str, str]:
        """Joint name → ``revolute``, ``continuous`` or ``prismatic``, as REPORT.json's ``chain``: the kinds
        :func:`pincal.model.effect_units.effect_unit` takes."""
        return {j.name: j.kind for j in self.joints}

    @property
    def root_link(self) -> str:
        return self.model.frames[1].name if self.model.nframes > 1 else "universe"

    # --- placements -----------------------------------------------------

    @property
    def tool(self) -> np.ndarray:
        """``tip_T_tool`` (4, 4)."""
        return self._tool.copy()

    def set_tool(self, tip_T_tool: npt.ArrayLike) -> None:
        self._tool = _checked_transform(tip_T_tool, "tool")

    def placements(self) -> list[np.ndarray]:
        """Current placements: N joint placements (``parent_T_joint`` at zero motion)
        followed by the tip link's placement in the last joint frame; 4x4 each."""
        out = [self.model.jointPlacements[j].homogeneous.copy() for j in self.joint_ids]
        out.append(self.model.frames[self.tip_frame_id].placement.homogeneous.copy())
        return out

    def set_placements(self, placements: Sequence[np.ndarray]) -> None:
        """Set the N joint placements and the tip placement (see :meth:`placements`)."""
        if len(placements) != self.n_joints + 1:
            raise ModelError(
                f"expected {self.n_joints + 1} placements, got {len(placements)}"
            )
        for jid, placement in zip(self.joint_ids, placements[:-1]):
            self.model.jointPlacements[jid] = pin.SE3(np.asarray(placement, dtype=float))
        self.model.frames[self.tip_frame_id].placement = pin.SE3(
            np.asarray(placements[-1], dtype=float)
        )

    @contextmanager
    def placed(
        self, placements: Sequence[np.ndarray] | None = None, tool: npt.ArrayLike | None = None
    ) -> Iterator[KinematicChain]:
        """The chain with ``placements`` (see :meth:`placements`) and ``tip_T_tool`` ``tool`` (4, 4)
        [m] inside a ``with`` block, its own placements and tool back on leaving it, also on an error:
        how code outside ``model/`` evaluates a model (a calibration's ``chain_placements``, a simulated
        truth, a TCP) without changing the chain it was given. None keeps the current one."""
        saved, saved_tool = self.placements(), self._tool
        try:
            if tool is not None:
                self.set_tool(tool)
            if placements is not None:
                self.set_placements(placements)  # a malformed entry may fail after moving some joints
            yield self
        finally:
            self.set_placements(saved)
            self._tool = saved_tool

    def follow(self, couplings: Sequence[ReadingCoupling]) -> None:
        """Make each ``--coupling`` the run decided ``follows`` a joint of the chain that follows its driver
        (eq M1, offset 0; :func:`pincal.measurements.mimics.followers`), as a URDF ``<mimic>`` would, for
        the whole run: its readers, its residuals (:meth:`followed_shifts`) and REPORT.json's ``chain.mimics``.

        Raises:
            MeasurementError: a ``--coupling`` on a joint the URDF already makes follow another.
        """
        mimics = followers(self.joint_specs, couplings)
        self.joints = tuple(replace(j, mimic=mimics.get(j.name)) for j in self.joints)

    # --- kinematics -----------------------------------------------------

    @property
    def follower_pairs(self) -> tuple[tuple[int, int, float], ...]:
        """(follower, driver, multiplier) of each joint that follows another on the chain (eq M1), as
        column indices of ``q``: d q_follower / d q_driver = multiplier. Empty on most chains."""
        names = self.joint_names
        return tuple((i, names.index(j.mimic.driver), j.mimic.multiplier) for i, j in enumerate(self.joints)
                     if j.mimic is not None and j.mimic.driver in names)

    def followed(self, q: npt.ArrayLike) -> np.ndarray:
        """Joint values (K, N) [rad or m] with each joint that follows another on the chain set from it
        (eq M1); ``q`` itself (no copy) on a chain without one. A joint that follows one off the chain
        keeps its value: the chain cannot tell it."""
        q = np.asarray(q, dtype=float)
        if not self.follower_pairs:
            return q
        out = np.array(q, dtype=float, copy=True)
        for i, driver, multiplier in self.follower_pairs:
            mimic = self.joints[i].mimic
            assert mimic is not None  # a follower has its mimic
            out[..., i] = multiplier * q[..., driver] + mimic.offset
        return out

    def followed_shifts(self, shifts: np.ndarray) -> np.ndarray:
        """Changes of the joint angles (K, N) [rad or m] carried to the joints that follow them (eq M1
        differentiated: a follower moves by multiplier × its driver's change, on top of its own); the
        same array on a chain without followers. What effects do to a driver's angle (compliance,
        backlash ...) moves its followers: ``<mimic>`` ties the joints' actual angles. Applied to
        Jacobian columns by the transpose (:meth:`followed_columns`)."""
        if not self.follower_pairs:
            return shifts
        out = np.array(shifts, dtype=float, copy=True)
        for i, driver, multiplier in self.follower_pairs:
            out[..., i] += multiplier * shifts[..., driver]
        return out

    def followed_columns(self, columns: np.ndarray) -> np.ndarray:
        """Derivatives with respect to the joints (..., N, D), N along axis −2, made derivatives with respect
        to the joints' own changes: a driver's row gains multiplier × its follower's (the chain rule of eq M1,
        the transpose of :meth:`followed_shifts`); the same array on a chain without followers."""
        if not self.follower_pairs:
            return columns
        out = np.array(columns, dtype=float, copy=True)
        for i, driver, multiplier in self.follower_pairs:
            out[..., driver, :] += multiplier * columns[..., i, :]
        return out

    def configurations(self, q: npt.ArrayLike) -> np.ndarray:
        """Joint readings (K, N) → Pinocchio configurations (K, nq).

        Continuous joints are stored by Pinocchio as (cos, sin); others as is.
        """
        q = np.atleast_2d(np.asarray(q, dtype=float))
        if q.shape[1] != self.n_joints:
            raise ModelError(f"expected {self.n_joints} joint values per row, got {q.shape[1]}")
        if not any(self._continuous):
            return q
        columns = []
        for i, continuous in enumerate(self._continuous):
            if continuous:
                columns += [np.cos(q[:, i]), np.sin(q[:, i])]
            else:
                columns.append(q[:, i])
        return np.column_stack(columns)

    def tool_poses(self, q: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """World rotations (K, 3, 3) and positions [m] (K, 3) of the tool at K joint readings (K, N).

        The tool part of :meth:`poses`, the same numbers (one Pinocchio
        ``forwardKinematics`` per row), without copying every joint frame out of
        Pinocchio, which is most of the time :meth:`poses` takes (~0.1 ms instead of
        ~1 ms for 50 KUKA rows).
        """
        configurations = self.configurations(q)
        k = configurations.shape[0]
        tool_placement = self.model.frames[self.tip_frame_id].placement * pin.SE3(self._tool)
        last = self.joint_ids[-1]
        tool_rot = np.empty((k, 3, 3))
        tool_pos = np.empty((k, 3))
        model, data, oMi = self.model, self.data, self.data.oMi
        for row in range(k):
            pin.forwardKinematics(model, data, configurations[row])
            tool = oMi[last] * tool_placement
            tool_rot[row] = tool.rotation
            tool_pos[row] = tool.translation
        return tool_rot, tool_pos

    def poses(self, q: npt.ArrayLike) -> ChainPoses:
        """Forward kinematics (Pinocchio) of K joint readings (K, N)."""
        configurations = self.configurations(q)
        k = configurations.shape[0]
        n = self.n_joints
        joint_rot = np.empty((k, n, 3, 3))
        joint_pos = np.empty((k, n, 3))
        tip_T_tool = pin.SE3(self._tool)
        tool_placement = self.model.frames[self.tip_frame_id].placement * tip_T_tool
        last = self.joint_ids[-1]
        tool_rot = np.empty((k, 3, 3))
        tool_pos = np.empty((k, 3))
        model, data, oMi = self.model, self.data, self.data.oMi
        for row in range(k):
            pin.forwardKinematics(model, data, configurations[row])
            for col, jid in enumerate(self.joint_ids):
                placement = oMi[jid]
                joint_rot[row, col] = placement.rotation
                joint_pos[row, col] = placement.translation
            tool = oMi[last] * tool_placement
            tool_rot[row] = tool.rotation
            tool_pos[row] = tool.translation
        return ChainPoses(joint_rot, joint_pos, tool_rot, tool_pos)


def _off_chain(model: pin.Model, tip: pin.Frame, support: Sequence[int]) -> tuple[dict[str, str], tuple[str, ...]]:
    """The movable joints of ``model`` not in ``support``: ({joint: its child link} of those whose
    parent link hangs below the link ``tip``, through fixed joints or not; the others' names), in the
    model's (depth-first) order."""
    tip_id = model.getFrameId(tip.name, pin.FrameType.BODY)
    child = {model.frames[f.parentFrame].name: f.name for f in model.frames if f.type == pin.FrameType.BODY}
    beyond: dict[str, str] = {}
    other = []
    for frame in model.frames:
        if frame.type != pin.FrameType.JOINT or frame.parentJoint in support:
            continue
        up = frame.parentFrame
        while up not in (0, tip_id):  # up the frame tree to the tip or the root (frame 0)
            up = model.frames[up].parentFrame
        if up == tip_id:
            beyond[frame.name] = child.get(frame.name, frame.name)
        else:
            other.append(frame.name)
    return beyond, tuple(other)


def reduced_model(model: pin.Model, locked: list[int]) -> pin.Model:
    """``model`` with the joints ``locked`` fixed at their neutral values (Pinocchio's buildReducedModel).

    Pinocchio 3–4 looks frames up by name alone while reducing, so a joint named like a
    link (allowed in URDF, e.g. anymal_c's ``LF_HAA`` or b1-z1's fixed ``gripperStator``) fails
    it; such joints and their frames are renamed for the reduction and given their names back after it.
    """
    model = model.copy()
    names = [frame.name for frame in model.frames]
    clashing = {name for name in names if names.count(name) > 1}
    renamed: dict[str, str] = {}  # temporary name -> the original
    joint_frames: dict[int, str] = {}  # joint id -> its joint frame's temporary name
    for index, frame in enumerate(model.frames):
        if frame.name in clashing and frame.type != pin.FrameType.BODY:
            temporary = f"{frame.name} (frame {index})"
            renamed[temporary] = frame.name
            if frame.type == pin.FrameType.JOINT:
                joint_frames[frame.parentJoint] = temporary
            frame.name = temporary
            model.frames[index] = frame
    for jid in range(1, model.njoints):
        if model.names[jid] in clashing:  # named as its own joint frame, as Pinocchio names them
            temporary = joint_frames.get(jid, f"{model.names[jid]} (joint {jid})")
            renamed[temporary] = model.names[jid]
            model.names[jid] = temporary
    reduced = pin.buildReducedModel(model, locked, pin.neutral(model))
    for jid in range(1, reduced.njoints):
        reduced.names[jid] = renamed.get(reduced.names[jid], reduced.names[jid])
    for index, frame in enumerate(reduced.frames):
        if frame.name in renamed:
            frame.name = renamed[frame.name]
            reduced.frames[index] = frame
    return reduced


def points_in_base(
    tool_positions: np.ndarray, tool_rotations: np.ndarray, points_in_tool: npt.ArrayLike
) -> np.ndarray:
    """World (URDF-root) positions of points fixed in the tool frame: t_k + R_k m_p.

    Args:
        tool_positions: (K, 3) [m]; tool_rotations: (K, 3, 3).
        points_in_tool: (P, 3) [m].

    Returns:
        (K, P, 3) [m].
    """
    points = np.atleast_2d(np.asarray(points_in_tool, dtype=float))
    return tool_positions[:, None, :] + np.einsum("kij,pj->kpi", tool_rotations, points)


def _checked_transform(matrix: npt.ArrayLike, what: str) -> np.ndarray:
    m = np.asarray(matrix, dtype=float)
    if m.shape != (4, 4) or not np.all(np.isfinite(m)):
        raise ModelError(f"{what} must be a finite 4x4 homogeneous matrix")
    rot = m[:3, :3]
    if np.abs(rot @ rot.T - np.eye(3)).max() > 1e-9 or np.linalg.det(rot) < 0:
        raise ModelError(f"{what} rotation is not a proper rotation matrix")
    return m.copy()


def pose_from_xyz_rpy(xyz: Sequence[float], rpy: Sequence[float]) -> np.ndarray:
    """Homogeneous matrix from a URDF-style origin: ``xyz`` [m] and fixed-axis roll-pitch-yaw [rad]."""
    out = np.eye(4)
    out[:3, :3] = pin.rpy.rpyToMatrix(np.asarray(rpy, dtype=float))
    out[:3, 3] = xyz
    return out


def xyz_rpy_from_pose(pose: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of :func:`pose_from_xyz_rpy`."""
    m = np.asarray(pose, dtype=float)
    return m[:3, 3].copy(), np.asarray(pin.rpy.matrixToRpy(m[:3, :3])).copy()
