"""effects.yaml beside the corrected URDF: what a URDF cannot carry, for a controller
(:mod:`pincal.report.effects_file`).

The cell: example-robot-data's UR5 measured by a tracker 3 m away in 6D (20 µm, 0.003°), 150
calibration and 60 held-out rows, whose controller reads the elbow from the horizontal (reading =
J3 − J2) and whose elbow deflects by 5e-5 rad/(N·m) × the shoulder-lift torque (as in
tests/test_torque_coupling.py). Shifts from the file and from REPORT.json must agree to 1e-12 rad:
the same numbers, written by PyYAML as Python's shortest round-trip repr, so only the rounding of
evaluating the same formula twice (~1e-16 rad) may differ.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml

from pincal.cli.commands import main
from pincal.errors import PincalError
from pincal.measurements.couplings import corrected_angles
from pincal.measurements.csv_v1 import read_measurements, write_measurements
from pincal.model.chain import KinematicChain
from pincal.model.effects import Effect, effect_from_dict, effect_inputs, joint_shifts
from pincal.model.parameter_sets import PlacementErrors
from pincal.report.document import read_report
from pincal.report.effects_file import SCHEMA, effects_path, read_effects_file, write_effects_file
from pincal.robots import example_robot_data_urdf
from pincal.simulation.cells import measure_truth, sensor_at
from pincal.simulation.sensor import SimulatedEffects, SimulatedSensor, random_configurations

UR5 = example_robot_data_urdf("ur_description/urdf/ur5_robot.urdf")
SAME_RAD = 1e-12
ELBOW = ["--coupling", "elbow_joint=-1*shoulder_lift_joint"]


@pytest.fixture(scope="module")
def chain():
    return KinematicChain.from_urdf(UR5, "tool0")


@pytest.fixture(scope="module")
def cell(chain, tmp_path_factory):
    """calibration and held-out CSV files of the module docstring's cell."""
    params = PlacementErrors(chain)
    rng = np.random.default_rng(21)
    truth = rng.normal(0.0, 3e-4, params.size)
    hidden = [(Effect("compliance", "elbow_joint", driver="shoulder_lift_joint"), np.array([5e-5]))]
    folder = tmp_path_factory.mktemp("effects_file")
    for count, role, name in ((150, "calibration", "cal.csv"), (60, "validation", "val.csv")):
        q = random_configurations(chain, rng, count)
        q[:, 1:3] = rng.uniform(-np.pi / 2, np.pi / 2, (count, 2))  # J3 − J2 within J3's limits (±π)
        rows = measure_truth(params, truth, q, sensor_at(3.0), rng,
                             SimulatedSensor(20e-6, np.radians(0.003), points=np.array([[0.03, 0.0, 0.1]])), role,
                             effects=SimulatedEffects(effects=hidden))
        read = q.copy()
        read[:, 2] -= q[:, 1]  # the controller reads the elbow from the horizontal
        write_measurements(folder / name, replace(rows, q=read))
    return folder


def _shifts(chain, data, effects, payload_kg, point):
    inputs = effect_inputs(chain, data, payload_kg, point)
    return joint_shifts([e for e, _ in effects], [v for _, v in effects], inputs, chain.joint_names)


def test_diagnose_writes_what_the_urdf_cannot_carry_and_it_reads_back_as_the_report(chain, cell, capsys):
    out = cell / "d.urdf"
    assert main(["diagnose", str(UR5), str(cell / "cal.csv"), "--validation", str(cell / "val.csv"), "--tip-link",
                 "tool0", *ELBOW, "--quiet", "--out", str(out), "--report", str(cell / "d" / "REPORT.json")]) == 0
    printed = capsys.readouterr().out
    path = effects_path(out)
    assert path == cell / "d.effects.yaml"
    assert f"the URDF cannot carry 1 coupling and 1 effect: written to {path} (for a controller)" in printed
    document = yaml.safe_load(path.read_text(encoding="utf-8"))
    (effect,) = document["effects"]
    assert (effect["type"], effect["driver"], effect["unit"], effect["side"]) == (
        "compliance", "shoulder_lift_joint", "rad/(N·m)", "joint")
    assert "value x tau(q)[shoulder_lift_joint]" in effect["equation"]
    assert document["couplings"][0]["equation"].startswith(
        "q[elbow_joint] = r[elbow_joint] - factor x r[shoulder_lift_joint]")
    docs = _docs_listing()  # the example docs/diagnose.md shows: the keys of a file written
    assert list(docs) == list(document) and [list(e) for e in docs["effects"]] == [list(e) for e in document["effects"]]
    assert [list(c) for c in docs["couplings"]] == [list(c) for c in document["couplings"]]
    report = read_report(cell / "d" / "REPORT.json")
    carried = read_effects_file(path)
    assert carried.urdf == str(out) and carried.urdf_sha256 == report.urdf_sha256
    assert carried.couplings == report.couplings  # eq C1 the same
    readings = read_measurements(cell / "val.csv", chain.joint_specs)[0]
    corrected = replace(readings, q=corrected_angles(readings.q, carried.couplings, chain.joint_names))
    from_report = _shifts(chain, corrected, [effect_from_dict(e) for e in report.effects["effects"]],
                          report.effects["payload_kg"], report.points.mean(axis=0))
    from_file = _shifts(chain, corrected, carried.effects, carried.payload_kg, carried.payload_point_m)
    assert np.abs(from_report).max() > 1e-3  # the effect acts (~mrad), so agreeing means something
    assert np.abs(from_file - from_report).max() <= SAME_RAD


