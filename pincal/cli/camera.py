"""What ``pincal calibrate --camera-link`` and ``pincal evaluate`` of a camera's report print; the refusal of a
camera's DATA.csv without ``--camera-link`` and of flags a camera has no use for.

The jobs are :mod:`pincal.workflows.camera_calibration` and :mod:`pincal.workflows.camera_evaluation`.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pincal.cli.arguments import selection_criterion
from pincal.errors import PincalError

if TYPE_CHECKING:
    from pincal.workflows.camera_calibration import CameraCalibrateSettings, CameraCalibrationRun

__all__ = ["CAMERA_NOT_USED", "DIAGNOSE_NOT_USED", "is_camera_data", "refuse_camera_data", "refuse_camera_flags",
           "run_calibrate", "run_diagnose", "is_camera_report", "run_evaluate"]

#: Flags of calibrate that a camera's calibration has no use for (argparse dest → flag).
CAMERA_NOT_USED = {"tip_link": "--tip-link (the chain ends at the camera's or the board's link)",
                   "method": "--method", "weight": "--weight", "tool": "--tool", "fixture": "--fixture",
                   "sigma_column": "--sigma-column", "reject_outliers": "--reject-outliers",
                   "sigma_pos": "--sigma-pos", "coupling": "--coupling"}
#: Flags of diagnose that a camera's diagnosis has no use for (argparse dest → flag), besides calibrate's.
DIAGNOSE_NOT_USED = {"payload_kg": "--payload-kg", "lateral": "--lateral", "time_column": "--time-column",
                     "temperature_column": "--temperature-column", "pause_s": "--pause-s", "plots": "--plots"}
#: The columns that make a CSV a camera's DATA.csv (pincal detect's).
_CAMERA_COLUMNS = ("image", "corner", "u", "v")


def is_camera_data(paths: Sequence[Path]) -> Path | None:
    """The first of ``paths`` whose header has a camera's DATA.csv columns, else None (an unreadable file is left
    to its reader's message)."""
    for path in paths:
        try:
            with open(path, newline="", encoding="utf-8-sig") as handle:
                header = next(csv.reader(line for line in handle if line.strip() and not line.startswith("#")), [])
        except (OSError, UnicodeDecodeError, csv.Error):
            continue
        if all(c in [h.strip() for h in header] for c in _CAMERA_COLUMNS):
            return path
    return None


def refuse_camera_data(paths: Sequence[Path], give: str) -> None:
    """Refuse, in one line naming the file, a camera's DATA.csv among ``paths`` given where a point sensor's is read
    (``--tip-link``); ``give``: the flags that read it instead."""
    camera = is_camera_data(paths)
    if camera is not None:
        raise PincalError(f"{camera}: a camera's DATA.csv (columns image, corner, u, v ...: detect's); give {give} "
                          "instead of --tip-link")


def refuse_camera_flags(args: argparse.Namespace) -> None:
    """Refuse, in one line, calibrate's flags a camera's data have no use for; and the camera's flags without
    ``--camera-link``."""
    given = [flag for name, flag in CAMERA_NOT_USED.items() if getattr(args, name, None) not in (None, False, [])]
    if given:
        raise PincalError(f"{', '.join(given)} {'does' if len(given) == 1 else 'do'} not apply to a camera's images "
                          "(--camera-link); drop " + ("it" if len(given) == 1 else "them"))


def run_calibrate(args: argparse.Namespace) -> tuple[Mapping[str, Any], bool]:
    """``pincal calibrate URDF DATA.csv --camera-link LINK [--board-link LINK] --intrinsics FILE|estimate``: prints
    the summary; returns the report (its warnings printed by the caller) and whether the URDF was withheld."""
    from pincal.workflows.camera_calibration import calibrate_camera_files

    refuse_camera_flags(args)
    run = calibrate_camera_files(args.urdf, args.data[0], args.out, args.report, _settings(args), html=args.html)
    _print_run(args, run)
    return run.report, run.withheld


def _settings(args: argparse.Namespace) -> CameraCalibrateSettings:
    """The camera calibration's settings of calibrate's or diagnose's arguments (one DATA.csv, intrinsics given)."""
    from pincal.workflows.camera_calibration import CameraCalibrateSettings

    if len(args.data) != 1:
        raise PincalError(f"a camera's calibration takes one DATA.csv (its 'session' column tells sessions apart), "
                          f"got {len(args.data)}; join them into one file")
    if args.intrinsics is None:
        raise PincalError("--camera-link needs --intrinsics FILE (ROS camera_info or OpenCV YAML) or --intrinsics "
                          "estimate (the intrinsics fitted with the rest)")
    return CameraCalibrateSettings(args.camera_link, args.intrinsics, board_link=args.board_link,
                                   level=args.level or "full", selection=selection_criterion(args),
                                   xacro_args=args.xacro_args, force=args.force,
                                   images=args.images)


