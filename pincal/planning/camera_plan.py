"""``pincal plan`` for a camera: choose the N configurations to image the board from.

The information of an image is the reprojection Jacobian of its corners (eqs C1-C3 of
:mod:`pincal.residuals.camera`: the kinematic parameters of the level, the world frame, the mount and the
intrinsics estimated), each row divided by the pixel noise σ [px]: F_k (2P × n, the board's P corners; an
image that shows fewer has zero rows in place of the others, which carry no information), linearised at the
camera's estimate and the chain as it is. The candidates are the configurations whose image is usable
(:mod:`pincal.planning.camera_views`); the criteria, the greedy choice and the exchange are the sensors'
(:mod:`pincal.planning.design`), with the ``accuracy`` criterion's error the position of the mount's origin
in the base frame — the camera's optical centre eye in hand, the board's origin eye to hand — over a sample
of the usable candidates (eq A1: ``y = t_k + R_k t_M``, dy/dθ the point's velocity, dy/dt_M = R_k). The
plan is set beside random choices of as many usable candidates, and visited in a short tour.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from pincal.errors import PincalError
from pincal.measurements.camera_csv import CornerSet
from pincal.measurements.charuco import CharucoSpec
from pincal.model.chain import KinematicChain
from pincal.model.parameter_sets import CHAIN_LEVELS, LEVELS, ChainLevel, NoParameters
from pincal.model.pinhole import INTRINSIC_NAMES
from pincal.planning.camera_views import BoardViews, ViewLimits, board_views
from pincal.planning.defaults import WORKSPACE_SIZE
from pincal.planning.design import CRITERIA, DesignProblem, Prediction, select
from pincal.planning.ordering import move_times, short_tour
from pincal.planning.planner import RANDOM_DRAWS, _velocities
from pincal.progress import Counter, Progress
from pincal.residuals.base import KinematicsCache
from pincal.residuals.camera import CameraEstimate, CameraResidual
from pincal.simulation.camera_scene import board_corners

__all__ = ["DEFAULT_SIGMA_PX", "MIN_IMAGES", "CameraPlanSettings", "CameraPlan", "plan_camera_views"]

#: Pixel noise assumed per corner coordinate when no image is recorded [px]: a ChArUco corner refined by
#: OpenCV's cornerSubPix is found to about 0.1-0.2 px (the tests' rendered 1280x960 images: 0.2 px). It scales
#: the predicted errors only, never the choice.
DEFAULT_SIGMA_PX = 0.2
#: Images a camera calibration needs at least: two motions about axes not parallel (hand-eye calibration's
#: condition, Tsai & Lenz 1989), as :func:`pincal.fit.camera_calibration.calibrate_camera` requires.
MIN_IMAGES = 3


@dataclass(frozen=True)
class CameraPlanSettings:
    """What to plan for.

    Attributes:
        count: N, images to choose.
        level: ``registration``, ``offsets`` or ``full`` (what the calibration will estimate).
        criterion: ``accuracy``, ``d`` or ``a`` (:data:`pincal.planning.design.CRITERIA`).
        sigma_px: the pixel noise per coordinate [px]; it scales the predictions.
        intrinsics: the intrinsics the calibration will estimate too, by name (default: none, given).
        limits: what makes an image usable.
        seed: seed of the workspace sample, the exchange's random starts and the random comparison.
        random_draws: random N-subsets of the usable candidates the plan is compared with.
        workspace_size: usable candidates the accuracy is averaged over.
    """

    count: int
    level: ChainLevel = "full"
    criterion: str = "accuracy"
    sigma_px: float = DEFAULT_SIGMA_PX
    intrinsics: tuple[str, ...] = ()
    limits: ViewLimits = ViewLimits()
    seed: int = 0
    random_draws: int = RANDOM_DRAWS
    workspace_size: int = WORKSPACE_SIZE

    def __post_init__(self) -> None:
        if self.level not in CHAIN_LEVELS:
            raise PincalError(f"--level must be one of {', '.join(CHAIN_LEVELS)} for a camera, got '{self.level}'")
        if self.criterion not in CRITERIA:
            raise PincalError(f"--criterion must be one of {', '.join(CRITERIA)}, got '{self.criterion}'")
        if not (np.isfinite(self.sigma_px) and self.sigma_px > 0.0):
            raise PincalError(f"the pixel noise must be a positive number of pixels, got {self.sigma_px}")
        unknown = [n for n in self.intrinsics if n not in INTRINSIC_NAMES]
        if unknown:
            raise PincalError(f"no intrinsic named {', '.join(unknown)}; they are {', '.join(INTRINSIC_NAMES)}")


@dataclass(frozen=True)
class CameraPlan:
    """The planned images and what they are predicted to give.

    Attributes:
        settings: the settings.
        q: the chosen configurations in visiting order (N, n_joints) [rad or m].
        candidates: their indices into the candidates (N,).
        priority: each visited configuration's rank in the greedy re-addition (1 = the most informative) (N,).
        usable: which candidates give a usable image (K,).
        min_spacing_px: the smallest distance between neighbouring corners of a usable image [px]
            (:meth:`pincal.planning.camera_views.ViewLimits.min_spacing_px`).
        views: the board as the chosen configurations see it, in visiting order.
        criterion_value: the criterion of the plan (with the recorded images).
        log_det / random_log_det: ln det of the information of the identifiable parameters (scaled as
            :class:`pincal.planning.design.DesignProblem` scales them) of the plan and the median over random
            choices of usable candidates: the larger, the better determined.
        prediction / random: the expected error of the mount's origin (the module docstring) of the plan and
            the median over the random choices (None: singular).
        random_singular: random choices that do not determine the parameters.
        identifiable / not_identifiable: kinematic parameters the usable candidates can / cannot determine.
        estimated: every parameter the calibration estimates (the identifiable ones, world frame, mount,
            intrinsics).
        travel_s: time of the moves at the URDF's velocity limits [s].
        seconds: planning time [s].
        notes: what the user should know.
    """

    settings: CameraPlanSettings
    q: np.ndarray
    candidates: np.ndarray
    priority: np.ndarray
    usable: np.ndarray
    min_spacing_px: float
    views: BoardViews
    criterion_value: float
    log_det: float
    random_log_det: float
    prediction: Prediction | None
    random: Prediction | None
    random_singular: int
    identifiable: tuple[str, ...]
    not_identifiable: tuple[str, ...]
    estimated: tuple[str, ...]
    travel_s: float
    seconds: float
    notes: tuple[str, ...] = ()


def _view_corners(chain: KinematicChain, board: CharucoSpec, q: np.ndarray, views: BoardViews,
                  session: str) -> CornerSet:
    """Every corner of the board in each image at ``q`` (K, N), where ``views`` sees them (no noise)."""
    k, p = views.pixels.shape[:2]
    size = np.array([0, 0])
    return CornerSet(joint_names=chain.joint_names, images=tuple(f"candidate_{i}" for i in range(k)), q=q,
                     roles=np.full(k, "calibration", dtype=object), sessions=np.full(k, session, dtype=object),
                     sizes=np.tile(size, (k, 1)), image_of=np.repeat(np.arange(k), p),
                     corners=np.tile(np.arange(p), k), pixels=views.pixels.reshape(-1, 2),
                     board_points=np.tile(board_corners(board), (k, 1)), lines=np.zeros(k * p, dtype=int),
                     source="<candidates>")


def _residual(chain: KinematicChain, level: ChainLevel, corners: CornerSet, camera: CameraEstimate,
              fitted: tuple[int, ...], sessions: np.ndarray) -> CameraResidual:
    """Eqs C1-C3 over ``corners`` with every kinematic parameter of ``level`` free, at the chain as it is."""
    params = LEVELS[level](chain) if level in LEVELS else NoParameters(chain)
    size = params.size if level in LEVELS else 0
    cache = KinematicsCache(params, np.arange(size), np.zeros(size), corners.q)
    return CameraResidual(cache, corners, camera, fitted, sessions)


def _image_blocks(residual: CameraResidual, n_images: int, rows: int, sigma_px: float) -> np.ndarray:
    """The weighted Jacobian (:class:`CameraResidual` rows / σ) as one block per image (K, rows, n), each
    image's corners first, zero rows after them."""
    jacobian = residual.jacobian(residual.start_vector()) / sigma_px  # (2M, n)
    image_of = residual.image_of
    slot = np.arange(len(image_of)) - np.searchsorted(image_of, image_of)  # the corner's place in its image
    if np.any(np.diff(image_of) < 0) or (len(slot) and slot.max() * 2 + 2 > rows):
        raise PincalError("the corners must be grouped by image, at most the board's per image")
    blocks = np.zeros((n_images, rows, jacobian.shape[1]))
    pairs = jacobian.reshape(len(image_of), 2, -1)
    blocks[image_of, 2 * slot] = pairs[:, 0]
    blocks[image_of, 2 * slot + 1] = pairs[:, 1]
    return blocks


