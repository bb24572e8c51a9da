"""The ``pincal`` command line: a thin layer over :mod:`pincal.workflows`.

The arguments are defined in :mod:`pincal.cli.parser`. Every user error is
printed as one line ``pincal: error: ...`` with exit code 2; ``pincal
evaluate`` exits 1 when a threshold is exceeded; ``calibrate`` and ``diagnose``
exit 3 when their model misses its rows grossly and the corrected URDF is
withheld (:mod:`pincal.workflows.verdict`), and any of the three with ``--strict``
and a warning.
"""

from __future__ import annotations

import argparse
import gc
import sys
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any, cast

from pincal.cli.arguments import selection_criterion
from pincal.cli.error_table import HEADER, error_columns, point_rows
from pincal.cli.paper_commands import demo_command, simulate_command, study_command
from pincal.cli.parser import build_parser
from pincal.cli.tree import is_tree_report, one_tip_link, run_calibrate_tree, run_diagnose_tree, run_evaluate_tree
from pincal.errors import PincalError

if TYPE_CHECKING:
    from contextlib import AbstractContextManager

    from pincal.workflows.settings import CalibrateLevel

__all__ = ["EXIT_THRESHOLD", "EXIT_USAGE", "EXIT_WARNING", "main", "console"]

EXIT_THRESHOLD = 1
EXIT_USAGE = 2
EXIT_WARNING = 3  # --strict and a warning (the outputs written), or a gross misfit (the corrected URDF withheld)


def _print_notes(notes: Sequence[str]) -> None:
    for note in notes:
        print(f"pincal: note: {note}", file=sys.stderr)


def _warned(report: Mapping[str, Any], strict: bool, withheld: bool = False) -> int:
    """Print REPORT.json's ``warnings`` on stderr; the exit code: 3 with ``strict`` and a warning, or when
    the corrected URDF was ``withheld`` (a gross misfit: pincal.workflows.verdict), else 0."""
    warnings = report.get("warnings") or []
    for warning in warnings:
        print(f"pincal: warning: {warning['message']}", file=sys.stderr)
    return EXIT_WARNING if withheld or (strict and warnings) else 0


def _run_calibrate(args: argparse.Namespace) -> int:
    from pincal.cli.progress import progress_bar
    from pincal.workflows.calibration import calibrate_files
    from pincal.workflows.settings import CalibrateSettings

    if args.camera_link is not None:  # a camera's DATA.csv: the chain ends at the camera's or the board's link
        from pincal.cli.camera import run_calibrate as run_camera

        camera_report, camera_withheld = run_camera(args)
        return _warned(camera_report, args.strict, camera_withheld)
    _no_camera(args)
    if isinstance(args.tip_link, list):  # several targets on several chains, one calibration
        tree_report, tree_withheld = run_calibrate_tree(args)
        return _warned(tree_report, args.strict, tree_withheld)
    if args.fixture is not None:  # socket-fixture data, no sensor
        from pincal.cli.fixture import run_calibrate

        report, withheld = run_calibrate(args)
        return _warned(report, args.strict, withheld)
    level = cast("CalibrateLevel", args.level or ("dh" if args.method is not None else "full"))  # --level's choices
    if level == "dh" and args.strict:  # --force at level dh: CalibrateSettings refuses it
        raise PincalError("--strict applies to --level registration, offsets, full or auto (the plausibility "
                          "checks of pincal.fit.plausibility), not to the paper's methods; drop it")
    settings = CalibrateSettings(
        tip_link=args.tip_link, level=level, method=args.method,
        weight=1.0 if args.weight is None else args.weight,  # None: not given (refused with --fixture)
        tool_pose=args.tool, sigma_column=args.sigma_column, reject_outliers=args.reject_outliers,
        selection=selection_criterion(args), sigma_pos_mm=args.sigma_pos, xacro_args=args.xacro_args,
        couplings=args.coupling or (), force=args.force)
    method = settings.paper_method
    with progress_bar("calibrate", quiet=args.quiet, unit="fit") as progress:
        run = calibrate_files(args.urdf, args.data, args.out, args.report, settings, progress=progress, html=args.html)
    _print_notes(run.notes + list(run.result.notes))
    _print_level_choice(run.report)
    if level == "dh":
        from pincal.paper.methods import PaperCalibration  # loaded by the run

        assert isinstance(run.result, PaperCalibration)  # level dh runs the paper's methods
        for stage in run.result.stages:
            print(f"{stage.name}: {len(stage.parameters)} parameters, RMS residual {stage.rms:.4g} "
                  f"{stage.unit}, {stage.n_evaluations} evaluations")
        print(f"Method {method} calibrated in {run.seconds * 1000:.1f} ms")
    else:
        _print_chain_summary(run)
    several = run.sessions if len(run.sessions) > 1 else ()
    for session in several:
        print(f"session {session.name} ({session.source}, {session.rows} rows): "
              f"registration {_registration_text(session.registration)}")
    print(HEADER)
    print(f"{'calibration rows':24s} {error_columns(run.errors)}")
    for line in point_rows(run.errors):
        print(line)
    before_after = _before_after(run.report)
    if before_after:
        print(before_after)
    for session in several:
        print(f"{'  session ' + session.name:24s} {error_columns(session.errors)}")
    from pincal.workflows.verdict import urdf_line

    print(urdf_line(args.out, run.withheld, run.reload_error))
    print(f"wrote {args.report}")
    _print_effects_file(run.effects_file, run.report)
    _print_written(run.html)
    return _warned(run.report, args.strict, run.withheld)


