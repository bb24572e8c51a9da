"""Absolute residuals of measured target points (and orientations) in the sensor frame.

For row k and target point p, with the tool pose (t_k, R_k) from the chain, the
target's points m_p in the tool frame and the registration sensor_T_base
(Omega, tau) of row k's session (one registration per session: the sensor moved
between sessions, the robot and the target did not):

    e_kp = w_k (Omega (t_k + R_k m_p) + tau − g_kp)            [dimensionless]
    o_k  = v_k log(G_kᵀ Omega R_k R_T)                          (with orientations)

w_k = 1/sigma_pos,k [1/m] and v_k = 1/sigma_rot,k [1/rad] weight each row by its
measurement noise, so position and orientation need no ad-hoc scale. Unknowns,
in this order: the free kinematic parameters (through the cache), the
registrations (Omega_s = Omega_s0 exp(phi_s), tau_s: 6 per session, session 0
first), the points m_p, and the target
rotation R_T = R_T0 exp(psi), and the values of unmodelled effects
(:mod:`pincal.model.effects`): joint effects shift the joint readings before the
forward kinematics, ``drift`` adds t_k u to the registration's translation,
``sensor_scale`` multiplies the sensed coordinates by (1 + s), ``thermal`` scales
y by f_k and ``pause_step`` adds d_k like a drift (eq T1–T2 of :mod:`pincal.model.thermal`;
columns :mod:`pincal.residuals.conditions`). Each block can be held fixed.

Jacobians (right perturbations, Pinocchio's Jexp3 and Jlog3):
d e/d theta = w Omega · point velocity; d e/d phi = −w Omega [y]× Jexp3(phi) with
y = t + R m; d e/d tau = w I; d e/d m_p = w Omega R (a row's registration columns
are those of its own session, zero in the others'). With E = G_kᵀ Omega R_k R_T:
d o/d theta = v Jlog3(E) Eᵀ G_kᵀ Omega · angular velocity;
d o/d phi = v Jlog3(E) (R_k R_T)ᵀ Jexp3(phi); d o/d psi = v Jlog3(E) Jexp3(psi).

With the chain's tool as the measured frame (one zero target point, R_T = I,
neither fitted: :func:`pincal.residuals.tool_pose.tool_pose_residual`) and w = 1/sigma_p, v = 1/sigma_a
the sensor's noise (eq 20–22), the least-squares solution is the
maximum-likelihood estimate of :mod:`pincal.paper.ml_estimator`;
:meth:`SensorResidual.noise_jacobian` gives the derivative with respect to the
sensor noise that :mod:`pincal.paper.noise_limit` propagates.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import cast

import numpy as np
import numpy.typing as npt
import pinocchio as pin

from pincal.model.chain import points_in_base
from pincal.model.effects import JOINT_EFFECTS, Effect, EffectInputs, joint_basis, sensed_points
from pincal.model.sensitivity import Sensitivity, ToolPoses
from pincal.model.sensor import Registration
from pincal.model.thermal import row_conditions
from pincal.residuals.base import BlockObjective, KinematicsCache
from pincal.residuals.bends import bend_bases, bend_columns, lateral_columns, row_bends
from pincal.residuals.conditions import condition_columns, point_columns
from pincal.residuals.sensor_values import (
    FittedBlocks,
    Linearisation,
    ModelledEffects,
    RowWeights,
    SensorState,
    TargetEstimate,
)
from pincal.residuals.so3 import jlog3, log3, skew

# TargetEstimate: defined in sensor_values, listed here too for the code that imports it from here
__all__ = ["REGISTRATION_NAMES", "TargetEstimate", "SensorResidual"]

#: Names of the six registration unknowns: the right rotation phi of Omega_0 [rad], tau [m].
REGISTRATION_NAMES = ("phi_x", "phi_y", "phi_z", "tau_x", "tau_y", "tau_z")


class SensorResidual(BlockObjective):
    """Eq of the module docstring over the rows the cache holds.

    Args:
        cache: kinematics of the K rows.
        sensor_points: measured points g_kp [m], (K, P, 3).
        sensor_rotations: measured target orientations G_k, (K, 3, 3), or None.
        start: registration, points and target rotation to start from.
        weights: w_k [1/m] and v_k [1/rad] (:class:`~pincal.residuals.sensor_values.RowWeights`; default: 1).
        fitted: which blocks are unknown, in which directions
            (:class:`~pincal.residuals.sensor_values.FittedBlocks`; default: all, in every direction).
        effects: the effects fitted, their inputs, and fixed per-row changes they add to
            (:class:`~pincal.residuals.sensor_values.ModelledEffects`; default: none).
        sessions: (K,) each row's session, an index into ``start.registrations``;
            needed when there are several (default: every row in session 0).
    """

    def __init__(
        self,
        cache: KinematicsCache,
        sensor_points: npt.ArrayLike,
        sensor_rotations: npt.ArrayLike | None,
        start: TargetEstimate,
        weights: RowWeights | None = None,
        fitted: FittedBlocks | None = None,
        effects: ModelledEffects | None = None,
        sessions: npt.ArrayLike | None = None,
    ) -> None:
        super().__init__(cache)
        weights = RowWeights() if weights is None else weights
        fitted = FittedBlocks() if fitted is None else fitted
        effects = ModelledEffects() if effects is None else effects
        inputs, conditions = effects.inputs, effects.conditions
        fit_registration, fit_points, fit_rotation = fitted.registration, fitted.points, fitted.rotation
        point_basis, registration_basis = fitted.point_basis, fitted.registration_basis
        self.effects = tuple(effects.effects)
        self.inputs = inputs
        self.conditions = conditions
        self._conditional = conditions is not None or any(e.type in ("thermal", "pause_step") for e in self.effects)
        if self.effects and inputs is None:
            raise ValueError("effects need their inputs (gravity torques, time)")
        joint_names = list(cache.params.chain.joint_names)
        self._effect_joint = [joint_names.index(e.joint) if e.joint else -1 for e in self.effects]
        self._effect_basis = [  # effects have their inputs (raised above otherwise)
            joint_basis(e, cast(EffectInputs, inputs), j) if e.type in JOINT_EFFECTS else None
            for e, j in zip(self.effects, self._effect_joint)
        ]
        self._bend_basis = bend_bases(self.effects, inputs, self._effect_joint)  # lateral compliances' (eq L3)
        if any(e.type == "drift" for e in self.effects) and (inputs is None or inputs.time is None):
            raise ValueError("a drift effect needs a time column")
        self.g = np.asarray(sensor_points, dtype=float)
        self.G = None if sensor_rotations is None else np.asarray(sensor_rotations, dtype=float)
        k, n_points = self.g.shape[:2]
        self.start = start
        self.n_sessions = len(start.registrations)
        if sessions is None and self.n_sessions > 1:
            raise ValueError(f"{self.n_sessions} registrations need each row's session")
        self.sessions = np.zeros(k, dtype=np.intp) if sessions is None else np.asarray(sessions, dtype=np.intp)
        if self.sessions.shape != (k,) or np.any((self.sessions < 0) | (self.sessions >= self.n_sessions)):
            raise ValueError(f"sessions must be ({k},) indices below {self.n_sessions}")
        self._session_rows = [np.flatnonzero(self.sessions == s) for s in range(self.n_sessions)]
        self.w = np.broadcast_to(np.asarray(weights.position, dtype=float), (k,)).copy()
        self.v = np.broadcast_to(np.asarray(weights.rotation, dtype=float), (k,)).copy()
        n_kin = len(cache.free)
        self.point_basis = None
        if point_basis is not None and fit_points:
            self.point_basis = np.asarray(point_basis, dtype=float).reshape(3 * n_points, -1)
        self.registration_basis = None
        if registration_basis is not None and fit_registration:
            self.registration_basis = np.asarray(registration_basis, dtype=float).reshape(6 * self.n_sessions, -1)
        self.effect_slices = []
        sizes = {
            "kinematic": n_kin,
            "registration": (6 * self.n_sessions if self.registration_basis is None
                             else self.registration_basis.shape[1]) if fit_registration else 0,
            "points": (3 * n_points if self.point_basis is None else self.point_basis.shape[1]) if fit_points else 0,
            "rotation": 3 if (fit_rotation and self.G is not None) else 0,
            "effects": sum(e.n_values for e in self.effects),
        }
        self.blocks: dict[str, slice] = {}
        offset = 0
        for name, size in sizes.items():
            self.blocks[name] = slice(offset, offset + size)
            offset += size
        self.n_params = offset
        first = self.blocks["effects"].start
        for effect in self.effects:
            self.effect_slices.append(slice(first, first + effect.n_values))
            first += effect.n_values
        # the last state computed: (x, the kinematics it came from, the state)
        self._memo: tuple[np.ndarray, tuple[ToolPoses, Sensitivity], SensorState] | None = None

    def start_vector(self) -> np.ndarray:
        """Kinematic values from the cache's base, zero registration/rotation steps, start points."""
        x = np.zeros(self.n_params)
        x[self.blocks["kinematic"]] = self.cache.base[self.cache.free]
        reg, pts = self.blocks["registration"], self.blocks["points"]
        if reg.stop > reg.start and self.registration_basis is None:
            for s, registration in enumerate(self.start.registrations):
                x[reg.start + 6 * s + 3 : reg.start + 6 * s + 6] = registration.translation
        if pts.stop > pts.start and self.point_basis is None:
            x[pts] = self.start.points.ravel()
        return x

    def estimate(self, x: npt.ArrayLike) -> TargetEstimate:
        """Registrations, points and target rotation at ``x``."""
        x = np.asarray(x, dtype=float)
        reg = self._registration_values(x)
        registrations = self.start.registrations
        if reg.size:
            registrations = tuple(start.turned(reg[6 * s : 6 * s + 3], reg[6 * s + 3 : 6 * s + 6])
                                  for s, start in enumerate(registrations))
        pts = x[self.blocks["points"]]
        if self.point_basis is not None:  # the start's points moved within the basis's span
            points = self.start.points + (self.point_basis @ pts).reshape(-1, 3)
        else:
            points = pts.reshape(-1, 3) if pts.size else self.start.points
        rot = x[self.blocks["rotation"]]
        rotation = self.start.rotation @ pin.exp3(rot) if rot.size else self.start.rotation
        conditions = None
        if self._conditional:
            conditions = row_conditions(self.effects, self.effect_values(x), self.inputs, self.conditions)
        return TargetEstimate(registrations[0], points, rotation, registrations, conditions)

    def _registration_values(self, x: np.ndarray) -> np.ndarray:
        """(phi_s, tau_s) of every session at ``x`` (6S,), through ``registration_basis`` if any."""
        reg = x[self.blocks["registration"]]
        if self.registration_basis is None or not reg.size:
            return reg
        start = np.concatenate([np.r_[0.0, 0.0, 0.0, r.translation] for r in self.start.registrations])
        return start + self.registration_basis @ reg

    def _in_basis(self, columns: np.ndarray) -> np.ndarray:
        """Jacobian columns (..., 6S) of every registration unknown as those of ``registration_basis``'s."""
        return columns if self.registration_basis is None else columns @ self.registration_basis

    def row_frames(self, target: TargetEstimate) -> tuple[np.ndarray, np.ndarray]:
        """Omega and tau of each row's session: (3, 3) and (3,) with one session,
        (K, 3, 3) and (K, 3) [m] with several (both broadcast against per-row stacks)."""
        if self.n_sessions == 1:
            return target.registration.rotation, target.registration.translation
        rotations = np.stack([r.rotation for r in target.registrations])
        translations = np.stack([r.translation for r in target.registrations])
        return rotations[self.sessions], translations[self.sessions]

    def _session_blocks(self, target: TargetEstimate) -> list[tuple[int, slice | np.ndarray, Registration]]:
        """(session, its rows, its registration): all rows as one slice with one session."""
        if self.n_sessions == 1:
            return [(0, slice(None), target.registration)]
        return list(zip(range(self.n_sessions), self._session_rows, target.registrations))

    def _registered(self, target: TargetEstimate, world: np.ndarray) -> np.ndarray:
        """Omega f_k y + tau of each row's session for base-frame points ``world`` (K, P, 3) [m] (eq T1)."""
        if target.conditions is not None:
            world = target.conditions.world(world)
        if self.n_sessions == 1:
            return target.registration.apply_points(world)
        omega, tau = self.row_frames(target)
        return world @ omega.transpose(0, 2, 1) + tau[:, None, :]

    def effect_values(self, x: npt.ArrayLike) -> list[np.ndarray]:
        """Values of each effect at ``x``."""
        x = np.asarray(x, dtype=float)
        return [x[sl] for sl in self.effect_slices]

    def _sensor_terms(self, x: np.ndarray, target: TargetEstimate | None = None) -> tuple[float, np.ndarray]:
        """Sensor scale s and drift offset t_k u (K, 3) at ``x``, plus the pause steps d_k of ``target`` (eq T2)."""
        scale, drift = 0.0, np.zeros((self.g.shape[0], 3))
        for effect, sl in zip(self.effects, self.effect_slices):
            if effect.type == "sensor_scale":
                scale = float(x[sl][0])
            elif effect.type == "drift":
                assert self.inputs is not None and self.inputs.time is not None  # checked in __init__
                drift = self.inputs.time[:, None] * x[sl]
        if target is not None and target.conditions is not None and target.conditions.steps is not None:
            drift = drift + target.conditions.steps
        return scale, drift

    def state(self, x: npt.ArrayLike) -> SensorState:
        """Tool poses, sensitivities, target and target points in the base frame at ``x``
        (the last one is kept: least_squares asks for the residual and the Jacobian at the same x)."""
        x = np.asarray(x, dtype=float)
        kinematics = self.cache.evaluate(x[self.blocks["kinematic"]], *self._joint_state(x))
        memo = self._memo
        if memo is not None and memo[1] is kinematics and np.array_equal(memo[0], x):
            return memo[2]
        poses, sens = kinematics
        target = self.estimate(x)
        world = points_in_base(poses.tool_positions, poses.tool_rotations, target.points)  # (K, P, 3)
        state = (poses, sens, target, world)
        self._memo = (x.copy(), kinematics, state)
        return state

    def _joint_state(self, x: np.ndarray) -> tuple[np.ndarray | None, np.ndarray | None]:
        """The joint values the joint effects at ``x`` shift the readings to (None: the readings), and the joints'
        lateral deflections (eq L1–L3 of :mod:`pincal.model.lateral`; None: none)."""
        q = None
        if self.effects:
            assert self.inputs is not None  # effects need their inputs (__init__)
            shifts = np.zeros_like(self.inputs.q)
            for j, basis, sl in zip(self._effect_joint, self._effect_basis, self.effect_slices):
                if basis is not None:
                    shifts[:, j] += basis @ x[sl]
            q = self.inputs.q + self.cache.params.chain.followed_shifts(shifts)  # followers move too (eq M1)
        return q, row_bends(self._bend_basis, self._effect_joint, self.effect_values(x), self.cache.bends,
                            self.cache.params.chain.n_joints)

    def predicted_points(self, x: npt.ArrayLike) -> np.ndarray:
        """Model points in the sensor frame (K, P, 3) [m]: (1 + s)(Omega y + tau + t u)."""
        x = np.asarray(x, dtype=float)
        _, _, target, world = self.state(x)
        return self._sensed(x, target, world)

    def _sensed(self, x: np.ndarray, target: TargetEstimate, world: np.ndarray) -> np.ndarray:
        scale, drift = self._sensor_terms(x, target)
        if self.n_sessions == 1:
            world = world if target.conditions is None else target.conditions.world(world)
            return sensed_points(target.registration, world, scale, drift)
        return (1.0 + scale) * (self._registered(target, world) + drift[:, None, :])

    def residual(self, x: npt.ArrayLike) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        poses, _, target, world = self.state(x)
        position = (self._sensed(x, target, world) - self.g) * self.w[:, None, None]
        parts = [position.reshape(-1)]
        if self.G is not None:
            relative = self.orientation_error(poses, target)
            logs = log3(relative) * self.v[:, None]
            parts.append(logs.reshape(-1))
        return np.concatenate(parts)

    def row_indices(self) -> np.ndarray:
        """Where each row's residuals sit in :meth:`residual`, (K, 3P) or (K, 3P + 3).

        Row k's entries are e_k1, ..., e_kP (three components each), then o_k
        (with orientations): ``residual(x)[row_indices()]`` is the residual
        row by row, in the order of :meth:`noise_jacobian`'s blocks.
        """
        k, n_points = self.g.shape[:2]
        indices = np.arange(3 * k * n_points).reshape(k, 3 * n_points)
        if self.G is None:
            return indices
        return np.hstack([indices, 3 * k * n_points + np.arange(3 * k).reshape(k, 3)])

    def noise_jacobian(self, x: npt.ArrayLike) -> np.ndarray:
        """Derivative of each row's residual with respect to that row's sensor noise.

        The noise of row k is (zeta_k1, ..., zeta_kP [m], xi_k [rad]):
        g_kp → g_kp + zeta_kp and G_k → exp(xi_k) G_k, the linearised sensor
        model of eq 20–22 (R_ZYX(xi) and exp(xi) agree to first order). The
        residual is block-diagonal in the rows: d e_kp/d zeta_kp = −w_k I and,
        as G_kᵀ exp(−xi) = exp(−G_kᵀ xi) G_kᵀ, d o_k/d xi_k = −v_k Jlog3(E_k) E_kᵀ G_kᵀ.

        Returns:
            (K, m, m) with m = 3P (+ 3 with orientations): block k is the
            derivative of row k's residuals (in the order of :meth:`row_indices`)
            by row k's noise (zeta_k1, ..., zeta_kP, xi_k).
        """
        k, n_points = self.g.shape[:2]
        n_pos = 3 * n_points
        size = n_pos + (0 if self.G is None else 3)
        blocks = np.zeros((k, size, size))
        blocks[:, :n_pos, :n_pos] = -self.w[:, None, None] * np.eye(n_pos)
        if self.G is not None:
            poses, _, target, _ = self.state(x)
            relative = self.orientation_error(poses, target)
            jlog = jlog3(relative)
            turn = jlog @ relative.transpose(0, 2, 1) @ self.G.transpose(0, 2, 1)
            blocks[:, n_pos:, n_pos:] = -self.v[:, None, None] * turn
        return blocks

    def orientation_error(self, poses: ToolPoses, target: TargetEstimate) -> np.ndarray:
        """E_k = G_kᵀ Omega R_k R_T, (K, 3, 3)."""
        omega, _ = self.row_frames(target)
        assert self.G is not None  # called only with orientations
        return self.G.transpose(0, 2, 1) @ omega @ poses.tool_rotations @ target.rotation

    def jacobian(self, x: npt.ArrayLike) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        lin = self._linearisation(x, joints=any(b is not None for b in self._effect_basis),
                                  bends=any(b is not None for b in self._bend_basis))
        poses, sens, target, world = lin.state
        k, n_points = world.shape[:2]
        omega, _ = self.row_frames(target)
        rows_pos = np.zeros((k, n_points, 3, self.n_params))
        kin, reg, pts = self.blocks["kinematic"], self.blocks["registration"], self.blocks["points"]
        # einsum in the reference study's order: the same arithmetic, the same fits (pincal.residuals.so3)
        turn = "ij,knj->kin" if omega.ndim == 2 else "kij,knj->kin"  # one session, or each row's
        factor = 1.0 if target.conditions is None or target.conditions.factor is None \
            else target.conditions.factor[:, None, None]  # f_k of eq T1 scales every column of y
        for p in range(n_points):  # Omega (v + w x o), the point's velocity in the base frame turned
            rows_pos[:, p, :, kin] = np.einsum(turn, omega, sens.point_velocity(world[:, p, :])) * factor
        if reg.stop > reg.start:  # -Omega [y]x Jexp3(phi), per session
            scaled = world if target.conditions is None else target.conditions.world(world)
            values = self._registration_values(x)
            columns = np.zeros((k, n_points, 3, values.size))
            for s, rows, registration in self._session_blocks(target):
                columns[rows, ..., 6 * s : 6 * s + 3] = -np.einsum(
                    "ij,kpjl,lm->kpim", registration.rotation, skew(scaled[rows]), pin.Jexp3(values[6 * s : 6 * s + 3]))
                columns[rows, ..., 6 * s + 3 : 6 * s + 6] = np.eye(3)
            rows_pos[..., reg] = self._in_basis(columns)
        if pts.stop > pts.start:
            rotated = omega @ poses.tool_rotations * factor  # Omega R_k (f_k)
            for p in range(n_points):
                if self.point_basis is None:
                    rows_pos[:, p, :, pts.start + 3 * p : pts.start + 3 * p + 3] = rotated
                else:
                    rows_pos[:, p, :, pts] = rotated @ self.point_basis[3 * p : 3 * p + 3]
        for effect, j, basis, bend, sl in zip(self.effects, self._effect_joint, self._effect_basis,
                                              self._bend_basis, self.effect_slices):
            if effect.type != "sensor_scale":
                rows_pos[..., sl] = self._effect_position_columns(lin, effect, j, basis, bend)
        rows_pos *= 1.0 + lin.scale  # every term is scaled by the sensor's (1 + s)
        for effect, sl in zip(self.effects, self.effect_slices):
            if effect.type == "sensor_scale":
                rows_pos[..., sl] = lin.sensed[..., None]
        rows_pos *= self.w[:, None, None, None]
        blocks = [rows_pos.reshape(-1, self.n_params)]
        if self.G is not None:
            blocks.append(self._orientation_jacobian(x, lin))
        return np.vstack(blocks)

    def effect_columns(self, x: npt.ArrayLike, effects: Sequence[Effect]) -> list[np.ndarray]:
        """The Jacobian columns each of ``effects`` would add to this objective at
        ``x``, its values zero: (m, n_values) per effect, in the row order of
        :meth:`residual`. The effects need not be part of the objective (a
        candidate's columns, for a linearised test of adding it); a sensor scale
        already in the objective is not offered again."""
        x = np.asarray(x, dtype=float)
        joint_names = list(self.cache.params.chain.joint_names)
        joints = [joint_names.index(e.joint) if e.joint else -1 for e in effects]
        bends = bend_bases(effects, self.inputs, joints)
        lin = self._linearisation(x, joints=any(e.type in JOINT_EFFECTS for e in effects),
                                  bends=any(b is not None for b in bends))
        out = []
        for effect, j, bend in zip(effects, joints, bends):
            # a joint effect's columns need the effect inputs: the caller gives them
            basis = joint_basis(effect, cast(EffectInputs, self.inputs), j) if effect.type in JOINT_EFFECTS else None
            if effect.type == "sensor_scale":
                position = lin.sensed[..., None]
            else:
                position = self._effect_position_columns(lin, effect, j, basis, bend) * (1.0 + lin.scale)
            parts = [(position * self.w[:, None, None, None]).reshape(-1, effect.n_values)]
            if self.G is not None:
                rotation = np.zeros((len(self.G), 3, effect.n_values))
                if basis is not None:
                    assert lin.joint_turns is not None  # a joint effect's, linearised with joints and orientations
                    rotation = lin.joint_turns[:, :, j, None] * basis[:, None, :]
                elif bend is not None:
                    rotation = lateral_columns(cast(np.ndarray, lin.bend_turns), j, bend)
                parts.append((rotation * self.v[:, None, None]).reshape(-1, effect.n_values))
            out.append(np.vstack(parts))
        return out

    def _linearisation(self, x: np.ndarray, joints: bool, bends: bool = False) -> Linearisation:
        """What the Jacobian blocks share at ``x``: the state; the target points'
        offsets from the tool origin in the sensor frame (K, P, 3); the sensor
        scale and the sensed points (1 + s excluded); with orientations, E_k, Jlog3(E_k)
        and Jlog3(E_k) E_kᵀ G_kᵀ Omega ("left", K × 3 × 3); with ``joints``, the chain
        joints' point columns d(point)/d(q_j) (K, P, 3, N) and turns (K, 3, N); with ``bends``, the bend slots'
        (:func:`pincal.residuals.bends.bend_columns`: from the bent model, at zero bends when the fit has none)."""
        state = self.state(x)
        poses, sens, target, world = state
        omega, _ = self.row_frames(target)
        omega_t = np.swapaxes(omega, -1, -2)
        scale, drift = self._sensor_terms(x, target)
        lin = Linearisation(
            state=state,
            omega=omega,
            offsets=(world - sens.origin[:, None, :]) @ omega_t,
            scale=scale,
            sensed=self._registered(target, world) + drift[:, None, :],
        )
        if self.G is not None:
            relative = self.orientation_error(poses, target)
            jlog = jlog3(relative)
            lin.jlog, lin.left = jlog, jlog @ relative.transpose(0, 2, 1) @ self.G.transpose(0, 2, 1) @ omega
        if joints:
            assert sens.joint_angular is not None and sens.joint_linear is not None  # SensitivityModel sets them
            joint_points = point_columns(sens.joint_linear @ omega_t, sens.joint_angular @ omega_t, lin.offsets)
            if target.conditions is not None and target.conditions.factor is not None:  # eq T1
                joint_points *= target.conditions.factor[:, None, None, None]
            lin.joint_points = joint_points
            if lin.left is not None:  # with orientations
                lin.joint_turns = lin.left @ sens.joint_angular.transpose(0, 2, 1)
        if bends:
            zero = np.zeros((len(world), 2 * self.cache.params.chain.n_joints))  # no bends yet: at zero ones
            bent = sens if sens.bend_angular is not None else self.cache.evaluate(
                x[self.blocks["kinematic"]], self._joint_state(x)[0], zero)[1]
            lin.bend_points, lin.bend_turns = bend_columns(
                bent, omega_t, lin.offsets, lin.left, None if target.conditions is None else target.conditions.factor)
        return lin

    def _effect_position_columns(self, lin: Linearisation, effect: Effect, j: int,
                                 basis: np.ndarray | None, bend: np.ndarray | None = None) -> np.ndarray:
        """d(sensed point)/d(effect values) before the sensor scale and weights, (K, P, 3, n_values)."""
        k, n_points = lin.offsets.shape[:2]
        if bend is not None:  # a lateral compliance: the bend slots' columns times B_k (eq L3)
            return lateral_columns(cast(np.ndarray, lin.bend_points), j, bend)
        if basis is not None:  # joint shift: the joint's column times the basis
            assert lin.joint_points is not None  # a joint effect's lin is made with joints
            return lin.joint_points[:, :, :, j, None] * basis[:, None, None, :]
        if effect.type == "drift":
            assert self.inputs is not None and self.inputs.time is not None  # drift is offered only with a time column
            return np.broadcast_to(self.inputs.time[:, None, None, None] * np.eye(3), (k, n_points, 3, 3))
        if effect.type in ("thermal", "pause_step"):  # thermal and pause steps have their inputs (offered with them)
            return condition_columns(effect, cast(EffectInputs, self.inputs), lin.state[3], lin.omega)
        return np.zeros((k, n_points, 3, effect.n_values))

    def _orientation_jacobian(self, x: np.ndarray, lin: Linearisation) -> np.ndarray:
        poses, sens, target, _ = lin.state
        jlog, left = lin.jlog, lin.left  # (K, 3, 3) each
        assert jlog is not None and left is not None  # called with orientations
        rows = np.zeros((len(jlog), 3, self.n_params))
        kin, reg, rot = self.blocks["kinematic"], self.blocks["registration"], self.blocks["rotation"]
        # world angular velocity w of R_k: d log E = Jlog3(E) Eᵀ G_kᵀ Omega w ("left" w)
        rows[:, :, kin] = np.einsum("kij,knj->kin", left, sens.angular)
        tool = poses.tool_rotations @ target.rotation  # R_k R_T
        if reg.stop > reg.start:
            values = self._registration_values(x)
            columns = np.zeros((len(jlog), 3, values.size))
            for s, session_rows, _ in self._session_blocks(target):
                columns[session_rows, :, 6 * s : 6 * s + 3] = (
                    jlog[session_rows] @ tool[session_rows].transpose(0, 2, 1) @ pin.Jexp3(values[6 * s : 6 * s + 3]))
            rows[:, :, reg] = self._in_basis(columns)
        if rot.stop > rot.start:
            rows[:, :, rot] = jlog @ pin.Jexp3(x[rot])
        for j, basis, bend, sl in zip(self._effect_joint, self._effect_basis, self._bend_basis, self.effect_slices):
            if basis is not None:
                assert lin.joint_turns is not None  # a joint effect's lin is made with joints
                rows[:, :, sl] = lin.joint_turns[:, :, j, None] * basis[:, None, :]
            elif bend is not None:
                rows[:, :, sl] = lateral_columns(cast(np.ndarray, lin.bend_turns), j, bend)
        rows *= self.v[:, None, None]
        return rows.reshape(-1, self.n_params)

