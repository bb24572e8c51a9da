"""Simulated cells that look like real ones: is every calibration at its noise floor?

    python scripts/scenarios.py [--only NAME[,NAME...]] [--markdown docs/scenarios.md] [--json PATH]

Each scenario is a robot (a URDF written from a DH table by ``pincal urdf-from-dh``, or the
packaged KUKA LWR 4+), a sensor and a way the robot was moved, simulated with a seed:

* a laser tracker 2, 4 and 6 m away measuring a 6D probe (position and orientation), and one
  measuring a reflector only (3D), at a few dozen spread postures;
* paths at constant tool orientation, as a robot program runs them (straight lines, arcs and a
  surface raster reversing every 50 rows), the orientation held by the controller in its own —
  the nominal — model (:mod:`pincal.simulation.cells`): the target cannot be estimated, and must be
  reported as held;
* one straight line, or one arc, at constant orientation (every pass on the same path, 210 rows, a
  6D probe or a reflector, the target unknown or known: ``--tool``): a line leaves the sensor's
  rotation about it free besides (:mod:`pincal.fit.registration_hold`), held and reported; these are
  held out along the same path (its other points: 37 rows a pass instead of 50), where the model is
  checked, not off it;
* motion-capture markers (three points on a rigid plate, 0.3 mm noise) 1.5 m away;
* circle point analysis (one joint moving at a time from a posture, four angles over ±60° each; held out two
  angles per joint 13° off them) of an arm whose controller reads A3 from the horizontal (the reading is
  A3 − A2), three reflectors, positions only: ``calibrate`` on the readings as read, and ``diagnose``, which
  must name the convention and reach the noise floor (its row is the one checked);
* a socket fixture (no external sensor): a ball on the flange seated in 9 sockets of a plate in
  three placements, the joint readings noisy (20 µrad); held out on other configurations in the
  same sockets and placements, predicted as sqrt(joint noise's share² + e²) (below);
* the same arm on a fixture of 3 sockets not in a line at four placements, three postures per
  socket, each placement left out in turn (:mod:`pincal.fit.placement_check`): calibrated on the
  other three, the left-out placement's rows with only its own pose refitted, RMS over all four;
  predicted as the joint noise's and the estimation's shares left after that pose's refit (below);
  *placements warned* counts the left-out placements the check warns about (calibrated worse
  than the nominal model beyond 1 + 2/sqrt(2 rows));
* revolute, prismatic and continuous joints; 6- and 7-axis arms in standard and modified DH.
* revolute, prismatic and continuous joints; 6- and 7-axis arms in standard and modified DH;
* robots whose placements are far off the URDF, for the prior's scales estimated from the rows
  (pincal.fit.prior_scales): a 3D tracker on the 6-axis arm with every placement off by 5–10 mm /
  2–5 mrad (ten times the old fixed prior of 1 mm / 0.5°), and a humanoid's torso and arm (9 joints)
  with 3-marker motion capture (0.4 mm), placements off by N(0, 3 mm) / N(0, 5 mrad), 43 rows over
  30 % of each joint's range and 18 held-out rows over 60 % (a recording's last rows reaching
  further than its first);
* a humanoid's whole upper body: TALOS (example-robot-data) with a motion-capture marker on each gripper's
  fingertip (0.15 mm), both arms on the shared torso in one tree calibration (``--tip-link LINK:1 --tip-link
  LINK:2``), 20 joints of which the four finger joints follow their gripper's joint by ``<mimic>`` (the rows
  have no column for them), placements off by N(0, 1 mm) / N(0, 1 mrad) (:mod:`pincal.simulation.humanoid`);
  predicted as below with e the tree fit's covariance propagated
  (:meth:`pincal.fit.tree_calibration.TreeCalibration.predicted_point_rms`). Once rigid (60 + 30 rows), and
  once (150 + 60 rows, the walk-through's) with the torso's pitch and both shoulders giving under loads the
  URDF's masses do not explain (1 kg at each hand it lacks) and the torso's pitch joint bending about its roll
  and yaw axes (:data:`pincal.simulation.humanoid.TALOS_LATERAL`; the hands move 5.7 mm RMS, 15 mm at most):
  compliance without a mass model. No calibration level models that, and the levels' rows show what the elastic
  joints cost; ``diagnose --masses unknown --lateral`` on several targets models it, and its row is the one
  checked, against its final fit's covariance (geometry and effect values) propagated
  (:attr:`pincal.diagnosis.tree_diagnose.TreeDiagnosis.heldout_predicted_m`). It names both shoulders'
  compliances and, for the torso, the yaw joint's bending: its lateral axes are the pitch joint's axis and
  nearly its roll axis, so one effect stands in for the pitch joint's two.

The true geometry has every joint placement off by ~0.3 mm / 0.3 mrad (level full), but where a
scenario says otherwise (``deviations``). Every level
is calibrated with ``calibrate``'s defaults on the calibration rows and evaluated on as many
held-out rows of the same kind (the same session: its registration). The noise-limited
prediction of the held-out RMS distance between measured and predicted points is

    sqrt(3 σ² + e²)

with σ the sensor's noise per axis and e the calibration's own estimation error at the held-out
configurations (:meth:`pincal.fit.chain_calibration.ChainCalibration.predicted_point_rms`, the
fit's covariance propagated). At level full (the truth's) each scenario must be within 1.3× it (the
scenario of a joint read against another: ``diagnose`` at level full, its final model's e);
lower levels lack part of the truth and show how much. A scenario whose truth has an effect no
level models (joint 2 re-mastered between the fixture's placements) has no truth's level: it is
there to show what the checks say. Prints a table, writes ``--markdown``
(the docs' table) and ``--json``. About 30 s on 2 cores.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from pincal.fit.chain_calibration import CHAIN_LEVELS, ChainFitOptions, calibrate_chain
from pincal.fit.tree_calibration import calibrate_tree
from pincal.fit.fixture_calibration import calibrate_fixture, initial_fixture
from pincal.fit.level_choice import fixture_heldout_error
from pincal.fit.metrics import pose_errors
from pincal.fit.placement_check import predictions
from pincal.measurements.couplings import apply_couplings
from pincal.measurements.fixture import Fixture
from pincal.model.chain import KinematicChain
from pincal.model.dh.conversion import urdf_from_dh_table
from pincal.model.parameter_sets import NoParameters, PlacementErrors
from pincal.residuals.base import KinematicsCache
from pincal.residuals.fixture import FixtureResidual
from pincal.robots import KUKA_FLANGE_LINK, kuka_lwr4plus_urdf
from pincal.simulation.cells import (
    INDUSTRIAL_6R_START,
    INDUSTRIAL_6R_TABLE,
    ToolPath,
    constant_orientation_path,
    measure_truth,
    sensor_at,
)
from pincal.simulation.fixture import ball_and_jacobian, simulate_fixture
from pincal.simulation.humanoid import (
    TALOS_COMPLIANCE,
    TALOS_LATERAL,
    HumanoidSettings,
    simulate_humanoid,
    talos_description,
    with_followers,
)
from pincal.simulation.sensor import SimulatedSensor, cpa_configurations, random_configurations

#: The bound of the issue: held-out within 1.3× the noise-limited prediction (level full).
BOUND = 1.3
#: ``calibrate``'s default selection.
DEFAULT_SELECTION = "prior"

TABLES = {
    # modified DH (Craig), degrees and metres: a 6-axis industrial arm, KR-16-like (no vendor's table)
    "6R modified": ("modified", INDUSTRIAL_6R_TABLE),
    # standard DH: a 7-axis arm with a continuous last joint (a wrist that turns endlessly)
    "7R standard": ("standard", """joint,type,a,alpha,d,theta,lower,upper
