"""``pincal evaluate CORRECTED.urdf REPORT.json DATA.csv`` of a camera's report: each image's corners reprojected
before and after (:func:`evaluate_camera_files`), the errors in pixels, and the relative poses between images.

After: the corrected URDF (kinematics, mount and, eye to hand, the camera in the world) with its camera_info YAML
(beside it, else the report's ``sources.camera_info``). Before: the nominal URDF (``--nominal``, else the report's
``sources.urdf``) with the mount, world frame and intrinsics the calibration fitted to the nominal kinematics
(OpenCV's hand-eye refined by reprojection: what hand-eye tools give). The world frame -- the board in the world eye
in hand, the camera eye to hand -- is the report's for a session it has; with ``--new-session``, or for a session
it lacks, it is re-estimated on the evaluated images (6 unknowns per session, by Gauss-Newton on eq C3 with the
model fixed), for either model. Images the corrected model misses grossly (the pixels seen at the board beyond
5 % of the reach, as calibrate withholds a model) even with every world frame re-estimated are refused: no moved
board or camera explains them, they are of the other arrangement or another robot.

Then the relative poses (:mod:`pincal.fit.camera_motion`): between consecutive images of each session, the camera's
(eye in hand) or the board's (eye to hand) motion as each model predicts it, against the motion the images measure
(each image's board pose by PnP with the corrected intrinsics, the same measured motions for both models), in mm
and degrees, with the floor of that comparison: what the corners' noise (the PnP residuals') leaves in the measured
motion, a perfect model's RMS error. The PnP pose errs about the board's in-plane axes by far more than the
reprojection it comes from, so the floor is often above both models' errors (millimetres at a camera 0.5 m from a
28 x 20 cm board at 0.2 px): the verdict then says the images cannot tell the models apart by relative pose, and
the pixels are the measure. No world frame enters the motions.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import cast

import numpy as np
import pinocchio as pin

from pincal.errors import PincalError
from pincal.fit.camera_calibration import mounted_frames, refit_worlds
from pincal.fit.camera_motion import measured_motions, motion_errors, relative_motions
from pincal.measurements.camera_csv import CornerSet, read_corners
from pincal.model.camera_chain import camera_chain
from pincal.model.camera_info import check_image_size, read_intrinsics
from pincal.model.camera_view import Arrangement
from pincal.model.description import read_description
from pincal.model.effects import effect_from_dict
from pincal.outputs import file_sha256, write_text
from pincal.report.camera import (
    frame_matrix,
    image_errors_json,
    intrinsics_from_json,
    picture_json,
    relative_pose_json,
    reprojection_json,
)
from pincal.report.document import write_evaluation
from pincal.report.model_camera import CameraEvaluationJson, CameraReport, FrameJson
from pincal.report.reading import load_report
from pincal.residuals.camera import CameraEstimate
from pincal.workflows.camera_calibration import camera_info_path, refuse_other_images
from pincal.workflows.paths import description_inputs, refuse_overwrite
from pincal.workflows.report_page import refuse_page

__all__ = ["CameraEvaluateSettings", "CameraEvaluation", "evaluate_camera_files"]


@dataclass(frozen=True)
class CameraEvaluateSettings:
    """``pincal evaluate`` of a camera's report without its paths.

    Attributes:
        new_session: re-estimate every session's world frame on the evaluated images (the board or the camera
            moved since the calibration).
        allow_other_urdf: accept a URDF other than the one written with the report.
        nominal: the uncalibrated URDF, for "before" (None: the report's ``sources.urdf``).
        xacro_args: ``NAME:=VALUE`` pairs of a ``.xacro`` nominal URDF (default: the report's).
    """

    new_session: bool = False
    allow_other_urdf: bool = False
    nominal: Path | None = None
    xacro_args: tuple[tuple[str, str], ...] = ()


@dataclass(frozen=True)
class CameraEvaluation:
    """Outcome of :func:`evaluate_camera_files`: ``document`` (``--json``'s), notes, and the files written: ``--json``'s
    and ``--html``'s (or None)."""

    document: CameraEvaluationJson
    notes: tuple[str, ...]
    written: Path | None
    html: Path | None = None


def _session_indices(corners: CornerSet, names: list[str], new_session: bool
                     ) -> tuple[np.ndarray, list[str], list[str]]:
    """Each image's world frame (K,) among the report's sessions then the new ones, the new ones' names, and every
    session's name in that order."""
    seen = [str(s) for s in dict.fromkeys(corners.sessions.astype(str))]
    new = seen if new_session else [s for s in seen if s not in names]
    order = ([] if new_session else list(names)) + new
    index = {name: i for i, name in enumerate(order)}
    return np.array([index[str(s)] for s in corners.sessions], dtype=np.intp), new, order


def evaluate_camera_files(urdf: str | Path, report_path: str | Path, data: str | Path,
                          settings: CameraEvaluateSettings = CameraEvaluateSettings(),
                          json_path: str | Path | None = None, html_path: str | Path | None = None) -> CameraEvaluation:
    """Reproject the corners of ``data`` through the corrected ``urdf`` and the nominal one, and compare the motions
    between its images (module docstring);
    write ``json_path`` (``--json``) and ``html_path`` (``--html``: the report's page with these images' errors, the
    picture drawn from the image files beside ``data``) if given.

    Raises:
        PincalError: one line naming the file: the report is not a camera's, the URDF not the report's (without
            ``allow_other_urdf``), its camera or board link missing, the camera_info or nominal URDF missing,
            images of another size than the intrinsics, DATA.csv not a camera's, images the corrected model misses
            grossly even with their world frames re-estimated (the other arrangement's, another robot's).
    """
    urdf, report_path, data = Path(urdf), Path(report_path), Path(data)
    report = cast(CameraReport, load_report(report_path, accept=("camera",),
                                            hint="pass the REPORT.json of calibrate --camera-link"))
    if json_path is not None:
        json_path = Path(json_path)
        refuse_overwrite(json_path, *description_inputs(urdf), report_path, data)
    html_path = refuse_page(html_path, [*description_inputs(urdf), report_path, data],
                            [] if json_path is None else [json_path])
    notes: list[str] = []
    if file_sha256(urdf) != report["urdf_sha256"]:
        if not settings.allow_other_urdf:
            raise PincalError(f"{urdf}: not the URDF {report_path} was written with (its SHA-256 differs from the "
                              "report's urdf_sha256); evaluate the pair calibrate wrote, or pass --allow-other-urdf "
                              "if you changed it on purpose")
        notes.append(f"{urdf}: not the URDF {report_path} was written with (--allow-other-urdf)")
    camera = report["camera"]
    arrangement = cast(Arrangement, camera["arrangement"])
    after_chain, _ = camera_chain(read_description(urdf), camera["camera_link"], camera["board_link"])
    corners, read_notes = read_corners(data, after_chain.joint_specs)
    notes += read_notes
    beside = camera_info_path(urdf)
    info = beside if beside.is_file() else Path(report["sources"]["camera_info"])
    if not info.is_file():
        raise PincalError(f"{report_path}: no camera_info beside {urdf} ({beside.name}) nor at {info}; put the "
                          "camera_info YAML calibrate wrote beside the corrected URDF")
    after_intrinsics = read_intrinsics(info)
    check_image_size(after_intrinsics, corners.sizes, corners.images, corners.source, str(info))
    nominal = settings.nominal or Path(report["sources"]["urdf"])
    if not nominal.is_file():
        raise PincalError(f"{report_path}: the nominal URDF {nominal} (sources.urdf) is not there; give it with "
                          "--nominal URDF, for the errors before calibration")
    xacro = settings.xacro_args or tuple(report["xacro_args"].items())
    before_chain, _ = camera_chain(read_description(nominal, xacro or None), camera["camera_link"],
                                   camera["board_link"])
    names = list(camera["sessions"])
    trained = int(np.count_nonzero(corners.roles != "validation"))
    if trained:
        notes.append(f"{data}: {trained} of the {len(corners.images)} images have a role other than validation: if "
                     "the calibration used them, their errors are not held out")
    sessions, new, order = _session_indices(corners, names, settings.new_session)
    refit = np.array([order.index(n) for n in new], dtype=np.intp)
    if new:
        notes.append(f"world frame re-estimated on these images for session(s) {', '.join(new)}"
                     + (" (--new-session)" if settings.new_session else " (not in the report)"))
    after_worlds = _reported_worlds(camera["worlds"], arrangement, str(report_path))
    before_worlds = _reported_worlds(camera["nominal_worlds"], arrangement, str(report_path))
    if arrangement == "eye_to_hand":  # the corrected URDF places the camera: W from it, as calibrated
        model = pin.buildModelFromXML(read_description(urdf).text)
        root_T_camera = model.frames[model.getFrameId(camera["camera_link"], pin.FrameType.BODY)].placement.homogeneous
        after_worlds[0] = np.linalg.inv(root_T_camera)
    # a new session's world frame starts from the first reported one
    start_after = ([] if settings.new_session else after_worlds) + [after_worlds[0]] * len(new)
    start_before = ([] if settings.new_session else before_worlds) + [before_worlds[0]] * len(new)
    after = CameraEstimate(arrangement, np.array(start_after), np.eye(4), after_intrinsics)
    before_mount = frame_matrix(camera["nominal_mount"], f"{report_path}: camera.nominal_mount")
    before = CameraEstimate(arrangement, np.array(start_before), np.eye(4),
                            intrinsics_from_json(camera["nominal_intrinsics"], f"{report_path}: camera"))
    effects = [effect_from_dict(entry) for entry in report.get("effects") or []]  # diagnose's, applied after
    after_px, _ = refit_worlds(after_chain, corners, after, sessions, refit, effects)
    notes += refuse_other_images(after_chain, corners, after, sessions, (after_px, effects),
                                 (str(data), str(report_path), camera["camera_link"], camera["board_link"]))
    placements = before_chain.placements()
    with before_chain.placed([*placements[:-1], before_mount]):  # the hand-eye mount on the nominal chain
        before_px, _ = refit_worlds(before_chain, corners, before, sessions, refit)
        before_frames = mounted_frames(before_chain, corners, np.eye(4))
    # the same measured motions judge both models: PnP with the corrected intrinsics
    measured = measured_motions(corners, after_intrinsics, arrangement)
    errors = tuple(motion_errors(relative_motions(frames, measured.pairs), measured.motions)
                   for frames in (before_frames, mounted_frames(after_chain, corners, np.eye(4), effects)))
    document: CameraEvaluationJson = {
        "urdf": str(urdf), "report": str(report_path), "data": str(data), "camera_info": str(info),
        "world": "re-estimated" if new else "reported",
        "reprojection": {"before": reprojection_json(corners, before_px),
                         "after": reprojection_json(corners, after_px)},
        "images": image_errors_json(corners, after_px, before_px),
        "picture": picture_json(corners, after_px),
        "relative_pose": relative_pose_json(corners, measured, (errors[0], errors[1]),
                                            "camera" if arrangement == "eye_in_hand" else "board"),
    }
    page = None
    if html_path is not None:  # made before anything is written
        from pincal.report.camera_html import camera_page
        from pincal.report.html import render_html

        page = render_html(dict(report), camera=camera_page(report, document), source=report_path)
    if json_path is not None:
        write_evaluation(json_path, document)
    if page is not None and html_path is not None:
        write_text(html_path, page)
    return CameraEvaluation(document, tuple(notes), json_path, html_path)


def _reported_worlds(frames: list[FrameJson], arrangement: Arrangement, where: str) -> list[np.ndarray]:
    """The report's world frames as W (:mod:`pincal.model.camera_view`): the board in the root eye in hand, the
    inverse of the camera in the root eye to hand."""
    out = [frame_matrix(f, f"{where}: camera.worlds") for f in frames]
    return out if arrangement == "eye_in_hand" else [np.linalg.inv(w) for w in out]