def _compressed(blocks: np.ndarray, rank: int) -> np.ndarray:
    """Blocks (K, rank, n) with the information of ``blocks`` (K, m, n): an image moves its corners through the
    camera's pose relative to the board (6 directions) and the intrinsics estimated, so F_k = (d pixels / d
    pose, intrinsics) · (d pose, intrinsics / d unknowns) has rank 6 + those at most; its leading singular
    rows S_i v_iᵀ keep F_kᵀ F_k whole and make every step of the search cheaper by (m / rank)²."""
    if rank >= blocks.shape[1]:
        return blocks
    _, values, vectors = np.linalg.svd(blocks, full_matrices=False)
    return values[:, :rank, None] * vectors[:, :rank]


def _origin_rows(residual: CameraResidual) -> np.ndarray:
    """Eq A1's rows: the mount's origin in the base frame at each of the residual's images, per unknown
    (E, 1, 3, n) [m per unit]."""
    x = residual.start_vector()
    poses, sens = residual.cache.evaluate(x[residual.blocks["kinematic"]])
    rotations, positions = poses.tool_rotations, poses.tool_positions  # (E, 3, 3), (E, 3)
    y = positions + rotations @ residual.start.mount[:3, 3]
    velocity = sens.linear + np.cross(sens.angular, (y - sens.origin)[:, None, :])  # (E, n_kin, 3)
    rows = np.zeros((len(y), 3, residual.n_params))
    rows[:, :, residual.blocks["kinematic"]] = velocity.transpose(0, 2, 1)
    mount = residual.blocks["mount"]
    rows[:, :, mount.start + 3 : mount.stop] = rotations
    return rows[:, None]