def run_diagnose(args: argparse.Namespace) -> tuple[Mapping[str, Any], bool]:
    """``pincal diagnose URDF DATA.csv --camera-link LINK [--board-link LINK] --intrinsics FILE|estimate
    [--validation HELD_OUT.csv]``: prints the camera calibration's summary and the effects adopted; returns the
    report and whether the URDF was withheld."""
    from pincal.cli.progress import progress_bar
    from pincal.workflows.camera_diagnosis import CameraDiagnoseSettings, diagnose_camera_files

    given = [flag for name, flag in {**CAMERA_NOT_USED, **DIAGNOSE_NOT_USED}.items()
             if getattr(args, name, None) not in (None, False, [])]
    if given:
        raise PincalError(f"{', '.join(given)} {'does' if len(given) == 1 else 'do'} not apply to diagnose on a "
                          "camera's images (--camera-link); drop " + ("it" if len(given) == 1 else "them"))
    if args.level == "auto":
        raise PincalError("diagnose --camera-link: --level auto is not supported; give registration, offsets or full")
    settings = CameraDiagnoseSettings(_settings(args), masses=args.masses)
    with progress_bar("diagnose", quiet=args.quiet, unit="fit") as progress:
        diagnosed = diagnose_camera_files(args.urdf, args.data[0], args.out, args.report, settings,
                                          validation=args.validation, progress=progress, html=args.html)
    run, diagnosis = diagnosed.run, diagnosed.diagnosis
    _print_run(args, run)
    held = diagnosis.heldout_before_px is not None
    print(f"then {len(diagnosis.effects)} effect(s) adopted, calibration RMS {diagnosis.calibration_rms_px:.4f} -> "
          f"{diagnosis.rms_px:.4f} px" + (f", held-out RMS {diagnosis.heldout_before_px:.4f} -> "
                                          f"{diagnosis.heldout_after_px:.4f} px" if held else ""))
    from pincal.model.effect_units import effect_unit

    kinds = dict(zip(run.report["chain"]["joints"], run.report["chain"]["joint_kinds"]))
    for step in diagnosis.steps:
        values = ", ".join(f"{v:.4g}" for v in step.values)
        stds = ", ".join(f"{v:.2g}" for v in step.std)
        print(f"  {step.effect.label}: {values} ± {stds} {effect_unit(step.effect, kinds)} (ΔBIC {step.delta_bic:.1f})")
    if not diagnosis.effects and diagnosis.last_candidates:
        best = diagnosis.last_candidates[0]
        print(f"  best candidate {best.effect.label}: {best.verdict}")
    if not run.withheld and diagnosis.effects:
        from pincal.report.effects_file import effects_path, written_line

        print(written_line(effects_path(args.out), run.report))
    return run.report, run.withheld


def _print_run(args: argparse.Namespace, run: CameraCalibrationRun) -> None:
    """calibrate's summary of a camera's run: the fit, frames, intrinsics, reprojection table, files written."""
    report, result = run.report, run.result
    for note in report["notes"]:
        print(f"pincal: note: {note}", file=sys.stderr)
    camera = report["camera"]
    kept = sum(1 for p in report["parameters"] if p["calibrated"] is not None)
    print(f"camera {camera['arrangement'].replace('_', ' ')}, level {result.level}: "
          f"{camera['reprojection']['calibration']['after']['images']} calibration images, {kept} kinematic "
          f"parameters kept of {len(report['parameters'])} ({report['identifiability']['rank']} identifiable), plus "
          f"the mount, the world frame{'s' if len(camera['worlds']) > 1 else ''}"
          + (" and the intrinsics" if camera["intrinsics"]["fitted"] else "")
          + f"; {report['fit_seconds']:.2f} s")
    print(_frame_line("mount", camera["mount"]))
    for world in camera["worlds"]:
        print(_frame_line("world", world))
    intrinsics = camera["intrinsics"]
    print(f"intrinsics: fx {intrinsics['fx']:.2f}, fy {intrinsics['fy']:.2f}, cx {intrinsics['cx']:.2f}, "
          f"cy {intrinsics['cy']:.2f} px, distortion " + ", ".join(f"{v:.4g}" for v in intrinsics["distortion"])
          + (" (fitted)" if intrinsics["fitted"] else " (given)"))
    for words in camera["cannot_see"]:
        print(f"not seen by one camera: {words}")
    _print_reprojection(camera["reprojection"])
    from pincal.workflows.verdict import urdf_line

    print(urdf_line(args.out, run.withheld, run.reload_error))
    if run.camera_info is not None:
        print(f"wrote {run.camera_info}")
    print(f"wrote {args.report}")
    if run.html is not None:
        print(f"wrote {run.html}")


