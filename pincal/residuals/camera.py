"""Reprojection residuals of a board's corners seen by a camera, through the chain, in pixels.

Image k shows corner c at the pixel g_c; the corner is b_c on the board [m] (z = 0, OpenCV's board
frame). With the tip pose (t_k, R_k) from the chain (:class:`pincal.residuals.base.KinematicsCache`,
the tool the identity), the mount M = (R_M, t_M) on the tip link, the world frame W_s = (R_W, t_W) of
image k's session and the camera's intrinsics kappa (:func:`pincal.model.pinhole.project`, eqs P1-P3):

* **eye to hand** (the board on the chain, M = tip_T_board; the camera fixed, W = camera_T_base):
  ``y = t_k + R_k (R_M b + t_M)``, ``p = R_W y + t_W``                                       (C1)
* **eye in hand** (the camera on the chain, M = tip_T_camera; the board fixed, W = base_T_board):
  ``y = R_W b + t_W``, ``p = R_Mᵀ (R_kᵀ (y − t_k) − t_M)``                                    (C2)

and the residual is ``e_c = project(kappa, p) − g_c`` [px] (C3). Eye to hand is the point sensor of
:mod:`pincal.residuals.sensor` with the target points M b (known up to the mount) and a projection; W
plays the registration's part in both (eqs C1, C2: :func:`pincal.model.camera_view.camera_points`).
Unknowns, in this order: the free kinematic parameters, W_s of each session (6 each: the right
rotation phi of the start's R_W [rad], then t_W [m]), the mount
(psi of R_M [rad], t_M [m]), the intrinsics fitted (a subset of ``fx fy cx cy k1 k2 p1 p2 k3``,
their values), and the values a_e of the joint effects fitted (:mod:`pincal.model.effects`).

A joint effect moves its joint's angle from the reading: q_k = q̃_k + Σ_e B_e(k) a_e (B_e the effect's basis over
the images, :func:`pincal.model.effects.joint_basis`; followers of a ``<mimic>`` driver move with it), so the
chain is evaluated at q_k and the camera or board moves as under a joint offset:

* de/da_e = (dpixel/dp) (dp/dq_j) B_e(k), with dp/dq_j eq C1's or C2's dp/dtheta for the joint's own
  Jacobian column (Pinocchio's joint Jacobian at q_k, carried to the followers' joints).                  (C4)

Jacobians, with v the velocity of the base-frame point y carried by the tip per unit parameter
(:meth:`pincal.model.sensitivity.Sensitivity.point_velocity`, Pinocchio's frame Jacobians) and
Jexp3 Pinocchio's right Jacobian (d(R exp(phi) b) = −R [b]× Jexp3(phi) d phi):

* C1: dp/dtheta = R_W v; dp/dphi_W = −R_W [y]× Jexp3(phi_W); dp/dt_W = I;
  dp/dpsi = −R_W R_k R_M [b]× Jexp3(psi); dp/dt_M = R_W R_k;
* C2: dp/dtheta = −R_Mᵀ R_kᵀ v; dp/dphi_W = −R_Mᵀ R_kᵀ R_W [b]× Jexp3(phi_W); dp/dt_W = R_Mᵀ R_kᵀ;
  dp/dpsi = [p]× Jexp3(psi) (from exp(psi + d)ᵀ ≈ (I − [Jexp3(psi) d]×) exp(psi)ᵀ); dp/dt_M = −R_Mᵀ;

then de/d(·) = (dpixel/dp) dp/d(·) and de/dkappa from :func:`pincal.model.pinhole.projection_jacobians`.
Every corner of every image is evaluated at once (stacks of M corners); the chain's model is only
evaluated, never rebuilt.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import cast

import numpy as np
import numpy.typing as npt
import pinocchio as pin

from pincal.measurements.camera_csv import CornerSet
from pincal.model.camera_view import Arrangement, camera_points, pose
from pincal.model.effects import JOINT_EFFECTS, Effect, EffectInputs, joint_basis
from pincal.model.pinhole import INTRINSIC_NAMES, CameraIntrinsics, project, projection_jacobians
from pincal.model.sensitivity import Sensitivity, ToolPoses
from pincal.residuals.base import BlockObjective, KinematicsCache
from pincal.residuals.sensor_values import ModelledEffects
from pincal.residuals.so3 import skew

__all__ = ["CameraEstimate", "CameraResidual"]

#: dp/d(·) of velocities of the carried points (M, n, 3) → (M, 3, n).
_Carry = Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True)
class CameraEstimate:
    """The camera's unknowns besides the kinematics, at a parameter vector.

    Attributes:
        arrangement: ``eye_in_hand`` or ``eye_to_hand``.
        worlds: W_s per session (S, 4, 4): ``camera_T_base`` (eye to hand) or ``base_T_board`` (eye in hand) [m].
        mount: M (4, 4): ``tip_T_board`` (eye to hand) or ``tip_T_camera`` (eye in hand) [m], the camera's
            optical frame (x right, y down, z ahead).
        intrinsics: the camera's intrinsics.
    """

    arrangement: Arrangement
    worlds: np.ndarray
    mount: np.ndarray
    intrinsics: CameraIntrinsics


class CameraResidual(BlockObjective):
    """Eqs C1-C3 of the module docstring over the images the cache holds (its rows).

    Args:
        cache: kinematics of the K images (the chain's tip: the link carrying the board or the camera).
        corners: the corners seen (their image, board point and pixel).
        start: the world frames, mount and intrinsics to start from (the intrinsics not fitted stay there).
        fitted_intrinsics: indices into :data:`pincal.model.pinhole.INTRINSIC_NAMES` of the intrinsics
            estimated (default: none, the intrinsics given).
        sessions: (K,) each image's session, an index into ``start.worlds`` (default: all in session 0).
        effects: the joint effects fitted and their inputs over the K images (eq C4; default: none). Inputs
            without effects let :meth:`effect_columns` test candidates.
    """

    def __init__(self, cache: KinematicsCache, corners: CornerSet, start: CameraEstimate,
                 fitted_intrinsics: tuple[int, ...] = (), sessions: npt.ArrayLike | None = None,
                 effects: ModelledEffects | None = None) -> None:
        super().__init__(cache)
        self.start = start
        self.image_of = np.asarray(corners.image_of, dtype=np.intp)  # (M,)
        self.board = np.asarray(corners.board_points, dtype=float)  # (M, 3) [m]
        self.pixels = np.asarray(corners.pixels, dtype=float)  # (M, 2) [px]
        k = len(cache.q)
        self.n_sessions = len(start.worlds)
        image_sessions = np.zeros(k, dtype=np.intp) if sessions is None else np.asarray(sessions, dtype=np.intp)
        if image_sessions.shape != (k,) or np.any((image_sessions < 0) | (image_sessions >= self.n_sessions)):
            raise ValueError(f"sessions must be ({k},) indices below {self.n_sessions}")
        self.session_of = image_sessions[self.image_of]  # each corner's session (M,)
        self.fitted_intrinsics = tuple(int(i) for i in fitted_intrinsics)
        effects = ModelledEffects() if effects is None else effects
        self.effects = tuple(effects.effects)
        self.inputs = effects.inputs
        other = [e.label for e in self.effects if e.type not in JOINT_EFFECTS]
        if other or (self.effects and self.inputs is None):
            raise ValueError(f"a camera's residual fits joint effects with their inputs, not {other or 'without'}")
        self._effect_joint = [cache.params.chain.joint_names.index(cast(str, e.joint)) for e in self.effects]
        self._effect_basis = [joint_basis(e, cast(EffectInputs, self.inputs), j)
                              for e, j in zip(self.effects, self._effect_joint)]  # (K, n_values) each
        sizes = {"kinematic": len(cache.free), "world": 6 * self.n_sessions, "mount": 6,
                 "intrinsics": len(self.fitted_intrinsics), "effects": sum(e.n_values for e in self.effects)}
        self.blocks: dict[str, slice] = {}
        offset = 0
        for name, size in sizes.items():
            self.blocks[name] = slice(offset, offset + size)
            offset += size
        self.n_params = offset
        first = self.blocks["effects"].start
        self.effect_slices: list[slice] = []
        for effect in self.effects:
            self.effect_slices.append(slice(first, first + effect.n_values))
            first += effect.n_values

    def start_vector(self) -> np.ndarray:
        """Kinematic values from the cache's base, zero rotation steps, the start's translations and intrinsics."""
        x = np.zeros(self.n_params)
        x[self.blocks["kinematic"]] = self.cache.base[self.cache.free]
        world = x[self.blocks["world"]].reshape(-1, 6)
        world[:, 3:] = self.start.worlds[:, :3, 3]
        x[self.blocks["mount"].start + 3 : self.blocks["mount"].stop] = self.start.mount[:3, 3]
        x[self.blocks["intrinsics"]] = self.start.intrinsics.vector()[list(self.fitted_intrinsics)]
        return x

    def estimate(self, x: npt.ArrayLike) -> CameraEstimate:
        """World frames, mount and intrinsics at ``x``."""
        x = np.asarray(x, dtype=float)
        world = x[self.blocks["world"]].reshape(-1, 6)
        worlds = np.array([pose(w[:3, :3] @ pin.exp3(v[:3]), v[3:]) for w, v in zip(self.start.worlds, world)])
        mount = x[self.blocks["mount"]]
        values = self.start.intrinsics.vector()
        values[list(self.fitted_intrinsics)] = x[self.blocks["intrinsics"]]
        return CameraEstimate(self.start.arrangement, worlds,
                              pose(self.start.mount[:3, :3] @ pin.exp3(mount[:3]), mount[3:]),
                              self.start.intrinsics.with_vector(values))

    def effect_values(self, x: npt.ArrayLike) -> list[np.ndarray]:
        """Values of each effect at ``x``."""
        x = np.asarray(x, dtype=float)
        return [x[sl] for sl in self.effect_slices]

    def joint_values(self, x: npt.ArrayLike) -> np.ndarray | None:
        """The joint angles q_k the effects at ``x`` move the readings to (K, N) [rad or m] (eq C4; None: the
        readings, without effects)."""
        if not self.effects:
            return None
        x = np.asarray(x, dtype=float)
        inputs = cast(EffectInputs, self.inputs)
        shifts = np.zeros_like(inputs.q)
        for j, basis, sl in zip(self._effect_joint, self._effect_basis, self.effect_slices):
            shifts[:, j] += basis @ x[sl]
        return inputs.q + self.cache.params.chain.followed_shifts(shifts)  # followers move too (eq M1)

    def _state(self, x: np.ndarray) -> tuple[ToolPoses, Sensitivity, CameraEstimate, np.ndarray, np.ndarray]:
        """Tip poses, sensitivities, the estimate, each corner's base-frame point y (M, 3) and camera point p (M, 3)."""
        poses, sens = self.cache.evaluate(x[self.blocks["kinematic"]], self.joint_values(x))
        estimate = self.estimate(x)
        tips = (poses.tool_rotations[self.image_of], poses.tool_positions[self.image_of])
        y, p = camera_points(self.start.arrangement, tips, estimate.worlds[self.session_of], estimate.mount, self.board)
        return poses, sens, estimate, y, p

    def camera_points(self, x: npt.ArrayLike) -> np.ndarray:
        """Each corner in the camera's optical frame at ``x`` (M, 3) [m]."""
        return self._state(np.asarray(x, dtype=float))[4]

    def residual(self, x: npt.ArrayLike) -> np.ndarray:
        """Eq C3: (u, v) of each corner, model minus measured, (2M,) [px]."""
        _, _, estimate, _, p = self._state(np.asarray(x, dtype=float))
        return (project(estimate.intrinsics, p) - self.pixels).reshape(-1)

    def jacobian(self, x: npt.ArrayLike) -> np.ndarray:
        """d(eq C3)/dx (2M, n) [px per unit] (the module docstring's chain rule)."""
        x = np.asarray(x, dtype=float)
        poses, sens, estimate, y, p = self._state(x)
        c = self.image_of
        rotations = poses.tool_rotations[c]  # R_k of each corner (M, 3, 3)
        velocity = sens.linear[c] + np.cross(sens.angular[c], (y - sens.origin[c])[:, None, :])  # v (M, n, 3)
        w_rot = estimate.worlds[self.session_of, :3, :3]
        m_rot = estimate.mount[:3, :3]
        world_steps = x[self.blocks["world"]].reshape(-1, 6)[:, :3]
        jexp_world = np.array([pin.Jexp3(v) for v in world_steps])[self.session_of]  # (M, 3, 3)
        jexp_mount = pin.Jexp3(x[self.blocks["mount"]][:3])
        n_corners = len(c)
        world = np.zeros((n_corners, 3, 6))
        mount = np.zeros((n_corners, 3, 6))
        carry = self._carry(rotations, w_rot, m_rot)
        kinematic = carry(velocity)
        if self.start.arrangement == "eye_to_hand":  # eq C1's derivatives
            world[:, :, :3] = -w_rot @ skew(y) @ jexp_world
            world[:, :, 3:] = np.eye(3)
            carried = w_rot @ rotations  # R_W R_k
            mount[:, :, :3] = -carried @ m_rot @ skew(self.board) @ jexp_mount
            mount[:, :, 3:] = carried
        else:  # eq C2's
            back = m_rot.T @ rotations.transpose(0, 2, 1)  # R_Mᵀ R_kᵀ
            world[:, :, :3] = -back @ w_rot @ skew(self.board) @ jexp_world
            world[:, :, 3:] = back
            mount[:, :, :3] = skew(p) @ jexp_mount
            mount[:, :, 3:] = -m_rot.T
        d_point, d_intrinsics = projection_jacobians(estimate.intrinsics, p)  # (M, 2, 3), (M, 2, 9)
        out = np.zeros((n_corners, 2, self.n_params))
        out[:, :, self.blocks["kinematic"]] = d_point @ kinematic
        sessions = self.blocks["world"].start + 6 * self.session_of[:, None] + np.arange(6)  # (M, 6) columns
        np.put_along_axis(out, np.broadcast_to(sessions[:, None, :], (n_corners, 2, 6)), d_point @ world, axis=2)
        out[:, :, self.blocks["mount"]] = d_point @ mount
        out[:, :, self.blocks["intrinsics"]] = d_intrinsics[:, :, list(self.fitted_intrinsics)]
        if self.effects:  # eq C4
            joints = self._joint_pixels(sens, y, d_point, carry)
            for j, basis, sl in zip(self._effect_joint, self._effect_basis, self.effect_slices):
                out[:, :, sl] = joints[:, :, j, None] * basis[c][:, None, :]
        return out.reshape(2 * n_corners, self.n_params)

    def _carry(self, rotations: np.ndarray, w_rot: np.ndarray, m_rot: np.ndarray) -> _Carry:
        """dp/d(·) of velocities v (M, n, 3) of the base-frame points y carried by the tip (eq C1: R_W v; eq C2:
        −R_Mᵀ R_kᵀ v), as (M, 3, n)."""
        if self.start.arrangement == "eye_to_hand":
            return lambda velocity: np.einsum("mij,mnj->min", w_rot, velocity)
        back = m_rot.T @ rotations.transpose(0, 2, 1)
        return lambda velocity: -np.einsum("mij,mnj->min", back, velocity)

    def _joint_pixels(self, sens: Sensitivity, y: np.ndarray, d_point: np.ndarray, carry: _Carry) -> np.ndarray:
        """de/dq_j of each corner and chain joint (M, 2, N) [px per rad or m] (eq C4 before the basis), a driver's
        column with its followers' (:meth:`pincal.model.chain.KinematicChain.followed_columns`)."""
        c = self.image_of
        assert sens.joint_angular is not None and sens.joint_linear is not None  # SensitivityModel sets them
        velocity = sens.joint_linear[c] + np.cross(sens.joint_angular[c], (y - sens.origin[c])[:, None, :])
        velocity = self.cache.params.chain.followed_columns(velocity)  # (M, N, 3)
        return d_point @ carry(velocity)

    def effect_columns(self, x: npt.ArrayLike, effects: Sequence[Effect]) -> list[np.ndarray]:
        """The Jacobian columns each joint effect of ``effects`` would add at ``x``, its values zero: (2M,
        n_values) per effect in the row order of :meth:`residual` (eq C4; the residual needs its inputs)."""
        x = np.asarray(x, dtype=float)
        if not effects:
            return []
        inputs = cast(EffectInputs, self.inputs)
        poses, sens, estimate, y, p = self._state(x)
        c = self.image_of
        carry = self._carry(poses.tool_rotations[c], estimate.worlds[self.session_of, :3, :3], estimate.mount[:3, :3])
        joints = self._joint_pixels(sens, y, projection_jacobians(estimate.intrinsics, p)[0], carry)
        names = list(self.cache.params.chain.joint_names)
        out = []
        for effect in effects:
            j = names.index(cast(str, effect.joint))
            basis = joint_basis(effect, inputs, j)
            out.append((joints[:, :, j, None] * basis[c][:, None, :]).reshape(2 * len(c), effect.n_values))
        return out

    def column_names(self, kinematic: list[str], session_names: tuple[str, ...] = ()) -> list[str]:
        """Names of the columns: ``kinematic`` (the free kinematic parameters'), then ``camera.rx`` ... /
        ``board.rx`` ... (the world frame, ``[session]`` with several), ``mount.rx`` ..., the intrinsics."""
        world = "camera" if self.start.arrangement == "eye_to_hand" else "board"
        prefixes = [world] if self.n_sessions == 1 else [f"{world}[{n}]" for n in session_names]
        names = list(kinematic)
        names += [f"{prefix}.{axis}" for prefix in prefixes for axis in ("rx", "ry", "rz", "x", "y", "z")]
        names += [f"mount.{axis}" for axis in ("rx", "ry", "rz", "x", "y", "z")]
        names += [f"intrinsics.{INTRINSIC_NAMES[i]}" for i in self.fitted_intrinsics]
        return names
