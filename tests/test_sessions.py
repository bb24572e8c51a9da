"""Several sessions in one calibration: one registration per session, one model and one target.

Noise-free simulated sessions of a UR5 (example-robot-data), each seen by a sensor
placed elsewhere. Bounds: the Jacobian against central differences (step 1e-6,
as tests/test_effects.py); recovery to 1e-9 because the data are noise-free —
the model reproduces them exactly, so what is left is the solver's stopping
tolerance and rounding (measured: ~1e-15 m).
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest
from conftest import assert_close, numeric_jacobian
from scipy.spatial.transform import Rotation

from pincal.cli.commands import main
from pincal.errors import CalibrationError
from pincal.fit.chain_calibration import calibrate_chain
from pincal.fit.metrics import RowCorrections, pose_errors
from pincal.fit.sessions import initial_target, register_session, session_pose_errors
from pincal.measurements.csv_v1 import (
    read_measurements,
    read_sessions,
    write_measurements,
)
from pincal.measurements.data import join_sets
from pincal.model.chain import KinematicChain
from pincal.model.parameter_sets import JointOffsets, PlacementErrors
from pincal.model.sensor import Registration
from pincal.model.thermal import RowConditions
from pincal.residuals.base import KinematicsCache
from pincal.residuals.sensor import SensorResidual, TargetEstimate
from pincal.residuals.sensor_values import RowWeights
from pincal.robots import example_robot_data_urdf
from pincal.simulation.sensor import SimulatedSensor, measure, random_configurations
from pincal.workflows.evaluation import REESTIMATED, SessionEvaluation

URDF = example_robot_data_urdf("ur_description/urdf/ur5_robot.urdf")
TIP = "tool0"
POINT = np.array([[0.03, -0.02, 0.08]])  # the target in tool0 [m]
#: Noise-free data: the bound is the solver's tolerance and rounding, not noise (measured ~1e-15 m).
EXACT = 1e-9
#: Three sensor placements (sensor_T_base), and a fourth the fit never sees.
PLACEMENTS = {
    name: Registration(Rotation.from_euler("ZYX", angles, degrees=True).as_matrix(), np.array(shift))
    for name, angles, shift in (
        ("A", [35, -12, 8], [1.85, -0.62, 0.43]),
        ("B", [-80, 5, -3], [0.2, 1.5, -0.1]),
        ("C", [170, 2, 1], [-1.2, -0.3, 0.6]),
        ("D", [60, 10, -20], [0.9, 0.9, 0.2]),
    )
}


@pytest.fixture(scope="module")
def truth():
    """The true UR5: its URDF with the zeros of joints 2–5 off (joint 1's zero is absorbed by the
    registrations and joint 6's by the target, so every registration is recoverable absolutely)."""
    chain = KinematicChain.from_urdf(URDF, TIP)
    offsets = np.zeros(chain.n_joints)
    offsets[1:5] = [2e-3, -3e-3, 1.5e-3, -2.5e-3]
    JointOffsets(chain).apply(offsets)
    return chain


def _session(truth, name, rows, seed, role="calibration"):
    rng = np.random.default_rng(seed)
    data = measure(truth, random_configurations(truth, rng, rows), PLACEMENTS[name], rng,
                   SimulatedSensor(0.0, 0.0, points=POINT, with_rotation=False), role)
    return replace(data, sessions=np.full(rows, name, dtype=object))


def _registration(entry) -> Registration:
    return Registration.from_dict(entry["registration"]["position"])


def _same(a: Registration, b: Registration) -> float:
    return max(np.abs(a.rotation - b.rotation).max(), np.abs(a.translation - b.translation).max())


# --- the residual -----------------------------------------------------------------------


def test_multi_session_jacobian_matches_finite_differences():
    rng = np.random.default_rng(5)
    chain = KinematicChain.from_urdf(URDF, TIP)
    params = PlacementErrors(chain)
    q = random_configurations(chain, rng, 9)
    cache = KinematicsCache(params, rng.permutation(params.size)[:10], rng.normal(0, 1e-2, params.size), q)
    registrations = tuple(Registration(pin.exp3(rng.normal(size=3)), rng.normal(size=3)) for _ in range(3))
    start = TargetEstimate(registrations[0], rng.normal(0, 0.1, (2, 3)), pin.exp3(rng.normal(size=3)), registrations)
    rotations = np.stack([pin.exp3(rng.normal(size=3)) for _ in q])
    sessions = np.array([0, 1, 2, 0, 1, 2, 2, 1, 0])
    objective = SensorResidual(cache, rng.normal(size=(9, 2, 3)), rotations, start,
                               RowWeights(position=rng.uniform(0.5, 2.0, 9), rotation=2.0), sessions=sessions)
    assert objective.blocks["registration"].stop - objective.blocks["registration"].start == 18
    x = objective.start_vector() + rng.normal(0, 0.05, objective.n_free)
    jac = objective.jacobian(x)
    # central differences, step 1e-6: truncation ~1e-12, rounding ~1e-16 |r| / 1e-6 ≈ 1e-9 (tests/test_effects.py)
    assert_close(jac, numeric_jacobian(objective.residual, x), 1e-6, "several sessions")
    # a row's registration columns are its own session's: zero in the others'
    reg = objective.blocks["registration"].start
    rows = objective.row_indices()
    for k, s in enumerate(sessions):
        for other in {0, 1, 2} - {s}:
            assert not np.any(jac[rows[k]][:, reg + 6 * other : reg + 6 * other + 6])
        assert np.any(jac[rows[k]][:, reg + 6 * s : reg + 6 * s + 6])
    # the noise Jacobian: g_kp → g_kp + zeta, G_k → exp(xi) G_k moves only row k, by its block
    blocks = objective.noise_jacobian(x)
    for k in (1, 6):
        for c in range(blocks.shape[2]):

            def moved(h, k=k, c=c):
                g, turned = objective.g.copy(), rotations.copy()
                if c < 6:
                    g[k, c // 3, c % 3] += h
                else:
                    turned[k] = pin.exp3(h * np.eye(3)[c - 6]) @ turned[k]
                return SensorResidual(cache, g, turned, start, RowWeights(position=objective.w, rotation=2.0),
                                      sessions=sessions).residual(x)

            expected = np.zeros(rows.size)
            expected[rows[k]] = blocks[k][:, c]
            assert_close((moved(1e-6) - moved(-1e-6)) / 2e-6, expected, 1e-6, f"row {k} noise {c}")


def test_one_session_is_the_single_registration_residual():
    rng = np.random.default_rng(2)
    chain = KinematicChain.from_urdf(URDF, TIP)
    params = PlacementErrors(chain)
    q = random_configurations(chain, rng, 6)
    cache = KinematicsCache(params, np.arange(8), np.zeros(params.size), q)
    start = TargetEstimate(Registration(pin.exp3(rng.normal(size=3)), rng.normal(size=3)), POINT, np.eye(3))
    one = SensorResidual(cache, rng.normal(size=(6, 1, 3)), None, start)
    labelled = SensorResidual(cache, one.g, None, start, sessions=np.zeros(6, dtype=int))
    x = one.start_vector() + rng.normal(0, 0.01, one.n_free)
    assert np.array_equal(one.residual(x), labelled.residual(x))
    assert np.array_equal(one.jacobian(x), labelled.jacobian(x))
    with pytest.raises(ValueError, match="session"):
        SensorResidual(cache, one.g, None, replace(start, registrations=(start.registration,) * 2))


# --- the calibration ----------------------------------------------------------------------


def test_noise_free_sessions_recover_the_truth(truth):
    """UR5, full level, three sessions of 15 point rows, each seen from another sensor pose."""
    data = join_sets([_session(truth, name, 15, seed) for seed, name in enumerate("ABC")])
    chain = KinematicChain.from_urdf(URDF, TIP)
    result = calibrate_chain(chain, data, "full")
    assert result.session_names == ("A", "B", "C") and len(result.target.registrations) == 3
    assert result.rms_m < EXACT
    for name, registration in zip("ABC", result.target.registrations):
        held = _session(truth, name, 50, 10 + ord(name), "validation")
        with chain.placed(result.chain_placements):
            errors = session_pose_errors(chain, held, np.zeros(50, dtype=int), [registration],
                                         points=result.target.points)
        assert errors.position_m.max() < EXACT, name
    # the full level leaves the base placement to the registrations; between two sessions it cancels
    truths = [PLACEMENTS[n] for n in "ABC"]
    for a in range(3):
        for b in range(3):
            fitted = _relative(result.target.registrations[a], result.target.registrations[b])
            assert np.abs(fitted - _relative(truths[a], truths[b])).max() < EXACT
    # registration columns are always kept: named per session, never dropped
    names = [name for d in result.dropped for name, _ in d.absorbed_into]
    assert any(n.startswith("registration[B].") for n in names)


def _relative(a: Registration, b: Registration) -> np.ndarray:
    """sensor_a_T_sensor_b as a 4x4 matrix."""
    ta, tb = np.eye(4), np.eye(4)
    ta[:3, :3], ta[:3, 3] = a.rotation, a.translation
    tb[:3, :3], tb[:3, 3] = b.rotation, b.translation
    return ta @ np.linalg.inv(tb)


def test_initial_target_registers_each_session_and_an_unseen_one(truth):
    data = join_sets([_session(truth, name, 8, seed) for seed, name in enumerate("ABC")])
    start = initial_target(truth, data, fit_points=True)
    # a start, not the estimate: 10 alternations of Arun and the points converge linearly (measured 3e-7)
    for name, registration in zip("ABC", start.registrations):
        assert _same(registration, PLACEMENTS[name]) < 1e-5, name
    assert_close(start.points, POINT, 1e-5, "target")
    unseen = _session(truth, "D", 6, 40)
    assert _same(register_session(truth, unseen, POINT, np.eye(3)), PLACEMENTS["D"]) < EXACT


# --- the command line ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def calibrated(truth, tmp_path_factory):
    """calibrate URDF A.csv BC.csv (BC.csv holds sessions B and C in a ``session`` column)."""
    folder = tmp_path_factory.mktemp("sessions")
    write_measurements(folder / "A.csv", _session(truth, "A", 14, 1))
    write_measurements(folder / "BC.csv", join_sets([_session(truth, "B", 12, 2), _session(truth, "C", 12, 3)]))
    write_measurements(folder / "D.csv", _session(truth, "D", 30, 4, "validation"))
    write_measurements(folder / "heldA.csv", _session(truth, "A", 30, 5, "validation"))
    code = main(["calibrate", str(URDF), str(folder / "A.csv"), str(folder / "BC.csv"), "--tip-link", TIP,
                 "--level", "offsets", "--out", str(folder / "ur5.urdf"), "--report", str(folder / "REPORT.json")])
    assert code == 0
    return folder, json.loads((folder / "REPORT.json").read_text())


def test_cli_calibrates_files_and_session_column_with_one_registration_each(calibrated, capsys):
    folder, report = calibrated
    sessions = report["sessions"]
    assert [s["name"] for s in sessions] == ["A", "BC:B", "BC:C"]
    assert [s["rows"] for s in sessions] == [14, 12, 12]
    assert [s["file"] for s in sessions] == [str(folder / "A.csv"), str(folder / "BC.csv"), str(folder / "BC.csv")]
    for entry, name in zip(sessions, "ABC"):
        assert _same(_registration(entry), PLACEMENTS[name]) < EXACT, name
        assert entry["calibration_errors"]["position"]["max_mm"] < EXACT * 1000
    assert report["registration"] == sessions[0]["registration"]  # the first session's
    assert report["sources"]["data"] == [str(folder / "A.csv"), str(folder / "BC.csv")]
    offsets = {p["joint"]: p["calibrated"] for p in report["parameters"]}
    assert offsets["elbow_joint"] == pytest.approx(-3e-3, abs=EXACT)


def test_cli_prints_each_sessions_registration_and_errors(truth, tmp_path, capsys):
    write_measurements(tmp_path / "A.csv", _session(truth, "A", 10, 1))
    write_measurements(tmp_path / "B.csv", _session(truth, "B", 10, 2))
    assert main(["calibrate", str(URDF), str(tmp_path / "A.csv"), str(tmp_path / "B.csv"), "--tip-link", TIP,
                 "--level", "registration", "--out", str(tmp_path / "c.urdf"),
                 "--report", str(tmp_path / "R.json")]) == 0
    out = capsys.readouterr().out
    assert f"session B (fitted on {tmp_path / 'B.csv'}, 10 rows): registration translation (" in out
    assert "  session A " in out and "  session B " in out


def test_cli_evaluate_reestimates_an_unseen_sessions_registration(calibrated, capsys):
    folder, _ = calibrated
    capsys.readouterr()
    args = ["evaluate", str(folder / "ur5.urdf"), str(folder / "REPORT.json")]
    assert main([*args, str(folder / "D.csv"), "--json", str(folder / "D.json")]) == 0
    out = capsys.readouterr().out
    assert "session D (30 rows): registration: re-estimated on these rows (6 parameters" in out
    evaluation = json.loads((folder / "D.json").read_text())
    (session,) = evaluation["sessions"]
    assert session["registration_reestimated"] and session["name"] == "D"
    assert _same(_registration(session), PLACEMENTS["D"]) < EXACT
    assert evaluation["position"]["max_mm"] < EXACT * 1000
    # several sessions in the report: a file of session A's rows is still a session the fit has not seen
    assert main([*args, str(folder / "heldA.csv"), "--json", str(folder / "heldA.json")]) == 0
    assert json.loads((folder / "heldA.json").read_text())["sessions"][0]["registration_reestimated"]


def test_cli_evaluate_fixed_registration_reuses_a_reported_one(calibrated, capsys):
    folder, _ = calibrated
    args = ["evaluate", str(folder / "ur5.urdf"), str(folder / "REPORT.json")]
    assert main([*args, str(folder / "heldA.csv"), "--fixed-registration", "--json", str(folder / "f.json")]) == 0
    fixed = json.loads((folder / "f.json").read_text())
    assert fixed["sessions"][0]["registration_source"] == "reported session 'A'"
    assert fixed["position"]["max_mm"] < EXACT * 1000  # A's own registration fits A's rows
    assert main([*args, str(folder / "D.csv"), "--fixed-registration", "BC:C", "--json", str(folder / "g.json")]) == 0
    wrong = json.loads((folder / "g.json").read_text())
    assert wrong["sessions"][0]["registration_source"] == "reported session 'BC:C'"
    assert wrong["position"]["mean_mm"] > 100.0  # D's rows seen through C's sensor pose: metres off
    # rows naming a reported session in a ``session`` column use its registration
    labelled, _ = read_measurements(folder / "heldA.csv", KinematicChain.from_urdf(URDF, TIP).joint_specs)
    both = join_sets([replace(labelled, sessions=np.full(30, "A", dtype=object)),
                      replace(_session_like(folder, "D.csv"), sessions=np.full(30, "new", dtype=object))])
    write_measurements(folder / "mixed.csv", both)
    assert main([*args, str(folder / "mixed.csv"), "--json", str(folder / "m.json")]) == 0
    mixed = json.loads((folder / "m.json").read_text())
    assert [(s["name"], s["registration_reestimated"]) for s in mixed["sessions"]] == [("A", False), ("new", True)]
    assert mixed["position"]["max_mm"] < EXACT * 1000


def _session_like(folder, name):
    data, _ = read_measurements(folder / name, KinematicChain.from_urdf(URDF, TIP).joint_specs)
    return data


def test_one_session_report_evaluates_as_before_unless_new_session(truth, tmp_path, capsys):
    write_measurements(tmp_path / "cal.csv", _session(truth, "A", 14, 1))
    write_measurements(tmp_path / "held.csv", _session(truth, "A", 20, 2, "validation"))
    write_measurements(tmp_path / "moved.csv", _session(truth, "D", 20, 3, "validation"))
    assert main(["calibrate", str(URDF), str(tmp_path / "cal.csv"), "--tip-link", TIP, "--level", "offsets",
                 "--out", str(tmp_path / "c.urdf"), "--report", str(tmp_path / "R.json")]) == 0
    report = json.loads((tmp_path / "R.json").read_text())
    assert [s["name"] for s in report["sessions"]] == ["cal"]
    assert report["sessions"][0]["registration"] == report["registration"]
    args = ["evaluate", str(tmp_path / "c.urdf"), str(tmp_path / "R.json")]
    assert main([*args, str(tmp_path / "held.csv"), "--json", str(tmp_path / "h.json")]) == 0
    held = json.loads((tmp_path / "h.json").read_text())
    assert held["sessions"][0]["registration_source"] == "reported session 'cal'"
    assert held["position"]["max_mm"] < EXACT * 1000
    assert main([*args, str(tmp_path / "moved.csv"), "--json", str(tmp_path / "m.json")]) == 0
    assert json.loads((tmp_path / "m.json").read_text())["position"]["mean_mm"] > 100.0
    assert main([*args, str(tmp_path / "moved.csv"), "--new-session", "--json", str(tmp_path / "n.json")]) == 0
    moved = json.loads((tmp_path / "n.json").read_text())
    assert moved["sessions"][0]["registration_reestimated"] and moved["position"]["max_mm"] < EXACT * 1000


def test_outliers_are_reported_by_file_and_line(truth, tmp_path):
    write_measurements(tmp_path / "A.csv", _session(truth, "A", 14, 1))
    bad = _session(truth, "B", 14, 2)
    points = bad.points.copy()
    points[5, 0, 0] += 0.02  # 20 mm off, far above the noise-free rows
    write_measurements(tmp_path / "B.csv", replace(bad, points=points))
    assert main(["calibrate", str(URDF), str(tmp_path / "A.csv"), str(tmp_path / "B.csv"), "--tip-link", TIP,
                 "--level", "offsets", "--select", "aic", "--out", str(tmp_path / "c.urdf"), "--report", str(tmp_path / "R.json")]) == 0
    report = json.loads((tmp_path / "R.json").read_text())
    assert [(o["file"], o["line"], o["by"]) for o in report["outliers"]] == [(str(tmp_path / "B.csv"), 7, "position")]


# --- the reader ---------------------------------------------------------------------------


def test_session_column_and_several_files_label_rows(truth, tmp_path):
    joints = truth.joint_specs
    day1, day2 = _session(truth, "A", 4, 1), _session(truth, "B", 3, 2)
    data = join_sets([replace(day1, sessions=np.full(4, "day1", dtype=object)),
                      replace(day2, sessions=np.full(3, "day2", dtype=object))])
    write_measurements(tmp_path / "S.csv", data)
    assert "session" in (tmp_path / "S.csv").read_text().splitlines()[0].split(",")
    back, _ = read_measurements(tmp_path / "S.csv", joints)
    assert back.session_names == ("day1", "day2") and back.sessions.tolist() == ["day1"] * 4 + ["day2"] * 3
    text = (tmp_path / "S.csv").read_text().replace(",day2", ",")  # an empty cell: the file's own session
    (tmp_path / "T.csv").write_text(text)
    partly, _ = read_measurements(tmp_path / "T.csv", joints)
    assert partly.session_names == ("day1", "T")
    write_measurements(tmp_path / "U.csv", _session(truth, "C", 2, 3))
    assert "session" not in (tmp_path / "U.csv").read_text().splitlines()[0]  # one session: no column
    both, _ = read_sessions([tmp_path / "S.csv", tmp_path / "U.csv"], joints)
    assert both.session_names == ("S:day1", "S:day2", "U")
    assert both.files.tolist() == [str(tmp_path / "S.csv")] * 7 + [str(tmp_path / "U.csv")] * 2
    assert both.lines.tolist() == [2, 3, 4, 5, 6, 7, 8, 2, 3]


# --- errors that help ---------------------------------------------------------------------------


def _calibrate_error(tmp_path, capsys, *files, extra=()):
    code = main(["calibrate", str(URDF), *map(str, files), "--tip-link", TIP, "--level", "offsets", *extra,
                 "--out", str(tmp_path / "c.urdf"), "--report", str(tmp_path / "R.json")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and err.startswith("pincal: error: "), err
    assert not (tmp_path / "c.urdf").exists()
    return err


def test_sessions_that_cannot_register_get_one_line_naming_file_session_and_remedy(truth, tmp_path, capsys):
    write_measurements(tmp_path / "A.csv", _session(truth, "A", 14, 1))
    write_measurements(tmp_path / "B.csv", _session(truth, "B", 2, 2))
    err = _calibrate_error(tmp_path, capsys, tmp_path / "A.csv", tmp_path / "B.csv")
    assert f"{tmp_path / 'B.csv'}, session 'B': 2 row(s) with 2 measured point(s)" in err
    assert "needs 3 or more points not on one line" in err and "add rows" in err
    # a fixture's socket measured in every row: one point
    socket = _session(truth, "B", 10, 3)
    write_measurements(tmp_path / "S.csv", replace(socket, points=np.broadcast_to([[0.5, 0.2, 0.1]], (10, 1, 3))))
    err = _calibrate_error(tmp_path, capsys, tmp_path / "A.csv", tmp_path / "S.csv")
    assert f"{tmp_path / 'S.csv'}, session 'S': all 10 measured points coincide" in err
    # its two sockets, 50 mm apart, without the grouping: one line
    sockets = np.where(np.arange(10)[:, None, None] % 2, [[0.5, 0.2, 0.1]], [[0.55, 0.2, 0.1]])
    write_measurements(tmp_path / "L.csv", replace(socket, points=sockets))
    err = _calibrate_error(tmp_path, capsys, tmp_path / "L.csv")
    assert f"{tmp_path / 'L.csv'}: all 10 measured points lie on one line" in err
    assert "two sockets of a fixture" in err and "add rows measuring a point off the line" in err


def test_session_mistakes_are_one_line(truth, tmp_path, capsys):
    write_measurements(tmp_path / "A.csv", _session(truth, "A", 14, 1))
    write_measurements(tmp_path / "P.csv", replace(_session(truth, "B", 14, 2), points=np.zeros((14, 2, 3)) + 0.1))
    err = _calibrate_error(tmp_path, capsys, tmp_path / "A.csv", tmp_path / "P.csv")
    assert "differs from" in err and "target points per row (2 against 1)" in err
    err = _calibrate_error(tmp_path, capsys, tmp_path / "A.csv", tmp_path / "A.csv")
    assert "given twice" in err
    write_measurements(tmp_path / "B.csv", _session(truth, "B", 14, 3))
    err = _calibrate_error(tmp_path, capsys, tmp_path / "A.csv", tmp_path / "B.csv",
                           extra=("--level", "dh", "--tool", "0,0,0,0,0,0"))
    assert "2 sessions (A, B)" in err and "--level dh" in err


def test_evaluate_session_mistakes_are_one_line(calibrated, truth, tmp_path, capsys):
    folder, _ = calibrated
    args = ["evaluate", str(folder / "ur5.urdf"), str(folder / "REPORT.json")]
    capsys.readouterr()
    assert main([*args, str(folder / "D.csv"), "--fixed-registration", "Z"]) == 2
    err = capsys.readouterr().err
    assert "--fixed-registration Z" in err and "its sessions are: A, BC:B, BC:C" in err and err.count("\n") == 1
    write_measurements(tmp_path / "few.csv", _session(truth, "D", 2, 9, "validation"))
    assert main([*args, str(tmp_path / "few.csv")]) == 2
    err = capsys.readouterr().err
    assert f"{tmp_path / 'few.csv'}: 2 row(s) with 2 measured point(s)" in err and err.count("\n") == 1


def test_diagnose_held_out_rows_need_a_known_session(truth, tmp_path, capsys):
    write_measurements(tmp_path / "A.csv", _session(truth, "A", 14, 1))
    write_measurements(tmp_path / "B.csv", _session(truth, "B", 14, 2))
    write_measurements(tmp_path / "H.csv", _session(truth, "B", 10, 3, "validation"))
    code = main(["diagnose", str(URDF), str(tmp_path / "A.csv"), str(tmp_path / "B.csv"), "--tip-link", TIP,
                 "--level", "offsets", "--validation", str(tmp_path / "H.csv"), "--out", str(tmp_path / "c.urdf"),
                 "--report", str(tmp_path / "R.json"), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1
    assert f"{tmp_path / 'H.csv'}: not one of the calibrated sessions (A, B)" in err and "'session' column" in err


def test_registration_problems_of_data_in_memory_still_say_what_to_add(truth):
    data = _session(truth, "A", 2, 1)  # four rows, two distinct points: a line
    with pytest.raises(CalibrationError, match=r"<simulation>, session 'A': all 4 measured points lie on one line"):
        calibrate_chain(KinematicChain.from_urdf(URDF, TIP), join_sets([data, data]), "offsets")


# --- diagnose and plan take several sessions ------------------------------------------------------


def test_diagnose_takes_several_sessions(truth, tmp_path, capsys):
    write_measurements(tmp_path / "A.csv", _session(truth, "A", 14, 1))
    write_measurements(tmp_path / "B.csv", _session(truth, "B", 14, 2))
    assert main(["diagnose", str(URDF), str(tmp_path / "A.csv"), str(tmp_path / "B.csv"), "--tip-link", TIP,
                 "--level", "offsets", "--out", str(tmp_path / "c.urdf"), "--report", str(tmp_path / "R.json"),
                 "--quiet"]) == 0
    report = json.loads((tmp_path / "R.json").read_text())
    assert [s["name"] for s in report["sessions"]] == ["A", "B"]
    for entry, name in zip(report["sessions"], "AB"):
        assert _same(_registration(entry), PLACEMENTS[name]) < EXACT, name
    assert report["diagnosis"]["calibration_errors"]["position"]["max_mm"] < EXACT * 1000


def test_plan_existing_sessions_each_cost_a_registration(truth, tmp_path, capsys):
    """The same rows as two sessions (two registrations) or one: 6 more unknowns, never a better prediction."""
    first, second = _session(truth, "A", 10, 1), _session(truth, "A", 10, 2)
    write_measurements(tmp_path / "A1.csv", first)
    write_measurements(tmp_path / "A2.csv", second)
    write_measurements(tmp_path / "A12.csv", join_sets([first, second]))
    documents = []
    for existing in (["A1.csv", "A2.csv"], ["A12.csv"]):
        out = tmp_path / f"P{len(existing)}"
        assert main(["plan", str(URDF), "--tip-link", TIP, "--level", "offsets", "--count", "3", "--sample", "200",
                     "--sigma-pos", "0.1", "--existing", *[str(tmp_path / f) for f in existing],
                     "--out", str(out.with_suffix(".csv")), "--report", str(out.with_suffix(".json")),
                     "--quiet"]) == 0
        documents.append(json.loads(out.with_suffix(".json").read_text()))
    two, one = documents
    assert two["identifiability"]["estimated_parameters"] == one["identifiability"]["estimated_parameters"] + 6
    assert two["sources"]["existing"] == [str(tmp_path / "A1.csv"), str(tmp_path / "A2.csv")]
    # more unknowns from the same rows: the information about the model can only shrink
    recorded = [doc["predicted"]["recorded_only"]["mean_position_mm"] for doc in (two, one)]
    assert recorded[0] >= recorded[1]


# --- review fixes: 6D sessions of one row, the evaluate rule, degrees of freedom, dropped sessions ------------

#: The measured frame in tool0 (6D rows): not the identity, so a registration from orientations must use it.
TARGET_ROTATION = Rotation.from_euler("xyz", [10, -20, 30], degrees=True).as_matrix()


def _session6d(truth, name, rows, seed, role="calibration"):
    rng = np.random.default_rng(seed)
    data = measure(truth, random_configurations(truth, rng, rows), PLACEMENTS[name], rng,
                   SimulatedSensor(0.0, 0.0, points=POINT, target_rotation=TARGET_ROTATION, with_rotation=True), role)
    return replace(data, sessions=np.full(rows, name, dtype=object))


def test_a_6d_session_of_one_row_registers_from_its_orientation(truth, tmp_path, capsys):
    """One 6D row fixes a registration (3 position + 3 orientation residuals for 6 parameters):
    Registration 2 starts it where Arun's 3 points are missing — in calibrate (a session among
    several) and in evaluate (an unseen session). Noise-free: recovered to EXACT."""
    write_measurements(tmp_path / "A.csv", _session6d(truth, "A", 14, 1))
    write_measurements(tmp_path / "B.csv", _session6d(truth, "B", 1, 2))
    write_measurements(tmp_path / "D.csv", _session6d(truth, "D", 1, 3, "validation"))
    assert main(["calibrate", str(URDF), str(tmp_path / "A.csv"), str(tmp_path / "B.csv"), "--tip-link", TIP,
                 "--level", "offsets", "--out", str(tmp_path / "c.urdf"), "--report", str(tmp_path / "R.json"),
                 "--quiet"]) == 0
    report = json.loads((tmp_path / "R.json").read_text())
    assert [(s["name"], s["rows"]) for s in report["sessions"]] == [("A", 14), ("B", 1)]
    for entry, name in zip(report["sessions"], "AB"):
        assert _same(_registration(entry), PLACEMENTS[name]) < EXACT, name
    assert main(["evaluate", str(tmp_path / "c.urdf"), str(tmp_path / "R.json"), str(tmp_path / "D.csv"),
                 "--json", str(tmp_path / "D.json")]) == 0
    (session,) = json.loads((tmp_path / "D.json").read_text())["sessions"]
    assert session["registration_reestimated"] and (session["residuals"], session["registration_dof"]) == (6, 0)
    assert _same(_registration(session), PLACEMENTS["D"]) < EXACT
    # the library alone: the alternation's fixed point is the truth on noise-free rows (it converges
    # linearly: after 100 alternations, measured 4e-16)
    start = initial_target(truth, join_sets([_session6d(truth, "A", 6, 4), _session6d(truth, "B", 1, 5)]), True, 100)
    assert _same(start.registrations[1], PLACEMENTS["B"]) < EXACT
    assert _same(register_session(truth, _session6d(truth, "D", 1, 6), POINT, TARGET_ROTATION), PLACEMENTS["D"]) < EXACT


def test_one_session_report_keeps_its_registration_for_a_session_column(truth, tmp_path, capsys):
    """A ``session`` column (text, or a number: it used to be a kept extra column) does not make a
    one-session report re-estimate: as before, its registration is used, and a note says so."""
    write_measurements(tmp_path / "cal.csv", _session(truth, "A", 14, 1))
    held = _session(truth, "A", 20, 2, "validation")
    write_measurements(tmp_path / "plain.csv", held)
    assert main(["calibrate", str(URDF), str(tmp_path / "cal.csv"), "--tip-link", TIP, "--level", "offsets",
                 "--out", str(tmp_path / "c.urdf"), "--report", str(tmp_path / "R.json"), "--quiet"]) == 0
    args = ["evaluate", str(tmp_path / "c.urdf"), str(tmp_path / "R.json")]
    assert main([*args, str(tmp_path / "plain.csv"), "--json", str(tmp_path / "plain.json")]) == 0
    plain = json.loads((tmp_path / "plain.json").read_text())
    for label in ("day2", "7"):
        write_measurements(tmp_path / "labelled.csv", join_sets([replace(held, sessions=np.full(20, label, dtype=object)),
                                                                 _session(truth, "A", 1, 3, "cpa")]))
        capsys.readouterr()
        assert main([*args, str(tmp_path / "labelled.csv"), "--json", str(tmp_path / "l.json")]) == 0
        err = capsys.readouterr().err
        assert f"session(s) '{label}' evaluated through reported session 'cal'" in err and "--new-session" in err
        labelled = json.loads((tmp_path / "l.json").read_text())
        assert labelled["sessions"][0]["registration_source"] == "reported session 'cal'"
        assert labelled["position"] == plain["position"]  # the same rows, the same numbers
    assert main([*args, str(tmp_path / "labelled.csv"), "--new-session", "--json", str(tmp_path / "n.json")]) == 0
    assert json.loads((tmp_path / "n.json").read_text())["sessions"][0]["registration_reestimated"]


def test_a_file_named_like_a_session_is_not_that_session(calibrated, truth, tmp_path, monkeypatch):
    """Several sessions: the report's session matches only the file it was read from, or a ``session``
    cell naming it in full — never a file's stem alone."""
    folder, _ = calibrated
    args = ["evaluate", str(folder / "ur5.urdf"), str(folder / "REPORT.json")]

    def sources(path):
        assert main([*args, str(path), "--json", str(tmp_path / "e.json")]) == 0
        return [(s["name"], s["registration_source"]) for s in json.loads((tmp_path / "e.json").read_text())["sessions"]]

    (tmp_path / "val").mkdir()
    write_measurements(tmp_path / "val" / "A.csv", _session(truth, "A", 10, 7, "validation"))
    assert sources(tmp_path / "val" / "A.csv") == [("A", REESTIMATED)]  # stem A, another file: unseen
    assert sources(folder / "A.csv") == [("A", "reported session 'A'")]  # the file session A was read from
    monkeypatch.chdir(folder)  # the same file by a relative path
    assert sources("BC.csv") == [("B", "reported session 'BC:B'"), ("C", "reported session 'BC:C'")]
    named = join_sets([_session(truth, "A", 10, 8, "validation"), _session(truth, "C", 10, 9, "validation")])
    write_measurements(tmp_path / "val" / "named.csv", replace(named, sessions=np.array(["A"] * 10 + ["BC:C"] * 10,
                                                                                       dtype=object)))
    assert sources(tmp_path / "val" / "named.csv") == [("A", "reported session 'A'"), ("BC:C", "reported session 'BC:C'")]
    write_measurements(tmp_path / "val" / "short.csv", replace(named, sessions=np.array(["x"] * 10 + ["C"] * 10,
                                                                                       dtype=object)))
    # 'C' alone names no reported session (it is BC:C, read from another file): unseen
    assert sources(tmp_path / "val" / "short.csv") == [("x", REESTIMATED), ("C", REESTIMATED)]


def test_reestimated_sessions_report_their_degrees_of_freedom(calibrated, truth, tmp_path, capsys):
    folder, _ = calibrated
    args = ["evaluate", str(folder / "ur5.urdf"), str(folder / "REPORT.json")]
    write_measurements(tmp_path / "three.csv", _session(truth, "D", 3, 11, "validation"))
    capsys.readouterr()
    assert main([*args, str(tmp_path / "three.csv"), "--json", str(tmp_path / "t.json")]) == 0
    err = capsys.readouterr().err
    assert ("errors are after fitting 6 registration parameters to 9 residuals (3 degree(s) of freedom left); "
            "expect them about sqrt((9−6)/9) = 0.58 of the true error") in err
    (session,) = json.loads((tmp_path / "t.json").read_text())["sessions"]
    assert (session["residuals"], session["registration_dof"]) == (9, 3)
    # a threshold cannot judge errors that optimistic: one line, exit 2, no verdict
    for flag in ("--max-pos-mm", "--max-rot-deg"):
        assert main([*args, str(tmp_path / "three.csv"), flag, "1"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and f"{flag}: session 'three'" in err and "3 degree(s) of freedom left" in err
        assert "measure at least 4 rows" in err  # 4 point rows: 12 residuals, 6 left
    write_measurements(tmp_path / "four.csv", _session(truth, "D", 4, 12, "validation"))
    assert main([*args, str(tmp_path / "four.csv"), "--max-pos-mm", "1"]) == 0
    # positions only: --max-rot-deg refused in one line before any output is written
    capsys.readouterr()
    assert main([*args, str(tmp_path / "four.csv"), "--max-rot-deg", "1", "--json", str(tmp_path / "r.json")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--max-rot-deg needs orientation columns" in err
    assert not (tmp_path / "r.json").exists()
    # reported registrations leave all their residuals: no dof, thresholds as ever
    assert main([*args, str(tmp_path / "three.csv"), "--fixed-registration", "--json", str(tmp_path / "f.json")]) == 0
    assert json.loads((tmp_path / "f.json").read_text())["sessions"][0]["registration_dof"] is None


def test_each_session_meets_the_corrections_of_its_own_rows(truth):
    """Through several sessions' registrations, eq 24 corrects each row by its own joint values, drift and
    thermal terms (RowCorrections.select): the errors are one session's at a time with its rows' corrections."""
    data = join_sets([_session(truth, "A", 5, 1), _session(truth, "B", 5, 2)])
    rng = np.random.default_rng(4)
    k = data.n_rows
    q, drift = data.q + rng.normal(0.0, 1e-3, data.q.shape), rng.normal(0.0, 1e-4, (k, 3))
    expansion, steps = rng.normal(0.0, 1e-4, k), rng.normal(0.0, 1e-4, (k, 3))
    corrections = RowCorrections(q, 2e-4, drift, RowConditions(expansion, steps))
    registrations = [PLACEMENTS["A"], PLACEMENTS["B"]]
    both = session_pose_errors(truth, data, data.session_index, registrations, points=POINT, corrections=corrections)
    for s, registration in enumerate(registrations):
        rows = np.flatnonzero(data.session_index == s)
        own = RowCorrections(q[rows], 2e-4, drift[rows], RowConditions(expansion[rows], steps[rows]))
        alone = pose_errors(truth, data.select(rows), registration, registration, POINT, corrections=own)
        assert np.array_equal(both.position_m[rows], alone.position_m)
    plain = session_pose_errors(truth, data, data.session_index, registrations, points=POINT)
    assert plain.position_m.max() < EXACT < both.position_m.min()  # the corrections moved every row


def test_the_stated_factor_is_what_a_reestimated_registration_leaves(truth):
    """Noisy 3-row sessions, the model exact: after re-estimating the registration the mean squared
    error is (N − 6)/N of the noise's (N = 9 residuals; least squares leaves N − p of them).
    200 trials: RSS/σ² ~ χ²(3), SE of its mean sqrt(6/200) = 0.17; bound 4 SE."""
    sigma = 5e-5  # 0.05 mm, the reviewer's case
    rng = np.random.default_rng(21)
    ratios = []
    for _ in range(200):
        rows = _session(truth, "D", 3, int(rng.integers(1 << 30)))
        noisy = replace(rows, points=rows.points + rng.normal(0.0, sigma, rows.points.shape))
        registration = register_session(truth, noisy, POINT, np.eye(3), sigma_pos_m=sigma)
        errors = session_pose_errors(truth, noisy, np.zeros(3, dtype=int), [registration], points=POINT)
        ratios.append(np.sum(errors.position_m**2) / sigma**2)
    assert abs(np.mean(ratios) - 3.0) < 4 * np.sqrt(6 / 200)
    # the factor evaluate states: RMS after the fit / RMS of the noise (4 SE of the mean above: ±0.05 on 0.58)
    stated = SessionEvaluation("D", 3, registration, registration, REESTIMATED, errors, residuals=9).shrink
    assert np.sqrt(np.mean(ratios) / 9) == pytest.approx(stated, abs=0.05)


def test_a_session_of_validation_rows_only_is_reported_not_dropped(truth, tmp_path, capsys):
    for name, rows, seed, role in (("A", 14, 1, "calibration"), ("B", 14, 2, "calibration"),
                                   ("D", 10, 3, "validation")):
        write_measurements(tmp_path / f"{name}2.csv", _session(truth, name, rows, seed, role))
    capsys.readouterr()
    assert main(["calibrate", str(URDF), *(str(tmp_path / f"{n}2.csv") for n in "ABD"), "--tip-link", TIP,
                 "--level", "offsets", "--out", str(tmp_path / "c.urdf"), "--report", str(tmp_path / "R.json"),
                 "--quiet"]) == 0
    note = (f"{tmp_path / 'D2.csv'}, session 'D2': all 10 row(s) have role 'validation', so this session is not "
            "in the fit")
    assert note in capsys.readouterr().err
    report = json.loads((tmp_path / "R.json").read_text())
    assert [s["name"] for s in report["sessions"]] == ["A2", "B2"]
    assert any(n.startswith(note) for n in report["notes"])
