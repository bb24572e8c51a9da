"""Leave-fold-out errors at scale: one Gauss–Newton step from the fit of all rows.

Cross-validating a level refits it once per fold (:mod:`pincal.fit.level_choice`). With many
rows that costs ten calibrations per level, while leaving out a tenth of K rows moves the
parameters only by about a third of their standard deviation (the information falls by 10 %),
where the fit's quadratic model is exact to the rounding of its curvature. So from
:data:`LINEARISED_FROM_ROWS` rows on, fold f's fit is the all-rows solution x̂ moved by the
Gauss–Newton step of the training rows T (the prior's rows, if any, stay with them):

    δ_f = −(J_Tᵀ J_T)⁺ J_Tᵀ r_T,    e_V = r_V + J_V δ_f                 (L1)

with J, r the Jacobian and the noise-weighted residual at x̂ (Allen 1974's leave-out formula
for a block of rows, without the linearisation's assumption that x̂ fits the held-out rows:
δ_f is computed, not approximated by the hat matrix). The held-out error is then the RMS
distance of the held-out rows' target points, e_V turned back into metres. The selection of
the fold's parameters is the all-rows fit's: under ``--select prior`` (the default) that is
every identifiable parameter anyway. The prior's scales, where they were estimated from the
rows, are estimated again for each fold from its training rows alone, by the same rule on the
same linearisation (:func:`pincal.fit.prior_scales.chosen_scales`), and the fold's prior rows
θ/σ take them: a refit of the fold estimates its own, and a scale estimated on all rows would
let the held-out rows into the fold's fit through three numbers. Several sessions, and
``--reject-outliers``, keep the exact refits (a held-out session needs its own registration).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import cast

import numpy as np

from pincal.errors import CalibrationError
from pincal.fit.chain_calibration import ChainCalibration, ChainFitOptions, FitProblem, calibrate_chain, row_weights
from pincal.fit.prior import Prior, PriorResidual, parameter_kinds, prior_of
from pincal.fit.prior_scales import LinearisedFit, chosen_scales
from pincal.measurements.data import MeasurementSet
from pincal.model.chain import KinematicChain
from pincal.model.parameter_sets import ChainLevel, ChainParameters
from pincal.progress import Counter

__all__ = ["LINEARISED_FROM_ROWS", "final_problem", "linearised_fold_errors", "linearised_levels"]

#: Rows from which the folds are scored by eq L1 instead of refits: each then holds 50 or
#: more rows and a fold moves the parameters by ~1/3 of their standard deviation.
LINEARISED_FROM_ROWS = 500


def final_problem(chain: KinematicChain, result: ChainCalibration, rows: MeasurementSet,
                  row_weight: np.ndarray | None = None) -> FitProblem:
    """The fit problem of a calibration's final fit, rebuilt (its rows, start, held target, noise
    scales, weights ``row_weight`` — default ones — and prior): ``problem.objective(result.kept, zeros)``
    at ``result.solution`` is that fit's objective at its solution."""
    weight = np.ones(rows.n_rows) if row_weight is None else row_weight
    assert result.start is not None  # calibrate_chain always sets it
    return FitProblem(chain, result.params, rows, result.start, fit_target=result.fit_target, row_weight=weight,
                      session_names=result.session_names, sigma_pos=result.sigma_pos_m,
                      sigma_rot=result.sigma_rot_rad, prior=result.prior_sigma, point_basis=result.point_basis,
                      registration_basis=result.registration_basis)


