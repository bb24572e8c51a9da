"""Close the loop through a camera: the joint effects its images show that the geometry lacks (``diagnose
--camera-link``).

After the camera calibration (:func:`pincal.fit.camera_calibration.calibrate_camera`), every joint-angle candidate
of the single chain's catalogue (:func:`pincal.diagnosis.catalogue.candidate_effects`: compliance, encoder scale,
cyclic errors, backlash, couplings between parallel neighbours) is tested on the corners' reprojection residual:
an effect shifts its joint's angle from the reading, and the camera (eye in hand) or the board (eye to hand)
moves as under a joint offset (eq C4 of :mod:`pincal.residuals.camera`). The loop and its rules are those of a
tree's (:mod:`pincal.diagnosis.effect_loop`): screen, fit the shortlist with the kinematic parameters the
calibration kept, the world frames and the mount, judge by ΔBIC < −10, a value 2σ from zero and in physical range,
a change of some corner by a tenth of its noise, a basis that is not an offset, and, with held-out images, the
signed-rank test of their per-image change of reprojection error (:func:`pincal.diagnosis.held_out.held_out_verdict`,
an image's corners its points, in pixels); adopt, refit at the new noise scale.

The intrinsics stay those the calibration ended with; the sensor's effects (a drift, a scale) are not a camera's.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import cast

import numpy as np

from pincal.diagnosis.catalogue import candidate_effects
from pincal.diagnosis.diagnose import DiagnoseOptions
from pincal.diagnosis.effect_loop import EffectCandidate, EffectStep, Found, Model, search_effects
from pincal.diagnosis.held_out import held_out_verdict
from pincal.diagnosis.moment_candidates import masses_unknown, testable_pool
from pincal.diagnosis.screening import FitObjective
from pincal.fit.camera_calibration import (
    CameraCalibration,
    CameraProblem,
    camera_effect_inputs,
    image_sessions,
    images_of,
)
from pincal.fit.metrics import PoseErrors
from pincal.fit.prior import PriorResidual, standard_deviations
from pincal.fit.solver import Solution, solve
from pincal.measurements.camera_csv import CornerSet
from pincal.model.chain import KinematicChain
from pincal.model.effects import JOINT_EFFECTS, Effect, EffectInputs
from pincal.model.parameter_sets import NoParameters
from pincal.progress import Counter, Progress
from pincal.residuals.camera import CameraEstimate, CameraResidual
from pincal.residuals.sensor_values import ModelledEffects

__all__ = ["CORNER_NOISE_FLOOR_PX", "CameraDiagnosis", "camera_candidates", "diagnose_camera"]

#: Pixel noise no corner detection goes below [px]: a hundredth of a pixel, the accuracy sub-pixel corner
#: refinement reaches on ideal synthetic images (real ones: ~0.05-0.2 px, OpenCV's ChArUco tutorial). The
#: noise a fit estimates on noise-free corners is rounding; this stands for it in the held-out test.
CORNER_NOISE_FLOOR_PX = 0.01


@dataclass(frozen=True)
class CameraDiagnosis:
    """Outcome of :func:`diagnose_camera`.

    Attributes:
        effects: the adopted effects with their values and standard deviations.
        steps: one per adopted effect (its errors: each image's corners' reprojection distances (K, P) [px],
            P the board's corner ids, NaN where not seen).
        last_candidates: the ranking of the step that adopted nothing (best first).
        untestable: the candidates the images cannot test (no gravity torque on the joint; masses unknown).
        vector / std: the kinematic parameters of the final model [m, rad] (NaN std where not estimated).
        estimate: its world frames, mount and intrinsics.
        chain_placements: its chain placements; tip_placement: the tip's with the mount folded in (as
            :attr:`pincal.fit.camera_calibration.CameraCalibration.tip_placement`).
        rms_px: RMS reprojection error per coordinate of the calibration images [px], the final model's;
            calibration_rms_px: the camera calibration's.
        heldout_before_px / heldout_after_px: the held-out images' RMS per coordinate [px] of the calibration
            and of the final model (None without them).
        masses_unknown: compliances follow mass moments (``--masses unknown`` or no inertias).
        notes: what the user should know.
        inputs: the effect inputs of the calibration images (columns: the chain's joints).
    """

    effects: tuple[tuple[Effect, np.ndarray, np.ndarray], ...]
    steps: tuple[EffectStep, ...]
    last_candidates: tuple[EffectCandidate, ...]
    untestable: tuple[Effect, ...]
    vector: np.ndarray
    std: np.ndarray
    estimate: CameraEstimate
    chain_placements: tuple[np.ndarray, ...]
    tip_placement: np.ndarray
    rms_px: float
    calibration_rms_px: float
    heldout_before_px: float | None
    heldout_after_px: float | None
    masses_unknown: bool
    notes: tuple[str, ...]
    inputs: EffectInputs


def camera_candidates(chain: KinematicChain) -> list[Effect]:
    """The catalogue's joint-angle effects on the chain (:func:`candidate_effects` without the sensor's)."""
    return [e for e in candidate_effects(chain, has_time=False) if e.type in JOINT_EFFECTS]


@dataclass(frozen=True)
class _Search:
    """The loop's residual (:class:`pincal.diagnosis.effect_loop.EffectSearch`): the calibration images' problem
    (with their effect inputs), the kept kinematic parameters and the base vector, the held-out images' problem."""

    problem: CameraProblem
    kept: np.ndarray
    base: np.ndarray
    held: CameraProblem | None

    def body(self) -> KinematicChain:
        return self.problem.chain

    def objective(self, problem: CameraProblem, effects: Sequence[Effect]) -> CameraResidual | PriorResidual:
        inputs = cast(ModelledEffects, problem.effects)
        return replace(problem, effects=replace(inputs, effects=tuple(effects))).objective(self.kept, self.base)

    def fit(self, effects: Sequence[Effect], x0: np.ndarray | None = None) -> tuple[FitObjective, Solution]:
        objective = self.objective(self.problem, effects)
        start = objective.start_vector() if x0 is None else x0
        return cast(FitObjective, objective), solve(objective, start, what="effect fit")

    def rescaled(self, objective: FitObjective, solution: Solution) -> _Search:
        return replace(self, problem=self.problem.rescaled(cast(CameraResidual | PriorResidual, objective), solution))

    def row_noise(self) -> float:
        return self.problem.noise  # the residual is in pixels

    def errors(self, objective: FitObjective, x: np.ndarray) -> np.ndarray:
        return _per_image(_camera(objective), self.problem.corners, x)

    def held_errors(self, effects: Sequence[Effect], x: np.ndarray) -> np.ndarray | None:
        if self.held is None:
            return None
        return _per_image(_camera(self.objective(self.held, effects)), self.held.corners, x)

    def turns(self, objective: FitObjective, x: np.ndarray) -> np.ndarray | None:
        return None  # an image measures corners, no orientation

    def held_turns(self, effects: Sequence[Effect], x: np.ndarray) -> np.ndarray | None:
        return None

    def reproduced(self, errors: np.ndarray, turns: np.ndarray | None, effects: int) -> str | None:
        return None  # pixels, not metres: no floor of reproduction is set for a camera (noise-free images untested)

    def held_verdict(self, before: np.ndarray, after: np.ndarray, fit: tuple[FitObjective, Solution],
                     models: tuple[Model, Model]) -> str:
        """The held-out test of :func:`held_out_verdict` on the images' corner distances [px]: in its units of a
        thousandth (its text's "mm" then reads pixels, said so)."""
        objective, solution = fit
        fitted = self.problem.rescaled(cast(CameraResidual | PriorResidual, objective), solution).noise
        noise = max(min(self.problem.noise, fitted), CORNER_NOISE_FLOOR_PX)
        text = held_out_verdict(PoseErrors(1e-3 * np.nan_to_num(before), None),
                                PoseErrors(1e-3 * np.nan_to_num(after), None), 1e-3 * noise, None)
        return text.replace("position ", "reprojection ").replace(" mm RMS", " px RMS of the corners' distances")