J1,revolute,0,-90,0.34,0,-170,170
J2,revolute,0,90,0,0,-120,120
J3,revolute,0,90,0.4,0,-170,170
J4,revolute,0,-90,0,0,-120,120
J5,revolute,0,-90,0.4,0,-170,170
J6,revolute,0,90,0,0,-120,120
J7,continuous,0,0,0.126,0,,
"""),
    # standard DH: a humanoid's torso (yaw, pitch) and 7-axis arm, 0.25-0.3 m links (no vendor's table)
    "humanoid 9R standard": ("standard", """joint,type,a,alpha,d,theta,lower,upper
T1,revolute,0,-90,0.25,0,-60,60
T2,revolute,0.2,0,0,-90,-30,60
S1,revolute,0,-90,0.15,0,-170,170
S2,revolute,0,90,0,0,-100,100
S3,revolute,0,-90,0.28,0,-170,170
E1,revolute,0,90,0,0,-120,120
W1,revolute,0,-90,0.25,0,-170,170
W2,revolute,0,90,0,0,-90,90
W3,revolute,0,0,0.1,0,-170,170
"""),
    # standard DH: a gantry-like arm, prismatic column and a continuous base joint
    "RPRRR standard": ("standard", """joint,type,a,alpha,d,theta,lower,upper
