"""The ``pincal`` command line: a thin layer over :mod:`pincal.cli.workflows`.

Every user error is printed as one line ``pincal: error: ...`` with exit code
2; ``pincal evaluate`` exits 1 when a threshold is exceeded.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Sequence

import numpy as np

from pincal._version import __version__
from pincal.errors import PincalError
from pincal.fit.metrics import PoseErrors
from pincal.model.chain import pose_from_xyz_rpy
from pincal.simulation.paper import SimulationSettings

EXIT_THRESHOLD = 1
EXIT_USAGE = 2


def _tool(text: str) -> np.ndarray:
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != 6 or not np.all(np.isfinite(values)):
        raise argparse.ArgumentTypeError(
            f"'{text}' is not X,Y,Z,ROLL,PITCH,YAW (six numbers: metres, then radians)"
        )
    return pose_from_xyz_rpy(values[:3], values[3:])


def _number(kind: type, minimum: float, what: str):
    """argparse type: a finite ``kind`` (float or int) >= ``minimum``; ``what`` names it in errors."""

    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"'{text}' is not {what}") from None
        if not (np.isfinite(value) and value >= minimum):
            raise argparse.ArgumentTypeError(f"'{text}' must be >= {minimum:g} (a finite {what})")
        return value

    return parse


_non_negative = _number(float, 0.0, "number")
_count_or_zero = _number(int, 0, "integer")
_count = _number(int, 1, "integer")


def _positive(text: str) -> float:
    value = _non_negative(text)
    if value == 0:
        raise argparse.ArgumentTypeError(f"'{text}' must be > 0")
    return value


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="pincal",
        description="Calibrate robot kinematic models (URDF) with Pinocchio.",
    )
    parser.add_argument("--version", action="version", version=f"pincal {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    sim = sub.add_parser("simulate", help="simulate the paper's KUKA LWR 4+ experiment (Section 7)")
    sim.add_argument("--out", required=True, type=Path, help="output directory")
    sim.add_argument("--deviations", choices=("small", "large"), default="large",
                     help="Table 2 deviation set of the ground truth (default: large)")
    sim.add_argument("--sigma-pos", type=_non_negative, default=0.055, metavar="MM",
                     help="position noise per axis [mm] (default 0.055)")
    sim.add_argument("--sigma-rot", type=_non_negative, default=0.055, metavar="DEG",
                     help="orientation noise per angle [deg] (default 0.055)")
    sim.add_argument("--seed", type=_count_or_zero, default=0, help="random seed (default 0)")
    sim.add_argument("--effect", action="append", default=[], metavar="TYPE:JOINT:VALUE",
                     help="inject an undeclared effect (repeatable): compliance:J:RAD_PER_NM, "
                          "encoder_scale:J:REL, cyclic:J:H:SIN:COS, backlash:J:RAD[:gravity|approach], "
                          "drift:VX:VY:VZ (m/s), sensor_scale:REL")

    cal = sub.add_parser("calibrate", help="calibrate a URDF from measurements")
    cal.add_argument("urdf", type=Path, help="URDF to calibrate (never overwritten)")
    cal.add_argument("data", type=Path, help="measurement CSV (format v1)")
    cal.add_argument("--method", type=int, choices=(1, 2, 3),
                     help="1: positions only; 2: offsets from orientations, lengths from "
                          "positions (default); 3: full pose in one cost")
    cal.add_argument("--weight", type=_positive, default=1.0, metavar="W",
                     help="Method 3 weight w of Err_rot [mm^2/deg^2] (default 1)")
    cal.add_argument("--level", choices=("dh", "registration", "offsets", "full"),
                     help="what to calibrate: dh = the paper's DH parameters (needs --tool); "
                          "registration, offsets (joint zeros) or full (SE(3) error of every joint "
                          "placement) on any chain, estimating the target. Default: dh when "
                          "--method is given, else full")
    cal.add_argument("--tool", type=_tool, metavar="X,Y,Z,ROLL,PITCH,YAW",
                     help="known pose of the measured target in the tip link [m, rad]; "
                          "without it (levels other than dh) the target is estimated")
    cal.add_argument("--tool-parent", "--tip-link", dest="tip_link", metavar="LINK",
                     help="link at the end of the calibrated chain, carrying the target")
    cal.add_argument("--sigma-column", metavar="COLUMN",
                     help="extra data column with a per-row noise scale [mm]: rows are weighted by it")
    cal.add_argument("--reject-outliers", action="store_true",
                     help="refit without the rows reported as outliers (> 5 robust sigma)")
    cal.add_argument("--select", choices=("aic", "bic", "press", "all"), default="aic",
                     help="criterion choosing how many weakly identified parameters to keep "
                          "(default aic; computed on the calibration rows only)")
    cal.add_argument("--out", required=True, type=Path, metavar="CORRECTED.urdf",
                     help="corrected URDF to write")
    cal.add_argument("--report", required=True, type=Path, metavar="REPORT.json",
                     help="report to write")

    ev = sub.add_parser("evaluate", help="errors of a calibrated model on measured rows (eq 24)")
    ev.add_argument("urdf", type=Path, help="corrected URDF")
    ev.add_argument("report", type=Path, help="REPORT.json of the calibration")
    ev.add_argument("data", type=Path, help="measurement CSV to evaluate on")
    ev.add_argument("--json", type=Path, metavar="OUT", help="also write the metrics as JSON")
    ev.add_argument("--max-pos-mm", type=_non_negative, metavar="X",
                    help="fail (exit 1) if the largest position error exceeds X mm")
    ev.add_argument("--max-rot-deg", type=_non_negative, metavar="Y",
                    help="fail (exit 1) if the largest orientation error exceeds Y deg")

    dia = sub.add_parser("diagnose", help="calibrate, then find and add the effects the model lacks")
    dia.add_argument("urdf", type=Path, help="URDF to calibrate (never overwritten)")
    dia.add_argument("data", type=Path, help="measurement CSV (format v1)")
    dia.add_argument("--validation", type=Path, metavar="DATA2",
                     help="held-out measurements: errors reported before/after, effects that make them worse are refused")
    dia.add_argument("--tool-parent", "--tip-link", dest="tip_link", required=True, metavar="LINK",
                     help="link at the end of the calibrated chain, carrying the target")
    dia.add_argument("--level", choices=("registration", "offsets", "full"), default="full",
                     help="geometric model under the effects (default full)")
    dia.add_argument("--tool", type=_tool, metavar="X,Y,Z,ROLL,PITCH,YAW",
                     help="known pose of the measured target in the tip link [m, rad] (default: estimated)")
    dia.add_argument("--sigma-column", metavar="COLUMN", help="per-row noise scale column [mm]")
    dia.add_argument("--select", choices=("aic", "bic", "press", "all"), default="aic",
                     help="criterion for the geometric parameters (default aic)")
    dia.add_argument("--payload-kg", type=_non_negative, default=0.0, metavar="KG",
                     help="point mass at the target for gravity torques (default 0)")
    dia.add_argument("--time-column", metavar="COLUMN",
                     help="row time [s] for drift and approach order (default: time, t, timestamp or t_start_robot)")
    dia.add_argument("--plots", type=Path, metavar="DIR", help="write PNG plots into DIR (default: beside the report)")
    dia.add_argument("--out", required=True, type=Path, metavar="CORRECTED.urdf", help="corrected URDF to write")
    dia.add_argument("--report", required=True, type=Path, metavar="REPORT.json", help="report to write")

    demo = sub.add_parser("demo", help="simulate, calibrate with Methods 1-3, evaluate (< 30 s)")
    demo.add_argument("--out", type=Path, default=Path("pincal-demo"),
                      help="output directory (default: ./pincal-demo)")
    demo.add_argument("--seed", type=_count_or_zero, default=0, help="random seed (default 0)")

    study = sub.add_parser("study", help="the paper's simulation study (Section 7): all methods, "
                                         "noise limit, findings, figures")
    study.add_argument("--out", type=Path, default=Path("pincal-study"),
                       help="output directory (default: ./pincal-study)")
    study.add_argument("--reps", type=_count, default=25, metavar="N",
                       help="noise realisations per level, N_rep (default 25)")
    study.add_argument("--levels", type=_count, default=16, metavar="M",
                       help="noise levels from 0 to 0.15, M_n (default 16)")
    study.add_argument("--restarts", type=_count_or_zero, default=300, metavar="N",
                       help="random starting points per restart case (default 300, the paper's; 0 skips)")
    study.add_argument("--limit-pose-sets", type=_count_or_zero, default=2, metavar="L",
                       help="pose sets the noise limit is averaged over (default 2; 0 skips it)")
    study.add_argument("--workers", type=_count, default=None, metavar="N",
                       help="local worker processes (default: all cores; 1 runs in this process)")
    study.add_argument("--scheduler", metavar="ADDRESS",
                       help="run on a Dask cluster at ADDRESS, or 'local' to start a Dask LocalCluster")
    return parser


def _error_columns(errors: PoseErrors) -> str:
    pos = errors.position
    text = f"{pos.mean:9.4f} {pos.rms:9.4f} {pos.max:9.4f}"
    rot = errors.rotation
    text += f"  {rot.mean:9.4f} {rot.rms:9.4f} {rot.max:9.4f}" if rot else "  " + " " * 9 + "(no orientation data)"
    return text


_HEADER = (
    f"{'':24s} {'pos mean':>9s} {'pos RMS':>9s} {'pos max':>9s}  {'rot mean':>9s} {'rot RMS':>9s} {'rot max':>9s}\n"
    f"{'':24s} {'[mm]':>9s} {'[mm]':>9s} {'[mm]':>9s}  {'[deg]':>9s} {'[deg]':>9s} {'[deg]':>9s}"
)


def _print_notes(notes: Sequence[str]) -> None:
    for note in notes:
        print(f"pincal: note: {note}", file=sys.stderr)


def _run_simulate(args: argparse.Namespace) -> int:
    from pincal.cli.workflows import simulate_to_directory

    settings = SimulationSettings(sigma_pos_mm=args.sigma_pos, sigma_rot_deg=args.sigma_rot, seed=args.seed)
    experiment, truth = simulate_to_directory(args.out, args.deviations, settings, effects=args.effect)
    print(f"wrote {args.out / 'calibration.csv'} ({experiment.calibration.n_rows} rows: "
          f"{int(np.sum(experiment.calibration.roles == 'cpa'))} cpa, "
          f"{int(np.sum(experiment.calibration.roles == 'calibration'))} calibration)")
    print(f"wrote {args.out / 'validation.csv'} ({experiment.validation.n_rows} rows)")
    print(f"wrote {args.out / 'truth.json'}")
    print(f"next: {truth['calibrate_command']}")
    return 0


def _run_calibrate(args: argparse.Namespace) -> int:
    from pincal.cli.workflows import calibrate_files

    level = args.level or ("dh" if args.method is not None else "full")
    if args.tip_link is None:
        raise PincalError("give the end of the chain: --tip-link LINK (or --tool-parent LINK)")
    if level != "dh" and args.method is not None:
        raise PincalError(f"--method applies to --level dh only (got --level {level})")
    method = args.method or 2
    run = calibrate_files(args.urdf, args.data, method, args.weight, args.tool, args.tip_link,
                          args.out, args.report, level=level, sigma_column=args.sigma_column,
                          reject_outliers=args.reject_outliers, selection=args.select)
    _print_notes(run.notes + list(run.result.notes))
    if level == "dh":
        for stage in run.result.stages:
            print(f"{stage.name}: {len(stage.parameters)} parameters, RMS residual {stage.rms:.4g} "
                  f"{stage.unit}, {stage.n_evaluations} evaluations")
        print(f"Method {method} calibrated in {run.seconds * 1000:.1f} ms")
    else:
        _print_chain_summary(run)
    print(_HEADER)
    print(f"{'calibration rows':24s} {_error_columns(run.errors)}")
    print(f"wrote {args.out} (reload check: TCP reproduced to {run.reload_error:.1e} m)")
    print(f"wrote {args.report}")
    return 0


def _print_chain_summary(run) -> None:
    result = run.result
    ident = run.report["identifiability"]
    kept = sum(1 for p in run.report["parameters"] if p["calibrated"] is not None)
    print(f"level {result.level}: {kept} kinematic parameters kept of {len(run.report['parameters'])} "
          f"({ident['rank']} identifiable), plus registration and target")
    if ident["selection"]:
        sel = ident["selection"]
        print(f"selection: {sel['criterion']} = {sel['value']:.4g} with {sel['kept']} kept")
    print(f"Jacobian condition number (scaled): {ident['jacobian_condition']:.3g}")
    for pair in ident["correlated_pairs"][:10]:
        print(f"correlated: {pair['a']} ~ {pair['b']} ({pair['correlation']:+.3f})")
    for line, score in result.outliers:
        print(f"outlier: line {line} (robust score {score:.1f})")
    print(f"estimated noise: {result.sigma_pos_m * 1000:.3f} mm"
          + ("" if result.sigma_rot_rad is None else f", {np.degrees(result.sigma_rot_rad):.4f} deg"))
    print(f"fit {result.fit_seconds * 1000:.1f} ms (with selection {result.total_seconds * 1000:.0f} ms)")


def _run_evaluate(args: argparse.Namespace) -> int:
    from pincal.cli.workflows import evaluate_files

    evaluation = evaluate_files(args.urdf, args.report, args.data)
    _print_notes(evaluation.notes)
    errors = evaluation.errors
    print(_HEADER)
    print(f"{f'{errors.n_rows} rows':24s} {_error_columns(errors)}")
    if args.json:
        from pincal.cli.workflows import refuse_overwrite

        refuse_overwrite(args.json, args.urdf, args.report, args.data)
        args.json.write_text(json.dumps(evaluation.as_dict(), indent=2) + "\n", encoding="utf-8")
        print(f"wrote {args.json}")
    failed = []
    if args.max_pos_mm is not None and errors.position.max > args.max_pos_mm:
        failed.append(f"max position error {errors.position.max:.4f} mm > {args.max_pos_mm} mm")
    if args.max_rot_deg is not None:
        if errors.rotation is None:
            raise PincalError(f"{args.data}: --max-rot-deg needs orientation columns qx,qy,qz,qw")
        if errors.rotation.max > args.max_rot_deg:
            failed.append(f"max orientation error {errors.rotation.max:.4f} deg > {args.max_rot_deg} deg")
    for line in failed:
        print(f"pincal: FAIL: {line}", file=sys.stderr)
    return EXIT_THRESHOLD if failed else 0


def _run_diagnose(args: argparse.Namespace) -> int:
    from pincal.cli.workflows import diagnose_files

    plots = args.plots if args.plots is not None else args.report.parent / "diagnose_plots"
    run = diagnose_files(args.urdf, args.data, args.out, args.report, args.tip_link, level=args.level,
                         tool_pose=args.tool, validation_path=args.validation, sigma_column=args.sigma_column,
                         selection=args.select, payload_kg=args.payload_kg, time_column_name=args.time_column,
                         plots_dir=plots)
    _print_notes(run.notes + list(run.calibration.notes))
    diagnosis = run.diagnosis
    held = diagnosis.heldout_errors is not None
    print(f"geometric calibration ({run.calibration.level}), then {len(diagnosis.steps)} effect(s) adopted:")
    header = f"{'step':38s} {'value ± std':>26s} {'dBIC':>8s} {'cal RMS [mm]':>17s}"
    print(header + (f" {'held-out RMS [mm]':>19s}" if held else ""))
    for step in diagnosis.steps:
        value = ", ".join(f"{v:.4g}±{s:.2g}" for v, s in zip(step.values, step.std))
        line = (f"{step.effect.label:38s} {value:>26s} {step.delta_bic:8.1f} "
                f"{step.calibration_before.position.rms:7.3f} -> {step.calibration_after.position.rms:6.3f}")
        if held:
            line += f" {step.heldout_before.position.rms:8.3f} -> {step.heldout_after.position.rms:6.3f}"
        print(line)
    if not diagnosis.steps:
        print("  nothing significant: no effect is claimed")
    for effect, values, std in diagnosis.effects:  # refitted together: what evaluate applies
        value = ", ".join(f"{v:.4g} ± {s:.2g}" for v, s in zip(values, std))
        print(f"final model: {effect.label} = {value}")
    for note in diagnosis.notes:
        print(f"reported, not adopted: {note}")
    print(diagnosis.unexplained or "no structure left that a generic joint-angle correction would explain")
    print(_HEADER)
    print(f"{'calibration rows':24s} {_error_columns(diagnosis.calibration_errors)}")
    if held:
        print(f"{'held-out rows':24s} {_error_columns(diagnosis.heldout_errors)}")
    for path in run.plots:
        print(f"wrote {path}")
    print(f"wrote {args.out}\nwrote {args.report} (effects: pincal evaluate applies them; a URDF cannot carry them)")
    return 0


def _run_demo(args: argparse.Namespace) -> int:
    from pincal.cli.workflows import run_demo

    settings = SimulationSettings(sigma_pos_mm=0.055, sigma_rot_deg=0.055, seed=args.seed)
    print("KUKA LWR 4+ (Table 1), ground truth = Table 1 + large deviations (Table 2),")
    print(f"sensor noise sigma_p = {settings.sigma_pos_mm} mm, sigma_a = {settings.sigma_rot_deg} deg, "
          f"K = {settings.n_calibration} calibration + {settings.n_cpa} CPA rows per joint, "
          f"J = {settings.n_validation} held-out rows, seed {settings.seed}")
    rows = run_demo(args.out, settings)
    print()
    print("errors on held-out rows (eq 24; positions through Registration 1, orientations through Registration 2)")
    print(_HEADER + f" {'fit [ms]':>9s}")
    for row in rows:
        timing = f" {row.seconds * 1000:9.1f}" if row.seconds else f" {'-':>9s}"
        print(f"{row.label:24s} {_error_columns(row.validation)}{timing}")
    print()
    print(f"corrected URDFs, reports and data in {args.out}/ "
          f"(kuka_lwr4plus_method2.urdf is the paper's recommended calibration)")
    return 0


def _run_study(args: argparse.Namespace) -> int:
    from pincal.cli.workflows import ensure_directory
    from pincal.study.run import ProgressBar, StudyConfig, run_study, write_study

    ensure_directory(args.out)  # before the run, not after it
    config = StudyConfig(levels=args.levels, repeats=args.reps, restarts=args.restarts,
                         limit_pose_sets=args.limit_pose_sets)
    progress = ProgressBar(sys.stderr) if sys.stderr.isatty() else None
    result = run_study(config, workers=args.workers, scheduler=args.scheduler, progress=progress)
    paths = write_study(result, args.out)
    print(f"{len(result.rows)} rows from {config.levels} noise levels x {config.repeats} repeats x "
          f"{len(config.deviations)} deviation sets, {sum(r['starts'] for r in result.restart_summary)} restarts; "
          f"{result.wall_s:.1f} s on {result.executor}")
    print()
    for finding in result.findings:
        print(f"{'holds' if finding['holds'] else 'FAILS':5s}  {finding['finding']}: {finding['evidence']}")
    print()
    for name in ("study", "summary", "restarts", "findings", "json"):
        print(f"wrote {paths[name]}")
    print(f"wrote {len(paths['figures'])} figures in {args.out}/")
    return 0


_COMMANDS = {
    "simulate": _run_simulate,
    "calibrate": _run_calibrate,
    "evaluate": _run_evaluate,
    "diagnose": _run_diagnose,
    "demo": _run_demo,
    "study": _run_study,
}


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``pincal`` console script; returns the exit code."""
    args = build_parser().parse_args(argv)
    try:
        return _COMMANDS[args.command](args)
    except PincalError as exc:
        print(f"pincal: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except OSError as exc:  # file system trouble not caught closer to its cause
        print(f"pincal: error: {exc.filename or ''}: {exc.strerror or exc}", file=sys.stderr)
        return EXIT_USAGE


if __name__ == "__main__":
    sys.exit(main())
