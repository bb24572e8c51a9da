"""Compliance without a mass model on a whole upper body: two arms on a four-joint torso whose 4th joint is coupled
(tests/torso_robot.py), from a URDF without any ``<inertial>``.

The simulated robot (its masses known to the simulation only) gives under its own weight: the right shoulder
(arm_r_1, a joint compliance) and the torso's base (torso_1, bending about its lateral axis u, not v). ``pincal
diagnose --tip-link hand_r:1 --tip-link hand_l:2 --lateral`` takes the masses as unknown (the URDF has none), names
both effects in their mass-moment form, says each value's combination in words with its unit, writes them to
effects.yaml and brings each hand's held-out error to the noise floor; ``evaluate`` applies them. The same robot
without the compliances: nothing is claimed.
"""

from __future__ import annotations

import io
from contextlib import redirect_stdout

import numpy as np
import pytest
import yaml
from torso_robot import TARGETS, torso_urdf

from pincal.cli.commands import main
from pincal.diagnosis.diagnose import DiagnoseOptions
from pincal.diagnosis.tree_diagnose import diagnose_tree
from pincal.fit.chain_calibration import ChainFitOptions
from pincal.fit.prior import Prior
from pincal.fit.tree_calibration import calibrate_tree
from pincal.measurements.csv_v1 import write_measurements
from pincal.measurements.data import MeasurementSet
from pincal.model.effects import gravity_torques, joint_shifts
from pincal.model.lateral import bend_angles
from pincal.model.tree import KinematicTree, parse_targets
from pincal.model.tree_effects import TreeBody, target_inputs, tree_inputs
from pincal.model.tree_parameters import TreeParameters
from pincal.simulation.humanoid import MOCAP, HumanoidSettings, simulate_humanoid, with_followers
from pincal.workflows import tree_diagnosis

#: the right shoulder's joint compliance [rad/(N·m)], a joint that sags (c < 0)
SHOULDER = ("arm_r_1", -3e-4)
#: torso_1's lateral compliances about its u (x) and v (y) axes [rad/(N·m)]: it bends sideways only
BENDING = ("torso_1", 3e-4, 0.0)
SIGMA_MM = 0.1  # the motion capture's noise per axis [mm]
ROWS, HELD = 120, 60


def _simulate(folder, name, elastic):
    """The rows of the simulated robot (``elastic``: with :data:`SHOULDER` and :data:`BENDING`), written as
    ``NAME.csv`` and ``NAME_held.csv``; its data."""
    data = simulate_humanoid(HumanoidSettings(
        targets=TARGETS, rows=ROWS, held_out_rows=HELD, sigma_pos_mm=SIGMA_MM, deviation_mm=0.5, deviation_mrad=0.5,
        compliance=(SHOULDER,) if elastic else (), lateral=(BENDING,) if elastic else (), payload_kg=0.0,
        marker_m=(0.0, 0.0, 0.0), joint_range_rad=1.2, seed=3, urdf=str(folder / "truth.urdf")))
    write_measurements(folder / f"{name}.csv", data.calibration)
    write_measurements(folder / f"{name}_held.csv", data.validation)
    return data


@pytest.fixture(scope="module")
def torso(tmp_path_factory):
    """The user's URDF (no inertias), the simulated robot's (with them), and the elastic and the rigid rows."""
    folder = tmp_path_factory.mktemp("torso4")
    (folder / "robot.urdf").write_text(torso_urdf(inertias=False), encoding="utf-8")
    (folder / "truth.urdf").write_text(torso_urdf(inertias=True), encoding="utf-8")
    return folder, _simulate(folder, "elastic", True), _simulate(folder, "rigid", False)


