"""Lateral (bending) compliance on a tree: ``pincal diagnose --tip-link A:1 --tip-link B:2 --lateral`` names a
shared torso joint's bending from both hands, evaluate applies it, and nothing is claimed where there is none."""

from __future__ import annotations

import json

import numpy as np
import pinocchio as pin
import pytest
import yaml
from conftest import assert_close, numeric_jacobian, validate_document
from test_tree_diagnose import FLOOR_MM, SIGMA_M, TARGETS, _write
from tree_robot import compliant_rows, two_arm_urdf

from pincal.cli.commands import main
from pincal.diagnosis.diagnose import DiagnoseOptions
from pincal.diagnosis.tree_diagnose import diagnose_tree, tree_candidates
from pincal.fit.chain_calibration import ChainFitOptions
from pincal.fit.prior import Prior
from pincal.fit.tree_calibration import calibrate_tree, initial_tree_target, tree_rows
from pincal.measurements.data import MeasurementSet
from pincal.model.effects import Effect
from pincal.model.tree import KinematicTree, parse_targets
from pincal.model.mass_moments import bending_moments
from pincal.model.tree_effects import target_inputs, tree_inputs
from pincal.model.tree_parameters import TreeParameters
from pincal.residuals.sensor_values import ModelledEffects, RowWeights
from pincal.residuals.tree import TreeResidual

#: torso_2's lateral compliances about its u and v axes [rad/(N·m)]: the torso bends under both arms by up to
#: ~10 mrad, the hands by 3.6 mm RMS (12.8 mm at most) on these rows
LATERAL = (6e-4, -5e-4)
#: torso_2's joint compliance [rad/(N·m)] of the rows without bending (test_tree_diagnose's)
COMPLIANCE = -4e-4


def _sets(tree, params, lateral, compliance, seed=11):
    rng = np.random.default_rng(seed)
    truth = rng.normal(0.0, 5e-4, params.size)
    out = []
    for rows, role in ((60, "calibration"), (30, "validation")):
        q, sensed = compliant_rows(tree, params, truth, compliance, rows, rng, lateral=lateral)
        out.append(MeasurementSet(tree.joint_names, q, sensed, None, np.full(rows, role, dtype=object),
                                  np.arange(rows)))
    return out


@pytest.fixture(scope="module")
def robot():
    tree = KinematicTree(pin.buildModelFromXML(two_arm_urdf()), parse_targets(TARGETS[1::2]))
    return tree, TreeParameters(tree, "full")


@pytest.fixture(scope="module")
def diagnosed(robot, tmp_path_factory):
    """diagnose --lateral on rows with torso_2 bent (the URDF's masses), and evaluate of its report."""
    tree, params = robot
    folder = tmp_path_factory.mktemp("tree_lateral")
    urdf = folder / "robot.urdf"
    urdf.write_text(two_arm_urdf(), encoding="utf-8")
    for name, rows in zip(("data", "held"), _sets(tree, params, ("torso_2", *LATERAL), 0.0)):
        _write(folder / f"{name}.csv", tree.joint_names, rows.q, rows.points)
    out, report = folder / "out.urdf", folder / "REPORT.json"
    code = main(["diagnose", str(urdf), str(folder / "data.csv"), *TARGETS, "--lateral", "--validation",
                 str(folder / "held.csv"), "--out", str(out), "--report", str(report), "--quiet"])
    return code, folder, out, report


