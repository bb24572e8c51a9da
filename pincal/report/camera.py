"""A camera's REPORT.json (:class:`pincal.report.model_camera.CameraReport`) built from its calibration, and its
frames and intrinsics read back for ``evaluate``."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from pincal._version import __version__
from pincal.errors import PincalError
from pincal.fit.camera_calibration import CameraCalibration
from pincal.fit.camera_motion import MeasuredMotions, within_floor
from pincal.measurements.camera_csv import CornerSet
from pincal.model.camera_view import pose
from pincal.model.chain import KinematicChain
from pincal.model.pinhole import CameraIntrinsics
from pincal.report.document import REPORT_VERSION, chain_summary, identifiability_report, parameters_report
from pincal.report.model import Finding
from pincal.report.model_camera import (
    CameraReport,
    CameraSources,
    FrameJson,
    ImageErrorJson,
    IntrinsicsJson,
    MotionRmsJson,
    PictureJson,
    RelativePoseJson,
    ReprojectionJson,
    ReprojectionPair,
)

__all__ = ["ImageErrors", "CameraRecord", "frame_json", "frame_matrix", "intrinsics_json", "intrinsics_from_json",
           "reprojection_json", "image_errors_json", "picture_json", "relative_pose_json", "cannot_see",
           "camera_report"]

#: A set of images with each corner's error after and before (M, 2) [px] each.
ImageErrors = tuple[CornerSet, np.ndarray, np.ndarray]
#: Decimals of a corner's error length in REPORT.json [px]: 1e-4 px, a thousandth of a ChArUco corner's
#: detection noise (~0.1 px, docs/camera.md), keeps 60 images of 24 corners to ~30 kB of indented JSON.
ERROR_DECIMALS = 4


def frame_json(parent: str, child: str, transform: np.ndarray) -> FrameJson:
    """``parent_T_child`` (4, 4) [m] as the report writes it."""
    quat = Rotation.from_matrix(transform[:3, :3]).as_quat()  # scalar-last
    return {"parent": parent, "child": child, "translation_m": [float(v) for v in transform[:3, 3]],
            "rotation_xyzw": [float(v) for v in quat]}


def frame_matrix(frame: Mapping[str, Any], where: str) -> np.ndarray:
    """Inverse of :func:`frame_json` (4, 4); one line naming ``where`` when malformed."""
    try:
        rotation = Rotation.from_quat(np.asarray(frame["rotation_xyzw"], dtype=float)).as_matrix()
        return pose(rotation, np.asarray(frame["translation_m"], dtype=float).reshape(3))
    except (KeyError, TypeError, ValueError) as exc:
        raise PincalError(f"{where}: not a frame with rotation_xyzw and translation_m ({exc})") from None


def intrinsics_json(intrinsics: CameraIntrinsics, fitted: Sequence[str]) -> IntrinsicsJson:
    return {"fx": intrinsics.fx, "fy": intrinsics.fy, "cx": intrinsics.cx, "cy": intrinsics.cy,
            "distortion": [float(v) for v in intrinsics.distortion], "width": int(intrinsics.width),
            "height": int(intrinsics.height), "fitted": list(fitted)}


def intrinsics_from_json(value: Mapping[str, Any], where: str) -> CameraIntrinsics:
    """Inverse of :func:`intrinsics_json`; one line naming ``where`` when malformed."""
    try:
        k1, k2, p1, p2, k3 = (float(v) for v in value["distortion"])
        return CameraIntrinsics(float(value["fx"]), float(value["fy"]), float(value["cx"]), float(value["cy"]),
                                (k1, k2, p1, p2, k3), int(value["width"]), int(value["height"]))
    except (KeyError, TypeError, ValueError) as exc:
        raise PincalError(f"{where}: not the intrinsics fx, fy, cx, cy, distortion, width, height ({exc})") from None


def reprojection_json(corners: CornerSet, errors: np.ndarray) -> ReprojectionJson:
    """RMS per coordinate and the largest distance [px] of ``errors`` (M, 2), null without corners."""
    empty = errors.size == 0
    return {"images": len(corners.images), "corners": len(errors),
            "rms_px": None if empty else float(np.sqrt(np.mean(errors**2))),
            "max_px": None if empty else float(np.linalg.norm(errors, axis=1).max())}


def image_errors_json(corners: CornerSet, after: np.ndarray, before: np.ndarray) -> list[ImageErrorJson]:
    """Each image's RMS per coordinate before and after [px] (an image without corners left out)."""
    out: list[ImageErrorJson] = []
    for k, name in enumerate(corners.images):
        mine = corners.image_of == k
        if np.any(mine):
            out.append({"image": name, "role": str(corners.roles[k]), "session": str(corners.sessions[k]),
                        "corners": int(np.count_nonzero(mine)),
                        "before_rms_px": float(np.sqrt(np.mean(before[mine] ** 2))),
                        "after_rms_px": float(np.sqrt(np.mean(after[mine] ** 2))),
                        "errors_px": [round(float(v), ERROR_DECIMALS) for v in np.linalg.norm(after[mine], axis=1)]})
    return out


