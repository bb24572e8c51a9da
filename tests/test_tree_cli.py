"""``pincal calibrate`` with several --tip-link LINK:POINTS, end to end, and the commands that refuse them."""

from __future__ import annotations

import csv
import json

import numpy as np
import pinocchio as pin
import pytest
from tree_robot import two_arm_urdf

from pincal.cli.commands import main
from pincal.model.tree import KinematicTree, parse_targets
from pincal.model.tree_parameters import TreeParameters
from pincal.report.reading import PAGE_KINDS, load_report

TARGETS = ["--tip-link", "left_marker:1", "--tip-link", "right_marker:2,3"]
LOCAL = [np.array([[0.01, 0.0, 0.02]]), np.array([[0.0, 0.01, 0.0], [0.03, -0.01, 0.01]])]


def _write_rows(path, names, q, sensed, hidden=()):
    """A CSV of rows ``q`` measuring ``sensed`` (K, 3, 3); (row, point) pairs in ``hidden`` left empty."""
    with open(path, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow([*names, *(f"{a}{i}" for i in (1, 2, 3) for a in "xyz")])
        for k in range(len(q)):
            cells = [repr(float(v)) for v in sensed[k].ravel()]
            for row, point in hidden:
                if row == k:
                    cells[3 * point:3 * point + 3] = ["", "", ""]
            writer.writerow([*(repr(float(v)) for v in q[k]), *cells])


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """The robot, 40 noise-free rows of a perturbed one (point 2 not seen on line 5), 10 held-out rows (point 1
    not seen on line 2), and the calibration."""
    folder = tmp_path_factory.mktemp("tree")
    urdf = folder / "robot.urdf"
    urdf.write_text(two_arm_urdf(), encoding="utf-8")
    tree = KinematicTree(pin.buildModelFromXML(two_arm_urdf()), parse_targets(TARGETS[1::2]))
    params = TreeParameters(tree, "full")
    rng = np.random.default_rng(3)
    q = rng.uniform(-1.2, 1.2, (50, tree.n_joints))
    with tree.placed(params.placements(rng.normal(0.0, 1e-3, params.size))):
        world = tree.target_points(q, LOCAL)
    sensed = world @ pin.rpy.rpyToMatrix(0.1, -0.2, 0.3).T + np.array([1.0, 0.5, -0.2])
    data, held_out = folder / "data.csv", folder / "held_out.csv"
    _write_rows(data, tree.joint_names, q[:40], sensed[:40], hidden=[(3, 1)])
    _write_rows(held_out, tree.joint_names, q[40:], sensed[40:], hidden=[(0, 0)])
    out, report = folder / "out.urdf", folder / "REPORT.json"
    code = main(["calibrate", str(urdf), str(data), *TARGETS, "--select", "all", "--out", str(out),
                 "--report", str(report), "--quiet"])
    return folder, urdf, data, out, report, code, (q[:40], sensed[:40]), held_out


def test_calibrate_several_targets_writes_every_chain_and_each_targets_errors(files):
    folder, urdf, data, out, report_path, code, (q, sensed), _ = files
    assert code == 0
    report = json.loads(report_path.read_text(encoding="utf-8"))
    names = [p["name"] for p in report["parameters"]]
    assert names.count("torso_2.tx") == 1 and len(names) == len(set(names)) == 72  # the torso fitted once
    assert [t["tip_link"] for t in report["targets"]] == ["left_marker", "right_marker"]
    left, right = report["targets"]
    assert left["joints"][:2] == right["joints"][:2] == ["torso_1", "torso_2"]
    assert right["calibration_errors"]["seen"] == 79  # 2 points x 40 rows, one not seen
    assert left["nominal_errors"]["position"]["rms_mm"] > 1.0  # the perturbation is seen before
    for target in report["targets"]:
        assert target["calibration_errors"]["position"]["max_mm"] < 1e-8
    # the corrected URDF alone, with the report's points and registration, reproduces every measured point
    tree = KinematicTree.from_urdf(out, parse_targets(TARGETS[1::2]))
    points = [np.array(t["points_m"]) for t in report["targets"]]
    registration = report["registration"]["position"]
    rotation = pin.Quaternion(*np.roll(registration["rotation_xyzw"], 1)).toRotationMatrix()  # w first
    predicted = tree.target_points(q, points) @ rotation.T + registration["translation_m"]
    assert np.abs(predicted - sensed).max() < 1e-9


def test_evaluate_gives_each_targets_errors_on_held_out_rows(files, capsys):
    folder, _, _, out, report, *_, held_out = files
    assert main(["evaluate", str(out), str(report), str(held_out), "--max-pos-mm", "1e-6"]) == 0
    printed = capsys.readouterr().out.splitlines()
    assert printed[0] == "10 rows; registration: held_out: the report's 'data'"
    left, right = (line.split() for line in printed[2:4])
    assert left[:2] == ["left_marker", "9"] and right[:2] == ["right_marker", "20"]  # point 1 not seen once
    assert float(left[-1]) < 1e-6 and float(right[-1]) < 1e-6  # noise-free rows: the truth predicted
    assert main(["evaluate", str(out), str(report), str(held_out), "--json", str(folder / "e.json")]) == 0
    document = json.loads((folder / "e.json").read_text(encoding="utf-8"))  # what it printed, per target
    assert [(t["tip_link"], t["points"], t["errors"]["seen"]) for t in document["evaluated_targets"]] == [
        ("left_marker", [1], 9), ("right_marker", [2, 3], 20)]
    assert document["rows"] == 10 and document["max_mm"] < 1e-6
    assert main(["evaluate", str(out), str(report), str(held_out), "--json", str(held_out)]) == 2  # an input
    capsys.readouterr()
    assert main(["report", str(folder / "e.json"), "--out", str(folder / "e.html")]) == 2  # told apart, and why
    err = capsys.readouterr().err
    assert "'pincal evaluate --json' of a tree's report" in err and "pincal report REPORT.json" in err
    assert not (folder / "e.html").exists()


def test_evaluate_says_a_target_not_seen_and_refuses_rows_without_a_point(files, capsys):
    folder, _, _, out, report, *_, held_out = files
    lines = held_out.read_text(encoding="utf-8").splitlines()
    header = lines[0].split(",")
    point_2 = [header.index(c) for c in ("x2", "y2", "z2", "x3", "y3", "z3")]
    unseen = folder / "unseen.csv"
    unseen.write_text("\n".join([lines[0], *(",".join("" if i in point_2 else c for i, c in enumerate(line.split(",")))
                                             for line in lines[1:])]) + "\n", encoding="utf-8")
    assert main(["evaluate", str(out), str(report), str(unseen)]) == 0
    printed = capsys.readouterr().out.splitlines()
    assert printed[3].split() == ["right_marker", "0", "not", "seen"]  # points 2 and 3 empty in every row
    one = folder / "one_unseen.csv"
    one.write_text("\n".join([lines[0], *(",".join("" if i in point_2[:3] else c for i, c in enumerate(line.split(",")))
                                          for line in lines[1:])]) + "\n", encoding="utf-8")
    assert main(["evaluate", str(out), str(report), str(one)]) == 0
    captured = capsys.readouterr()
    assert captured.out.splitlines()[3].split()[:2] == ["right_marker", "10"]  # point 3 only
    assert "point(s) 2 of right_marker not seen in any row" in captured.err
    assert main(["evaluate", str(out), str(report), str(unseen), "--new-session"]) == 0  # points 1 still seen
    session = folder / "session.csv"  # session b: no point measured
    session.write_text("\n".join([lines[0] + ",session", *(line + ",a" for line in lines[1:6]),
                                   *(",".join(["" if i >= len(header) - 9 else c for i, c in enumerate(line.split(","))]
                                              + ["b"]) for line in lines[6:])]) + "\n", encoding="utf-8")
    capsys.readouterr()
    assert main(["evaluate", str(out), str(report), str(session), "--new-session"]) == 2
    assert f"{session}: session 'b' has 0 measured point(s)" in capsys.readouterr().err
    cpa = folder / "cpa.csv"
    cpa.write_text("\n".join([lines[0] + ",role", *(line + ",cpa" for line in lines[1:])]) + "\n", encoding="utf-8")
    assert main(["evaluate", str(out), str(report), str(cpa)]) == 2
    assert f"{cpa}: no measured point in a row that is not role=cpa" in capsys.readouterr().err


def test_the_report_page_shows_each_targets_errors(files, capsys):
    folder, *_, report, _, _, _ = files
    assert load_report(report, PAGE_KINDS)["targets"]  # the page's loader (pincal report, --html)
    assert main(["report", str(report), "--out", str(folder / "tree.html")]) == 0
    page = (folder / "tree.html").read_text(encoding="utf-8")
    assert 'id="targets-table"' in page and "Calibration (full) of 2 targets" in page
    assert "target-orientations-table" not in page  # no orientation measured: no orientation table
    document = json.loads(report.read_text(encoding="utf-8"))
    for target in document["targets"]:  # each target's line: its link, its RMS before and after as the report's
        before, after = target["nominal_errors"]["position"]["rms_mm"], target["calibration_errors"]["position"]
        assert f"<td>{target['tip_link']}</td>" in page and f"<td>{before:.3f}</td>" in page
        assert f"<td>{after['rms_mm']:.3f}</td>" in page


def test_evaluate_html_shows_each_targets_errors_on_the_evaluated_rows(files, capsys):
    """evaluate --html of a tree's report: the report's page with each target's errors on the rows given (as
    --json has them) beside its own; an --html that is an input, or the --json, leaves nothing written."""
    folder, *_, out, report, _, _, held_out = files
    page_path, json_path = folder / "evaluated.html", folder / "evaluated.json"
    assert main(["evaluate", str(out), str(report), str(held_out), "--json", str(json_path), "--html",
                 str(page_path)]) == 0
    assert f"wrote {page_path}" in capsys.readouterr().out
    page = page_path.read_text(encoding="utf-8")
    assert 'id="targets-table"' in page and "<th>evaluated RMS [mm]</th>" in page and str(held_out) in page
    for target in json.loads(json_path.read_text(encoding="utf-8"))["evaluated_targets"]:
        errors = target["errors"]["position"]  # the row of this target: its own numbers, then the evaluated ones
        row = next(line for line in page.splitlines() if line.startswith(f"<tr><td>{target['tip_link']}</td>"))
        assert row.endswith(f"<td>{target['errors']['seen']}</td><td>{errors['rms_mm']:.3f}</td>"
                            f"<td>{errors['max_mm']:.3f}</td></tr>")
    for bad in (held_out, json_path):
        assert main(["evaluate", str(out), str(report), str(held_out), "--json", str(json_path), "--html",
                     str(bad)]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 2


def test_one_tip_link_keeps_refusing_an_empty_point_cell(files, capsys):
    folder, urdf, data, *_ = files
    code = main(["calibrate", str(urdf), str(data), "--tip-link", "right_marker", "--out", str(folder / "one.urdf"),
                 "--report", str(folder / "one.json"), "--quiet"])
    assert code == 2
    assert "line 5, column 'x2': empty cell; expected a finite number" in capsys.readouterr().err


@pytest.mark.parametrize("extra, named", [
    (["--tool", "0,0,0,0,0,0"], "several --tip-link: --tool is not yet supported"),
    (["--level", "dh"], "several --tip-link: --level dh fits one serial chain's DH table"),
    (["--method", "2"], "several --tip-link: --method is not yet supported"),
    (["--select", "press"], "several --tip-link: --select press is not yet supported")])
def test_flags_a_tree_does_not_take_yet_are_refused(files, capsys, extra, named):
    """Each flag calibrate takes with one chain and not yet with several is refused in one line, nothing written."""
    folder, urdf, data, *_ = files
    out = folder / f"refused_{extra[0].strip('-')}"
    code = main(["calibrate", str(urdf), str(data), *TARGETS, *extra, "--out", str(out / "t.urdf"),
                 "--report", str(out / "t.json")])
    err = capsys.readouterr().err
    assert code == 2 and named in err and len(err.strip().splitlines()) == 1
    assert not (out / "t.urdf").exists() and not (out / "t.json").exists()


@pytest.mark.parametrize("extra", [["--nominal", "x.urdf"], ["--fixed-registration"],
                                   ["--temperature-column", "t"]])
def test_evaluate_refuses_what_a_tree_does_not_take_yet(files, capsys, extra):
    folder, *_, out, report, _, _, held_out = files
    assert main(["evaluate", str(out), str(report), str(held_out), *extra]) == 2
    err = capsys.readouterr().err
    assert extra[0] in err and "several --tip-link" in err and len(err.strip().splitlines()) == 1



@pytest.mark.parametrize("extra, named", [(["--pause-s", "60"], "--pause-s"),
                                          (["--intrinsics", "camera_info.yaml"], "--intrinsics"),
                                          (["--board-link", "board"], "--board-link")])
@pytest.mark.parametrize("targets", [TARGETS, TARGETS[:2]], ids=["several", "one"])
def test_diagnose_refuses_what_it_would_ignore(files, capsys, extra, named, targets):
    """diagnose runs no differently for a flag it does not use: each is refused in one line, nothing written
    (a pause length with several targets, whose search has no pause steps; a camera's flags without
    --camera-link, with one target or several)."""
    folder, urdf, data, *_ = files
    if named == "--pause-s" and targets is not TARGETS:
        pytest.skip("one chain takes --pause-s")
    out = folder / f"refused_{named.strip('-')}_{len(targets)}"
    code = main(["diagnose", str(urdf), str(data), *targets, *extra, "--out", str(out / "t.urdf"),
                 "--report", str(out / "t.json"), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and named in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


MIMIC = '<mimic joint="arm_left_3" multiplier="0.5" offset="0.1"/>'


@pytest.fixture(scope="module")
def mimic_files(tmp_path_factory):
    """The robot with arm_left_4 following arm_left_3 (x0.5, +0.1), 30 noise-free rows of a perturbed one without
    arm_left_4's column, and the same rows with a column for it that is wrong on line 4."""
    folder = tmp_path_factory.mktemp("tree_mimic")
    text = two_arm_urdf()
    start = text.index('<joint name="arm_left_4"')
    end = text.index("</joint>", start)
    urdf = folder / "robot.urdf"
    urdf.write_text(text[:end] + MIMIC + text[end:], encoding="utf-8")
    tree = KinematicTree.from_urdf(urdf, parse_targets(TARGETS[1::2]))
    params = TreeParameters(tree, "full")
    rng = np.random.default_rng(5)
    q = rng.uniform(-1.2, 1.2, (30, tree.n_joints))
    names = list(tree.joint_names)
    follower, driver = names.index("arm_left_4"), names.index("arm_left_3")
    q[:, follower] = 0.5 * q[:, driver] + 0.1
    with tree.placed(params.placements(rng.normal(0.0, 1e-3, params.size))):
        sensed = tree.target_points(q, LOCAL) + np.array([0.3, -0.1, 0.2])
    without, wrong = folder / "without.csv", folder / "wrong.csv"
    keep = [i for i in range(len(names)) if i != follower]
    _write_rows(without, [names[i] for i in keep], q[:, keep], sensed)
    bad = q.copy()
    bad[2, follower] += 0.01
    _write_rows(wrong, names, bad, sensed)
    return folder, urdf, without, wrong, tree


def test_several_targets_follow_a_mimic_joint_without_its_column(mimic_files):
    folder, urdf, without, _, tree = mimic_files
    assert tree.joint_specs[tree.joint_names.index("arm_left_4")].mimic is not None
    report_path = folder / "REPORT.json"
    assert main(["calibrate", str(urdf), str(without), *TARGETS, "--out", str(folder / "out.urdf"),
                 "--report", str(report_path), "--quiet"]) == 0
    report = json.loads(report_path.read_text(encoding="utf-8"))
    for target in report["targets"]:
        assert target["calibration_errors"]["position"]["max_mm"] < 1e-6  # noise-free rows reproduced
    assert report["chain"]["mimics"] == [{"joint": "arm_left_4", "driver": "arm_left_3", "multiplier": 0.5,
                                          "offset": 0.1}]


def test_several_targets_refuse_a_column_that_does_not_follow_its_mimic(mimic_files, capsys):
    folder, urdf, _, wrong, _ = mimic_files
    assert main(["calibrate", str(urdf), str(wrong), *TARGETS, "--out", str(folder / "w.urdf"),
                 "--report", str(folder / "w.json"), "--quiet"]) == 2
    assert "wrong.csv: line 4, column 'arm_left_4'" in capsys.readouterr().err
    assert not (folder / "w.urdf").exists()


def _robot(folder, seed, n_rows):
    """The two-arm robot's URDF written to ``folder``, its tree of TARGETS, its full parameters, a generator of
    ``seed`` and ``n_rows`` joint readings drawn from it."""
    urdf = folder / "robot.urdf"
    urdf.write_text(two_arm_urdf(), encoding="utf-8")
    tree = KinematicTree.from_urdf(urdf, parse_targets(TARGETS[1::2]))
    rng = np.random.default_rng(seed)
    return urdf, tree, TreeParameters(tree, "full"), rng, rng.uniform(-1.2, 1.2, (n_rows, tree.n_joints))


COUPLINGS = ["--coupling", "arm_left_4=0.5*arm_left_3", "--coupling", "arm_right_3=-1*arm_right_2"]


@pytest.fixture(scope="module")
def coupled_files(tmp_path_factory):
    """30 noise-free rows of a perturbed two-arm robot whose arm_left_4 turns at 0.5 x arm_left_3 (no column for
    it) and whose arm_right_3 is read against arm_right_2 (its reading q3 - q2), calibrated with --coupling."""
    folder = tmp_path_factory.mktemp("tree_coupling")
    urdf, tree, params, rng, q = _robot(folder, 7, 30)
    names = list(tree.joint_names)
    q[:, names.index("arm_left_4")] = 0.5 * q[:, names.index("arm_left_3")]
    with tree.placed(params.placements(rng.normal(0.0, 1e-3, params.size))):
        sensed = tree.target_points(q, LOCAL) + np.array([0.3, -0.1, 0.2])
    readings = q.copy()
    readings[:, names.index("arm_right_3")] -= q[:, names.index("arm_right_2")]
    keep = [i for i, name in enumerate(names) if name != "arm_left_4"]
    data = folder / "coupled.csv"
    _write_rows(data, [names[i] for i in keep], readings[:, keep], sensed)
    out, report = folder / "out.urdf", folder / "REPORT.json"
    code = main(["calibrate", str(urdf), str(data), *TARGETS, *COUPLINGS, "--out", str(out), "--report", str(report),
                 "--quiet"])
    return folder, urdf, data, out, report, code


def test_several_targets_honour_coupling_without_a_column_and_read_against_a_driver(coupled_files, capsys):
    """--coupling with several targets means what it means with one: a joint without a column follows its driver
    (eq M1), a reading taken against another joint is corrected (eq C1); the report and effects.yaml record them,
    evaluate applies them to its rows."""
    folder, urdf, data, out, report_path, code = coupled_files
    assert code == 0
    report = json.loads(report_path.read_text(encoding="utf-8"))
    for target in report["targets"]:
        assert target["calibration_errors"]["position"]["max_mm"] < 1e-6  # noise-free rows reproduced
    assert report["couplings"] == [{"joint": "arm_left_4", "factor": 0.5, "driver": "arm_left_3", "follows": True},
                                   {"joint": "arm_right_3", "factor": -1.0, "driver": "arm_right_2"}]
    assert {"joint": "arm_left_4", "driver": "arm_left_3", "multiplier": 0.5, "offset": 0.0} in report["chain"]["mimics"]
    assert (folder / "out.effects.yaml").exists()
    capsys.readouterr()
    assert main(["evaluate", str(out), str(report_path), str(data), "--max-pos-mm", "1e-6"]) == 0
    assert "readings corrected as" in capsys.readouterr().err
    assert main(["calibrate", str(urdf), str(data), *TARGETS, "--out", str(folder / "no.urdf"),
                 "--report", str(folder / "no.json"), "--quiet"]) == 2  # without it: arm_left_4 has no column
    assert "arm_left_4" in capsys.readouterr().err and not (folder / "no.urdf").exists()


def test_diagnose_claims_nothing_on_rows_the_geometry_reproduces_below_any_sensor(coupled_files, capsys):
    """The same noise-free rows: the calibrated geometry reproduces every one to within about 1e-10 m, far below the
    1e-8 m an effect could be told by (pincal.diagnosis.reproduction.REPRODUCED: a tenth of the 0.1 µm no sensor
    resolves). Judged in a noise estimate that is rounding, a sensor scale — nearly the geometry's lengths — once
    improved that by a third and was adopted at -0.2 % (ΔBIC -63); now no effect is claimed and a note says why."""
    folder, urdf, data, *_ = coupled_files
    report = folder / "diagnosed.json"
    assert main(["diagnose", str(urdf), str(data), *TARGETS, *COUPLINGS, "--out", str(folder / "diagnosed.urdf"),
                 "--report", str(report), "--quiet"]) == 0
    doc = json.loads(report.read_text(encoding="utf-8"))
    assert doc["effects"] == [] and doc["diagnosis"]["steps"] == []
    assert any(note.startswith("the geometry reproduces every row to within ") and note.endswith(
        "below the 1e-08 m (rad) an effect would have to change to be told: no further effect is sought")
        for note in doc["notes"])
    capsys.readouterr()


def test_plan_with_several_targets_honours_coupling(coupled_files, capsys):
    """plan --coupling with several targets: the recorded rows corrected and the joint without a column following
    its driver, as a URDF <mimic> and corrected readings would give (the same plan), PLAN.csv in the controller's
    readings (arm_right_3 read against arm_right_2) without a column for the follower."""
    folder, urdf, data, *_ = coupled_files
    text = two_arm_urdf()
    end = text.index("</joint>", text.index('<joint name="arm_left_4"'))
    mimic = folder / "mimic.urdf"
    mimic.write_text(text[:end] + '<mimic joint="arm_left_3" multiplier="0.5"/>' + text[end:], encoding="utf-8")
    rows = list(csv.DictReader(data.read_text(encoding="utf-8").splitlines()))
    corrected = folder / "corrected.csv"  # the actual angles: arm_right_3's reading plus arm_right_2's
    with open(corrected, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows({**row, "arm_right_3": repr(float(row["arm_right_3"]) + float(row["arm_right_2"]))}
                         for row in rows)
    common = [*TARGETS, "--count", "3", "--sample", "60", "--quiet"]
    assert main(["plan", str(urdf), "--existing", str(data), *COUPLINGS, *common,
                 "--out", str(folder / "c.csv"), "--report", str(folder / "c.json")]) == 0
    assert main(["plan", str(mimic), "--existing", str(corrected), *common,
                 "--out", str(folder / "p.csv"), "--report", str(folder / "p.json")]) == 0
    coupled, plain = (json.loads((folder / f"{n}.json").read_text(encoding="utf-8")) for n in ("c", "p"))
    assert coupled["sources"]["couplings"][0] == {"joint": "arm_left_4", "factor": 0.5, "driver": "arm_left_3",
                                                  "follows": True}
    for key in ("mean_position_mm", "max_position_mm", "condition"):  # the recorded rows read alike
        assert coupled["predicted"]["recorded_only"][key] == pytest.approx(plain["predicted"]["recorded_only"][key],
                                                                           rel=1e-9)
    c_rows, p_rows = (list(csv.DictReader((folder / f"{n}.csv").read_text(encoding="utf-8").splitlines()))
                      for n in ("c", "p"))
    assert "arm_left_4" not in c_rows[0] and [r["candidate"] for r in c_rows] == [r["candidate"] for r in p_rows]
    for c_row, p_row in zip(c_rows, p_rows):
        assert float(c_row["arm_right_3"]) == pytest.approx(float(p_row["arm_right_3"]) - float(p_row["arm_right_2"]))
    capsys.readouterr()


def test_level_auto_with_several_targets_chooses_by_cross_validation(tmp_path, capsys):
    """calibrate --level auto with several targets: the tree's levels cross-validated (two sessions, each held out
    and registered anew), the level chosen printed and in REPORT.json (level_choice), the fit at it."""
    urdf, tree, params, rng, q = _robot(tmp_path, 4, 24)
    with tree.placed(params.placements(rng.normal(0.0, 2e-3, params.size))):  # every placement off by ~2 mm, mrad
        sensed = tree.target_points(q, LOCAL) + np.array([0.3, -0.1, 0.2])
    rows = tmp_path / "rows.csv"
    _write_rows(rows, tree.joint_names, q, sensed + rng.normal(0.0, 1e-4, sensed.shape))
    lines = rows.read_text(encoding="utf-8").splitlines()
    data = tmp_path / "two_sessions.csv"
    data.write_text("\n".join([lines[0] + ",session", *(f"{line},{'ab'[k // 12]}" for k, line in enumerate(lines[1:]))])
                    + "\n", encoding="utf-8")
    report_path = tmp_path / "REPORT.json"
    assert main(["calibrate", str(urdf), str(data), *TARGETS, "--level", "auto", "--select", "all", "--out",
                 str(tmp_path / "out.urdf"), "--report", str(report_path), "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "level auto: leave-one-session-out, 2 folds" in printed and "chosen: full" in printed
    report = json.loads(report_path.read_text(encoding="utf-8"))
    choice = report["level_choice"]
    assert report["level"] == choice["chosen"] == "full" and [s["level"] for s in choice["levels"]] == [
        "registration", "offsets", "full"]
    assert choice["levels"][2]["cv_error_mm"] < 0.5 < choice["levels"][1]["cv_error_mm"]  # 0.1 mm noise per axis
    assert "(level full, chosen by " in (tmp_path / "out.urdf").read_text(encoding="utf-8")  # its comment says how


def test_a_gross_misfit_withholds_the_urdf_unless_forced(files, capsys):
    folder, urdf, data, *_ = files
    rows = list(csv.reader(data.read_text(encoding="utf-8").splitlines()))
    rng = np.random.default_rng(11)
    scrambled = folder / "scrambled.csv"  # points of no robot: uniform in a 0.6 m cube
    with open(scrambled, "w", newline="") as handle:
        csv.writer(handle).writerows([rows[0], *([*row[:-9], *(repr(float(v)) for v in rng.uniform(-0.3, 0.3, 9))]
                                                 for row in rows[1:])])
    out, report_path = folder / "gross.urdf", folder / "gross.json"
    out.write_text("an earlier run's", encoding="utf-8")
    command = ["calibrate", str(urdf), str(scrambled), *TARGETS, "--level", "registration", "--out", str(out),
               "--report", str(report_path), "--quiet"]
    assert main(command) == 3
    assert "pincal: warning: the calibrated model misses the measured points by" in capsys.readouterr().err
    report = json.loads(report_path.read_text(encoding="utf-8"))
    assert [w["code"] for w in report["warnings"]] == ["residual", "gross_misfit"]  # one chain's two findings
    assert report["sources"]["corrected_urdf_withheld"] is True and not out.exists()
    assert main([*command, "--force"]) == 0 and out.exists()
    assert "written all the same (--force)" in json.loads(report_path.read_text(encoding="utf-8"))["warnings"][-1][
        "message"]
    assert main([*command, "--force", "--strict"]) == 3  # a warning with --strict


def test_sigma_pos_judges_the_residual_of_several_targets(files, capsys):
    """--sigma-pos with several targets: the residual per axis beyond 20x the stated noise is the noise warning
    (--strict: exit 3), beyond 3x a note naming the diagnose command of these targets; within it, neither."""
    folder, urdf, data, *_ = files
    command = ["calibrate", str(urdf), str(data), *TARGETS, "--level", "offsets", "--out", str(folder / "s.urdf"),
               "--report", str(folder / "s.json"), "--quiet", "--strict", "--sigma-pos"]
    assert main([*command, "0.001"]) == 3  # the offsets leave the placements' ~1 mm errors: far beyond 1 µm
    report = json.loads((folder / "s.json").read_text(encoding="utf-8"))
    assert [w["code"] for w in report["warnings"]] == ["noise"]
    assert any("pincal diagnose" in n and "--tip-link left_marker:1 --tip-link right_marker:2,3" in n
               for n in report["notes"])
    assert main([*command, "10"]) == 0  # 10 mm per axis: within it
    report = json.loads((folder / "s.json").read_text(encoding="utf-8"))
    assert report["warnings"] == [] and not any("pincal diagnose" in n for n in report["notes"])
    capsys.readouterr()


def test_reject_outliers_with_several_targets_removes_a_bad_row_and_refits(files):
    """--reject-outliers with several targets: in rows with 0.1 mm of noise, one whose point 2 is 30 mm off (a
    swapped marker) is flagged by its RMS point error as with one chain, removed, and the rest refitted to the
    noise."""
    folder, urdf, data, *_ = files
    header, *lines = data.read_text(encoding="utf-8").splitlines()
    rng, first = np.random.default_rng(8), header.split(",").index("x1")
    rows = []
    for k, line in enumerate(lines):
        cells = line.split(",")
        cells[first:] = [c and repr(float(c) + rng.normal(0.0, 1e-4) + (0.03 if (k, i) == (7, 3) else 0.0))
                         for i, c in enumerate(cells[first:])]  # x2 of line 9: 30 mm off
        rows.append(",".join(cells))
    bad = folder / "one_bad_row.csv"
    bad.write_text("\n".join([header, *rows]) + "\n", encoding="utf-8")
    report_path = folder / "rejected.json"
    assert main(["calibrate", str(urdf), str(bad), *TARGETS, "--select", "all", "--reject-outliers", "--out",
                 str(folder / "rejected.urdf"), "--report", str(report_path), "--quiet"]) == 0
    report = json.loads(report_path.read_text(encoding="utf-8"))
    # the 30 mm pull the fit spread to line 27 (2.4 mm there, robust score 6.7) flags it too, as with one chain
    assert "removed 2 outlier row(s) at lines [9, 27] and refitted" in report["notes"]
    assert report["sessions"][0]["rows"] == 38
    for target in report["targets"]:
        assert target["calibration_errors"]["position"]["rms_mm"] < 0.2  # the others' noise: 0.17 mm per point


def test_one_tip_link_with_points_says_it_takes_a_link_only(files, capsys):
    folder, urdf, data, *_ = files
    code = main(["calibrate", str(urdf), str(data), "--tip-link", "left_marker:1", "--out", str(folder / "p.urdf"),
                 "--report", str(folder / "p.json")])
    assert code == 2
    assert "a single --tip-link takes LINK only (LINK:POINTS is for several --tip-link): --tip-link left_marker" in \
        capsys.readouterr().err


def test_validation_rows_are_left_out_of_the_fit_with_a_note(files, tmp_path):
    """Rows with role 'validation' are not calibrated on; the report says how many and how to judge them."""
    folder, urdf, data, *_ = files
    lines = data.read_text().splitlines()
    rows = [lines[0] + ",role"] + [f"{line},{'validation' if k >= 35 else ''}" for k, line in enumerate(lines[1:])]
    split = tmp_path / "split.csv"
    split.write_text("\n".join(rows) + "\n")
    out, report = tmp_path / "out.urdf", tmp_path / "REPORT.json"
    assert main(["calibrate", str(urdf), str(split), *TARGETS, "--select", "all", "--out", str(out),
                 "--report", str(report), "--quiet"]) == 0
    document = json.loads(report.read_text())
    assert [s["rows"] for s in document["sessions"]] == [35]
    assert any(note.startswith("5 row(s) with role 'validation' are not in the fit") for note in document["notes"])
