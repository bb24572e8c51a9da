"""``pincal calibrate`` with several ``--tip-link LINK:POINTS``: one calibration of every target's chain, its
summary printed per target (:func:`run_calibrate_tree`); the commands that take one chain refuse several
``--tip-link`` with one line (:func:`one_tip_link`)."""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from pincal.cli.arguments import selection_criterion
from pincal.errors import PincalError

if TYPE_CHECKING:
    from pincal.report.model_tree import TreeReport

__all__ = ["one_tip_link", "run_calibrate_tree", "run_diagnose_tree", "is_tree_report", "run_evaluate_tree"]

#: What the calibration of several targets does not take yet (each flag set refuses it).
_NOT_YET = (("fixture", "--fixture"), ("method", "--method"), ("weight", "--weight"), ("tool", "--tool"))


def one_tip_link(command: str, tip_links: Sequence[str] | str | None) -> str:
    """The one ``--tip-link`` of ``command``, which calibrates one chain; several are refused with one line,
    none too (``plan`` asks for it or ``--camera-link``)."""
    if tip_links is None:
        raise PincalError(f"{command}: give --tip-link LINK (the chain's end, carrying the target)"
                          + (", or --camera-link LINK to plan a camera's images" if command == "plan" else "")
                          + (", or --camera-link LINK for a camera's DATA.csv" if command == "diagnose" else ""))
    if isinstance(tip_links, str):
        return tip_links
    if len(tip_links) > 1:
        raise PincalError(f"several --tip-link: not yet supported by {command}; calibrate, diagnose, evaluate and plan "
                          "are (pincal calibrate ... --tip-link LINK:POINTS --tip-link LINK:POINTS)")
    return tip_links[0]


def run_calibrate_tree(args: argparse.Namespace) -> tuple[TreeReport, bool]:
    """Calibrate the targets of ``args.tip_link`` (several ``LINK:POINTS``), print each one's errors before
    and after, write the corrected URDF (unless withheld: a gross misfit without ``--force``) and REPORT.json;
    the report (its warnings for the caller to print) and whether the URDF was withheld."""
    from pincal.cli.progress import progress_bar
    from pincal.model.tree import parse_targets
    from pincal.workflows.settings import CalibrateSettings
    from pincal.workflows.tree_calibration import calibrate_tree_files, refuse_tree_level
    from pincal.workflows.verdict import urdf_line

    for attribute, flag in _NOT_YET:
        value = getattr(args, attribute, None)
        if value is not None and value is not False and not (isinstance(value, list) and not value):
            raise PincalError(f"several --tip-link: {flag} is not yet supported; calibrate one --tip-link with it, "
                              "or leave it out")
    refuse_tree_level(args.level, None)  # before the settings, whose level dh asks for a tool
    targets = parse_targets(args.tip_link)
    settings = CalibrateSettings(tip_link=targets[0].link, level=args.level or "full",
                                 sigma_column=args.sigma_column, selection=selection_criterion(args),
                                 sigma_pos_mm=args.sigma_pos, xacro_args=args.xacro_args,
                                 couplings=args.coupling or (), reject_outliers=args.reject_outliers,
                                 force=args.force)
    with progress_bar("calibrate", quiet=args.quiet, unit="fit") as progress:
        run = calibrate_tree_files(args.urdf, args.data, args.out, args.report, targets, settings, progress,
                                   html=args.html)
    for note in run.notes:
        print(f"pincal: note: {note}", file=sys.stderr)
    result = run.result
    _print_level_choice(run.report)
    size, joints = 0 if result.params is None else result.params.size, len(run.report["chain"]["joints"])
    noise = f"{result.sigma_pos_m * 1000:.3f} mm" + ("" if result.sigma_rot_rad is None else
                                                     f", {math.degrees(result.sigma_rot_rad):.4f} deg")
    print(f"level {result.level}: {result.rank} of {size} parameters identifiable on {joints} joints "
          f"({len(targets)} targets); noise {noise}; calibrated in {run.seconds:.2f} s")
    print(f"{'target (points)':32s} {'seen':>5s} {'RMS before':>11s} {'RMS after':>10s} {'max after':>10s}  [mm]")
    for target in run.report["targets"]:
        before, after = target["nominal_errors"], target["calibration_errors"]
        name = f"{target['tip_link']} ({','.join(map(str, target['points']))})"
        print(f"{name:32s} {after['seen']:5d} {before['position']['rms_mm']:11.3f} {after['position']['rms_mm']:10.3f} "
              f"{after['position']['max_mm']:10.3f}")
    oriented = [t for t in run.report["targets"] if "orientation" in t["calibration_errors"]]
    if oriented:  # each target's orientation (columns qxN,qyN,qzN,qwN) before and after
        print(f"{'target orientation':32s} {'seen':>5s} {'RMS before':>11s} {'RMS after':>10s} {'max after':>10s}  "
              "[deg]")
    for target in oriented:
        before, after = target["nominal_errors"], target["calibration_errors"]
        print(f"{target['tip_link']:32s} {after['orientation_seen']:5d} {before['orientation']['rms_deg']:11.4f} "
              f"{after['orientation']['rms_deg']:10.4f} {after['orientation']['max_deg']:10.4f}")
    if run.withheld:
        print(urdf_line(Path(args.out), True))
    else:
        print(f"wrote {args.out} (reload check: every target reproduced to {run.reload_error:.1e} m)")
    if run.effects_file is not None:
        print(f"wrote {run.effects_file}")
    print(f"wrote {args.report}")
    if run.html is not None:
        print(f"wrote {run.html}")
    return run.report, run.withheld


