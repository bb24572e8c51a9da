"""``pincal plan`` with several --tip-link LINK:POINTS: the configurations of a tree (tests/tree_robot.py).

The planner's promise, as one chain's (tests/test_plan.py, PREDICTION_TOLERANCE and RANDOM_RATIO): calibrating on
the planned configurations gives a held-out error within 15 % of the plan's prediction — here for each target —
and at most 0.7 × the error of as many random candidates. Plus the command end to end (PLAN.csv read by
``calibrate`` with the same --tip-link values, PLAN.json's per-target prediction, ``--existing``), a joint that
follows another without a column, and bad input in one line.
"""

from __future__ import annotations

import csv
import json

import numpy as np
import pinocchio as pin
import pytest
from test_plan import PREDICTION_TOLERANCE, RANDOM_RATIO
from tree_robot import two_arm_urdf

from pincal.cli.commands import main
from pincal.fit.chain_calibration import ChainFitOptions
from pincal.fit.tree_calibration import calibrate_tree
from pincal.measurements.data import MeasurementSet
from pincal.model.tree import KinematicTree, parse_targets
from pincal.model.tree_parameters import TreeParameters
from pincal.planning.planner import PlanSettings
from pincal.planning.tree_plan import plan_tree_measurements
from pincal.simulation.sensor import DEFAULT_REGISTRATION, random_configurations

TARGETS = ["--tip-link", "left_marker:1", "--tip-link", "right_marker:2"]
LOCAL = [np.array([[0.01, 0.0, 0.02]]), np.array([[0.0, 0.01, 0.0]])]  # each target's point in its tip link [m]
#: 10 configurations: 1.25 x the fewest that determine the 46 parameters (34 kinematic, registration, two points;
#: 6 measurements each) — the few-measurements regime where a plan matters, as test_plan.py's N.
COUNT = 10


def _sensed(tree, placements, q, rng=None, sigma_m=1e-4):
    """Each target's point seen through the simulation's registration at readings ``q`` with the tree at
    ``placements``, with Gaussian noise ``sigma_m`` per axis when ``rng`` is given, (K, 2, 3) [m]."""
    with tree.placed(placements):
        sensed = DEFAULT_REGISTRATION.apply_points(tree.target_points(q, LOCAL))
    return sensed if rng is None else sensed + rng.normal(0.0, sigma_m, sensed.shape)


@pytest.fixture(scope="module")
def robot():
    """The two-arm tree, placement errors ~1 mm / 1 mrad on every joint, and the truth's placements."""
    tree = KinematicTree(pin.buildModelFromXML(two_arm_urdf()), parse_targets(TARGETS[1::2]))
    params = TreeParameters(tree, "full")
    truth = np.random.default_rng(1).normal(0.0, 1e-3, params.size)
    return tree, params.placements(truth)


def test_planned_configurations_calibrate_as_predicted_for_each_target_and_beat_random(robot):
    """Full level, σ 0.1 mm, 300 candidates, 16 noise seeds (8 leave each target's mean ±15 % of its own spread:
    one seed's held-out error varies by ~25 %)."""
    tree, truth = robot
    candidates = random_configurations(tree, np.random.default_rng(0), 300)
    plan = plan_tree_measurements(tree, candidates, PlanSettings(count=COUNT, level="full", sigma_pos_mm=0.1,
                                                                 target_points=np.vstack(LOCAL)))
    held_out = random_configurations(tree, np.random.default_rng(123), 300)
    true = _sensed(tree, truth, held_out)
    errors: dict[str, list[np.ndarray]] = {"planned": [], "random": []}
    for seed in range(16):
        rng = np.random.default_rng(1000 + seed)
        for kind in errors:
            q = plan.q if kind == "planned" else candidates[rng.choice(len(candidates), COUNT, replace=False)]
            data = MeasurementSet(tree.joint_names, q, _sensed(tree, truth, q, rng), None,
                                  np.full(COUNT, "calibration", dtype=object), np.arange(2, COUNT + 2))
            result = calibrate_tree(tree, data, "full", ChainFitOptions(selection="aic"))
            points = [result.target.points[np.array(t.spec.points) - 1] for t in tree.targets]
            with tree.placed(result.tree_placements):
                predicted = result.target.registration.apply_points(tree.target_points(held_out, points))
            errors[kind].append(np.linalg.norm(predicted - true, axis=2).mean(axis=0) * 1000.0)  # per target [mm]
    planned, random = np.array(errors["planned"]), np.array(errors["random"])
    for t, target in enumerate(plan.targets):
        observed = float(planned[:, t].mean())
        assert abs(observed / target.plan[0] - 1.0) <= PREDICTION_TOLERANCE, (target.link, observed, target.plan)
        assert target.plan[0] < target.random[0]
    ratio = np.median(planned.mean(axis=1)) / np.median(random.mean(axis=1))
    assert ratio <= RANDOM_RATIO, f"planned / random = {ratio:.3f}"


