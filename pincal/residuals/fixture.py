"""Residuals of a ball seated in the sockets of a fixture (no sensor; joints only).

Row k has the ball in socket i(k) of the fixture in placement s(k). With the
tip pose (t_k, R_k) from the chain, the ball centre m in the tip frame, the
socket centre f_i in the fixture frame and the placement's pose base_T_fixture
(R_s, c_s):

    e_k = t_k + R_k m − (c_s + R_s f_i)                         [m]     (F1)

Unknowns, in this order: the free kinematic parameters (through the cache),
m (3), then per placement c_s (3) and the rotation steps a_s of
R_s = R_s0 exp(B_s a_s). B_s (3 × d_s) spans what the placement's sockets
determine: with sockets on one line (direction u in the fixture frame) a turn
about u moves every socket alike — not at all if the line passes through the
fixture's origin — which c_s already covers, so B_s spans the two directions
orthogonal to u (d_s = 2) and that turn is never estimated; with sockets
spanning a plane, B_s = I (d_s = 3).

Jacobians (Pinocchio's right Jacobian Jexp3): d e/d theta = the ball's
velocity per unit parameter (:meth:`pincal.model.sensitivity.Sensitivity.point_velocity`);
d e/d m = R_k; d e/d c_s = −I; d e/d a_s = R_s [f_i]× Jexp3(B_s a_s) B_s
(from d(exp(phi) f) = −exp(phi) [f]× Jexp3(phi) d phi).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pinocchio as pin

from pincal.errors import CalibrationError
from pincal.residuals.base import BlockObjective, KinematicsCache
from pincal.residuals.so3 import skew

__all__ = ["COLLINEAR_TOLERANCE", "rotation_basis", "FixtureEstimate", "FixtureResidual"]

#: Sockets whose centred positions have a second singular value below this span a line [m].
COLLINEAR_TOLERANCE = 1e-6


def rotation_basis(points: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray | None]:
    """The rotation directions sockets at ``points`` (M, 3) [m] determine.

    Returns:
        B (3, d) with orthonormal columns — d = 2 for collinear sockets (the
        directions orthogonal to their line), 3 otherwise — and the line's unit
        direction u in the fixture frame (None when not collinear).

    Raises:
        CalibrationError: fewer than two distinct sockets.
    """
    points = np.asarray(points, dtype=float)
    centred = points - points.mean(axis=0)
    _, singular, vt = np.linalg.svd(centred)
    if singular[0] <= COLLINEAR_TOLERANCE:
        raise CalibrationError("a placement needs two distinct sockets to determine its pose")
    if len(singular) > 1 and singular[1] > COLLINEAR_TOLERANCE:
        return np.eye(3), None
    return vt[1:3].T.copy(), vt[0].copy()


@dataclass(frozen=True)
class FixtureEstimate:
    """Ball centre and placement poses at a parameter vector.

    Attributes:
        ball: m, the ball centre in the tip frame [m], (3,).
        rotations: R_s of each placement (S, 3, 3) (about a collinear fixture's
            line: the start's, not determined by the data).
        positions: c_s, each fixture frame's origin in the URDF root frame [m], (S, 3).
    """

    ball: np.ndarray
    rotations: np.ndarray
    positions: np.ndarray


class FixtureResidual(BlockObjective):
    """Eq F1 over the rows the cache holds.

    Args:
        cache: kinematics of the K rows (the chain's tool is the tip frame m is given in).
        placement: (K,) placement index s(k) of each row, 0 .. S − 1.
        socket_points: (K, 3) f_i(k), each row's socket centre in the fixture frame [m].
        bases: B_s per placement, (3, d_s) each.
        start: ball and placement poses to start from (a = 0).
        weight: residual weight [1/m] (1: residuals in metres).
    """

    def __init__(
        self,
        cache: KinematicsCache,
        placement: npt.ArrayLike,
        socket_points: npt.ArrayLike,
        bases: Sequence[np.ndarray],
        start: FixtureEstimate,
        weight: float = 1.0,
    ) -> None:
        super().__init__(cache)
        self.placement = np.asarray(placement, dtype=int)
        self.f = np.asarray(socket_points, dtype=float)
        self.bases = [np.asarray(b, dtype=float) for b in bases]
        self.start = start
        self.weight = float(weight)
        k = len(cache.q)
        if self.placement.shape != (k,) or self.f.shape != (k, 3):
            raise CalibrationError(f"fixture residual: expected placement ({k},) and socket points ({k}, 3), "
                                   f"got {self.placement.shape} and {self.f.shape}")
        self.blocks: dict[str, slice] = {"kinematic": slice(0, len(cache.free))}
        offset = len(cache.free)
        self.blocks["ball"] = slice(offset, offset + 3)
        offset += 3
        self.position_slices, self.rotation_slices = [], []
        for basis in self.bases:
            self.position_slices.append(slice(offset, offset + 3))
            self.rotation_slices.append(slice(offset + 3, offset + 3 + basis.shape[1]))
            offset += 3 + basis.shape[1]
        self.blocks["placements"] = slice(self.blocks["ball"].stop, offset)
        self.n_params = offset

    def start_vector(self) -> np.ndarray:
        """Kinematic values from the cache's base, the start's ball and positions, zero rotation steps."""
        x = np.zeros(self.n_params)
        x[self.blocks["kinematic"]] = self.cache.base[self.cache.free]
        x[self.blocks["ball"]] = self.start.ball
        for s, sl in enumerate(self.position_slices):
            x[sl] = self.start.positions[s]
        return x

    def _turns(self, x: np.ndarray) -> list[np.ndarray]:
        """phi_s = B_s a_s of each placement (3,)."""
        return [basis @ x[sl] for basis, sl in zip(self.bases, self.rotation_slices)]

    def estimate(self, x: npt.ArrayLike) -> FixtureEstimate:
        """Ball centre and placement poses at ``x``."""
        x = np.asarray(x, dtype=float)
        rotations = np.array([r0 @ pin.exp3(phi) for r0, phi in zip(self.start.rotations, self._turns(x))])
        positions = np.array([x[sl] for sl in self.position_slices])
        return FixtureEstimate(x[self.blocks["ball"]].copy(), rotations, positions)

    def ball_positions(self, x: npt.ArrayLike) -> np.ndarray:
        """p_k = t_k + R_k m, the ball centre of each row in the URDF root frame [m], (K, 3)."""
        x = np.asarray(x, dtype=float)
        poses, _ = self.cache.evaluate(x[self.blocks["kinematic"]])
        return poses.tool_positions + poses.tool_rotations @ x[self.blocks["ball"]]

    def socket_positions(self, x: npt.ArrayLike) -> np.ndarray:
        """c_s + R_s f_i of each row in the URDF root frame [m], (K, 3)."""
        fixture = self.estimate(x)
        rotations = fixture.rotations[self.placement]
        return fixture.positions[self.placement] + np.einsum("kij,kj->ki", rotations, self.f)

    def residual(self, x: npt.ArrayLike) -> np.ndarray:
        return (self.weight * (self.ball_positions(x) - self.socket_positions(x))).reshape(-1)

    def root_rotation_columns(self, x: npt.ArrayLike) -> np.ndarray:
        """d e/d omega for a turn exp(omega) of the whole URDF root frame, (3K, 3): −[p_k]×.

        Without a sensor nothing fixes the root frame: turning it turns every
        ball centre p_k and every placement with it, which leaves each ‖e_k‖
        as it is. The placements absorb the turn in the cost but not row by
        row — with collinear sockets they cannot turn about their line, and
        e_k itself turns — so this symmetry is stated here, for the
        identifiability analysis, which projects these columns out with the
        ball and the placements. (A shift of the root frame is the placements'
        shifts together: no column needed.)
        """
        return -skew(self.ball_positions(x)).reshape(-1, 3)

    def jacobian(self, x: npt.ArrayLike) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        poses, sens = self.cache.evaluate(x[self.blocks["kinematic"]])
        k = len(self.placement)
        rows = np.zeros((k, 3, self.n_params))
        ball = poses.tool_positions + poses.tool_rotations @ x[self.blocks["ball"]]
        rows[:, :, self.blocks["kinematic"]] = sens.point_velocity(ball).transpose(0, 2, 1)
        rows[:, :, self.blocks["ball"]] = poses.tool_rotations
        fixture = self.estimate(x)
        turned = fixture.rotations[self.placement] @ skew(self.f)  # R_s [f]x, (K, 3, 3)
        for s, (basis, phi) in enumerate(zip(self.bases, self._turns(x))):
            mine = self.placement == s
            rows[mine, :, self.position_slices[s]] = -np.eye(3)
            rows[mine, :, self.rotation_slices[s]] = turned[mine] @ (pin.Jexp3(phi) @ basis)
        return (self.weight * rows).reshape(-1, self.n_params)
