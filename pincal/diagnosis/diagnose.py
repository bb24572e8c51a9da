"""Close the loop: find in the residuals what the model lacks, add it, say what it gained.

After the geometric calibration (:func:`pincal.fit.chain_calibration.calibrate_chain`)
every candidate effect of :mod:`pincal.model.effects` — each type on each joint, both
backlash sources, both cyclic harmonics, drift when the data has a time column,
the sensor's scale, thermal expansion and a step per pause where the rows allow them
(:mod:`pincal.diagnosis.conditions`) — is fitted together with the geometry, registration and
target it would change. Candidates are ranked by the change of the Bayesian
information criterion on the calibration rows (Schwarz 1978),

    ΔBIC = m ln(RSS₁/RSS₀) + Δn ln(m),

with the noise scales held at the geometric calibration's estimates. The best
one is adopted when the evidence is very strong (ΔBIC < −10, Kass & Raftery
1995) and it is not one of the cases that fool a selection
(:mod:`pincal.diagnosis.verdicts`):

* a value outside physical range — a stand-in for something else;
* a basis that barely varies (e.g. sign(tau_j) constant on most rows): it acts
  as a joint offset, which the model already has;
* an effect too small to change any measured coordinate by a tenth of its noise;
* when held-out rows are given, an effect that does not make them better beyond their
  noise (a signed-rank test of the per-row change of their error that a few wild rows cannot decide).

Such cases are reported, not adopted. Candidates that correct the same poses the same way (a close
competitor with a strongly correlated basis, e.g. the approach flanks of two joints that always move
together, or two harmonics over a short range) are not refused: the one that predicts the held-out rows
best, or the simpler, is taken and the others named. A gross effect is fitted to the end: a fit given
a budget goes on while it gains (:mod:`pincal.diagnosis.effect_fits`), and a coupling nearer ±1 than 0 is
tried as a joint read against another — the readings corrected, the geometry calibrated again on them
(:mod:`pincal.diagnosis.conventions`). The loop repeats until nothing
significant remains; then a generic per-joint correction (polynomial and
harmonics of the joint angle) tests whether structure remains that no
candidate explains.

Screening. Each step first scores every candidate by the linearised fit
(:mod:`pincal.diagnosis.screening`: Gauss–Newton from the current solution, a
score test). Only candidates whose score could put them in what the step
reports or judges — the first eight, every one the adoption checks look at,
with a margin for the linearisation — and, at the first step, every nearly
inseparable one are refitted in full, from their Gauss–Newton step, so the
ranking, values and verdicts are those of the full fits (a nearly inseparable
one whose fit stops gaining before it converges counts as absorbed: chunks of
:data:`NAMING_EVALUATIONS`). All fits share one sensitivity model per set of free parameters.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import NamedTuple, cast

import numpy as np

from pincal.diagnosis.catalogue import PARALLEL_AXES_RAD, candidate_effects, parallel_neighbours
from pincal.diagnosis.conditions import ConditionSearch, Readings, search_conditions
from pincal.diagnosis.conventions import ConventionTrial, adopted_trial, convention_for, read_against_words
from pincal.diagnosis.effect_fits import EffectModel, heldout_errors, pose_errors_of
from pincal.diagnosis.screening import (
    GENERIC_NOT_RUN,
    SCREEN_CONDITION,
    SCREEN_INSEPARABLE,
    Score,
    bic,
    may_reach,
    n_prior_rows,
    residual_freedom,
    screen,
    testable,
)
from pincal.diagnosis.structure import partial_residual, remaining_structure
from pincal.diagnosis.verdicts import EVIDENCE, SHOWN, Candidate, Judge, TargetChange, target_changes
from pincal.errors import CalibrationError
from pincal.fit.chain_calibration import ChainCalibration, row_weights
from pincal.fit.metrics import PoseErrors
from pincal.fit.prior import standard_deviations
from pincal.fit.sessions import session_rows
from pincal.fit.solver import solve
from pincal.measurements.couplings import ReadingCoupling, apply_couplings
from pincal.measurements.data import MeasurementSet
from pincal.model.chain import KinematicChain
from pincal.model.effect_units import shift_unit
from pincal.model.effects import (
    HARMONICS,
    Effect,
    EffectInputs,
    effect_inputs,
)
from pincal.progress import Counter, Progress
from pincal.residuals.sensor import SensorResidual

__all__ = [
    "MAX_EFFECTS", "GRAVITY_REFRESHES", "CANDIDATE_TOLERANCE", "PARALLEL_AXES_RAD", "Step", "Diagnosis",
    "parallel_neighbours", "candidate_effects", "diagnose",
    "NO_TORQUE", "NAMING_EVALUATIONS",
]

#: Most effects adopted.
MAX_EFFECTS = 4
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
#: Largest |gravity torque| [N·m or N] of a joint over the rows below which it has none: compliance and
#: gravity-flank backlash cannot be tested there (rounding of Pinocchio's RNEA is ~1e-12).
NO_TORQUE = 1e-9

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
class Diagnosis:
    """Outcome of :func:`diagnose`.

    Attributes:
        effects: adopted effects with their values and standard deviations.
        steps: one per adopted effect.
        last_candidates: the ranking of the step that adopted nothing.
        unexplained: a plain statement of remaining structure, or None.
        objective / solution: the final fit (for writing the URDF and report).
        inputs: effect inputs of the calibration rows; ``time_reference`` [s].
        notes: cases reported rather than adopted, and other remarks.
        chain_placements: the final model's chain placements (the geometry refitted with the
            effects; 4×4 each, as :meth:`pincal.model.chain.KinematicChain.placements`).
        target_changes: how far each of ``effects`` moves the target over the calibration rows.
        conditions: the temperature range and pauses of the fitted rows (thermal, pause steps).
        calibration: the geometric calibration the final model grew from: the one given, or the one
            calibrated again on readings corrected by ``couplings``.
        couplings: the joints found read against another, applied to the readings (eq C1 of
            :mod:`pincal.measurements.couplings`; REPORT.json's ``couplings``, as ``--coupling``).
    """

    effects: tuple[tuple[Effect, np.ndarray, np.ndarray], ...]
    steps: tuple[Step, ...]
    last_candidates: tuple[Candidate, ...]
    unexplained: str | None
    objective: SensorResidual
    solution_x: np.ndarray
    inputs: EffectInputs
    time_reference: float | None
    calibration_errors: PoseErrors
    heldout_errors: PoseErrors | None
    solution_std: np.ndarray = field(default_factory=lambda: np.array([]))
    sigma_pos_m: float = float("nan")
    sigma_rot_rad: float | None = None
    notes: tuple[str, ...] = field(default=())
    chain_placements: tuple[np.ndarray, ...] = ()
    target_changes: tuple[TargetChange, ...] = ()
    conditions: ConditionSearch | None = None
    calibration: ChainCalibration | None = None
    couplings: tuple[ReadingCoupling, ...] = ()

    def final_calibration(self) -> ChainCalibration:
        """The final model as a calibration of ``calibration``'s parameters: the geometry, target, their standard
        deviations, noise scales and fit of the final fit (its effects in ``effects``)."""
        assert self.calibration is not None  # diagnose sets it
        calibration, objective, x = self.calibration, self.objective, self.solution_x
        kinematic = objective.blocks["kinematic"]
        vector, std = calibration.vector.copy(), np.full(calibration.vector.size, np.nan)
        vector[calibration.kept], std[calibration.kept] = x[kinematic], self.solution_std[kinematic]
        return replace(calibration, vector=vector, std=std, target=objective.estimate(x),
                       target_std=self.solution_std[kinematic.stop : objective.blocks["effects"].start],
                       sigma_pos_m=self.sigma_pos_m, sigma_rot_rad=self.sigma_rot_rad,
                       rms_m=float(np.sqrt(np.mean(self.calibration_errors.position_m**2))),
                       chain_placements=self.chain_placements)


class _Restart(NamedTuple):
    """A convention adopted at a step: the search goes on from its trial (the corrected rows, the geometry
    calibrated again), the steps so far ending with its own."""

    trial: ConventionTrial
    steps: tuple[Step, ...]


def diagnose(
    chain: KinematicChain,
    calibration: ChainCalibration,
    data: MeasurementSet,
    heldout: MeasurementSet | None = None,
    sigma_column: str | None = None,
    payload_kg: float = 0.0,
    time: np.ndarray | None = None,
    heldout_time: np.ndarray | None = None,
    candidates: Sequence[Effect] | None = None,
    progress: Progress | None = None,
    readings: Readings | None = None,
    recalibrate: Callable[[MeasurementSet], ChainCalibration] | None = None,
    couplings: Sequence[ReadingCoupling] = (),
    stated_sigma_pos_m: float | None = None,
) -> Diagnosis:
    """Search the calibrated model's residuals for missing effects (module docstring).

    The chain is not changed (the search evaluates it at ``calibration.chain_placements``); the final
    model is the result's ``chain_placements``.

    Args:
        chain: the chain the calibration was made on.
        calibration: its result (:func:`calibrate_chain`).
        data: the measurement set it was calibrated on.
        heldout: held-out rows to report (and veto) on, in the registration of
            their calibrated session (the only one, or the one their ``session`` names).
        sigma_column: the row-weight column used by the calibration.
        payload_kg: point mass at the target for gravity torques [kg].
        time / heldout_time: row times [s] of ``data`` / ``heldout``, or None.
        candidates: effects to try (default: :func:`candidate_effects`; thermal and pause steps where allowed).
        progress: ``progress(done, total)`` (:mod:`pincal.progress`): each step counts
            one unit per candidate offered (refitted or screened out) and one for
            adopting the best; the final fit and the search for remaining structure one.
        readings: the rows' temperatures and the pause rule (default: no temperature, pauses of 1800 s).
        recalibrate: the geometric calibration of rows as ``calibration`` was made (its level, selection,
            weights), to test a coupling as a joint read against another (:mod:`pincal.diagnosis.conventions`);
            None: such a coupling stays an effect, its advice naming ``--coupling``.
        couplings: the couplings ``data`` and ``heldout`` were corrected by (``--coupling``): their joints
            are not corrected again.
        stated_sigma_pos_m: the sensor's position noise per axis [m] when stated (``--sigma-pos``): the scale
            of the held-out test (:meth:`pincal.diagnosis.verdicts.Judge.judged_noise`).
    """
    if candidates is None:  # on the nominal geometry: which axes are parallel is the design's (drift: with a time)
        candidates = candidate_effects(chain, True)
    nominal, counter = chain.placements(), Counter(progress)
    applied: list[ReadingCoupling] = []
    earlier: tuple[Step, ...] = ()
    while True:
        corrected = {name for c in (*couplings, *applied) for name in (c.joint, c.driver)}

        def trial(coupling: ReadingCoupling, rows: MeasurementSet = data,
                  held: MeasurementSet | None = heldout) -> ConventionTrial:
            assert recalibrate is not None  # offered only with it
            rows, held = apply_couplings(rows, [coupling]), None if held is None else apply_couplings(held, [coupling])
            with chain.placed(nominal):  # calibrated as at the start: from the nominal geometry
                return ConventionTrial(coupling, recalibrate(rows), rows, held)

        with chain.placed(calibration.chain_placements):  # gravity torques at the calibrated geometry
            outcome = _diagnose(chain, calibration, data, heldout, sigma_column, payload_kg, time, heldout_time,
                                candidates, counter, readings or Readings(), None if recalibrate is None else trial,
                                corrected, earlier, stated_sigma_pos_m)
        if isinstance(outcome, Diagnosis):
            return replace(outcome, calibration=calibration, couplings=tuple(applied))
        applied.append(outcome.trial.coupling)
        calibration, data, heldout, earlier = (outcome.trial.calibration, outcome.trial.data, outcome.trial.heldout,
                                               outcome.steps)


def _diagnose(chain, calibration, data, heldout, sigma_column, payload_kg, time, heldout_time, candidates,
              counter, readings, trial, corrected, earlier, stated_pos) -> Diagnosis | _Restart:
    rows = data.select(calibration.used_index)
    row_time = None if time is None else time[calibration.used_index]
    if heldout is not None:  # its rows need a calibrated session's registration
        session_rows(heldout, calibration.session_names)
    points = calibration.target.points
    point = points.mean(axis=0)
    reference = None if row_time is None else float(np.mean(row_time))
    if heldout is not None and (heldout.n_points != rows.n_points or heldout.has_orientation != rows.has_orientation):
        raise CalibrationError(
            f"{heldout.source}: the held-out rows must measure the same target as the calibration rows "
            f"({rows.n_points} point(s){' and orientations' if rows.has_orientation else ''}); "
            f"they have {heldout.n_points} point(s){' and orientations' if heldout.has_orientation else ''}"
        )
    inputs = effect_inputs(chain, rows, payload_kg, point, row_time,
                           context_q=None if heldout is None else heldout.q, context_time=heldout_time)
    names = np.asarray(calibration.session_names, dtype=object)  # each row's session, for its pauses
    row_names = names[session_rows(rows, calibration.session_names)]
    conditions = search_conditions(row_time, row_names, readings, calibration.used_index)
    inputs = conditions.inputs(inputs, conditions.temperature, row_time, row_names)
    model = EffectModel.of(chain, calibration, rows, row_weights(rows, sigma_column), inputs)
    held_inputs = None
    if heldout is not None:  # rows of both sets interleaved in time share their approach flanks
        held_inputs = effect_inputs(chain, heldout, payload_kg, point, heldout_time, reference, rows.q, row_time,
                                    held_sessions=(session_rows(heldout, calibration.session_names),  # as evaluate
                                                   session_rows(rows, calibration.session_names)))
        held_inputs = conditions.inputs(held_inputs, readings.heldout_temperature, heldout_time,
                                        names[session_rows(heldout, calibration.session_names)])
    pool = list(candidate_effects(chain, row_time is not None) if candidates is None else candidates)
    if row_time is None:
        pool = [e for e in pool if e.type != "drift"]
    pool += [e for e in conditions.candidates if e not in pool]
    # a joint no gravity torque acts on in any row (a vertical axis; a URDF without inertias): nothing to test
    weightless = {name for j, name in enumerate(chain.joint_names) if np.max(np.abs(inputs.gravity[:, j])) < NO_TORQUE}
    untestable = [e for e in pool if (e.type == "compliance" or e.source == "gravity")
                  and (e.driver or e.joint) in weightless]  # a torque coupling needs its driver's torque
    pool = [e for e in pool if e not in untestable]

    adopted: list[Effect] = []
    objective, solution = model.fit([], calibration.solution, [])
    current_x, current_bic = solution.x, bic(solution.residual, solution.x.size, n_prior_rows(objective))
    steps: list[Step] = list(earlier)
    notes: list[str] = [read_against_words(s.convention) for s in earlier if s.convention is not None]
    ranking: list[Candidate] = []
    inseparable: set[str] = set()
    rejected: dict[str, str] = {}
    untested: dict[str, float] = {}  # candidates too many for the residual degrees of freedom (_testable)
    current_objective, current_solution = objective, solution
    while len(adopted) < MAX_EFFECTS:
        offered = [e for e in pool if e not in adopted]
        if not offered:  # every candidate adopted (or none offered)
            break
        counter.expect(len(offered) + 1)
        step_end = counter.total
        screened = screen(current_objective, current_solution, offered, current_bic)
        fits: dict[Effect, tuple | None] = {}
        freedom = residual_freedom(current_objective, current_solution)

        def refit(effect: Effect, score: Score) -> None:
            # an effect the geometry absorbs is inseparable (below), whatever the freedom left
            if score.condition <= SCREEN_INSEPARABLE and not testable(freedom, effect.n_values, EVIDENCE):
                untested[effect.label] = freedom[1]
                counter.tick()
                fits[effect] = None
                return
            if score.condition > SCREEN_INSEPARABLE:
                sol = None
            else:
                start = current_x + score.step[: current_x.size]
                naming = score.condition > SCREEN_CONDITION  # a fit that tells whether the geometry absorbs it
                try:
                    obj, sol = model.fit(adopted + [effect], start[: current_objective.blocks["effects"].start],
                                         [start[sl] for sl in current_objective.effect_slices]
                                         + [score.step[current_x.size:]], tolerance=CANDIDATE_TOLERANCE,
                                         chunk=NAMING_EVALUATIONS if naming else None)
                except CalibrationError:
                    sol = None
                if naming and sol is not None and not sol.converged:  # it crawls: absorbed (NAMING_EVALUATIONS)
                    sol = None
            counter.tick()
            if sol is None:
                if not adopted:
                    inseparable.add(effect.label)
                fits[effect] = None
                return
            fits[effect] = (bic(sol.residual, sol.x.size, n_prior_rows(obj)) - current_bic, effect, obj, sol)

        held_errors = None if heldout is None else (
            lambda objective, x, held_inputs=held_inputs: cast(PoseErrors, heldout_errors(
                model, objective, x, heldout, held_inputs)))
        judge = Judge(inputs, chain, held_errors, current_objective, current_x, (model.sigma_pos, model.sigma_rot),
                      stated_pos, pool)
        if not adopted:  # name every candidate the geometry absorbs
            for effect, score in screened:
                if score.condition > SCREEN_CONDITION:
                    refit(effect, score)
        while True:
            tried = sorted((t for t in fits.values() if t is not None), key=lambda t: (t[0], pool.index(t[1])))
            if len(tried) < SHOWN and len(fits) < len(screened):  # refit the next best until eight are shown
                refit(*next((effect, score) for effect, score in screened if effect not in fits))
                continue
            ranking, chosen, step_rejected, cut = judge.rank(tried)
            pending = [(effect, score) for effect, score in screened
                       if effect not in fits and may_reach(score.delta_bic, cut)]
            if not pending:
                break
            for effect, score in pending:
                refit(effect, score)
        rejected.update(step_rejected)
        counter.tick(step_end - 1 - counter.done)  # the candidates the screen ruled out
        if chosen is None:
            break
        delta, effect, obj, sol = chosen
        before_cal = pose_errors_of(current_objective, current_x)
        before_held = heldout_errors(model, current_objective, current_x, heldout, held_inputs)
        driver, driver_label, joint_residual, fitted = partial_residual(effect, obj, sol, inputs, chain)
        unit = shift_unit(chain.joint_kinds.get(effect.joint or "") == "prismatic")
        coupling = None if trial is None else convention_for(effect, float(sol.x[obj.effect_slices[-1]][0]), corrected)
        try:
            found = None if coupling is None else adopted_trial(trial(coupling), chain, sigma_column, inputs,
                                                                held_inputs, (obj, sol), before_held, judge)
        except CalibrationError:  # the corrected rows cannot be calibrated: the coupling stays an effect
            found = None
        if found is not None:  # a joint read against another: the search goes on from the corrected readings
            counter.tick()
            convention, after_cal, after_held = found
            return _Restart(convention, (*steps, Step(
                effect, np.array([-convention.coupling.factor]), np.zeros(1), float(delta), before_cal, after_cal,
                before_held, after_held, tuple(ranking[:SHOWN]), driver, driver_label, joint_residual, fitted, unit,
                convention=convention.coupling)))
        adopted.append(effect)
        # noise scales re-estimated with the effect in the model (maximum likelihood)
        reestimated = model.reestimated(obj, sol)
        try:
            obj, sol = reestimated.fit(adopted, sol.x[: obj.blocks["effects"].start],
                                       [sol.x[sl] for sl in obj.effect_slices])
        except CalibrationError as error:  # sparse data: with the scales re-estimated it is not determined
            adopted.pop()
            rejected[effect.label] = (f"{effect.label} not adopted: its refit with the noise re-estimated "
                                      f"fails ({error}); the search stops here")
            ranking = [replace(c, verdict="refit failed, not adopted") if c.effect == effect else c for c in ranking]
            break
        model = reestimated
        if any(e.type == "compliance" or e.source == "gravity" for e in adopted):
            # gravity torques on the refitted geometry, not the one fitted without the effects
            for _ in range(GRAVITY_REFRESHES):
                refitted = calibration.chain_placements
                if calibration.params is not None:
                    vector = calibration.vector.copy()
                    vector[calibration.kept] = sol.x[obj.blocks["kinematic"]]
                    refitted = calibration.params.placements(vector)
                with chain.placed(refitted):
                    inputs = replace(inputs, gravity=effect_inputs(chain, rows, payload_kg, point).gravity)
                    if heldout is not None:
                        assert held_inputs is not None  # set with the held-out rows
                        held_inputs = replace(held_inputs,
                                              gravity=effect_inputs(chain, heldout, payload_kg, point).gravity)
                model = replace(model, inputs=inputs)
                obj, sol = model.fit(adopted, sol.x[: obj.blocks["effects"].start],
                                     [sol.x[sl] for sl in obj.effect_slices])
        current_objective, current_solution, current_x = obj, sol, sol.x
        current_bic = bic(sol.residual, sol.x.size, n_prior_rows(obj))
        counter.tick()
        steps.append(Step(
            effect=effect, values=sol.x[obj.effect_slices[-1]],
            std=standard_deviations(obj, sol)[obj.effect_slices[-1]],
            delta_bic=float(delta), calibration_before=before_cal, calibration_after=pose_errors_of(obj, sol.x),
            heldout_before=before_held,
            heldout_after=heldout_errors(model, obj, sol.x, heldout, held_inputs),
            candidates=tuple(ranking[:SHOWN]),
            driver=driver, driver_label=driver_label, joint_residual=joint_residual, fitted_shift=fitted,
            shift_unit=unit,
        ))
    notes += [text for label, text in rejected.items() if label not in {e.label for e in adopted}]
    if untestable:
        notes.append(f"cannot be tested, {len(untestable)} candidate(s): no gravity torque acts on their joints in "
                     "any row (an axis along gravity, or no mass beyond the joint in the URDF: give the links' "
                     f"inertias, or --payload-kg KG for the tool): {', '.join(e.label for e in untestable)}")
    untested = {label: d for label, d in untested.items()
                if label not in rejected and label not in {e.label for e in adopted}}
    if untested:
        notes.append(f"not tested, {len(untested)} candidate(s): the fit leaves {min(untested.values()):.1f} residual "
                     f"degrees of freedom, too few to test their values (noise alone would reach the evidence cut "
                     f"ΔBIC < {EVIDENCE:g}); add rows: {', '.join(untested)}")
    notes += conditions.notes
    if inseparable:
        labels = [e.label for e in pool if e.label in inseparable]
        notes.append(
            f"not separable from the calibrated geometry at this level (absorbed by it): {', '.join(labels)}"
        )
    counter.expect(1)
    final_solution = solve(current_objective, current_x, what="final fit")
    final_std = standard_deviations(current_objective, final_solution)  # the posterior's under a prior
    effects = tuple(
        (e, final_solution.x[sl], final_std[sl]) for e, sl in zip(adopted, current_objective.effect_slices)
    )
    freedom = residual_freedom(current_objective, final_solution)
    unexplained = remaining_structure(model, adopted, current_objective, final_solution, chain, freedom)
    if unexplained is None and not testable(freedom, 1 + 2 * len(HARMONICS), EVIDENCE):
        notes.append(GENERIC_NOT_RUN)
    counter.settle()
    final_placements = calibration.chain_placements
    if calibration.params is not None:
        vector = calibration.vector.copy()
        vector[calibration.kept] = final_solution.x[current_objective.blocks["kinematic"]]
        final_placements = tuple(calibration.params.placements(vector))
    return Diagnosis(
        effects=effects,
        steps=tuple(steps),
        last_candidates=tuple(ranking[:SHOWN]),
        unexplained=unexplained,
        objective=current_objective,
        solution_x=final_solution.x,
        inputs=inputs,
        time_reference=reference,
        calibration_errors=pose_errors_of(current_objective, final_solution.x),
        heldout_errors=heldout_errors(model, current_objective, final_solution.x, heldout, held_inputs),
        solution_std=final_std,
        sigma_pos_m=model.sigma_pos,
        sigma_rot_rad=model.sigma_rot,
        notes=tuple(notes),
        chain_placements=final_placements,
        target_changes=tuple(target_changes(current_objective, final_solution.x)),
        conditions=conditions,
    )