B1,continuous,0,0,0.4,0,,
Z2,prismatic,0.3,-90,0.2,0,-0.3,0.3
R3,revolute,0.35,0,0,-90,-150,150
R4,revolute,0,-90,0,0,-150,150
R5,revolute,0,90,0.25,0,-170,170
"""),
}
DOWN = np.diag([-1.0, 1.0, -1.0])
START_6R = INDUSTRIAL_6R_START  # near the bench, tool down


@dataclass(frozen=True)
class Scenario:
    """One simulated cell: robot, sensor, motion."""

    name: str
    robot: str  # a key of TABLES, or "KUKA LWR 4+"
    distance_m: float = 4.2
    sigma_pos_mm: float = 0.02
    sigma_rot_deg: float | None = 0.003  # None: positions only
    motion: str = "spread"  # spread postures, or a path at constant orientation: line, arc, raster
    rows: int = 40
    points: tuple[tuple[float, float, float], ...] = ((0.035, -0.02, 0.21),)
    notes: str = ""
    seed: int = 0
    joint_noise_rad: float = 2e-5  # socket fixture: the joint readings' noise
    levels: tuple[str, ...] = field(default=CHAIN_LEVELS)
    heights: int = 3  # a line or arc's passes stepped through this many heights (1: one path)
    tool_known: bool = False  # the target given as --tool (the chain's tool), not estimated
    # leave-one-placement-out cells: joint 2's zero on each placement [rad] (re-mastered between them: an
    # effect no level models, so level full is not the truth's and is not held to the bound)
    remastered_rad: tuple[float, ...] = ()
    read_against: bool = False  # A3 read against A2 (cpa motion): calibrate at the levels, then diagnose
    #: the true placement errors: ("normal", mm, mrad), each translation N(0, mm) and rotation N(0, mrad);
    #: ("uniform", (mm, mm), (mrad, mrad)), magnitudes uniform between the two, signs at random
    deviations: tuple = ("normal", 0.3, 0.3)
    held_out_rows: int | None = None  # held-out rows (None: as many as ``rows``)
    joint_range: float = 1.0  # spread postures: the share of each joint's range they span, about its middle
    held_out_range: float | None = None  # the held-out postures' share (None: as the calibration's)
    elastic: bool = False  # humanoid: joints giving under loads the URDF's masses do not explain (no level models it)
    lateral: bool = False  # humanoid, elastic: the torso bending too (TALOS_LATERAL), diagnose offered --lateral


SCENARIOS = (
    Scenario("tracker 2 m, 6D, 40 postures", "6R modified", distance_m=2.0, seed=1),
    Scenario("tracker 4 m, 6D, 40 postures", "6R modified", distance_m=4.0, seed=2),
    Scenario("tracker 6 m, 6D, 40 postures", "6R modified", distance_m=6.0, seed=3),
    Scenario("tracker 4 m, 3D, 40 postures", "6R modified", sigma_rot_deg=None, seed=4),
    Scenario("tracker 4 m, 3D, 24 postures", "6R modified", sigma_rot_deg=None, rows=24, seed=5),
    Scenario("tracker 4.2 m, 6D, lines at constant orientation", "6R modified", motion="line", rows=300, seed=6),
    Scenario("tracker 4.2 m, 6D, arcs at constant orientation", "6R modified", motion="arc", rows=300, seed=7),
    Scenario("tracker 4.2 m, 6D, raster at constant orientation", "6R modified", motion="raster", rows=500,
             seed=8),
    Scenario("tracker 4.2 m, 3D, raster at constant orientation", "6R modified", motion="raster", rows=500,
             sigma_rot_deg=None, seed=9),
    Scenario("mocap 1.5 m, 3 markers, 40 postures", "6R modified", distance_m=1.5, sigma_pos_mm=0.3,
             sigma_rot_deg=None, points=((0.05, 0.0, 0.1), (-0.03, 0.05, 0.12), (0.0, -0.06, 0.08)), seed=10),
    Scenario("tracker 4 m, 6D, 7-axis, standard DH, continuous J7", "7R standard", rows=50, seed=11),
    Scenario("tracker 4 m, 6D, prismatic + continuous joints", "RPRRR standard", rows=40, seed=12),
    Scenario("tracker 3 m, 6D, KUKA LWR 4+ (7 axes)", "KUKA LWR 4+", distance_m=3.0, rows=50, seed=13),
    Scenario("socket fixture, 9 sockets x 3 placements", "6R modified", motion="fixture", rows=3, seed=14),
    *(Scenario(f"tracker 4.2 m, {dims}, one {path} at constant orientation{tool}", "6R modified", motion=path,
               rows=210, heights=1, sigma_rot_deg=0.003 if dims == "6D" else None, tool_known=bool(tool), seed=seed)
      for seed, (path, dims, tool) in enumerate(((p, d, t) for p in ("line", "arc") for d in ("6D", "3D")
                                                 for t in ("", ", --tool")), start=15)),
    Scenario("socket fixture, 3 sockets x 4 placements, each left out in turn", "6R modified",
             motion="fixture placements", rows=3, seed=15),
    Scenario("socket fixture, 3 sockets x 4 placements, each left out in turn, J2 re-mastered between them",
             "6R modified", motion="fixture placements", rows=3, seed=15, remastered_rad=(1.5e-3, -5e-4, -5e-4, -5e-4)),
    Scenario("tracker 4 m, 3 reflectors, 24 CPA rows, A3 read against A2", "6R modified", distance_m=4.0,
             sigma_rot_deg=None, motion="cpa", rows=24, seed=3, levels=("full",), read_against=True,
             points=((0.05, 0.0, 0.1), (-0.03, 0.05, 0.12), (0.0, -0.06, 0.08))),
    Scenario("tracker 4 m, 3D, 24 postures, deviations 10x the old prior", "6R modified", distance_m=4.0,
             sigma_rot_deg=None, rows=24, seed=15, deviations=("uniform", (5.0, 10.0), (2.0, 5.0))),
    Scenario("humanoid arm, mocap 1.5 m, 3 markers, 43 + 18 rows, mm deviations", "humanoid 9R standard",
             distance_m=1.5, sigma_pos_mm=0.4, sigma_rot_deg=None, rows=43, held_out_rows=18, seed=16,
             points=((0.05, 0.0, 0.05), (-0.03, 0.04, 0.06), (0.0, -0.05, 0.04)), deviations=("normal", 3.0, 5.0),
             joint_range=0.3, held_out_range=0.6),
    Scenario("TALOS upper body, mocap 1.1 m, a marker per hand, 2 arms on one torso, mimic fingers",
             "TALOS upper body", motion="humanoid", sigma_pos_mm=0.15, sigma_rot_deg=None, rows=60, held_out_rows=30,
             seed=1, levels=("registration", "full")),
    # the effects' mass-moment values (128 with the torso's bending) want the walk-through's 150 rows: on 60 the
    # torso's bending and pitch compliance are taken together for the yaw joint's bending, whose values are
    # then out of range, and the search stops short of the noise
    Scenario("TALOS upper body, mocap 1.1 m, a marker per hand, 2 arms on one torso, mimic fingers, elastic torso "
             "and shoulders, torso bending, masses unknown", "TALOS upper body", motion="humanoid", sigma_pos_mm=0.15,
             sigma_rot_deg=None, rows=150, held_out_rows=60, seed=1, levels=("registration", "full"), elastic=True,
             lateral=True),
)
#: The socket fixture's plate: a 3 x 3 grid, 120 mm pitch [m]; its placements (base_T_fixture: where,
#: and a tilt about x then y [deg]) in front of the 6R arm; the ball's centre on the flange [m].
PLATE = np.array([[x, y, 0.0] for x in (-0.12, 0.0, 0.12) for y in (-0.12, 0.0, 0.12)])
PLACEMENTS = (((0.9, -0.35, 0.25), (0, 0)), ((1.0, 0.3, 0.45), (20, -15)), ((0.75, 0.05, 0.7), (-10, 25)))
BALL = np.array([0.01, -0.02, 0.12])
#: The leave-one-placement-out cell: 3 sockets not in a line [m] and four placements (where, tilt about x, y, z [deg]).
TRIANGLE = np.array([[0.0, 0.0, 0.0], [0.12, 0.0, 0.0], [0.0, 0.12, 0.0]])
FOUR_PLACEMENTS = (((0.9, -0.35, 0.25), (0, 0, 0)), ((1.0, 0.3, 0.45), (20, -15, 30)),
                   ((0.75, 0.05, 0.7), (-10, 25, -40)), ((1.1, -0.1, 0.1), (5, 10, 80)))


def build_robots(folder: Path) -> dict[str, tuple[Path, str]]:
    """URDF and tip link of every robot, written from the DH tables into ``folder``."""
    robots = {"KUKA LWR 4+": (kuka_lwr4plus_urdf(), KUKA_FLANGE_LINK),
              "TALOS upper body": (talos_description().path, "")}  # its tip links: HumanoidSettings.targets
    for name, (convention, table) in TABLES.items():
        csv = folder / f"{name.replace(' ', '_')}.csv"
        csv.write_text(table, encoding="utf-8")
        urdf_from_dh_table(csv, convention, csv.with_suffix(".urdf"), degrees=True)
        robots[name] = (csv.with_suffix(".urdf"), "flange")
    return robots


def true_deviations(params, deviations: tuple, rng: np.random.Generator) -> np.ndarray:
    """The true placement errors of ``params`` [m, rad] drawn as :attr:`Scenario.deviations` says."""
    metres = np.array([info.unit == "m" for info in params.info])
    if deviations[0] == "normal":
        return rng.normal(0.0, 1.0, params.size) * np.where(metres, deviations[1] * 1e-3, deviations[2] * 1e-3)
    (low_mm, high_mm), (low_mrad, high_mrad) = deviations[1:]
    size = rng.uniform(0.0, 1.0, params.size)
    magnitude = np.where(metres, low_mm + size * (high_mm - low_mm), low_mrad + size * (high_mrad - low_mrad))
    return rng.choice([-1.0, 1.0], params.size) * magnitude * 1e-3


def spread_configurations(chain: KinematicChain, rng: np.random.Generator, rows: int, share: float) -> np.ndarray:
    """Random configurations (rows, N) over ``share`` of each joint's range about its middle (continuous
    joints: of ±π about 0); the whole range draws as :func:`pincal.simulation.sensor.random_configurations`."""
    if share >= 1.0:
        return random_configurations(chain, rng, rows)
    lower = np.array([j.lower if np.isfinite(j.lower) else -np.pi for j in chain.joints])
    upper = np.array([j.upper if np.isfinite(j.upper) else np.pi for j in chain.joints])
    middle, half = (lower + upper) / 2.0, share * (upper - lower) / 2.0
    return rng.uniform(middle - half, middle + half, (rows, chain.n_joints))


def simulate(scenario: Scenario, urdf: Path, tip: str):
    """The chain (with the target as its tool when it is known), its calibration rows and held-out rows
    (same kind, same session), seeded."""
    chain = KinematicChain.from_urdf(urdf, tip)
    target = np.eye(4)
    target[:3, :3] = Rotation.from_euler("xyz", [10, -20, 30], degrees=True).as_matrix()
    target[:3, 3] = scenario.points[0]
    params = PlacementErrors(chain)
    rng = np.random.default_rng(scenario.seed)
    truth = true_deviations(params, scenario.deviations, rng)
    held_out = scenario.held_out_rows or scenario.rows
    if scenario.motion == "spread":
        q, q_test = (spread_configurations(chain, rng, scenario.rows, scenario.joint_range),
                     spread_configurations(chain, rng, held_out, scenario.held_out_range or scenario.joint_range))
    elif scenario.heights == 1:  # one path: held out at its other points
        path = ToolPath(scenario.motion, scenario.rows, np.array([1.2, 0.0, 0.5]), heights=1)
        q, q_test = (constant_orientation_path(chain, p, DOWN, START_6R)
                     for p in (path, replace(path, rows_per_line=37)))
    elif scenario.motion == "cpa":  # one joint at a time from the start posture, as tests/test_read_against.py
        span = np.radians(60.0)
        q, q_test = (cpa_configurations(START_6R - span + offset, START_6R + span + offset, count, start=START_6R)
                     for count, offset in ((scenario.rows // 6, 0.0), (scenario.rows // 12, np.radians(13.0))))
    else:
        centre = np.array([1.2, 0.0, 0.5])
        q = constant_orientation_path(chain, ToolPath(scenario.motion, scenario.rows, centre), DOWN, START_6R)
        q_test = constant_orientation_path(chain, ToolPath(scenario.motion, scenario.rows, centre + [0.0, 0.05, 0.05]),
                                           DOWN, START_6R)
    options = dict(points=np.array(scenario.points), with_rotation=scenario.sigma_rot_deg is not None,
                   target_rotation=target[:3, :3])
    if scenario.tool_known:  # the same robot program; the sensor measures the tool frame itself
        chain = KinematicChain.from_urdf(urdf, tip, tool=target)
        params = PlacementErrors(chain)
        options.update(points=np.zeros((1, 3)), target_rotation=np.eye(3))
    sigma_p, sigma_a = scenario.sigma_pos_mm / 1000.0, np.radians(scenario.sigma_rot_deg or 0.0)
    sensor = sensor_at(scenario.distance_m)
    actual, actual_test = q.copy(), q_test.copy()
    if scenario.read_against:  # the controller reads A3 from the horizontal: A3 − A2
        actual[:, 2] += q[:, 1]
        actual_test[:, 2] += q_test[:, 1]
    measured = SimulatedSensor(sigma_p, sigma_a, **options)
    calibration = measure_truth(params, truth, actual, sensor, rng, measured)
    test = measure_truth(params, truth, actual_test, sensor, rng, measured, "validation")
    return chain, replace(calibration, q=q), replace(test, q=q_test)


def run_fixture(scenario: Scenario, urdf: Path, tip: str, selection: str = DEFAULT_SELECTION) -> dict:
    """A socket-fixture cell: calibrate_fixture at every level; held out on ``rows`` other
    configurations per socket of the same placements (their fitted poses), against the prediction
    sqrt(n² + e²): n² the joint noise's mean share, σ_q² ‖J_ball‖²_F per row, e the estimation's
    (:meth:`pincal.fit.fixture_calibration.FixtureCalibration.predicted_ball_rms`)."""
    chain = KinematicChain.from_urdf(urdf, tip)
    params = PlacementErrors(chain)
    rng = np.random.default_rng(scenario.seed)
    truth = rng.normal(0.0, 3e-4, params.size)
    fixture = Fixture(tuple(f"s{i}" for i in range(len(PLATE))), PLATE)
    poses = []
    for where, (tilt_x, tilt_y) in PLACEMENTS:
        pose = np.eye(4)
        pose[:3, :3], pose[:3, 3] = Rotation.from_euler("xy", [tilt_x, tilt_y], degrees=True).as_matrix(), where
        poses.append(pose)
    sigma_q = scenario.joint_noise_rad
    with chain.placed(params.placements(truth)):
        calibration = simulate_fixture(chain, fixture, poses, BALL, scenario.rows, rng, joint_noise_rad=sigma_q)
        test = simulate_fixture(chain, fixture, poses, BALL, scenario.rows, rng, joint_noise_rad=sigma_q)
        jacobians = np.array([ball_and_jacobian(chain, q, BALL)[1] for q in test.q])
    noise = sigma_q * float(np.sqrt(np.mean(np.sum(jacobians**2, axis=(1, 2)))))  # [m]
    rows = []
    for level in scenario.levels:
        started = time.perf_counter()
        result = calibrate_fixture(chain, calibration, level, selection=selection)
        seconds = time.perf_counter() - started
        with chain.placed(result.chain_placements):
            tool = chain.poses(test.q)
        balls = np.einsum("kij,j->ki", tool.tool_rotations, result.ball) + tool.tool_positions
        sockets = np.array([result.placements[s].socket_positions[result.placements[s].sockets.index(
            fixture.names[i])] for s, i in zip(test.placement, test.socket)])
        held_out = float(np.sqrt(np.mean(np.sum((balls - sockets) ** 2, axis=1)))) * 1000.0
        predicted = float(np.hypot(noise, result.predicted_ball_rms(chain, test))) * 1000.0
        rows.append({
            "level": level, "kept": int(result.kept.size), "identifiable": int(result.rank),
            "held_out_mm": held_out, "predicted_mm": predicted, "ratio": held_out / predicted,
            "not_determined": 0, "seconds": seconds,
        })
    return {"scenario": scenario.name, "robot": scenario.robot, "rows": calibration.n_rows,
            "sigma_pos_mm": noise * 1000.0, "levels": rows}


def _left_out_predicted(chain, params, result, test, truth_jacobians, sigma_q) -> float:
    """Predicted sum over ``test``'s rows (one placement the fit has not seen) of ‖p_k − c − R f_i‖² [m²] once
    its pose is refitted: tr(P N) + tr(P J Σ Jᵀ), P the projection off the pose's columns, N the joint noise's
    covariance of each row (σ_q² J_q J_qᵀ), J and Σ the Jacobian and covariance of the fit's kinematics and ball."""
    with chain.placed(result.chain_placements):
        start, bases, _ = initial_fixture(chain, test)
    start = replace(start, ball=result.ball)
    cache = KinematicsCache(params if params is not None else NoParameters(chain), result.kept, result.vector, test.q)
    objective = FixtureResidual(cache, test.placement, test.socket_points, bases, start)
    jac = objective.jacobian(objective.start_vector())
    model = np.r_[objective.blocks["kinematic"], objective.blocks["ball"]]
    pose = jac[:, objective.blocks["placements"]]
    projection = np.eye(len(jac)) - pose @ np.linalg.pinv(pose)
    noise = np.zeros((len(jac), len(jac)))
    for k, j in enumerate(truth_jacobians):
        noise[3 * k:3 * k + 3, 3 * k:3 * k + 3] = sigma_q**2 * j @ j.T
    size = len(result.kept) + 3
    sigma = result.covariance[:size, :size]  # the fit's unknowns: kept kinematics, ball, then its placements
    estimation = jac[:, model] @ sigma @ jac[:, model].T
    return float(np.trace(projection @ (noise + estimation)))


