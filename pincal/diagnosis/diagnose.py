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

Each step of the loop — screen, fit candidate, judge, adopt, refit — is a function of values returning new ones
(:mod:`pincal.diagnosis.steps`); this module prepares a pass of the search, runs its steps, and concludes it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from pincal.diagnosis.catalogue import PARALLEL_AXES_RAD, candidate_effects, parallel_neighbours
from pincal.diagnosis.conditions import ConditionSearch, Readings, search_conditions
from pincal.diagnosis.conventions import ConventionTrial, mimic_words, read_against_words
from pincal.diagnosis.effect_fits import EffectModel, heldout_errors, pose_errors_of
from pincal.diagnosis.moment_candidates import NO_TORQUE, masses_unknown, testable_pool
from pincal.diagnosis.screening import GENERIC_NOT_RUN, FitObjective, bic, n_prior_rows, residual_freedom, testable
from pincal.diagnosis.steps import (
    CANDIDATE_TOLERANCE,
    GRAVITY_REFRESHES,
    NAMING_EVALUATIONS,
    Restart,
    Search,
    State,
    Step,
    placements_of,
    regravitated,
    search_step,
)
from pincal.diagnosis.structure import remaining_structure
from pincal.diagnosis.verdicts import EVIDENCE, SHOWN, Candidate, TargetChange, target_changes
from pincal.errors import CalibrationError, expect_value
from pincal.fit.chain_calibration import ChainCalibration, row_weights
from pincal.fit.metrics import PoseErrors
from pincal.fit.prior import standard_deviations
from pincal.fit.sessions import session_rows
from pincal.fit.solver import solve
from pincal.measurements.couplings import ReadingCoupling, apply_couplings
from pincal.measurements.data import MeasurementSet
from pincal.model.chain import KinematicChain
from pincal.model.effects import BEND_EFFECTS, HARMONICS, Effect, EffectInputs, RowContext, effect_inputs, with_loads
from pincal.model.masses import Masses
from pincal.progress import Counter, Progress

__all__ = [
    "MAX_EFFECTS", "GRAVITY_REFRESHES", "CANDIDATE_TOLERANCE", "PARALLEL_AXES_RAD", "Step", "Diagnosis",
    "parallel_neighbours", "candidate_effects", "DiagnoseOptions", "diagnose",
    "NO_TORQUE", "NAMING_EVALUATIONS", "Recalibration",
]

#: Most effects adopted.
MAX_EFFECTS = 4

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
    objective: FitObjective
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


@dataclass(frozen=True)
class DiagnoseOptions:
    """What the caller of :func:`diagnose` fixes for the whole search, besides the chain and the rows.

    Attributes:
        sigma_column: the row-weight column used by the calibration.
        payload_kg: point mass at the target for gravity torques [kg].
        time / heldout_time: row times [s] of the calibration / held-out rows, or None.
        candidates: effects to try (None: :func:`candidate_effects`; thermal and pause steps where allowed).
        readings: the rows' temperatures and the pause rule (default: no temperature, pauses of 1800 s).
        recalibrate: the geometric calibration of rows as the given calibration was made (its level, selection,
            weights), to test a coupling as a joint read against another (:mod:`pincal.diagnosis.conventions`);
            None: such a coupling stays an effect, its advice naming ``--coupling``.
        couplings: the couplings the rows were corrected by (``--coupling``): their joints are not corrected again.
        stated_sigma_pos_m: the sensor's position noise per axis [m] when stated (``--sigma-pos``): the scale
            of the held-out test (:meth:`pincal.diagnosis.verdicts.Judge.judged_noise`).
        masses: ``urdf``: gravity torques of the URDF's inertias; ``unknown``: compliances follow the carried links'
            mass moments (:mod:`pincal.diagnosis.moment_candidates`), as they do with ``urdf`` on a URDF without
            inertias and no payload.
        lateral: the default candidates include each revolute joint's lateral (bending) compliance
            (:mod:`pincal.model.lateral`; ``diagnose --lateral``).
    """

    sigma_column: str | None = None
    payload_kg: float = 0.0
    time: np.ndarray | None = field(default=None, compare=False)
    heldout_time: np.ndarray | None = field(default=None, compare=False)
    candidates: Sequence[Effect] | None = None
    readings: Readings = field(default_factory=Readings)
    recalibrate: Callable[[MeasurementSet], ChainCalibration] | None = None
    couplings: Sequence[ReadingCoupling] = ()
    stated_sigma_pos_m: float | None = None
    masses: Masses = "urdf"
    lateral: bool = False


