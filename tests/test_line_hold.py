"""Rows on one straight line at constant tool orientation: held, not refused (pincal.fit.registration_hold).

A laser tracker measuring a probe while the robot runs one straight line, the orientation held by the
controller: the sensor's rotation about the line cannot be told from the probe's rotation on the tool
about it (6D), or from anything (3D), and the target's position not from the registration. These are
held at stated values, the rest calibrated, and the rows along the line predicted at the noise floor.

Thresholds: the noise-limited prediction of a held-out point distance is sqrt(3 σ² + e²)
(scripts/scenarios.py; e from the fit's covariance, ChainCalibration.predicted_point_rms), the issue's
bound 1.3× it (and, so that a wide prediction cannot pass, at least 1/1.3 of it).
"""

from __future__ import annotations

import functools
import json
from dataclasses import replace

import lxml.html
import numpy as np
import pytest
import scipy.linalg
from conftest import INDUSTRIAL_ARM_START, assert_close, numeric_jacobian
from scipy.spatial.transform import Rotation

from pincal.cli.commands import main
from pincal.errors import CalibrationError
from pincal.fit.chain_calibration import ChainFitOptions, calibrate_chain
from pincal.fit.metrics import pose_errors
from pincal.fit.plausibility import check_calibration
from pincal.fit.registration import register_line
from pincal.fit.sessions import LINE_RATIO, initial_target
from pincal.measurements.csv_v1 import write_measurements
from pincal.model.chain import KinematicChain, pose_from_xyz_rpy
from pincal.model.parameter_sets import PlacementErrors
from pincal.residuals.base import KinematicsCache
from pincal.residuals.sensor import SensorResidual
from pincal.residuals.sensor_values import FittedBlocks, RowWeights
from pincal.simulation.cells import ToolPath, constant_orientation_path, measure_truth, sensor_at
from pincal.simulation.sensor import SimulatedSensor

SIGMA_POS_M = 20e-6  # a laser tracker at a few metres
SIGMA_ROT_RAD = np.radians(0.003)  # its 6D probe
BOUND = 1.3
TOOL_XYZ, TOOL_RPY = [0.035, -0.02, 0.21], [0.2, -0.35, 0.5]  # the probe on the flange [m, rad]
TOOL = pose_from_xyz_rpy(TOOL_XYZ, TOOL_RPY)
DOWN = np.diag([-1.0, 1.0, -1.0])  # tool pointing down


def _line(urdf, with_rotation: bool, tool_known: bool, kind: str = "line", seed: int = 3):
    """One path at constant orientation (2 passes of 50 rows) and its other points (37 a pass) held out;
    the target known (the chain's tool, measured as itself) or not (measured at TOOL, estimated). Simulated once
    per cell however the call spells its arguments (a cache keys on the arguments as given)."""
    return _simulated_line(urdf, with_rotation, tool_known, kind, seed)


@functools.cache
def _simulated_line(urdf, with_rotation: bool, tool_known: bool, kind: str, seed: int):
    plain = KinematicChain.from_urdf(urdf, "flange")
    path = ToolPath(kind, 100, np.array([1.2, 0.0, 0.5]), heights=1)
    q, q_test = (constant_orientation_path(plain, p, DOWN, INDUSTRIAL_ARM_START)
                 for p in (path, replace(path, rows_per_line=37)))
    chain = KinematicChain.from_urdf(urdf, "flange", tool=TOOL if tool_known else None)
    params = PlacementErrors(chain)
    rng = np.random.default_rng(seed)
    truth = rng.normal(0.0, 3e-4, params.size)
    target = dict(points=np.zeros((1, 3)), target_rotation=np.eye(3)) if tool_known else dict(
        points=TOOL[None, :3, 3], target_rotation=TOOL[:3, :3])
    sensor = SimulatedSensor(SIGMA_POS_M, SIGMA_ROT_RAD, with_rotation=with_rotation, **target)
    rows = measure_truth(params, truth, q, sensor_at(4.2), rng, sensor)
    test = measure_truth(params, truth, q_test, sensor_at(4.2), rng, sensor, "validation")
    return chain, rows, test


@functools.cache
def _calibrated(urdf, with_rotation: bool, tool_known: bool, kind: str = "line"):
    """``_line``'s rows calibrated at level full under the prior, once per cell: the tests that hold, predict
    and move the same rows share this one fit (a frozen ChainCalibration, read only)."""
    chain, rows, _ = _line(urdf, with_rotation, tool_known, kind)
    return calibrate_chain(chain, rows, "full", ChainFitOptions(tool_known=tool_known, selection="prior"))


