"""The ``pincal`` command line's arguments: every subcommand, flag and default (the values' types,
which check them so that a bad number is one argparse line, are :mod:`pincal.cli.arguments`).

No numpy, scipy or Pinocchio here (``--help`` and refusals in 0.06 s, not 0.7 s; tests/test_cli_start.py):
defaults and choices come from constant modules of the layers owning them; a type returning a library value
imports it for a valid one. ``--coupling`` and ``--xacro-arg`` load numpy, lxml (refused in 0.12, 0.09 s)."""

from __future__ import annotations

import argparse
from pathlib import Path

from pincal._version import __version__
from pincal.cli.arguments import (
    TipLinks,
    count,
    count_or_zero,
    coupling_arg,
    joint_names,
    measure,
    non_negative,
    package_dir,
    positive,
    prior_scale,
    seconds,
    target_points,
    tool_pose,
    xacro_arg,
)
from pincal.fit.prior_defaults import DEFAULT_JOINT_ZERO_DEG, DEFAULT_ROTATION_DEG, DEFAULT_TRANSLATION_MM
from pincal.measurements.charuco import BOARD_EXAMPLE, BOARD_FORM
from pincal.measurements.plateau_defaults import (
    MAX_OFFSET_S,
    MAX_SPREAD_MM,
    MIN_SAMPLES,
    MIN_STILL_S,
    STILL_TOL,
    TRIM_S,
)
from pincal.model.dh.conventions import DH_CONVENTIONS
from pincal.model.masses import DEFAULT_MASSES, MASSES
from pincal.planning.defaults import DEFAULT_AIMED, DEFAULT_SAMPLE, PLAN_LEVELS, WORKSPACE_SIZE

__all__ = ["build_parser"]


def _add_coupling(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--coupling", type=coupling_arg, action="append", metavar="JOINT=FACTOR*DRIVER",
                        help="JOINT's reading includes FACTOR x DRIVER's (repeatable): corrected in every row read, "
                             "recorded in REPORT.json and CORRECTED.effects.yaml (beside --out) and applied by "
                             "evaluate; e.g. A3=-1*A2 where the controller reads J3 from the horizontal (pincal "
                             "diagnose names it)")


def _add_xacro_arg(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--xacro-arg", dest="xacro_args", type=xacro_arg, action="append", default=[],
                        metavar="NAME:=VALUE", help="argument of a .xacro robot description (repeatable); "
                        "the .xacro file is expanded in memory")


def _add_temperature(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--temperature-column", metavar="COLUMN", help="row temperature [°C] for thermal expansion "
                        "(default: temperature_c or temperature; evaluate: the report's)")


