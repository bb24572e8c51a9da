"""The steps of diagnose's search (:mod:`pincal.diagnosis.diagnose`), each a function of values returning new ones.

One pass of the search holds a :class:`Search` fixed (the rows, the candidates, how to try a convention) and
carries a :class:`State` from step to step (the model so far, its fit, what was adopted, reported, named). A step
of the search (:func:`search_step`) is:

* screen (:func:`screen_candidates`): every candidate not adopted yet scored by the linearised fit
  (:mod:`pincal.diagnosis.screening`);
* fit candidate (:func:`fit_candidate`): one candidate fitted in full beside the geometry, from its
  Gauss–Newton step (:class:`CandidateFit`), or why it is not (:class:`Trial`);
* judge (:func:`judge_candidates`): candidates fitted, best screened first, until the ranking, the verdicts and
  the one to adopt are those of the full fits (:class:`Judgement`, :class:`pincal.diagnosis.verdicts.Judge`);
* adopt (:func:`adopt`): the chosen effect's step recorded, or a convention it reveals restarting the search
  (:class:`Restart`);
* refit (:func:`refit`, :func:`refresh_gravity`): the model with the effect, its noise scales re-estimated and
  gravity torques recomputed on the refitted geometry (:class:`Refitted`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import NamedTuple, TypeVar, cast

import numpy as np

from pincal.diagnosis.conditions import ConditionSearch
from pincal.diagnosis.conventions import ConventionTrial, adopted_trial, convention_for, followers_of
from pincal.diagnosis.effect_fits import CandidateFit, EffectModel, heldout_errors, pose_errors_of
from pincal.diagnosis.reproduction import reproduced_note
from pincal.diagnosis.screening import (
    SCREEN_CONDITION,
    SCREEN_INSEPARABLE,
    FitObjective,
    Score,
    bic,
    may_reach,
    n_prior_rows,
    residual_freedom,
    screen,
    testable,
)
from pincal.diagnosis.structure import partial_residual
from pincal.diagnosis.verdicts import EVIDENCE, SHOWN, Candidate, Judge
from pincal.errors import CalibrationError
from pincal.fit.chain_calibration import ChainCalibration
from pincal.fit.metrics import PoseErrors
from pincal.fit.prior import standard_deviations
from pincal.fit.solver import Solution
from pincal.measurements.couplings import ReadingCoupling
from pincal.measurements.data import MeasurementSet
from pincal.model.chain import KinematicChain
from pincal.model.effect_units import shift_unit
from pincal.model.effects import BEND_EFFECTS, Effect, EffectInputs, effect_inputs, with_loads
from pincal.progress import Counter

__all__ = [
    "GRAVITY_REFRESHES", "CANDIDATE_TOLERANCE", "NAMING_EVALUATIONS", "Step", "CandidateFit", "Trial", "Search",
    "State", "Judgement", "Restart", "Refitted", "screen_candidates", "fit_candidate", "judge_candidates", "adopt",
    "refit", "refresh_gravity", "search_step", "placements_of", "judged", "drop_superseded", "gravity_driven",
    "regravitated",
]

#: Refits with gravity torques recomputed on the refitted geometry.
GRAVITY_REFRESHES = 2
#: Tolerance of a candidate's full fit (:func:`pincal.fit.solver.solve`): it ranks
#: and is judged; an adopted effect is refitted at the solver's own tolerance.
CANDIDATE_TOLERANCE = 1e-10
#: Evaluations of one chunk of the full fit of a candidate the screen finds nearly inseparable from the
#: geometry (condition number of [J, B] above :data:`pincal.diagnosis.screening.SCREEN_CONDITION`),
#: fitted to tell whether the geometry absorbs it. The fit goes on chunk by chunk while each chunk still
#: gains (:func:`pincal.diagnosis.effect_fits.fit_while_gaining`, eq F1): one that stops gaining before it
#: converges crawls along a valley the data do not determine (as
#: :data:`pincal.diagnosis.structure.GENERIC_EVALUATIONS`), and counts as absorbed: a cyclic term on
#: scripts/benchmark.py's UR5 wrist held at zero (sin q ≈ 0, cos q ≈ 1, its zero offset) ran 2 800
#: evaluations (150 s) to amplitudes of 3 and 20 rad without converging, gaining 1e-4 of BIC per chunk.
#: Naming fits that converge took at most 12 on such sessions of 300–2 500 rows, 8 on the README
#: commands; a coupling read against its driver, fitted from far, more than one chunk.
NAMING_EVALUATIONS = 50

V = TypeVar("V")


@dataclass(frozen=True)
class Step:
    """One adopted effect, with the errors before and after adding it; a joint effect's ``driver`` (its
    ``driver_label`` saying what it is), ``joint_residual`` and ``fitted_shift`` per row (the shifts in
    ``shift_unit``: rad, or m for a prismatic joint) for its plot. A coupling found to be a joint read against
    another has its ``convention``: applied to the readings (:mod:`pincal.diagnosis.conventions`), its value
    exactly ±1 (``std`` 0), ``calibration_after`` the geometry calibrated again on the corrected readings."""

    effect: Effect
    values: np.ndarray
    std: np.ndarray
    delta_bic: float
    calibration_before: PoseErrors
    calibration_after: PoseErrors
    heldout_before: PoseErrors | None
    heldout_after: PoseErrors | None
    candidates: tuple[Candidate, ...]
    driver: np.ndarray | None = None
    driver_label: str = ""
    joint_residual: np.ndarray | None = None
    fitted_shift: np.ndarray | None = None
    shift_unit: str = "rad"
    convention: ReadingCoupling | None = None


@dataclass(frozen=True)
class Trial:
    """What fitting a candidate gave: its ``fit``, or None — too many values for the residual degrees of freedom
    left (``untested``: those [-]), or ``inseparable``: the geometry absorbs it."""

    fit: CandidateFit | None
    untested: float | None = None
    inseparable: bool = False


@dataclass(frozen=True)
class Search:
    """What one pass of the search holds fixed: the chain (placed at the calibrated geometry), its calibration and
    calibration rows, the held-out rows, the candidates in the catalogue's order (``pool``; ``untestable``: those no
    gravity torque drives), the row-weight column, the payload [kg] at ``point`` (the target's mean, m), the
    stated position noise [m], ``trial``: the geometry calibrated again on rows corrected by a coupling (None:
    a coupling stays an effect), the joints already corrected, the row conditions and mean row time [s], and
    whether the masses are unknown (compliances follow mass moments, :mod:`pincal.diagnosis.moment_candidates`);
    ``flagged``: the joints a ``--coupling`` made follow their driver (not a URDF ``<mimic>``)."""

    chain: KinematicChain
    calibration: ChainCalibration
    rows: MeasurementSet
    heldout: MeasurementSet | None
    pool: tuple[Effect, ...]
    untestable: tuple[Effect, ...]
    sigma_column: str | None
    payload_kg: float
    point: np.ndarray
    stated_pos: float | None
    trial: Callable[[ReadingCoupling], ConventionTrial] | None
    corrected: frozenset[str]
    conditions: ConditionSearch
    time_reference: float | None
    masses_unknown: bool = False
    flagged: frozenset[str] = frozenset()


@dataclass(frozen=True)
class State:
    """The search between steps: the model (its noise scales and effect inputs; ``held_inputs`` those of the
    held-out rows), its fit (``objective`` at ``solution``, ``bic``), the effects adopted and their steps, the
    last step's ranking, the notes of candidates reported rather than adopted (by label, first-reported order),
    the labels the geometry absorbs, those not tested (with the residual degrees of freedom left), ``done`` once
    the search stops, and ``remarks``: why it stopped, where that is worth a note."""

    model: EffectModel
    held_inputs: EffectInputs | None
    objective: FitObjective
    solution: Solution
    bic: float
    adopted: tuple[Effect, ...] = ()
    steps: tuple[Step, ...] = ()
    ranking: tuple[Candidate, ...] = ()
    rejected: tuple[tuple[str, str], ...] = ()
    inseparable: frozenset[str] = frozenset()
    untested: tuple[tuple[str, float], ...] = ()
    done: bool = False
    dropped: frozenset[str] = frozenset()  # adopted, then dropped as superseded (:func:`drop_superseded`)
    remarks: tuple[str, ...] = ()


@dataclass(frozen=True)
class Judgement:
    """A step's judged candidates: each one fitted (its :class:`Trial`), the ranking shown, the one to adopt (or
    None), the notes of those reported rather than adopted, and the judge that decided (its noise scales)."""

    trials: Mapping[Effect, Trial]
    ranking: tuple[Candidate, ...]
    chosen: CandidateFit | None
    rejected: Mapping[str, str]
    judge: Judge = field(repr=False)


class Restart(NamedTuple):
    """A convention adopted at a step: the search goes on from its trial (the corrected rows, the geometry
    calibrated again), the steps so far ending with its own."""

    trial: ConventionTrial
    steps: tuple[Step, ...]


class Refitted(NamedTuple):
    """The model with an adopted effect: its noise scales re-estimated, effect inputs (and held-out ones), fit."""

    model: EffectModel
    held_inputs: EffectInputs | None
    objective: FitObjective
    solution: Solution


def screen_candidates(search: Search, state: State) -> tuple[tuple[Effect, Score], ...]:
    """Screen: each candidate not adopted yet with its linearised score test from the current fit, best first
    (:func:`pincal.diagnosis.screening.screen`); empty when none is left."""
    offered = [e for e in search.pool if e not in state.adopted and e.label not in state.dropped]
    return tuple(screen(state.objective, state.solution, offered, state.bic)) if offered else ()


def fit_candidate(state: State, effect: Effect, score: Score, freedom: tuple[int, float]) -> Trial:
    """Fit candidate: ``effect`` fitted with the adopted ones, geometry, registration and target, from the
    current fit plus its Gauss–Newton ``score.step``. Not fitted when too many values for the residual
    ``freedom`` (:func:`pincal.diagnosis.screening.testable`) — unless the geometry absorbs it: a fit beyond
    :data:`SCREEN_INSEPARABLE`, failing, or one past :data:`SCREEN_CONDITION` that crawls (chunks of
    :data:`NAMING_EVALUATIONS`) is inseparable."""
    if score.condition <= SCREEN_INSEPARABLE and not testable(freedom, effect.n_values, EVIDENCE):
        return Trial(None, untested=freedom[1])
    if score.condition > SCREEN_INSEPARABLE:
        return Trial(None, inseparable=True)
    x = state.solution.x
    start = x + score.step[: x.size]
    naming = score.condition > SCREEN_CONDITION  # a fit that tells whether the geometry absorbs it
    try:
        obj, sol = state.model.fit([*state.adopted, effect], start[: state.objective.blocks["effects"].start],
                                   [start[sl] for sl in state.objective.effect_slices] + [score.step[x.size:]],
                                   tolerance=CANDIDATE_TOLERANCE, chunk=NAMING_EVALUATIONS if naming else None)
    except CalibrationError:
        return Trial(None, inseparable=True)
    if naming and not sol.converged:  # it crawls: absorbed (NAMING_EVALUATIONS)
        return Trial(None, inseparable=True)
    return Trial(CandidateFit(bic(sol.residual, sol.x.size, n_prior_rows(obj)) - state.bic, effect, obj, sol))


def judge_candidates(search: Search, state: State, screened: tuple[tuple[Effect, Score], ...],
                     counter: Counter) -> Judgement:
    """Judge: at the first step every candidate the geometry may absorb fitted (to name it), then the best
    screened ones until eight are shown, and any whose score could still reach what the ranking shows or
    judges (:func:`pincal.diagnosis.screening.may_reach`); ranked, given verdicts, one chosen by a
    :class:`Judge` of the current model. One unit of ``counter`` per candidate fitted."""
    freedom = residual_freedom(state.objective, state.solution)
    model, held_inputs, heldout = state.model, state.held_inputs, search.heldout
    held_errors = None if heldout is None else (
        lambda objective, x: cast(PoseErrors, heldout_errors(model, objective, x, heldout, held_inputs)))
    judge = Judge(state.model.inputs, search.chain, held_errors, state.objective, state.solution.x,
                  (state.model.sigma_pos, state.model.sigma_rot), search.stated_pos, search.pool)
    # at the first step, name every candidate the geometry absorbs
    absorbed = () if state.adopted else tuple((e, s) for e, s in screened if s.condition > SCREEN_CONDITION)
    trials = _fitted({}, absorbed, state, freedom, counter)
    while True:
        fits = sorted((t.fit for t in trials.values() if t.fit is not None),
                      key=lambda f: (f.delta_bic, search.pool.index(f.effect)))
        if len(fits) < SHOWN and len(trials) < len(screened):  # fit the next best until eight are shown
            following = next((effect, score) for effect, score in screened if effect not in trials)
            trials = _fitted(trials, (following,), state, freedom, counter)
            continue
        ranking, chosen, rejected, cut = judge.rank(fits)
        pending = tuple((effect, score) for effect, score in screened
                        if effect not in trials and may_reach(score.delta_bic, cut))
        if not pending:
            return Judgement(trials, tuple(ranking), chosen, rejected, judge)
        trials = _fitted(trials, pending, state, freedom, counter)


def _fitted(trials: Mapping[Effect, Trial], candidates: tuple[tuple[Effect, Score], ...], state: State,
            freedom: tuple[int, float], counter: Counter) -> dict[Effect, Trial]:
    """``trials`` and each of ``candidates`` fitted (:func:`fit_candidate`), one unit of ``counter`` each."""
    out = dict(trials)
    for effect, score in candidates:
        out[effect] = fit_candidate(state, effect, score, freedom)
        counter.tick()
    return out


def judged(state: State, judgement: Judgement) -> State:
    """The state with a step's judgement: its ranking, notes, and the candidates it found absorbed (named at the
    first step only) or could not test."""
    inseparable = {e.label for e, t in judgement.trials.items() if t.inseparable} if not state.adopted else set()
    untested = {e.label: t.untested for e, t in judgement.trials.items() if t.untested is not None}
    return replace(state, ranking=judgement.ranking, rejected=_merged(state.rejected, judgement.rejected),
                   inseparable=state.inseparable | inseparable, untested=_merged(state.untested, untested))


def _merged(pairs: tuple[tuple[str, V], ...], update: Mapping[str, V]) -> tuple[tuple[str, V], ...]:
    """``pairs`` updated by ``update`` as a dict is: a label already there keeps its place, takes the new value."""
    return tuple({**dict(pairs), **update}.items())


def refit(state: State, fit: CandidateFit) -> Refitted:
    """Refit: the adopted effects and ``fit``'s refitted from its solution, at the noise scales re-estimated with
    it in the model (maximum likelihood). Raises :class:`CalibrationError` when that fit fails (sparse data)."""
    model = state.model.reestimated(fit.objective, fit.solution)
    obj, sol = model.fit([*state.adopted, fit.effect], fit.solution.x[: fit.objective.blocks["effects"].start],
                         [fit.solution.x[sl] for sl in fit.objective.effect_slices])
    return Refitted(model, state.held_inputs, obj, sol)


def placements_of(calibration: ChainCalibration, objective: FitObjective, x: np.ndarray) -> Sequence[np.ndarray]:
    """The chain placements (4×4 each) of the geometry of a fit of ``calibration``'s parameters at ``x``."""
    if calibration.params is None:
        return calibration.chain_placements
    vector = calibration.vector.copy()
    vector[calibration.kept] = x[objective.blocks["kinematic"]]
    return calibration.params.placements(vector)


