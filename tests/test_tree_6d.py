"""Several targets with their orientations (columns qxN,qyN,qzN,qwN): read, fitted, reported, evaluated."""

from __future__ import annotations

import contextlib
import csv
import io
import json
from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest
from conftest import assert_close, numeric_jacobian
from scipy.spatial.transform import Rotation
from tree_robot import two_arm_urdf

from pincal.cli.commands import main
from pincal.errors import PincalError
from pincal.fit.chain_calibration import ChainFitOptions
from pincal.fit.tree_calibration import calibrate_tree, initial_tree_target, tree_rows
from pincal.measurements.csv_v1 import read_measurements, read_sessions, write_measurements
from pincal.measurements.data import MeasurementSet
from pincal.model.tree import KinematicTree, parse_targets
from pincal.model.tree_parameters import TreeParameters
from pincal.report.tree_html import tree_section
from pincal.residuals.sensor_values import RowWeights
from pincal.residuals.tree import TreeResidual

TARGETS = ["left_marker:1", "right_marker:2,3"]
TIP_LINKS = ["--tip-link", TARGETS[0], "--tip-link", TARGETS[1]]
LOCAL = [np.array([[0.01, 0.0, 0.02]]), np.array([[0.0, 0.01, 0.0], [0.03, -0.01, 0.01]])]  # points in the tip links
FRAMES = [pin.rpy.rpyToMatrix(0.2, 0.1, -0.3), pin.rpy.rpyToMatrix(-0.1, 0.4, 0.2)]  # each target's frame in its link
NUMBERS = (1, 3)  # left_marker's orientation measured with point 1, right_marker's with point 3
HIDDEN_TURN = (5, 1)  # (row, target) whose orientation is not seen
OMEGA, TAU = pin.rpy.rpyToMatrix(0.1, -0.2, 0.3), np.array([1.0, 0.5, -0.2])


def _poses(tree, q, placements):
    """Sensed points (K, 3, 3) [m] and each target's sensed orientation (K, 3, 3) of the tree at ``placements``."""
    with tree.placed(placements):
        world = tree.target_points(q, LOCAL)
        turns = [t.chain.tool_poses(q[:, t.columns])[0] @ frame for t, frame in zip(tree.targets, FRAMES)]
    return world @ OMEGA.T + TAU, [OMEGA @ turn for turn in turns]


@pytest.fixture(scope="module")
def simulated():
    """40 noise-free 6D rows of the two-arm robot with perturbed joint placements; one orientation occluded."""
    tree = KinematicTree(pin.buildModelFromXML(two_arm_urdf()), parse_targets(TARGETS))
    params = TreeParameters(tree, "full")
    rng = np.random.default_rng(7)
    truth = rng.normal(0.0, 1e-3, params.size)
    truth[[i for i, info in enumerate(params.info) if info.name.endswith((".rx", ".ry", ".rz"))]] *= 10.0  # ~0.6 deg
    q = rng.uniform(-1.2, 1.2, (40, tree.n_joints))
    sensed, turns = _poses(tree, q, params.placements(truth))
    measured = {n: turn.copy() for n, turn in zip(NUMBERS, turns)}
    measured[NUMBERS[HIDDEN_TURN[1]]][HIDDEN_TURN[0]] = np.nan
    data = MeasurementSet(tree.joint_names, q, sensed, None, np.full(len(q), "calibration", dtype=object),
                          np.arange(2, len(q) + 2), target_rotations=measured)
    result = calibrate_tree(tree, data, "full", ChainFitOptions(selection="all"))
    nominal = calibrate_tree(tree, data, "registration")
    return tree, params, truth, data, (sensed, turns), result, nominal


