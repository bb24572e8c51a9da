"""Continuous joints wherever a revolute one works, and every serial chain of example-robot-data.

The sweep's rule: in each URDF of example-robot-data, the chain runs from the root to the
deepest link — the one with the most moving joints between it and the root, the last such
in the file's order (a foot or fingertip rather than its parent). Noise-free 6D rows of that
chain with every placement off by ~1 mm / 1 mrad are calibrated at level full (every
identifiable parameter kept), and held-out rows must be reproduced to 1e-6 m and 1e-6 rad
(the issue's bound; the fits reach ~1e-12). The robots skipped are listed with the reason.
"""

from __future__ import annotations

import json

import numpy as np
import pinocchio as pin
import pytest

from pincal.cli.commands import main
from pincal.fit.chain_calibration import ChainFitOptions, calibrate_chain
from pincal.fit.metrics import pose_errors
from pincal.measurements.csv_v1 import write_measurements
from pincal.model.chain import KinematicChain
from pincal.model.dh.urdf import dh_robot_from_urdf
from pincal.model.parameter_sets import PlacementErrors
from pincal.robots import example_robot_data_dir, example_robot_data_urdf
from pincal.simulation.chain import simulate_chain
from pincal.simulation.paper import SimulationSettings

#: The issue asks for 1e-6 (m and rad); noise-free fits reach ~1e-15, so 1e-10 catches a fit that
#: stopped early or a Jacobian that is slightly wrong, with five orders of margin for rounding.
BOUND = 1e-10
#: Robots whose deepest chain cannot be calibrated: why, and the error that must still say so.
SKIPPED = {
    "ur_description/urdf/ur3.urdf": ("no robot name: Pinocchio's URDF parser refuses the file",
                                     "does not contain a valid URDF model"),
    "iris_description/robots/iris.urdf": ("a quadrotor: no chain of two moving joints", "two moving joints"),
    "iris_description/robots/iris_simple.urdf": ("a quadrotor: no chain of two moving joints", "two moving joints"),
    "hector_description/robots/quadrotor_base.urdf": ("a quadrotor: no chain of two moving joints",
                                                       "two moving joints"),
    "double_pendulum_description/urdf/double_pendulum.urdf": (
        "its joints' limits are [0, 0]: they never move", "never moves"),
    "double_pendulum_description/urdf/double_pendulum_simple.urdf": ("as double_pendulum.urdf", "never moves"),
    "quadruped_description/urdf/quadruped.urdf": ("the knee's limits are [0, 0]: the joint never moves",
                                                  "never moves"),
}


def _urdfs():
    root = example_robot_data_dir()
    return sorted(str(p.relative_to(root)) for p in root.rglob("*.urdf"))


def _deepest_link(path) -> str | None:
    try:
        model = pin.buildModelFromUrdf(str(path))
    except ValueError as exc:  # Pinocchio's parser
        raise ValueError(f"Pinocchio cannot read it: {exc}") from None
    bodies = [f for f in model.frames if f.type == pin.FrameType.BODY]
    depth = [sum(1 for j in model.supports[f.parentJoint] if j != 0) for f in bodies]
    best = max(range(len(bodies)), key=lambda i: (depth[i], i))
    return bodies[best].name if depth[best] >= 2 else None


@pytest.mark.parametrize("relative", _urdfs())
def test_every_serial_chain_of_example_robot_data_is_recovered(relative):
    path = example_robot_data_dir() / relative
    if relative in SKIPPED:
        reason, message = SKIPPED[relative]
        with pytest.raises(Exception, match=message):
            _calibrate(path)
        pytest.skip(reason)
    chain, errors = _calibrate(path)
    assert errors.position.max * 1e-3 < BOUND and np.radians(errors.rotation.max) < BOUND


def _calibrate(path):
    tip = _deepest_link(path)
    if tip is None:
        raise ValueError("no chain of two moving joints")
    chain = KinematicChain.from_urdf(path, tip)
    if any(j.lower == j.upper for j in chain.joints):
        raise ValueError("a joint whose limits are equal never moves")
    params = PlacementErrors(chain)
    truth = np.random.default_rng(0).normal(0.0, 1e-3, params.size)
    settings = SimulationSettings(n_calibration=max(40, 8 * chain.n_joints), n_validation=30, seed=1)
    experiment = simulate_chain(params, truth, np.array([[0.02, -0.01, 0.05]]), settings, with_rotation=True)
    result = calibrate_chain(chain, experiment.calibration, "full", ChainFitOptions(selection="all"))
    target = result.target
    with chain.placed(result.chain_placements):
        return chain, pose_errors(chain, experiment.validation, target.registration, target.registration,
                                  points=target.points, target_rotation=target.rotation)


def test_the_sweep_covers_continuous_and_prismatic_joints():
    kinds = set()
    for relative in ("kinova_description/robots/kinova.urdf", "pr2_description/urdf/pr2.urdf"):
        path = example_robot_data_dir() / relative
        kinds |= {j.kind for j in KinematicChain.from_urdf(path, _deepest_link(path)).joints}
    assert kinds == {"revolute", "continuous", "prismatic"}