def _camera(objective: object) -> CameraResidual:
    """The reprojection residual of a fit's objective (inside a prior-wrapped one)."""
    return cast(CameraResidual, getattr(objective, "objective", objective))


def _per_image(objective: CameraResidual, corners: CornerSet, x: np.ndarray) -> np.ndarray:
    """Each image's corners' reprojection distances (K, P) [px] at ``x``, P the board's corner ids, NaN where
    not seen."""
    distances = np.linalg.norm(objective.residual(x).reshape(-1, 2), axis=1)
    out = np.full((len(corners.images), int(np.max(corners.corners, initial=0)) + 1), np.nan)
    out[corners.image_of, corners.corners] = distances
    return out


def diagnose_camera(chain: KinematicChain, calibration: CameraCalibration, corners: CornerSet,
                    heldout: CornerSet | None = None, options: DiagnoseOptions | None = None,
                    progress: Progress | None = None) -> CameraDiagnosis:
    """Search the camera calibration's reprojection errors for missing joint effects (module docstring).

    Args:
        chain: the chain ``calibration`` was made on (not changed).
        calibration: its result (:func:`pincal.fit.camera_calibration.calibrate_camera`).
        corners: the corners it was calibrated on (images of role ``validation`` are left out).
        heldout: held-out images, each in the world frame of its calibrated session (None: no held-out test).
        options: the masses and the candidates (:class:`DiagnoseOptions`; the rest is a sensor's).
        progress: ``progress(done, total)``: one unit per candidate fitted in full, one per step.
    """
    options = DiagnoseOptions() if options is None else options
    used = images_of(corners, corners.roles != "validation")
    unknown = masses_unknown(chain, options.masses, 0.0)
    inputs = camera_effect_inputs(chain, used, unknown)
    pool = list(options.candidates) if options.candidates is not None else camera_candidates(chain)
    pool, untestable = testable_pool(pool, inputs, chain, unknown)
    sessions = image_sessions(used, calibration.session_names, len(calibration.estimate.worlds))
    problem = CameraProblem(chain, calibration.params, used, calibration.estimate, sessions,
                            prior=calibration.prior_sigma, noise=calibration.rms_px,
                            effects=ModelledEffects((), inputs))
    held = None
    if heldout is not None and len(heldout.images):
        held = replace(problem, corners=heldout, sessions=image_sessions(heldout, calibration.session_names,
                                                                        len(calibration.estimate.worlds)),
                       effects=ModelledEffects((), camera_effect_inputs(chain, heldout, unknown)))
    search = _Search(problem, calibration.kept, calibration.vector, held)
    found = search_effects(search, inputs, pool, Counter(progress))
    return _concluded(found, calibration, untestable, unknown)


