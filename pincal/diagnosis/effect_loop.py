"""The search loop of ``diagnose`` on a residual other than one chain's sensor rows (a tree's targets, a camera's
corners): screen, fit the shortlist, judge, adopt, refit, until no candidate passes.

The residual is behind an :class:`EffectSearch` (a tree's :func:`pincal.diagnosis.tree_diagnose.diagnose_tree`, a
camera's :func:`pincal.diagnosis.camera_diagnose.diagnose_camera`); the rules are the single chain's
(:mod:`pincal.diagnosis.verdicts`). Each step screens every candidate by the linearised score test of
:mod:`pincal.diagnosis.screening` at the current fit, fits those that may reach the evidence cut in full (the
geometry, the residual's own unknowns and the effects together), and adopts the best that passes

    ΔBIC = m ln(RSS₁/RSS₀) + Δn ln(m) < EVIDENCE = −10      (Schwarz 1978; Kass & Raftery 1995)

on the calibration rows (m: their residual's entries; the noise scale the current model's, re-estimated after
each adoption), a value some :data:`DETERMINED_Z` standard deviations from zero, in physical range, a change of
some measured coordinate of at least NEGLIGIBLE × its noise, a basis that is not an offset, and with held-out
rows better on them beyond their noise (the search's held-out test). The search stops when no candidate passes,
or after :data:`pincal.diagnosis.diagnose.MAX_EFFECTS`.

A candidate that passes every check too, within :data:`ALIKE_WINDOW` of the adopted one's ΔBIC, and changes the
measured coordinates as it does (beyond what the fit's other unknowns can: the cosine of the two changes above
:data:`pincal.diagnosis.verdicts.AMBIGUOUS`) is named beside it, as the single chain names candidates that correct
alike (:func:`pincal.diagnosis.ambiguity.ambiguity_words`): the rows cannot tell them apart.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Protocol, TypeVar

import numpy as np
import scipy.stats

from pincal.diagnosis.ambiguity import ambiguity_words
from pincal.diagnosis.diagnose import MAX_EFFECTS
from pincal.diagnosis.held_out import HELD_OUT_LEVEL, HELD_OUT_Z
from pincal.diagnosis.screening import (
    FitObjective,
    Linearisation,
    bic,
    may_reach,
    n_prior_rows,
    residual_freedom,
    testable,
)
from pincal.diagnosis.verdicts import AMBIGUOUS, EVIDENCE, NEGLIGIBLE, effect_basis, offset_like, plausible
from pincal.errors import CalibrationError
from pincal.fit.prior import PriorResidual, posterior, standard_deviations
from pincal.fit.solver import Solution, gram
from pincal.model.chain import KinematicChain
from pincal.model.effects import Effect, EffectInputs
from pincal.progress import Counter

__all__ = ["SHORTLIST", "DETERMINED_Z", "DETERMINED_LEVEL", "ALIKE_WINDOW", "EffectCandidate", "EffectStep",
           "EffectSearch", "Found", "Model", "search_effects"]

#: Candidates fitted in full per step, the best of the screen that may reach the evidence cut: the single
#: chain's "first eight" (:mod:`pincal.diagnosis.diagnose`, screening).
SHORTLIST = 8

#: Least |value| / standard deviation of some value of an effect to adopt it: a one-value effect entering linearly
#: gains about (v/σ)² − ln m of BIC, so one within 2σ of zero (the held-out test's z, HELD_OUT_Z of
#: :mod:`pincal.diagnosis.held_out`) passes the cut only through the prior's rows — a direction of the geometry
#: the prior held (a sensor scale against every length), freed; not through the data.
DETERMINED_Z = HELD_OUT_Z
#: The same level for an effect of any number of values (a compliance over mass moments: each value alone may
#: be undetermined, their combination not): Wald's χ² of the values above its quantile at 1 − 2 Φ(−2) (one
#: value: χ² = (v/σ)² ≥ 4, |v| ≥ 2σ).
DETERMINED_LEVEL = 1.0 - 2.0 * HELD_OUT_LEVEL
#: Largest ΔBIC above the adopted candidate's of another that corrects alike and is named beside it: the single
#: chain's window (:meth:`pincal.diagnosis.verdicts.Judge.judged`, competitors within 6 of its ΔBIC), the "strong"
#: evidence of Kass & Raftery (1995) below which the rows do not prefer one.
ALIKE_WINDOW = 6.0
#: The verdict of a candidate fitted after the one adopted, not judged.
NOT_JUDGED = "not judged: another adopted"


@dataclass(frozen=True)
class EffectCandidate:
    """A candidate of a step: the effect, its full fit's ΔBIC against the step's model (the linearised one,
    marked ``screened``, when it was not fitted in full), its values and the verdict in words."""

    effect: Effect
    delta_bic: float
    values: np.ndarray
    verdict: str
    screened: bool = False


@dataclass(frozen=True)
class EffectStep:
    """One adopted effect: its values and standard deviations [unit of :func:`pincal.model.effect_units.effect_unit`],
    its ΔBIC, the calibration rows' errors before and after it (the search's :meth:`EffectSearch.errors`), the
    held-out rows' (None without them), the step's candidates (best first), and the orientation errors before and
    after it on the calibration and on the held-out rows (:meth:`EffectSearch.turns`; None where the rows measure
    none, or none are held out)."""

    effect: Effect
    values: np.ndarray
    std: np.ndarray
    delta_bic: float
    calibration_before: np.ndarray
    calibration_after: np.ndarray
    heldout_before: np.ndarray | None
    heldout_after: np.ndarray | None
    candidates: tuple[EffectCandidate, ...]
    calibration_turns: tuple[np.ndarray, np.ndarray] | None = None
    heldout_turns: tuple[np.ndarray, np.ndarray] | None = None


S = TypeVar("S", bound="EffectSearch")
#: A model of a search: its effects and the fit's unknowns.
Model = tuple[Sequence[Effect], np.ndarray]


class EffectSearch(Protocol):
    """What the loop asks of a residual: fits with effects, errors and the held-out test."""

    def body(self) -> KinematicChain:
        """The chain (or a tree's body) the effects act on: their physical range and bases."""
        ...

    def fit(self, effects: Sequence[Effect], x0: np.ndarray | None = None) -> tuple[FitObjective, Solution]:
        """The fit of the geometry with ``effects`` (their values last), from ``x0`` (default: the start)."""
        ...

    def rescaled(self: S, objective: FitObjective, solution: Solution) -> S:
        """This search at the noise scale of a fit's residual."""
        ...

    def row_noise(self) -> float:
        """The noise of one entry of the fits' residual [its unit]: 1 for a whitened residual."""
        ...

    def errors(self, objective: FitObjective, x: np.ndarray) -> np.ndarray:
        """The calibration rows' errors (K, P) of a fit, NaN where not seen."""
        ...

    def held_errors(self, effects: Sequence[Effect], x: np.ndarray) -> np.ndarray | None:
        """The held-out rows' errors (K_h, P) of the model at ``x`` (None without them)."""
        ...

    def turns(self, objective: FitObjective, x: np.ndarray) -> np.ndarray | None:
        """The calibration rows' orientation errors (K, T) [rad] of a fit, NaN where not seen (None: none measured)."""
        ...

    def reproduced(self, errors: np.ndarray, turns: np.ndarray | None, effects: int) -> str | None:
        """Why no effect can be told from these rows — a fit (the geometry and ``effects`` effects) whose errors
        (:meth:`errors`, :meth:`turns`) are within :data:`pincal.diagnosis.reproduction.REPRODUCED`, where the
        BIC's noise estimate is rounding and any change "significant" — as a note, or None."""
        ...

    def held_turns(self, effects: Sequence[Effect], x: np.ndarray) -> np.ndarray | None:
        """The held-out rows' orientation errors (K_h, T) [rad] of the model at ``x`` (None: none, or no rows)."""
        ...

    def held_verdict(self, before: np.ndarray, after: np.ndarray, fit: tuple[FitObjective, Solution],
                     models: tuple[Model, Model]) -> str:
        """``adopted``, or why not, from the held-out rows' errors without and with the candidate (its fit);
        ``models``: the effects and unknowns of the two models, for what else a residual measures there."""
        ...


@dataclass(frozen=True)
class Found:
    """Where :func:`search_effects` ended: the search at the final noise scale, the final fit, the effects adopted,
    their steps, the ranking of the step that adopted nothing, notes, and the unknowns of the fit without effects
    (``start_x``: what the steps' errors before the first are of)."""

    search: EffectSearch
    objective: FitObjective
    solution: Solution
    adopted: tuple[Effect, ...]
    steps: tuple[EffectStep, ...]
    ranking: tuple[EffectCandidate, ...]
    notes: tuple[str, ...]
    start_x: np.ndarray | None = None


def _pair(before: np.ndarray | None, after: np.ndarray | None) -> tuple[np.ndarray, np.ndarray] | None:
    return None if before is None or after is None else (before, after)


def search_effects(search: EffectSearch, inputs: EffectInputs, pool: Sequence[Effect], counter: Counter) -> Found:
    """Run the loop of the module docstring from the fit without effects."""
    objective, solution = search.fit([])
    start_x = solution.x
    adopted: list[Effect] = []
    steps: list[EffectStep] = []
    ranking: tuple[EffectCandidate, ...] = ()
    notes: list[str] = []
    while len(adopted) < MAX_EFFECTS:
        # the current model's errors at the scales its residual is whitened with: the step's "before"
        before, turns_before = search.errors(objective, solution.x), search.turns(objective, solution.x)
        floor = search.reproduced(before, turns_before, len(adopted))
        if floor:
            notes.append(floor)
            break
        chosen, ranking, alike = _step(search, inputs, (objective, solution), adopted, pool, counter)
        if chosen is None:
            break
        if alike:
            notes.append(alike)
        effect, new_objective, new_solution, delta = chosen
        # refitted at the noise scale of its residual (maximum likelihood; with a prior, eq P2), as the single
        # chain's adoption does: a scale the unmodelled effect inflated weighs the prior on the geometry too
        # strongly against the rows, and what it held would be left for the next candidates to imitate
        rescaled = search.rescaled(new_objective, new_solution)
        try:
            new_objective, new_solution = rescaled.fit([*adopted, effect], new_solution.x)
        except CalibrationError as error:  # sparse data: with the scale re-estimated it is not determined
            notes.append(f"{effect.label} not adopted: its refit with the noise re-estimated fails ({error}); the "
                         "search stops here")
            break
        search = rescaled  # kept only with the refit it weighs: the final errors are un-whitened at its scales
        values = new_solution.x[new_objective.effect_slices[-1]]
        std = standard_deviations(new_objective, new_solution)[new_objective.effect_slices[-1]]
        steps.append(EffectStep(effect, values, std, delta, before,
                                search.errors(new_objective, new_solution.x),
                                search.held_errors(adopted, solution.x), search.held_errors([*adopted, effect],
                                                                                            new_solution.x),
                                ranking, _pair(turns_before, search.turns(new_objective, new_solution.x)),
                                _pair(search.held_turns(adopted, solution.x),
                                      search.held_turns([*adopted, effect], new_solution.x))))
        adopted.append(effect)
        objective, solution = new_objective, new_solution
    return Found(search, objective, solution, tuple(adopted), tuple(steps), ranking, tuple(notes), start_x)


def _step(search: EffectSearch, inputs: EffectInputs, current: tuple[FitObjective, Solution], adopted: list[Effect],
          pool: Sequence[Effect], counter: Counter
          ) -> tuple[tuple[Effect, FitObjective, Solution, float] | None, tuple[EffectCandidate, ...], str]:
    """One step: screen every candidate not adopted, fit the shortlist in full, judge them best first; the one
    adopted (its fit and ΔBIC) or None, the ranking, and the candidates that correct alike in words (empty
    without, :func:`_alike`)."""
    objective, solution = current
    now = bic(solution.residual, solution.x.size, n_prior_rows(objective))
    freedom = residual_freedom(objective, solution)
    offered = [e for e in pool if e not in adopted and testable(freedom, e.n_values, EVIDENCE)]
    if not offered:
        return None, (), ""
    scores = Linearisation(solution, n_prior_rows(objective)).test(objective.effect_columns(solution.x, offered), now)
    screened = sorted(zip(offered, scores), key=lambda item: item[1].delta_bic)
    shortlist = [e for e, score in screened[:SHORTLIST] if may_reach(score.delta_bic, EVIDENCE)]
    counter.expect(len(shortlist) + 1)
    fitted = []
    failed: list[EffectCandidate] = []
    for effect in shortlist:
        counter.tick()
        try:
            new_objective, new_solution = search.fit([*adopted, effect], np.r_[solution.x, np.zeros(effect.n_values)])
        except CalibrationError as error:  # the rows do not determine it beside the geometry: reported, not adopted
            failed.append(EffectCandidate(effect, np.inf, np.zeros(effect.n_values), f"its fit fails ({error})"))
            continue
        fitted.append((bic(new_solution.residual, new_solution.x.size, n_prior_rows(new_objective)) - now, effect,
                       new_objective, new_solution))
    fitted.sort(key=lambda item: item[0])
    chosen = None
    ranking = []
    for delta, effect, new_objective, new_solution in fitted:
        values = new_solution.x[new_objective.effect_slices[-1]]
        verdict = NOT_JUDGED if chosen is not None else _verdict(
            search, inputs, effect, (delta, adopted), (new_objective, new_solution), solution.x)
        ranking.append(EffectCandidate(effect, float(delta), values, verdict))
        if verdict == "adopted":
            chosen = (effect, new_objective, new_solution, float(delta))
    alike = ""
    if chosen is not None:
        fits = {effect: (obj, sol) for _, effect, obj, sol in fitted}
        ranking, alike = _alike(search, inputs, (chosen, fits), ranking, (adopted, solution.x))
    ranking += failed
    ranking += [EffectCandidate(e, s.delta_bic, np.zeros(e.n_values), "screened out", screened=True)
                for e, s in screened if e not in shortlist][: max(0, SHORTLIST - len(ranking))]
    counter.tick()
    return chosen, tuple(ranking), alike


def _changes(objective: FitObjective, solution: Solution) -> np.ndarray:
    """What the last effect of a fit changes in the measured coordinates beyond what the fit's other unknowns can:
    its whitened Jacobian columns times its values on the data rows (not the prior's), less their least-squares
    part in the span of every other unknown's columns (the geometry takes that part in any fit)."""
    rows = solution.residual.size - n_prior_rows(objective)
    jacobian, sl = solution.jacobian[:rows], objective.effect_slices[-1]
    own = jacobian[:, sl] @ solution.x[sl]
    others = np.delete(jacobian, np.arange(sl.start, sl.stop), axis=1)
    return own - others @ np.linalg.lstsq(others, own, rcond=None)[0]


def _alike(search: EffectSearch, inputs: EffectInputs,
           step: tuple[tuple[Effect, FitObjective, Solution, float], dict[Effect, tuple[FitObjective, Solution]]],
           ranking: list[EffectCandidate], before: tuple[list[Effect], np.ndarray]
           ) -> tuple[list[EffectCandidate], str]:
    """The ranking with each candidate fitted after the adopted one that corrects alike (module docstring) given
    that verdict, and the group in words (:func:`pincal.diagnosis.ambiguity.ambiguity_words`; empty without one);
    ``before``: the effects adopted before the step and the current fit's unknowns."""
    (taken, objective, solution, delta), fits = step
    change = _changes(objective, solution)
    out, others = [], []
    for candidate in ranking:
        if candidate.verdict == NOT_JUDGED and candidate.delta_bic - delta <= ALIKE_WINDOW:
            fit = fits[candidate.effect]
            other = _changes(*fit)
            cosine = float(change @ other / max(np.linalg.norm(change) * np.linalg.norm(other), np.finfo(float).tiny))
            if abs(cosine) > AMBIGUOUS and _verdict(search, inputs, candidate.effect, (candidate.delta_bic, before[0]),
                                                    fit, before[1]) == "adopted":
                others.append(candidate.effect)
                candidate = replace(candidate, verdict=(
                    f"{taken.label} corrects the same poses the same way (changes correlated {cosine:+.2f}): these "
                    f"poses cannot tell them apart, and {taken.label} is preferred (the best ΔBIC)"))
        out.append(candidate)
    return out, ambiguity_words(taken, others, "the best ΔBIC") if others else ""


def _verdict(search: EffectSearch, inputs: EffectInputs, effect: Effect, evidence: tuple[float, Sequence[Effect]],
             fit: tuple[FitObjective, Solution], x_before: np.ndarray) -> str:
    """``adopted``, or why not, by the single chain's rules (module docstring)."""
    delta, adopted = evidence
    objective, solution = fit
    body = search.body()
    values = solution.x[objective.effect_slices[-1]]
    if delta >= EVIDENCE:
        return f"ΔBIC {delta:.1f} not below {EVIDENCE:g}"
    wald = _wald(objective, solution)
    if wald < float(scipy.stats.chi2.ppf(DETERMINED_LEVEL, values.size)):  # one value: |v| < 2σ
        return (f"its value {np.round(values, 6).tolist()} is not {DETERMINED_Z:g} standard deviations from zero "
                f"(Wald χ² {wald:.3g} over {values.size} value(s)): its ΔBIC is gained by the geometry it frees, not "
                "by a value the rows determine")
    if not plausible(effect, values, body):
        return f"its value {np.round(values, 6).tolist()} is outside the physical range (a stand-in for something else)"
    sl = objective.effect_slices[-1]
    largest = float(np.max(np.abs(objective.jacobian(solution.x)[: solution.residual.size - n_prior_rows(objective),
                                                                 sl] @ values), initial=0.0)) / search.row_noise()
    if largest < NEGLIGIBLE:  # the residual's columns times the values, in noise units
        return f"it changes no measured coordinate by more than {largest:.2g} of its noise: too small to matter"
    if effect.type != "coupling" and offset_like(effect_basis(effect, inputs, body)):
        return "its basis barely changes over the rows, so it acts as a joint offset"
    before, after = search.held_errors(adopted, x_before), search.held_errors([*adopted, effect], solution.x)
    if before is None or after is None:
        return "adopted"
    return search.held_verdict(before, after, fit, ((adopted, x_before), ([*adopted, effect], solution.x)))


def _wald(objective: FitObjective, solution: Solution) -> float:
    """Wald's statistic vᵀ C⁻¹ v of the last effect's values v, C their covariance: the posterior's under a prior
    (:func:`pincal.fit.prior.posterior`), else the solver's s² (JᵀJ)⁻¹ (:func:`pincal.fit.solver.solve`)."""
    jacobian, residual, sl = solution.jacobian, solution.residual, objective.effect_slices[-1]
    if isinstance(objective, PriorResidual):
        covariance, _ = posterior(jacobian, residual, objective.n_prior, objective.noise)
    else:
        covariance = float(residual @ residual) / max(jacobian.shape[0] - jacobian.shape[1], 1) * np.linalg.inv(
            gram(jacobian))
    values = solution.x[sl]
    return float(values @ np.linalg.lstsq(covariance[sl, sl], values, rcond=None)[0])
