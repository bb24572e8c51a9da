"""DH parameters of a chain as the unknowns of a calibration.

:class:`DHParameterSet` ties a :class:`pincal.model.dh.table.DHTable` to a
:class:`pincal.model.chain.KinematicChain` whose joint placements realise it (see
:meth:`pincal.model.dh.table.DHTable.joint_origins`). It gives the names of the 4N
parameters, writes a table into the chain's placements, and says where each
parameter acts (:class:`pincal.model.sensitivity.ParameterSlot`) so that
:class:`pincal.model.sensitivity.SensitivityModel` can differentiate with Pinocchio.

The flat order is that of :meth:`DHTable.to_vector`: ``alpha_1..N, epsilon_1..N,
r_1..N, d_1..N`` (rad, rad, m, m).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pincal.errors import ModelError, PincalError
from pincal.model.chain import KinematicChain
from pincal.model.dh.table import DH_FIELDS, DHTable, dh_joint_origins
from pincal.model.sensitivity import ParameterSlot

__all__ = ["ParameterInfo", "DHParameterSet"]

_UNITS = {"alpha": "rad", "epsilon": "rad", "r": "m", "d": "m"}


@dataclass(frozen=True)
class ParameterInfo:
    """Name, joint and unit of one parameter."""

    name: str
    joint: str
    unit: str


class DHParameterSet:
    """The 4N DH parameters of a DH-shaped chain.

    Args:
        chain: the chain; its current placements must be DH-shaped.
        table: the table to start from (default: read from the chain).
    """

    def __init__(self, chain: KinematicChain, table: DHTable | None = None) -> None:
        if any(j.kind == "prismatic" for j in chain.joints):
            raise ModelError(f"{chain.source}: DH parameters need revolute joints only")
        if any(np.abs(j.axis - (0.0, 0.0, 1.0)).max() > 1e-12 for j in chain.joints):
            raise ModelError(f"{chain.source}: DH parameters need joint axes along z")
        if table is None:
            try:
                table = DHTable.from_joint_origins(chain.placements())
            except PincalError as exc:
                raise ModelError(
                    f"{chain.source}: the chain to '{chain.tip_link}' is not DH-shaped ({exc})"
                ) from None
        if table.n_joints != chain.n_joints:
            raise ModelError(
                f"DH table has {table.n_joints} rows but the chain has {chain.n_joints} joints"
            )
        self.chain = chain
        self.nominal = table
        n = table.n_joints
        self.info = tuple(
            ParameterInfo(f"{field}_{i + 1}", chain.joints[i].name, _UNITS[field])
            for field in DH_FIELDS
            for i in range(n)
        )

    @property
    def size(self) -> int:
        return 4 * self.nominal.n_joints

    def indices(self, field: str, joints: range | list[int] | None = None) -> np.ndarray:
        """Flat indices of ``field`` (alpha, epsilon, r, d) for 0-based ``joints`` (all if None)."""
        n = self.nominal.n_joints
        start = DH_FIELDS.index(field) * n
        joints = range(n) if joints is None else joints
        return np.array([start + j for j in joints], dtype=int)

    def placements(self, vector: np.ndarray) -> list[np.ndarray]:
        """Chain placements (N joints + tip) realising the table ``vector`` (4N,)."""
        return dh_joint_origins(vector)

    def apply(self, vector: np.ndarray) -> None:
        """Write the table ``vector`` (4N,) into the chain's joint placements."""
        self.chain.set_placements(self.placements(vector))

    @property
    def slots(self) -> tuple[ParameterSlot, ...]:
        """Where each parameter acts, all in the child frame of its joint n:
        alpha_n turns about x through (r_n, 0, d_n), eps_n turns about z like
        the joint itself, r_n translates along x and d_n along z."""
        n = self.nominal.n_joints
        kinds = {
            "alpha": ("revolute", (1.0, 0.0, 0.0)),
            "epsilon": ("revolute", (0.0, 0.0, 1.0)),
            "r": ("prismatic", (1.0, 0.0, 0.0)),
            "d": ("prismatic", (0.0, 0.0, 1.0)),
        }
        return tuple(
            ParameterSlot(joint=i, after_motion=True, kind=kinds[field][0], axis=kinds[field][1])
            for field in DH_FIELDS
            for i in range(n)
        )

    def slot_jacobian(self, vector: np.ndarray) -> None:
        """DH parameters are the slot coordinates themselves (identity map)."""
        return None

    def coupled(self, free: np.ndarray) -> np.ndarray:
        return np.asarray(free, dtype=int)

    def slot_points(self, vector: np.ndarray) -> np.ndarray:
        """Point each slot turns about, in its frame [m], (4N, 3): (r_n, 0, d_n) for alpha_n."""
        _, _, r, d = np.asarray(vector, dtype=float).reshape(4, -1)
        points = np.zeros((4, r.size, 3))
        points[0, :, 0] = r
        points[0, :, 2] = d
        return points.reshape(-1, 3)