def test_the_tree_residual_with_lateral_compliances_matches_finite_differences(robot):
    """Lateral compliances of a shared joint (the URDF's masses) and of one arm's (mass moments), with a joint
    compliance: each target's part bends as its chain has the joint, the Jacobian matches central differences."""
    tree, params = robot
    data = _sets(tree, params, None, 0.0)[0].select(np.arange(8))
    rows = tree_rows(tree, data)
    inputs = tree_inputs(tree, data, loads=True)
    right = tree.targets[1]  # a target's part: its chain's columns; an arm's own joints bend under that arm only
    alone = bending_moments(right.chain, data.q[:, right.columns])
    assert_close(target_inputs(inputs, right).bending[:, 2:], alone[:, 2:], 1e-9, "an arm's own bending moments")
    effects = (Effect("lateral", "torso_2"), Effect("lateral", "arm_left_2", moments=("u/mx:arm_left_3_link",
                                                                                      "v/m:arm_left_4_link")),
               Effect("compliance", "torso_2"))
    start = initial_tree_target(tree, data, rows)
    free = np.arange(params.size)[::3]
    base = np.random.default_rng(3).normal(0.0, 1e-3, params.size)
    objective = TreeResidual(tree, params, free, base, rows, start, RowWeights(1000.0),
                             effects=ModelledEffects(effects, inputs))
    x = objective.start_vector()
    x[objective.blocks["effects"]] = [5e-4, -4e-4, 0.02, -0.03, 3e-4]
    without = TreeResidual(tree, params, free, base, rows, start, RowWeights(1000.0),
                           effects=ModelledEffects(effects[2:], inputs))
    assert np.max(np.abs(objective.residual(x) - without.residual(np.r_[x[:-5], x[-1]]))) > 1.0  # > 1 mm: bent
    assert_close(objective.jacobian(x), numeric_jacobian(objective.residual, x), 1e-5, "tree lateral columns")
    seen_right = np.repeat(objective.observations()[1] > 0, 3)  # the left arm's bending moves no right-hand point
    assert not objective.jacobian(x)[seen_right][:, objective.effect_slices[1]].any()


def test_diagnose_lateral_names_the_torso_bending_and_evaluate_applies_it(diagnosed, capsys):
    code, folder, out, report_path = diagnosed
    assert code == 0
    report = json.loads(report_path.read_text(encoding="utf-8"))
    validate_document(report)  # a tree's report with a lateral compliance: of the schema's TreeReport kind only
    [effect] = report["effects"]
    assert (effect["type"], effect["joint"]) == ("lateral", "torso_2")
    assert effect["value"] == pytest.approx(list(LATERAL), rel=0.03)
    for target in report["targets"]:
        before, after = target["validation_geometry_errors"], target["validation_errors"]
        assert before["position"]["rms_mm"] > 10 * FLOOR_MM  # the geometry cannot bend the torso
        assert after["position"]["rms_mm"] < 1.25 * FLOOR_MM
    effects = yaml.safe_load(out.with_name("out.effects.yaml").read_text(encoding="utf-8"))
    assert [(e["type"], e["joint"]) for e in effects["effects"]] == [("lateral", "torso_2")]
    capsys.readouterr()
    assert main(["evaluate", str(out), str(report_path), str(folder / "held.csv")]) == 0
    rows = [line.split() for line in capsys.readouterr().out.splitlines()[2:4]]
    for row, target in zip(rows, report["targets"]):
        # its moments at the corrected URDF's geometry, diagnose's at the URDF's (0.196 and 0.192 mm): within 3 %;
        # without the bending evaluate would give the geometry's ~3 mm
        assert float(row[3]) == pytest.approx(target["validation_errors"]["position"]["rms_mm"], rel=0.03)


@pytest.mark.parametrize(("lateral", "compliance", "masses", "named"), [
    (None, COMPLIANCE, "urdf", ["compliance:torso_2"]),
    (None, 0.0, "urdf", []),
    (("torso_2", *LATERAL), 0.0, "unknown", ["lateral:torso_2"]),
], ids=["joint-compliance-only", "no-effect", "unknown-masses"])
def test_lateral_is_claimed_only_where_the_torso_bends(robot, lateral, compliance, masses, named):
    tree, params = robot
    data, held = _sets(tree, params, lateral, compliance)
    calibration = calibrate_tree(tree, data, "full", ChainFitOptions(selection=Prior()))  # diagnose's default
    found = diagnose_tree(tree, calibration, data, held, DiagnoseOptions(masses=masses, lateral=True))
    assert [e.label.split(":moments")[0] for e, _, _ in found.effects] == named
    assert Effect("lateral", "torso_2") in tree_candidates(tree, False, lateral=True)
    assert np.all(np.sqrt(np.nanmean(found.heldout_after**2, axis=0)) < 1.25 * np.sqrt(3.0) * SIGMA_M)
    # the final fit's estimation noise at the held-out rows: a fraction of the noise, so the held-out RMS is
    # within 1.3x sqrt(3 σ² + e²) either way (scripts/scenarios.py's bound)
    predicted = np.sqrt(3.0 * SIGMA_M**2 + found.heldout_predicted_m**2)
    assert 0.0 < found.heldout_predicted_m < 2 * SIGMA_M  # 0.12 mm over 34 mass-moment values (unknown masses)
    assert 1 / 1.3 < np.sqrt(np.nanmean(found.heldout_after**2)) / predicted < 1.3