def test_noise_free_6d_rows_give_the_truth(simulated):
    tree, _, _, data, (sensed, turns), result, _ = simulated
    assert result.orientation_errors is not None and result.sigma_rot_rad is not None
    assert result.rms_m < 1e-11 and np.nanmax(result.orientation_errors) < 1e-11
    # the calibrated model with the fitted frames reproduces every pose, the occluded orientation too
    registration = result.target.registration
    with tree.placed(result.tree_placements):
        fitted = [t.chain.tool_poses(data.q[:, t.columns])[0] @ result.target.rotation[i]
                  for i, t in enumerate(tree.targets)]
    for measured, model in zip(turns, fitted):
        assert_close(registration.rotation @ model, measured, 1e-10, "each target's orientation")
    for t, frame in enumerate(FRAMES):  # the frame in its link, up to what the link's own rotation error absorbs
        assert np.degrees(np.linalg.norm(pin.log3(result.target.rotation[t].T @ frame))) < 5.0


def test_tree_jacobian_with_orientations_matches_finite_differences(simulated):
    tree, params, truth, data, _, _, _ = simulated
    data = data.select(np.arange(8))  # the occluded orientation among them
    rows = tree_rows(tree, data)
    start = initial_tree_target(tree, data, rows)
    objective = TreeResidual(tree, params, np.arange(params.size), truth, rows, start, RowWeights(1000.0, 300.0))
    x = objective.start_vector() + np.random.default_rng(2).normal(0.0, 1e-3, objective.n_params)
    jacobian = objective.jacobian(x)
    assert jacobian.shape == (3 * 3 * 8 + 3 * (2 * 8 - 1), objective.n_params)
    assert objective.blocks["rotation"].stop - objective.blocks["rotation"].start == 6
    assert_close(jacobian, numeric_jacobian(objective.residual, x), 1e-5, "tree Jacobian with orientations")
    # a target's frame rotation moves its own orientation only
    left = slice(objective.blocks["rotation"].start, objective.blocks["rotation"].start + 3)
    turns = jacobian[objective.n_positions:]
    right = np.repeat(np.nonzero(objective.rotation_seen)[1] == 1, 3)  # entries row by row, targets within a row
    assert np.all(turns[right][:, left] == 0.0) and np.any(turns[~right][:, left] != 0.0)


def test_orientation_errors_before_and_after(simulated):
    _, _, _, _, _, result, nominal = simulated
    before = np.degrees(np.sqrt(np.nanmean(nominal.orientation_errors ** 2, axis=0)))
    after = np.degrees(np.sqrt(np.nanmean(result.orientation_errors ** 2, axis=0)))
    assert np.all(before > 0.2) and np.all(after < 1e-8)


def test_an_occluded_orientation_removes_only_itself(simulated):
    _, _, _, data, _, result, _ = simulated
    row, target = HIDDEN_TURN
    assert np.isnan(result.orientation_errors[row, target])
    assert np.isfinite(result.orientation_errors).sum() == 2 * data.n_rows - 1
    assert np.isfinite(result.point_errors).all()  # the row's points stay


def test_orientations_are_weighted_by_their_own_noise_scale(simulated):
    """sigma_rot is estimated from the orientation residuals alone, sigma_pos from the points' (each row's
    entries whitened by its own: maximum likelihood with unknown variances, as one chain's)."""
    tree, _, _, data, _, _, _ = simulated
    rng = np.random.default_rng(11)
    sigma_pos, sigma_rot = 2e-4, np.radians(0.3)  # a mocap rigid body's: 0.2 mm, 0.3 deg
    noisy = {n: turns @ Rotation.from_rotvec(rng.normal(0.0, sigma_rot, (len(turns), 3))).as_matrix()
             for n, turns in data.target_rotations.items()}
    rows = MeasurementSet(data.joint_names, data.q, data.points + rng.normal(0.0, sigma_pos, data.points.shape), None,
                          data.roles, data.lines, target_rotations=noisy)
    result = calibrate_tree(tree, rows, "full", ChainFitOptions(selection="all"))
    assert 0.7 < result.sigma_pos_m / sigma_pos < 1.1 and 0.7 < result.sigma_rot_rad / sigma_rot < 1.1
    assert 0.0 < result.predicted_point_rms(tree, data.q[:5]) < sigma_pos  # the frames' columns in its covariance


