"""Analytic parameter Jacobians from Pinocchio's joint Jacobians.

Every kinematic parameter pincal identifies moves the chain by a unit twist in
one joint frame: a DH link offset d_n translates along the z axis of joint n's
child frame, a zero offset turns about the joint axis, a link twist alpha_n
turns about the x axis through (r_n, 0, d_n), a placement error of issue-4 style
is any of the six generators in the joint's placement frame.

:class:`SensitivityModel` builds, once per fit, a Pinocchio model of the chain
in which each such parameter is an extra 1-DoF joint (revolute or prismatic)
held at zero — a *sensitivity joint* — placed where its twist acts. At zero the
extra joints do not change the kinematics, and the columns of the tool frame's
Jacobian (``pin.computeFrameJacobian``, LOCAL_WORLD_ALIGNED) for those joints
are exactly the derivatives of the tool pose with respect to the parameters
(Murray, Li & Sastry 1994, eq 3.55: the Jacobian column of a joint is its twist
transported by the adjoint). A few Pinocchio calls per configuration
(``computeJointJacobians``, ``getFrameJacobian``) then give the tool pose and
every parameter derivative; the model is never rebuilt inside a
cost function, only its placements are updated.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pinocchio as pin

from pincal.model.chain import KinematicChain

__all__ = ["ParameterSlot", "ToolPoses", "Sensitivity", "SensitivityModel"]

_ALIGNED_REVOLUTE = {0: pin.JointModelRX, 1: pin.JointModelRY, 2: pin.JointModelRZ}
_ALIGNED_PRISMATIC = {0: pin.JointModelPX, 1: pin.JointModelPY, 2: pin.JointModelPZ}
_EYE3 = np.eye(3)
_IDENTITY = pin.SE3.Identity()


@dataclass(frozen=True)
class ParameterSlot:
    """Where a parameter acts: a unit twist in a frame of chain joint ``joint``.

    Attributes:
        joint: index of the chain joint (0-based).
        after_motion: True for the joint's child frame (after its motion),
            False for its placement frame (before the motion).
        kind: ``revolute`` (turns about ``axis`` through a point given at
            evaluation time), ``prismatic`` (translates along ``axis``) or ``bend`` (turns about ``axis``
            through the joint's origin right after its motion, at an angle :meth:`SensitivityModel.evaluate`
            is given per row: a joint's lateral deflection, :mod:`pincal.model.lateral`).
        axis: unit direction in that frame, shape (3,).
    """

    joint: int
    after_motion: bool
    kind: str
    axis: tuple[float, float, float]


@dataclass(frozen=True)
class ToolPoses:
    """Tool poses of K configurations in the URDF root frame.

    Attributes:
        tool_positions: tool frame origins (the TCP) [m], (K, 3).
        tool_rotations: tool frame rotations, (K, 3, 3).
    """

    tool_positions: np.ndarray
    tool_rotations: np.ndarray


@dataclass(frozen=True)
class Sensitivity:
    """Derivatives of the tool pose with respect to the parameters.

    Attributes:
        angular: world angular velocity of the tool [rad/unit], (K, n_par, 3).
        linear: world velocity of the tool frame origin [m/unit], (K, n_par, 3).
        origin: the tool frame origins the linear part refers to [m], (K, 3).
        joint_angular / joint_linear: the same for the chain's own joints
            (Pinocchio's joint Jacobian columns), (K, N, 3).
        bend_angular / bend_linear: the same for the ``bend`` slots, in their order (K, B, 3), or None.
    """

    angular: np.ndarray
    linear: np.ndarray
    origin: np.ndarray
    joint_angular: np.ndarray | None = None
    joint_linear: np.ndarray | None = None
    bend_angular: np.ndarray | None = None
    bend_linear: np.ndarray | None = None

    def point_velocity(self, points: npt.ArrayLike) -> np.ndarray:
        """d(point)/d(parameter) for points rigidly attached to the tool, (K, 3) → (K, n_par, 3)."""
        offset = np.asarray(points, dtype=float) - self.origin
        return self.linear + np.cross(self.angular, offset[:, None, :])

    def joint_point_velocity(self, points: npt.ArrayLike) -> np.ndarray:
        """d(point)/d(joint value) of the chain's joints, (K, 3) → (K, N, 3)."""
        offset = np.asarray(points, dtype=float) - self.origin
        assert self.joint_angular is not None and self.joint_linear is not None  # SensitivityModel sets them
        return self.joint_linear + np.cross(self.joint_angular, offset[:, None, :])


def _sensitivity_joint(slot: ParameterSlot) -> pin.JointModel:
    axis = np.asarray(slot.axis, dtype=float)
    aligned = np.flatnonzero(np.abs(axis) > 1e-15)
    if len(aligned) == 1 and axis[aligned[0]] == 1.0:
        table = _ALIGNED_PRISMATIC if slot.kind == "prismatic" else _ALIGNED_REVOLUTE
        return table[int(aligned[0])]()
    if slot.kind in ("revolute", "bend"):
        return pin.JointModelRevoluteUnaligned(axis)
    return pin.JointModelPrismaticUnaligned(axis)


def _group(slot: ParameterSlot) -> str:
    """Where a slot sits at its joint: ``placement`` (before the motion), ``bend`` (right after it), ``child``."""
    return "bend" if slot.kind == "bend" else "child" if slot.after_motion else "placement"


class SensitivityModel:
    """A Pinocchio model of ``chain`` with one zero-valued joint per parameter slot.

    Args:
        chain: the chain (its joint types and tool are used).
        slots: where each parameter acts, in parameter order; ``bend`` slots (after the others) sit right
            after their joint's motion, before its other child-frame slots: a parameter of the next link's
            placement acts beyond the joint's deflection.
    """

    def __init__(self, chain: KinematicChain, slots: Sequence[ParameterSlot]) -> None:
        self.chain = chain
        self.slots = tuple(slots)
        model = pin.Model()
        parent = 0
        self._real_ids: list[int] = []
        self._slot_ids: list[int] = [0] * len(self.slots)
        # joint order: [placement-frame slots of joint i], joint i, [its bends], [child-frame slots of joint i], ...
        self._order: list[tuple[str, int]] = []
        for i, jid in enumerate(chain.joint_ids):
            for group in ("placement", "bend", "child"):
                if group == "bend":
                    parent = model.addJoint(parent, chain.model.joints[jid], pin.SE3.Identity(), chain.joint_names[i])
                    self._real_ids.append(parent)
                    self._order.append(("joint", i))
                for s, slot in enumerate(self.slots):
                    if slot.joint == i and _group(slot) == group:
                        parent = model.addJoint(
                            parent, _sensitivity_joint(slot), pin.SE3.Identity(), f"pincal_slot_{s}")
                        self._slot_ids[s] = parent
                        self._order.append(("slot", s))
        self._tool_frame = model.addFrame(
            pin.Frame("pincal_tool", parent, 0, pin.SE3.Identity(), pin.FrameType.OP_FRAME)
        )
        self.model = model
        self.data = model.createData()
        self._slot_columns = np.array([model.joints[j].idx_v for j in self._slot_ids], dtype=int)
        self._real_columns = np.array([model.joints[j].idx_v for j in self._real_ids], dtype=int)
        self._real_q = np.concatenate(
            [np.arange(model.joints[j].idx_q, model.joints[j].idx_q + model.joints[j].nq) for j in self._real_ids]
        )
        self._q_template = pin.neutral(model)
        self._slot_q = np.array([model.joints[j].idx_q for j in self._slot_ids], dtype=int)
        bent = np.array([slot.kind == "bend" for slot in self.slots], dtype=bool)
        self._bent = np.flatnonzero(bent)
        self._straight: np.ndarray | slice = np.flatnonzero(~bent) if bent.any() else slice(None)
        # per element of _order: its model joint, its chain joint, and its slot if that is revolute
        # (turning about a point, which set_state places) else None
        self._elements = [
            (self._real_ids[i], i, None) if what == "joint"
            else (self._slot_ids[i], self.slots[i].joint, i if self.slots[i].kind == "revolute" else None)
            for what, i in self._order
        ]
        self._identity_at = [True] * len(self._order)  # whether an element's placement is the identity

    def set_state(
        self,
        placements: Sequence[np.ndarray],
        slot_points: npt.ArrayLike,
        tip_T_tool: np.ndarray,
    ) -> None:
        """Set the chain's placements, the slots' points and the tool.

        Args:
            placements: N joint placements and the tip placement, as in
                :meth:`KinematicChain.placements`.
            slot_points: point each revolute slot turns about, in its frame
                [m], (n_slots, 3); ignored for prismatic slots.
            tip_T_tool: the tool (4, 4).
        """
        points = np.asarray(slot_points, dtype=float).reshape(len(self.slots), 3)
        off_origin = np.any(points != 0.0, axis=1).tolist()
        joint_placements, identity_at = self.model.jointPlacements, self._identity_at
        pending = None  # placement of the next element relative to the last frame; None: the identity
        group = -1
        for k, (element, joint, revolute) in enumerate(self._elements):
            if joint != group:  # first element of joint `joint`: its placement comes first
                pending = placements[joint] if pending is None else pending @ placements[joint]
                group = joint
            if revolute is not None and off_origin[revolute]:
                point = points[revolute]  # turn about an axis through the point
                if pending is None:
                    placement = pin.SE3(_EYE3, point)
                else:
                    placement = pin.SE3(pending[:3, :3], pending[:3, :3] @ point + pending[:3, 3])
                pending = np.eye(4)
                pending[:3, 3] = -point
            elif pending is not None:
                placement = pin.SE3(pending)
                pending = None
            elif identity_at[k]:  # the identity, which most slots keep: written only when it changes
                continue
            else:
                placement = _IDENTITY
            joint_placements[element] = placement
            identity_at[k] = placement is _IDENTITY
        tool = placements[-1] @ tip_T_tool if pending is None else pending @ placements[-1] @ tip_T_tool
        self.model.frames[self._tool_frame].placement = pin.SE3(tool)

    def evaluate(self, q: npt.ArrayLike, bends: npt.ArrayLike | None = None) -> tuple[ToolPoses, Sensitivity]:
        """Tool poses and parameter derivatives at K joint readings (K, N), the ``bend`` slots turned by
        ``bends`` (K, B) [rad] (None: zero); the other slots at zero."""
        configurations = self.chain.configurations(q)
        k = configurations.shape[0]
        augmented = np.tile(self._q_template, (k, 1))
        augmented[:, self._real_q] = configurations
        bent = self._bent
        if bends is not None and bent.size:
            augmented[:, self._slot_q[bent]] = np.asarray(bends, dtype=float).reshape(k, bent.size)
        model, data, fid = self.model, self.data, self._tool_frame
        world = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        joint_jacobians, frame_jacobian = pin.computeJointJacobians, pin.getFrameJacobian
        frame_placement = pin.updateFramePlacement
        rows_jacobians, rows_poses = [], []  # stacked once at the end: cheaper than a copy per row
        for configuration in augmented:
            joint_jacobians(model, data, configuration)  # forward kinematics + joint Jacobians
            rows_jacobians.append(frame_jacobian(model, data, fid, world))  # a new (6, nv) array
            rows_poses.append(frame_placement(model, data, fid).homogeneous)  # a new (4, 4) array
        jacobians = np.array(rows_jacobians).reshape(k, 6, model.nv)  # reshape: the shape for K = 0 too
        poses = np.array(rows_poses).reshape(k, 4, 4)
        joints = self.chain.followed_columns(jacobians[:, :, self._real_columns].transpose(0, 2, 1))  # eq M1
        jacobians = jacobians[:, :, self._slot_columns].transpose(0, 2, 1)
        positions = poses[:, :3, 3]
        straight = self._straight
        sensitivity = Sensitivity(
            angular=jacobians[:, straight, 3:],
            linear=jacobians[:, straight, :3],
            origin=positions,
            joint_angular=joints[:, :, 3:],
            joint_linear=joints[:, :, :3],
            bend_angular=jacobians[:, bent, 3:] if bent.size else None,
            bend_linear=jacobians[:, bent, :3] if bent.size else None,
        )
        return ToolPoses(positions, poses[:, :3, :3]), sensitivity
