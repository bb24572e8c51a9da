"""One weighted fit of several targets on a tree as a value: the problem the calibration pipeline
(:mod:`pincal.fit.pipeline`) runs for :func:`pincal.fit.tree_calibration.calibrate_tree`.

Its residual is :class:`pincal.residuals.tree.TreeResidual` (with a prior,
:class:`pincal.fit.prior.PriorResidual` wrapping it); its noise scales are the positions' and, when
some target's orientation is measured, the orientations' (each re-estimated from its own entries,
as one chain's: :class:`pincal.fit.sensor_problem.FitProblem`). Its data entries are the seen
(row, point) pairs, then the seen (row, target) orientations, 3 each: what the pipeline's scales,
evidence and folds count.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import cast

import numpy as np

from pincal.fit.prior import PriorResidual, log_evidence, reestimated_scales
from pincal.fit.sensor_problem import START_SIGMA_POS_M, START_SIGMA_ROT_RAD, kind_scales
from pincal.fit.solver import Solution, solve
from pincal.model.sensitivity import ParameterSlot, SensitivityModel
from pincal.model.tree import KinematicTree
from pincal.model.tree_parameters import TreeParameters
from pincal.residuals.sensor import TargetEstimate
from pincal.residuals.sensor_values import ModelledEffects, RowWeights
from pincal.residuals.tree import TreeResidual, TreeRows

__all__ = ["TreeProblem"]


@dataclass(frozen=True, eq=False)
class TreeProblem:
    """One weighted fit of the registrations, the points and a subset of the tree's parameters: a value.

    ``rows``: the measurements; ``start``: the registrations and points to start from; ``row_weight``: each
    row's relative weight (K,); ``sigma_pos``: the position noise scale [m]; ``sigma_rot``: the orientation noise
    scale [rad] (None when no target's orientation is measured, whatever is given); ``prior``: σ_i of every tree
    parameter with ``--select prior`` (eq P1); ``models``: sensitivity models shared by the variants;
    ``effects``: the effects fitted beside the geometry and the tree's effect inputs (``diagnose``).
    """

    tree: KinematicTree
    params: TreeParameters | None
    rows: TreeRows
    start: TargetEstimate
    row_weight: np.ndarray
    session_names: tuple[str, ...]
    sigma_pos: float = START_SIGMA_POS_M
    prior: np.ndarray | None = None
    models: dict[tuple[ParameterSlot, ...], SensitivityModel] = field(default_factory=dict)
    effects: ModelledEffects | None = None
    sigma_rot: float | None = START_SIGMA_ROT_RAD

    def __post_init__(self) -> None:
        if not self.rows.oriented().size:  # frozen: normalised once, here, as a constructor's would be
            object.__setattr__(self, "sigma_rot", None)

    def objective(self, free: np.ndarray, base: np.ndarray) -> TreeResidual | PriorResidual:
        weights = RowWeights(self.row_weight / self.sigma_pos, self.row_weight / (self.sigma_rot or 1.0))
        objective = TreeResidual(self.tree, self.params, free, base, self.rows, self.start, weights, self.models,
                                 self.effects)
        return objective if self.prior is None else PriorResidual(objective, self.prior[free])

    def fit(self, free: np.ndarray, base: np.ndarray, x0: np.ndarray | None = None,
            what: str = "fit") -> tuple[TreeResidual | PriorResidual, Solution]:
        objective = self.objective(free, base)
        x0 = objective.start_vector() if x0 is None else x0
        return objective, solve(objective, x0, what=what)

    def scales(self) -> tuple[float | None, ...]:
        """The noise scales weighting the rows: positions [m], and orientations [rad] when measured."""
        return (self.sigma_pos,) if self.sigma_rot is None else (self.sigma_pos, self.sigma_rot)

    def with_scales(self, scales: tuple[float | None, ...]) -> TreeProblem:
        turns = scales[1] if len(scales) > 1 else None
        return replace(self, sigma_pos=cast(float, scales[0]), sigma_rot=turns)  # positions: always measured

    def with_prior(self, prior: np.ndarray | None) -> TreeProblem:
        return replace(self, prior=prior)

    def orientation_seen(self) -> np.ndarray:
        """(K, T) whether each target's orientation is an entry of the residual in each row."""
        seen = self.rows.rotation_seen
        return np.zeros((len(self.rows.q), 0), dtype=bool) if seen is None or self.sigma_rot is None else seen

    @property
    def n_positions(self) -> int:
        """How many of the data entries are the points': 3 per seen (row, point) pair."""
        return 3 * int(np.count_nonzero(self.rows.seen))

    @property
    def n_data(self) -> int:
        """How many data entries the residual has: 3 per seen (row, point) pair and per seen orientation."""
        return self.n_positions + 3 * int(np.count_nonzero(self.orientation_seen()))

    def log_evidence(self, objective: TreeResidual | PriorResidual, solution: Solution) -> float:
        """Eq P3 (:func:`pincal.fit.prior.log_evidence`) with each entry whitened by w_k = row weight / σ_pos, an
        orientation's by v_k = row weight / σ_rot."""
        log_variances = -2.0 * 3 * float(np.sum(np.log(self.row_weight / self.sigma_pos)[:, None] * self.rows.seen))
        if self.sigma_rot is not None:
            log_variances -= 2.0 * 3 * float(np.sum(np.log(self.row_weight / self.sigma_rot)[:, None]
                                                    * self.orientation_seen()))
        return log_evidence(solution.jacobian, solution.residual, log_variances)

    def scale_rows(self, objective: TreeResidual | PriorResidual) -> tuple[slice, ...]:
        if self.sigma_rot is None:
            return (slice(0, self.n_data),)
        return slice(0, self.n_positions), slice(self.n_positions, self.n_data)

    def fold_rows(self, objective: TreeResidual | PriorResidual) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Each seen pair's (point, then orientation) joint readings, session and 3 entries: pairs of one
        configuration share its fold (:func:`pincal.fit.prior_scales.scale_folds` deals configurations)."""
        rows = np.concatenate([np.nonzero(self.rows.seen)[0], np.nonzero(self.orientation_seen())[0]])
        return self.rows.q[rows], self.rows.sessions[rows], np.arange(3 * rows.size).reshape(-1, 3)

    def rescaled(self, objective: TreeResidual | PriorResidual, solution: Solution) -> TreeProblem:
        """This problem at the noise scales of a fit's residual: the mean squared weighted error over the seen
        entries of each kind (maximum likelihood with unknown variances); with a prior, eq P2."""
        n_pos = self.n_positions
        if isinstance(objective, PriorResidual):
            scales = reestimated_scales(solution, objective.n_prior, n_pos, self.sigma_pos, self.sigma_rot)
            return self.with_scales(scales if self.sigma_rot is not None else scales[:1])
        scales = kind_scales(solution.residual, n_pos, self.n_data, self.sigma_pos, self.sigma_rot)
        return self.with_scales(scales if self.sigma_rot is not None else scales[:1])


def registration_fit(problem: TreeProblem, size: int, iterations: int) -> tuple[TreeProblem, Solution]:
    """The registrations and points with the nominal kinematics, at the noise scales of their residual
    (re-estimated ``iterations`` times): the pipeline's start."""
    empty, base = np.array([], dtype=int), np.zeros(size)
    objective, solution = problem.fit(empty, base, what="registration")
    for _ in range(iterations):
        problem = problem.rescaled(objective, solution)
        objective, solution = problem.fit(empty, base, solution.x, what="registration")
    return replace(problem, start=cast(TreeResidual, objective).estimate(solution.x)), solution