def test_a_row_whose_orientation_alone_is_off_is_named_and_removed_when_asked(simulated):
    """Rows with a mocap rigid body's noise (0.2 mm, 0.3°, as the test above) and one row whose right target's orientation is turned by
    5° (its markers matched the wrong way round), its points right: noted by its line, removed by
    ``reject_outliers``; the rows as they were flag nothing."""
    tree, _, _, data, _, _, _ = simulated
    rng = np.random.default_rng(12)
    noisy = {n: turns @ Rotation.from_rotvec(rng.normal(0.0, np.radians(0.3), (len(turns), 3))).as_matrix()
             for n, turns in data.target_rotations.items()}
    points = data.points + rng.normal(0.0, 2e-4, data.points.shape)
    clean = MeasurementSet(data.joint_names, data.q, points, None, data.roles, data.lines, target_rotations=noisy)
    bad_turns = {n: turns.copy() for n, turns in noisy.items()}
    bad_turns[NUMBERS[1]][17] = bad_turns[NUMBERS[1]][17] @ pin.exp3(np.array([0.0, np.radians(5.0), 0.0]))
    bad = replace(clean, target_rotations=bad_turns)
    line = int(data.lines[17])
    assert not any("outlier" in note for note in calibrate_tree(tree, clean, "full", ChainFitOptions()).notes)
    noted = calibrate_tree(tree, bad, "full", ChainFitOptions())
    assert any(f"1 row(s) look like outliers (lines [{line}]; by their orientation: lines [{line}])" in note
               for note in noted.notes), noted.notes
    assert line in data.lines[noted.used_index]  # noted, kept in the fit
    removed = calibrate_tree(tree, bad, "full", ChainFitOptions(reject_outliers=True))
    assert line not in data.lines[removed.used_index] and removed.used_index.size == data.n_rows - 1
    assert any(f"removed 1 outlier row(s) at lines [{line}]; by their orientation: lines [{line}] and refitted" in note
               for note in removed.notes), removed.notes
    # the same row seeing none of its points (every cell of x,y,z empty), its orientations only: scored by them
    blind = replace(bad, points=np.where(np.arange(data.n_rows)[:, None, None] == 17, np.nan, bad.points))
    noted = calibrate_tree(tree, blind, "full", ChainFitOptions())
    assert any(f"(lines [{line}]; by their orientation: lines [{line}])" in note for note in noted.notes), noted.notes


def test_the_same_rows_without_orientations_fit_points_only(simulated):
    tree, _, _, data, _, result, _ = simulated
    plain = MeasurementSet(data.joint_names, data.q, data.points, None, data.roles, data.lines)
    points_only = calibrate_tree(tree, plain, "full", ChainFitOptions(selection="all"))
    assert points_only.orientation_errors is None and points_only.sigma_rot_rad is None
    assert points_only.rms_m < 1e-11 and points_only.rank == result.rank  # the frames absorb the tips' rotations


def _header(tree):
    return [*tree.joint_names, *(f"{a}{i}" for i in (1, 2, 3) for a in "xyz"),
            *(f"q{a}{n}" for n in NUMBERS for a in "xyzw")]


def _cells(q, sensed, turns, index):
    """The CSV cells of rows ``index``: joints, points, each target's quaternion (scalar last)."""
    return [[*(repr(float(v)) for v in q[k]), *(repr(float(v)) for v in sensed[k].ravel()),
             *(repr(float(v)) for turn in turns for v in Rotation.from_matrix(turn[k]).as_quat())] for k in index]


