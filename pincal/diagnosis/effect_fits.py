"""The calibrated geometry with effects added, refitted: the fits every step of ``diagnose`` makes.

:class:`EffectModel` holds the geometric calibration, its rows and the effect inputs, and refits
geometry, registration, target and effects together (:func:`pincal.fit.solver.solve`). A fit given
a budget (``chunk``) runs in chunks of that many evaluations and goes on while a chunk still gains:

    ΔBIC_chunk = m ln(RSS_after / RSS_before) ≤ −:data:`GAIN_PER_CHUNK`,                      (F1)

m the data rows of the residual (the BIC of :func:`pincal.diagnosis.screening.bic`): a fit that
crawls along a valley the data do not determine stops at its first chunk, a fit still descending
toward an effect that explains most of the residual is taken to convergence.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import numpy as np
from scipy.spatial.transform import Rotation

from pincal.diagnosis.screening import FitObjective, bic, n_prior_rows
from pincal.fit.chain_calibration import ChainCalibration, FitProblem
from pincal.fit.metrics import PoseErrors
from pincal.fit.solver import Solution, solve
from pincal.measurements.data import MeasurementSet
from pincal.model.chain import KinematicChain
from pincal.model.effects import Effect, EffectInputs
from pincal.model.sensitivity import ParameterSlot, SensitivityModel

__all__ = ["GAIN_PER_CHUNK", "CandidateFit", "EffectModel", "fit_while_gaining", "pose_errors_of", "heldout_errors"]

#: Least BIC gain of a chunk of evaluations for a budgeted fit to go on (eq F1): one unit of BIC. A crawl
#: gains ~1e-4 per 50 evaluations (the UR5 wrist's cyclic terms of tests/test_crawling_fits.py: 3 599.6001
#: → 3 599.5974 over 1 000 evaluations), a coupling read against its driver hundreds per chunk; a fit gaining
#: less than one unit per chunk would need ten chunks to move a candidate across the evidence cut of 10.
GAIN_PER_CHUNK = 1.0


def fit_while_gaining(objective: FitObjective, x0: np.ndarray, chunk: int, tolerance: float | None = None) -> Solution:
    """:func:`solve` in chunks of ``chunk`` evaluations, from ``x0``, while each chunk gains at least
    :data:`GAIN_PER_CHUNK` of BIC (eq F1) and the total stays within scipy's own budget (100 per unknown);
    the last chunk's solution (``converged`` False when it stopped gaining before converging)."""
    n_prior = n_prior_rows(objective)
    last = bic(objective.residual(x0), x0.size, n_prior)
    spent = 0
    while True:
        solution = solve(objective, x0, what="effect fit", max_evaluations=chunk, tolerance=tolerance)
        spent += solution.n_evaluations
        now = bic(solution.residual, x0.size, n_prior)
        if solution.converged or last - now < GAIN_PER_CHUNK or spent >= 100 * x0.size:
            return solution
        x0, last = solution.x, now


class CandidateFit(NamedTuple):
    """A candidate's full fit beside the geometry: its ΔBIC against the fit it extends, the effect, the objective
    of the adopted effects and it (``effect`` last), its solution (the tuple
    :meth:`pincal.diagnosis.verdicts.Judge.rank` ranks)."""

    delta_bic: float
    effect: Effect
    objective: FitObjective
    solution: Solution