def _held_out(chain, result, test):
    """RMS point distance of the held-out rows [m] and its noise-limited prediction sqrt(3σ² + e²) [m]."""
    target = result.target
    with chain.placed(result.chain_placements):
        errors = pose_errors(chain, test, target.registration, target.registration, points=target.points,
                             target_rotation=target.rotation)
    return float(np.sqrt(np.mean(errors.position_m**2))), float(np.hypot(
        np.sqrt(3.0) * SIGMA_POS_M, result.predicted_point_rms(chain, test.q)))


@pytest.mark.parametrize("with_rotation,tool_known,rotations_held", [
    (True, False, 1), (True, True, 0), (False, False, 1), (False, True, 1)],
    ids=["6D", "6D --tool", "3D", "3D --tool"])
def test_one_line_holds_what_the_rows_leave_free_and_predicts_the_path(industrial_arm_urdf, with_rotation,
                                                                        tool_known, rotations_held):
    """The rotation about the line held where the rows leave it free — and only there: a correct --tool with
    orientations fixes it, positions alone never do —; the rows along the line within 1.3× the prediction; the
    plausibility warning 'path' exactly when something was held."""
    chain, rows, test = _line(industrial_arm_urdf, with_rotation, tool_known)
    result = _calibrated(industrial_arm_urdf, with_rotation, tool_known)
    assert len(result.held_rotations) == rotations_held and len(result.held) == (0 if tool_known else 3)
    for held in result.held_rotations:
        assert abs(held.axis[0]) == pytest.approx(1.0) and held.seen <= LINE_RATIO  # the path runs along base x
    measured, predicted = _held_out(chain, result, test)
    assert 1.0 / BOUND <= measured / predicted <= BOUND
    codes = [finding.code for finding in check_calibration(chain, result, rows)]
    assert ("path" in codes) == bool(rotations_held)
    if rotations_held:
        assert any("registration not determined" in note for note in result.notes)


@pytest.mark.parametrize("with_rotation,tool_known", [(True, False), (True, True), (False, False), (False, True)],
                         ids=["6D", "6D --tool", "3D", "3D --tool"])
def test_one_arc_at_constant_orientation_predicts_the_path(industrial_arm_urdf, with_rotation, tool_known):
    """One arc at constant orientation: its points span a plane, so the registration's rotation is fixed and
    nothing is held about an axis; what the rows leave free of the target is held as for a line; the rows
    along the arc within 1.3× the noise-limited prediction."""
    chain, rows, test = _line(industrial_arm_urdf, with_rotation, tool_known, kind="arc")
    result = _calibrated(industrial_arm_urdf, with_rotation, tool_known, kind="arc")
    assert result.held_rotations == () and len(result.held) == (0 if tool_known else 3)
    measured, predicted = _held_out(chain, result, test)
    assert 1.0 / BOUND <= measured / predicted <= BOUND