@pytest.fixture(scope="module")
def csv_rows(tmp_path_factory, simulated):
    """Three of the simulated rows as a CSV file with orientation columns qx1.. and qx3.. (header, lines 2-4)."""
    tree, _, _, data, (sensed, turns), _, _ = simulated
    return tmp_path_factory.mktemp("tree6d"), tree, _header(tree), _cells(data.q, sensed, turns, range(3))


def _file(folder, header, rows, name="data.csv"):
    with open(folder / name, "w", newline="") as handle:
        csv.writer(handle).writerows([header, *rows])
    return folder / name


def test_orientation_columns_are_read_per_target_and_an_empty_group_is_not_seen(csv_rows):
    folder, tree, header, rows = csv_rows
    rows = [list(r) for r in rows]
    column = header.index("qx3")
    rows[1][column:column + 4] = ["", "", "", ""]
    data, notes = read_measurements(_file(folder, header, rows), tree.joint_specs, (), tree.other_branch_joints,
                                    occlusion=True)
    assert sorted(data.target_rotations) == [1, 3] and not data.extra and not notes
    table = tree_rows(tree, data)
    assert table.rotation_seen.tolist() == [[True, True], [True, False], [True, True]]


def test_sessions_of_one_calibration_give_the_same_orientation_columns(csv_rows):
    folder, tree, header, rows = csv_rows
    plain = [name for name in header if not name.startswith("q")]
    other = _file(folder, plain, [row[:len(plain)] for row in rows], "points_only.csv")
    with pytest.raises(PincalError, match="differs from .* in its orientation columns qxN,qyN,qzN,qwN"):
        read_sessions([_file(folder, header, rows), other], tree.joint_specs, (), tree.other_branch_joints,
                      occlusion=True)


@pytest.mark.parametrize(("cells", "message"), [
    ({"qy3": "abc"}, "line 3, column 'qy3': 'abc' is not a finite number"),
    ({"qw1": ""}, "line 3, column 'qw1': some of qx1,qy1,qz1,qw1 empty"),
    ({"qx1": "0.9"}, "line 3: quaternion qx1,qy1,qz1,qw1 has norm"),
])
def test_a_bad_quaternion_cell_is_one_line_naming_row_and_column(csv_rows, cells, message):
    folder, tree, header, rows = csv_rows
    rows = [list(r) for r in rows]
    for name, text in cells.items():
        rows[1][header.index(name)] = text
    with pytest.raises(PincalError, match=message) as caught:
        read_measurements(_file(folder, header, rows, "bad.csv"), tree.joint_specs, (), tree.other_branch_joints,
                          occlusion=True)
    assert "\n" not in str(caught.value)


@pytest.mark.parametrize(("rename", "message"), [
    ({"qx3": "qx2", "qy3": "qy2", "qz3": "qz2", "qw3": "qw2"}, None),  # any one of the target's points
    ({"qx3": "qx4", "qy3": "qy4", "qz3": "qz4", "qw3": "qw4"}, "there is no point 4"),
    ({"qx1": "qx2", "qy1": "qy2", "qz1": "qz2", "qw1": "qw2"}, "are both the orientation of right_marker"),
    ({"qx1": "qx", "qy1": "qy", "qz1": "qz", "qw1": "qw"}, "name no target with several --tip-link"),
])
def test_orientation_columns_name_a_target_by_one_of_its_points(csv_rows, rename, message):
    folder, tree, header, rows = csv_rows
    header = [rename.get(name, name) for name in header]
    data, _ = read_measurements(_file(folder, header, rows, "renamed.csv"), tree.joint_specs, (),
                                tree.other_branch_joints, occlusion=True)
    if message is None:
        assert tree_rows(tree, data).rotation_seen.all()
    else:
        with pytest.raises(PincalError, match=message):
            tree_rows(tree, data)