@pytest.fixture(scope="module")
def diagnosed(torso):
    """``pincal diagnose ... --lateral`` on the elastic rows: exit code, console, and the workflow's run."""
    folder = torso[0]
    runs, console = [], io.StringIO()
    workflow = tree_diagnosis.diagnose_tree_files
    with pytest.MonkeyPatch.context() as patch, redirect_stdout(console):  # the run the command printed
        patch.setattr(tree_diagnosis, "diagnose_tree_files", lambda *a, **k: runs.append(workflow(*a, **k)) or runs[-1])
        code = main(["diagnose", str(folder / "robot.urdf"), str(folder / "elastic.csv"), "--validation",
                     str(folder / "elastic_held.csv"), "--tip-link", TARGETS[0], "--tip-link", TARGETS[1], "--lateral",
                     "--out", str(folder / "out.urdf"), "--report", str(folder / "REPORT.json")])
    return code, console.getvalue(), runs[0]


def test_the_robot_couples_its_torso_and_the_truth_moves_the_hands_by_5_to_15_mm(torso):
    folder, elastic, rigid = torso
    assert "<inertial" not in (folder / "robot.urdf").read_text(encoding="utf-8")
    user = KinematicTree.from_urdf(folder / "robot.urdf", parse_targets(list(TARGETS)))
    assert user.followers == ("torso_3", "torso_4")  # no column: each from torso_2
    tree = elastic.tree  # the simulated robot's: its masses
    assert tree.joint_names == user.joint_names
    q = tree.followed(np.random.default_rng(0).uniform(-0.5, 0.5, (5, tree.n_joints)))
    names = tree.joint_names
    assert np.allclose(q[:, names.index("torso_4")], -(q[:, names.index("torso_2")] + q[:, names.index("torso_3")]))
    assert "torso_3" not in elastic.calibration.joint_names and "torso_4" not in elastic.calibration.joint_names
    # the upright upper body only translates as torso_2 turns: the load torso_2 holds (its own and its followers'
    # torques, by virtual work) is a function of its angle alone, whatever the arms do (docs/whole-robots.md)
    moved = q.copy()
    moved[:, 4:] = np.random.default_rng(1).uniform(-1.2, 1.2, (5, tree.n_joints - 4))  # the arms' joints
    held = [gravity_torques(TreeBody(tree), rows)[:, names.index("torso_2")] for rows in (q, moved)]
    assert np.max(np.abs(held[0])) > 1.0 and np.allclose(held[0], held[1], rtol=0.0, atol=1e-9)
    rms_mm, max_mm = elastic.deflection_mm
    assert 5.0 <= max_mm <= 15.0 and rms_mm > 10 * np.sqrt(3.0) * SIGMA_MM  # the 5-15 mm, far above noise
    assert rigid.deflection_mm == (0.0, 0.0)


def test_diagnose_names_the_shoulder_and_the_sideways_bending_without_masses(diagnosed, torso):
    code, console, run = diagnosed
    assert code == 0
    report = run.report
    assert report["diagnosis"]["masses"] == "unknown"  # the URDF has none
    assert [(e["type"], e["joint"]) for e in report["effects"]] == [("lateral", "torso_1"), ("compliance", "arm_r_1")]
    assert not any("these poses cannot tell" in note for note in run.notes)  # each far ahead of any other
    folder, elastic, _ = torso
    truth = KinematicTree.from_urdf(folder / "truth.urdf", parse_targets(list(TARGETS)))
    rows = with_followers(truth, elastic.calibration)
    inputs, tree = run.diagnosis.inputs, elastic.tree
    effects = [(effect, values) for effect, values, _ in run.diagnosis.effects]
    # torso_1 bends about u as the truth does and not about v (the mean: a placement the geometry took)
    moments = tree_inputs(truth, rows).bending[:, 0]  # the true masses' moments about torso_1's u and v [N·m]
    true_bend = np.array(BENDING[1:]) * moments
    right = tree.targets[0]
    bends = bend_angles(*zip(*effects[:1]), target_inputs(inputs, right), right.chain.joint_names)[:, :2]
    off = bends - true_bend
    scale = np.std(true_bend[:, 0])
    assert scale > 1e-3  # ~mrad of bending
    # 5 % of it: 0.17 mrad, 0.12 mm at the hands 0.72 m (RMS) from torso_1: the noise per axis
    assert np.std(off[:, 0]) < 0.05 * scale and np.std(bends[:, 1]) < 0.05 * scale
    # arm_r_1 sags by its true compliance under the true masses' torque, likewise
    j = tree.joint_names.index("arm_r_1")
    true_shift = SHOULDER[1] * gravity_torques(TreeBody(truth), rows.q)[:, j]
    shift = joint_shifts(*zip(*effects[1:]), inputs, tree.joint_names)[:, j]
    # 10 % of its 2.2 mrad: 0.14 mm at the hand 0.65 m (RMS) from the shoulder: the noise per axis
    assert np.std(shift - true_shift) < 0.1 * np.std(true_shift)
    # each value a combination of mass moments, in words with its unit: on the console and in the report
    for entry in report["effects"]:
        assert len(entry["combinations"]) == len(entry["value"]) == len(entry["moments"])
        assert all(w.startswith("g·(") and w.endswith(" [rad]") for w in entry["combinations"])
        assert f"{entry['value'][0]:.4g} = {entry['combinations'][0]}" in console
    assert "/k_u[torso_1] [rad]" in console and "/k[arm_r_1] [rad]" in console


