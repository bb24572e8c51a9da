"""Kinematic parameter sets over any serial chain of a URDF.

A parameter set maps a flat vector (zero = the URDF as loaded) to the chain's
placements and says where each parameter acts, so that
:class:`pincal.model.sensitivity.SensitivityModel` differentiates it with Pinocchio.

* :class:`JointOffsets` — the zero of each joint: a revolute or continuous
  joint's encoder offset [rad], a prismatic joint's zero [m]. Applied as an
  extra motion of the joint, ``M_j · X_j(delta_j)``.
* :class:`PlacementErrors` — the full placement error of each joint as an SE(3)
  exponential perturbation of its placement, ``M_j · exp(xi_j)`` with
  ``xi_j = (v, w)`` (m, rad; Pinocchio's ``exp6``). Six per joint; the joint
  offset is the rotation (or translation) about the joint axis among them.

Both share the interface of :class:`pincal.model.dh.parameters.DHParameterSet`:
``info``, ``size``, ``slots``, ``placements(vector)``, ``slot_points(vector)``,
``apply(vector)`` and ``slot_jacobian(vector)`` (the map from parameter steps to
slot twists; identity where the parameters are the slot coordinates).
"""

from __future__ import annotations

from typing import Literal, cast, get_args

import numpy as np
import pinocchio as pin

from pincal.model.chain import KinematicChain
from pincal.model.dh.parameters import ParameterInfo
from pincal.model.sensitivity import ParameterSlot

__all__ = [
    "joint_motion", "ChainParameters", "JointOffsets", "PlacementErrors", "NoParameters", "LEVELS", "CHAIN_LEVELS",
    "ChainLevel", "ParameterLevel",
]

_AXES = ("x", "y", "z")


class ChainParameters:
    """Common part: the chain and its placements as loaded (the zero vector)."""

    def __init__(self, chain: KinematicChain) -> None:
        self.chain = chain
        self.nominal_placements = chain.placements()
        self.info: tuple[ParameterInfo, ...] = ()
        self.slots: tuple[ParameterSlot, ...] = ()

    @property
    def size(self) -> int:
        return len(self.info)

    @property
    def nominal_vector(self) -> np.ndarray:
        return np.zeros(self.size)

    def slot_points(self, vector: np.ndarray) -> np.ndarray:
        """All revolute slots turn about their frame's origin."""
        return np.zeros((self.size, 3))

    def slot_jacobian(self, vector: np.ndarray) -> np.ndarray | None:
        """Map from parameter steps to slot coordinates (None: identity)."""
        return None

    def coupled(self, free: np.ndarray) -> np.ndarray:
        """Slots whose twists a step of the ``free`` parameters moves (see :meth:`slot_jacobian`)."""
        return np.asarray(free, dtype=int)

    def apply(self, vector: np.ndarray) -> None:
        self.chain.set_placements(self.placements(vector))

    def placements(self, vector: np.ndarray) -> list[np.ndarray]:
        raise NotImplementedError


def joint_motion(kind: str, axis: np.ndarray, value: float) -> np.ndarray:
    """Homogeneous motion of a joint of ``kind`` about/along ``axis`` by ``value`` [rad or m]."""
    out = np.eye(4)
    if kind == "prismatic":
        out[:3, 3] = axis * value
    else:
        out[:3, :3] = pin.exp3(axis * value)
    return out


class JointOffsets(ChainParameters):
    """Zero offset of every chain joint (N parameters, rad or m)."""

    def __init__(self, chain: KinematicChain) -> None:
        super().__init__(chain)
        self.info = tuple(
            ParameterInfo(f"{j.name}.offset", j.name, "m" if j.kind == "prismatic" else "rad")
            for j in chain.joints
        )
        self.slots = tuple(
            ParameterSlot(
                joint=i,
                after_motion=True,
                kind="prismatic" if j.kind == "prismatic" else "revolute",
                axis=cast("tuple[float, float, float]", tuple(float(a) for a in j.axis)),  # (3,)
            )
            for i, j in enumerate(chain.joints)
        )

    def placements(self, vector: np.ndarray) -> list[np.ndarray]:
        out = [p.copy() for p in self.nominal_placements]
        for i, joint in enumerate(self.chain.joints):
            out[i] = out[i] @ joint_motion(joint.kind, joint.axis, vector[i])
        return out