@pytest.fixture(scope="module")
def cli_run(tmp_path_factory, simulated):
    """``pincal calibrate`` of 30 of the 6D rows (right_marker's orientation not seen on line 7), 10 held out."""
    tree, _, _, data, (sensed, turns), _, _ = simulated
    folder = tmp_path_factory.mktemp("tree6d_cli")
    urdf = folder / "robot.urdf"
    urdf.write_text(two_arm_urdf(), encoding="utf-8")
    rows = _cells(data.q, sensed, turns, range(30))
    column = _header(tree).index("qx3")
    rows[5][column:column + 4] = ["", "", "", ""]
    calibration = _file(folder, _header(tree), rows)
    held = _file(folder, _header(tree), _cells(data.q, sensed, turns, range(30, 40)), "held.csv")
    out, report = folder / "out.urdf", folder / "REPORT.json"
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        code = main(["calibrate", str(urdf), str(calibration), *TIP_LINKS, "--select", "all", "--out", str(out),
                     "--report", str(report), "--quiet"])
    return folder, urdf, calibration, held, out, report, code, printed.getvalue()


def test_calibrate_reports_and_prints_each_targets_orientation_before_and_after(cli_run):
    *_, report_path, code, printed = cli_run
    assert code == 0
    report = json.loads(report_path.read_text(encoding="utf-8"))
    assert report["noise"]["sigma_rot_deg"] is not None
    for target, seen in zip(report["targets"], (30, 29)):
        before, after = target["nominal_errors"], target["calibration_errors"]
        assert after["orientation_seen"] == seen and len(target["rotation_xyzw"]) == 4
        assert before["orientation"]["rms_deg"] > 0.2 and after["orientation"]["max_deg"] < 1e-6
    lines = printed.splitlines()
    at = next(i for i, line in enumerate(lines) if line.startswith("target orientation"))
    assert [line.split()[:2] for line in lines[at + 1:at + 3]] == [["left_marker", "30"], ["right_marker", "29"]]


def test_evaluate_prints_and_writes_each_targets_orientation_errors(cli_run, capsys):
    folder, _, _, held, out, report, *_ = cli_run
    assert main(["evaluate", str(out), str(report), str(held), "--max-rot-deg", "1e-6", "--json",
                 str(folder / "e.json")]) == 0
    lines = capsys.readouterr().out.splitlines()
    at = next(i for i, line in enumerate(lines) if line.startswith("target orientation"))
    for line, link in zip(lines[at + 1:at + 3], ("left_marker", "right_marker")):
        assert line.split()[:2] == [link, "10"] and float(line.split()[-1]) < 1e-6
    document = json.loads((folder / "e.json").read_text(encoding="utf-8"))
    assert document["max_deg"] < 1e-6
    assert [t["errors"]["orientation_seen"] for t in document["evaluated_targets"]] == [10, 10]


def test_plan_continues_6d_rows_and_says_it_plans_the_points(cli_run, capsys):
    folder, urdf, calibration, *_ = cli_run
    assert main(["plan", str(urdf), *TIP_LINKS, "--count", "2", "--sample", "40", "--existing", str(calibration),
                 "--out", str(folder / "MORE.csv"), "--report", str(folder / "MORE.json"), "--quiet"]) == 0
    assert "orientation columns qxN,qyN,qzN,qwN are not counted in the plan's information" in capsys.readouterr().err


def test_a_target_beyond_reach_is_not_told_to_give_a_tool_a_tree_refuses(simulated):
    """The beyond-reach finding of one chain advises --tool; with several targets --tool is refused, so the
    finding gives the rest of its advice only."""
    from dataclasses import replace

    from pincal.workflows.tree_calibration import tree_findings

    tree, _, _, data, _, result, _ = simulated
    far = replace(result, target=replace(result.target, points=result.target.points * 100.0))
    _, found = tree_findings(tree, far, data.q, None)
    target = [f.message for f in found if f.code == "target"]
    assert target and "vary the tool's orientation" in target[0] and "--tool" not in target[0]