def _write_measured(path, plan_csv, sensed):
    """PLAN.csv with the measured columns x1..z2 added: a CSV v1 file."""
    with open(plan_csv, newline="") as handle:
        rows = list(csv.reader(handle))
    with open(path, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow([*rows[0], *(f"{a}{p}" for p in (1, 2) for a in "xyz")])
        for row, points in zip(rows[1:], sensed):
            writer.writerow([*row, *(repr(float(v)) for v in points.ravel())])


@pytest.fixture(scope="module")
def planned(robot, tmp_path_factory):
    """``pincal plan`` of the two targets, then the planned rows measured on the perturbed robot."""
    tree, truth = robot
    folder = tmp_path_factory.mktemp("tree_plan")
    urdf = folder / "robot.urdf"
    urdf.write_text(two_arm_urdf(), encoding="utf-8")
    plan_csv, plan_json = folder / "PLAN.csv", folder / "PLAN.json"
    code = main(["plan", str(urdf), *TARGETS, "--count", "12", "--sample", "200", "--sigma-pos", "0.1",
                 "--out", str(plan_csv), "--report", str(plan_json), "--quiet"])
    with open(plan_csv, newline="") as handle:
        header = next(csv.reader(handle))
    q = np.loadtxt(plan_csv, delimiter=",", skiprows=1, usecols=range(tree.n_joints), ndmin=2)
    measured = folder / "measured.csv"
    _write_measured(measured, plan_csv, _sensed(tree, truth, q, np.random.default_rng(5)))
    return folder, urdf, code, header, json.loads(plan_json.read_text(encoding="utf-8")), measured


def test_plan_writes_every_joint_column_and_each_targets_prediction_and_calibrate_reads_it(robot, planned, capsys):
    tree, _ = robot
    folder, urdf, code, header, document, measured = planned
    assert code == 0
    assert header == [*tree.joint_names, "priority", "candidate"]  # torso, both arms; head_1 on no chain
    assert [t["tip_link"] for t in document["chain"]["targets"]] == ["left_marker", "right_marker"]
    assert document["chain"]["joints"] == list(tree.joint_names)
    targets = document["predicted"]["targets"]
    assert [t["points"] for t in targets] == [[1], [2]]
    for target in targets:
        assert 0.0 < target["plan"]["mean_position_mm"] < target["random"]["mean_position_mm"]
    assert document["settings"]["measure"] == "points:2"
    page = folder / "PLAN.html"  # the plan's page: each target's prediction
    assert main(["report", str(folder / "PLAN.json"), "--out", str(page)]) == 0
    html = page.read_text(encoding="utf-8")
    assert 'id="targets-table"' in html and "left_marker (1)" in html and "right_marker (2)" in html
    out, report = folder / "out.urdf", folder / "REPORT.json"
    assert main(["calibrate", str(urdf), str(measured), *TARGETS, "--out", str(out), "--report", str(report),
                 "--quiet"]) == 0
    assert "right_marker (2)" in capsys.readouterr().out


def test_plan_continues_recorded_rows(planned, capsys):
    folder, urdf, _, _, _, measured = planned
    plan_csv, plan_json = folder / "MORE.csv", folder / "MORE.json"
    assert main(["plan", str(urdf), *TARGETS, "--count", "3", "--sample", "100", "--existing", str(measured),
                 "--out", str(plan_csv), "--report", str(plan_json), "--quiet"]) == 0
    document = json.loads(plan_json.read_text(encoding="utf-8"))
    assert document["settings"]["sigma_source"].startswith("estimated from")
    recorded, plan = document["predicted"]["recorded_only"], document["predicted"]["plan"]
    assert plan["mean_position_mm"] < recorded["mean_position_mm"]  # three more rows help
    assert "left_marker (1): plan mean" in capsys.readouterr().out


def test_recorded_sessions_get_a_registration_each_and_an_unseen_point_no_information(planned):
    """Two --existing files (sessions), the first with point 2 not seen in one row: each session's registration
    is estimated (6 unknowns each), the candidates continue the last one's."""
    folder, urdf, _, _, _, measured = planned
    rows = list(csv.reader(open(measured, newline="")))
    first, second = folder / "first.csv", folder / "second.csv"
    hidden = [*rows[1][:-3], "", "", ""]  # the first row's x2,y2,z2 empty: not seen
    with open(first, "w", newline="") as handle:
        csv.writer(handle).writerows([rows[0], hidden, *rows[2:7]])
    with open(second, "w", newline="") as handle:
        csv.writer(handle).writerows([rows[0], *rows[7:]])
    plan_json = folder / "SESSIONS.json"
    assert main(["plan", str(urdf), *TARGETS, "--count", "3", "--sample", "100", "--existing", str(first),
                 str(second), "--level", "offsets", "--out", str(folder / "SESSIONS.csv"), "--report", str(plan_json),
                 "--quiet"]) == 0
    identifiability = json.loads(plan_json.read_text(encoding="utf-8"))["identifiability"]
    assert identifiability["estimated_parameters"] == identifiability["kinematic_parameters"] + 2 * 6 + 2 * 3


_ARM_4 = '<child link="arm_{0}_4_link"/><origin xyz="0.01 0 -0.25" rpy="0 0 0"/><axis xyz="0 1 0"/>'


@pytest.mark.parametrize(("mimics", "columns", "absent"), [
    ({"right": ("arm_right_3", 0.5)}, ["arm_right_3"], ["arm_right_4"]),  # its driver on the tree
    ({"left": ("head_1", 1.0), "right": ("head_1", -1.0)}, ["head_1"], ["arm_left_4", "arm_right_4"]),  # off it
])
def test_a_joint_that_follows_another_has_no_column(tmp_path, mimics, columns, absent):
    """URDF <mimic>: the candidates obey it, PLAN.csv has no column for a follower (its driver's, off the tree, one
    value for both of its followers), and PLAN.json's joints are the tree's."""
    text = two_arm_urdf()
    for side, (driver, multiplier) in mimics.items():
        text = text.replace(_ARM_4.format(side), _ARM_4.format(side) +
                            f'<mimic joint="{driver}" multiplier="{multiplier}"/>')
    assert text.count("<mimic") == len(mimics)
    urdf = tmp_path / "robot.urdf"
    urdf.write_text(text, encoding="utf-8")
    plan_csv, plan_json = tmp_path / "PLAN.csv", tmp_path / "PLAN.json"
    assert main(["plan", str(urdf), *TARGETS, "--count", "10", "--sample", "100", "--out", str(plan_csv),
                 "--report", str(plan_json), "--quiet"]) == 0
    with open(plan_csv, newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert all(c in rows[0] for c in columns) and not any(a in rows[0] for a in absent)
    tree = KinematicTree.from_urdf(urdf, parse_targets(TARGETS[1::2]))
    assert json.loads(plan_json.read_text(encoding="utf-8"))["chain"]["joints"] == list(tree.joint_names)
    drawn = random_configurations(tree, np.random.default_rng(0), 50)
    for side, (driver, multiplier) in mimics.items():  # each follower at its driver's value (one for both)
        follower = drawn[:, tree.joint_names.index(f"arm_{side}_4")]
        if driver in tree.joint_names:
            assert np.allclose(follower, multiplier * drawn[:, tree.joint_names.index(driver)])
        else:
            assert np.allclose(follower * multiplier, drawn[:, tree.joint_names.index("arm_left_4")])


@pytest.mark.parametrize(("extra", "message"), [
    (["--tip-link", "left_marker:1", "--tip-link", "no_such_link:2"], "no_such_link"),
    ([*TARGETS, "--existing", "MISSING_COLUMN"], "arm_right_4"),
    ([*TARGETS, "--tool", "0,0,0,0,0,0"], "--tool"),
    ([*TARGETS, "--level", "dh"], "several --tip-link: plan --level dh"),  # not first sent to give --tool
])
def test_bad_input_is_refused_in_one_line(planned, extra, message, capsys):
    folder, urdf, *_ = planned
    if "MISSING_COLUMN" in extra:  # the recorded rows without one joint's column
        rows = list(csv.reader(open(folder / "measured.csv", newline="")))
        drop = rows[0].index("arm_right_4")
        short = folder / "short.csv"
        with open(short, "w", newline="") as handle:
            csv.writer(handle).writerows([r[:drop] + r[drop + 1:] for r in rows])
        extra = [str(short) if e == "MISSING_COLUMN" else e for e in extra]
    code = main(["plan", str(urdf), *extra, "--count", "10", "--sample", "50", "--out", str(folder / "BAD.csv"),
                 "--report", str(folder / "BAD.json"), "--quiet"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and message in err, err
    assert not (folder / "BAD.csv").exists()