def test_one_line_end_to_end_calibrate_diagnose_and_evaluate(industrial_arm_urdf, tmp_path, capsys):
    """calibrate and diagnose on one line: written, exit 0 with the warning, 3 with --strict; the report says
    what was held; evaluate on the line's other points notes it; a correct --tool: nothing held or warned."""
    _, rows, test = _line(industrial_arm_urdf, True, False)
    line, held_out = tmp_path / "line.csv", tmp_path / "test.csv"
    write_measurements(line, rows)
    write_measurements(held_out, test)
    common = [str(industrial_arm_urdf), str(line), "--tip-link", "flange", "--quiet"]
    for command in ("calibrate", "diagnose"):
        for strict in (False, True):
            out, report = tmp_path / f"{command}{strict}.urdf", tmp_path / f"{command}{strict}.json"
            html = ["--html", str(tmp_path / f"{command}.html")] if command == "calibrate" and not strict else []
            code = main([command, *common, "--out", str(out), "--report", str(report), *(["--strict"] * strict),
                         *html])
            err = capsys.readouterr().err
            assert code == (3 if strict else 0), err
            assert out.exists() and "registration not determined" in err and "checked only near that path" in err
            doc = json.loads(report.read_text())
            assert [w["code"] for w in doc["warnings"]] == ["path"]
            (held,) = doc["identifiability"]["not_determined_rotations"]
            assert held["name"] == "registration.rotation" and held["rule"] == "nearest_tool_rotation"
            assert abs(held["axis"][0]) == pytest.approx(1.0) and held["frame"] == "base_link"
    page = lxml.html.fromstring((tmp_path / "calibrate.html").read_text(encoding="utf-8"))
    (table,) = page.xpath('//table[@id="not-determined-table"]')
    names = [tr.xpath("./td")[0].text_content() for tr in table.xpath("./tbody/tr")]
    assert names == ["target.position"] * 3 + ["registration.rotation"]
    assert main(["evaluate", str(tmp_path / "calibrateFalse.urdf"), str(tmp_path / "calibrateFalse.json"),
                 str(held_out), "--json", str(tmp_path / "e.json")]) == 0
    assert "rows off that line" in capsys.readouterr().err
    assert json.loads((tmp_path / "e.json").read_text())["position"]["rms_mm"] < BOUND * np.sqrt(3) * 0.02

    _, known, _ = _line(industrial_arm_urdf, True, True)
    write_measurements(tmp_path / "known.csv", known)
    tool = ",".join(str(v) for v in TOOL_XYZ + TOOL_RPY)
    code = main(["calibrate", str(industrial_arm_urdf), str(tmp_path / "known.csv"), "--tip-link", "flange",
                 "--tool", tool, "--out", str(tmp_path / "k.urdf"), "--report", str(tmp_path / "k.json"),
                 "--strict", "--quiet"])
    assert code == 0, capsys.readouterr().err
    doc = json.loads((tmp_path / "k.json").read_text())
    assert doc["warnings"] == [] and "not_determined_rotations" not in doc["identifiability"]


def _outcome(chain, data, result=None):
    """Placements and per-row position errors [m] of ``data`` calibrated (or of ``result``, its calibration)."""
    if result is None:
        result = calibrate_chain(chain, data, "full", ChainFitOptions(selection="prior"))
    with chain.placed(result.chain_placements):
        errors = pose_errors(chain, data, result.target.registration, result.target.registration,
                             points=result.target.points, target_rotation=result.target.rotation)
    return np.array(result.chain_placements), errors.position_m


def _moved(data, rotation, shift):
    return replace(data, points=data.points @ rotation.T + shift,
                   rotations=None if data.rotations is None else rotation @ data.rotations)


@pytest.mark.parametrize("with_rotation", [True, False], ids=["6D", "3D"])
def test_moving_the_sensor_changes_nothing(industrial_arm_urdf, with_rotation):
    """The rows in a sensor frame moved by 12 m and turned: with orientations, the held rotation is the sensor
    frame's (register_line's reference), so nothing changes (1e-9 m per row's error, 1e-9 relative placements,
    as tests/test_frame_invariance.py). Positions alone carry no direction to hold it by but the vertical: a
    sensor turned about its z axis changes nothing either (placements to 1e-7: measured 3e-9 with fixed prior
    scales, 5e-8 with the scales estimated from the rows, whose estimate stops when they move by less than
    1 %: the solver's stop in the flat valley of the directions only the prior holds); tilted, only the geometry across the line
    may differ, by what the data cannot see: the held-out rows along the line are predicted to within 1 %
    (measured 0.05 %; the placements moved by 1e-4)."""
    chain, rows, test = _line(industrial_arm_urdf, with_rotation, False)
    result = _calibrated(industrial_arm_urdf, with_rotation, False)
    placements, errors = _outcome(chain, rows, result)
    about_z = Rotation.from_euler("z", 137.0, degrees=True).as_matrix()
    tilted = Rotation.from_rotvec([0.4, -0.9, 0.3]).as_matrix()
    for turn in (about_z,) if not with_rotation else (tilted,):
        moved, moved_errors = _outcome(chain, _moved(rows, turn, np.array([-7.0, 9.0, 2.5])))
        assert np.abs(moved_errors - errors).max() <= 1e-9
        scale = max(1.0, np.abs(placements).max())
        assert np.abs(moved - placements).max() <= (1e-9 if with_rotation else 1e-7) * scale
    if not with_rotation:
        shift = np.array([-7.0, 9.0, 2.5])
        moved = calibrate_chain(chain, _moved(rows, tilted, shift), "full", ChainFitOptions(selection="prior"))
        measured, _ = _held_out(chain, result, test)
        moved_measured, _ = _held_out(chain, moved, _moved(test, tilted, shift))
        assert moved_measured == pytest.approx(measured, rel=0.01)