def test_the_report_page_shows_each_targets_orientation_before_and_after(cli_run):
    folder, *_, report_path, _, _ = cli_run
    assert main(["report", str(report_path), "--out", str(folder / "tree.html")]) == 0
    page = (folder / "tree.html").read_text(encoding="utf-8")
    table = page[page.index('id="target-orientations-table"'):]
    table = table[:table.index("</table>")]
    for target in json.loads(report_path.read_text(encoding="utf-8"))["targets"]:
        before, after = target["nominal_errors"], target["calibration_errors"]
        row = table[table.index(f"<td>{target['tip_link']}</td>"):]
        row = row[:row.index("</tr>")]
        assert (f"<td>{after['orientation_seen']}</td><td>{before['orientation']['rms_deg']:.3f}</td>"
                f"<td>{after['orientation']['rms_deg']:.3f}</td>") in row


def test_written_6d_tree_rows_read_back_exactly(simulated, tmp_path):
    """write_measurements writes each target's qxN group (an occluded orientation or point: empty cells)."""
    tree, _, _, data, *_ = simulated
    points = data.points.copy()
    points[2, 1] = np.nan  # point 2 not seen on the third row
    data = MeasurementSet(data.joint_names, data.q[:8], points[:8], None, data.roles[:8], data.lines[:8],
                          target_rotations={n: r[:8] for n, r in data.target_rotations.items()})
    write_measurements(tmp_path / "rows.csv", data)
    back, _ = read_measurements(tmp_path / "rows.csv", tree.joint_specs, (), tree.other_branch_joints, occlusion=True)
    assert np.array_equal(back.q, data.q) and np.array_equal(back.points, data.points, equal_nan=True)
    assert sorted(back.target_rotations) == sorted(NUMBERS)
    for number in NUMBERS:
        seen = np.isfinite(data.target_rotations[number]).all(axis=(1, 2))
        assert np.array_equal(np.isfinite(back.target_rotations[number]).all(axis=(1, 2)), seen)
        assert_close(back.target_rotations[number][seen], data.target_rotations[number][seen], 1e-15, f"qx{number}")
    with open(tmp_path / "rows.csv", newline="") as handle:
        header, *rows = list(csv.reader(handle))
    assert header == [*_header(tree), "role"] and sum(cell == "" for row in rows for cell in row) == 3 + 4


SAG = -4e-4  # torso_2's compliance [rad/(N·m)]: it sags under both arms by up to ~7 mrad (test_tree_diagnose's)
SIGMA_M, SIGMA_RAD = 1e-4, np.radians(0.1)  # a mocap rigid body's noise per axis: 0.1 mm, 0.1 deg
FLOOR_DEG = np.sqrt(3.0) * 0.1  # the RMS angle of an orientation at the noise alone (three axes) [deg]


def _sagging_6d_rows(tree, params, truth, n_rows, rng, sag=SAG):
    """6D rows of the two-arm robot (one point per hand, its orientation as qx1.., qx2..) with torso_2 sagging by
    ``sag`` times its gravity torque, each point and orientation with its noise."""
    from pincal.model.effects import gravity_torques
    from pincal.model.tree_effects import TreeBody

    q = rng.uniform(-1.2, 1.2, (n_rows, tree.n_joints))
    actual = q.copy()
    with tree.placed(params.placements(truth)):
        actual[:, 1] += sag * gravity_torques(TreeBody(tree), q)[:, 1]
        world = tree.target_points(actual, LOCAL[:1] * 2)
        turns = [OMEGA @ t.chain.tool_poses(actual[:, t.columns])[0] @ frame for t, frame in zip(tree.targets, FRAMES)]
    sensed = world @ OMEGA.T + TAU + rng.normal(0.0, SIGMA_M, world.shape)
    measured = {n + 1: turn @ Rotation.from_rotvec(rng.normal(0.0, SIGMA_RAD, (n_rows, 3))).as_matrix()
                for n, turn in enumerate(turns)}
    return MeasurementSet(tree.joint_names, q, sensed, None, np.full(n_rows, "calibration", dtype=object),
                          np.arange(2, n_rows + 2), target_rotations=measured)


