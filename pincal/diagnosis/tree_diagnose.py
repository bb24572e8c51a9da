"""Close the loop on a tree: the effects the geometry of several targets lacks (``diagnose --tip-link A:1
--tip-link B:2``).

After the tree's geometric calibration (:func:`pincal.fit.tree_calibration.calibrate_tree`), every candidate
of the single chain's catalogue on every target's chain (:func:`pincal.diagnosis.catalogue.candidate_effects`,
a joint shared by several chains once; with ``lateral``, each revolute joint's lateral compliance too) is tested
on the tree's residual (:class:`pincal.residuals.tree.TreeResidual`): a joint effect shifts its joint's reading,
and a lateral compliance bends the chain at it, in every chain that has the joint, its load that of everything
the joint carries (:mod:`pincal.model.tree_effects`). Each step screens
every candidate by the linearised score test of :mod:`pincal.diagnosis.screening` at the current fit, fits
those that may reach the evidence cut in full (geometry, registrations, points and the effects together),
and adopts the best by the single chain's rules (:mod:`pincal.diagnosis.verdicts`):

    ΔBIC = m ln(RSS₁/RSS₀) + Δn ln(m) < EVIDENCE = −10      (Schwarz 1978; Kass & Raftery 1995)

on the calibration rows (m: their seen coordinates, and with a target's orientation measured its seen
orientations' 3 entries each; every entry whitened by its own noise scale, the positions' or the orientations',
the current model's, each re-estimated from its own entries after each adoption, as the tree's fit weighs them),
a value some :data:`DETERMINED_Z` standard deviations from zero, in physical range, a change of some measured
coordinate of at least NEGLIGIBLE × its noise, a basis that is not an offset, and with held-out rows better on
them beyond their noise (the signed-rank test of :func:`pincal.diagnosis.held_out.held_out_verdict`, on the
held-out points and orientations). The search stops when no candidate passes, or after
:data:`pincal.diagnosis.diagnose.MAX_EFFECTS`.

A candidate that passes too and corrects the same poses alike, within 6 of the adopted one's ΔBIC, is named beside
it (:mod:`pincal.diagnosis.effect_loop`); the adopted one is the best ΔBIC (the single chain's prefers the one that
predicts the held-out rows best). Not yet as with one chain: a coupling nearer ±1 tried as a joint read against
another (it stays an effect), thermal and pause steps, a payload, the generic check for remaining structure.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import cast

import numpy as np

from pincal.diagnosis.catalogue import candidate_effects
from pincal.diagnosis.diagnose import DiagnoseOptions
from pincal.diagnosis.effect_loop import (
    DETERMINED_LEVEL,
    DETERMINED_Z,
    SHORTLIST,
    EffectCandidate,
    EffectStep,
    Found,
    Model,
    search_effects,
)
from pincal.diagnosis.held_out import held_out_verdict
from pincal.diagnosis.moment_candidates import masses_unknown, testable_pool
from pincal.diagnosis.reproduction import reproduced_note
from pincal.diagnosis.screening import FitObjective
from pincal.diagnosis.verdicts import NOISE_FLOOR
from pincal.fit.chain_calibration import row_weights
from pincal.fit.metrics import PoseErrors
from pincal.fit.prior import PriorResidual, posterior, standard_deviations
from pincal.fit.sessions import session_rows
from pincal.fit.solver import Solution, gram, solve
from pincal.fit.tree_calibration import TreeCalibration, tree_rows
from pincal.fit.tree_problem import TreeProblem
from pincal.measurements.data import MeasurementSet
from pincal.model.chain import KinematicChain
from pincal.model.effects import Effect, EffectInputs
from pincal.model.tree import KinematicTree, TreePlacements
from pincal.model.tree_effects import TreeBody, tree_inputs
from pincal.progress import Counter, Progress
from pincal.residuals.sensor_values import ModelledEffects, TargetEstimate
from pincal.residuals.tree import TreeResidual, TreeRows

__all__ = ["SHORTLIST", "DETERMINED_Z", "DETERMINED_LEVEL", "TreeStep", "TreeCandidate", "TreeDiagnosis",
           "tree_candidates", "diagnose_tree"]

#: A candidate of a step and an adopted effect (the loop's, :mod:`pincal.diagnosis.effect_loop`).
TreeCandidate = EffectCandidate
TreeStep = EffectStep


@dataclass(frozen=True)
class TreeDiagnosis:
    """Outcome of :func:`diagnose_tree`.

    Attributes:
        effects: the adopted effects with their values and standard deviations.
        steps: one per adopted effect.
        last_candidates: the ranking of the step that adopted nothing (best first).
        untestable: the candidates the rows cannot test (no gravity torque on the joint; masses unknown).
        vector / std: every tree parameter [m, rad] of the final model, (n,) (NaN std where not estimated).
        target: the registrations and points of the final model.
        tree_placements: each target's chain placements of the final model.
        point_errors: the calibration rows' point errors of the final model (K, P) [m], NaN where not seen.
        heldout_before / heldout_after: the held-out rows' point errors (K_h, P) [m] of the geometric
            calibration and of the final model (None without held-out rows).
        heldout_turns: the held-out rows' orientation errors (K_h, T) [rad] of the geometric calibration and of
            the final model, NaN where not seen (None without held-out rows or without orientations).
        sigma_pos_m: the noise scale of the final model's residuals [m].
        orientation_errors: the calibration rows' orientation errors of the final model (K, T) [rad], NaN where not
            seen; None when no target's orientation is measured.
        sigma_rot_rad: the orientation noise scale of the final model's residuals [rad]; None without orientations.
        masses_unknown: compliances follow mass moments (``--masses unknown`` or no inertias).
        time_reference: the calibration rows' mean time [s] a drift is relative to (None without times).
        notes: what the user should know.
        inputs: the effect inputs of the calibration rows (columns: the tree's joints).
        heldout_predicted_m: the held-out points' RMS error [m] the final fit's estimation noise makes (its
            covariance propagated to the held-out rows; None without them): beside the noise σ,
            sqrt(3 σ² + this²) is the RMS the held-out rows should show.
    """

    effects: tuple[tuple[Effect, np.ndarray, np.ndarray], ...]
    steps: tuple[TreeStep, ...]
    last_candidates: tuple[TreeCandidate, ...]
    untestable: tuple[Effect, ...]
    vector: np.ndarray
    std: np.ndarray
    target: TargetEstimate
    tree_placements: TreePlacements
    point_errors: np.ndarray
    heldout_before: np.ndarray | None
    heldout_after: np.ndarray | None
    sigma_pos_m: float
    masses_unknown: bool
    time_reference: float | None
    notes: tuple[str, ...]
    inputs: EffectInputs
    heldout_predicted_m: float | None = None
    orientation_errors: np.ndarray | None = None
    sigma_rot_rad: float | None = None
    heldout_turns: tuple[np.ndarray, np.ndarray] | None = None


def tree_candidates(tree: KinematicTree, has_time: bool, lateral: bool = False) -> list[Effect]:
    """The single chain's catalogue on every target's chain (:func:`candidate_effects`; with ``lateral``, each
    revolute joint's lateral compliance too), each effect once: a joint shared by several chains is one candidate
    of each kind."""
    out: list[Effect] = []
    for target in tree.targets:
        out += [e for e in candidate_effects(target.chain, has_time, lateral) if e not in out]
    return out


@dataclass(frozen=True)
class _Search:
    """What the search holds fixed: the problem (with the tree's effect inputs), the fitted geometry's
    indices and base vector, the held-out rows' problem (None without them), the sensor's stated position
    noise per axis [m] (``--sigma-pos``; None: the fits' own)."""

    problem: TreeProblem
    kept: np.ndarray
    base: np.ndarray
    held: TreeProblem | None
    stated: float | None

    def body(self) -> KinematicChain:
        return TreeBody(self.problem.tree)

    def rescaled(self, objective: FitObjective, solution: Solution) -> _Search:
        return replace(self, problem=self.problem.rescaled(cast(TreeResidual | PriorResidual, objective), solution))

    def row_noise(self) -> float:
        return 1.0  # the residual is whitened: its rows are in noise units

    def held_verdict(self, before: np.ndarray, after: np.ndarray, fit: tuple[FitObjective, Solution],
                     models: tuple[Model, Model]) -> str:
        """The held-out test on the points and, with orientations, on each row's targets' angles too (row_changes:
        both in noise units); an unseen point or orientation changes nothing: a zero for both."""
        sigma_pos, sigma_rot = self.judged_noise(*fit)
        turns = [self.held_turns(*model) for model in models]
        # each (K, T), NaN where not seen; held-out rows that measure no orientation: their points alone
        rows = [None if t is None or sigma_rot is None or not np.isfinite(t).any() else t for t in turns]
        return held_out_verdict(PoseErrors(np.nan_to_num(before), rows[0]), PoseErrors(np.nan_to_num(after), rows[1]),
                                sigma_pos, sigma_rot)

    def judged_noise(self, objective: FitObjective, solution: Solution) -> tuple[float, float | None]:
        """The noise scales (σ_pos [m], σ_rot [rad] or None) a held-out test judges in: σ_pos the stated one, else
        per kind the smaller of the current model's and the candidate's fit's
        (:meth:`pincal.diagnosis.verdicts.Judge.judged_noise`: a model far off the data puts its own estimate too
        high), at least :data:`pincal.diagnosis.verdicts.NOISE_FLOOR`."""
        fitted = self.problem.rescaled(cast(TreeResidual | PriorResidual, objective), solution)
        rot = None if self.problem.sigma_rot is None or fitted.sigma_rot is None else max(
            min(self.problem.sigma_rot, fitted.sigma_rot), NOISE_FLOOR)
        return self.stated or max(min(self.problem.sigma_pos, fitted.sigma_pos), NOISE_FLOOR), rot

    def fit(self, effects: Sequence[Effect], x0: np.ndarray | None = None) -> tuple[FitObjective, Solution]:
        objective = self.objective(self.problem, effects)
        start = objective.start_vector() if x0 is None else x0
        return cast(FitObjective, objective), solve(objective, start, what="effect fit")

    def objective(self, problem: TreeProblem, effects: Sequence[Effect]) -> TreeResidual | PriorResidual:
        effects_inputs = cast(ModelledEffects, problem.effects)
        return replace(problem, effects=replace(effects_inputs, effects=tuple(effects))).objective(self.kept,
                                                                                                  self.base)

    def errors(self, objective: FitObjective, x: np.ndarray) -> np.ndarray:
        """The calibration rows' point errors (K, P) [m] of a fit, NaN where not seen."""
        tree_objective = cast(TreeResidual, getattr(objective, "objective", objective))
        return tree_objective.point_errors(x, self.problem.row_weight / self.problem.sigma_pos)

    def turns(self, objective: FitObjective, x: np.ndarray) -> np.ndarray | None:
        """The calibration rows' orientation errors (K, T) [rad] of a fit, NaN where not seen (None without
        orientations)."""
        if self.problem.sigma_rot is None:
            return None
        tree_objective = cast(TreeResidual, getattr(objective, "objective", objective))
        return tree_objective.orientation_errors(x, self.problem.row_weight / self.problem.sigma_rot)

    def reproduced(self, errors: np.ndarray, turns: np.ndarray | None, effects: int) -> str | None:
        """:func:`pincal.diagnosis.reproduction.reproduced_note`: metres and radians (noise-free rows)."""
        return reproduced_note(errors, turns, effects)

    def held_errors(self, effects: Sequence[Effect], x: np.ndarray) -> np.ndarray | None:
        """The held-out rows' point errors (K_h, P) [m] of the model at ``x`` (None without them)."""
        held = self._held_objective(effects)
        return None if held is None else held.point_errors(x, np.ones(held.seen.shape[0]))

    def held_turns(self, effects: Sequence[Effect], x: np.ndarray) -> np.ndarray | None:
        """The held-out rows' orientation errors (K_h, T) [rad] of the model at ``x``, NaN where not seen (None
        without held-out rows or without orientations)."""
        held = self._held_objective(effects)
        if held is None or self.problem.sigma_rot is None:
            return None
        return held.orientation_errors(x, np.ones(held.seen.shape[0]))

    def _held_objective(self, effects: Sequence[Effect]) -> TreeResidual | None:
        """The held-out rows' residual with ``effects`` in metres and radians (their weights and scales 1)."""
        if self.held is None:
            return None
        held = self.objective(self.held, effects)
        return cast(TreeResidual, getattr(held, "objective", held))


def diagnose_tree(tree: KinematicTree, calibration: TreeCalibration, data: MeasurementSet,
                  heldout: MeasurementSet | None = None, options: DiagnoseOptions | None = None,
                  progress: Progress | None = None) -> TreeDiagnosis:
    """Search the tree calibration's residuals for missing effects (module docstring).

    Args:
        tree: the tree ``calibration`` was made on (not changed: the final model is the result's placements).
        calibration: its result (:func:`pincal.fit.tree_calibration.calibrate_tree`).
        data: the measurement set it was calibrated on (its calibration rows: ``calibration.used_index``).
        heldout: held-out rows, each in the registration of its calibrated session.
        options: the row weights, row times, masses and stated noise (:class:`DiagnoseOptions`; a payload,
            candidates of a thermal or pause kind and a recalibration are not taken).
        progress: ``progress(done, total)``: one unit per candidate fitted in full, one per step.
    """
    options = DiagnoseOptions() if options is None else options
    used = data.select(calibration.used_index)
    rows = tree_rows(tree, used, calibration.row_sessions)
    time = None if options.time is None else np.asarray(options.time, dtype=float)[calibration.used_index]
    unknown = masses_unknown(TreeBody(tree), options.masses, 0.0)
    # the loads at the URDF's geometry: at the calibrated one a mass-moment column the URDF's symmetry makes
    # dependent (a combination the rows cannot determine) becomes independent by a hair, its value unbounded
    inputs = tree_inputs(tree, used, time, loads=unknown)
    pool = (list(options.candidates) if options.candidates is not None
            else tree_candidates(tree, time is not None, options.lateral))
    pool, untestable = testable_pool(pool, inputs, TreeBody(tree), unknown)
    kept = calibration.kept  # under a prior also the parameters it holds near nominal: free in the fit
    problem = TreeProblem(tree, calibration.params, rows, calibration.target, row_weights(used, options.sigma_column),
                          calibration.session_names, sigma_pos=calibration.sigma_pos_m, prior=calibration.prior_sigma,
                          effects=ModelledEffects((), inputs), sigma_rot=calibration.sigma_rot_rad)
    held = None
    if heldout is not None:
        held_rows = tree_rows(tree, heldout, session_rows(heldout, calibration.session_names))
        held_time = None if options.heldout_time is None else np.asarray(options.heldout_time, dtype=float)
        reference = None if time is None else float(np.mean(time))
        held_inputs = tree_inputs(tree, heldout, held_time, loads=unknown)
        if held_time is not None and reference is not None:  # a drift's time as the calibration rows'
            held_inputs = replace(held_inputs, time=held_time - reference)
        held = replace(problem, rows=_with_frames(held_rows, rows.oriented(), len(tree.targets)),
                       row_weight=np.ones(heldout.n_rows), sigma_pos=1.0, sigma_rot=1.0,
                       effects=ModelledEffects((), held_inputs))
    search = _Search(problem, kept, calibration.vector, held,
                     options.stated_sigma_pos_m)
    found = search_effects(search, inputs, pool, Counter(progress))
    return _concluded(found, untestable, unknown, time)


def _with_frames(rows: TreeRows, frames: np.ndarray, n_targets: int) -> TreeRows:
    """``rows`` with the frame rotations of ``frames`` as unknowns (the calibration rows' targets measured in
    orientation), whichever orientations they measure themselves: the fits' unknowns at the same places. An
    orientation of a target not among ``frames`` is unused; one of ``frames`` never measured here is not seen."""
    k = rows.seen.shape[0]
    seen = np.zeros((k, n_targets), dtype=bool) if rows.rotation_seen is None else np.asarray(rows.rotation_seen, bool)
    turns = np.broadcast_to(np.eye(3), (k, n_targets, 3, 3)) if rows.rotations is None else rows.rotations
    return replace(rows, rotations=turns, rotation_seen=seen & np.isin(np.arange(n_targets), frames), frames=frames)


def _covariance(objective: FitObjective, solution: Solution) -> np.ndarray:
    """The covariance of every unknown of a fit [their units²]: the posterior's under a prior
    (:func:`pincal.fit.prior.posterior`), else the solver's s² (JᵀJ)⁻¹ (:func:`pincal.fit.solver.solve`)."""
    jacobian, residual = solution.jacobian, solution.residual
    if isinstance(objective, PriorResidual):
        return posterior(jacobian, residual, objective.n_prior, objective.noise)[0]
    return float(residual @ residual) / max(jacobian.shape[0] - jacobian.shape[1], 1) * np.linalg.inv(gram(jacobian))


def _held_predicted(search: _Search, effects: Sequence[Effect], final: tuple[FitObjective, Solution]) -> float | None:
    """The held-out points' RMS error [m] the final fit's estimation noise alone makes: its covariance C
    (:func:`_covariance`: geometry, registrations, points and effect values) propagated through the held-out rows'
    Jacobian J_h at the final model, sqrt(Σ diag(J_h C J_hᵀ) / seen points), as
    :meth:`pincal.fit.tree_calibration.TreeCalibration.predicted_point_rms` for the geometry alone; None without
    held-out rows."""
    held = search._held_objective(effects)  # in metres: its rows' weights and scale are 1
    if held is None:
        return None
    objective, solution = final
    jacobian = held.jacobian(solution.x)[:held.n_positions]  # the points' entries (orientations' follow)
    variance = np.einsum("ij,jk,ik->i", jacobian, _covariance(objective, solution), jacobian)
    return float(np.sqrt(variance.sum() / max(int(held.seen.sum()), 1)))



def _held_turns(search: _Search, adopted: Sequence[Effect], xs: tuple[np.ndarray | None, np.ndarray]
                ) -> tuple[np.ndarray, np.ndarray] | None:
    """The held-out rows' orientation errors (K_h, T) [rad] of the fit without effects (``xs[0]``) and of the final
    one, None without held-out rows or orientations."""
    before, after = search.held_turns([], xs[1] if xs[0] is None else xs[0]), search.held_turns(adopted, xs[1])
    return None if before is None or after is None else (before, after)


def _concluded(found: Found, untestable: Sequence[Effect], unknown: bool, time: np.ndarray | None) -> TreeDiagnosis:
    """The final model as a value: the tree vector, placements, target and errors of the search's last fit."""
    search = cast(_Search, found.search)
    adopted, steps, ranking, notes = found.adopted, found.steps, found.ranking, list(found.notes)
    objective, solution = found.objective, found.solution
    problem = search.problem
    kinematic = objective.blocks["kinematic"]
    std_all = standard_deviations(objective, solution)
    vector, std = search.base.copy(), np.full(search.base.size, np.nan)
    vector[search.kept], std[search.kept] = solution.x[kinematic], std_all[kinematic]
    errors = search.errors(objective, solution.x)
    seen = errors[np.isfinite(errors)]
    turns = search.turns(objective, solution.x)
    effects = tuple((effect, solution.x[sl], std_all[sl]) for effect, sl in zip(adopted, objective.effect_slices))
    if untestable:
        notes.append(f"{len(untestable)} candidate(s) cannot be tested on these rows ("
                     f"{', '.join(e.label for e in untestable[:4])}{' ...' if len(untestable) > 4 else ''}): "
                     + ("no mass moment loads the joint" if unknown else
                        "no gravity torque acts on the joint in any row (give the URDF's inertias, or --masses "
                        "unknown)"))
    return TreeDiagnosis(
        effects=effects, steps=tuple(steps), last_candidates=ranking, untestable=tuple(untestable),
        vector=vector, std=std, target=cast(TreeResidual, objective).estimate(solution.x),
        tree_placements=problem.tree.placements() if problem.params is None else problem.params.placements(vector),
        point_errors=errors, heldout_before=steps[0].heldout_before if steps else search.held_errors([], solution.x),
        heldout_after=search.held_errors(adopted, solution.x),
        heldout_predicted_m=_held_predicted(search, adopted, (objective, solution)),
        heldout_turns=_held_turns(search, adopted, (found.start_x, solution.x)),
        sigma_pos_m=float(np.sqrt(np.mean(seen**2) / 3.0)), masses_unknown=unknown, orientation_errors=turns,
        sigma_rot_rad=None if turns is None else float(np.sqrt(np.nanmean(turns**2) / 3.0)),
        time_reference=None if time is None else float(np.mean(time)), notes=tuple(notes),
        inputs=cast(EffectInputs, cast(ModelledEffects, problem.effects).inputs))