def linearised_fold_errors(chain: KinematicChain, result: ChainCalibration, rows: MeasurementSet,
                           tests: Sequence[np.ndarray], row_weight: np.ndarray | None = None,
                           calibrated_with: Prior | None = None) -> list[float]:
    """Eq L1's held-out RMS point distance [m] of each fold, its held-out rows ``tests`` (indices into
    ``rows``, the rows ``result`` was fitted on); ``calibrated_with``: the prior ``result`` was calibrated with (where
    its scales were estimated, each fold's estimate starts from its scales, as the fit's did; default
    the default scales)."""
    problem = final_problem(chain, result, rows, row_weight)
    size = 0 if result.params is None else result.params.size
    objective = problem.objective(result.kept, np.zeros(size))
    jacobian = objective.jacobian(result.solution)
    residual = objective.residual(result.solution)
    data = getattr(objective, "objective", objective)  # the sensor residual inside a prior-wrapped one
    blocks = data.row_indices()  # (K, b): row k's residual entries, its 3P point coordinates first
    n_pos = 3 * rows.n_points
    scale = np.linalg.norm(jacobian, axis=0)
    scale[scale == 0.0] = 1.0
    estimated = _estimated_prior(result, calibrated_with)
    if estimated is not None:  # each fold's scales from its training rows alone (pincal.fit.prior_scales)
        prior = cast(PriorResidual, objective)  # an estimated prior's fit carries its rows
        linear = LinearisedFit.of(prior, result.solution, jacobian, residual, problem.scale_rows(prior),
                                  [s for s in problem.scales() if s is not None],
                                  parameter_kinds(cast(ChainParameters, result.params))[result.kept])  # a MAP fit's
        m, kin = residual.size - prior.n_prior, prior.blocks["kinematic"]
    out = []
    for test in tests:
        held = np.zeros(residual.size, dtype=bool)
        held[blocks[test].ravel()] = True
        if estimated is not None:
            train = np.setdiff1d(np.arange(rows.n_rows), test)
            sigma = chosen_scales(linear, ~held[:m], rows.q[train], rows.session_index[train], blocks[train],
                                  estimated)
            jacobian[m:, kin] = np.diag(1.0 / sigma)  # the prior rows θ/σ (eq P1) at the fold's scales
            residual[m:] = result.solution[kin] / sigma
        step, *_ = np.linalg.lstsq(jacobian[~held] / scale, -residual[~held], rcond=None)
        positions = blocks[test][:, :n_pos]
        predicted = residual[positions] + (jacobian[positions] / scale) @ step  # (V, 3P), weighted
        metres = predicted * (problem.sigma_pos / problem.row_weight[test])[:, None]
        distances = np.linalg.norm(metres.reshape(len(test), rows.n_points, 3), axis=2)
        out.append(float(np.sqrt(np.mean(distances**2))))
    return out


def _estimated_prior(result: ChainCalibration, prior: Prior | None) -> np.ndarray | None:
    """The scales the estimate of ``result``'s prior started from [m, rad, rad] (3,): ``prior``'s (the
    defaults without one), where its scales were estimated from the rows (REPORT.json's ``prior_scale``
    has an ``estimate``); else None."""
    scale = None if result.selection is None else result.selection.prior_scale
    if not scale or "estimate" not in scale:
        return None
    return (Prior() if prior is None else prior).si


def linearised_levels(chain: KinematicChain, rows: MeasurementSet, tests: Sequence[np.ndarray],
                      levels: Sequence[ChainLevel], counter: Counter, options: ChainFitOptions
                      ) -> list[tuple[ChainLevel, list[float], list[int], list[str]]]:
    """Every level's fit of all ``rows`` (``options``: how :func:`calibrate_chain` fits), then eq L1 for
    each fold's held-out rows ``tests``: (level, fold errors [mm], kept per fold, failures) per level.
    As with refits, the first level must fit (else one line); a later one that cannot is no candidate
    (NaN errors)."""
    out = []
    counter.expect(len(levels))
    for level in levels:
        try:
            result = calibrate_chain(chain, rows, level, options)
        except CalibrationError as exc:
            if level == levels[0]:
                raise CalibrationError(f"--level auto: the {rows.n_rows} rows cannot be calibrated even at "
                                       f"level {level}: {exc}") from None
            out.append((level, [np.nan] * len(tests), [-1] * len(tests), [f"all rows: {exc}"]))
            continue
        finally:
            counter.tick()
        errors = linearised_fold_errors(chain, result, rows, tests, row_weights(rows, options.sigma_column),
                                        prior_of(options.selection))
        out.append((level, [e * 1000.0 for e in errors], [len(result.kept)] * len(tests), []))
    return out