def test_calibrate_writes_couplings_only_and_a_plain_run_removes_its_stale_file(cell, capsys):
    out, report = cell / "c.urdf", cell / "c.json"
    common = [str(UR5), str(cell / "cal.csv"), "--tip-link", "tool0", "--quiet", "--out", str(out),
              "--report", str(report)]
    assert main(["calibrate", *common, *ELBOW]) in (0, 3)
    carried = read_effects_file(effects_path(out))
    assert [c.label for c in carried.couplings] == ["elbow_joint=-1*shoulder_lift_joint"] and carried.effects == ()
    assert "the URDF cannot carry 1 coupling: written to" in capsys.readouterr().out
    assert main(["calibrate", *common]) in (0, 3)  # no coupling, no effect: the old file would mislead
    assert not effects_path(out).exists() and "cannot carry" not in capsys.readouterr().out
    foreign = effects_path(out)
    foreign.write_text("not: ours\n", encoding="utf-8")  # a file pincal did not write is left alone
    assert main(["calibrate", *common]) in (0, 3) and foreign.read_text(encoding="utf-8") == "not: ours\n"


def test_every_effect_type_reads_back_with_its_unit_side_and_shift(chain, tmp_path):
    """A report with one effect of each type: the file's effects give the report's shifts; the sensor's
    are marked measurement-side."""
    entries = [{"type": "compliance", "joint": "elbow_joint", "value": 3e-5},
               {"type": "compliance", "joint": "elbow_joint", "value": 2e-5, "driver": "shoulder_lift_joint"},
               {"type": "encoder_scale", "joint": "wrist_1_joint", "value": 1e-3},
               {"type": "cyclic", "joint": "wrist_2_joint", "harmonic": 2, "sin": 1e-4, "cos": -2e-4},
               {"type": "backlash", "joint": "shoulder_lift_joint", "value": 5e-4, "source": "gravity"},
               {"type": "backlash", "joint": "wrist_3_joint", "value": 4e-4, "source": "approach"},
               {"type": "coupling", "joint": "wrist_1_joint", "value": 2e-3, "driver": "elbow_joint"},
               {"type": "drift", "joint": None, "value": [1e-7, 0.0, -2e-7]},
               {"type": "sensor_scale", "joint": None, "value": 1e-5},
               {"type": "pause_step", "joint": None, "value": [0.0, -7.6e-5, 0.0], "pause": 1},
               {"type": "thermal", "joint": None, "value": 1.2e-5}]
    report = {"effects": entries, "payload_kg": 1.5, "time_reference_s": 12.0, "temperature_column": "temperature_c",
              "temperature_range_c": {"min": 20.0, "max": 26.0, "mean": 23.5},
              "tool": {"parent_link": "tool0", "points_m": [[0.0, 0.0, 0.1], [0.02, 0.0, 0.1]]},
              "chain": {"joints": list(chain.joint_names), "joint_kinds": ["revolute"] * 6}, "urdf_sha256": None}
    path = write_effects_file(tmp_path / "x.urdf", tmp_path / "REPORT.json", report)
    assert path == tmp_path / "x.effects.yaml"
    document = yaml.safe_load(path.read_text(encoding="utf-8"))
    assert document["schema"] == SCHEMA and [e["side"] for e in document["effects"]] == ["joint"] * 7 + [
        "measurement"] * 3 + ["geometry"]  # thermal scales the URDF's lengths: no joint shift
    assert [e["unit"] for e in document["effects"]] == ["rad/(N·m)"] * 2 + ["(relative)", "rad", "rad", "rad",
                                                                           "(relative)", "m/s", "(relative)", "m",
                                                                           "1/K"]
    assert "(T - 23.5 degC)" in document["effects"][-1]["equation"]
    assert (document["effects"][-1]["temperature_reference_c"], document["effects"][-1]["temperature_range_c"],
            document["effects"][-1]["temperature_column"]) == (23.5, [20.0, 26.0], "temperature_c")
    assert any("side geometry" in line for line in document["apply"])
    assert "after the calibration's pause" in document["effects"][-2]["equation"]
    carried = read_effects_file(path)
    assert carried.payload_point_m.tolist() == [0.01, 0.0, 0.1] and carried.payload_kg == 1.5
    rows = _rows(chain, random_configurations(chain, np.random.default_rng(4), 30))
    expected = _shifts(chain, rows, [effect_from_dict(e) for e in entries], 1.5, np.array([0.01, 0.0, 0.1]))
    assert np.abs(expected).max() > 1e-4
    assert np.abs(_shifts(chain, rows, carried.effects, carried.payload_kg, carried.payload_point_m)
                  - expected).max() <= SAME_RAD


def _rows(chain, q):
    """Rows of readings ``q`` (their targets unused: shifts depend on the readings only)."""
    from pincal.simulation.sensor import DEFAULT_REGISTRATION, measure

    return measure(chain, q, DEFAULT_REGISTRATION, np.random.default_rng(0), SimulatedSensor(0.0, 0.0), "calibration")


def test_a_file_that_is_not_one_is_refused_in_one_line(tmp_path):
    for text in ("schema: other\n", "[1, 2]\n", f"schema: {SCHEMA}\nschema_version: 99\n"):
        (tmp_path / "e.yaml").write_text(text, encoding="utf-8")
        with pytest.raises(PincalError, match="e.yaml: not a readable pincal effects.yaml"):
            read_effects_file(tmp_path / "e.yaml")


def _docs_listing() -> dict:
    """The effects.yaml listing of docs/diagnose.md (its section 'effects.yaml for a controller')."""
    page = (Path(__file__).resolve().parents[1] / "docs" / "diagnose.md").read_text(encoding="utf-8")
    section = page[page.index("## effects.yaml for a controller"):]
    return yaml.safe_load(section[section.index("```yaml") + len("```yaml"):].split("```")[0])
