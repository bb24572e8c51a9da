"""Calibration of a serial chain from a camera's images of a board: the kinematics, the mount and the world
frame (and the intrinsics, if asked) in one fit of the corners' reprojection errors [px].

The residual is eqs C1-C3 of :mod:`pincal.residuals.camera`; the start, the board poses and the closed-form
hand-eye calibration of :mod:`pincal.fit.camera_start` on the nominal kinematics. From there the steps are
the one pipeline of :mod:`pincal.fit.pipeline`, as for sensor rows and socket-fixture rows: the fit with the
nominal kinematics (level ``registration``: OpenCV's hand-eye answer refined by reprojection), then which
kinematic parameters the images determine given the mount, the world frame and the intrinsics fitted (those
always estimated), how many weak ones to keep (AIC by default), the fit and its covariance.

What one camera cannot see is what the always-estimated part absorbs, reported by name as for the other
kinds: the tip link's placement is the mount's (``<tip link>.t*``, ``.r*`` of level ``full``), and the
placement of the first joint and the first joint's offset move the whole chain as the world frame does
(eye to hand: the camera's pose in the base; eye in hand: the board's).

The intrinsics (:attr:`CameraFitOptions.intrinsics`) join the always-estimated part. With one image the mount
and the world frame are one pose (six directions undetermined) and with two the motion's axis leaves two; from
three images on (two motions about axes not parallel, as hand-eye calibration needs) all nine intrinsics are
determined together with the mount and the world frame, the kinematics' identifiable combinations besides.
How well, on the UR5 of the tests (7x5 board 0.5 m ahead, 0.2 px noise, the kinematics fixed): with 5
images fx, fy to ~1 px, cx, cy to ~2-3 px, k1 to ~0.01, k2 to ~0.02-0.15, k3 to ~0.02-0.4; with 20 images
those shrink by ~2-5, k3 staying the weakest (its r⁶ term matters only in the image's corners) -- estimate k3
only from images that fill the frame, and prefer intrinsics from a dedicated calibration when there are few.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import cast

import numpy as np
from scipy.optimize import least_squares

from pincal.errors import CalibrationError
from pincal.fit.identifiability import Ordering, Selection, condition_number, correlated_pairs
from pincal.fit.pipeline import Analysis, Dropped, dropped_parameters, fit_kinematics
from pincal.fit.prior import SCALE_FLOOR, Prior, PriorResidual, data_rows, effective_scale, hat_diagonal, log_evidence
from pincal.fit.selection import SelectionCriterion
from pincal.fit.solver import Solution, solve
from pincal.measurements.camera_csv import CornerSet
from pincal.measurements.data import MeasurementSet
from pincal.model.chain import KinematicChain
from pincal.model.effects import Effect, EffectInputs, effect_inputs, joint_shifts, with_loads
from pincal.model.parameter_sets import CHAIN_LEVELS, LEVELS, ChainLevel, ChainParameters, NoParameters
from pincal.model.pinhole import INTRINSIC_NAMES
from pincal.model.sensitivity import ParameterSlot, SensitivityModel
from pincal.residuals.base import KinematicsCache
from pincal.residuals.camera import CameraEstimate, CameraResidual
from pincal.residuals.sensor_values import ModelledEffects

__all__ = ["CAMERA_SELECTIONS", "CameraFitOptions", "CameraProblem", "CameraCalibration", "calibrate_camera",
           "images_of", "reprojection_errors", "refit_worlds", "mounted_frames", "image_sessions",
           "images_as_rows", "camera_effect_inputs"]

#: The selection criteria a camera's fit offers: leave-one-row-out (``press``) needs rows of one size,
#: and an image shows any number of corners.
CAMERA_SELECTIONS = ("aic", "bic", "all", "prior")


@dataclass(frozen=True)
class CameraFitOptions:
    """How :func:`calibrate_camera` fits: a value.

    Attributes:
        intrinsics: the intrinsics estimated with the rest, by name (:data:`pincal.model.pinhole.INTRINSIC_NAMES`;
            default: none, the start's kept).
        selection: the criterion choosing how many identifiable parameters to keep (:data:`CAMERA_SELECTIONS`)
            or a :class:`pincal.fit.prior.Prior`.
        refits: re-estimations of the pixel noise scale after the fit (with a prior: up to eq P2's fixed point).
    """

    intrinsics: tuple[str, ...] = ()
    selection: SelectionCriterion | Prior = "aic"
    refits: int = 1


@dataclass(frozen=True, eq=False)
class CameraProblem:
    """Fits of eqs C1-C3 over subsets of the kinematic parameters (:class:`pincal.fit.problem.KindProblem`): a
    value, its variants new problems (:meth:`with_prior`, :meth:`with_scales`, :meth:`rescaled`, ``replace``).

    ``sessions``: each image's session (K,), an index into ``start.worlds``. ``fitted``: the intrinsics
    estimated, indices into :data:`pincal.model.pinhole.INTRINSIC_NAMES`. ``models``: sensitivity models by
    slots, shared by every problem derived from this one. ``prior``: σ_i of every kinematic parameter
    (eq P1 of :mod:`pincal.fit.prior`). ``noise``: the pixel noise σ [px] weighting a prior's rows.
    ``effects``: the joint effects fitted with the rest and their inputs over the images (eq C4 of
    :mod:`pincal.residuals.camera`; None: none).
    """

    chain: KinematicChain
    params: ChainParameters | None
    corners: CornerSet
    start: CameraEstimate
    sessions: np.ndarray
    fitted: tuple[int, ...] = ()
    models: dict[tuple[ParameterSlot, ...], SensitivityModel] = field(default_factory=dict)
    prior: np.ndarray | None = None
    noise: float = 1.0
    effects: ModelledEffects | None = None

    def objective(self, free: np.ndarray, base: np.ndarray) -> CameraResidual | PriorResidual:
        params = self.params if self.params is not None else NoParameters(self.chain)
        cache = KinematicsCache(params, free, base, self.corners.q, self.models)
        objective = CameraResidual(cache, self.corners, self.start, self.fitted, self.sessions, self.effects)
        return objective if self.prior is None else PriorResidual(objective, self.prior[free], self.noise)

    def fit(self, free: np.ndarray, base: np.ndarray, x0: np.ndarray | None = None,
            what: str = "fit") -> tuple[CameraResidual | PriorResidual, Solution]:
        objective = self.objective(free, base)
        solution = solve(objective, objective.start_vector() if x0 is None else x0, what=what)
        return objective, solution

    def scales(self) -> tuple[float]:
        """The pixel noise σ [px] weighting a prior's rows."""
        return (self.noise,)

    def rescaled(self, objective: CameraResidual | PriorResidual, solution: Solution) -> CameraProblem:
        """This problem at σ [px] from a fit: with a prior, eq P2 from the data rows; without, their RMS."""
        if isinstance(objective, PriorResidual):
            return replace(self, noise=max(effective_scale(solution.residual[: -objective.n_prior],
                                                           hat_diagonal(solution.jacobian, objective.n_prior)),
                                           SCALE_FLOOR))
        return replace(self, noise=float(np.sqrt(np.mean(solution.residual**2))) or self.noise)

    def with_scales(self, scales: tuple[float | None, ...]) -> CameraProblem:
        (noise,) = scales
        return replace(self, noise=cast(float, noise))  # the one scale, of the pixels: always measured

    def with_prior(self, prior: np.ndarray | None) -> CameraProblem:
        return replace(self, prior=prior)

    def fold_rows(self, objective: CameraResidual | PriorResidual) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The prior's folds deal corners, each with its image's joint readings (M, N) (the folds keep equal
        readings together: an image's corners stay in one fold), its session (M,), its u and v entries (M, 2)."""
        corners = self.corners
        m = len(corners.image_of)
        return corners.q[corners.image_of], self.sessions[corners.image_of], np.arange(2 * m).reshape(m, 2)

    def scale_rows(self, objective: CameraResidual | PriorResidual) -> tuple[slice, ...]:
        """The data rows the noise scale weights: every corner's u and v."""
        return (slice(0, 2 * len(self.corners.image_of)),)

    def log_evidence(self, objective: CameraResidual | PriorResidual, solution: Solution) -> float:
        """Eq P3 (:func:`pincal.fit.prior.log_evidence`) with the rows [px] divided by σ."""
        prior = cast(PriorResidual, objective)  # eq P3 is of a MAP fit
        rows = solution.residual.size - prior.n_prior
        return log_evidence(solution.jacobian / prior.noise, solution.residual / prior.noise,
                            rows * 2.0 * np.log(prior.noise))

    def rows_view(self) -> MeasurementSet:
        """The images as rows of one point, for the selection's bookkeeping (their count and the file)."""
        return images_as_rows(self.corners)


def images_as_rows(corners: CornerSet) -> MeasurementSet:
    """The images of ``corners`` as rows of one point at zero, their joint readings and the file (what the
    selection's bookkeeping and the effects' inputs read)."""
    k = len(corners.images)
    return MeasurementSet(corners.joint_names, corners.q, np.zeros((k, 1, 3)), None,
                          np.full(k, "calibration", dtype=object), np.arange(k) + 2, {}, corners.source)


@dataclass(frozen=True)
class CameraCalibration:
    """Outcome of :func:`calibrate_camera`.

    Attributes:
        level: ``registration``, ``offsets`` or ``full``.
        params: the kinematic parameter set (None at level ``registration``).
        vector / std / status: kinematic parameters (zero = nominal), their standard deviations (NaN where
            not estimated) and why not.
        estimate: the world frames, mount and intrinsics fitted; nominal: the same fitted with the nominal
            kinematics (level ``registration``'s answer, the "before").
        session_names: the sessions, in the order of ``estimate.worlds``.
        rms_px / nominal_rms_px: RMS reprojection error per coordinate (u, v) of the fit and of the nominal fit [px].
        rank, condition, selection, dropped, correlated: identifiability report (column names as
            :meth:`pincal.residuals.camera.CameraResidual.column_names`).
        kept: the kinematic parameters estimated.
        chain_placements: the calibrated chain's joint and tip placements (4×4 each, as
            :meth:`pincal.model.chain.KinematicChain.placements`).
        tip_placement: the tip link's corrected placement on the last joint with the mount folded in,
            ``chain_placements[-1] @ mount`` (4, 4) [m]: the fixed joint's origin a corrected URDF writes
            when the tip link is the camera's optical frame (eye in hand) or the board's frame (eye to hand).
        solution / covariance: the final fit's unknowns and their covariance (the posterior with a prior).
        fit_seconds / total_seconds: the final fit; everything, start and selection included [s].
        notes: things the user should know.
        prior_sigma: with ``selection`` prior, σ_i of every kinematic parameter (eq P1 of :mod:`pincal.fit.prior`),
            (n,); None without a prior.
    """

    level: ChainLevel
    params: ChainParameters | None
    vector: np.ndarray
    std: np.ndarray
    status: tuple[str, ...]
    estimate: CameraEstimate
    nominal: CameraEstimate
    session_names: tuple[str, ...]
    rms_px: float
    nominal_rms_px: float
    rank: int
    condition: float
    selection: Selection | None
    dropped: tuple[Dropped, ...]
    correlated: tuple[tuple[str, str, float], ...]
    kept: np.ndarray
    chain_placements: tuple[np.ndarray, ...]
    tip_placement: np.ndarray
    solution: np.ndarray
    covariance: np.ndarray
    fit_seconds: float
    total_seconds: float
    notes: tuple[str, ...] = ()
    prior_sigma: np.ndarray | None = None

    @property
    def corrected_placements(self) -> tuple[np.ndarray, ...]:
        """``chain_placements`` with the tip's replaced by :attr:`tip_placement`: the model with the mount in the
        URDF, for :func:`pincal.model.corrected_urdf.write_corrected_urdf` (the mount then the identity)."""
        return (*self.chain_placements[:-1], self.tip_placement)


def calibrate_camera(chain: KinematicChain, corners: CornerSet, start: CameraEstimate, level: ChainLevel,
                     options: CameraFitOptions = CameraFitOptions(), session_names: tuple[str, ...] = ()
                     ) -> CameraCalibration:
    """Calibrate ``chain`` at ``level`` from the calibration images of ``corners``.

    Args:
        chain: the chain to the link carrying the camera (eye in hand) or the board (eye to hand), its tool
            the identity; it is not changed.
        corners: the corners (images with role ``validation`` are not used).
        start: where the fit starts (:func:`pincal.fit.camera_start.hand_eye_start`).
        level: one of :data:`pincal.model.parameter_sets.CHAIN_LEVELS`.
        options: what else is estimated and how many parameters are kept (:class:`CameraFitOptions`).
        session_names: the sessions of ``start.worlds`` (default: the single one); each image uses its own's.

    Raises:
        CalibrationError: an unknown level, criterion or intrinsic, an image of a session ``start`` lacks,
            fewer reprojection errors than unknowns, or a fit the images cannot determine.
    """
    started = time.perf_counter()
    if level not in CHAIN_LEVELS:
        raise CalibrationError(f"level must be one of {CHAIN_LEVELS}, got '{level}'")
    if options.selection not in CAMERA_SELECTIONS:
        raise CalibrationError(f"selection must be one of {CAMERA_SELECTIONS} for a camera, got '{options.selection}'")
    unknown = [n for n in options.intrinsics if n not in INTRINSIC_NAMES]
    if unknown:
        raise CalibrationError(f"no intrinsic named {', '.join(unknown)}; they are {', '.join(INTRINSIC_NAMES)}")
    corners = _calibration_images(corners)
    sessions = image_sessions(corners, session_names, len(start.worlds))
    params = LEVELS[level](chain) if level in LEVELS else None
    fitted = tuple(INTRINSIC_NAMES.index(n) for n in dict.fromkeys(options.intrinsics))
    problem = CameraProblem(chain, params, corners, start, sessions)
    size = params.size if params is not None else 0
    base, empty = np.zeros(size), np.array([], dtype=int)
    what = "camera mount and world frame (nominal kinematics)"
    objective, solution = problem.fit(empty, base, what=what)
    if fitted:  # the intrinsics freed once the frames fit the given ones: from a far start they can run off
        problem = replace(problem, start=cast(CameraResidual, objective).estimate(solution.x), fitted=fitted)
        objective, solution = problem.fit(empty, base, what=what + " and intrinsics")
    nominal = cast(CameraResidual, objective).estimate(solution.x)
    problem = replace(problem, start=nominal, noise=solution.rms)
    analysis: Analysis | None = None
    full = cast(CameraResidual, problem.objective(np.arange(size), base))  # no prior yet: the plain residual
    if size:
        jac = full.jacobian(full.start_vector())
        analysis = Analysis(jac, np.arange(size), np.arange(size, jac.shape[1]))
    fit = fit_kinematics(problem, analysis, problem.rows_view(), options.selection, level, options.refits,
                         from_selection=False)
    dropped: tuple[Dropped, ...] = ()
    names = session_names or ("session",)
    if analysis is not None:
        kinematic = [p.name for p in cast(ChainParameters, params).info]
        dropped = dropped_parameters(analysis.jacobian, cast(Ordering, fit.ordering), fit.kept, analysis.always,
                                     full.column_names(kinematic, names))
    final = fit.objective
    residual_of = cast(CameraResidual, getattr(final, "objective", final))  # inside a prior-wrapped one
    x, kept, covariance = fit.solution.x, fit.kept, fit.covariance
    estimate = residual_of.estimate(x)
    column_names = residual_of.column_names([] if params is None else [params.info[i].name for i in kept], names)
    placements = tuple(cast(ChainParameters, params).placements(fit.vector)) if size else tuple(chain.placements())
    pixels = fit.solution.residual[: 2 * len(corners.image_of)]
    return CameraCalibration(
        level=level, params=params, vector=fit.vector, std=fit.std, status=fit.status, estimate=estimate,
        nominal=nominal, session_names=tuple(session_names), rms_px=float(np.sqrt(np.mean(pixels**2))),
        nominal_rms_px=solution.rms, rank=fit.rank,
        condition=condition_number(data_rows(fit.solution.jacobian, final)), selection=fit.selection,
        dropped=dropped, correlated=tuple((column_names[a], column_names[b], c)
                                          for a, b, c in correlated_pairs(covariance)),
        kept=kept, chain_placements=placements, tip_placement=placements[-1] @ estimate.mount, solution=x.copy(),
        covariance=covariance, fit_seconds=fit.fit_seconds, total_seconds=time.perf_counter() - started,
        notes=() if fit.selection is None else tuple(fit.selection.notes),
        prior_sigma=cast(CameraProblem, fit.problem).prior,
    )


def images_of(corners: CornerSet, keep: np.ndarray) -> CornerSet:
    """The images ``keep`` (indices, or a boolean mask over the images) of ``corners``, with their corners."""
    keep = np.flatnonzero(keep) if np.asarray(keep).dtype == bool else np.asarray(keep, dtype=int)
    new_index = np.full(len(corners.images), -1)
    new_index[keep] = np.arange(len(keep))
    mine = new_index[corners.image_of] >= 0
    return replace(corners, images=tuple(corners.images[k] for k in keep), q=corners.q[keep],
                   roles=corners.roles[keep], sessions=corners.sessions[keep], sizes=corners.sizes[keep],
                   image_of=new_index[corners.image_of[mine]], corners=corners.corners[mine],
                   pixels=corners.pixels[mine], board_points=corners.board_points[mine], lines=corners.lines[mine],
                   extra={n: v[keep] for n, v in corners.extra.items()})


def camera_effect_inputs(chain: KinematicChain, corners: CornerSet, loads: bool = False) -> EffectInputs:
    """The effect inputs of the images of ``corners`` (one row each, in file order: their approach flanks follow
    it), with the gravity loads per mass moment when ``loads`` (compliances of unknown masses)."""
    inputs = effect_inputs(chain, images_as_rows(corners))
    return with_loads(inputs, chain) if loads else inputs


def reprojection_errors(chain: KinematicChain, result: CameraCalibration, corners: CornerSet,
                        effects: Sequence[tuple[Effect, np.ndarray]] = ()) -> np.ndarray:
    """Each corner of every image of ``corners`` (any role) reprojected through the calibrated model, minus
    where it was seen (M, 2) [px] (eq C3 at the result's kinematics, world frames, mount and intrinsics; with
    ``effects``, joint effects and their values, eq C4 over these images)."""
    params = result.params if result.params is not None else NoParameters(chain)
    cache = KinematicsCache(params, np.array([], dtype=int), result.vector, corners.q)
    sessions = image_sessions(corners, result.session_names, len(result.estimate.worlds))
    objective, x = _reprojection(chain, cache, corners, result.estimate, sessions, effects)
    return objective.residual(x).reshape(-1, 2)


def refit_worlds(chain: KinematicChain, corners: CornerSet, estimate: CameraEstimate, sessions: np.ndarray,
                 refit: np.ndarray, effects: Sequence[tuple[Effect, np.ndarray]] = ()) -> tuple[np.ndarray, np.ndarray]:
    """Each corner's reprojection error (M, 2) [px] through ``chain`` as it is placed, ``estimate``'s world frames
    (``sessions``: each image's index), mount and intrinsics, the joint ``effects`` at their values (eq C4 over these
    images); the world frames of sessions ``refit`` (indices) re-estimated first on these images (6 unknowns each,
    Levenberg-Marquardt on eq C3 with the model fixed). Returns the errors and the world frames used (S, 4, 4)."""
    cache = KinematicsCache(NoParameters(chain), np.array([], dtype=int), np.zeros(0), corners.q)
    objective, x0 = _reprojection(chain, cache, corners, estimate, sessions, effects)
    columns = (np.concatenate([objective.blocks["world"].start + 6 * s + np.arange(6) for s in refit]).astype(int)
               if len(refit) else np.array([], dtype=int))
    if columns.size:
        def residual(v: np.ndarray) -> np.ndarray:
            x = x0.copy()
            x[columns] = v
            return objective.residual(x)

        def jacobian(v: np.ndarray) -> np.ndarray:
            x = x0.copy()
            x[columns] = v
            return objective.jacobian(x)[:, columns]

        x0[columns] = least_squares(residual, x0[columns], jac=jacobian, method="lm").x
    return objective.residual(x0).reshape(-1, 2), objective.estimate(x0).worlds


def mounted_frames(chain: KinematicChain, corners: CornerSet, mount: np.ndarray,
                   effects: Sequence[tuple[Effect, np.ndarray]] = ()) -> np.ndarray:
    """The mounted frame ``T_k = base_T_tip(q_k) M`` at each image of ``corners`` (K, 4, 4) [m]: the camera eye in
    hand, the board eye to hand, through ``chain`` as it is placed and the ``mount`` M (4, 4) [m]; with joint
    ``effects`` at their values, q_k the readings they move (eq C4 over these images)."""
    q = corners.q
    if effects:
        inputs = camera_effect_inputs(chain, corners, loads=any(e.moments for e, _ in effects))
        q = q + chain.followed_shifts(joint_shifts([e for e, _ in effects], [v for _, v in effects], inputs,
                                                   chain.joint_names))
    rotations, positions = chain.tool_poses(q)
    out = np.tile(np.eye(4), (len(rotations), 1, 1))
    out[:, :3, :3], out[:, :3, 3] = rotations, positions
    return out @ mount


def _reprojection(chain: KinematicChain, cache: KinematicsCache, corners: CornerSet, estimate: CameraEstimate,
                  sessions: np.ndarray, effects: Sequence[tuple[Effect, np.ndarray]]
                  ) -> tuple[CameraResidual, np.ndarray]:
    """The reprojection residual (eqs C3-C4) of ``corners`` with nothing free but the world frames, mount and
    intrinsics (at ``estimate``) and the ``effects`` (at their values), and its vector at those values."""
    modelled = None
    if effects:
        inputs = camera_effect_inputs(chain, corners, loads=any(e.moments for e, _ in effects))
        modelled = ModelledEffects(tuple(e for e, _ in effects), inputs)
    objective = CameraResidual(cache, corners, estimate, (), sessions, modelled)
    x = objective.start_vector()
    if effects:
        x[objective.blocks["effects"]] = np.concatenate([np.asarray(v, dtype=float) for _, v in effects])
    return objective, x


def _calibration_images(corners: CornerSet) -> CornerSet:
    """``corners`` without its validation images (and their corners)."""
    keep = np.flatnonzero(corners.roles != "validation")
    if len(keep) < 3:
        raise CalibrationError(f"{corners.source}: {len(keep)} calibration image(s) (role 'validation' is not "
                               "used); a camera calibration needs at least 3")
    return corners if len(keep) == len(corners.images) else images_of(corners, keep)


def image_sessions(corners: CornerSet, session_names: tuple[str, ...], n_worlds: int) -> np.ndarray:
    """Each image's index into the start's world frames (K,): by ``session_names``, or 0 with one world frame."""
    if not session_names:
        if n_worlds != 1:
            raise CalibrationError(f"{n_worlds} world frames need their session names")
        return np.zeros(len(corners.images), dtype=np.intp)
    lookup = {name: s for s, name in enumerate(session_names)}
    missing = sorted({str(s) for s in corners.sessions if str(s) not in lookup})
    if missing:
        raise CalibrationError(f"{corners.source}: session(s) {', '.join(missing)} have no world frame in the "
                               "start; start from these images (hand_eye_start)")
    return np.array([lookup[str(s)] for s in corners.sessions], dtype=np.intp)