def run_fixture_placements(scenario: Scenario, urdf: Path, tip: str, selection: str = DEFAULT_SELECTION) -> dict:
    """Leave-one-placement-out on a socket-fixture cell: every level calibrated on three placements, the fourth
    predicted with only its own pose refitted (:func:`pincal.fit.level_choice.fixture_heldout_error`), RMS over the
    four; predicted from the joint noise and the fit's covariance (:func:`_left_out_predicted`); the placements the
    check of :mod:`pincal.fit.placement_check` warns about (against level registration, the nominal model)."""
    chain = KinematicChain.from_urdf(urdf, tip)
    params = PlacementErrors(chain)
    rng = np.random.default_rng(scenario.seed)
    truth = rng.normal(0.0, 3e-4, params.size)
    fixture = Fixture(("a", "b", "c"), TRIANGLE)
    poses = []
    for where, angles in FOUR_PLACEMENTS:
        pose = np.eye(4)
        pose[:3, :3], pose[:3, 3] = Rotation.from_euler("xyz", angles, degrees=True).as_matrix(), where
        poses.append(pose)
    sigma_q = scenario.joint_noise_rad
    with chain.placed(params.placements(truth)):
        data = simulate_fixture(chain, fixture, poses, BALL, scenario.rows, rng, joint_noise_rad=sigma_q)
        jacobians = np.array([ball_and_jacobian(chain, q, BALL)[1] for q in data.q])
    if scenario.remastered_rad:  # joint 2 read with another zero on each placement
        q = data.q.copy()
        q[:, 1] += np.asarray(scenario.remastered_rad)[data.placement]
        data = replace(data, q=q)
    errors: dict[str, list[float]] = {}
    rows = []
    for level in scenario.levels:
        started = time.perf_counter()
        squared = predicted = 0.0
        kept, identifiable, errors[level] = [], [], []
        for name in data.placements:
            train = data.select_placements([n for n in data.placements if n != name])
            test = data.select_placements([name])
            result = calibrate_fixture(chain, train, level, selection=selection)
            with chain.placed(result.chain_placements):
                errors[level].append(float(fixture_heldout_error(chain, test, result.ball)[0]))
            squared += errors[level][-1] ** 2 * test.n_rows
            predicted += _left_out_predicted(chain, result.params, result, test,
                                             jacobians[data.placement == data.placements.index(name)], sigma_q)
            kept.append(int(result.kept.size))
            identifiable.append(int(result.rank))
        held_out = float(np.sqrt(squared / data.n_rows)) * 1000.0
        estimate = float(np.sqrt(predicted / data.n_rows)) * 1000.0
        checked = predictions(data, errors[level], errors["registration"]) if "registration" in errors else ()
        rows.append({
            "level": level, "kept": min(kept), "identifiable": min(identifiable), "held_out_mm": held_out,
            "predicted_mm": estimate, "ratio": held_out / estimate, "not_determined": 0,
            "seconds": time.perf_counter() - started,
            "left_out": [{"placement": p.placement, "nominal_mm": p.nominal_mm, "calibrated_mm": p.calibrated_mm,
                          "warned": p.worse} for p in checked],
        })
    return {"scenario": scenario.name, "robot": scenario.robot, "rows": data.n_rows,
            "sigma_pos_mm": float(np.sqrt(np.mean(np.sum(jacobians**2, axis=(1, 2))))) * sigma_q * 1000.0,
            "levels": rows, "unmodelled": bool(scenario.remastered_rad)}


