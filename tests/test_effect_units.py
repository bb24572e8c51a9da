"""The unit of an effect's value follows the kinds of both joints it involves (:mod:`pincal.model.effect_units`).

A compliance's value is its joint's shift per unit of a gravity load: the shift is in rad (m for a
prismatic joint), the load a torque in N·m of a revolute joint or a force in N along a prismatic one,
its own or its driver's. TIAGo's chain (example-robot-data) starts with a prismatic torso lift under
seven revolute arm joints: the lift deflecting under the shoulder's (arm_2) gravity torque is in
m/(N·m), an arm joint under the lift's gravity force in rad/N. The cell: 80 calibration and 30
held-out rows, a tracker 3 m away (20 µm), the lift sagging 5e-5 m/(N·m) × arm_2's torque (|tau| up
to ~30 N·m: up to ~1.5 mm, 75 × the noise); the plausible range of a prismatic joint's compliance to a
revolute joint's torque is 1e-3 m/(N·m) (pincal.diagnosis.verdicts.PLAUSIBLE).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

import pincal.diagnosis.diagnose as diagnose_module
from pincal.cli.commands import main
from pincal.diagnosis.verdicts import torque_coupling_advice
from pincal.measurements.csv_v1 import write_measurements
from pincal.model.chain import KinematicChain
from pincal.model.effect_units import effect_unit, value_unit
from pincal.model.effects import Effect
from pincal.model.parameter_sets import PlacementErrors
from pincal.report.effects_file import effects_document
from pincal.report.sections import effects_section
from pincal.robots import example_robot_data_urdf
from pincal.simulation.cells import measure_truth, sensor_at
from pincal.simulation.sensor import SimulatedEffects, SimulatedSensor, random_configurations

TIAGO = example_robot_data_urdf("tiago_description/robots/tiago.urdf")
TIP = "wrist_ft_tool_link"
SAG = Effect("compliance", "torso_lift_joint", driver="arm_2_joint")
SAG_VALUE = 5e-5  # m/(N·m)
KINDS = {"torso_lift_joint": "prismatic", "arm_1_joint": "revolute", "arm_2_joint": "revolute"}


def test_a_compliance_is_its_joints_shift_per_unit_of_the_load_it_follows():
    assert [value_unit("compliance", joint, driver) for joint, driver in
            ((False, None), (True, None), (False, False), (True, True), (False, True), (True, False))] == [
        "rad/(N·m)", "m/N", "rad/(N·m)", "m/N", "rad/N", "m/(N·m)"]
    assert effect_unit(SAG, KINDS) == "m/(N·m)"
    assert effect_unit(Effect("compliance", "arm_1_joint", driver="torso_lift_joint"), KINDS) == "rad/N"
    assert effect_unit(Effect("compliance", "torso_lift_joint"), KINDS) == "m/N"  # its own gravity force
    assert effect_unit(Effect("compliance", "arm_1_joint", driver="arm_2_joint"), KINDS) == "rad/(N·m)"
    # a reading coupling between a revolute and a prismatic joint is no longer a ratio
    assert effect_unit(Effect("coupling", "arm_1_joint", driver="torso_lift_joint"), KINDS) == "rad/m"
    assert effect_unit(Effect("coupling", "arm_1_joint", driver="arm_2_joint"), KINDS) == "(relative)"


@pytest.fixture(scope="module")
def cell(tmp_path_factory) -> Path:
    chain = KinematicChain.from_urdf(TIAGO, TIP)
    params = PlacementErrors(chain)
    rng = np.random.default_rng(5)
    truth = rng.normal(0.0, 3e-4, params.size)
    folder = tmp_path_factory.mktemp("effect_units")
    for count, role, name in ((80, "calibration", "cal.csv"), (30, "validation", "val.csv")):
        q = random_configurations(chain, rng, count)
        rows = measure_truth(params, truth, q, sensor_at(3.0), rng,
                             SimulatedSensor(20e-6, 0.0, points=np.array([[0.0, 0.0, 0.05]])), role,
                             effects=SimulatedEffects(effects=[(SAG, np.array([SAG_VALUE]))]))
        write_measurements(folder / name, rows)
    return folder


def test_a_lift_sagging_under_the_shoulders_torque_is_stated_in_m_per_newton_metre(cell, monkeypatch, capsys):
    """Console, REPORT.json's advice, effects.yaml and the HTML page say m/(N·m) (mm/(N·m) on the page)."""
    monkeypatch.setattr(diagnose_module, "candidate_effects", lambda chain, has_time, lateral=False: [SAG])
    out, report, html = cell / "d.urdf", cell / "d" / "REPORT.json", cell / "d" / "REPORT.html"
    assert main(["diagnose", str(TIAGO), str(cell / "cal.csv"), "--validation", str(cell / "val.csv"),
                 "--tip-link", TIP, "--quiet", "--out", str(out), "--report", str(report), "--html", str(html)]) == 0
    printed = capsys.readouterr().out
    (line,) = [text for text in printed.splitlines() if text.startswith("final model: compliance")]
    assert " m/(N·m): " in line and "rad/" not in line
    (effect,) = json.loads(report.read_text(encoding="utf-8"))["effects"]
    assert abs(effect["value"] - SAG_VALUE) < 5 * effect["std"]
    assert f"deflects by {effect['value']:.4g} m/(N·m) x arm_2_joint's gravity torque" in effect["advice"]
    (entry,) = yaml.safe_load((cell / "d.effects.yaml").read_text(encoding="utf-8"))["effects"]
    assert entry["unit"] == "m/(N·m)"
    page = html.read_text(encoding="utf-8")
    assert "mm/(N·m)" in page and "mrad/(N·m)" not in page