def _no_camera(args: argparse.Namespace) -> None:
    """Without ``--camera-link``: refuse the camera's flags and a camera's DATA.csv, and ask for ``--tip-link``."""
    from pincal.cli.camera import is_camera_data

    given = [flag for flag, value in (("--board-link", args.board_link), ("--intrinsics", args.intrinsics),
                                      ("--images", getattr(args, "images", None))) if value]
    if given:
        raise PincalError(f"{' and '.join(given)} apply with --camera-link only (a camera's DATA.csv); give "
                          "--camera-link LINK, or drop them")
    camera = is_camera_data(args.data)
    if camera is not None:
        raise PincalError(f"{camera}: a camera's DATA.csv (columns image, corner, u, v ...: detect's); give "
                          "--camera-link LINK (the camera's optical frame) and --intrinsics FILE|estimate instead of "
                          "--tip-link")
    if args.tip_link is None:
        raise PincalError("the following arguments are required: --tip-link (or --camera-link for a camera's "
                          "DATA.csv)")


def _print_effects_file(path, report: Mapping[str, Any]) -> None:
    """One line where the couplings and effects a URDF cannot carry were written (effects.yaml), if any."""
    if path is not None:
        from pincal.report.effects_file import written_line

        print(written_line(path, report))


def _before_after(report: Mapping[str, Any]) -> str | None:
    """One line: the calibration rows' RMS position error of the nominal model (registered to them)
    and of the calibrated one [mm], over all target points and, with several, for point 1 — the
    metric the docs quote for TIAGo (REPORT.json ``row_errors``); None without both models."""
    rows = next((s for s in report.get("row_errors", []) if s.get("set") == "calibration"), None)
    models = {m["model"]: m["errors"] for m in rows["models"]} if rows else {}
    before, after = (models.get(name) for name in ("nominal geometry", "calibrated geometry"))
    if before is None or after is None:
        return None
    text = (f"before -> after, calibration rows, RMS position: {before['position']['rms_mm']:.3f} -> "
            f"{after['position']['rms_mm']:.3f} mm")
    points = after.get("position_per_point") or []
    if len(points) > 1:
        first = before["position_per_point"][0]["rms_mm"], points[0]["rms_mm"]
        text += f" (all {len(points)} points); point 1: {first[0]:.3f} -> {first[1]:.3f} mm"
    return text + " (before: the nominal model, registered to these rows)"