def diagnose(
    chain: KinematicChain,
    calibration: ChainCalibration,
    data: MeasurementSet,
    heldout: MeasurementSet | None = None,
    options: DiagnoseOptions | None = None,
    progress: Progress | None = None,
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
        options: the row weights, payload, times, candidates, readings, recalibration, couplings and stated
            noise (:class:`DiagnoseOptions`; None: its defaults).
        progress: ``progress(done, total)`` (:mod:`pincal.progress`): each step counts
            one unit per candidate offered (refitted or screened out) and one for
            adopting the best; the final fit and the search for remaining structure one.
    """
    options = DiagnoseOptions() if options is None else options
    expect_value(options, DiagnoseOptions, "diagnose")
    candidates = options.candidates
    if candidates is None:  # on the nominal geometry: which axes are parallel is the design's (drift: with a time)
        candidates = candidate_effects(chain, True, options.lateral)
    nominal, counter = chain.placements(), Counter(progress)
    settings = replace(options, candidates=tuple(candidates))
    recalibrate, couplings, time, heldout_time = (options.recalibrate, options.couplings, options.time,
                                                  options.heldout_time)
    applied: tuple[ReadingCoupling, ...] = ()
    earlier: tuple[Step, ...] = ()
    while True:
        trial = None if recalibrate is None else Recalibration(chain, nominal, recalibrate, data, heldout)
        corrected = frozenset(name for c in (*couplings, *applied) for name in (c.joint, c.driver))
        with chain.placed(calibration.chain_placements):  # gravity torques at the calibrated geometry
            search, state = _prepare(chain, calibration, (data, heldout), (time, heldout_time), settings, trial,
                                     corrected, earlier)
            outcome = _run(search, state, counter)
        if isinstance(outcome, Diagnosis):
            return replace(outcome, calibration=calibration, couplings=applied)
        applied = (*applied, outcome.trial.coupling)
        calibration, data, heldout, earlier = (outcome.trial.calibration, outcome.trial.data, outcome.trial.heldout,
                                               outcome.steps)


@dataclass(frozen=True)
class Recalibration:
    """A coupling tried as a joint read against another: ``data`` and ``heldout`` corrected by it, the geometry
    calibrated again on them by ``recalibrate`` as at the start, from the ``nominal`` placements."""

    chain: KinematicChain
    nominal: Sequence[np.ndarray]
    recalibrate: Callable[[MeasurementSet], ChainCalibration]
    data: MeasurementSet
    heldout: MeasurementSet | None

    def __call__(self, coupling: ReadingCoupling) -> ConventionTrial:
        rows = apply_couplings(self.data, [coupling])
        held = None if self.heldout is None else apply_couplings(self.heldout, [coupling])
        with self.chain.placed(self.nominal):  # calibrated as at the start: from the nominal geometry
            return ConventionTrial(coupling, self.recalibrate(rows), rows, held)


def _prepare(chain: KinematicChain, calibration: ChainCalibration,
             sets: tuple[MeasurementSet, MeasurementSet | None], times: tuple[np.ndarray | None, np.ndarray | None],
             settings: DiagnoseOptions, trial: Callable[[ReadingCoupling], ConventionTrial] | None,
             corrected: frozenset[str], earlier: tuple[Step, ...]) -> tuple[Search, State]:
    """One pass's search and its start: the calibration rows of ``sets`` (calibration, held-out rows) and
    ``times`` [s], their effect inputs and conditions, the candidates that can be tested, the model of
    ``calibration`` fitted with no effect (``earlier``: the steps of passes before)."""
    data, heldout = sets
    time, heldout_time = times
    payload_kg, readings = settings.payload_kg, settings.readings
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
                           context=None if heldout is None or heldout_time is None
                           else RowContext(heldout.q, heldout_time))
    names = np.asarray(calibration.session_names, dtype=object)  # each row's session, for its pauses
    row_names = names[session_rows(rows, calibration.session_names)]
    conditions = search_conditions(row_time, row_names, readings, calibration.used_index)
    inputs = conditions.inputs(inputs, conditions.temperature, row_time, row_names)
    unknown = masses_unknown(chain, settings.masses, payload_kg)
    inputs = with_loads(inputs, chain) if unknown else inputs  # the loads per mass moment (eq M1-M2)
    model = EffectModel.of(chain, calibration, rows, row_weights(rows, settings.sigma_column), inputs)
    held_inputs = None
    if heldout is not None:  # rows of both sets interleaved in time share their approach flanks
        held_inputs = effect_inputs(chain, heldout, payload_kg, point, heldout_time, reference,
                                    None if row_time is None else RowContext(
                                        rows.q, row_time,
                                        held_sessions=(session_rows(heldout, calibration.session_names),  # as evaluate
                                                       session_rows(rows, calibration.session_names))))
        held_inputs = conditions.inputs(held_inputs, readings.heldout_temperature, heldout_time,
                                        names[session_rows(heldout, calibration.session_names)])
        held_inputs = with_loads(held_inputs, chain) if unknown else held_inputs
    pool = list(settings.candidates or ())
    if row_time is None:
        pool = [e for e in pool if e.type != "drift"]
    pool += [e for e in conditions.candidates if e not in pool]
    pool, untestable = testable_pool(pool, inputs, chain, unknown)
    search = Search(chain, calibration, rows, heldout, tuple(pool),
                    tuple(untestable), settings.sigma_column, payload_kg, point, settings.stated_sigma_pos_m, trial,
                    corrected, conditions, reference, unknown,
                    frozenset(c.joint for c in settings.couplings if c.follows))
    objective, solution = model.fit([], calibration.solution, [])
    return search, State(model, held_inputs, objective, solution,
                         bic(solution.residual, solution.x.size, n_prior_rows(objective)), steps=earlier)


def _run(search: Search, state: State, counter: Counter) -> Diagnosis | Restart:
    """The search's steps (:func:`pincal.diagnosis.steps.search_step`) until it stops or adopts
    :data:`MAX_EFFECTS`, then its conclusion; or a restart on readings a convention corrected."""
    while not state.done and len(state.adopted) < MAX_EFFECTS:
        outcome = search_step(search, state, counter)
        if isinstance(outcome, Restart):
            return outcome
        state = outcome
    return _conclude(search, state, counter)


def _conclude(search: Search, state: State, counter: Counter) -> Diagnosis:
    """The final fit of the adopted effects, what structure remains, and the notes of what was reported."""
    adopted, labels, model = list(state.adopted), {e.label for e in state.adopted}, state.model
    current_objective, calibration, chain, heldout = state.objective, search.calibration, search.chain, search.heldout
    notes = [read_against_words(s.convention) for s in state.steps if s.convention is not None]
    notes += [text for label, text in state.rejected if label not in labels]
    notes += state.remarks
    untestable = search.untestable
    if untestable and search.masses_unknown:
        notes.append(f"cannot be tested, {len(untestable)} candidate(s): the masses are unknown (--masses unknown, or "
                     "a URDF without inertias), and these need the URDF's gravity torques, or no mass moment loads "
                     f"their joint in any row (an axis along gravity): {', '.join(e.label for e in untestable)}")
    elif untestable:
        notes.append(f"cannot be tested, {len(untestable)} candidate(s): no gravity torque acts on their joints in "
                     "any row (an axis along gravity, or no mass beyond the joint in the URDF: give the links' "
                     f"inertias, or --payload-kg KG for the tool): {', '.join(e.label for e in untestable)}")
    rejected = {label for label, _ in state.rejected}
    untested = {label: d for label, d in state.untested if label not in rejected and label not in labels}
    if untested:
        notes.append(f"not tested, {len(untested)} candidate(s): the fit leaves {min(untested.values()):.1f} residual "
                     f"degrees of freedom, too few to test their values (noise alone would reach the evidence cut "
                     f"ΔBIC < {EVIDENCE:g}); add rows: {', '.join(untested)}")
    notes += search.conditions.notes
    if state.inseparable:
        inseparable = [e.label for e in search.pool if e.label in state.inseparable]
        notes.append(
            f"not separable from the calibrated geometry at this level (absorbed by it): {', '.join(inseparable)}"
        )
    counter.expect(1)
    final_solution = solve(current_objective, state.solution.x, what="final fit")
    final_std = standard_deviations(current_objective, final_solution)  # the posterior's under a prior
    effects = tuple(
        (e, final_solution.x[sl], final_std[sl]) for e, sl in zip(adopted, current_objective.effect_slices)
    )
    notes += [words for e, v, _ in effects if (words := mimic_words(e, float(v[0]), chain, search.flagged)) is not None]
    freedom = residual_freedom(current_objective, final_solution)
    unexplained = remaining_structure(model, adopted, current_objective, final_solution, chain, freedom)
    if unexplained is None and not testable(freedom, 1 + 2 * len(HARMONICS), EVIDENCE):
        notes.append(GENERIC_NOT_RUN)
    counter.settle()
    placements = placements_of(calibration, current_objective, final_solution.x)
    held_inputs, judged = state.held_inputs, current_objective
    if any(e.type in BEND_EFFECTS for e in adopted):  # the bending moments of the final geometry, as evaluate has them
        model, held_inputs = regravitated(search, model, held_inputs, placements)
        judged = model.problem(adopted).objective(calibration.kept, calibration.vector)
    return Diagnosis(
        effects=effects,
        steps=state.steps,
        last_candidates=state.ranking[:SHOWN],
        unexplained=unexplained,
        objective=current_objective,
        solution_x=final_solution.x,
        inputs=model.inputs,
        time_reference=search.time_reference,
        calibration_errors=pose_errors_of(judged, final_solution.x),
        heldout_errors=heldout_errors(model, judged, final_solution.x, heldout, held_inputs),
        solution_std=final_std,
        sigma_pos_m=model.sigma_pos,
        sigma_rot_rad=model.sigma_rot,
        notes=tuple(notes),
        chain_placements=tuple(placements),
        target_changes=tuple(target_changes(judged, final_solution.x)),
        conditions=search.conditions,
    )