def run_humanoid(scenario: Scenario, selection: str = DEFAULT_SELECTION) -> dict:
    """TALOS's upper body (:func:`pincal.simulation.humanoid.simulate_humanoid`): both hands' markers in one tree
    calibration at each level, held out on rows of the same session, against sqrt(3 σ² + e²), e the tree fit's
    covariance propagated to the held-out configurations."""
    settings = HumanoidSettings(rows=scenario.rows, held_out_rows=scenario.held_out_rows or scenario.rows,
                                sigma_pos_mm=scenario.sigma_pos_mm, seed=scenario.seed,
                                compliance=TALOS_COMPLIANCE if scenario.elastic else (),
                                lateral=TALOS_LATERAL if scenario.lateral else ())
    data = simulate_humanoid(settings)
    tree = data.tree
    calibration, test = with_followers(tree, data.calibration), with_followers(tree, data.validation)
    sigma = scenario.sigma_pos_mm
    rows, fitted = [], {}
    for level in scenario.levels:
        started = time.perf_counter()
        result = calibrate_tree(tree, calibration, level, ChainFitOptions(
            selection=selection if level != "registration" else "aic"))
        seconds = time.perf_counter() - started
        fitted[level] = result
        registration = result.target.registrations[0]
        points = [result.target.points[[p - 1 for p in t.spec.points]] for t in tree.targets]
        with tree.placed(result.tree_placements):
            world = tree.target_points(test.q, points)
        errors = np.linalg.norm(world @ registration.rotation.T + registration.translation - test.points, axis=2)
        held_out = float(np.sqrt(np.mean(errors**2))) * 1000.0
        predicted = float(np.sqrt(3.0 * sigma**2 + (result.predicted_point_rms(tree, test.q) * 1000.0) ** 2))
        rows.append({"level": level, "kept": int(result.kept.size), "identifiable": int(result.rank),
                     "held_out_mm": held_out, "predicted_mm": predicted, "ratio": held_out / predicted,
                     "not_determined": 0, "seconds": seconds})
    checked = "full"
    if scenario.elastic:  # diagnose models the elastic joints: its row is the one checked
        rows.append(run_tree_diagnose(tree, (calibration, test), sigma, (fitted["full"], scenario.lateral)))
        checked = "diagnose"
    return {"scenario": scenario.name, "robot": scenario.robot, "rows": scenario.rows, "sigma_pos_mm": sigma,
            "levels": rows, "checked": checked, "deflection_mm": data.deflection_mm}