def _print_level_choice(report: Mapping[str, Any]) -> None:
    """The table of ``--level auto`` (REPORT.json's ``level_choice``), when the level was chosen."""
    if "level_choice" in report:
        from pincal.cli.level_table import level_choice_lines

        print("\n".join(level_choice_lines(report["level_choice"])))


def _registration_text(registration) -> str:
    """sensor_T_base in one line: translation [m] and rotation vector [deg]."""
    import numpy as np
    from scipy.spatial.transform import Rotation

    turn = np.degrees(Rotation.from_matrix(registration.rotation).as_rotvec())
    return (f"translation ({', '.join(f'{v:.4f}' for v in registration.translation)}) m, "
            f"rotation vector ({', '.join(f'{v:.3f}' for v in turn)}) deg")


def _print_written(path) -> None:
    """``wrote PATH`` for an optional output (``--html``) that was written."""
    if path is not None:
        print(f"wrote {path}")


def _print_chain_summary(run) -> None:
    import numpy as np

    from pincal.cli.level_table import held_by_prior, prior_scale_line

    result = run.result
    ident = run.report["identifiability"]
    kept = sum(1 for p in run.report["parameters"] if p["calibrated"] is not None)
    print(f"level {result.level}: {kept} kinematic parameters kept of {len(run.report['parameters'])} "
          f"({ident['rank']} identifiable{held_by_prior(ident, kept)}), plus registration and target")
    if ident["selection"]:
        sel = ident["selection"]
        print(f"selection: {sel['criterion']} = {sel['value']:.4g} with {sel['kept']} kept")
        scales = prior_scale_line(sel)
        if scales:
            print(scales)
    print(f"Jacobian condition number (scaled): {ident['jacobian_condition']:.3g}")
    for pair in ident["correlated_pairs"][:10]:
        print(f"correlated: {pair['a']} ~ {pair['b']} ({pair['correlation']:+.3f})")
    files = result.outlier_files if len(result.session_names) > 1 else [""] * len(result.outliers)
    for (line, score), file, by in zip(result.outliers, files, result.outlier_errors()):
        print(f"outlier: {file + ' ' if file else ''}line {line} (robust score {score:.1f}"
              + (" of its orientation error)" if by == "orientation" else ")"))
    print(f"estimated noise: {result.sigma_pos_m * 1000:.3f} mm"
          + ("" if result.sigma_rot_rad is None else f", {np.degrees(result.sigma_rot_rad):.4f} deg"))
    print(f"fit {result.fit_seconds * 1000:.1f} ms (with selection {result.total_seconds * 1000:.0f} ms)")


def _run_evaluate(args: argparse.Namespace) -> int:
    from pincal.workflows.evaluation_outputs import EvaluateOutputs, evaluate_and_write
    from pincal.workflows.settings import EvaluateSettings

    if args.fixture is not None:
        from pincal.cli.fixture import run_evaluate

        return _warned(run_evaluate(args), args.strict)
    from pincal.cli.camera import is_camera_report

    if is_camera_report(args.report):  # a camera's images: reprojection errors in pixels
        from pincal.cli.camera import run_evaluate as run_camera

        return run_camera(args)
    if is_tree_report(args.report):  # several targets on several chains
        return run_evaluate_tree(args)
    if args.nominal is not None:
        raise PincalError("--nominal applies to socket-fixture data only (with --fixture); drop it")
    settings = EvaluateSettings(allow_other_urdf=args.allow_other_urdf, xacro_args=args.xacro_args,
                                fixed_registration=args.fixed_registration, new_session=args.new_session,
                                temperature_column=args.temperature_column, max_pos_mm=args.max_pos_mm,
                                max_rot_deg=args.max_rot_deg)
    run = evaluate_and_write(args.urdf, args.report, args.data, settings, EvaluateOutputs(args.json, args.html))
    evaluation = run.evaluation
    _print_notes(evaluation.notes)
    errors = evaluation.errors
    for session in evaluation.sessions:
        text = f"session {session.name} ({session.rows} rows): registration: {session.source}"
        if session.reestimated:
            text += (f": {_registration_text(session.registration)}; {session.residuals} residuals, "
                     f"{session.dof} degrees of freedom left")
        print(text)
    print(HEADER)
    print(f"{f'{errors.n_rows} rows':24s} {error_columns(errors)}")
    for line in point_rows(errors):
        print(line)
    for session in evaluation.sessions if len(evaluation.sessions) > 1 else ():
        print(f"{'  session ' + session.name:24s} {error_columns(session.errors)}")
    if evaluation.nominal_rms_mm is not None:  # as calibrate's line, on these rows
        print(f"before -> after, these rows, RMS position: {evaluation.nominal_rms_mm:.3f} -> "
              f"{errors.position.rms:.3f} mm (before: {evaluation.nominal_urdf}, its registration and target "
              "fitted to these rows; after: the calibrated model, registrations as above)")
    for path in run.written:
        print(f"wrote {path}")
    for failure in run.failed:
        print(f"pincal: FAIL: {failure.text}", file=sys.stderr)
    warned = _warned(run.document, args.strict)  # its warnings are printed and shown as such
    return warned or (EXIT_THRESHOLD if run.failed else 0)  # implausible data first: a FAIL on them means little


