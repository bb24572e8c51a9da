"""The page of a camera's REPORT.json (``calibrate --camera-link``), from the report alone: what
``calibrate --html`` writes and ``pincal report`` redraws alike.

:func:`camera_page` reads the report's ``camera`` block into the values of ``camera.html.j2``: a card per role
(calibration and validation images) with the RMS per coordinate (u, v) before → after [px], as the terminal prints
it; the camera's facts (arrangement, mount, world frame of each session, intrinsics); each image's row (its RMS per
coordinate before and after, and its corners' error lengths ‖e‖ [px] from ``errors_px``, drawn as a box per image);
and the picture of ``camera.picture`` (its corners as detected and reprojected), drawn on the image file when
``sources.images`` holds a file of that name and size, else on a blank image of its size. ``evaluate --html`` adds
the evaluated images' card and, among the facts, their relative poses (RMS before, after and the floor, the verdict).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from pincal.report.camera_figures import CameraImages, section_values
from pincal.report.sections import num

__all__ = ["is_camera", "camera_title", "camera_page"]


def is_camera(document: Mapping[str, Any]) -> bool:
    """Whether ``document`` is a camera's REPORT.json (:func:`pincal.report.reading.document_kind`'s test)."""
    return document.get("measurement") == "camera" and isinstance(document.get("camera"), dict)


def camera_title(document: Mapping[str, Any]) -> str:
    """The page's kind: ``Camera calibration (full, eye in hand)``."""
    return f"Camera calibration ({document.get('level')}, {str(document['camera']['arrangement']).replace('_', ' ')})"


def _frame_text(frame: Mapping[str, Any]) -> str:
    """``child in parent: x, y, z mm; rotation r deg about (ax, ay, az)``."""
    xyz = ", ".join(num(1000.0 * float(v), 5) for v in frame["translation_m"])
    rotvec = Rotation.from_quat(np.asarray(frame["rotation_xyzw"], dtype=float)).as_rotvec()
    angle = float(np.linalg.norm(rotvec))
    about = ", ".join(num(float(v), 3) for v in rotvec / angle) if angle > 0 else "—"
    return f"{frame['child']} in {frame['parent']}: ({xyz}) mm; rotation {num(math.degrees(angle), 5)}° about ({about})"


def _facts(document: Mapping[str, Any]) -> list[tuple[str, str]]:
    camera, sources = document["camera"], document.get("sources") or {}
    eye_in_hand = camera["arrangement"] == "eye_in_hand"
    facts = [("camera", f"{str(camera['arrangement']).replace('_', ' ')}: {camera['camera_link']}"
              + ("" if eye_in_hand else f", the board on {camera['board_link']}")),
             ("mount (in the corrected URDF)", _frame_text(camera["mount"])),
             ("mount fitted to the nominal kinematics", _frame_text(camera["nominal_mount"]))]
    sessions = list(camera.get("sessions") or [])
    for i, world in enumerate(camera["worlds"]):
        which = f" (session '{sessions[i]}')" if len(sessions) > 1 else ""
        if not eye_in_hand and i == 0:
            which += " — in the corrected URDF" + (", the first session's" if len(sessions) > 1 else "")
        facts.append((("board in the world" if eye_in_hand else "camera in the world") + which, _frame_text(world)))
    intrinsics = camera["intrinsics"]
    fitted = intrinsics.get("fitted") or []
    origin = f"fitted ({', '.join(fitted)})" if fitted else f"given ({sources.get('intrinsics')})"
    facts.append(("intrinsics", f"fx {num(intrinsics['fx'], 6)}, fy {num(intrinsics['fy'], 6)}, cx "
                                f"{num(intrinsics['cx'], 6)}, cy {num(intrinsics['cy'], 6)} px; distortion "
                                + ", ".join(num(v, 4) for v in intrinsics["distortion"])
                                + f"; {intrinsics['width']}×{intrinsics['height']} px; "
                                + origin))
    if sources.get("camera_info"):
        facts.append(("camera_info", str(sources["camera_info"])
                      + (" (not written: withheld with the URDF)" if sources.get("corrected_urdf_withheld") else "")))
    facts += [("not seen by one camera", str(words)) for words in camera.get("cannot_see") or []]
    if document.get("fit_seconds") is not None:
        facts.append(("time", f"start and fit {num(float(document['fit_seconds']), 3)} s"))
    return facts


def _cards(reprojection: Mapping[str, Any]) -> list[dict[str, Any]]:
    """A card per role with images: RMS per coordinate after, and before → after [px]."""
    cards = []
    for role, pair in reprojection.items():
        before, after = pair["before"], pair["after"]
        if after.get("images"):
            cards.append({"set": f"{role} images", "images": after["images"], "corners": after["corners"],
                          "before": num(before["rms_px"], 4), "after": num(after["rms_px"], 4)})
    return cards


def _motion_text(motion: Mapping[str, Any]) -> str:
    """evaluate's relative poses in a line: their RMS before, after and the floor [mm, deg], and the verdict."""
    if not motion["pairs"]:
        return str(motion["verdict"])
    rms = "; ".join(f"{key} {num(float(motion[key]['mm']), 3)} mm, {num(float(motion[key]['deg']), 3)}°"
                    for key in ("before", "after", "floor"))
    return (f"RMS over {len(motion['pairs'])} pairs: {rms} (the floor: what {num(float(motion['noise_px']), 3)} px "
            f"of corner noise leaves in PnP's poses): {motion['verdict']}")


def camera_page(document: Mapping[str, Any], evaluation: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The values of ``camera.html.j2`` for a camera's REPORT.json ``document`` (module docstring); with
    ``evaluation`` (``evaluate --json``'s document), its images instead of the report's, an ``evaluated`` card
    after the report's, and its picture drawn from the image files beside the evaluated DATA.csv."""
    camera, sources = document["camera"], document.get("sources") or {}
    if evaluation is None:
        rows, shown, folder = list(camera["images"]), camera.get("picture"), sources.get("images")
    else:
        rows, shown = list(evaluation["images"]), evaluation.get("picture")
        folder = Path(str(evaluation["data"])).parent
    per_image = [np.asarray(row["errors_px"], dtype=float) for row in rows]
    picture = None
    if shown:
        detected = np.asarray(shown["detected_px"], dtype=float).reshape(-1, 2)
        corners = CameraImages((str(shown["image"]),), np.zeros(len(detected), dtype=np.intp), detected,
                               np.asarray(shown["reprojected_px"], dtype=float).reshape(-1, 2),
                               np.array([[shown["width"], shown["height"]]]), (str(shown["role"]),),
                               None if folder is None else Path(str(folder)))
        picture = (corners, 0, True)
    section = section_values([str(r["image"]) for r in rows], [str(r["role"]) for r in rows], per_image, picture)
    for row, values in zip(section["rows"], rows):
        row.update(session=values["session"], before_rms_uv=values["before_rms_px"],
                   after_rms_uv=values["after_rms_px"])
    cards, facts = _cards(camera["reprojection"]), _facts(document)
    if evaluation is not None:
        cards += _cards({"evaluated": evaluation["reprojection"]})
        facts.append(("evaluated", f"{evaluation['data']} through {evaluation['urdf']} and {evaluation['camera_info']} "
                                   f"(world frame {evaluation['world']})"))
        motion = evaluation.get("relative_pose")  # absent from files written before it was measured
        if motion:
            facts.append((f"{motion['frame']} motion between consecutive images", _motion_text(motion)))
    section.update(per_coordinate=True, cards=cards, facts=facts,
                   sessions=len({r["session"] for r in rows}) > 1)
    return section