def run_tree_diagnose(tree, rows: tuple, sigma: float, how: tuple) -> dict:
    """``diagnose --masses unknown`` on several targets after the calibration at level full (``how``: it, and
    whether with ``--lateral``) with the held-out rows (as ``--validation``): the held-out RMS of its final model
    (geometry and effects) against sqrt(3 σ² + e²), e its fit's covariance (geometry, registration, points and
    effect values) propagated to the held-out rows
    (:attr:`pincal.diagnosis.tree_diagnose.TreeDiagnosis.heldout_predicted_m`)."""
    from pincal.diagnosis.diagnose import DiagnoseOptions
    from pincal.diagnosis.tree_diagnose import diagnose_tree

    calibration, test = rows
    result, lateral = how
    started = time.perf_counter()
    found = diagnose_tree(tree, result, calibration, test, DiagnoseOptions(masses="unknown", lateral=lateral))
    held_out = float(np.sqrt(np.nanmean(found.heldout_after**2))) * 1000.0
    predicted = float(np.sqrt(3.0 * sigma**2 + (found.heldout_predicted_m * 1000.0) ** 2))
    return {"level": "diagnose", "kept": int(result.kept.size), "identifiable": int(result.rank),
            "held_out_mm": held_out, "predicted_mm": predicted, "ratio": held_out / predicted, "not_determined": 0,
            "seconds": time.perf_counter() - started,
            "found": [e.label.split(":moments")[0] for e, _, _ in found.effects]}