def _run_diagnose(args: argparse.Namespace) -> int:
    from pincal.cli.camera import is_camera_data
    from pincal.cli.level_table import prior_scale_line
    from pincal.cli.progress import progress_bar
    from pincal.model.thermal import shown
    from pincal.workflows.diagnosis import DiagnoseOutputs, diagnose_files
    from pincal.workflows.settings import DiagnoseSettings

    camera = is_camera_data([*args.data, *([args.validation] if args.validation else [])])
    if camera is not None:
        raise PincalError(f"{camera}: a camera's DATA.csv (columns image, corner, u, v ...: detect's); give "
                          "--camera-link LINK (the camera's optical frame) and --intrinsics FILE|estimate instead of "
                          "--tip-link")
    plots = args.plots if args.plots is not None else args.report.parent / "diagnose_plots"
    settings = DiagnoseSettings(tip_link=args.tip_link, level=args.level, tool_pose=args.tool,
                                sigma_column=args.sigma_column, selection=selection_criterion(args),
                                payload_kg=args.payload_kg, time_column=args.time_column, sigma_pos_mm=args.sigma_pos,
                                xacro_args=args.xacro_args, couplings=args.coupling or (),
                                temperature_column=args.temperature_column, force=args.force, masses=args.masses,
                                lateral=args.lateral,
                                **({} if args.pause_s is None else {"pause_s": args.pause_s}))
    with progress_bar("diagnose", quiet=args.quiet, unit="fit") as progress:
        run = diagnose_files(args.urdf, args.data, args.out, args.report, settings, validation_path=args.validation,
                             outputs=DiagnoseOutputs(plots, args.html), progress=progress)
    _print_notes(run.notes + list(run.calibration.notes))
    _print_level_choice(run.report)
    diagnosis = run.diagnosis
    held = diagnosis.heldout_errors is not None
    print(f"geometric calibration ({run.calibration.level}), then {len(diagnosis.steps)} effect(s) adopted:")
    scales = prior_scale_line((run.report.get("identifiability") or {}).get("selection"))
    if scales:
        print(scales)
    print(f"{'step':38s} {'value ± std':>26s} {'dBIC':>8s} {'cal RMS [mm]':>17s}"
          + (f" {'held-out RMS [mm]':>19s}" if held else ""))
    kinds = dict(zip(run.report["chain"]["joints"], run.report["chain"]["joint_kinds"]))

    def unit(effect) -> str:
        from pincal.model.effect_units import effect_unit

        return effect_unit(effect, kinds)

    for step in diagnosis.steps:
        values, std, shown_unit = shown(step.effect, step.values, step.std, unit(step.effect))  # α in µm/m/K
        value = (f"{values[0]:g} (read against)" if step.convention else  # a convention is exact
                 ", ".join(f"{v:.4g}±{s:.2g}" for v, s in zip(values, std)) + f" {shown_unit}")
        line = (f"{step.effect.label:38s} {value:>26s} {step.delta_bic:8.1f} "
                f"{step.calibration_before.position.rms:7.3f} -> {step.calibration_after.position.rms:6.3f}")
        if step.heldout_before is not None and step.heldout_after is not None:  # with --validation
            line += f" {step.heldout_before.position.rms:8.3f} -> {step.heldout_after.position.rms:6.3f}"
        print(line)
    if not diagnosis.steps:
        print("  nothing significant: no effect is claimed")
    entries = run.report["effects"]  # each effect as written, a coupling's advice among its keys
    for (effect, values, std), change, entry in zip(diagnosis.effects, diagnosis.target_changes, entries):
        values, std, shown_unit = shown(effect, values, std, unit(effect))
        value = ", ".join(f"{v:.4g} ± {s:.2g}" for v, s in zip(values, std))  # what evaluate applies
        print(f"final model: {effect.label} = {value} {shown_unit}: {change.describe(effect)}")
        if "advice" in entry:  # what a coupling asks of the data, what a compliance's sign means
            print(f"  {entry['advice']}")
        for words, number in zip(entry.get("combinations", ()), values):  # what a mass-moment value stands for
            print(f"  {number:.4g} = {words}")
    from pincal.diagnosis.screening import GENERIC_NOT_RUN  # loaded already by the run
    from pincal.diagnosis.verdicts import REJECTED

    for note in diagnosis.notes:  # a rejected effect's note ends with REJECTED; others say what was not tested
        print(f"reported, not adopted: {note.removesuffix(REJECTED)}" if note.endswith(REJECTED) else f"note: {note}")

    if diagnosis.unexplained or GENERIC_NOT_RUN not in diagnosis.notes:
        print(diagnosis.unexplained or "no structure left that a generic joint-angle correction would explain")
    print(HEADER)
    print(f"{'calibration rows':24s} {error_columns(diagnosis.calibration_errors)}")
    for line in point_rows(diagnosis.calibration_errors):
        print(line)
    if diagnosis.heldout_errors is not None:
        print(f"{'held-out rows':24s} {error_columns(diagnosis.heldout_errors)}")
        for line in point_rows(diagnosis.heldout_errors):
            print(line)
    for path in run.plots:
        print(f"wrote {path}")
    from pincal.workflows.verdict import urdf_line

    print(f"{urdf_line(args.out, run.withheld)}\n"
          f"wrote {args.report} (effects: pincal evaluate applies them; a URDF cannot carry them)")
    _print_effects_file(run.effects_file, run.report)
    _print_written(run.html)
    return _warned(run.report, args.strict, run.withheld)