def refresh_gravity(search: Search, refitted: Refitted, effects: list[Effect]) -> Refitted:
    """With a compliance or gravity-flank effect among ``effects``: gravity torques of the calibration (and
    held-out) rows recomputed on the refitted geometry, not the one fitted without the effects, and the model
    fitted again, :data:`GRAVITY_REFRESHES` times."""
    if not gravity_driven(effects):
        return refitted
    model, held_inputs, obj, sol = refitted
    for _ in range(GRAVITY_REFRESHES):
        model, held_inputs = regravitated(search, model, held_inputs, placements_of(search.calibration, obj, sol.x))
        obj, sol = model.fit(effects, sol.x[: obj.blocks["effects"].start], [sol.x[sl] for sl in obj.effect_slices])
    return Refitted(model, held_inputs, obj, sol)


def gravity_driven(effects: Sequence[Effect]) -> bool:
    """Whether some of ``effects`` follow the gravity loads (a compliance, a lateral one, a gravity flank)."""
    return any(e.type in ("compliance", "lateral") or e.source == "gravity" for e in effects)


def regravitated(search: Search, model: EffectModel, held_inputs: EffectInputs | None,
                 placements: Sequence[np.ndarray]) -> tuple[EffectModel, EffectInputs | None]:
    """``model`` and the held-out rows' inputs with the gravity loads (torques, bending moments, loads per mass
    moment) of the calibration and held-out rows recomputed on the geometry ``placements``."""
    chain, heldout, inputs = search.chain, search.heldout, model.inputs
    with chain.placed(placements):
        fresh = effect_inputs(chain, search.rows, search.payload_kg, search.point)
        inputs = replace(inputs, gravity=fresh.gravity, bending=fresh.bending)
        inputs = inputs if inputs.loads is None else with_loads(inputs, chain)
        if heldout is not None:
            assert held_inputs is not None  # set with the held-out rows
            fresh = effect_inputs(chain, heldout, search.payload_kg, search.point)
            held_inputs = replace(held_inputs, gravity=fresh.gravity, bending=fresh.bending)
            held_inputs = held_inputs if held_inputs.loads is None else with_loads(held_inputs, chain)
    return replace(model, inputs=inputs), held_inputs