@dataclass(frozen=True, eq=False)
class EffectModel:
    """The calibrated geometry plus a list of effects, refittable on calibration rows: a value, its
    variants new models (:meth:`reestimated`, ``dataclasses.replace``); :meth:`of` makes the first.

    Under ``--select prior`` every fit keeps the calibration's prior on the geometry
    (``calibration.prior_sigma``, eq P1 of :mod:`pincal.fit.prior`): its residual ends with
    the prior rows and its ΔBIC compares the penalised sums of squares. The effects get no
    prior (their columns are zero on the prior rows).

    ``sigma_pos`` [m], ``sigma_rot`` [rad, None without orientations]: the noise scales weighting the
    rows. ``models``: sensitivity models, a cache shared by every fit and held-out
    evaluation of this model and of every model derived from it.
    """

    chain: KinematicChain
    calibration: ChainCalibration
    rows: MeasurementSet
    row_weight: np.ndarray
    inputs: EffectInputs
    sigma_pos: float
    sigma_rot: float | None
    models: dict[tuple[ParameterSlot, ...], SensitivityModel] = field(default_factory=dict)

    @classmethod
    def of(cls, chain: KinematicChain, calibration: ChainCalibration, rows: MeasurementSet, row_weight: np.ndarray,
           inputs: EffectInputs) -> EffectModel:
        """The model of ``calibration`` with no effect yet, at its noise scales."""
        return cls(chain, calibration, rows, row_weight, inputs, calibration.sigma_pos_m, calibration.sigma_rot_rad)

    def problem(self, effects: Sequence[Effect], data: MeasurementSet | None = None,
                inputs: EffectInputs | None = None) -> FitProblem:
        data = self.rows if data is None else data
        weight = self.row_weight if data is self.rows else np.ones(data.n_rows)
        assert self.calibration.start is not None  # calibrate_chain always sets it
        problem = FitProblem(
            self.chain, self.calibration.params, data, self.calibration.start,
            fit_target=self.calibration.fit_target, row_weight=weight,
            effects=effects, inputs=self.inputs if inputs is None else inputs, models=self.models,
            session_names=self.calibration.session_names,
            sigma_pos=self.sigma_pos, sigma_rot=self.sigma_rot,
            prior=self.calibration.prior_sigma,  # the geometry's prior, if any (class docstring)
            point_basis=self.calibration.point_basis,  # a target held where the data leave it free
            registration_basis=self.calibration.registration_basis,  # a registration rotation held
        )
        return problem

    def reestimated(self, objective: FitObjective, solution: Solution) -> EffectModel:
        """This model at the noise scales of a fit's residuals (maximum likelihood)."""
        problem = self.problem(objective.effects).rescaled(objective, solution)
        return replace(self, sigma_pos=problem.sigma_pos, sigma_rot=problem.sigma_rot)

    def fit(self, effects: Sequence[Effect], x_start: np.ndarray, values_start: Sequence[np.ndarray],
            max_evaluations: int | None = None, tolerance: float | None = None, chunk: int | None = None
            ) -> tuple[FitObjective, Solution]:
        """Fit geometry, registration, target and ``effects`` from a start: at most ``max_evaluations``, or
        in chunks of ``chunk`` while they gain (:func:`fit_while_gaining`)."""
        problem = self.problem(effects)
        base = self.calibration.vector
        objective = problem.objective(self.calibration.kept, base)
        x0 = np.zeros(objective.n_params)
        n_core = x_start.size
        x0[:n_core] = x_start
        for sl, value in zip(objective.effect_slices, values_start):
            x0[sl] = value
        if chunk is not None:
            return objective, fit_while_gaining(objective, x0, chunk, tolerance)
        solution = solve(objective, x0, what="effect fit", max_evaluations=max_evaluations, tolerance=tolerance)
        return objective, solution


def pose_errors_of(objective: FitObjective, x: np.ndarray) -> PoseErrors:
    """Point errors (and orientation errors with 6D data) of a fit on its own rows (eq 24)."""
    position = np.linalg.norm(objective.predicted_points(x) - objective.g, axis=2)
    rotation = None
    if objective.G is not None:
        poses, _, target, _ = objective.state(x)
        relative = objective.orientation_error(poses, target)
        rotation = np.linalg.norm(Rotation.from_matrix(relative).as_rotvec(), axis=1)
    return PoseErrors(position_m=position, rotation_rad=rotation)


def heldout_errors(model: EffectModel, objective: FitObjective, x: np.ndarray,
                   heldout: MeasurementSet | None,
                   held_inputs: EffectInputs | None) -> PoseErrors | None:
    """The errors of the fit (``objective`` at ``x``) on held-out rows (None without them), each in its
    calibrated session's registration."""
    if heldout is None:
        return None
    problem = model.problem(objective.effects, heldout, held_inputs)
    return pose_errors_of(problem.objective(model.calibration.kept, model.calibration.vector), x)