def _rms(errors: np.ndarray | None) -> float | None:
    """RMS per coordinate [px] of corner distances (K, P) [px], NaN where not seen."""
    return None if errors is None else float(np.sqrt(np.nanmean(errors**2) / 2.0))


def _concluded(found: Found, calibration: CameraCalibration, untestable: Sequence[Effect],
               unknown: bool) -> CameraDiagnosis:
    """The final model as a value: the kinematic vector, the camera's estimate and placements of the last fit."""
    search = cast(_Search, found.search)
    objective, solution = _camera(found.objective), found.solution
    problem = search.problem
    kinematic = objective.blocks["kinematic"]
    std_all = standard_deviations(found.objective, solution)
    vector, std = search.base.copy(), np.full(search.base.size, np.nan)
    vector[search.kept], std[search.kept] = solution.x[kinematic], std_all[kinematic]
    estimate = objective.estimate(solution.x)
    params = problem.params if problem.params is not None else NoParameters(problem.chain)
    placements = tuple(params.placements(vector))
    effects = tuple((effect, solution.x[sl], std_all[sl]) for effect, sl in zip(found.adopted,
                                                                                 objective.effect_slices))
    notes = list(found.notes)
    if untestable:
        notes.append(f"{len(untestable)} candidate(s) cannot be tested on these images ("
                     f"{', '.join(e.label for e in untestable[:4])}{' ...' if len(untestable) > 4 else ''}): "
                     + ("no mass moment loads the joint" if unknown else
                        "no gravity torque acts on the joint in any image (give the URDF's inertias, or --masses "
                        "unknown)"))
    before = found.steps[0].heldout_before if found.steps else search.held_errors([], solution.x)
    return CameraDiagnosis(
        effects=effects, steps=found.steps, last_candidates=found.ranking, untestable=tuple(untestable),
        vector=vector, std=std, estimate=estimate, chain_placements=placements,
        tip_placement=placements[-1] @ estimate.mount,
        rms_px=float(np.sqrt(np.mean(objective.residual(solution.x)**2))),
        calibration_rms_px=calibration.rms_px, heldout_before_px=_rms(before),
        heldout_after_px=_rms(search.held_errors(found.adopted, solution.x)), masses_unknown=unknown,
        notes=tuple(notes), inputs=cast(EffectInputs, cast(ModelledEffects, problem.effects).inputs))