def test_a_dh_table_with_continuous_joints_round_trips(tmp_path, capsys):
    table = tmp_path / "arm.csv"
    table.write_text("joint,type,a,alpha,d,theta,lower,upper\nj1,continuous,0,0,0.3,0,,\n"
                     "j2,revolute,0.4,-90,0,0,-90,90\nj3,prismatic,0,0,0.1,0,-0.1,0.2\nj4,continuous,0,90,0.2,0,,\n",
                     encoding="utf-8")
    assert main(["urdf-from-dh", str(table), "--convention", "modified", "--degrees",
                 "--out", str(tmp_path / "arm.urdf")]) == 0
    out = capsys.readouterr().out
    assert "2 continuous" in out and "Pinocchio FK = DH product" in out
    chain = KinematicChain.from_urdf(tmp_path / "arm.urdf", "flange")
    assert [j.kind for j in chain.joints] == ["continuous", "revolute", "prismatic", "continuous"]
    assert not np.isfinite(chain.joints[0].lower)
    robot = dh_robot_from_urdf(tmp_path / "arm.urdf", "modified")  # and back to a DH table (the --level dh path)
    assert robot.types == ("continuous", "revolute", "prismatic", "continuous")
    assert np.allclose(np.degrees(robot.alpha), [0, -90, 0, 90]) and np.allclose(robot.d, [0.3, 0, 0.1, 0.2])


def test_a_limit_on_a_continuous_joint_is_refused(tmp_path, capsys):
    table = tmp_path / "arm.csv"
    table.write_text("joint,type,a,alpha,d,theta,lower,upper\nj1,continuous,0,0,0.3,0,-1,1\n", encoding="utf-8")
    assert main(["urdf-from-dh", str(table), "--convention", "modified", "--out", str(tmp_path / "a.urdf")]) == 2
    err = capsys.readouterr().err
    assert "line 2" in err and "continuous joint has no position limits" in err and err.count("\n") == 1


KINOVA_TIP = "j2s6s200_end_effector"


@pytest.fixture(scope="module")
def kinova(tmp_path_factory):
    """Kinova j2s6s200 (continuous joints 1, 4, 6): its URDF and a folder holding seeded simulated
    calibration and validation rows (``cal.csv``, ``val.csv``), shared by the commands' tests below so
    each command runs once and a parallel run spreads them over its workers."""
    urdf = example_robot_data_urdf("kinova_description/robots/kinova.urdf")
    folder = tmp_path_factory.mktemp("kinova")
    chain = KinematicChain.from_urdf(urdf, KINOVA_TIP)
    params = PlacementErrors(chain)
    truth = np.random.default_rng(2).normal(0.0, 1e-3, params.size)
    settings = SimulationSettings(n_calibration=60, n_validation=30, seed=2, sigma_pos_mm=0.02, sigma_rot_deg=0.01)
    experiment = simulate_chain(params, truth, np.array([[0.01, 0.02, 0.1]]), settings, with_rotation=True)
    write_measurements(folder / "cal.csv", experiment.calibration)
    write_measurements(folder / "val.csv", experiment.validation)
    return urdf, folder


KINOVA_COMMON = ["--tip-link", KINOVA_TIP, "--quiet"]


def test_kinova_calibrate_and_evaluate(kinova, tmp_path):
    """The commands a revolute arm runs, on an arm with continuous joints: calibrate, evaluate ..."""
    urdf, data = kinova
    assert main(["calibrate", str(urdf), str(data / "cal.csv"), *KINOVA_COMMON, "--out", str(tmp_path / "c.urdf"),
                 "--report", str(tmp_path / "c.json")]) == 0
    assert main(["evaluate", str(tmp_path / "c.urdf"), str(tmp_path / "c.json"), str(data / "val.csv"),
                 "--max-pos-mm", "0.2"]) == 0
    doc = json.loads((tmp_path / "c.json").read_text())
    assert doc["chain"]["joint_kinds"] == ["continuous", "revolute", "revolute", "continuous", "revolute",
                                           "continuous"]


def test_kinova_diagnose(kinova, tmp_path):
    """... diagnose, with its plots ..."""
    urdf, data = kinova
    assert main(["diagnose", str(urdf), str(data / "cal.csv"), *KINOVA_COMMON, "--out", str(tmp_path / "d.urdf"),
                 "--report", str(tmp_path / "d.json"), "--plots", str(tmp_path / "plots")]) == 0


def test_kinova_plan(kinova, tmp_path):
    """... and plan, over its default 2000 candidates. Without the self-collision check: Kinova's meshes
    cost ~10-35 ms a configuration (tens of seconds for 2000), and tests/test_plan_collisions.py checks
    Kinova's collisions; here the point is the continuous joints' sampling and design."""
    urdf, _ = kinova
    assert main(["plan", str(urdf), *KINOVA_COMMON, "--count", "12", "--no-collision-check",
                 "--out", str(tmp_path / "plan.csv"), "--report", str(tmp_path / "plan.json")]) == 0