def _frame_line(what: str, frame: Mapping[str, Any]) -> str:
    xyz = ", ".join(f"{v:.5f}" for v in frame["translation_m"])
    quat = ", ".join(f"{v:.5f}" for v in frame["rotation_xyzw"])
    return f"{what}: {frame['child']} in {frame['parent']}: ({xyz}) m, rotation xyzw ({quat})"


def _print_reprojection(reprojection: Mapping[str, Any]) -> None:
    """The before -> after table of reprojection RMS per role [px]."""
    print(f"{'reprojection RMS [px]':24s} {'images':>6s} {'corners':>8s} {'before':>9s} {'after':>9s}")
    for role, pair in reprojection.items():
        before, after = pair["before"], pair["after"]
        if after["images"]:
            print(f"{role + ' images':24s} {after['images']:6d} {after['corners']:8d} {before['rms_px']:9.4f} "
                  f"{after['rms_px']:9.4f}")
    print("before: the nominal kinematics with their own mount and world frame fitted (OpenCV's hand-eye, refined)")


def _print_relative_pose(motion: Mapping[str, Any]) -> None:
    """evaluate's relative poses between consecutive images: per pair and their RMS, before, after and the floor
    [mm, deg], then the verdict."""
    frame = motion["frame"]
    if motion["pairs"]:
        print(f"{frame + ' motion, image to image':32s} {'before':>17s} {'after':>17s} {'floor':>17s}  [mm, deg]")
        for pair in motion["pairs"]:
            print(f"{pair['first'] + ' -> ' + pair['second']:32s} {pair['before_mm']:8.3f} {pair['before_deg']:8.4f} "
                  f"{pair['after_mm']:8.3f} {pair['after_deg']:8.4f} {pair['floor_mm']:8.3f} {pair['floor_deg']:8.4f}")
        rms = [motion[key] for key in ("before", "after", "floor")]
        print(f"{'all ' + str(len(motion['pairs'])) + ' pairs':32s} "
              + " ".join(f"{v['mm']:8.3f} {v['deg']:8.4f}" for v in rms))
    for session in motion["no_pairs"]:
        print(f"session {session}: no pairs (fewer than 2 images whose board pose PnP can measure)")
    noise = "" if motion["noise_px"] is None else (f" (floor: what {motion['noise_px']:.3f} px of corner noise leaves "
                                                   "in PnP's poses)")
    print(f"{frame} motion: {motion['verdict']}{noise}")


def is_camera_report(path: Path) -> bool:
    """Whether ``path`` is a camera's REPORT.json (``measurement`` camera); False for anything else, whose reader
    then says what is wrong with it."""
    try:
        document = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return isinstance(document, dict) and document.get("measurement") == "camera" and "camera" in document


def run_evaluate(args: argparse.Namespace) -> int:
    """``pincal evaluate CORRECTED.urdf REPORT.json DATA.csv`` of a camera's report: the images' reprojection
    errors before and after, overall and per image; writes ``--json``. Returns the exit code."""
    from pincal.workflows.camera_evaluation import CameraEvaluateSettings, evaluate_camera_files

    not_used = {"fixture": "--fixture", "max_pos_mm": "--max-pos-mm",
                "max_rot_deg": "--max-rot-deg", "fixed_registration": "--fixed-registration",
                "temperature_column": "--temperature-column"}
    given = [flag for name, flag in not_used.items() if getattr(args, name, None) not in (None, False)]
    if given:
        raise PincalError(f"{', '.join(given)} {'does' if len(given) == 1 else 'do'} not apply to a camera's "
                          "report; drop " + ("it" if len(given) == 1 else "them"))
    settings = CameraEvaluateSettings(new_session=args.new_session, allow_other_urdf=args.allow_other_urdf,
                                      nominal=args.nominal, xacro_args=tuple(args.xacro_args))
    run = evaluate_camera_files(args.urdf, args.report, args.data, settings, json_path=args.json, html_path=args.html)
    for note in run.notes:
        print(f"pincal: note: {note}", file=sys.stderr)
    document = run.document
    print(f"{'image':24s} {'corners':>8s} {'before':>9s} {'after':>9s}  [RMS px, u and v]")
    for image in document["images"]:
        print(f"{image['image']:24s} {image['corners']:8d} {image['before_rms_px']:9.4f} {image['after_rms_px']:9.4f}")
    before, after = document["reprojection"]["before"], document["reprojection"]["after"]
    print(f"{'all ' + str(after['images']) + ' images':24s} {after['corners']:8d} {before['rms_px']:9.4f} "
          f"{after['rms_px']:9.4f}")
    print(f"world frame: {document['world']}; before: {document['report']}'s nominal kinematics with their own mount "
          "and world frame (OpenCV's hand-eye, refined); after: the corrected URDF and its camera_info")
    _print_relative_pose(document["relative_pose"])
    for written in (run.written, run.html):
        if written is not None:
            print(f"wrote {written}")
    return 0