def test_a_held_registration_rotation_has_the_finite_difference_jacobian(industrial_arm_urdf):
    """SensorResidual with registration_basis (two sessions, one rotation held in each): its analytic
    Jacobian against central differences (step 1e-6, tolerance 1e-6 as tests/test_sessions.py)."""
    rng = np.random.default_rng(4)
    chain, rows, _ = _line(industrial_arm_urdf, True, False)
    rows = rows.select(np.arange(12))
    params = PlacementErrors(chain)
    cache = KinematicsCache(params, rng.permutation(params.size)[:8], rng.normal(0, 1e-3, params.size), rows.q)
    start = initial_target(chain, rows, fit_points=True)
    start = replace(start, registrations=(start.registration, start.registration))
    held = np.zeros((12, 2))
    held[:3, 0] = [1.0, 0.0, 0.0]
    held[6:9, 1] = np.array([0.0, 0.6, 0.8])
    basis = scipy.linalg.null_space(held.T)
    sessions = np.arange(12) % 2
    objective = SensorResidual(cache, rows.points, rows.rotations, start, RowWeights(rotation=2.0),
                               FittedBlocks(registration_basis=basis), sessions=sessions)
    assert objective.blocks["registration"].stop - objective.blocks["registration"].start == 10
    x = objective.start_vector() + rng.normal(0, 0.05, objective.n_free)
    assert_close(objective.jacobian(x), numeric_jacobian(objective.residual, x), 1e-6, "held rotations")
    turned = objective.estimate(x).registrations  # the held rotations stay the start's
    for session, axis in ((0, held[:3, 0]), (1, held[6:9, 1])):
        step = Rotation.from_matrix(start.registration.rotation.T @ turned[session].rotation).as_rotvec()
        assert abs(step @ axis) < 1e-12


def test_register_line_states_the_rotation_about_the_line():
    """A levelled sensor (turned about z) is recovered exactly without a reference; with one, the rotation
    nearest it; the rule moves with the sensor; a vertical line falls back to the nearest the identity;
    points at one place are refused."""
    line = np.array([1.0, 0.5, 0.2]) / np.linalg.norm([1.0, 0.5, 0.2])
    robot = np.array([1.2, 0.0, 0.5]) + np.linspace(-0.3, 0.3, 20)[:, None] * line
    levelled = Rotation.from_euler("z", 70.0, degrees=True).as_matrix()
    sensed = robot @ levelled.T + [1.0, 2.0, 3.0]
    registration = register_line(robot, sensed)
    assert np.abs(registration.rotation - levelled).max() < 1e-12
    assert np.abs(registration.apply_points(robot) - sensed).max() < 1e-12
    reference = Rotation.from_rotvec([0.3, -0.2, 1.0]).as_matrix()
    near = register_line(robot, sensed, reference).rotation
    assert np.abs(near @ line - levelled @ line).max() < 1e-12  # the line onto the sensed line
    angle = np.linalg.norm(Rotation.from_matrix(near @ reference.T).as_rotvec())
    assert angle <= np.linalg.norm(Rotation.from_matrix(levelled @ reference.T).as_rotvec()) + 1e-12
    turn = Rotation.from_euler("z", -33.0, degrees=True).as_matrix()
    assert np.abs(register_line(robot, sensed @ turn.T + 5.0).rotation - turn @ registration.rotation).max() < 1e-12
    vertical = np.array([1.2, 0.0, 0.5]) + np.linspace(-0.3, 0.3, 20)[:, None] * [0.0, 0.0, 1.0]
    assert np.abs(register_line(vertical, vertical + 1.0).rotation - np.eye(3)).max() < 1e-12
    with pytest.raises(CalibrationError, match="coincide"):
        register_line(np.ones((5, 3)), np.zeros((5, 3)))


def test_a_tool_at_one_point_is_refused_in_one_line(industrial_arm_urdf):
    """Every row at one modelled tool pose: no line to hold a rotation about, nothing to calibrate."""
    chain, rows, _ = _line(industrial_arm_urdf, False, False)
    still = rows.select(np.zeros(10, dtype=int))
    with pytest.raises(CalibrationError, match="at one point"):
        initial_target(chain, still, fit_points=True)