@pytest.fixture(scope="module")
def diagnosed_6d(tmp_path_factory):
    """``pincal diagnose`` of 40 such rows, 20 held out."""
    folder = tmp_path_factory.mktemp("tree6d_diagnose")
    targets = ["left_marker:1", "right_marker:2"]
    tree = KinematicTree(pin.buildModelFromXML(two_arm_urdf()), parse_targets(targets))
    params = TreeParameters(tree, "full")
    rng = np.random.default_rng(5)
    truth = rng.normal(0.0, 5e-4, params.size)
    for name, rows in (("data", 40), ("held", 20)):
        write_measurements(folder / f"{name}.csv", _sagging_6d_rows(tree, params, truth, rows, rng))
    (folder / "robot.urdf").write_text(two_arm_urdf(), encoding="utf-8")
    report, printed = folder / "REPORT.json", io.StringIO()
    with contextlib.redirect_stdout(printed):
        code = main(["diagnose", str(folder / "robot.urdf"), str(folder / "data.csv"), "--tip-link", targets[0],
                     "--tip-link", targets[1], "--validation", str(folder / "held.csv"), "--out",
                     str(folder / "out.urdf"), "--report", str(report), "--quiet"])
    return code, report, printed.getvalue()


def test_diagnose_of_6d_rows_names_the_sag_and_brings_each_orientation_to_its_noise(diagnosed_6d):
    code, report_path, printed = diagnosed_6d
    assert code == 0
    report = json.loads(report_path.read_text(encoding="utf-8"))
    [effect] = report["effects"]
    assert (effect["type"], effect["joint"]) == ("compliance", "torso_2")
    assert effect["value"] == pytest.approx(SAG, rel=0.03)
    assert report["noise"]["sigma_rot_deg"] == pytest.approx(0.1, rel=0.15)  # the orientations' own scale
    for target in report["targets"]:
        geometry, final = target["geometry_errors"], target["calibration_errors"]
        assert geometry["orientation_seen"] == final["orientation_seen"] == 40
        assert geometry["orientation"]["rms_deg"] > 1.25 * FLOOR_DEG  # the sag turns the hands too
        assert final["orientation"]["rms_deg"] < 1.15 * FLOOR_DEG
        held_before, held_after = target["validation_geometry_errors"], target["validation_errors"]
        assert held_before["orientation_seen"] == held_after["orientation_seen"] == 20
        assert held_before["orientation"]["rms_deg"] > 1.5 * FLOOR_DEG  # the geometry alone cannot turn the hands back
        assert held_after["orientation"]["rms_deg"] < 1.1 * FLOOR_DEG
    # the step that adopted the sag: every measured orientation before and after it, on the calibration rows (as
    # the targets' geometry and final errors, both targets together) and on the held-out rows
    [step] = report["diagnosis"]["steps"]
    for rows, (before, after), seen in (("calibration", ("geometry_errors", "calibration_errors"), 80),
                                         ("heldout", ("validation_geometry_errors", "validation_errors"), 40)):
        assert step[rows]["before"]["orientation_seen"] == step[rows]["after"]["orientation_seen"] == seen
        for key, errors in ((before, step[rows]["before"]), (after, step[rows]["after"])):  # RMS pooled by count
            counts = [t[key]["orientation_seen"] for t in report["targets"]]
            rms = np.sqrt(np.dot(counts, [t[key]["orientation"]["rms_deg"] ** 2 for t in report["targets"]])
                          / np.sum(counts))
            assert errors["orientation"]["rms_deg"] == pytest.approx(rms, rel=1e-9), (rows, key)
    # the page's values: each target's orientation nominal -> geometry -> with effects, and held out
    rows = [row["turns"] for row in tree_section(report)["rows"]]
    assert [len(r["steps"]) for r in rows] == [3, 3] and all("—" not in r["held"] for r in rows)
    for target in report["targets"]:  # printed: RMS geometry, final, held-out geometry, held-out final [deg]
        [line] = [line.split() for line in printed.splitlines() if line.startswith(f"{target['tip_link']} orient")]
        assert line[2:] == [f"{target[k]['orientation']['rms_deg']:.4f}" for k in (
            "geometry_errors", "calibration_errors", "validation_geometry_errors", "validation_errors")] + ["[deg]"]