def run_diagnose_tree(args: argparse.Namespace) -> tuple[TreeReport, bool]:
    """Diagnose the targets of ``args.tip_link`` (several ``LINK:POINTS``): calibrate them in one fit, search the
    tree's residuals for effects, print each effect adopted and each target's errors before and after, write the
    URDF, effects.yaml and REPORT.json; the report (its warnings for the caller to print) and whether the URDF was
    withheld."""
    from pincal.model.effect_units import effect_unit
    from pincal.model.tree import parse_targets
    from pincal.workflows.diagnosis import DiagnoseOutputs
    from pincal.workflows.settings import DiagnoseSettings
    from pincal.workflows.tree_diagnosis import diagnose_tree_files

    targets = parse_targets(args.tip_link)
    settings = DiagnoseSettings(tip_link=targets[0].link, level=args.level, tool_pose=args.tool,
                                sigma_column=args.sigma_column, selection=selection_criterion(args),
                                payload_kg=args.payload_kg, time_column=args.time_column, sigma_pos_mm=args.sigma_pos,
                                xacro_args=args.xacro_args, couplings=args.coupling or (),
                                temperature_column=args.temperature_column, force=args.force, masses=args.masses,
                                lateral=args.lateral, **({} if args.pause_s is None else {"pause_s": args.pause_s}))
    run = diagnose_tree_files(args.urdf, args.data, args.out, args.report, targets, settings,
                              validation_path=args.validation, outputs=DiagnoseOutputs(args.plots, args.html))
    for note in run.notes:
        print(f"pincal: note: {note}", file=sys.stderr)
    report, diagnosis = run.report, run.diagnosis
    _print_level_choice(report)
    kinds = dict(zip(report["chain"]["joints"], report["chain"]["joint_kinds"]))
    print(f"geometric calibration ({run.calibration.level}, {len(targets)} targets), then {len(diagnosis.steps)} "
          f"effect(s) adopted; masses: {report['diagnosis']['masses']}")
    for step in diagnosis.steps:
        value = ", ".join(f"{v:.4g}±{s:.2g}" for v, s in zip(step.values, step.std))
        print(f"  {step.effect.label:36s} {value} {effect_unit(step.effect, kinds)}  dBIC {step.delta_bic:.1f}")
    if not diagnosis.steps:
        print("  nothing significant: no effect is claimed")
    for entry in report.get("effects", []):
        if "advice" in entry:  # what a compliance's sign means, what a coupling asks of the data
            print(f"  {entry['advice']}")
        moments = entry.get("value")  # a mass-moment compliance's values, each a combination in words
        shown: list[float] = moments if isinstance(moments, list) else []
        for words, number in zip(entry.get("combinations", ()), shown):
            print(f"  {number:.4g} = {words}")
    held = any(t.get("validation_errors") for t in report["targets"])
    print(f"{'target (points)':32s} {'RMS geometry':>13s} {'RMS final':>10s}"
          + (f" {'held-out geometry':>18s} {'held-out final':>15s}" if held else "") + "  [mm]")
    for target in report["targets"]:
        name = f"{target['tip_link']} ({','.join(map(str, target['points']))})"
        line = (f"{name:32s} {target['geometry_errors']['position']['rms_mm']:13.3f} "
                f"{target['calibration_errors']['position']['rms_mm']:10.3f}")
        before, after = target.get("validation_geometry_errors"), target.get("validation_errors")
        if held:
            line += (f" {before['position']['rms_mm']:18.3f} {after['position']['rms_mm']:15.3f}" if before and after
                     else f" {'not seen':>18s} {'':>15s}")
        print(line)
    for target in (t for t in report["targets"] if "orientation" in t["calibration_errors"]):  # qxN,qyN,qzN,qwN
        turns = (target["geometry_errors"], target["calibration_errors"], target.get("validation_geometry_errors"),
                 target.get("validation_errors"))
        print(f"{target['tip_link'] + ' orientation':32s} " + " ".join(
            f"{e['orientation']['rms_deg']:{w}.4f}" if e and "orientation" in e else f"{'':{w}s}"
            for e, w in zip(turns, (13, 10, 18, 15) if held else (13, 10))) + "  [deg]")
    if run.withheld:
        print(f"{args.out}: not written (withheld; --force writes it)")
    else:
        print(f"wrote {args.out}")
    if run.effects_file is not None:
        print(f"wrote {run.effects_file}")
    print(f"wrote {args.report}")
    if run.html is not None:
        print(f"wrote {run.html}")
    return report, run.withheld


