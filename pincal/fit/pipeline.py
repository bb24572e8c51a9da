"""One calibration pipeline for every kind of measurement: order, select, fit, rescale, judge.

A kind of measurement differs from another only in its residual: sensor rows
(:mod:`pincal.fit.chain_calibration`: points and orientations in a sensor frame, a
registration per session, a target) and socket-fixture rows
(:mod:`pincal.fit.fixture_calibration`: the ball in a socket, a ball centre, a pose per
placement). Each gives a *problem* — its residual over any subset of the kinematic
parameters, with the always-estimated part (registration, target; ball, placements) free —
already fitted with the nominal kinematics, and the Jacobian its identifiability is judged on.
From there the steps are the same, and :func:`fit_kinematics` runs them:

1. order the kinematic parameters by how well the data determine them, given the
   always-estimated part (pivoted QR, :func:`pincal.fit.identifiability.order_parameters`);
2. keep the subset the criterion chooses (:func:`pincal.fit.selection.select_subset`; with
   ``prior``, every identifiable one in a MAP fit, :mod:`pincal.fit.prior` eq P1);
3. fit the kept parameters, then re-estimate the residual's noise scale and refit (without a
   prior a given number of times, maximum likelihood with unknown variances; with one, up to
   eq P2's fixed point; with a prior whose scales are estimated, then those scales,
   :mod:`pincal.fit.prior_scales`);
4. the covariance (the fit's, scaled by the residual; with a prior, the posterior) and each
   parameter's status: kept, not selected, not identifiable, or determined by the prior only.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Generic, cast

import numpy as np

from pincal.errors import CalibrationError
from pincal.fit.identifiability import Ordering, Selection, absorbed_into, order_parameters
from pincal.fit.prior import (
    DATA_SCALE_GAP,
    DECISIVE_LOG_EVIDENCE,
    MAX_SCALE_ITERATIONS,
    PRIOR_STATUS,
    Prior,
    PriorResidual,
    ScaleChoice,
    map_outcome,
    parameter_kinds,
    prior_of,
    prior_sigmas,
    settled,
)
from pincal.fit.prior_scales import (
    LinearisedFit,
    cross_validated,
    estimate_scales,
    hyperprior,
    prior_log_evidence,
    scale_folds,
)
from pincal.fit.problem import KindProblem, ObjectiveT, Refit
from pincal.fit.selection import SelectionCriterion, select_subset
from pincal.fit.solver import Solution, gram, solve
from pincal.measurements.data import MeasurementSet
from pincal.model.parameter_sets import ChainLevel, ChainParameters
from pincal.progress import Counter

__all__ = [
    "KEPT", "NOT_IDENTIFIABLE", "NOT_SELECTED", "Dropped", "ObjectiveT", "KindProblem", "Analysis", "KinematicFit",
    "fit_kinematics", "dropped_parameters", "SCALE_FIT_EVALUATIONS",
]

#: Evaluations allowed to the unregularised fit that gives the data's own noise scale
#: (:func:`_from_the_data_scale`). Where the data leave combinations undetermined (curvature
#: outweighing information, eq S3 of :mod:`pincal.fit.selection`), Levenberg–Marquardt crawls along
#: them without meeting its tolerances while the cost hardly moves: 2 × 10⁻⁷ of it per evaluation
#: on scripts/benchmark.py's UR5 session (f), 2 × 10⁻⁵ of the scale after 3 000 evaluations
#: (105 s), where the scale is compared with the prior's within a factor
#: :data:`pincal.fit.prior.DATA_SCALE_GAP`. Converging fits took at most 54 on the README commands.
SCALE_FIT_EVALUATIONS = 100

KEPT = "calibrated"
NOT_IDENTIFIABLE = "not determined: not identifiable from these measurements"
NOT_SELECTED = "not determined: weakly identified, left out by the selection criterion"


@dataclass(frozen=True)
class Dropped:
    """A parameter not estimated, and what absorbs it."""

    index: int
    reason: str
    absorbed_into: tuple[tuple[str, float], ...]


@dataclass(frozen=True)
class Analysis:
    """The Jacobian identifiability is judged on, at the problem's start, with every kinematic
    parameter free: which of its columns are kinematic, and which are always estimated (they
    may include columns the problem holds, e.g. a target direction the data cannot place)."""

    jacobian: np.ndarray
    kinematic: np.ndarray
    always: np.ndarray


@dataclass(frozen=True)
class KinematicFit(Generic[ObjectiveT]):
    """The outcome of :func:`fit_kinematics`.

    Attributes:
        ordering: the identifiability ordering (None at level registration).
        selection: the criterion's choice and its notes (None at level registration).
        kept: indices of the kinematic parameters estimated, sorted.
        objective, solution: the final fit (the objective carries a prior's rows with one).
        vector: (n,) every kinematic parameter's value, zero where not kept [m, rad].
        std: (n,) its standard deviation, NaN where not kept.
        std_all: standard deviation of every column of ``objective`` (kept kinematics first).
        status: (n,) ``kept``, ``not selected``, ``not identifiable`` or the prior's status.
        covariance: of the columns of ``objective`` (with a prior: the posterior).
        fit_seconds: the final fit and its refits [s].
        problem: the problem the final fit was made of (its noise scales and prior).
    """

    ordering: Ordering | None
    selection: Selection | None
    kept: np.ndarray
    objective: ObjectiveT
    solution: Solution
    vector: np.ndarray
    std: np.ndarray
    std_all: np.ndarray
    status: tuple[str, ...]
    covariance: np.ndarray
    fit_seconds: float
    problem: KindProblem[ObjectiveT]

    @property
    def rank(self) -> int:
        """How many kinematic parameters are identifiable."""
        return 0 if self.ordering is None else self.ordering.rank


def fit_kinematics(problem: KindProblem[ObjectiveT], analysis: Analysis | None, rows: MeasurementSet,
                   criterion: SelectionCriterion | Prior, level: ChainLevel, refits: int,
                   counter: Counter | None = None, from_selection: bool = True) -> KinematicFit[ObjectiveT]:
    """Steps 1–4 of the module docstring on ``problem`` (its start: the nominal kinematics' fit).

    Args:
        analysis: the Jacobian to order on (None when there are no kinematic parameters).
        rows: the problem's rows as measurements (the selection's bookkeeping).
        criterion: the selection criterion (:data:`pincal.fit.selection.SELECTION_CRITERIA`)
            or a :class:`pincal.fit.prior.Prior`.
        refits: re-estimations of the noise scale after the fit without a prior (with one: up to
            :data:`pincal.fit.prior.MAX_SCALE_ITERATIONS`, stopping at eq P2's fixed point).
        counter: ticks once per subset the selection fits, and once for the final fit.
        from_selection: start the final fit from the selected subset's solution (fitted at the
            selection's looser tolerance) rather than from the problem's start.
    """
    counter = Counter(None) if counter is None else counter
    params = problem.params  # every variant of the problem has the same
    size = params.size if params is not None else 0  # how many kinematic parameters the level has
    base, kept = np.zeros(size), np.array([], dtype=int)
    ordering, selection = None, None
    prior = prior_of(criterion)
    if analysis is not None and params is not None and size:
        ordering = order_parameters(analysis.jacobian, analysis.kinematic, analysis.always)
        problem = problem.with_prior(None if prior is None else prior_sigmas(params, prior))
        selection, kept = select_subset(problem, ordering, base, rows, criterion, counter)
    started = time.perf_counter()
    x0 = selection.solution if (from_selection and selection is not None) else None
    refit = Refit(kept, base, f"{level} fit")
    objective, solution = refit.of(problem, x0)
    if size:
        problem, objective, solution = _settle(problem, objective, solution, refit, refits)
    closer = None  # the unregularised fit's position scale, where the evidence kept the prior's fixed point
    choice = None if prior is None else ScaleChoice(prior)  # the prior's scales the fit ends with
    if problem.prior is not None and kept.size:
        problem, objective, solution, closer = _from_the_data_scale(problem, objective, solution, refit)
        if cast(Prior, prior).estimated:
            problem, objective, solution, choice = _estimated(problem, objective, solution, refit, cast(Prior, prior))
            closer = None if choice.used.estimated else closer
    fit_seconds = time.perf_counter() - started
    counter.tick()
    kinematic = objective.blocks["kinematic"]
    vector = base.copy()
    vector[kept] = solution.x[kinematic]
    std_all = solution.std
    status = np.array([NOT_IDENTIFIABLE] * size, dtype=object)
    if ordering is not None:
        status[ordering.order[: ordering.rank]] = NOT_SELECTED
        status[kept] = KEPT
    jac = solution.jacobian
    if not isinstance(objective, PriorResidual):
        covariance = np.linalg.pinv(gram(jac)) * (solution.rms**2 * jac.shape[0] / max(jac.shape[0] - jac.shape[1], 1))
    else:  # the posterior, and what the prior determines (pincal.fit.prior)
        # a PriorResidual is fitted only with a prior: problem.prior and prior are set
        covariance, weak, selection = map_outcome(jac, solution.residual, objective, kept,
                                                  cast(np.ndarray, problem.prior), selection,
                                                  cast(ChainParameters, params), cast(ScaleChoice, choice))
        std_all = np.sqrt(np.diag(covariance))
        status[weak] = PRIOR_STATUS
        if closer is not None:
            selection = replace(selection, notes=selection.notes + (_prior_too_narrow(
                kept.size, closer, cast(float, problem.scales()[0]), cast(Prior, prior)),))  # positions: measured
    std = np.full(size, np.nan)
    std[kept] = std_all[kinematic]
    return KinematicFit(ordering=ordering, selection=selection, kept=kept, objective=objective, solution=solution,
                        vector=vector, std=std, std_all=std_all, status=tuple(status), covariance=covariance,
                        fit_seconds=fit_seconds, problem=problem)


def _settle(problem: KindProblem[ObjectiveT], objective: ObjectiveT, solution: Solution, refit: Refit, refits: int
            ) -> tuple[KindProblem[ObjectiveT], ObjectiveT, Solution]:
    """Step 3's refits: the noise scales re-estimated and the fit repeated, ``refits`` times without a
    prior; with one, up to eq P2's fixed point (at most :data:`pincal.fit.prior.MAX_SCALE_ITERATIONS`).
    Returns the problem at the last scales (those of the last fit, or the fixed point's), and the last fit."""
    for _ in range(refits if problem.prior is None else MAX_SCALE_ITERATIONS):
        before = problem.scales()
        problem = problem.rescaled(objective, solution)
        if problem.prior is not None and settled(before, problem.scales()):
            break  # a prior's fixed point of eq P2 (pincal.fit.prior)
        objective, solution = refit.of(problem, solution.x)
    return problem, objective, solution


def _from_the_data_scale(problem: KindProblem[ObjectiveT], objective: ObjectiveT, solution: Solution, refit: Refit
                         ) -> tuple[KindProblem[ObjectiveT], ObjectiveT, Solution, float | None]:
    """Eq P2 from the data's own noise scale, kept if the evidence (eq P3) decisively prefers it.

    Started from the registration's scale (the nominal model's misfit), eq P2 can settle where the
    prior explains the misfit as noise: with deviations far beyond the prior's scale and few rows
    (the paper's large KUKA deviations, 10–14 6D rows) every parameter stayed prior-dominated and the
    model missed by 40 mm where the data determine it to 0.02 mm. The unregularised fit of the same
    parameters gives the data's scale (corrected for its degrees of freedom, ‖r‖²/(m − n)); when it
    is below :data:`pincal.fit.prior.DATA_SCALE_GAP` of the fixed point's, eq P2 is iterated from it
    too, and the fixed point with the larger evidence by more than
    :data:`pincal.fit.prior.DECISIVE_LOG_EVIDENCE` is the answer. Otherwise the prior's
    fixed point stands — under the prior the closer fit is the less probable one: deviations of
    10 mm against its 1 mm — and the fourth value returned is the closer fit's position scale [m]
    (None when it was not tried or was taken), for a note that the prior may be too narrow. The
    problem returned is the one of the fit returned.
    """
    first_evidence = problem.log_evidence(objective, solution)
    try:
        plain_problem = problem.with_prior(None)
        plain = plain_problem.objective(refit.kept, refit.base)  # a crawl stops at its budget: only its scale is used
        unregularised = solve(plain, solution.x, what=refit.what, max_evaluations=SCALE_FIT_EVALUATIONS)
        data_scale = plain_problem.rescaled(plain, unregularised).scales()  # the data's: maximum likelihood
    except CalibrationError:  # not determined without the prior: the first fixed point stands
        return problem, objective, solution, None
    # the maximum-likelihood scale is biased low by the m − n degrees of freedom: compared unbiased
    m, n = unregularised.residual.size, unregularised.x.size
    unbiased = [None if data is None else data * np.sqrt(m / max(m - n, 1)) for data in data_scale]
    # a kind measured (a scale not None) has its scale in both
    if not any(data is not None and data < DATA_SCALE_GAP * cast(float, scale)
               for data, scale in zip(unbiased, problem.scales())):
        return problem, objective, solution, None  # one basin: the fixed point already lies near the data's scale
    try:
        second_problem = problem.with_scales(data_scale)
        second, second_solution = refit.of(second_problem, unregularised.x)
        second_problem, second, second_solution = _settle(second_problem, second, second_solution, refit, 0)
        better = second_problem.log_evidence(second, second_solution) > first_evidence + DECISIVE_LOG_EVIDENCE
    except CalibrationError:  # a scale near rounding level makes the prior fit singular
        better = False
    if better:
        return second_problem, second, second_solution, None
    return problem, objective, solution, cast(float, unbiased[0])


def _estimated(problem: KindProblem[ObjectiveT], objective: ObjectiveT, solution: Solution, refit: Refit,
               prior: Prior) -> tuple[KindProblem[ObjectiveT], ObjectiveT, Solution, ScaleChoice]:
    """The prior's scales estimated from the rows, from the MAP fit at ``prior``'s (the defaults), and
    the fit kept: the estimate's where its posterior (eq P4 + P6) is the larger and it predicts held-out
    configurations better by more than one standard error, else the defaults'
    (:mod:`pincal.fit.prior_scales`). The first estimate, from the defaults' fit, is checked by the folds
    on that fit's linearisation before any refit: where it is no better, the defaults stand at the cost
    of one factorisation per trial. The problem returned is the one of the fit kept (its scales and prior)."""
    kinds, kept = parameter_kinds(cast(ChainParameters, problem.params)), refit.kept  # a MAP fit has parameters
    first_prior = cast(np.ndarray, problem.prior)
    default = _linearised(problem, objective, solution, kinds[kept])
    start = prior.si
    present = default.present
    defaults = Prior(*prior.scales, estimated=False)
    folds = scale_folds(*problem.fold_rows(objective))

    def posterior_gain(noise: np.ndarray, sigma: np.ndarray) -> tuple[float, float]:
        """eq P4 (linearised at the defaults' fit) and P4 + P6 of ``sigma`` over the defaults'."""
        at = np.log(np.r_[default.noise / noise, sigma[present]])
        gain = default.evidence(at)[0] - default.evidence(np.log(np.r_[np.ones(default.noise.size),
                                                                         start[present]]))[0]
        return gain, gain + hyperprior(np.log(sigma[present]), start[present])[0]

    estimate, fit = objective, solution  # the defaults' fit, until an estimate is refitted
    estimated = problem
    try:
        noise, sigma = default.maximise(start, start)
        check = cross_validated(default.at_scales(sigma), default, folds)
        gain, posterior = posterior_gain(noise, sigma)
        if check.better and posterior > 0.0:  # refitted at the estimate, and checked again
            estimated, estimate, fit, sigma = estimate_scales(problem, objective, solution, refit, kinds, start,
                                                              first=(noise, sigma))
            first_evidence = prior_log_evidence(problem.log_evidence(objective, solution), first_prior[kept])
            gain = prior_log_evidence(estimated.log_evidence(estimate, fit),
                                      cast(np.ndarray, estimated.prior)[kept]) - first_evidence
            posterior = gain + hyperprior(np.log(sigma[present]), start[present])[0]
            check = cross_validated(_linearised(estimated, estimate, fit, kinds[kept]), default, folds)
    except CalibrationError as exc:  # a scale the fit cannot take: the defaults' fit stands
        return problem, objective, solution, ScaleChoice(
            defaults, reason=f"the default scales: the estimate failed ({exc})")
    lengths, angles, zeros = sigma
    found = Prior(lengths * 1e3, float(np.degrees(angles)), float(np.degrees(zeros)), estimated=True)
    cv = (f"{check.folds}-fold cross-validated error {check.ratio:.3f} x the defaults' "
          f"(standard error {check.standard_error:.3f})")
    record = (found, gain, check.ratio, check.standard_error)
    if check.better and posterior > 0.0:
        reason = f"estimated: evidence e^{gain:.3g} times the defaults', {cv}"
        return estimated, estimate, fit, ScaleChoice(found, *record, reason)
    why = cv + ", not lower by one standard error" if not check.better else "posterior is not the larger"
    return problem, objective, solution, ScaleChoice(defaults, *record, f"the default scales: the estimate's {why}")


def _linearised(problem: KindProblem[ObjectiveT], objective: ObjectiveT, solution: Solution,
                kinds: np.ndarray) -> LinearisedFit:
    """Eq P5's linearisation of ``problem``'s MAP fit (``objective`` at ``solution``) at its noise scales now."""
    present = [s for s in problem.scales() if s is not None]
    # a problem with a prior fits a PriorResidual (eq P1)
    return LinearisedFit.at(cast(PriorResidual, objective), solution, problem.scale_rows(objective), present, kinds)


def _prior_too_narrow(n_kept: int, closer_m: float, scale_m: float, prior: Prior) -> str:
    """The note of a prior whose fixed point the evidence kept against a much closer fit."""
    return (f"without the prior the same {n_kept} parameters fit these rows to a noise scale of "
            f"{closer_m * 1e3:.3g} mm, against {scale_m * 1e3:.3g} mm with it; the prior of "
            f"{prior.translation_mm:g} mm / {prior.rotation_deg:g} deg finds the closer fit less probable "
            "(its deviations are large on that scale): if this robot's are, rerun with a wider "
            "--prior-scale MM,DEG or with --select aic")


def dropped_parameters(jacobian: np.ndarray, ordering: Ordering, kept: np.ndarray, always: np.ndarray,
                       names: list[str]) -> tuple[Dropped, ...]:
    """Each kinematic parameter not kept (not selected, or not identifiable), with the kept and
    always-estimated columns of ``jacobian`` that absorb it (:func:`pincal.fit.identifiability.absorbed_into`);
    ``names``: of every column of ``jacobian``, the kinematic parameters' first."""
    kept_set = set(kept.tolist())
    dropped = [(position, int(column)) for position, column in enumerate(ordering.order) if int(column) not in kept_set]
    absorbers = absorbed_into(jacobian, [column for _, column in dropped],
                              np.concatenate([kept, always]).astype(int))
    return tuple(
        Dropped(index=column, reason=NOT_SELECTED if position < ordering.rank else NOT_IDENTIFIABLE,
                absorbed_into=tuple((names[c], coef) for c, coef in absorbing))
        for (position, column), absorbing in zip(dropped, absorbers)
    )
