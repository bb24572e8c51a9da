"""What ``pincal calibrate --fixture`` and ``pincal evaluate --fixture`` print: socket-fixture data, no sensor.

The jobs themselves — the calibration, the evaluation of placements the fit has not seen, the
corrected URDF and REPORT.json, evaluate's ``--json`` and ``--html`` — are :mod:`pincal.workflows.fixture`,
which prints nothing; this module refuses the flags of sensor data, runs them, prints the metrics and each
placement left out, and writes calibrate's ``--html`` page (:mod:`pincal.report.fixture_html`).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from typing import Any, cast

import numpy as np

from pincal.cli.arguments import selection_criterion
from pincal.cli.level_table import held_by_prior, level_choice_lines, prior_scale_line
from pincal.errors import PincalError
from pincal.fit.placement_check import PlacementPrediction
from pincal.fit.socket_metrics import FixtureMetrics
from pincal.report.effects_file import written_line
from pincal.report.model_fixture import FixtureEvaluationJson, FixtureReport
from pincal.workflows.evaluation_outputs import EvaluateOutputs
from pincal.workflows.fixture import calibrate_fixture_files, evaluate_fixture_files
from pincal.workflows.settings import CalibrateLevel, CalibrateSettings

__all__ = ["CALIBRATE_SENSOR_ONLY", "EVALUATE_SENSOR_ONLY", "run_calibrate", "run_evaluate"]

#: Flags of a sensor calibration that a fixture calibration has no use for (argparse dest → flag).
CALIBRATE_SENSOR_ONLY = {"method": "--method", "weight": "--weight", "tool": "--tool",
                         "sigma_column": "--sigma-column", "reject_outliers": "--reject-outliers",
                         "sigma_pos": "--sigma-pos"}
#: Flags of a sensor evaluation that a fixture evaluation has no use for.
EVALUATE_SENSOR_ONLY = {"max_pos_mm": "--max-pos-mm", "max_rot_deg": "--max-rot-deg",
                        "fixed_registration": "--fixed-registration", "new_session": "--new-session",
                        "temperature_column": "--temperature-column"}  # thermal: diagnose of sensor rows only


def _refuse(args: argparse.Namespace, flags: dict[str, str]) -> None:
    """One line for flags given that socket-fixture data have no use for: a value flag is given
    when not None (a ``--tool`` pose is an array: never compared by value), a switch when True."""
    given = [flag for name, flag in flags.items() if getattr(args, name, None) is not None
             and getattr(args, name) is not False]
    if given:
        verb = "does" if len(given) == 1 else "do"
        raise PincalError(f"{', '.join(given)} {verb} not apply to socket-fixture data (--fixture: no sensor, the "
                          "ball centre is estimated); drop " + ("it" if len(given) == 1 else "them"))


def run_calibrate(args: argparse.Namespace) -> tuple[FixtureReport, bool]:
    """``pincal calibrate URDF DATA... --fixture FIXTURE.csv --tip-link LINK``: prints the summary, returns
    the report (whose ``warnings`` the caller prints and turns into ``--strict``'s exit code) and whether
    the corrected URDF was withheld (exit 3)."""
    _refuse(args, CALIBRATE_SENSOR_ONLY)
    asked = cast(CalibrateLevel, args.level or "full")  # one of --level's choices
    if asked == "dh":
        raise PincalError("--level dh (the paper's methods) needs a sensor; use registration, offsets or full "
                          "with --fixture")
    xacro_args = getattr(args, "xacro_args", ()) or ()
    settings = CalibrateSettings(args.tip_link, level=asked, selection=selection_criterion(args), xacro_args=xacro_args,
                                 couplings=args.coupling or (), force=args.force)
    run = calibrate_fixture_files(args.urdf, args.data, args.fixture, args.out, args.report, settings,
                                  html=args.html)
    result, report = run.result, run.report
    level = result.level
    for note in report["notes"]:
        print(f"pincal: note: {note}", file=sys.stderr)
    if "level_choice" in report:
        print("\n".join(level_choice_lines(report["level_choice"])))
    ident = report["identifiability"]
    kept = sum(1 for p in report["parameters"] if p["calibrated"] is not None)
    print(f"socket fixture, level {level}: {result.n_rows} rows in {len(result.placements)} placement(s); "
          f"{kept} kinematic parameters kept of {len(report['parameters'])} ({ident['rank']} identifiable"
          f"{held_by_prior(ident, kept)}), plus the ball centre and the placements")
    if ident["selection"]:
        print(f"selection: {ident['selection']['criterion']} = {ident['selection']['value']:.4g} "
              f"with {ident['selection']['kept']} kept")
        scales = prior_scale_line(ident["selection"])
        if scales:
            print(scales)
    ball, std = result.ball * 1000.0, result.ball_std * 1000.0
    print(f"ball centre in {args.tip_link}: " + ", ".join(f"{v:.3f} ± {s:.3f}" for v, s in zip(ball, std)) + " mm")
    for placement in result.placements:
        turn = " (turn about the socket line not determined)" if placement.line_direction is not None else ""
        print(f"placement {placement.name}: {placement.rows} rows, sockets {', '.join(placement.sockets)}{turn}")
    for file, line, score in result.outliers:
        print(f"outlier (kept in the fit): {file} line {line} (robust score {score:.1f})")
    _print_metrics("calibration placements", result.nominal_training, result.training)
    if run.check is not None:
        _print_predictions(f"each placement left out, level {level} fitted on the others", run.check.placements)
    print(f"fit {result.fit_seconds * 1000:.1f} ms (with selection {result.total_seconds * 1000:.0f} ms)")
    from pincal.workflows.verdict import urdf_line

    print(urdf_line(args.out, run.withheld, run.reload_error))
    print(f"wrote {args.report}")
    if run.effects_file is not None:
        print(written_line(run.effects_file, report))
    if run.html is not None:
        print(f"wrote {run.html}")
    return report, run.withheld


def _print_metrics(title: str, before: FixtureMetrics | None, after: FixtureMetrics) -> None:
    print(f"{title:24s} {'consistency [mm]':>22s} {'distortion [mm]':>22s}")
    rows: list[tuple[str, Any, Any]] = [  # per placement (PlacementMetrics), then all (FixtureMetrics)
        (p.placement, b, p) for p, b in zip(after.placements, before.placements if before else
                                           [None] * len(after.placements))]
    rows.append(("all", before, after))
    for name, b, a in rows:
        cons = f"{a.consistency_mm:8.3f}" if b is None else f"{b.consistency_mm:8.3f} -> {a.consistency_mm:7.3f}"
        dist = f"{a.distortion_mm:8.3f}" if b is None else f"{b.distortion_mm:8.3f} -> {a.distortion_mm:7.3f}"
        print(f"{name:24s} {cons:>22s} {dist:>22s}")
    print("(nominal -> calibrated)" if before is not None else "(calibrated model only)")


def _print_predictions(title: str, predicted: Sequence[PlacementPrediction]) -> None:
    """Each placement's RMS ball-to-socket distance with only its own pose refitted, nominal -> calibrated [mm]."""
    if predicted:
        print(f"{title}, each with only its own pose fitted to its rows: RMS ball-to-socket distance [mm]")
    for p in predicted:
        nominal = "—" if not np.isfinite(p.nominal_mm) else f"{p.nominal_mm:.3f}"
        calibrated = f"not fitted ({p.failure})" if p.failure else f"{p.calibrated_mm:.3f}"
        flag = f"  worse than nominal (×{p.ratio:.2f} > ×{p.bound:.2f})" if p.worse else ""
        print(f"{p.placement:24s} {nominal:>8s} -> {calibrated}{flag}")


def run_evaluate(args: argparse.Namespace) -> FixtureEvaluationJson:
    """``pincal evaluate CORRECTED.urdf REPORT.json DATA... --fixture FIXTURE.csv [--nominal URDF]``: prints the
    metrics, returns the ``--json`` document (whose ``warnings`` the caller prints, as for ``run_calibrate``)."""
    _refuse(args, EVALUATE_SENSOR_ONLY)
    evaluation = evaluate_fixture_files(args.urdf, args.report, args.data, args.fixture, nominal_urdf=args.nominal,
                                        allow_other_urdf=args.allow_other_urdf,
                                        xacro_args=getattr(args, "xacro_args", ()) or (),
                                        outputs=EvaluateOutputs(args.json, args.html))
    for note in evaluation.notes:
        print(f"pincal: note: {note}", file=sys.stderr)
    _print_metrics("evaluated placements" + (" (not held out)" if evaluation.not_held_out else ""),
                   evaluation.before, evaluation.after)
    _print_predictions("held-out placements", evaluation.held_out)
    for path in evaluation.written:
        print(f"wrote {path}")
    return evaluation.as_dict()