class PlacementErrors(ChainParameters):
    """SE(3) perturbation of every joint placement and of the tip (6N + 6 parameters).

    Joint j: ``M_j · exp(xi_j)``, xi_j in the joint's placement frame; names
    ``<joint>.tx, .ty, .tz`` (m) and ``.rx, .ry, .rz`` (rad). The tip link's
    placement on the last joint: ``exp(xi_tip) · M_tip``, xi_tip in the last
    joint's frame, names ``<tip link>.tx`` ... — absorbed by an estimated
    target, identifiable with a known tool.
    """

    def __init__(self, chain: KinematicChain) -> None:
        super().__init__(chain)
        info, slots = [], []
        owners = [(i, j.name, False) for i, j in enumerate(chain.joints)]
        owners.append((chain.n_joints - 1, chain.tip_link, True))
        for i, owner, after in owners:
            for kind, prefix, unit in (("prismatic", "t", "m"), ("revolute", "r", "rad")):
                for a, name in enumerate(_AXES):
                    axis = cast("tuple[float, float, float]", tuple(float(v) for v in np.eye(3)[a]))  # (3,)
                    info.append(ParameterInfo(f"{owner}.{prefix}{name}", owner, unit))
                    slots.append(ParameterSlot(joint=i, after_motion=after, kind=kind, axis=axis))
        self.info, self.slots = tuple(info), tuple(slots)

    def placements(self, vector: np.ndarray) -> list[np.ndarray]:
        xi = np.asarray(vector, dtype=float).reshape(-1, 6)
        out = [p.copy() for p in self.nominal_placements]
        for i in range(self.chain.n_joints):
            out[i] = out[i] @ pin.exp6(xi[i]).homogeneous
        out[-1] = pin.exp6(xi[-1]).homogeneous @ out[-1]
        return out

    def coupled(self, free: np.ndarray) -> np.ndarray:
        """Every parameter of a placement that has a free parameter."""
        blocks = np.unique(np.asarray(free, dtype=int) // 6)
        return (6 * blocks[:, None] + np.arange(6)).ravel()

    def slot_jacobian(self, vector: np.ndarray) -> np.ndarray:
        """Block diagonal of Pinocchio's right Jacobian ``Jexp6(xi_j)`` for the
        joints (exp(xi + d) ≈ exp(xi) exp(Jexp6(xi) d)) and of the left one,
        ``Jexp6(-xi_tip)``, for the tip."""
        xi = np.asarray(vector, dtype=float).reshape(-1, 6)
        out = np.zeros((self.size, self.size))
        for i, block in enumerate(xi):
            sign = -1.0 if i == len(xi) - 1 else 1.0
            out[6 * i : 6 * i + 6, 6 * i : 6 * i + 6] = pin.Jexp6(sign * block)
        return out


class NoParameters(ChainParameters):
    """The empty kinematic parameter set (level ``registration``): the URDF as loaded."""

    def placements(self, vector: np.ndarray) -> list[np.ndarray]:
        return [p.copy() for p in self.nominal_placements]


#: A level that fits kinematic parameters of any chain (a key of :data:`LEVELS`).
ParameterLevel = Literal["offsets", "full"]
#: A level of a calibration of any chain: the registration alone (nothing of the URDF fitted), then
#: the parameter sets of :data:`LEVELS`.
ChainLevel = Literal["registration", "offsets", "full"]

LEVELS: dict[ParameterLevel, type[JointOffsets] | type[PlacementErrors]] = {
    "offsets": JointOffsets, "full": PlacementErrors,
}
#: The values of :data:`ChainLevel`, in order.
CHAIN_LEVELS: tuple[ChainLevel, ...] = get_args(ChainLevel)