@pytest.fixture(scope="module")
def sagging():
    """40 6D rows of the two-arm robot whose torso pitch sags, 20 held-out rows of it stiff, 20 of it sagging, and
    the rows' calibration (every parameter)."""
    tree = KinematicTree(pin.buildModelFromXML(two_arm_urdf()), parse_targets(["left_marker:1", "right_marker:2"]))
    params = TreeParameters(tree, "full")
    rng = np.random.default_rng(3)
    truth = rng.normal(0.0, 5e-4, params.size)
    data, stiff, held = (_sagging_6d_rows(tree, params, truth, rows, rng, sag)
                         for rows, sag in ((40, SAG), (20, 0.0), (20, SAG)))
    return tree, data, held, stiff, calibrate_tree(tree, data, "full", ChainFitOptions(selection="all"))


def test_the_held_out_test_judges_the_orientations_too(sagging):
    """Held-out rows of a stiff robot refute the sag the calibration rows show, in their points and orientations."""
    from pincal.diagnosis.diagnose import DiagnoseOptions
    from pincal.diagnosis.tree_diagnose import diagnose_tree
    from pincal.model.effects import Effect

    tree, data, _, stiff, calibration = sagging
    found = diagnose_tree(tree, calibration, data, stiff, DiagnoseOptions(candidates=[Effect("compliance", "torso_2")]))
    [candidate] = found.last_candidates
    assert found.effects == () and candidate.verdict.startswith("it makes the held-out rows worse")
    assert "orientation" in candidate.verdict  # the angles' change beside the points'
    # the orientations alone refute it: held-out rows whose every point is unseen
    blind = replace(stiff, points=np.full_like(stiff.points, np.nan))
    found = diagnose_tree(tree, calibration, data, blind, DiagnoseOptions(candidates=[Effect("compliance", "torso_2")]))
    [candidate] = found.last_candidates
    assert found.effects == () and candidate.verdict.startswith("it makes the held-out rows worse")


@pytest.mark.parametrize("measured", [(1,), ()])
def test_held_out_rows_may_measure_fewer_orientations_than_the_calibration_rows(sagging, measured):
    """Held-out rows with one hand's orientation only, or none: the fits' unknowns stay where the calibration's
    are."""
    from pincal.diagnosis.diagnose import DiagnoseOptions
    from pincal.diagnosis.tree_diagnose import diagnose_tree
    from pincal.model.effects import Effect

    tree, data, held, _, calibration = sagging
    fewer = MeasurementSet(held.joint_names, held.q, held.points, None, held.roles, held.lines,
                           target_rotations={n: held.target_rotations[n] for n in measured})
    found = diagnose_tree(tree, calibration, data, fewer, DiagnoseOptions(candidates=[Effect("compliance", "torso_2")]))
    [(effect, values, _)] = found.effects
    assert values[0] == pytest.approx(SAG, rel=0.03) and found.heldout_turns is not None
    after = found.heldout_turns[1]
    assert np.isfinite(after[:, :len(measured)]).all() and np.isnan(after[:, len(measured):]).all()
    assert not measured or np.sqrt(np.mean(after[:, :1] ** 2)) < 1.25 * np.sqrt(3.0) * SIGMA_RAD  # the noise's