def test_each_hand_held_out_at_the_noise_floor_and_evaluate_applies_the_effects(diagnosed, torso, capsys):
    """The floor: the simulated noise σ per axis, √3 σ per point, with the final fit's own estimation noise e
    at the held-out rows (its covariance propagated: :attr:`TreeDiagnosis.heldout_predicted_m`): √(3σ² + e²)."""
    _, _, run = diagnosed
    folder = torso[0]
    floor_mm = np.hypot(np.sqrt(3.0) * SIGMA_MM, run.diagnosis.heldout_predicted_m * 1000.0)
    assert floor_mm < 1.2 * np.sqrt(3.0) * SIGMA_MM  # the fit's share is small beside the noise's (0.069 mm)
    for target in run.report["targets"]:
        before, after = target["validation_geometry_errors"], target["validation_errors"]
        assert before["position"]["rms_mm"] > 8 * floor_mm  # the geometry cannot bend
        assert after["position"]["rms_mm"] < 1.2 * floor_mm
    effects = yaml.safe_load((folder / "out.effects.yaml").read_text(encoding="utf-8"))
    written = {(e["type"], e["joint"]): e for e in effects["effects"]}
    assert set(written) == {("lateral", "torso_1"), ("compliance", "arm_r_1")}
    for entry in run.report["effects"]:  # each value with its combination in words, and how to apply it
        own = written[entry["type"], entry["joint"]]
        assert (own["moments"], own["combinations"]) == (entry["moments"], entry["combinations"]) and own["equation"]
    corrected = (folder / "out.urdf").read_text(encoding="utf-8")
    assert corrected.count("<mimic ") == 2 and "<inertial" not in corrected
    capsys.readouterr()
    assert main(["evaluate", str(folder / "out.urdf"), str(folder / "REPORT.json"),
                 str(folder / "elastic_held.csv")]) == 0
    lines = [line.split() for line in capsys.readouterr().out.splitlines()[2:4]]
    for line, target in zip(lines, run.report["targets"]):
        assert line[0] == target["tip_link"]
        # its loads at the corrected URDF's geometry, diagnose's at the URDF's
        assert float(line[3]) == pytest.approx(target["validation_errors"]["position"]["rms_mm"], rel=0.03)
        assert float(line[3]) < 1.2 * floor_mm


def test_without_the_compliances_nothing_is_claimed(torso):
    folder, _, rigid = torso
    tree = KinematicTree.from_urdf(folder / "robot.urdf", parse_targets(list(TARGETS)))
    data, held = with_followers(tree, rigid.calibration), with_followers(tree, rigid.validation)
    calibration = calibrate_tree(tree, data, "full", ChainFitOptions(selection=Prior()))  # diagnose's default
    found = diagnose_tree(tree, calibration, data, held, DiagnoseOptions(lateral=True))
    assert found.masses_unknown and found.effects == () and found.steps == ()