def picture_json(corners: CornerSet, after: np.ndarray) -> PictureJson | None:
    """The image the HTML page draws (:class:`pincal.report.model_camera.PictureJson`): of ``corners``, the one with
    the largest RMS of ``after`` (M, 2) [px] (eq C3: reprojected minus detected); None without corners."""
    counts = np.bincount(corners.image_of, minlength=len(corners.images))
    if not counts.any():
        return None
    sums = np.bincount(corners.image_of, weights=np.sum(after**2, axis=1), minlength=len(corners.images))
    k = int(np.argmax(np.where(counts > 0, sums / np.maximum(counts, 1), -1.0)))
    mine = corners.image_of == k
    width, height = (int(v) for v in corners.sizes[k])
    return {"image": corners.images[k], "role": str(corners.roles[k]), "width": width, "height": height,
            "detected_px": corners.pixels[mine].tolist(),
            "reprojected_px": (corners.pixels[mine] + after[mine]).tolist()}


def _rms(errors: np.ndarray) -> MotionRmsJson | None:
    if not len(errors):
        return None
    mm, deg = np.sqrt(np.mean(errors**2, axis=0))
    return {"mm": float(mm), "deg": float(deg)}


def relative_pose_json(corners: CornerSet, measured: MeasuredMotions, errors: tuple[np.ndarray, np.ndarray],
                       frame: str) -> RelativePoseJson:
    """The ``relative_pose`` of ``evaluate --json`` (:class:`pincal.report.model_camera.RelativePoseJson`): the
    ``frame``'s (``camera`` or ``board``) relative-pose ``errors`` before and after (P, 2) each [mm, deg] of the
    pairs ``measured`` (eqs R1-R6 of :mod:`pincal.fit.camera_motion`)."""
    before, after = errors
    placed = np.ones(len(corners.images), dtype=bool)
    placed[[corners.images.index(name) for name in measured.unplaced]] = False
    sessions = [str(s) for s in dict.fromkeys(corners.sessions.astype(str))]
    no_pairs = [s for s in sessions if np.count_nonzero(placed & (corners.sessions.astype(str) == s)) < 2]
    inside = within_floor(before, measured.floor), within_floor(after, measured.floor)
    if not len(measured.pairs):
        verdict = "no pairs: no session has 2 evaluated images whose board pose PnP can measure"
    elif all(inside):
        verdict = "the images cannot tell these models apart by relative pose"
    elif any(inside):
        verdict = (f"{'after' if inside[1] else 'before'} agrees with the images to their floor, "
                   f"{'before' if inside[1] else 'after'} does not")
    else:
        verdict = "neither model agrees with the images to their floor"
    return {
        "frame": "camera" if frame == "camera" else "board", "noise_px": measured.noise_px,
        "pairs": [{"first": corners.images[j], "second": corners.images[k], "session": str(corners.sessions[k]),
                   "before_mm": float(b[0]), "before_deg": float(b[1]), "after_mm": float(a[0]),
                   "after_deg": float(a[1]), "floor_mm": float(f[0]), "floor_deg": float(f[1])}
                  for (j, k), b, a, f in zip(measured.pairs, before, after, measured.floor)],
        "before": _rms(before), "after": _rms(after), "floor": _rms(measured.floor),
        "before_within_floor": inside[0], "after_within_floor": inside[1], "verdict": verdict,
        "no_pairs": no_pairs, "unplaced": list(measured.unplaced),
    }