def _add_quiet(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--quiet", action="store_true", help="no progress on stderr (default: a bar in a terminal "
                        "once the work takes over a second, a line every 10 s in logs; pincal.cli.progress)")


def _add_plausibility(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--sigma-pos", type=positive, metavar="MM",
                        help="the sensor's stated position noise per axis [mm]: a residual per axis above 3x it is "
                             "noted (with the pincal diagnose command to run), above 20x warned about "
                             "(pincal.fit.plausibility); the fit's weights come from the data either way")
    parser.add_argument("--strict", action="store_true",
                        help="exit 3 when any warning is given (the outputs are written all the same)")
    parser.add_argument("--force", action="store_true",
                        help="write the corrected URDF (and effects.yaml) even when the model misses its rows by more "
                             "than 5%% of the robot's reach, which no physical effect does (without it: exit 3, the "
                             "report and --html written, not these)")


def _add_extract(sub) -> None:
    ext = sub.add_parser("extract", help="cut the static postures of a ROS bag into measurement rows (CSV v1)")
    ext.add_argument("bag", type=Path, metavar="BAG",
                     help="ROS 1 .bag, rosbag2 folder (sqlite3 or MCAP), or one .mcap/.db3 file")
    ext.add_argument("--joints", required=True, metavar="TOPIC",
                     help="sensor_msgs/JointState topic: its joint names are the joint columns")
    measured = ext.add_mutually_exclusive_group(required=True)
    measured.add_argument("--pose", metavar="TOPIC", help="PoseStamped or TransformStamped topic, or tf:CHILD_FRAME "
                          "(a frame of /tf): columns x,y,z,qx,qy,qz,qw")
    measured.add_argument("--point", action="append", metavar="TOPIC",
                          help="PointStamped (or a pose topic, position only) or tf:CHILD_FRAME, repeatable: one gives "
                               "x,y,z, several x1,y1,z1,x2,... in the order given (points of one rigid target)")
    measured.add_argument("--image", metavar="TOPIC",
                          help="sensor_msgs/Image or CompressedImage topic of a camera: each stop's middle image "
                               "saved as a PNG in --image-dir, and --out is JOINTS.csv for pincal detect")
    ext.add_argument("--joint-names", type=joint_names, metavar="JOINT[,JOINT...]",
                     help="keep these joints only, judged still and written (default: every joint of the topic)")
    ext.add_argument("--still-tol", type=positive, default=STILL_TOL, metavar="RAD",
                     help=f"still: every joint within this (max - min) [rad; m for prismatic] (default {STILL_TOL:g})")
    ext.add_argument("--min-still", type=positive, default=MIN_STILL_S, metavar="S",
                     help=f"for at least this long [s] (default {MIN_STILL_S:g})")
    ext.add_argument("--trim", type=non_negative, default=TRIM_S, metavar="S",
                     help=f"cut from both ends of a still stretch before averaging [s] (default {TRIM_S:g})")
    ext.add_argument("--min-samples", type=count, default=MIN_SAMPLES, metavar="N",
                     help=f"refuse a stop with fewer samples of a measured topic in its window (default {MIN_SAMPLES})")
    ext.add_argument("--max-spread", type=positive, default=MAX_SPREAD_MM, metavar="MM",
                     help="refuse a stop whose measured positions spread more (RMS about their mean) [mm] "
                          f"(default {MAX_SPREAD_MM:g})")
    offset = ext.add_mutually_exclusive_group()  # a given offset is not searched for
    offset.add_argument("--max-offset", type=positive, default=MAX_OFFSET_S, metavar="S",
                     help="search the clock offset this far either side of the receive times' estimate [s] "
                          f"(default {MAX_OFFSET_S:g})")
    offset.add_argument("--clock-offset", type=seconds, metavar="S",
                     help="measurement stamp minus joint stamp of one instant [s], instead of estimating it")
    ext.add_argument("--out", required=True, type=Path, metavar="DATA.csv",
                     help="measurement CSV (v1) to write; with --image, JOINTS.csv")
    ext.add_argument("--image-dir", type=Path, metavar="DIR",
                     help="with --image: the folder of the images (default: OUT_images beside --out)")


def _add_detect(sub) -> None:
    detect = sub.add_parser("detect", help="find a ChArUco board's corners in images: a camera's measurement CSV")
    detect.add_argument("images", nargs="+", type=Path, metavar="IMAGES",
                        help="image files (PNG, JPEG) or folders (their PNG and JPEG files, by name)")
    detect.add_argument("--board", required=True, metavar=BOARD_FORM,
                        help=f"the board in OpenCV's conventions: squares across and down, square and marker sides "
                             f"[m], an OpenCV dictionary; e.g. {BOARD_EXAMPLE}")
    detect.add_argument("--joints", required=True, type=Path, metavar="JOINTS.csv",
                        help="an 'image' column naming each image file, then one column per URDF joint (rad; m for "
                             "prismatic), optionally role and session")
    detect.add_argument("--out", required=True, type=Path, metavar="DATA.csv",
                        help="CSV to write: one row per corner found (docs/camera.md)")


def _add_camera_plan(plan: argparse.ArgumentParser) -> None:
    """``plan``'s flags of a camera: the images to take of a ChArUco board (docs/camera.md)."""
    camera = plan.add_argument_group("a camera (plan the images of a ChArUco board instead of --tip-link)")
    camera.add_argument("--camera-link", metavar="LINK",
                        help="the link of the camera's optical frame, attached by a fixed joint: on the chain (eye "
                             "in hand) or hanging from the root (eye to hand)")
    camera.add_argument("--board-link", metavar="LINK", help="eye to hand: the link on the chain carrying the board")
    camera.add_argument("--intrinsics", type=Path, metavar="FILE",
                        help="the camera's intrinsics with its image size: ROS camera_info or OpenCV YAML")
    camera.add_argument("--board", metavar=BOARD_FORM, help=f"the board, as detect takes it; e.g. {BOARD_EXAMPLE}")
    camera.add_argument("--board-pose", type=tool_pose, metavar="X,Y,Z,ROLL,PITCH,YAW",
                        help="eye in hand: where the board is in the root link's frame, roughly [m, rad] (OpenCV's "
                             "board frame: origin at its outer corner before corner 0, z out of its back); or "
                             "--existing DATA.csv of a first run")


def _add_camera(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--camera-link", metavar="LINK",
                        help="DATA is a camera's DATA.csv (pincal detect): LINK is the camera's optical frame, "
                             "attached by a fixed joint; eye in hand when it rides on the chain (the board fixed in "
                             "the world), eye to hand when it hangs from the root (give --board-link); no --tip-link "
                             "(docs/camera.md)")
    parser.add_argument("--board-link", metavar="LINK",
                        help="with --camera-link, eye to hand: the link on the chain carrying the board (its frame "
                             "OpenCV's board frame), attached by a fixed joint")
    parser.add_argument("--intrinsics", metavar="FILE|estimate",
                        help="with --camera-link: the camera's intrinsics (ROS camera_info or OpenCV YAML), or "
                             "'estimate': started from OpenCV's calibrateCamera and fitted with the rest; written "
                             "as CORRECTED.camera_info.yaml beside --out")
    parser.add_argument("--images", type=Path, metavar="DIR",
                        help="with --camera-link: the folder of the image files, where the HTML page (--html, or "
                             "pincal report later) finds the one image it draws (default: DATA.csv's folder; DATA.csv "
                             "names each image by its file name)")


def _add_prior_scale(sub: argparse.ArgumentParser) -> None:
    sub.add_argument("--prior-scale", type=prior_scale, metavar="MM,DEG[,DEG]",
                     help="with --select prior: fix the prior std of each placement translation and prismatic joint "
                          "zero [mm], of each placement rotation [deg] and of each revolute joint zero [deg] (the "
                          "rotations' when not given) (default: estimated from the rows, from "
                          f"{DEFAULT_TRANSLATION_MM:g},{DEFAULT_ROTATION_DEG:g},{DEFAULT_JOINT_ZERO_DEG:g}; "
                          "pincal.fit.prior_scales)")


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
    sim.add_argument("--sigma-pos", type=non_negative, default=0.055, metavar="MM",
                     help="position noise per axis [mm] (default 0.055)")
    sim.add_argument("--sigma-rot", type=non_negative, default=0.055, metavar="DEG",
                     help="orientation noise per angle [deg] (default 0.055)")
    sim.add_argument("--seed", type=count_or_zero, default=0, help="random seed (default 0)")
    sim.add_argument("--effect", action="append", default=[], metavar="TYPE:JOINT:VALUE",
                     help="inject an undeclared effect (repeatable): compliance:J:RAD_PER_NM, "
                          "compliance:J:DRIVER:RAD_PER_NM (J deflects under DRIVER's gravity torque), "
                          "encoder_scale:J:REL, cyclic:J:H:SIN:COS, backlash:J:RAD[:gravity|approach], "
                          "coupling:J:DRIVER:REL (J's actual angle adds REL x DRIVER's reading), "
                          "drift:VX:VY:VZ (m/s), sensor_scale:REL, thermal:ALPHA (1/K; writes temperature_c), "
                          "pause_step:DX:DY:DZ (m; an 8 h pause halfway), lateral:J:CU:CV (rad/(N·m): J bends about "
                          "its two lateral axes under the gravity moment about them)")

    cal = sub.add_parser("calibrate", help="calibrate a URDF from measurements")
    cal.add_argument("urdf", type=Path, help="URDF to calibrate, or a .xacro (never overwritten)")
    cal.add_argument("data", type=Path, nargs="+", metavar="DATA",
                     help="measurement CSV(s) (format v1): each file a session with its own registration "
                          "(and within a file, each value of its 'session' column)")
    cal.add_argument("--method", type=int, choices=(1, 2, 3),
                     help="1: positions only; 2: offsets from orientations, lengths from "
                          "positions (default); 3: full pose in one cost")
    cal.add_argument("--weight", type=positive, metavar="W",
                     help="Method 3 weight w of Err_rot [mm^2/deg^2] (default 1)")
    cal.add_argument("--level", choices=("dh", "registration", "offsets", "full", "auto"),
                     help="what to calibrate: dh = the paper's DH parameters (needs --tool); "
                          "registration, offsets (joint zeros) or full (SE(3) error of every joint "
                          "placement) on any chain, estimating the target; auto = the one of those three "
                          "that cross-validation on the calibration data supports. Default: dh when "
                          "--method is given, else full")
    cal.add_argument("--tool", type=tool_pose, metavar="X,Y,Z,ROLL,PITCH,YAW",
                     help="known pose of the measured target in the tip link [m, rad]; "
                          "without it (levels other than dh) the target is estimated")
    cal.add_argument("--tip-link", "--tool-parent", dest="tip_link", metavar="LINK[:POINTS]",
                     action=TipLinks,
                     help="link at the end of the calibrated chain, carrying the target (or the ball, with "
                          "--fixture); repeat it as LINK:POINTS for several targets on several chains in one "
                          "calibration (e.g. --tip-link right_hand:1 --tip-link left_hand:2,3: point 1 is x1,y1,z1)")
    cal.add_argument("--sigma-column", metavar="COLUMN",
                     help="extra data column with a per-row noise scale [mm]: rows are weighted by it")
    cal.add_argument("--reject-outliers", action="store_true",
                     help="refit without the rows reported as outliers (> 5 robust sigma)")
    cal.add_argument("--select", choices=("aic", "bic", "press", "all", "prior"), default=None,
                     help="criterion choosing how many weakly identified parameters to keep "
                          "(default prior; computed on the calibration rows only); prior: keep every identifiable "
                          "one, each pulled towards nominal by a Gaussian prior (--prior-scale)")
    _add_prior_scale(cal)
    cal.add_argument("--fixture", type=Path, metavar="FIXTURE.csv",
                     help="socket-fixture data, no sensor: DATA names the socket of each row (point) and the "
                          "fixture placement; FIXTURE.csv gives the sockets (point,x,y,z [m] or "
                          "point_a,point_b,distance)")
    _add_camera(cal)
    _add_plausibility(cal)
    _add_coupling(cal)
    _add_xacro_arg(cal)
    _add_quiet(cal)
    cal.add_argument("--out", required=True, type=Path, metavar="CORRECTED.urdf",
                     help="corrected URDF to write")
    cal.add_argument("--report", required=True, type=Path, metavar="REPORT.json",
                     help="report to write")
    cal.add_argument("--html", type=Path, metavar="REPORT.html",
                     help="also write the report as one self-contained HTML page (figures embedded; opens from disk)")

    ev = sub.add_parser("evaluate", help="errors of a calibrated model on measured rows (eq 24)")
    ev.add_argument("urdf", type=Path, help="corrected URDF")
    ev.add_argument("report", type=Path, help="REPORT.json of the calibration")
    ev.add_argument("data", type=Path, help="measurement CSV to evaluate on")
    ev.add_argument("--json", type=Path, metavar="OUT", help="also write the metrics as JSON")
    ev.add_argument("--fixed-registration", nargs="?", const="", metavar="NAME",
                    help="evaluate every row through the registration of the report's session NAME (default: "
                         "its only or first session) instead of re-estimating it for a session the fit has not seen")
    ev.add_argument("--new-session", action="store_true",
                    help="DATA is a session the fit has not seen (the sensor moved): re-estimate its registration "
                         "(6 parameters; model and target fixed) even when the report has one session")
    ev.add_argument("--html", type=Path, metavar="REPORT.html",
                    help="also write the report with these errors (every row by file line) as one HTML page")
    _add_temperature(ev)
    _add_xacro_arg(ev)
    ev.add_argument("--allow-other-urdf", action="store_true",
                    help="evaluate a URDF other than the one the report was written with (edited on purpose)")
    ev.add_argument("--fixture", type=Path, metavar="FIXTURE.csv",
                    help="socket-fixture data (calibrate --fixture): consistency and distortion of the ball centre")
    ev.add_argument("--nominal", type=Path, metavar="URDF",
                    help="with --fixture: the uncalibrated URDF, for 'before' (default: the report's sources.urdf)")
    ev.add_argument("--max-pos-mm", type=non_negative, metavar="X",
                    help="fail (exit 1) if the largest position error exceeds X mm")
    ev.add_argument("--max-rot-deg", type=non_negative, metavar="Y",
                    help="fail (exit 1) if the largest orientation error exceeds Y deg")
    ev.add_argument("--strict", action="store_true", help="exit 3 when a warning is given (the evaluated error "
                    "implausible against the calibration's; with --fixture, a placement the calibration has not seen "
                    "predicted worse than by the nominal URDF; before --max-pos-mm's exit 1; --json written all the "
                    "same)")

    dia = sub.add_parser("diagnose", help="calibrate, then find and add the effects the model lacks")
    dia.add_argument("urdf", type=Path, help="URDF to calibrate, or a .xacro (never overwritten)")
    dia.add_argument("data", type=Path, nargs="+", metavar="DATA",
                     help="measurement CSV(s) (format v1): each file (or 'session' value) a session")
    dia.add_argument("--validation", type=Path, metavar="DATA2",
                     help="held-out measurements: errors reported before/after; an effect is adopted only if they "
                          "fit better beyond their noise (a paired test over their rows)")
    dia.add_argument("--tool-parent", "--tip-link", dest="tip_link", metavar="LINK", action=TipLinks,
                     help="link at the end of the calibrated chain, carrying the target (required, but for a "
                          "camera's DATA.csv: --camera-link)")
    dia.add_argument("--level", choices=("registration", "offsets", "full", "auto"), default="full",
                     help="geometric model under the effects (default full; auto: chosen by cross-validation "
                          "of the geometric calibration)")
    dia.add_argument("--tool", type=tool_pose, metavar="X,Y,Z,ROLL,PITCH,YAW",
                     help="known pose of the measured target in the tip link [m, rad] (default: estimated)")
    dia.add_argument("--sigma-column", metavar="COLUMN", help="per-row noise scale column [mm]")
    dia.add_argument("--select", choices=("aic", "bic", "press", "all", "prior"), default=None,
                     help="criterion for the geometric parameters (default prior; prior: see calibrate)")
    _add_prior_scale(dia)
    dia.add_argument("--payload-kg", type=non_negative, default=0.0, metavar="KG",
                     help="point mass at the target for gravity torques (default 0)")
    dia.add_argument("--masses", choices=MASSES, default=DEFAULT_MASSES,
                     help="gravity loads from the URDF's inertias (urdf, the default; a URDF without any counts as "
                          "unknown), or unknown: each compliance follows the carried links' mass moments, fitted as "
                          "the combinations the rows determine")
    dia.add_argument("--lateral", action="store_true",
                     help="also try each revolute joint's lateral (bending) compliance: the joint turning about the "
                          "two axes orthogonal to its own under the gravity moment it carries")
    dia.add_argument("--time-column", metavar="COLUMN",
                     help="row time [s] for drift and approach order (default: time, t, timestamp or t_start_robot)")
    _add_temperature(dia)
    dia.add_argument("--pause-s", type=positive, metavar="S",
                     help="a gap longer than S seconds between rows of a session starts a new segment, its "
                          "registration stepped (default 1800: a stop long enough for the cell's temperature to move; "
                          "a measuring program's rows are seconds to minutes apart)")
    dia.add_argument("--plots", type=Path, metavar="DIR", help="write PNG plots into DIR (default: beside the report)")
    _add_camera(dia)
    _add_plausibility(dia)
    _add_coupling(dia)
    _add_xacro_arg(dia)
    _add_quiet(dia)
    dia.add_argument("--out", required=True, type=Path, metavar="CORRECTED.urdf", help="corrected URDF to write")
    dia.add_argument("--report", required=True, type=Path, metavar="REPORT.json", help="report to write")
    dia.add_argument("--html", type=Path, metavar="REPORT.html",
                     help="also write the report as one self-contained HTML page (figures embedded; opens from disk)")

    dh = sub.add_parser("urdf-from-dh", help="write a URDF from a DH table (CSV, standard or modified convention)")
    dh.add_argument("table", type=Path, metavar="TABLE.csv",
                    help="one row per joint: joint, a [m], alpha [rad], d [m], theta (offset) [rad]; "
                         "optional type (revolute|prismatic|continuous), lower, upper, velocity, effort")
    dh.add_argument("--convention", choices=DH_CONVENTIONS, required=True,
                    help="what a row means: standard: Rz(theta+q) Tz(d) Tx(a) Rx(alpha) (distal); modified: "
                         "Craig's Rx(alpha_i-1) Tx(a_i-1) Rz(theta_i+q) Tz(d_i)")
    dh.add_argument("--out", type=Path, required=True, metavar="ROBOT.urdf",
                    help="URDF to write (its folder is created if missing)")
    dh.add_argument("--name", help="robot name (default: the output file's stem)")
    dh.add_argument("--degrees", action="store_true",
                    help="the table's alpha, theta and revolute limits are in degrees")
    dh.add_argument("--flange", type=tool_pose, metavar="X,Y,Z,ROLL,PITCH,YAW",
                    help="constant flange transform after the last DH frame [m, rad; always radians]")

    plan = sub.add_parser("plan", help="choose the robot configurations worth measuring, and their order")
    plan.add_argument("urdf", type=Path, help="URDF of the robot, or a .xacro")
    plan.add_argument("--tip-link", "--tool-parent", dest="tip_link", metavar="LINK[:POINTS]", action=TipLinks,
                      help="link at the end of the calibrated chain, carrying the target (required, but for a "
                           "camera: --camera-link); repeated, LINK:POINTS each: several targets on the chains of "
                           "a tree, as calibrate takes them")
    plan.add_argument("--count", type=count, required=True, metavar="N", help="configurations to choose")
    plan.add_argument("--out", required=True, type=Path, metavar="PLAN.csv", help="plan to write (visiting order)")
    plan.add_argument("--report", type=Path, metavar="PLAN.json", help="prediction to write (required, but for a "
                                                                        "camera)")
    _add_camera_plan(plan)
    plan.add_argument("--level", choices=PLAN_LEVELS, default="full",
                      help="what the calibration will estimate (default full); dh: the paper's DH parameters "
                           "with the tool known (needs --tool), as calibrate --level dh estimates them")
    plan.add_argument("--tool", type=tool_pose, metavar="X,Y,Z,ROLL,PITCH,YAW",
                      help="known target pose in the tip link [m, rad] (default: the target is estimated)")
    plan.add_argument("--measure", type=measure, metavar="point|points:M|pose",
                      help="what the sensor sees (default: point, or what --existing holds)")
    plan.add_argument("--target-points", type=target_points, metavar="X,Y,Z[;X,Y,Z...]",
                      help="assumed target points in the tip link [m] (default: --existing's, or 0.05 m about "
                           "(0, 0, 0.1))")
    pool = plan.add_mutually_exclusive_group()
    pool.add_argument("--candidates", type=Path, metavar="CSV", help="choose among these configurations "
                      "(joint columns as in CSV v1; other columns ignored)")
    pool.add_argument("--sample", type=count, default=None, metavar="M",
                      help=f"else draw M within the joint limits (default {DEFAULT_SAMPLE}; for a camera M aimed at "
                           f"the board and M drawn, default {DEFAULT_AIMED})")
    plan.add_argument("--seed", type=count_or_zero, default=0, help="random seed (default 0)")
    plan.add_argument("--existing", type=Path, nargs="+", metavar="DATA.csv", help="measurements already "
                      "recorded, one file per session (the plan continues the last): choose what adds most to them")
    plan.add_argument("--workspace", type=Path, metavar="CSV", help="configurations where accuracy matters "
                      f"(default: {WORKSPACE_SIZE} of the candidates)")
    plan.add_argument("--criterion", choices=("accuracy", "d", "a"), default="accuracy",
                      help="accuracy: predicted mean position error (default); d, a: D-/A-optimality")
    plan.add_argument("--select", choices=("aic", "bic", "press", "all", "prior"), default=None,
                      help="the selection the calibration will use, as calibrate's --select (default prior at "
                           "offsets and full, as calibrate): with prior the plan counts its information too")
    _add_prior_scale(plan)
    plan.add_argument("--sigma-pos", type=positive, metavar="MM", help="sensor noise per axis [mm] "
                      "(default: from --existing, else 0.055)")
    plan.add_argument("--sigma-rot", type=positive, metavar="DEG", help="orientation noise [deg] (pose)")
    collision = plan.add_mutually_exclusive_group()
    collision.add_argument("--min-distance", type=non_negative, metavar="M",
                           help="refuse candidates with links closer than M metres (default: those in "
                                "self-collision, where the URDF has collision geometry)")
    collision.add_argument("--no-collision-check", action="store_true",
                           help="do not check the candidates for self-collision")
    plan.add_argument("--srdf", metavar="FILE", help="the robot's SRDF: its disable_collisions link pairs (except "
                      "those disabled as 'Never' in collision) are the ones not checked (default: the pairs in contact "
                      "at the zero configuration); not with --min-distance or --no-collision-check")
    plan.add_argument("--package-dir", type=package_dir, action="append", default=[], metavar="NAME=DIR",
                      help="folder of ROS package NAME for package://NAME/... collision meshes (repeat for "
                           "several; else ROS_PACKAGE_PATH, the ament index, the folders above the URDF)")
    _add_coupling(plan)
    _add_xacro_arg(plan)
    _add_quiet(plan)
    plan.add_argument("--alternate", type=joint_names, default=(), metavar="JOINT[,JOINT...]",
                      help="order so that these joints reach their positions from both directions equally")

    html = sub.add_parser("report", help="write the HTML page of an existing REPORT.json (or evaluate --json file, "
                                               "or PLAN.json of plan: the plan's page)")
    html.add_argument("document", type=Path, metavar="REPORT.json",
                      help="report written by calibrate or diagnose (or PLAN.json)")
    html.add_argument("--out", required=True, type=Path, metavar="REPORT.html",
                      help="HTML page to write: self-contained, figures embedded, no network")

    example = sub.add_parser("example", help="copy a measurement set shipped with pincal (TIAGo mocap, MUKCa, "
                                             "a ROS 2 bag), the KUKA URDF or the example scripts to DIR/NAME, for "
                                             "the docs' commands outside a clone; talos: make TALOS's simulated set")
    example.add_argument("name", choices=("tiago_mocap", "mukca", "lwr_bag", "urdf", "examples", "talos"),
                         metavar="NAME",
                         help="tiago_mocap, mukca, lwr_bag, urdf, examples or talos (pincal example urdf --out . gives "
                              "the docs' urdf/kuka_lwr4plus.urdf, pincal example examples --out . their examples/*.py; "
                              "talos is simulated on the spot: TALOS's URDF and motion-capture rows of both hands)")
    example.add_argument("--out", type=Path, default=Path("data"),
                         help="folder to put NAME in (default: ./data, where the docs' commands look)")

    _add_extract(sub)
    _add_detect(sub)

    demo = sub.add_parser("demo", help="simulate, calibrate with Methods 1-3, evaluate (< 30 s)")
    demo.add_argument("--out", type=Path, default=Path("pincal-demo"),
                      help="output directory (default: ./pincal-demo)")
    demo.add_argument("--seed", type=count_or_zero, default=0, help="random seed (default 0)")

    study = sub.add_parser("study", help="the paper's simulation study (Section 7): all methods, "
                                         "noise limit, findings, figures")
    study.add_argument("--out", type=Path, default=Path("pincal-study"),
                       help="output directory (default: ./pincal-study)")
    study.add_argument("--reps", type=count, default=25, metavar="N",
                       help="noise realisations per level, N_rep (default 25)")
    study.add_argument("--levels", type=count, default=16, metavar="M",
                       help="noise levels from 0 to 0.15, M_n (default 16)")
    study.add_argument("--restarts", type=count_or_zero, default=300, metavar="N",
                       help="random starting points per restart case (default 300, the paper's; 0 skips)")
    study.add_argument("--limit-pose-sets", type=count_or_zero, default=2, metavar="L",
                       help="pose sets the noise limit is averaged over (default 2; 0 skips it)")
    study.add_argument("--workers", type=count, default=None, metavar="N",
                       help="local worker processes (default: all cores; 1 runs in this process)")
    study.add_argument("--scheduler", metavar="ADDRESS",
                       help="run on a Dask cluster at ADDRESS, or 'local' to start a Dask LocalCluster")
    _add_quiet(study)
    return parser