def test_an_arm_joint_under_the_lifts_gravity_force_is_stated_in_rad_per_newton():
    """The same statements from a report whose compliance follows a prismatic joint's load (a force)."""
    effect = Effect("compliance", "arm_1_joint", driver="torso_lift_joint")
    entry = {"type": "compliance", "joint": "arm_1_joint", "driver": "torso_lift_joint", "value": 2e-5, "std": 1e-6}
    report = {"chain": {"joints": list(KINDS), "joint_kinds": list(KINDS.values())}, "effects": [entry],
              "diagnosis": {"steps": [{"effect": entry}], "last_candidates": [{**entry, "delta_bic": -50.0}]}}
    assert effects_document(report, "x.urdf", "REPORT.json")["effects"][0]["unit"] == "rad/N"
    section = effects_section(report, KINDS, Path("."), lambda path: None)
    assert section is not None
    shown = [section["final"][0]["value"], section["steps"][0]["value"], section["candidates"][0]["value"]]
    assert all(text.endswith(" mrad/N") for text in shown), shown
    assert "2e-05 rad/N x torso_lift_joint's gravity force" in torque_coupling_advice(effect, 2e-5, "rad/N")


def test_a_compliance_says_its_sign_convention_and_stiffness():
    """c < 0 is a joint that sags under its holding torque (pincal.model.effects: actual = reading + c·τ, τ
    Pinocchio's generalized gravity), its stiffness 1/|c|; a prismatic joint's in N/m."""
    from pincal.report.diagnosis import compliance_words

    sag = compliance_words("A2", -2e-4, "rad/(N·m)")
    assert "c = -0.0002 rad/(N·m), a stiffness of 5e+03 N·m/rad" in sag and "gives way under its load" in sag
    lean = compliance_words("A2", 2e-4, "rad/(N·m)")
    assert "c > 0: it moves against the gravity torque" in lean and "stiffness of" not in lean
    lift = compliance_words("lift", -1e-6, "m/N")
    assert "gravity force" in lift and "a stiffness of 1e+06 N/m" in lift