def run(scenario: Scenario, urdf: Path, tip: str, selection: str = DEFAULT_SELECTION) -> dict:
    if scenario.motion == "humanoid":
        return run_humanoid(scenario, selection)
    if scenario.motion == "fixture":
        return run_fixture(scenario, urdf, tip, selection)
    if scenario.motion == "fixture placements":
        return run_fixture_placements(scenario, urdf, tip, selection)
    chain, calibration, test = simulate(scenario, urdf, tip)
    sigma = scenario.sigma_pos_mm
    rows = []
    for level in scenario.levels:
        started = time.perf_counter()
        options = ChainFitOptions(tool_known=scenario.tool_known, selection=selection)
        result = calibrate_chain(chain, calibration, level, options)
        seconds = time.perf_counter() - started
        target = result.target
        with chain.placed(result.chain_placements):
            errors = pose_errors(chain, test, target.registration, target.registration, points=target.points,
                                 target_rotation=target.rotation)
        estimation = result.predicted_point_rms(chain, test.q) * 1000.0
        held_out = float(np.sqrt(np.mean(errors.position_m**2))) * 1000.0
        predicted = float(np.sqrt(3.0 * sigma**2 + estimation**2))
        rows.append({
            "level": level, "kept": int(result.kept.size), "identifiable": int(result.rank),
            "held_out_mm": held_out, "predicted_mm": predicted, "ratio": held_out / predicted,
            "not_determined": len(result.held), "rotations_held": len(result.held_rotations), "seconds": seconds,
        })
    if scenario.read_against:
        rows.append(run_diagnose(chain, calibration, test, sigma, selection))
    return {"scenario": scenario.name, "robot": scenario.robot, "rows": scenario.rows, "sigma_pos_mm": sigma,
            "levels": rows, "checked": "diagnose" if scenario.read_against else "full"}


def run_diagnose(chain, calibration, test, sigma: float, selection: str) -> dict:
    """``diagnose`` at level full with the held-out rows (as ``--validation``): its held-out RMS, which evaluate of
    its report gives, against sqrt(3 σ² + e²) of its final model on the held-out rows read as it corrects them."""
    from pincal.diagnosis.diagnose import DiagnoseOptions, diagnose

    started = time.perf_counter()
    recalibrate = partial(calibrate_chain, chain, level="full",
                          options=ChainFitOptions(selection=selection, refit_offered=False))
    found = diagnose(chain, recalibrate(calibration), calibration, heldout=test,
                     options=DiagnoseOptions(recalibrate=recalibrate))
    final = found.final_calibration()
    estimation = final.predicted_point_rms(chain, apply_couplings(test, found.couplings).q) * 1000.0
    held_out = found.heldout_errors.position.rms
    predicted = float(np.sqrt(3.0 * sigma**2 + estimation**2))
    return {"level": "diagnose", "kept": int(final.kept.size), "identifiable": int(final.rank),
            "held_out_mm": held_out, "predicted_mm": predicted, "ratio": held_out / predicted,
            "not_determined": len(final.held), "seconds": time.perf_counter() - started,
            "found": [c.label for c in found.couplings] + [e.label for e, _, _ in found.effects]}


