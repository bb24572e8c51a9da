"""``pincal calibrate --camera-link``'s job: a camera's DATA.csv (what detect writes) → the kinematics, the camera's
mount and the world frame fitted from the corners' reprojection errors → the corrected URDF, a camera_info YAML
beside it and REPORT.json (:func:`calibrate_camera_files`), whole or not at all.

The chain runs from the URDF's root to the link carrying the camera (eye in hand) or the board (eye to hand,
``--board-link``): :func:`pincal.model.camera_chain.camera_chain`. The start is from nothing
(:func:`pincal.fit.camera_start.hand_eye_start`: solvePnP per image, OpenCV's hand-eye on the nominal kinematics),
then the joint fit (:func:`pincal.fit.camera_calibration.calibrate_camera`). Intrinsics come from a file
(:func:`pincal.model.camera_info.read_intrinsics`) or, with ``estimate``, start from OpenCV's ``calibrateCamera`` on
the calibration images' corners and are fitted with the rest. Images of role ``validation`` are held out; the
report gives every image's reprojection RMS before (the nominal kinematics with OpenCV's hand-eye refined: what
hand-eye tools give) and after.

The corrected URDF carries the fixed joints' origins: the mount (the camera's link on the chain, eye in hand; the
board's, eye to hand) and, eye to hand, the camera in the world (its link's fixed joint from the root side). Eye in
hand the board's pose in the world is in the report only (a URDF has no link for it). A model that misses its
corners grossly is withheld as calibrate withholds one (:mod:`pincal.workflows.verdict`): the pixel RMS seen at the
board's mean depth, ``e [m] = e [px] · Z / f``, against the same 5 % of the reach.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Literal, cast

import numpy as np
import pinocchio as pin

from pincal._version import __version__
from pincal.errors import CalibrationError, PincalError
from pincal.fit.camera_calibration import (
    CameraCalibration,
    CameraFitOptions,
    calibrate_camera,
    image_sessions,
    images_of,
    refit_worlds,
    reprojection_errors,
)
from pincal.fit.camera_start import hand_eye_start
from pincal.fit.plausibility import GROSS_REACH_FRACTION, gross_misfit, reach_m
from pincal.fit.prior import Prior
from pincal.fit.selection import SelectionCriterion
from pincal.measurements.camera_csv import CornerSet, read_corners
from pincal.model.camera_chain import camera_chain, world_link_origin
from pincal.model.camera_info import check_image_size, read_intrinsics, write_camera_info
from pincal.model.camera_view import Arrangement, camera_points
from pincal.model.chain import KinematicChain
from pincal.model.corrected_urdf import corrected_origins
from pincal.model.description import read_description, xacro_arguments
from pincal.model.effects import Effect
from pincal.model.parameter_sets import CHAIN_LEVELS, ChainLevel
from pincal.model.pinhole import INTRINSIC_NAMES, CameraIntrinsics
from pincal.report.camera import CameraRecord, camera_report
from pincal.report.document import write_report
from pincal.report.effects_file import effects_path, write_effects_file
from pincal.report.model import findings_json
from pincal.report.model_camera import CameraReport, CameraSources
from pincal.residuals.camera import CameraEstimate
from pincal.workflows.paths import description_inputs, refuse_overwrite
from pincal.workflows.report_page import refuse_page, render_page, write_page
from pincal.workflows.settings import default_selection, expect
from pincal.workflows.verdict import UrdfWrite, withhold, withholding, write_urdf_checked_by

__all__ = ["ESTIMATE", "CameraCalibrateSettings", "CameraSetup", "CameraCalibrationRun", "camera_info_path",
           "load_camera", "estimate_intrinsics", "calibrate_camera_files", "CameraPaths", "CameraFit", "CameraModel",
           "fit_camera", "write_camera_run", "misfit_m", "refuse_other_images",
           "arrangement_words"]

#: ``--intrinsics estimate``: the intrinsics started from OpenCV's calibrateCamera and fitted with the rest.
ESTIMATE = "estimate"


@dataclass(frozen=True)
class CameraCalibrateSettings:
    """``pincal calibrate --camera-link`` without its paths.

    Attributes:
        camera_link: the link of the camera's optical frame (x right, y down, z ahead), attached by a fixed joint.
        board_link: the link of the board's frame (eye to hand); None eye in hand.
        intrinsics: a ROS camera_info or OpenCV YAML file, or :data:`ESTIMATE`.
        level: registration, offsets or full (:data:`pincal.model.parameter_sets.CHAIN_LEVELS`).
        selection: the parameter selection (``aic``, ``bic``, ``all``, ``prior`` or a
            :class:`pincal.fit.prior.Prior`); None: the commands' default (:func:`default_selection`).
        xacro_args: ``NAME:=VALUE`` pairs for a ``.xacro`` description.
        force: write the corrected URDF and camera_info even of a model that misses its corners grossly.
        images: the folder of the image files, where the HTML page looks for the one it draws (by the name
            DATA.csv gives, which is a file name: detect keeps no folders); None: DATA.csv's folder.

    Raises:
        PincalError: an unknown level or selection, a prior at level registration.
    """

    camera_link: str
    intrinsics: Path | Literal["estimate"]
    board_link: str | None = None
    level: ChainLevel = "full"
    selection: SelectionCriterion | Prior | None = None
    xacro_args: tuple[tuple[str, str], ...] = ()
    force: bool = False
    images: Path | None = None

    def __post_init__(self) -> None:
        from pincal.fit.camera_calibration import CAMERA_SELECTIONS

        if self.level not in CHAIN_LEVELS:
            raise PincalError(f"--level must be one of {', '.join(CHAIN_LEVELS)} for a camera, got '{self.level}'")
        if self.selection is None:
            object.__setattr__(self, "selection", default_selection(self.level))
        name = "prior" if isinstance(self.selection, Prior) else self.selection
        if name not in CAMERA_SELECTIONS:
            raise PincalError(f"--select must be one of {', '.join(CAMERA_SELECTIONS)} for a camera (an image shows "
                              f"any number of corners, so press's rows of one size do not apply), got '{name}'")
        if name == "prior" and self.level == "registration":
            raise PincalError("--select prior does not apply to --level registration (it fits no kinematic "
                              "parameter): use --level offsets or full, or drop it")
        if self.intrinsics != ESTIMATE:
            object.__setattr__(self, "intrinsics", Path(self.intrinsics))
        if self.images is not None:
            object.__setattr__(self, "images", Path(self.images))
        object.__setattr__(self, "xacro_args", tuple((str(k), str(v)) for k, v in self.xacro_args))

    @property
    def criterion(self) -> SelectionCriterion | Prior:
        """``selection`` resolved when the settings were made (never None)."""
        return cast("SelectionCriterion | Prior", self.selection)


@dataclass(frozen=True)
class CameraSetup:
    """The chain, arrangement, corners and intrinsics of a camera's run, read and checked.

    Attributes:
        chain: from the root to the link carrying the camera (eye in hand) or the board (eye to hand).
        camera_link: the camera's link.
        arrangement: ``eye_in_hand`` or ``eye_to_hand``.
        corners: DATA.csv read.
        intrinsics: the file's, or None (to be estimated).
        notes: the reader's notes.
    """

    chain: KinematicChain
    camera_link: str
    arrangement: Arrangement
    corners: CornerSet
    intrinsics: CameraIntrinsics | None
    notes: tuple[str, ...]


def camera_info_path(out_urdf: str | Path) -> Path:
    """The camera_info YAML written beside the corrected URDF ``out_urdf``: ``STEM.camera_info.yaml``."""
    out_urdf = Path(out_urdf)
    return out_urdf.with_name(f"{out_urdf.stem}.camera_info.yaml")


def load_camera(urdf: Path, data: Path, camera_link: str, board_link: str | None,
                intrinsics: Path | Literal["estimate"], xacro_args: tuple[tuple[str, str], ...] = ()) -> CameraSetup:
    """Read the URDF's camera chain, DATA.csv and the intrinsics file, and check they go together.

    Raises:
        ModelError: a link not there or not fixed, the board's link missing eye to hand (one line naming the
            URDF); an intrinsics file that cannot be read, or of another image size than the images (naming both).
        MeasurementError: DATA.csv is not a camera's (naming the file and the columns it lacks).
    """
    description = read_description(urdf, xacro_args or None)
    chain, arrangement = camera_chain(description, camera_link, board_link)
    corners, notes = read_corners(data, chain.joint_specs)
    given = None
    if intrinsics != ESTIMATE:
        given = read_intrinsics(intrinsics)
        check_image_size(given, corners.sizes, corners.images, corners.source, str(intrinsics))
    elif len(np.unique(corners.sizes, axis=0)) > 1:
        raise PincalError(f"{corners.source}: images of {len(np.unique(corners.sizes, axis=0))} sizes; one camera's "
                          "intrinsics are for one size: give the images of one resolution")
    return CameraSetup(chain, camera_link, arrangement, corners, given, tuple(notes))


def estimate_intrinsics(corners: CornerSet) -> CameraIntrinsics:
    """OpenCV's ``calibrateCamera`` on the corners of every image (Zhang's planar method, then its
    Levenberg-Marquardt on fx, fy, cx, cy, k1, k2, p1, p2, k3): the start of ``--intrinsics estimate``.

    Raises:
        CalibrationError: fewer than 3 images of 6 corners or more (a homography per image and two views to
            separate the focal length from the board's distance), or OpenCV's failure, in one line.
    """
    import cv2

    objects, pixels = [], []
    for k in range(len(corners.images)):
        mine = corners.image_of == k
        if np.count_nonzero(mine) >= 6:  # a homography needs 4 points; 6 leave it overdetermined
            objects.append(corners.board_points[mine].astype(np.float32))
            pixels.append(corners.pixels[mine].astype(np.float32))
    if len(objects) < 3:
        raise CalibrationError(f"{corners.source}: {len(objects)} image(s) with 6 corners or more; estimating the "
                               "intrinsics needs 3 at least: give more images, or --intrinsics FILE")
    width, height = (int(v) for v in corners.sizes[0])
    try:
        _, matrix, distortion, _, _ = cv2.calibrateCamera(objects, pixels, (width, height), None, None)
    except cv2.error as exc:
        raise CalibrationError(f"{corners.source}: OpenCV cannot estimate the intrinsics from these corners "
                               f"({' '.join(str(exc).split())[-120:]}); give --intrinsics FILE") from None
    k1, k2, p1, p2, k3 = (float(v) for v in np.ravel(distortion)[:5])
    return CameraIntrinsics(float(matrix[0, 0]), float(matrix[1, 1]), float(matrix[0, 2]), float(matrix[1, 2]),
                            (k1, k2, p1, p2, k3), width, height)


@dataclass(frozen=True)
class CameraCalibrationRun:
    """Outcome of :func:`calibrate_camera_files`.

    Attributes:
        result: the fit.
        report: REPORT.json as written.
        camera_info: the camera_info YAML written beside the URDF (None when withheld).
        reload_error: the largest difference of the written URDF's camera (or board) poses, reloaded [m, -].
        withheld: the model misses its corners grossly: the corrected URDF and camera_info not written.
        notes: for the user.
        html: the report's page written (``--html``), or None.
    """

    result: CameraCalibration
    report: CameraReport
    camera_info: Path | None
    reload_error: float
    withheld: bool
    notes: tuple[str, ...]
    html: Path | None = None


def _start(setup: CameraSetup, calibration: CornerSet) -> tuple[CameraIntrinsics, tuple[str, ...]]:
    """The intrinsics to start from and those fitted (all nine with ``estimate``)."""
    if setup.intrinsics is not None:
        return setup.intrinsics, ()
    return estimate_intrinsics(calibration), INTRINSIC_NAMES


def misfit_m(chain: KinematicChain, corners: CornerSet, estimate: CameraEstimate, sessions: np.ndarray,
             rms_px: float) -> float:
    """A reprojection RMS ``rms_px`` [px, per coordinate] of ``corners`` seen at the board: e [m] = e [px] · √2 · Z / f
    over both image axes (a point residual, as the sensor path's ``rms_m``), Z the corners' mean depth through
    ``chain`` as it is placed and ``estimate`` (``sessions``: each image's index into its world frames)."""
    rotations, positions = chain.tool_poses(corners.q)
    c = corners.image_of
    _, p = camera_points(estimate.arrangement, (rotations[c], positions[c]), estimate.worlds[sessions[c]],
                         estimate.mount, corners.board_points)
    focal = 0.5 * (estimate.intrinsics.fx + estimate.intrinsics.fy)
    return float(rms_px * np.sqrt(2.0) * np.mean(np.abs(p[:, 2])) / focal)


def arrangement_words(camera_link: str, board_link: str | None) -> str:
    """The camera's arrangement in words, for a refusal of images of the other one."""
    return (f"eye in hand: {camera_link} on the chain, the board fixed in the world" if board_link is None else
            f"eye to hand: {camera_link} on the root, the board on {board_link}")


def refuse_other_images(chain: KinematicChain, corners: CornerSet, estimate: CameraEstimate, sessions: np.ndarray,
                        seen_with: tuple[np.ndarray, Sequence[tuple[Effect, np.ndarray]]],
                        names: tuple[str, str | None, str, str | None]) -> list[str]:
    """Refuse held-out images the model misses grossly (:func:`pincal.fit.plausibility.gross_misfit` of the pixels
    seen at the board, :func:`misfit_m`) even with every session's world frame re-estimated on them: images of the
    other arrangement, or of another robot. A miss the re-estimated world frame removes is a board (or camera) moved
    since the calibration: a note. ``chain`` as the model places it; ``estimate``: the model's world frames (the
    fitted or reported ones: the depth the pixels are seen at is taken through them, as one re-estimated on images of
    the other arrangement can put the board metres away), mount and intrinsics; ``seen_with``: the corners' errors
    (M, 2) [px] and the joint effects applied; ``names``: DATA.csv, the REPORT.json evaluated (None: the calibration
    being run), the camera's and the board's links.

    Raises:
        PincalError: one line naming DATA.csv, the model's arrangement and what to do.
    """
    data, report, camera_link, board_link = names
    errors, effects = seen_with
    reach = reach_m(chain, corners.q)
    rms = float(np.sqrt(np.mean(errors**2)))
    if gross_misfit(misfit_m(chain, corners, estimate, sessions, rms), reach) is None:
        return []
    errors, _ = refit_worlds(chain, corners, estimate, sessions, np.unique(sessions), effects)
    refit = float(np.sqrt(np.mean(errors**2)))
    seen = misfit_m(chain, corners, estimate, sessions, refit)
    model, these = ("the calibrated model", "its held-out") if report is None else ("the corrected model", "these")
    if gross_misfit(seen, reach) is not None:
        whose, advice = (("this calibration's", "hold out images of this arrangement, or calibrate these on their own")
                         if report is None else (f"{report}'s", "evaluate them against their own calibration's report"))
        raise PincalError(f"{data}: {model} misses {these} images' corners by {refit:.4g} px RMS even with the world "
                          f"frame re-estimated ({seen * 1e3:.3g} mm at the board, beyond "
                          f"{GROSS_REACH_FRACTION * 100:g} % of the reach): not images of {whose} arrangement "
                          f"({arrangement_words(camera_link, board_link)}) or not of this robot; {advice}")
    moved = "board" if board_link is None else "camera"
    return [f"{data}: through the {'fitted' if report is None else 'reported'} world frame {model} misses {these} "
            f"corners by {rms:.4g} px RMS, with it re-estimated by {refit:.4g} px: has the {moved} moved since the "
            "calibration? " + ("hold out images of the calibration's placement" if report is None else
                               "--new-session re-estimates it")]


def _misfit_m(result: CameraCalibration, chain: KinematicChain, calibration: CornerSet) -> float:
    """The calibration corners' RMS reprojection error seen at the board (:func:`misfit_m`)."""
    session = {name: s for s, name in enumerate(result.session_names)}
    sessions = np.array([session.get(str(n), 0) for n in calibration.sessions], dtype=np.intp)
    with chain.placed(list(result.chain_placements)):
        return misfit_m(chain, calibration, result.estimate, sessions, result.rms_px)


def _write_urdf(urdf: Path, out_urdf: Path, setup: CameraSetup, result: CameraCalibration, comment: str,
                xacro_args: tuple[tuple[str, str], ...], keep: bool) -> tuple[float, str]:
    """Write the corrected URDF (the chain's placements, the mount and, eye to hand, the camera in the world),
    checked on reloading: its tip link's poses at the images' configurations, and the camera's link in the
    root's frame, within :data:`pincal.workflows.verdict.RELOAD_TOLERANCE`. Returns that difference and the
    file's SHA-256."""
    chain, arrangement = setup.chain, setup.arrangement
    nominal = chain.placements()
    with chain.placed(list(result.corrected_placements)):
        origins = corrected_origins(urdf, chain, nominal, xacro_args or None)
        wanted = chain.tool_poses(setup.corners.q)
    description = read_description(urdf, xacro_args or None)
    camera_in_root = None
    if arrangement == "eye_to_hand":  # W = camera_T_base: the camera's link where inv(W) puts it
        camera_in_root = np.linalg.inv(result.estimate.worlds[0])
        joint, origin = world_link_origin(description, setup.camera_link, camera_in_root)
        origins[joint] = origin

    def difference(written: Path) -> float:
        reloaded = KinematicChain.from_urdf(written, chain.tip_link)
        rotations, positions = reloaded.tool_poses(setup.corners.q)
        error = max(np.abs(rotations - wanted[0]).max(), np.abs(positions - wanted[1]).max())
        if camera_in_root is not None:
            model = pin.buildModelFromUrdf(str(written))  # the camera hangs from the root: its frame's placement
            placed = model.frames[model.getFrameId(setup.camera_link, pin.FrameType.BODY)].placement.homogeneous
            error = max(error, np.abs(placed - camera_in_root).max())
        return float(error)

    return write_urdf_checked_by(UrdfWrite(urdf, out_urdf, comment, xacro_args, keep), origins, difference,
                                 "the camera")


@dataclass(frozen=True)
class CameraPaths:
    """The files of a camera's run: the URDF, DATA.csv, the corrected URDF and REPORT.json to write; ``validation``:
    held-out images of another file (None: DATA.csv's of role ``validation``); ``effects``: the run writes an
    effects.yaml beside the URDF (``diagnose``); ``html``: the report's page to write (``--html``), or None."""

    urdf: Path
    data: Path
    out_urdf: Path
    report: Path
    validation: Path | None = None
    effects: bool = False
    html: Path | None = None


@dataclass(frozen=True)
class CameraFit:
    """A camera's calibration before anything is written: the inputs read, the fit, its calibration and held-out
    images, the intrinsics fitted, notes and the fit's time [s]."""

    setup: CameraSetup
    result: CameraCalibration
    calibration: CornerSet
    validation: CornerSet
    fitted: tuple[str, ...]
    notes: tuple[str, ...]
    seconds: float


@dataclass(frozen=True)
class CameraModel:
    """What a camera's run writes: the model (``result``; the fit's, or ``diagnose``'s final one), the joint effects
    its errors apply (eq C4 of :mod:`pincal.residuals.camera`), and what completes its report (None: nothing)."""

    result: CameraCalibration
    effects: tuple[tuple[Effect, np.ndarray], ...] = ()
    extend: Callable[[CameraReport], CameraReport] | None = None


def fit_camera(paths: CameraPaths, settings: CameraCalibrateSettings) -> CameraFit:
    """Refuse outputs that are inputs, read the inputs and calibrate (:func:`calibrate_camera_files`'s first half).

    Raises:
        PincalError: the inputs' one-line errors (:func:`load_camera`), an output path that is an input, fewer
            than 3 calibration images, a fit the images cannot determine.
    """
    info_path = camera_info_path(paths.out_urdf)
    inputs = [*description_inputs(paths.urdf, settings.xacro_args), paths.data] + (
        [paths.validation] if paths.validation else [])
    if isinstance(settings.intrinsics, Path):
        inputs.append(settings.intrinsics)
    refuse_overwrite(paths.out_urdf, *inputs)
    refuse_overwrite(paths.report, *inputs, outputs=[paths.out_urdf])
    refuse_overwrite(info_path, *inputs, outputs=[paths.out_urdf, paths.report])
    if paths.effects:
        refuse_overwrite(effects_path(paths.out_urdf), *inputs, outputs=[paths.out_urdf, paths.report, info_path])
    refuse_page(paths.html, inputs, [paths.out_urdf, paths.report, info_path]
                + ([effects_path(paths.out_urdf)] if paths.effects else []))
    setup = load_camera(paths.urdf, paths.data, settings.camera_link, settings.board_link, settings.intrinsics,
                        settings.xacro_args)
    chain, corners = setup.chain, setup.corners
    notes = list(setup.notes)
    calibration = images_of(corners, corners.roles != "validation")
    if len(calibration.images) < 3:
        raise PincalError(f"{corners.source}: {len(calibration.images)} calibration image(s) (role 'validation' is "
                          "held out); a camera calibration needs at least 3, about axes not parallel")
    started = time.perf_counter()
    intrinsics, fitted = _start(setup, calibration)
    start, sessions = hand_eye_start(chain, calibration, setup.arrangement, intrinsics)
    result = calibrate_camera(chain, calibration, start, settings.level,
                              CameraFitOptions(intrinsics=fitted, selection=settings.criterion), sessions)
    seconds = time.perf_counter() - started
    validation = images_of(corners, corners.roles == "validation")
    if paths.validation is not None:
        validation, held_notes = read_corners(paths.validation, chain.joint_specs)
        notes += held_notes
        check_image_size(result.estimate.intrinsics, validation.sizes, validation.images, validation.source,
                         str(settings.intrinsics))
    unseen = sorted({str(s) for s in validation.sessions} - set(sessions))
    if unseen:
        notes.append(f"{validation.source}: session(s) {', '.join(unseen)} have validation images only: no world "
                     "frame was fitted for them, so their images are left out of the report's errors")
        validation = images_of(validation, np.isin(validation.sessions.astype(str), sessions))
    if len(validation.images):  # held-out images of another arrangement or robot would judge nothing
        held = image_sessions(validation, result.session_names, len(result.estimate.worlds))
        with chain.placed(list(result.chain_placements)):
            errors, _ = refit_worlds(chain, validation, result.estimate, held, np.array([], dtype=np.intp))
            notes += refuse_other_images(chain, validation, result.estimate, held, (errors, ()),
                                         (validation.source, None, settings.camera_link, settings.board_link))
    if setup.arrangement == "eye_to_hand" and len(sessions) > 1:
        notes.append(f"{len(sessions)} sessions: the corrected URDF places {settings.camera_link} where session "
                     f"'{sessions[0]}' saw it; every session's camera pose is in REPORT.json camera.worlds")
    return CameraFit(setup, result, calibration, validation, fitted, tuple(notes), seconds)


def calibrate_camera_files(urdf: str | Path, data: str | Path, out_urdf: str | Path, report_path: str | Path,
                           settings: CameraCalibrateSettings, html: str | Path | None = None) -> CameraCalibrationRun:
    """Calibrate ``urdf`` from a camera's ``data`` (DATA.csv, as detect writes it) as ``settings`` say; write the
    corrected URDF, its camera_info YAML (:func:`camera_info_path`), REPORT.json (module docstring) and, given
    ``html``, the report's page (:mod:`pincal.workflows.report_page`: the camera's section draws the image of
    REPORT.json's ``camera.picture`` from ``settings.images``).

    Raises:
        PincalError: the inputs' one-line errors (:func:`load_camera`), an output path that is an input, fewer
            than 3 calibration images, a fit the images cannot determine.
    """
    expect(settings, CameraCalibrateSettings, "calibrate_camera_files")
    paths = CameraPaths(Path(urdf), Path(data), Path(out_urdf), Path(report_path),
                        html=None if html is None else Path(html))
    fit = fit_camera(paths, settings)
    return write_camera_run(paths, settings, fit, CameraModel(fit.result))


def write_camera_run(paths: CameraPaths, settings: CameraCalibrateSettings, fit: CameraFit,
                     model: CameraModel) -> CameraCalibrationRun:
    """Write ``model``'s corrected URDF, camera_info, effects.yaml (``paths.effects``) and REPORT.json, or withhold
    the URDF, camera_info and effects.yaml of a model that misses its corners grossly (module docstring)."""
    setup, chain, result = fit.setup, fit.setup.chain, model.result
    urdf, data, out_urdf, report_path = paths.urdf, paths.data, paths.out_urdf, paths.report
    info_path = camera_info_path(out_urdf)
    notes = list(fit.notes)
    gross = gross_misfit(_misfit_m(result, chain, fit.calibration), reach_m(chain, fit.calibration.q))
    warnings, withheld = withholding([] if gross is None else [gross], settings.force)
    if not paths.effects:  # what is withheld beside a camera's URDF is its camera_info, not an effects.yaml
        warnings = [replace(w, message=w.message.replace("nor its effects.yaml", "nor its camera_info YAML"))
                    for w in warnings]
    comment = (f"Calibrated by pincal {__version__} (camera {setup.arrangement.replace('_', ' ')}, level "
               f"{result.level}{', diagnose' if paths.effects else ''}) from {urdf.name} and {data.name}. World "
               "frame, intrinsics" + (" and effects (which a URDF cannot carry)" if paths.effects else "")
               + ": see the report.")
    reload_error, urdf_sha256 = _write_urdf(urdf, out_urdf, setup, result, comment, settings.xacro_args,
                                            keep=not withheld)
    if withheld:
        removed = withhold(out_urdf)
        if info_path.is_file():
            info_path.unlink()
            removed.append(f"removed {info_path}, left by an earlier run")
        notes += removed
    nominal = _nominal(fit.result)
    errors = {role: (corners, reprojection_errors(chain, result, corners, model.effects),
                     reprojection_errors(chain, nominal, corners))
              for role, corners in (("calibration", fit.calibration), ("validation", fit.validation))}
    sources: CameraSources = {"urdf": str(urdf), "data": str(data), "corrected_urdf": str(out_urdf),
                              "intrinsics": str(settings.intrinsics), "camera_info": str(info_path),
                              "images": str(settings.images if settings.images is not None else data.parent)}
    if paths.validation is not None:
        sources["validation"] = str(paths.validation)
    if withheld:
        sources["corrected_urdf_withheld"] = True  # the paths name no file of this run
    record = CameraRecord(settings.camera_link, settings.board_link, errors, sources, notes + list(result.notes),
                          findings_json(warnings), urdf_sha256, dict(xacro_arguments(settings.xacro_args)),
                          fit.seconds, fit.fitted)
    report = camera_report(result, chain, record)
    if model.extend is not None:
        report = model.extend(report)
    page = render_page(paths.html, report, report_path)  # made before the report and camera_info are written
    camera_info = None
    if not withheld:
        write_camera_info(info_path, result.estimate.intrinsics, camera_name=settings.camera_link)
        camera_info = info_path
    if paths.effects and not withheld:
        write_effects_file(out_urdf, report_path, report)
    write_report(report_path, report)
    return CameraCalibrationRun(result, report, camera_info, reload_error, withheld, tuple(notes),
                                write_page(paths.html, page))


def _nominal(result: CameraCalibration) -> CameraCalibration:
    """The "before" model: the nominal kinematics with their own fitted mount and world frame (level
    registration's answer, OpenCV's hand-eye refined by reprojection)."""
    return replace(result, params=None, vector=np.zeros(0), estimate=result.nominal)