def _print_level_choice(report: TreeReport) -> None:
    """``--level auto``'s table: each level's cross-validated error and the one chosen (none for a level given)."""
    if "level_choice" in report:
        from pincal.cli.level_table import level_choice_lines

        print("\n".join(level_choice_lines(report["level_choice"])))


def is_tree_report(path: Path) -> bool:
    """Whether ``path`` is a REPORT.json of several targets (``targets``); False for anything else, whose
    reader then says what is wrong with it."""
    try:
        document = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return isinstance(document, dict) and "targets" in document and "parameters" in document


def run_evaluate_tree(args: argparse.Namespace) -> int:
    """``pincal evaluate CORRECTED.urdf REPORT.json DATA.csv`` of a tree's report: each target's errors; the
    exit code (1 beyond ``--max-pos-mm``)."""
    from pincal.workflows.settings import EvaluateSettings
    from pincal.workflows.tree_evaluation import evaluate_tree_files

    if getattr(args, "nominal", None) is not None:
        raise PincalError("several --tip-link: evaluate --nominal is not yet supported; leave it out")
    settings = EvaluateSettings(allow_other_urdf=args.allow_other_urdf, xacro_args=args.xacro_args,
                                fixed_registration=args.fixed_registration, new_session=args.new_session,
                                temperature_column=args.temperature_column, max_pos_mm=args.max_pos_mm,
                                max_rot_deg=args.max_rot_deg)
    run = evaluate_tree_files(args.urdf, args.report, args.data, settings, json_path=args.json, html_path=args.html)
    for note in run.notes:
        print(f"pincal: note: {note}", file=sys.stderr)
    print(f"{run.rows} rows; registration: {'; '.join(run.registrations)}")
    print(f"{'target (points)':32s} {'seen':>5s} {'mean':>8s} {'RMS':>8s} {'max':>8s}  [mm]")
    for link, errors in run.targets:
        if errors is None:
            print(f"{link:32s} {0:5d}  not seen")
            continue
        stats = errors["position"]
        print(f"{link:32s} {errors['seen']:5d} {stats['mean_mm']:8.3f} {stats['rms_mm']:8.3f} {stats['max_mm']:8.3f}")
    turned = [(link, errors) for link, errors in run.targets if errors is not None and "orientation_seen" in errors]
    if turned:  # each target whose orientation the report calibrated and these rows measure
        print(f"{'target orientation':32s} {'seen':>5s} {'mean':>8s} {'RMS':>8s} {'max':>8s}  [deg]")
    for link, errors in turned:
        if "orientation" not in errors:
            print(f"{link:32s} {0:5d}  not seen")
            continue
        angle = errors["orientation"]
        print(f"{link:32s} {errors['orientation_seen']:5d} {angle['mean_deg']:8.4f} {angle['rms_deg']:8.4f} "
              f"{angle['max_deg']:8.4f}")
    if args.json is not None:
        print(f"wrote {args.json}")
    if run.html is not None:
        print(f"wrote {run.html}")
    failed = 0
    if args.max_pos_mm is not None and run.max_mm > args.max_pos_mm:
        print(f"FAIL: largest position error {run.max_mm:.3f} mm > --max-pos-mm {args.max_pos_mm:g}")
        failed = 1
    if args.max_rot_deg is not None and run.max_deg is not None and run.max_deg > args.max_rot_deg:
        print(f"FAIL: largest orientation error {run.max_deg:.4f} deg > --max-rot-deg {args.max_rot_deg:g}")
        failed = 1
    return failed