def plan_camera_views(chain: KinematicChain, camera: CameraEstimate, board: CharucoSpec, candidates: np.ndarray,
                      settings: CameraPlanSettings, existing: CornerSet | None = None,
                      session_names: tuple[str, ...] = (), progress: Progress | None = None) -> CameraPlan:
    """Choose ``settings.count`` of the usable ``candidates`` (K, N) and order them.

    Args:
        chain: the chain to the link carrying the camera (eye in hand) or the board (eye to hand), its tool the
            identity; its placements as they are are the linearisation point (not changed).
        camera: the arrangement, world frame(s), mount and intrinsics (with the image size) to plan for.
        board: the ChArUco board.
        existing: images already recorded (their information counts; the plan continues the session of the
            last of them).
        session_names: the sessions of ``camera.worlds`` (with ``existing`` of several sessions).
        progress: ``progress(done, total)`` over the search's steps and the random draws.

    Raises:
        PincalError: fewer usable candidates than ``count``, a count below :data:`MIN_IMAGES` with the
            recorded images, recorded images of a session ``camera`` has no world frame for.
    """
    started = time.perf_counter()
    candidates = np.atleast_2d(np.asarray(candidates, dtype=float))
    fitted = tuple(INTRINSIC_NAMES.index(n) for n in dict.fromkeys(settings.intrinsics))
    names = session_names or ("session",)
    sessions = np.zeros(0, dtype=np.intp)
    if existing is not None:
        lookup = {name: s for s, name in enumerate(names)}
        missing = sorted({str(s) for s in existing.sessions if str(s) not in lookup}) if session_names else []
        if missing:
            raise PincalError(f"{existing.source}: session(s) {', '.join(missing)} have no world frame")
        sessions = (np.array([lookup[str(s)] for s in existing.sessions], dtype=np.intp) if session_names
                    else np.zeros(len(existing.images), dtype=np.intp))
    current = int(sessions[-1]) if len(sessions) else 0  # the planned images continue the last recorded one's
    viewing = replace(camera, worlds=camera.worlds[[current]])
    views = board_views(chain, viewing, board, candidates)
    width, height = camera.intrinsics.width, camera.intrinsics.height
    usable = settings.limits.usable(views, board, width, height)
    floor = settings.limits.min_spacing_px(board, width, height)
    pool = np.flatnonzero(usable)
    if settings.count > len(pool):
        raise PincalError(
            f"--count {settings.count} is more than the {len(pool)} of {len(candidates)} candidates that see the "
            f"whole board at most {settings.limits.max_angle_deg:g} degrees from facing it, its corners at least "
            f"{floor:.3g} px apart; lower --count or draw more "
            "(--sample)")
    recorded = 0 if existing is None else len(existing.images)
    if settings.count + recorded < MIN_IMAGES:
        raise PincalError(f"--count {settings.count}: a camera calibration needs at least {MIN_IMAGES} images "
                          f"(two motions about axes not parallel){f', {recorded} recorded' if recorded else ''}")
    rows = 2 * board.n_corners
    q_pool = candidates[pool]
    pool_views = BoardViews(views.pixels[pool], views.inside[pool], views.angle_deg[pool], views.spacing_px[pool],
                            views.distance_m[pool])
    candidate_corners = _view_corners(chain, board, q_pool, pool_views, names[current])
    candidate_residual = _residual(chain, settings.level, candidate_corners, camera, fitted,
                                   np.full(len(pool), current, dtype=np.intp))
    rank = 6 + len(fitted)
    blocks = _compressed(_image_blocks(candidate_residual, len(pool), rows, settings.sigma_px), rank)
    recorded_blocks = np.zeros((0, blocks.shape[1], blocks.shape[2]))
    if existing is not None:
        recorded_blocks = _compressed(_image_blocks(_residual(chain, settings.level, existing, camera, fitted,
                                                              sessions), len(existing.images), rows,
                                                    settings.sigma_px), rank)
    rng = np.random.default_rng(settings.seed)
    sample = np.sort(rng.choice(len(pool), min(len(pool), settings.workspace_size), replace=False))
    workspace = _residual(chain, settings.level, _view_corners(chain, board, q_pool[sample], replace(
        pool_views, pixels=pool_views.pixels[sample]), names[current]), camera, fitted,
        np.full(len(sample), current, dtype=np.intp))
    kinematic = np.arange(candidate_residual.blocks["kinematic"].stop)
    problem = DesignProblem(blocks, kinematic, recorded_blocks, _origin_rows(workspace), None)
    counter = Counter(progress)
    counter.expect(settings.random_draws)
    selection = select(problem, settings.count, settings.criterion, None, counter, seed=settings.seed)
    draws = [rng.choice(len(pool), settings.count, replace=False) for _ in range(settings.random_draws)]
    random, singular = _random(problem, draws, counter)
    counter.settle()
    start = existing.q[-1] if existing is not None else q_pool[selection.priority[0]]
    velocity = _velocities(chain)
    order = short_tour(q_pool[selection.chosen], velocity, start)
    chosen = selection.chosen[order]
    ranks = {int(c): i + 1 for i, c in enumerate(selection.priority)}
    prediction = problem.predict(selection.chosen)
    kinematic_names = [] if settings.level not in LEVELS else [p.name for p in LEVELS[settings.level](chain).info]
    columns = candidate_residual.column_names(kinematic_names, names)
    notes = []
    if prediction is None:
        notes.append("the chosen images do not determine every identifiable parameter; plan more")
    return CameraPlan(
        settings=settings, q=q_pool[chosen], candidates=pool[chosen],
        priority=np.array([ranks[int(c)] for c in chosen]), usable=usable, min_spacing_px=floor,
        views=BoardViews(*(getattr(pool_views, f)[chosen] for f in ("pixels", "inside", "angle_deg", "spacing_px",
                                                                   "distance_m"))),
        criterion_value=problem.criterion(selection.chosen, settings.criterion),
        log_det=problem.criterion(selection.chosen, "d"),
        random_log_det=float(np.median([problem.criterion(d, "d") for d in draws])),
        prediction=prediction, random=random, random_singular=singular,
        identifiable=tuple(columns[i] for i in problem.identifiable),
        not_identifiable=tuple(columns[i] for i in problem.not_identifiable),
        estimated=tuple(columns[i] for i in problem.columns),
        travel_s=float(move_times(q_pool[chosen], velocity).sum()), seconds=time.perf_counter() - started,
        notes=tuple(notes),
    )


def _random(problem: DesignProblem, draws: list[np.ndarray], counter: Counter) -> tuple[Prediction | None, int]:
    """The median prediction over random choices (a singular one counts as infinitely bad), and how many were
    singular; None when half or more are."""
    found = []
    for draw in draws:
        found.append(problem.predict(draw, condition=False))
        counter.tick()
    good = [d for d in found if d is not None]
    singular = len(found) - len(good)
    if len(good) <= len(found) // 2:
        return None, singular
    median: dict[str, Any] = {"mean_rotation_deg": None, "max_rotation_deg": None}
    for key in ("mean_position_mm", "max_position_mm", "condition"):
        median[key] = float(np.median([getattr(d, key) for d in good] + [np.inf] * singular))
    return Prediction(**median), singular