def adopt(search: Search, state: State, judgement: Judgement, counter: Counter, before_cal: PoseErrors
          ) -> State | Restart:
    """Adopt: the chosen candidate's step — the errors before and after, its partial residual for the plot — and
    the state refitted with it (:func:`refit`); a coupling that is a joint read against another, adopted as a
    convention (:func:`pincal.diagnosis.conventions.adopted_trial`), restarts the search on the corrected rows.
    A refit that fails leaves the model as it was, the candidate reported, and stops the search. ``before_cal``:
    the calibration rows' errors of the state's fit (:func:`pincal.diagnosis.effect_fits.pose_errors_of`)."""
    assert judgement.chosen is not None  # adopt only what was chosen
    delta, effect, obj, sol = judgement.chosen
    chain, model, heldout, held_inputs = search.chain, state.model, search.heldout, state.held_inputs
    before_held = heldout_errors(model, state.objective, state.solution.x, heldout, held_inputs)
    driver, driver_label, joint_residual, fitted = partial_residual(effect, obj, sol, model.inputs, chain)
    unit = shift_unit(chain.joint_kinds.get(effect.joint or "") == "prismatic")
    shown = judgement.ranking[:SHOWN]
    coupling = None if search.trial is None else convention_for(effect, float(sol.x[obj.effect_slices[-1]][0]),
                                                                (*search.corrected, *followers_of(chain)))
    try:
        found = None if coupling is None or search.trial is None else adopted_trial(
            search.trial(coupling), chain, search.sigma_column, model.inputs, held_inputs, (obj, sol), before_held,
            judgement.judge)
    except CalibrationError:  # the corrected rows cannot be calibrated: the coupling stays an effect
        found = None
    if found is not None:  # a joint read against another: the search goes on from the corrected readings
        counter.tick()
        convention, after_cal, after_held = found
        return Restart(convention, (*state.steps, Step(
            effect, np.array([-convention.coupling.factor]), np.zeros(1), float(delta), before_cal, after_cal,
            before_held, after_held, shown, driver, driver_label, joint_residual, fitted, unit,
            convention=convention.coupling)))
    try:
        refitted = refit(state, judgement.chosen)
    except CalibrationError as error:  # sparse data: with the scales re-estimated it is not determined
        note = (f"{effect.label} not adopted: its refit with the noise re-estimated "
                f"fails ({error}); the search stops here")
        return replace(state, rejected=_merged(state.rejected, {effect.label: note}), done=True,
                       ranking=tuple(replace(c, verdict="refit failed, not adopted") if c.effect == effect else c
                                     for c in state.ranking))
    adopted = [*state.adopted, effect]
    model, held_inputs, obj, sol = refresh_gravity(search, refitted, adopted)
    counter.tick()
    step = Step(
        effect=effect, values=sol.x[obj.effect_slices[-1]],
        std=standard_deviations(obj, sol)[obj.effect_slices[-1]],
        delta_bic=float(delta), calibration_before=before_cal, calibration_after=pose_errors_of(obj, sol.x),
        heldout_before=before_held,
        heldout_after=heldout_errors(model, obj, sol.x, heldout, held_inputs),
        candidates=shown,
        driver=driver, driver_label=driver_label, joint_residual=joint_residual, fitted_shift=fitted,
        shift_unit=unit,
    )
    return drop_superseded(replace(state, model=model, held_inputs=held_inputs, objective=obj, solution=sol,
                                   bic=bic(sol.residual, sol.x.size, n_prior_rows(obj)), adopted=tuple(adopted),
                                   steps=(*state.steps, step)))