def markdown(results: list[dict], selection: str = DEFAULT_SELECTION) -> str:
    lines = [
        "# Simulated cells: held-out error against the noise-limited prediction",
        "",
        "Written by `python scripts/scenarios.py --markdown docs/scenarios.md` (seeded); "
        f"`calibrate`'s defaults (`--select {selection}`). What each scenario is, the truth behind it and "
        "the prediction: the script's docstring. *kept / identifiable*: kinematic parameters; *target held*: "
        "directions of the target's position reported as not determined (`identifiability.not_determined`), "
        "and (+ rotation) the sensor's rotation about a line held (`identifiability.not_determined_rotations`). "
        f"At level full (the truth's) every scenario must be within {BOUND}× its prediction (✔); the lower "
        "levels lack part of the truth, and their ratio shows how much it costs. A scenario whose truth has an "
        "effect no level models (*re-mastered*) has no truth's level and is not marked. A joint read against another "
        "(*diagnose*) is checked on `diagnose`'s row: `calibrate` alone cannot know the readings' convention; so is "
        "the elastic humanoid (*elastic*): no level models joints that give under loads.",
        "",
        "| scenario | level | kept / identifiable | held-out RMS [mm] | predicted [mm] | ratio | target held |",
        "|---|---|---|---|---|---|---|",
    ]
    for entry in results:
        for row in entry["levels"]:
            checked = row["level"] == entry.get("checked", "full") and not _unmodelled(entry)
            mark = " ✔" if checked and row["ratio"] <= BOUND else (" ✘" if checked else "")
            lines.append(f"| {entry['scenario']} | {row['level']} | {row['kept']} / {row['identifiable']} | "
                         f"{row['held_out_mm']:.4f} | {row['predicted_mm']:.4f} | {row['ratio']:.2f}{mark} | "
                         f"{_held(row)} |")
    for entry in results:
        lines += _left_out_table(entry)
    return "\n".join(lines) + "\n"


def _held(row: dict) -> str:
    """The *target held* cell: the target directions held, and a registration rotation held (+ rotation)."""
    rotations = row.get("rotations_held", 0)
    return f"{row['not_determined']} + rotation" if rotations else f"{row['not_determined'] or '—'}"


def _unmodelled(entry: dict) -> bool:
    """A scenario whose truth has an effect no level models: level full is not held to the bound."""
    return bool(entry.get("unmodelled"))


def _left_out_table(entry: dict) -> list[str]:
    """Leave-one-placement-out scenarios: each placement's error, nominal → calibrated, and the check's verdict."""
    rows = [row for row in entry["levels"] if row.get("left_out") and row["level"] != "registration"]
    if not rows:
        return []
    names = [p["placement"] for p in rows[0]["left_out"]]
    lines = ["", f"**{entry['scenario']}**: each placement predicted by the level's calibration of the other "
             "three, its own pose refitted — RMS ball-to-socket distance [mm], nominal URDF → calibrated; "
             "⚠ where the check (`pincal.fit.placement_check`) warns: calibrated worse than nominal beyond "
             "1 + 2/√(2 rows).", "", "| level | " + " | ".join(names) + " | placements warned |",
             "|---|" + "---|" * (len(names) + 1)]
    for row in rows:
        cells = [f"{p['nominal_mm']:.4f} → {p['calibrated_mm']:.4f}" + (" ⚠" if p["warned"] else "")
                 for p in row["left_out"]]
        lines.append(f"| {row['level']} | " + " | ".join(cells) + f" | {sum(p['warned'] for p in row['left_out'])} "
                     f"of {len(cells)} |")
    return lines


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", help="comma-separated scenario names (substrings)")
    parser.add_argument("--markdown", type=Path, help="write the table as Markdown")
    parser.add_argument("--json", type=Path, help="write the numbers as JSON")
    parser.add_argument("--select", default=DEFAULT_SELECTION, help=f"selection (default {DEFAULT_SELECTION}, calibrate's)")
    args = parser.parse_args(argv)
    chosen = [s for s in SCENARIOS if not args.only or any(o in s.name for o in args.only.split(","))]
    with tempfile.TemporaryDirectory() as tmp:
        robots = build_robots(Path(tmp))
        results = []
        for scenario in chosen:
            entry = run(scenario, *robots[scenario.robot], selection=args.select)
            results.append(entry)
            full = next(r for r in entry["levels"] if r["level"] == entry.get("checked", "full"))
            print(f"{scenario.name:55s} full: {full['held_out_mm']:.4f} mm vs {full['predicted_mm']:.4f} "
                  f"({full['ratio']:.2f}x), kept {full['kept']}/{full['identifiable']}, "
                  f"target held {_held(full)}", flush=True)
    table = markdown(results, args.select)
    print(table)
    if args.markdown:
        args.markdown.write_text(table, encoding="utf-8")
    if args.json:
        args.json.write_text(json.dumps(results, indent=2) + "\n", encoding="utf-8")
    failed = [e["scenario"] for e in results for r in e["levels"]
              if r["level"] == e.get("checked", "full") and r["ratio"] > BOUND and not _unmodelled(e)]
    if failed:
        print(f"above {BOUND}x the prediction at level full: {', '.join(failed)}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