def _run_report(args: argparse.Namespace) -> int:
    from pincal.workflows.report_page import report_file

    print(f"wrote {report_file(args.document, args.out)}")
    return 0


def _run_example(args: argparse.Namespace) -> int:
    from pincal.workflows.example import EXAMPLES, copy_example

    target, files = copy_example(args.name, args.out)
    print(f"wrote {target}: {EXAMPLES[args.name]}")
    for path in files:
        print(f"  {target / path}")
    readme = target / "README.md"
    if args.name == "examples":
        print(f"what they print and read: {readme}")
    elif args.name == "talos":
        print(f"what was simulated: {readme}; the true values: {target / 'truth.json'}")
    else:
        print(f"provenance and licence: {readme}" if readme.exists() else "provenance: docs/paper.md (Table 1)")
    return 0


def _run_urdf_from_dh(args: argparse.Namespace) -> int:
    from pincal.model.dh.urdf import DH_BASE_LINK, DH_FLANGE_LINK
    from pincal.workflows.preparation import urdf_from_dh_file

    run = urdf_from_dh_file(args.table, args.convention, args.out, name=args.name, degrees=args.degrees,
                            flange=args.flange)
    _print_notes(run.notes)
    robot = run.robot
    kinds = ", ".join(f"{robot.types.count(t)} {t}" for t in ("revolute", "prismatic", "continuous")
                      if t in robot.types)
    print(f"read {args.table}: {robot.n_joints} joints ({kinds}), {robot.convention} DH convention")
    print(f"wrote {args.out}: root link {DH_BASE_LINK}, joints {', '.join(robot.names)}, tip link "
          f"{DH_FLANGE_LINK} (Pinocchio FK = DH product to {run.fk_error:.1e})")
    print(f"next: pincal calibrate {args.out} DATA.csv --tip-link {DH_FLANGE_LINK} --level offsets "
          "--out CORRECTED.urdf --report REPORT.json")
    return 0