def test_the_coupled_torso_gives_as_pincal_models_a_mimic_drivers_compliance(torso):
    """torso_2's compliance on the simulated robot (no noise, no errors): it holds its followers' torques too, by
    virtual work (τ₂ + τ₃ − 2 τ₄), and moves them with it, exactly as pincal's joint effects have a driver do."""
    folder = torso[0]
    exact = simulate_humanoid(HumanoidSettings(
        targets=TARGETS, rows=5, held_out_rows=1, sigma_pos_mm=0.0, deviation_mm=0.0, deviation_mrad=0.0,
        compliance=(("torso_2", -1e-4),), payload_kg=0.0, marker_m=(0.0, 0.0, 0.0), seed=3,
        urdf=str(folder / "truth.urdf")))
    tree, rows = exact.tree, with_followers(exact.tree, exact.calibration)
    assert exact.deflection_mm[1] > 1.0
    j = tree.joint_names.index("torso_2")
    shifts = np.zeros_like(rows.q)
    shifts[:, j] = -1e-4 * gravity_torques(TreeBody(tree), rows.q)[:, j]
    actual = tree.followed(rows.q + shifts)  # the followers from the driver's actual angle (eq M1)
    world = tree.target_points(actual, [np.zeros((1, 3))] * 2)
    sensed = (exact.calibration.points - MOCAP.translation) @ MOCAP.rotation
    assert np.allclose(world, sensed, atol=1e-12, rtol=0.0)


def test_candidates_that_correct_alike_are_named_together(torso):
    """torso_2's encoder off by 2 % (its followers moved with it): a coupling of torso_2 to torso_3's reading is
    the same correction (torso_3 reads torso_2's angle), so the rows cannot tell them apart; the one adopted is
    named with the other, as the single chain names candidates that correct alike."""
    folder = torso[0]
    tree = KinematicTree.from_urdf(folder / "robot.urdf", parse_targets(list(TARGETS)))
    params = TreeParameters(tree, "full")
    rng = np.random.default_rng(8)
    truth = rng.normal(0.0, 5e-4, params.size)
    j = tree.joint_names.index("torso_2")
    sets = []
    for count, role in ((60, "calibration"), (30, "validation")):
        q = rng.uniform(-1.2, 1.2, (count, tree.n_joints))
        q[:, j] *= 0.5 / 1.2  # within torso_2's limits, ±0.5 rad
        q = tree.followed(q)
        actual = q.copy()
        actual[:, j] *= 1.02
        with tree.placed(params.placements(truth)):
            world = tree.target_points(tree.followed(actual), [np.zeros((1, 3))] * 2)
        sensed = world @ MOCAP.rotation.T + MOCAP.translation + rng.normal(0.0, SIGMA_MM * 1e-3, world.shape)
        sets.append(MeasurementSet(tree.joint_names, q, sensed, None, np.full(count, role, dtype=object),
                                   np.arange(count)))
    calibration = calibrate_tree(tree, sets[0], "full", ChainFitOptions(selection=Prior()))
    found = diagnose_tree(tree, calibration, sets[0], sets[1])
    [(effect, values, _)] = found.effects
    twins = {"encoder_scale:torso_2", "coupling:torso_2:torso_3"}
    assert effect.label in twins
    [other] = [c for c in found.steps[0].candidates if c.effect.label in twins - {effect.label}]
    assert other.verdict.startswith(f"{effect.label} corrects the same poses the same way")
    [note] = [n for n in found.notes if "these poses cannot tell" in n]
    assert note.startswith("torso_2's error: an encoder scale or a coupling to torso_3's reading") or note.startswith(
        "torso_2's error: a coupling to torso_3's reading or an encoder scale")
