"""DH parameters of a chain as the unknowns of a calibration.

:class:`DHParameterSet` ties a :class:`pincal.dh.DHTable` to a
:class:`pincal.chain.KinematicChain` whose joint placements realise it (see
:meth:`pincal.dh.DHTable.joint_origins`). It gives the names of the 4N
parameters, writes a table into the chain's placements, and gives each
parameter's local twist for :func:`pincal.sensitivity.sensitivity`.

The flat order is that of :meth:`DHTable.to_vector`: ``alpha_1..N, epsilon_1..N,
r_1..N, d_1..N`` (rad, rad, m, m).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .chain import KinematicChain
from .dh import DH_FIELDS, DHTable
from .errors import ModelError, PincalError

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
        self.frame_index = np.tile(np.arange(n), 4)

    @property
    def size(self) -> int:
        return 4 * self.nominal.n_joints

    def indices(self, field: str, joints: range | list[int] | None = None) -> np.ndarray:
        """Flat indices of ``field`` (alpha, epsilon, r, d) for 0-based ``joints`` (all if None)."""
        n = self.nominal.n_joints
        start = DH_FIELDS.index(field) * n
        joints = range(n) if joints is None else joints
        return np.array([start + j for j in joints], dtype=int)

    def apply(self, vector: np.ndarray) -> None:
        """Write the table ``vector`` (4N,) into the chain's joint placements."""
        self.chain.set_placements(DHTable.from_vector(vector).joint_origins())

    def local_twists(self, vector: np.ndarray) -> np.ndarray:
        """Twist ``(v, w)`` of each parameter in its joint frame (4N, 6).

        In the child frame of joint n (after its motion), row n's d_n translates
        along z, r_n along x, alpha_n rotates about the x axis through (r_n, 0,
        d_n), and eps_n rotates about z like the joint itself.
        """
        table = DHTable.from_vector(vector)
        n = table.n_joints
        twists = np.zeros((4, n, 6))
        twists[0, :, 3] = 1.0  # alpha: w = x
        twists[0, :, 1] = table.d  # v = p x w with p = (r, 0, d)
        twists[1, :, 5] = 1.0  # epsilon: w = z
        twists[2, :, 0] = 1.0  # r: v = x
        twists[3, :, 2] = 1.0  # d: v = z
        return twists.reshape(4 * n, 6)