def _run_plan(args: argparse.Namespace) -> int:
    from pincal.cli.plan import run_plan  # what plan prints

    return run_plan(args)


def _run_extract(args: argparse.Namespace) -> int:
    from pincal.cli.extract import run_extract  # rosbags is loaded by this command only

    return run_extract(args)


def _run_detect(args: argparse.Namespace) -> int:
    from pincal.cli.detect import run_detect  # OpenCV is loaded by this command only

    return run_detect(args)


_COMMANDS = {
    "simulate": simulate_command, "calibrate": _run_calibrate, "evaluate": _run_evaluate, "diagnose": _run_diagnose,
    "demo": demo_command, "example": _run_example, "plan": _run_plan, "urdf-from-dh": _run_urdf_from_dh,
    "study": study_command, "report": _run_report, "extract": _run_extract,
    "detect": _run_detect,
}


def _blas_limited_to_one_thread() -> AbstractContextManager:
    """Many small factorisations: one BLAS thread each is faster than a pool that contends for the
    cores (the study's worker processes get the same setting). threadpoolctl limits the libraries
    already loaded, so numpy's and scipy's OpenBLAS (two builds) are loaded first, once the arguments
    are valid."""
    import numpy  # noqa: F401
    import scipy.linalg  # noqa: F401
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=1, user_api="blas")


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``pincal`` console script; returns the exit code."""
    args = build_parser().parse_args(argv)  # no numpy, scipy or Pinocchio yet: --help and refusals are quick
    try:
        with _blas_limited_to_one_thread():
            if args.command == "diagnose" and args.camera_link is not None:  # a camera's DATA.csv
                from pincal.cli.camera import run_diagnose as run_camera_diagnose

                camera_report, camera_withheld = run_camera_diagnose(args)
                return _warned(camera_report, args.strict, camera_withheld)
            if args.command == "diagnose":  # the camera's flags and data refused, --tip-link asked for
                _no_camera(args)
            if args.command == "diagnose" and not isinstance(args.tip_link, str) and len(args.tip_link) > 1:
                tree_report, tree_withheld = run_diagnose_tree(args)  # several targets on several chains
                return _warned(tree_report, args.strict, tree_withheld)
            several = isinstance(getattr(args, "tip_link", None), list) and len(args.tip_link) > 1  # plan: a tree
            if args.command == "diagnose" or (args.command == "plan" and args.camera_link is None and not several):
                args.tip_link = one_tip_link(args.command, args.tip_link)
            return _COMMANDS[args.command](args)
    except PincalError as exc:
        print(f"pincal: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except OSError as exc:  # file system trouble not caught closer to its cause
        print(f"pincal: error: {exc.filename or ''}: {exc.strerror or exc}", file=sys.stderr)
        return EXIT_USAGE


def console() -> None:
    """The ``pincal`` console script (and ``python -m pincal``): :func:`main`, then exit.

    Before exiting, :func:`gc.freeze` moves every live object out of the cyclic
    collector's reach, so the interpreter does not walk the heap that numpy,
    scipy, pinocchio, trimesh and matplotlib built (~0.2 s of a 2 s run); the
    process ends anyway, and every output was already written whole and
    flushed to disk (:mod:`pincal.outputs`)."""
    code = main()
    sys.stdout.flush()
    sys.stderr.flush()
    gc.freeze()
    sys.exit(code)


if __name__ == "__main__":
    console()
