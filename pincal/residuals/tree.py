"""Absolute residuals of several targets on the chains of a tree, one registration per session.

For row k and measured point p, carried by target t(p) on the chain root → its tip link,

    e_kp = w_k (Omega_s(k) (t_k,t + R_k,t m_p) + tau_s(k) − g_kp)            [dimensionless]

and for a target t whose orientation is measured (columns ``qxN,qyN,qzN,qwN``,
:mod:`pincal.measurements.target_orientations`), with G_kt that orientation in the sensor frame,

    o_kt = v_k log(G_ktᵀ Omega_s(k) R_k,t R_T,t)                           [dimensionless]

the equations of :mod:`pincal.residuals.sensor` with each target's tool pose from its own chain:
one :class:`~pincal.residuals.sensor.SensorResidual` per target, over its chain's joints, its
points and its orientation, sharing the registrations (Omega_s, tau_s); w_k = 1/sigma_pos,k and
v_k = 1/sigma_rot,k as for one chain. Unknowns, in this order: the free kinematic parameters of
the tree (:class:`pincal.model.tree_parameters.TreeParameters`; a parameter of a joint off a
target's chain has a zero column in its rows), the registrations (6 per session), the points
m_p (3 each, in the order of their numbers, each in its own tip link), the rotation of each
oriented target's frame in its tip link R_T,t = R_T0,t exp(psi_t) (3 each, in target order).
A point or an orientation not seen in a row (empty cells: occlusion) has no residual: the
entries are the seen (row, point) pairs, row by row and in point order within a row, 3 each,
then the seen (row, target) orientations likewise. The Jacobian is each target's analytic one
(:meth:`SensorResidual.jacobian`) placed in the tree's columns.

Effects (:mod:`pincal.model.effects`, as ``diagnose`` adds them) enter as they enter each target's
sensor residual: a joint effect shifts its joint's reading in every target whose chain has the joint
(its values one unknown of the tree, after the points), a sensor effect moves every target's points;
their inputs are the tree's (:func:`pincal.model.tree_effects.tree_inputs`: a shared joint's load is
that of everything it carries).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from pincal.model.effects import Effect
from pincal.model.parameter_sets import ChainParameters, NoParameters
from pincal.model.sensitivity import ParameterSlot, SensitivityModel
from pincal.model.sensor import Registration
from pincal.model.tree import KinematicTree
from pincal.model.tree_effects import acting_on, target_inputs
from pincal.model.tree_parameters import TreeParameters
from pincal.residuals.base import KinematicsCache
from pincal.residuals.sensor import SensorResidual, TargetEstimate
from pincal.residuals.sensor_values import FittedBlocks, ModelledEffects, RowWeights

__all__ = ["TreeRows", "TreeResidual"]


@dataclass(frozen=True)
class TreeRows:
    """What a tree residual measures: the rows' tree joint readings and points, which points were seen.

    Attributes:
        q: tree joint readings (K, N) [rad or m].
        points: measured points (K, P, 3) [m] (occluded ones anything: not read).
        seen: (K, P) whether each point was measured in each row.
        sessions: (K,) each row's session, an index into the registrations.
        rotations: each target's measured orientation in the sensor frame (K, T, 3, 3), in target order
            (where not seen anything: not read), or None (no orientation).
        rotation_seen: (K, T) whether each target's orientation was measured in each row, or None (none);
            a target never seen has no rotation unknown.
        frames: the targets whose frame rotation is an unknown (indices, sorted), when not those some row
            measures: another set of rows' (held-out rows evaluated with the calibration's unknowns), or None.
    """

    q: np.ndarray
    points: np.ndarray
    seen: np.ndarray
    sessions: np.ndarray
    rotations: np.ndarray | None = None
    rotation_seen: np.ndarray | None = None
    frames: np.ndarray | None = None

    def oriented(self) -> np.ndarray:
        """The targets whose frame rotation is an unknown: ``frames``, else those some row measures (sorted)."""
        if self.frames is not None:
            return np.asarray(self.frames, dtype=np.intp)
        return np.array([], dtype=np.intp) if self.rotation_seen is None else np.flatnonzero(
            np.any(self.rotation_seen, axis=0))


class TreeResidual:
    """The residual of the module docstring over the free tree parameters ``free``.

    Args:
        tree: the tree.
        params: the tree's parameters (None: none fitted, the URDF as loaded).
        free: tree indices of the parameters fitted, sorted.
        base: the tree vector holding the others' values (n,).
        rows: the measurements.
        start: the registrations (one per session), every point's start (P, 3) in its tip link and each
            target's rotation start R_T0,t in its tip link (T, 3, 3) (one (3, 3): the same for every target).
        weights: w_k [1/m] and v_k [1/rad] (the latter read for the orientations only).
        models: sensitivity models shared by the fits of one problem, by slots (as :class:`KinematicsCache`'s).
        effects: the effects fitted and the tree's inputs (:func:`pincal.model.tree_effects.tree_inputs`), whose
            columns are the tree's joints; inputs without effects: :meth:`effect_columns` can test candidates.
    """

    def __init__(  # noqa: PLR0913 - a sensor residual's arguments (the cache's three apart) and the tree's two
            self, tree: KinematicTree, params: TreeParameters | None, free: npt.ArrayLike, base: npt.ArrayLike,
                 rows: TreeRows, start: TargetEstimate, weights: RowWeights,
                 models: dict[tuple[ParameterSlot, ...], SensitivityModel] | None = None,
                 effects: ModelledEffects | None = None) -> None:
        self.tree = tree
        self.params = params
        self.free = np.asarray(free, dtype=np.intp)
        self.base = np.asarray(base, dtype=float)
        self.rows, self.start = rows, start
        k, n_points = rows.seen.shape
        self.n_sessions = len(start.registrations)
        self.registration_basis = None  # every registration unknown is fitted (a tree holds none)
        self.point_basis = None
        effects = ModelledEffects() if effects is None else effects
        self.effects, self.inputs = tuple(effects.effects), effects.inputs
        if self.effects and self.inputs is None:
            raise ValueError("effects need their inputs (gravity torques, time)")
        n_kin, n_reg, n_targets = self.free.size, 6 * self.n_sessions, len(tree.targets)
        self.oriented = rows.oriented()
        self.rotation_seen = np.zeros((k, n_targets), dtype=bool) if rows.rotation_seen is None else np.asarray(
            rows.rotation_seen, dtype=bool)
        turns = np.asarray(start.rotation, dtype=float)
        start_turns = np.broadcast_to(turns, (n_targets, 3, 3)) if turns.ndim == 2 else turns
        rot = n_kin + n_reg + 3 * n_points
        first = rot + 3 * self.oriented.size
        self.blocks = {"kinematic": slice(0, n_kin), "registration": slice(n_kin, n_kin + n_reg),
                       "points": slice(n_kin + n_reg, rot), "rotation": slice(rot, first),
                       "effects": slice(first, first + sum(e.n_values for e in self.effects))}
        self.n_params = self.blocks["effects"].stop
        self.effect_slices: list[slice] = []
        for effect in self.effects:
            self.effect_slices.append(slice(first, first + effect.n_values))
            first += effect.n_values
        self.seen = np.asarray(rows.seen, dtype=bool)
        #: each target's SensorResidual and the tree columns of its unknowns
        self.parts: list[tuple[SensorResidual, np.ndarray, np.ndarray]] = []
        position = {int(i): c for c, i in enumerate(self.free)}
        models = {} if models is None else models
        for t, target in enumerate(tree.targets):
            numbers = np.array(target.spec.points, dtype=np.intp) - 1  # the target's points (P_t,)
            cache_params: ChainParameters
            if params is None:
                local, cache_params, chain_base = np.array([], dtype=np.intp), NoParameters(target.chain), np.zeros(0)
            else:
                index = params.index[t]
                local = np.flatnonzero(np.isin(index, self.free))
                cache_params, chain_base = params.chains[t], self.base[index]
            cache = KinematicsCache(cache_params, local, chain_base, rows.q[:, target.columns], models)
            measured = np.where(self.seen[:, numbers, None], rows.points[:, numbers], 0.0)
            oriented = t in self.oriented
            turned = None  # G_kt, the identity where not seen (those entries are dropped)
            if oriented:
                assert rows.rotations is not None  # a target is oriented only with rotations
                turned = np.where(self.rotation_seen[:, t, None, None], rows.rotations[:, t], np.eye(3))
            part_start = TargetEstimate(start.registration, start.points[numbers], start_turns[t],
                                        start.registrations)
            acting = acting_on(self.effects, target)
            modelled = ModelledEffects() if self.inputs is None else ModelledEffects(
                [self.effects[i] for i in acting], target_inputs(self.inputs, target))
            part = SensorResidual(cache, measured, turned, part_start, weights,
                                  FittedBlocks(registration=True, points=True, rotation=oriented), modelled,
                                  sessions=rows.sessions)
            kin = np.array([position[int(i)] for i in (params.index[t][local] if params is not None else [])],
                           dtype=np.intp)
            values = [np.arange(self.effect_slices[i].start, self.effect_slices[i].stop) for i in acting]
            psi = rot + 3 * int(np.searchsorted(self.oriented, t)) + np.arange(3 if oriented else 0)
            columns = np.concatenate([kin, self.blocks["registration"].start + np.arange(n_reg),
                                      self.blocks["points"].start + (3 * numbers[:, None] + np.arange(3)).ravel(),
                                      psi, *values])
            self.parts.append((part, columns, numbers))

    @property
    def n_free(self) -> int:
        return self.n_params

    def start_vector(self) -> np.ndarray:
        """The fixed kinematic values' start, the registrations' translations, the points' start."""
        x = np.zeros(self.n_params)
        for part, columns, _ in self.parts:
            x[columns] = part.start_vector()
        x[self.blocks["kinematic"]] = self.base[self.free]
        return x

    def estimate(self, x: npt.ArrayLike) -> TargetEstimate:
        """The registrations, every point (P, 3), each in its own tip link [m], and each target's rotation in its
        tip link (T, 3, 3) (the start's for a target without orientation), at ``x``."""
        x = np.asarray(x, dtype=float)
        points = np.zeros((self.seen.shape[1], 3))
        rotations = np.zeros((len(self.parts), 3, 3))
        registrations: tuple[Registration, ...] = ()
        for t, (part, columns, numbers) in enumerate(self.parts):
            estimate = part.estimate(x[columns])
            points[numbers], rotations[t] = estimate.points, estimate.rotation
            registrations = estimate.registrations
        return TargetEstimate(registrations[0], points, rotations, registrations)

    def _full(self, x: np.ndarray, jacobian: bool) -> tuple[np.ndarray, np.ndarray]:
        """Every (row, point) pair's entries, seen or not, (K, P, 3) or (K, P, 3, n), and every (row, target)
        pair's orientation entries, (K, T, 3) or (K, T, 3, n) (zero for a target without orientation)."""
        k, n_points = self.seen.shape
        extra = (self.n_params,) if jacobian else ()
        out = np.zeros((k, n_points, 3) + extra)
        turns = np.zeros((k, len(self.parts), 3) + extra)
        for t, (part, columns, numbers) in enumerate(self.parts):
            local, n_pos = x[columns], 3 * k * numbers.size
            if jacobian:
                block = part.jacobian(local)
                positions = block[:n_pos].reshape(k, numbers.size, 3, columns.size)
                for i, p in enumerate(numbers):
                    out[:, p][..., columns] = positions[:, i]
                if part.G is not None:
                    turns[:, t][..., columns] = block[n_pos:].reshape(k, 3, columns.size)
            else:
                values = part.residual(local)
                out[:, numbers] = values[:n_pos].reshape(k, numbers.size, 3)
                if part.G is not None:
                    turns[:, t] = values[n_pos:].reshape(k, 3)
        return out, turns

    def effect_values(self, x: npt.ArrayLike) -> list[np.ndarray]:
        """Values of each effect at ``x``."""
        x = np.asarray(x, dtype=float)
        return [x[sl] for sl in self.effect_slices]

    def effect_columns(self, x: npt.ArrayLike, effects: Sequence[Effect]) -> list[np.ndarray]:
        """The Jacobian columns each of ``effects`` would add at ``x``, its values zero: (3 K_seen, n_values)
        each, in the row order of :meth:`residual` (as :meth:`SensorResidual.effect_columns`, each target's part
        from the targets it moves; zero in the others')."""
        x = np.asarray(x, dtype=float)
        k, n_points = self.seen.shape
        full = [np.zeros((k, n_points, 3, e.n_values)) for e in effects]
        turns = [np.zeros((k, len(self.parts), 3, e.n_values)) for e in effects]
        for t, ((part, columns, numbers), target) in enumerate(zip(self.parts, self.tree.targets)):
            acting = acting_on(effects, target)
            blocks = part.effect_columns(x[columns], [effects[i] for i in acting])
            for i, block in zip(acting, blocks):
                full[i][:, numbers] = block[: 3 * k * numbers.size].reshape(k, numbers.size, 3, -1)
                if part.G is not None:
                    turns[i][:, t] = block[3 * k * numbers.size:].reshape(k, 3, -1)
        return [np.vstack([f[self.seen].reshape(-1, f.shape[-1]), o[self.rotation_seen].reshape(-1, f.shape[-1])])
                for f, o in zip(full, turns)]

    def residual(self, x: npt.ArrayLike) -> np.ndarray:
        """The seen points' residuals, then the seen orientations', (3 K_seen + 3 K_turns,)."""
        positions, turns = self._full(np.asarray(x, dtype=float), False)
        return np.concatenate([positions[self.seen].ravel(), turns[self.rotation_seen].ravel()])

    def jacobian(self, x: npt.ArrayLike) -> np.ndarray:
        """d residual / d x, (3 K_seen + 3 K_turns, n)."""
        positions, turns = self._full(np.asarray(x, dtype=float), True)
        return np.vstack([positions[self.seen].reshape(-1, self.n_params),
                          turns[self.rotation_seen].reshape(-1, self.n_params)])

    @property
    def n_positions(self) -> int:
        """How many entries of the residual are the points' (the first ones): 3 per seen (row, point) pair."""
        return 3 * int(np.count_nonzero(self.seen))

    def observations(self) -> tuple[np.ndarray, np.ndarray]:
        """The row (K_seen,) and point (K_seen,) of each seen pair, in the residual's order (3 entries each)."""
        rows, points = np.nonzero(self.seen)
        return rows, points

    def point_errors(self, x: npt.ArrayLike, weights: Sequence[float] | np.ndarray) -> np.ndarray:
        """Each point's distance from the model in each row [m], NaN where not seen, (K, P); ``weights``: w_k."""
        full = self._full(np.asarray(x, dtype=float), False)[0] / np.asarray(weights, dtype=float)[:, None, None]
        out = np.linalg.norm(full, axis=2)
        out[~self.seen] = np.nan
        return out

    def orientation_errors(self, x: npt.ArrayLike, weights: Sequence[float] | np.ndarray) -> np.ndarray:
        """Each target's orientation error in each row, the angle of G_ktᵀ Omega R_k,t R_T,t [rad], NaN where not
        seen (or not measured), (K, T); ``weights``: v_k."""
        turns = self._full(np.asarray(x, dtype=float), False)[1] / np.asarray(weights, dtype=float)[:, None, None]
        out = np.linalg.norm(turns, axis=2)
        out[~self.rotation_seen] = np.nan
        return out
