"""One weighted fit of sensor rows (points, orientations) as a value: the problem the calibration pipeline
(:mod:`pincal.fit.pipeline`) runs for :func:`pincal.fit.chain_calibration.calibrate_chain`.

Its residual is :class:`pincal.residuals.sensor.SensorResidual` (with a prior,
:class:`pincal.fit.prior.PriorResidual` wrapping it); the holds of :mod:`pincal.fit.target_hold` and
:mod:`pincal.fit.registration_hold` derive the problem with the directions the rows cannot place held.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import cast

import numpy as np

from pincal.fit.prior import PriorResidual, log_evidence, reestimated_scales
from pincal.fit.sessions import session_rows
from pincal.fit.solver import Solution, solve
from pincal.measurements.data import MeasurementSet
from pincal.model.chain import KinematicChain
from pincal.model.effects import Effect, EffectInputs
from pincal.model.parameter_sets import ChainParameters, NoParameters
from pincal.model.sensitivity import ParameterSlot, SensitivityModel
from pincal.residuals.base import KinematicsCache
from pincal.residuals.sensor import SensorResidual, TargetEstimate
from pincal.residuals.sensor_values import FittedBlocks, ModelledEffects, RowWeights

__all__ = ["START_SIGMA_POS_M", "START_SIGMA_ROT_RAD", "FitProblem", "kind_scales"]

#: Starting noise scales for weighting positions against orientations; both
#: are re-estimated from the residuals (maximum likelihood with unknown variances).
START_SIGMA_POS_M = 1e-3
START_SIGMA_ROT_RAD = 1e-3


def kind_scales(residual: np.ndarray, n_pos: int, n_data: int, sigma_pos: float, sigma_rot: float | None
                ) -> tuple[float, float | None]:
    """Maximum likelihood with unknown variances, per kind of entry: σ² the mean squared error of the
    position entries ``residual[:n_pos]`` [m] and of the orientation ones ``residual[n_pos:n_data]`` [rad],
    each whitened by its scale now (``sigma_pos``, ``sigma_rot``; None: no orientations). A kind fitted
    exactly keeps its scale."""
    sigma = float(np.sqrt(np.mean((residual[:n_pos] * sigma_pos) ** 2))) or sigma_pos
    if sigma_rot is None:
        return sigma, None
    return sigma, float(np.sqrt(np.mean((residual[n_pos:n_data] * sigma_rot) ** 2))) or sigma_rot


@dataclass(frozen=True, eq=False)
class FitProblem:
    """One weighted fit of registration, target and a subset of kinematic parameters: a value.

    Everything a fit needs is given at construction; a variant is a new problem
    (:meth:`with_scales`, :meth:`with_prior`, :meth:`rescaled`, or ``dataclasses.replace``), never
    this one changed.

    ``models``: sensitivity models by slots (:class:`KinematicsCache`), a cache shared by the
    objectives of this problem, of every problem derived from it and of any problem given the
    same dict (an entry depends on the chain and the free parameters' slots only, nothing a
    variant changes).
    ``session_names``: the sessions of ``start.registrations`` (default, empty: those of
    ``data``); each row uses its session's (:func:`pincal.fit.sessions.session_rows`).
    ``sigma_pos`` [m], ``sigma_rot`` [rad]: the noise scales weighting the rows (``sigma_rot``
    None without measured orientations, whatever is given).
    ``prior``: with ``--select prior``, σ_i of every kinematic parameter (:mod:`pincal.fit.prior`, eq P1).
    ``point_basis``: the target points' free directions (:mod:`pincal.fit.target_hold`), None: all.
    ``registration_basis``: the registrations' free unknowns (:mod:`pincal.fit.registration_hold`), None: all.
    """

    chain: KinematicChain
    params: ChainParameters | None
    data: MeasurementSet
    start: TargetEstimate
    fit_target: bool
    row_weight: np.ndarray
    effects: Sequence[Effect] = ()
    inputs: EffectInputs | None = None
    models: dict[tuple[ParameterSlot, ...], SensitivityModel] = field(default_factory=dict)
    session_names: tuple[str, ...] = ()
    sigma_pos: float = START_SIGMA_POS_M
    sigma_rot: float | None = START_SIGMA_ROT_RAD
    prior: np.ndarray | None = None
    point_basis: np.ndarray | None = None
    registration_basis: np.ndarray | None = None
    sessions: np.ndarray = field(init=False, repr=False)  # each row's session index (K,)

    def __post_init__(self) -> None:
        # frozen: the normalised and derived fields are set once, here, as a constructor's would be
        names = tuple(self.session_names or self.data.session_names)
        object.__setattr__(self, "session_names", names)
        object.__setattr__(self, "effects", tuple(self.effects))
        object.__setattr__(self, "sessions", session_rows(self.data, names))
        if self.data.rotations is None:
            object.__setattr__(self, "sigma_rot", None)

    def objective(self, free: np.ndarray, base: np.ndarray) -> SensorResidual | PriorResidual:
        params = self.params if self.params is not None else NoParameters(self.chain)
        cache = KinematicsCache(params, free, base, self.data.q, self.models)
        objective = SensorResidual(
            cache,
            self.data.points,
            self.data.rotations,
            self.start,
            RowWeights(self.row_weight / self.sigma_pos, self.row_weight / (self.sigma_rot or 1.0)),
            FittedBlocks(points=self.fit_target, rotation=self.fit_target, point_basis=self.point_basis,
                         registration_basis=self.registration_basis),
            ModelledEffects(self.effects, self.inputs),
            sessions=self.sessions,
        )
        return objective if self.prior is None else PriorResidual(objective, self.prior[free])

    def fit(self, free: np.ndarray, base: np.ndarray, x0: np.ndarray | None = None,
            what: str = "fit") -> tuple[SensorResidual | PriorResidual, Solution]:
        objective = self.objective(free, base)
        x0 = objective.start_vector() if x0 is None else x0
        solution = solve(objective, x0, what=what)
        return objective, solution

    def scales(self) -> tuple[float, float | None]:
        """The noise scales weighting the rows: positions [m], orientations [rad] (None without)."""
        return self.sigma_pos, self.sigma_rot

    def with_scales(self, scales: tuple[float | None, ...]) -> FitProblem:
        """This problem with its rows weighted by ``scales`` (as :meth:`scales` gives them)."""
        return replace(self, sigma_pos=cast(float, scales[0]), sigma_rot=scales[1])  # positions: always measured

    def with_prior(self, prior: np.ndarray | None) -> FitProblem:
        """This problem with ``prior`` (σ_i of every kinematic parameter, eq P1; None: no prior)."""
        return replace(self, prior=prior)

    def log_evidence(self, objective: SensorResidual | PriorResidual, solution: Solution) -> float:
        """Eq P3 (:func:`pincal.fit.prior.log_evidence`): rows already whitened by w_k = 1/σ_pos and
        v_k = 1/σ_rot (times each row's weight, the same for every scale)."""
        data = cast(SensorResidual, cast(PriorResidual, objective).objective)  # eq P3 is of a MAP fit
        log_variances = -2.0 * 3 * data.g.shape[1] * np.sum(np.log(data.w))
        if data.G is not None:
            log_variances -= 2.0 * 3 * np.sum(np.log(data.v))
        return log_evidence(solution.jacobian, solution.residual, float(log_variances))

    def fold_rows(self, objective: SensorResidual | PriorResidual) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """What the prior's folds deal (:func:`pincal.fit.prior_scales.scale_folds`): each row's joint
        readings (K, N), its session (K,) and its entries in ``objective``'s residual (K, b)."""
        data = getattr(objective, "objective", objective)  # the sensor residual inside a prior-wrapped one
        return self.data.q, self.data.session_index, data.row_indices()

    def scale_rows(self, objective: SensorResidual | PriorResidual) -> tuple[slice, ...]:
        """The data rows each noise scale of :meth:`scales` weights (positions, then orientations if measured)."""
        n_pos = 3 * self.data.n_rows * self.data.n_points
        if self.sigma_rot is None:
            return (slice(0, n_pos),)
        return slice(0, n_pos), slice(n_pos, n_pos + 3 * self.data.n_rows)

    def rescaled(self, objective: SensorResidual | PriorResidual, solution: Solution) -> FitProblem:
        """This problem at the noise scales of a fit's residuals (:mod:`pincal.fit.pipeline`): maximum
        likelihood with unknown variances, sigma² = mean squared residual per kind; with a prior, eq P2
        of :mod:`pincal.fit.prior` (the effective degrees of freedom)."""
        k, p = self.data.n_rows, self.data.n_points
        n_pos = 3 * k * p
        if isinstance(objective, PriorResidual):
            return self.with_scales(reestimated_scales(solution, objective.n_prior, n_pos, self.sigma_pos,
                                                       self.sigma_rot))
        return self.with_scales(kind_scales(solution.residual, n_pos, solution.residual.size, self.sigma_pos,
                                            self.sigma_rot))
