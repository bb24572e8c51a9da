"""Absolute residuals of several targets on the chains of a tree, one registration per session.

For row k and measured point p, carried by target t(p) on the chain root → its tip link,

    e_kp = w_k (Omega_s(k) (t_k,t + R_k,t m_p) + tau_s(k) − g_kp)            [dimensionless]

the equation of :mod:`pincal.residuals.sensor` with each point's tool pose from its own chain:
one :class:`~pincal.residuals.sensor.SensorResidual` per target, over its chain's joints and
points, sharing the registrations (Omega_s, tau_s). Unknowns, in this order: the free
kinematic parameters of the tree (:class:`pincal.model.tree_parameters.TreeParameters`; a
parameter of a joint off a target's chain has a zero column in its rows), the registrations
(6 per session), the points m_p (3 each, in the order of their numbers, each in its own tip
link). A point not seen in a row (an empty cell: occlusion) has no residual: the entries are
the seen (row, point) pairs, row by row and in point order within a row, 3 each.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from pincal.model.parameter_sets import ChainParameters, NoParameters
from pincal.model.sensitivity import ParameterSlot, SensitivityModel
from pincal.model.sensor import Registration
from pincal.model.tree import KinematicTree
from pincal.model.tree_parameters import TreeParameters
from pincal.residuals.base import KinematicsCache
from pincal.residuals.sensor import SensorResidual, TargetEstimate
from pincal.residuals.sensor_values import FittedBlocks, RowWeights

__all__ = ["TreeRows", "TreeResidual"]


@dataclass(frozen=True)
class TreeRows:
    """What a tree residual measures: the rows' tree joint readings and points, which points were seen.

    Attributes:
        q: tree joint readings (K, N) [rad or m].
        points: measured points (K, P, 3) [m] (occluded ones anything: not read).
        seen: (K, P) whether each point was measured in each row.
        sessions: (K,) each row's session, an index into the registrations.
    """

    q: np.ndarray
    points: np.ndarray
    seen: np.ndarray
    sessions: np.ndarray


class TreeResidual:
    """The residual of the module docstring over the free tree parameters ``free``.

    Args:
        tree: the tree.
        params: the tree's parameters (None: none fitted, the URDF as loaded).
        free: tree indices of the parameters fitted, sorted.
        base: the tree vector holding the others' values (n,).
        rows: the measurements.
        start: the registrations (one per session) and every point's start (P, 3) in its tip link.
        weights: w_k [1/m] (``rotation`` is not used: the targets are points).
        models: sensitivity models shared by the fits of one problem, by slots (as :class:`KinematicsCache`'s).
    """

    def __init__(self, tree: KinematicTree, params: TreeParameters | None, free: npt.ArrayLike, base: npt.ArrayLike,
                 rows: TreeRows, start: TargetEstimate, weights: RowWeights,
                 models: dict[tuple[ParameterSlot, ...], SensitivityModel] | None = None) -> None:
        self.tree = tree
        self.params = params
        self.free = np.asarray(free, dtype=np.intp)
        self.base = np.asarray(base, dtype=float)
        self.rows, self.start = rows, start
        k, n_points = rows.seen.shape
        self.n_sessions = len(start.registrations)
        self.registration_basis = None  # every registration unknown is fitted (a tree holds none)
        self.point_basis = None
        n_kin, n_reg = self.free.size, 6 * self.n_sessions
        self.blocks = {"kinematic": slice(0, n_kin), "registration": slice(n_kin, n_kin + n_reg),
                       "points": slice(n_kin + n_reg, n_kin + n_reg + 3 * n_points),
                       "rotation": slice(n_kin + n_reg + 3 * n_points, n_kin + n_reg + 3 * n_points),
                       "effects": slice(n_kin + n_reg + 3 * n_points, n_kin + n_reg + 3 * n_points)}
        self.n_params = n_kin + n_reg + 3 * n_points
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
            part_start = TargetEstimate(start.registration, start.points[numbers], np.eye(3), start.registrations)
            part = SensorResidual(cache, measured, None, part_start, weights,
                                  FittedBlocks(registration=True, points=True, rotation=False),
                                  sessions=rows.sessions)
            kin = np.array([position[int(i)] for i in (params.index[t][local] if params is not None else [])],
                           dtype=np.intp)
            columns = np.concatenate([kin, self.blocks["registration"].start + np.arange(n_reg),
                                      self.blocks["points"].start + (3 * numbers[:, None] + np.arange(3)).ravel()])
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
        """The registrations and every point (P, 3), each in its own tip link [m], at ``x``."""
        x = np.asarray(x, dtype=float)
        points = np.zeros((self.seen.shape[1], 3))
        registrations: tuple[Registration, ...] = ()
        for part, columns, numbers in self.parts:
            estimate = part.estimate(x[columns])
            points[numbers] = estimate.points
            registrations = estimate.registrations
        return TargetEstimate(registrations[0], points, np.eye(3), registrations)

    def _full(self, x: np.ndarray, jacobian: bool) -> np.ndarray:
        """Every (row, point) pair's entries, seen or not: (K, P, 3) or (K, P, 3, n)."""
        k, n_points = self.seen.shape
        out = np.zeros((k, n_points, 3) + ((self.n_params,) if jacobian else ()))
        for part, columns, numbers in self.parts:
            local = x[columns]
            if jacobian:
                block = part.jacobian(local).reshape(k, numbers.size, 3, columns.size)
                for i, p in enumerate(numbers):
                    out[:, p][..., columns] = block[:, i]
            else:
                out[:, numbers] = part.residual(local).reshape(k, numbers.size, 3)
        return out

    def residual(self, x: npt.ArrayLike) -> np.ndarray:
        """The seen points' residuals, (3 K_seen,)."""
        return self._full(np.asarray(x, dtype=float), False)[self.seen].ravel()

    def jacobian(self, x: npt.ArrayLike) -> np.ndarray:
        """d residual / d x, (3 K_seen, n)."""
        return self._full(np.asarray(x, dtype=float), True)[self.seen].reshape(-1, self.n_params)

    def observations(self) -> tuple[np.ndarray, np.ndarray]:
        """The row (K_seen,) and point (K_seen,) of each seen pair, in the residual's order (3 entries each)."""
        rows, points = np.nonzero(self.seen)
        return rows, points

    def point_errors(self, x: npt.ArrayLike, weights: Sequence[float] | np.ndarray) -> np.ndarray:
        """Each point's distance from the model in each row [m], NaN where not seen, (K, P); ``weights``: w_k."""
        full = self._full(np.asarray(x, dtype=float), False) / np.asarray(weights, dtype=float)[:, None, None]
        out = np.linalg.norm(full, axis=2)
        out[~self.seen] = np.nan
        return out