def drop_superseded(state: State) -> State:
    """Each lateral compliance adopted before the last effect refitted out: when the effects adopted after it
    explain what it did — keeping it no longer gains the evidence cut, BIC without it − BIC with it above
    :data:`EVIDENCE` (the backward step of stepwise selection, Efroymson 1960) — it is dropped and noted. Its
    deflection fits many load patterns at once (a function of every carried link's mass moments without masses),
    so a forward step can take it for two effects that are each a joint's own, adopted next."""
    for effect in state.adopted[:-1]:
        if effect.type not in BEND_EFFECTS:
            continue
        obj, sol = state.objective, state.solution
        kept = [(e, sol.x[sl]) for e, sl in zip(state.adopted, obj.effect_slices) if e != effect]
        try:
            new_obj, new_sol = state.model.fit([e for e, _ in kept], sol.x[: obj.blocks["effects"].start],
                                               [v for _, v in kept])
        except CalibrationError:  # the fit without it fails: it stays
            continue
        without = bic(new_sol.residual, new_sol.x.size, n_prior_rows(new_obj))
        if without - state.bic < -EVIDENCE:
            note = (f"{effect.label} dropped after {state.adopted[-1].label} was adopted: the effects adopted after it "
                    f"explain what it did (keeping it gains ΔBIC {state.bic - without:.1f}, not below {EVIDENCE:g})")
            state = replace(state, objective=new_obj, solution=new_sol, bic=without,
                            adopted=tuple(e for e, _ in kept), dropped=state.dropped | {effect.label},
                            rejected=_merged(state.rejected, {f"{effect.label}:dropped": note}))
    return state


def search_step(search: Search, state: State, counter: Counter) -> State | Restart:
    """One step of the search: screen, fit and judge the candidates, adopt the chosen one and refit (module
    docstring); ``done`` when none is offered or chosen. ``counter`` expects one unit per candidate offered
    (fitted or screened out) and one for adopting."""
    errors = pose_errors_of(state.objective, state.solution.x)  # the step's "before"
    floor = reproduced_note(errors.position_m, errors.rotation_rad, len(state.adopted))  # noise-free rows
    if floor:
        return replace(state, done=True, remarks=(*state.remarks, floor))
    screened = screen_candidates(search, state)
    if not screened:  # every candidate adopted (or none offered)
        return replace(state, done=True)
    counter.expect(len(screened) + 1)
    step_end = counter.total
    judgement = judge_candidates(search, state, screened, counter)
    counter.tick(step_end - 1 - counter.done)  # the candidates the screen ruled out
    state = judged(state, judgement)
    if judgement.chosen is None:
        return replace(state, done=True)
    return adopt(search, state, judgement, counter, errors)  # judged() keeps the fit: its errors are these