def cannot_see(result: CameraCalibration, chain: KinematicChain) -> list[str]:
    """What one camera cannot determine, in words: the directions the fit hands to the mount and the world frame."""
    eye_in_hand = result.estimate.arrangement == "eye_in_hand"
    world = "the board's pose in the world" if eye_in_hand else "the camera's pose in the world"
    carried = "camera" if eye_in_hand else "board"
    words = [f"where the robot stands: the images show the {carried}'s motion relative to the "
             f"{'board' if eye_in_hand else 'camera'}, so the base's place and the first joint's placement and "
             f"zero move everything as {world} does, and are fitted as {world}",
             f"the last link's placement apart from the {carried}'s mount ({chain.tip_link}'s fixed joint): one "
             "camera sees the two only together, and the corrected URDF writes them as one origin"]
    if result.params is not None and result.dropped:
        names = sorted({result.params.info[d.index].name for d in result.dropped})
        words.append(f"{len(names)} kinematic parameter(s) not determined by these images, held at nominal: "
                     "identifiability.dropped names each and the parts that absorb it")
    return words


@dataclass(frozen=True)
class CameraRecord:
    """What a camera's REPORT.json records of the run beside the fit.

    Attributes:
        camera_link / board_link: the links named (board_link None eye in hand).
        errors: ``calibration`` and ``validation`` images with each corner's error after and before [px].
        sources: the files; notes and warnings: for the user (warnings: the plausibility findings).
        urdf_sha256: of the corrected URDF's bytes; xacro_args: of the description.
        seconds: the fit's time, start included [s]; fitted: the intrinsics estimated (their names).
    """

    camera_link: str
    board_link: str | None
    errors: Mapping[str, ImageErrors]
    sources: CameraSources
    notes: list[str]
    warnings: list[Finding]
    urdf_sha256: str
    xacro_args: dict[str, str]
    seconds: float
    fitted: Sequence[str] = ()


def camera_report(result: CameraCalibration, chain: KinematicChain, record: CameraRecord) -> CameraReport:
    """REPORT.json of a camera's calibration (``chain`` as loaded: the nominal placements)."""
    camera_link, board_link = record.camera_link, record.board_link
    estimate, nominal = result.estimate, result.nominal
    root, last_joint = chain.root_link, chain.joint_names[-1]
    carried = camera_link if estimate.arrangement == "eye_in_hand" else (board_link or "board")
    world_child = "board" if estimate.arrangement == "eye_in_hand" else camera_link
    names = result.session_names or ("session",)

    def worlds(frames: np.ndarray) -> list[FrameJson]:
        # eye to hand W = camera_T_base: the camera in the root is its inverse
        return [frame_json(root, f"{world_child}[{n}]" if len(names) > 1 else world_child,
                           w if estimate.arrangement == "eye_in_hand" else np.linalg.inv(w))
                for n, w in zip(names, frames)]

    fitted_names = list(record.fitted)
    return {
        "pincal_version": __version__, "report_version": REPORT_VERSION, "method": None, "level": result.level,
        "model": "joint placements", "measurement": "camera", "sources": record.sources, "chain": chain_summary(chain),
        "parameters": parameters_report(result), "identifiability": identifiability_report(result),
        "camera": {
            "arrangement": estimate.arrangement, "camera_link": camera_link, "board_link": board_link,
            "mount": frame_json(last_joint, carried, result.tip_placement),
            "nominal_mount": frame_json(last_joint, carried, chain.placements()[-1] @ nominal.mount),
            "sessions": list(result.session_names), "worlds": worlds(estimate.worlds),
            "nominal_worlds": worlds(nominal.worlds),
            "intrinsics": intrinsics_json(estimate.intrinsics, fitted_names),
            "nominal_intrinsics": intrinsics_json(nominal.intrinsics, fitted_names),
            "cannot_see": cannot_see(result, chain),
            "reprojection": {role: _pair(images, after, before)
                             for role, (images, after, before) in record.errors.items()},
            "images": [entry for images, after, before in record.errors.values()
                       for entry in image_errors_json(images, after, before)],
            "picture": picture_json(*record.errors["calibration"][:2]),
        },
        "fit_seconds": record.seconds, "notes": record.notes, "warnings": record.warnings,
        "urdf_sha256": record.urdf_sha256, "xacro_args": record.xacro_args,
    }


def _pair(corners: CornerSet, after: np.ndarray, before: np.ndarray) -> ReprojectionPair:
    return {"before": reprojection_json(corners, before), "after": reprojection_json(corners, after)}
