"""Joints that follow another (URDF ``<mimic>``, eq M1 of pincal.measurements.mimics).

The cell: the 6-axis arm of tests/conftest.py whose A3 follows A2 (``<mimic joint="A2" multiplier="-0.5"
offset="0.3">``, a linkage that keeps the forearm near level), measured noise-free in 6D: 40 calibration and
20 held-out postures, the files without a column for A3. Noise-free rows leave nothing but round-off, so
the calibrated model reproduces the held-out rows to ~1e-9 mm (bound 1e-6 mm).
"""

from __future__ import annotations

import csv
import json
import re
from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest
import yaml
from conftest import assert_close, numeric_jacobian

from pincal.cli.commands import main
from pincal.errors import MeasurementError, ModelError
from pincal.measurements.couplings import ReadingCoupling, decide_followers, parse_coupling
from pincal.measurements.csv_v1 import read_joint_columns, read_measurements, read_table, write_measurements
from pincal.measurements.data import JointMimic
from pincal.measurements.mimics import last_digit
from pincal.model.chain import KinematicChain
from pincal.model.effects import Effect, EffectInputs, gravity_torques
from pincal.model.parameter_sets import PlacementErrors
from pincal.model.sensor import Registration
from pincal.residuals.base import KinematicsCache
from pincal.residuals.sensor import SensorResidual, TargetEstimate
from pincal.residuals.sensor_values import ModelledEffects, RowWeights
from pincal.simulation.cells import measure_truth, sensor_at
from pincal.simulation.sensor import SimulatedSensor, random_configurations, sampling_limits

MIMIC = '<mimic joint="A2" multiplier="-0.5" offset="0.3"/>'
A3_LIMIT = 'lower="-2.2689280275926285" upper="2.6878070480712677"/>'
NOISE_FREE_MM = 1e-6  # round-off of noise-free rows: ~1e-9 mm


def _with_mimic(text: str, joint_limit: str, mimic: str) -> str:
    assert text.count(joint_limit) == 1
    return text.replace(joint_limit, f"{joint_limit}\n    {mimic}")


@pytest.fixture(scope="module")
def cell(industrial_arm_urdf, tmp_path_factory):
    """The URDF with A3 following A2, and the rows with (``full_*``) and without A3's column."""
    folder = tmp_path_factory.mktemp("mimic")
    urdf = folder / "arm.urdf"
    urdf.write_text(_with_mimic(industrial_arm_urdf.read_text(encoding="utf-8"), A3_LIMIT, MIMIC), encoding="utf-8")
    _measure(urdf, folder, 3)
    return folder


def _measure(urdf, folder, seed: int) -> None:
    """Noise-free 6D rows of the chain of ``urdf`` to 'flange' (40 calibration, 20 validation postures), written
    with (``full_*``) and without A3's column."""
    chain = KinematicChain.from_urdf(urdf, "flange")
    params = PlacementErrors(chain)
    rng = np.random.default_rng(seed)
    truth = rng.normal(0.0, 3e-4, params.size)
    keep = [0, 1, 3, 4, 5]
    for count, role in ((40, "calibration"), (20, "validation")):
        rows = measure_truth(params, truth, random_configurations(chain, rng, count), sensor_at(3.0), rng,
                             SimulatedSensor(0.0, 0.0, points=np.array([[0.03, 0.0, 0.1]])), role)
        write_measurements(folder / f"full_{role}.csv", rows)
        write_measurements(folder / f"{role}.csv", replace(rows, joint_names=tuple(rows.joint_names[i] for i in keep),
                                                           q=rows.q[:, keep]))


def test_the_chain_reads_the_tag_and_follows_it(cell):
    chain = KinematicChain.from_urdf(cell / "arm.urdf", "flange")
    assert chain.joints[2].mimic == JointMimic("A2", -0.5, 0.3) and chain.joints[1].mimic is None
    q = np.arange(12.0).reshape(2, 6) / 10
    assert np.array_equal(chain.followed(q)[:, 2], -0.5 * q[:, 1] + 0.3)
    lower, upper = sampling_limits(chain)  # A3 spans what A2's range gives it, within its own limits
    assert lower[2] == pytest.approx(-0.5 * upper[1] + 0.3) and upper[2] == pytest.approx(-0.5 * lower[1] + 0.3)
    data, _ = read_measurements(cell / "calibration.csv", chain.joint_specs)
    assert data.joint_names == chain.joint_names and np.array_equal(data.q[:, 2], -0.5 * data.q[:, 1] + 0.3)
    full, _ = read_measurements(cell / "full_calibration.csv", chain.joint_specs)
    assert np.array_equal(full.q, data.q)  # a consistent column: the same numbers


def test_a_column_that_disagrees_is_named_by_line_and_column(cell, tmp_path):
    chain = KinematicChain.from_urdf(cell / "arm.urdf", "flange")
    rows = list(csv.reader((cell / "full_calibration.csv").open(encoding="utf-8")))
    rounded = [rows[0]] + [[f"{float(v):.4f}" if i < 3 else v for i, v in enumerate(r)] for r in rows[1:]]
    with (tmp_path / "rounded.csv").open("w", newline="", encoding="utf-8") as handle:
        csv.writer(handle).writerows(rounded)  # 4 decimals: held to their rounding, 5e-5 + 0.5 x 5e-5 rad
    read_measurements(tmp_path / "rounded.csv", chain.joint_specs)
    rows[5][2] = repr(float(rows[5][2]) + 1e-3)
    with (tmp_path / "bad.csv").open("w", newline="", encoding="utf-8") as handle:
        csv.writer(handle).writerows(rows)
    with pytest.raises(MeasurementError, match=r"bad.csv: line 6, column 'A3': .* is not what its <mimic> gives, "
                                               r"-0.5 x A2 .* differ by 0.001, more than the cells' rounding"):
        read_measurements(tmp_path / "bad.csv", chain.joint_specs)
    assert last_digit("0.1235") == pytest.approx(1e-4) and last_digit("1.5e-3") == pytest.approx(1e-4)
    assert last_digit("2") == 1.0


def test_a_driver_off_the_chain_gives_the_column(industrial_arm_urdf, tmp_path):
    """A5 follows B, a joint on another branch: B's column gives A5; neither column is one clear error; a
    --coupling on a joint without a column makes it follow its driver likewise."""
    text = industrial_arm_urdf.read_text(encoding="utf-8").replace("</robot>", (
        '  <link name="aux"/>\n  <joint name="B" type="revolute"><parent link="base_link"/><child link="aux"/>'
        '<axis xyz="0 0 1"/><limit effort="1" velocity="1" lower="-1" upper="1"/></joint>\n</robot>'))
    urdf = tmp_path / "branch.urdf"
    urdf.write_text(_with_mimic(text, 'lower="-2.2689280275926285" upper="2.2689280275926285"/>',
                                '<mimic joint="B" multiplier="2"/>'), encoding="utf-8")
    chain = KinematicChain.from_urdf(urdf, "flange")
    assert chain.joints[4].mimic == JointMimic("B", 2.0, 0.0) and "B" in chain.other_branch_joints
    header = "A1,A2,A3,A4,A6,B,x,y,z\n"
    (tmp_path / "b.csv").write_text(header + "0.1,0.2,0.3,0.4,0.6,0.25,1,2,3\n", encoding="utf-8")
    data, notes = read_measurements(tmp_path / "b.csv", chain.joint_specs)
    assert data.q[0, 4] == 0.5 and "B" not in data.extra and not any("extra" in n for n in notes)
    (tmp_path / "n.csv").write_text("A1,A2,A3,A4,A6,x,y,z\n0.1,0.2,0.3,0.4,0.6,1,2,3\n", encoding="utf-8")
    with pytest.raises(MeasurementError, match="n.csv: no column for joint 'A5' nor for 'B', which it follows "
                                               r"\(q = 2 x B \+ 0\); add a column 'B' \(or 'A5'\)"):
        read_measurements(tmp_path / "n.csv", chain.joint_specs)
    plain = KinematicChain.from_urdf(industrial_arm_urdf, "flange")
    columns = [read_table(tmp_path / "n.csv").names]
    decided = decide_followers([parse_coupling("A5=-1.5*A4")], plain.joint_names, columns)
    assert decided == (ReadingCoupling("A5", -1.5, "A4", follows=True),)
    data, _ = read_measurements(tmp_path / "n.csv", plain.joint_specs, decided)
    assert data.q[0, 4] == -1.5 * 0.4 and np.array_equal(data.q[0, [0, 1, 2, 3, 5]], [0.1, 0.2, 0.3, 0.4, 0.6])
    with pytest.raises(MeasurementError, match="--coupling A9=1\\*A2: no joint 'A9' on the chain"):
        read_measurements(tmp_path / "b.csv", chain.joint_specs, [parse_coupling("A9=1*A2")])  # still checked
    with pytest.raises(MeasurementError, match="joint 'A5' follows 'B' by the URDF's <mimic>"):
        read_measurements(tmp_path / "b.csv", chain.joint_specs, [parse_coupling("A5=1*A4")])
    # plan: PLAN.csv gives B, the joint the controller commands, after the chain's columns, and reads back
    assert main(["plan", str(urdf), "--tip-link", "flange", "--count", "9", "--sample", "40", "--quiet",
                 "--out", str(tmp_path / "p.csv"), "--report", str(tmp_path / "p.json")]) == 0
    header = (tmp_path / "p.csv").read_text(encoding="utf-8").splitlines()[0]
    assert header == "A1,A2,A3,A4,A5,A6,B,priority,candidate"
    q, _ = read_joint_columns(tmp_path / "p.csv", chain.joint_specs)
    both = np.loadtxt(tmp_path / "p.csv", delimiter=",", skiprows=1, usecols=(4, 6))
    assert np.allclose(both[:, 0], 2.0 * both[:, 1], rtol=0, atol=1e-15) and np.array_equal(q[:, 4], both[:, 0])


def test_a_mimic_naming_no_joint_is_refused(cell, tmp_path):
    bad = tmp_path / "bad.urdf"
    text = (cell / "arm.urdf").read_text(encoding="utf-8")
    bad.write_text(text.replace('joint="A2"', 'joint="A9"'), encoding="utf-8")
    with pytest.raises(ModelError, match="joint 'A3': <mimic joint=\"A9\"> names no other movable joint"):
        KinematicChain.from_urdf(bad, "flange")
    assert KinematicChain.from_urdf(bad, "link_2").n_joints == 2  # off the chain: not this calibration's business


def _calibrate(cell, tmp_path, rows: str, name: str) -> dict:
    assert main(["calibrate", str(cell / "arm.urdf"), str(cell / rows), "--tip-link", "flange", "--quiet",
                 "--out", str(tmp_path / f"{name}.urdf"), "--report", str(tmp_path / f"{name}.json")]) == 0
    return json.loads((tmp_path / f"{name}.json").read_text(encoding="utf-8"))


def test_calibrate_and_evaluate_without_the_column(cell, tmp_path, capsys):
    """Noise-free rows without A3's column: the held-out rows reproduced; the same parameters as with a
    consistent column; the corrected URDF keeps the tag and reads back to the same kinematics."""
    report = _calibrate(cell, tmp_path, "calibration.csv", "a")
    assert report["identifiability"]["rank"] == 18  # of 42, as with A3 free (docs/calibrate.md)
    assert report["chain"]["mimics"] == [{"joint": "A3", "driver": "A2", "multiplier": -0.5, "offset": 0.3}]
    assert main(["report", str(tmp_path / "a.json"), "--out", str(tmp_path / "a.html")]) == 0
    assert report["parameters"] == _calibrate(cell, tmp_path, "full_calibration.csv", "b")["parameters"]
    written = (tmp_path / "a.urdf").read_text(encoding="utf-8")
    assert MIMIC in written
    assert main(["evaluate", str(tmp_path / "a.urdf"), str(tmp_path / "a.json"), str(cell / "validation.csv"),
                 "--json", str(tmp_path / "e.json")]) == 0
    assert json.loads((tmp_path / "e.json").read_text(encoding="utf-8"))["position"]["rms_mm"] < NOISE_FREE_MM
    chain = KinematicChain.from_urdf(tmp_path / "a.urdf", "flange")
    assert chain.joints[2].mimic == JointMimic("A2", -0.5, 0.3)
    capsys.readouterr()


def test_plan_draws_and_writes_the_follower_with_its_driver(cell, tmp_path):
    assert main(["plan", str(cell / "arm.urdf"), "--tip-link", "flange", "--count", "4", "--sample", "100",
                 "--existing", str(cell / "calibration.csv"), "--quiet",
                 "--out", str(tmp_path / "p.csv"), "--report", str(tmp_path / "p.json")]) == 0
    chain = KinematicChain.from_urdf(cell / "arm.urdf", "flange")
    q, _ = read_joint_columns(tmp_path / "p.csv", chain.joint_specs)  # its A3 column passes the check
    assert len(q) == 4 and np.allclose(q[:, 2], -0.5 * q[:, 1] + 0.3, rtol=0, atol=1e-15)
    ranges = json.loads((tmp_path / "p.json").read_text(encoding="utf-8"))["candidates"]["joint_ranges"]
    assert [r["source"] for r in ranges[1:3]] == ["URDF limits", "follows its driver"]
    assert ranges[2]["lower"] == pytest.approx(np.degrees(-0.5 * np.radians(ranges[1]["upper"]) + 0.3))


def test_a_drivers_effects_move_its_follower_and_their_jacobian_says_so(cell):
    """An effect on A2 changes A2's actual angle and so A3's (x -0.5, eq M1 differentiated): the residual
    at effect value s is the plain residual at those angles, and its Jacobian matches central differences
    (the driver's joint column gains -0.5 x the follower's)."""
    chain = KinematicChain.from_urdf(cell / "arm.urdf", "flange")
    rng = np.random.default_rng(8)
    params = PlacementErrors(chain)
    q = random_configurations(chain, rng, 9)
    effects = [Effect("encoder_scale", "A2"), Effect("cyclic", "A2", harmonic=1),
               Effect("coupling", "A4", driver="A2")]
    inputs = EffectInputs(q=q, gravity=gravity_torques(chain, q), time=None, order=np.arange(9),
                          joint_names=chain.joint_names)
    free = np.arange(params.size)[::3]
    start = TargetEstimate(Registration(pin.exp3(rng.normal(size=3)), rng.normal(size=3)),
                           rng.normal(0, 0.1, (2, 3)), pin.exp3(rng.normal(size=3)))
    rotations = np.stack([pin.exp3(rng.normal(size=3)) for _ in q])
    sensed = rng.normal(size=(9, 2, 3))
    nominal = rng.normal(0, 1e-3, params.size)

    def objective(effects, at):
        cache = KinematicsCache(params, free, nominal, at)
        return SensorResidual(cache, sensed, rotations, start, RowWeights(rotation=2.0),
                              effects=ModelledEffects(effects, inputs) if effects else None)

    with_effects = objective(effects, q)
    x = with_effects.start_vector()
    x[with_effects.blocks["effects"]] = [0.01, 0.02, -0.03, 0.005]
    shifts = np.zeros_like(q)
    shifts[:, 1] = 0.01 * q[:, 1] + 0.02 * np.sin(q[:, 1]) - 0.03 * np.cos(q[:, 1])
    shifts[:, 3] = 0.005 * q[:, 1]
    moved = q + shifts
    moved[:, 2] += -0.5 * shifts[:, 1]  # A3 follows A2's actual angle
    plain = objective([], moved)
    assert_close(with_effects.residual(x), plain.residual(x[: plain.n_free]), 1e-12, "followed shifts")
    assert_close(with_effects.jacobian(x), numeric_jacobian(with_effects.residual, x), 1e-6, "chained columns")


def test_a_driver_carries_its_followers_gravity_load(kuka_urdf, tmp_path):
    """KUKA's joint 4 following joint 2 (x0.7, +0.1): joint 2's gravity torque is the derivative of the
    potential energy along the tied motion, tau_2 + 0.7 tau_4 (virtual work); joint 4's its own."""
    text = kuka_urdf.read_text(encoding="utf-8")
    limit = 'velocity="2.2689280275926285" lower="-2.0943951023931953" upper="2.0943951023931953"/>'
    (tmp_path / "kuka.urdf").write_text(_with_mimic(text, limit, '<mimic joint="lwr_joint_2" multiplier="0.7" '
                                                                 'offset="0.1"/>'), encoding="utf-8")
    chain = KinematicChain.from_urdf(tmp_path / "kuka.urdf", "lwr_link_7")
    q = chain.followed(np.array([[0.2, 0.5, -0.3, 0.0, 0.4, -0.6, 0.1]]))
    model, data = chain.model, chain.model.createData()

    def potential(q2):
        moved = q.copy()
        moved[0, 1] = q2[0]
        return np.array([pin.computePotentialEnergy(model, data, chain.followed(moved)[0])])

    torque = gravity_torques(chain, q)[0]
    # central differences, step 1e-6 rad: ~1e-12 x third derivatives of ~100 J, far below 1e-6 N m
    assert torque[1] == pytest.approx(numeric_jacobian(potential, q[0, 1:2])[0, 0], abs=1e-6)
    assert torque[3] == pytest.approx(pin.computeGeneralizedGravity(model, data, q[0])[3], abs=1e-12)
    assert abs(torque[1] - pin.computeGeneralizedGravity(model, data, q[0])[1]) > 1.0  # N m: informative
    # without a mass model the loads per mass moment carry the follower's the same way (eq M2 with the URDF's
    # inertias is these torques, to rounding)
    from pincal.model.mass_moments import gravity_loads

    pi = np.concatenate([model.inertias[j].toDynamicParameters()[:4] for j in chain.joint_ids])
    g0 = np.linalg.norm(model.gravity.linear)
    np.testing.assert_allclose(gravity_loads(chain, q)[0, :, 0, :] @ pi * g0, torque, atol=1e-10)


def test_a_follower_that_fixes_the_forearm_costs_what_the_report_names(cell, tmp_path):
    """A3 following A2 by -1 (A2 ∥ A3): the forearm's attitude never changes, and the identifiability
    report drops A4.tx and A4.tz too (16 of 42 identifiable, against 18 by -0.5), with no values."""
    urdf = tmp_path / "upright.urdf"
    urdf.write_text((cell / "arm.urdf").read_text(encoding="utf-8").replace('multiplier="-0.5"', 'multiplier="-1"'),
                    encoding="utf-8")
    chain = KinematicChain.from_urdf(urdf, "flange")
    params = PlacementErrors(chain)
    rng = np.random.default_rng(3)
    rows = measure_truth(params, rng.normal(0.0, 3e-4, params.size), random_configurations(chain, rng, 40),
                         sensor_at(3.0), rng, SimulatedSensor(1e-5, 1e-4, points=np.array([[0.03, 0.0, 0.1]])))
    write_measurements(tmp_path / "upright.csv", rows)
    assert main(["calibrate", str(urdf), str(tmp_path / "upright.csv"), "--tip-link", "flange", "--quiet",
                 "--out", str(tmp_path / "u.urdf"), "--report", str(tmp_path / "u.json")]) == 0
    report = json.loads((tmp_path / "u.json").read_text(encoding="utf-8"))
    assert report["identifiability"]["rank"] == 16
    dropped = {d["name"]: d for d in report["identifiability"]["dropped"]}
    assert {"A4.tx", "A4.tz"} <= set(dropped)
    values = {p["name"]: p for p in report["parameters"]}
    assert values["A4.tx"]["calibrated"] is None and values["A4.tz"]["calibrated"] is None


def test_diagnose_names_a_wrong_multiplier(cell, tmp_path, capsys):
    """The linkage moves A3 by -0.45 x A2, the URDF says -0.5: diagnose adopts the coupling of A3 to A2 (+0.05)
    and says which multiplier the <mimic> should have; no convention (a follower has no reading)."""
    chain = KinematicChain.from_urdf(cell / "arm.urdf", "flange")
    params = PlacementErrors(chain)
    rng = np.random.default_rng(5)
    truth = rng.normal(0.0, 3e-4, params.size)
    keep = [0, 1, 3, 4, 5]
    for count, role in ((60, "calibration"), (30, "validation")):
        q = random_configurations(chain, rng, count)
        actual = q.copy()
        actual[:, 2] = -0.45 * q[:, 1] + 0.3
        rows = measure_truth(params, truth, actual, sensor_at(3.0), rng,
                             SimulatedSensor(20e-6, np.radians(0.003), points=np.array([[0.03, 0.0, 0.1]])), role)
        write_measurements(tmp_path / f"{role}.csv", replace(rows, joint_names=tuple(rows.joint_names[i] for i in keep),
                                                             q=q[:, keep]))
    assert main(["diagnose", str(cell / "arm.urdf"), str(tmp_path / "calibration.csv"), "--validation",
                 str(tmp_path / "validation.csv"), "--tip-link", "flange", "--quiet", "--out", str(tmp_path / "d.urdf"),
                 "--report", str(tmp_path / "d" / "REPORT.json")]) == 0
    document = json.loads((tmp_path / "d" / "REPORT.json").read_text(encoding="utf-8"))
    (effect,) = document["effects"]
    assert effect["type"] == "coupling" and effect["joint"] == "A3" and effect["value"] == pytest.approx(0.05, abs=1e-3)
    assert "couplings" not in document
    assert ('A3 follows A2 by -0.45, not by its <mimic> multiplier -0.5: set multiplier="-0.45"'
            in " ".join(document["diagnosis"]["notes"]))
    # the same tie given by --coupling on the URDF without the tag: the flag is named, not the URDF (its 0.3 is
    # then A3's zero, 17 deg against the 0.5 deg prior scale, so the factor fitted is not -0.45 here: the words only)
    plain = cell.parent / "plain.urdf"
    plain.write_text((cell / "arm.urdf").read_text(encoding="utf-8").replace(MIMIC, ""), encoding="utf-8")
    assert main(["diagnose", str(plain), str(tmp_path / "calibration.csv"), "--validation",
                 str(tmp_path / "validation.csv"), "--tip-link", "flange", "--quiet", "--coupling", "A3=-0.5*A2",
                 "--out", str(tmp_path / "f.urdf"), "--report", str(tmp_path / "f.json")]) == 0
    document = json.loads((tmp_path / "f.json").read_text(encoding="utf-8"))
    assert document["couplings"] == [{"joint": "A3", "factor": -0.5, "driver": "A2", "follows": True}]
    assert re.search(r"A3 follows A2 by (-[0-9.]+), not by its --coupling factor -0.5: give --coupling A3=\1\*A2",
                     " ".join(document["diagnosis"]["notes"]))
    capsys.readouterr()


@pytest.fixture(scope="module")
def passive_a3(industrial_arm_urdf, tmp_path_factory):
    """The plain arm whose A3 is passive and follows A2 by 0.5 (no URDF tag: ``--coupling A3=0.5*A2``), measured
    noise-free: 40 calibration and 20 held-out postures, the files without A3's column and (``full_*``) with
    its true angle."""
    folder = tmp_path_factory.mktemp("passive")
    simulated = folder / "tied.urdf"  # only to draw the tied postures and measure them
    simulated.write_text(_with_mimic(industrial_arm_urdf.read_text(encoding="utf-8"), A3_LIMIT,
                                     '<mimic joint="A2" multiplier="0.5"/>'), encoding="utf-8")
    _measure(simulated, folder, 5)
    assert main(["calibrate", str(industrial_arm_urdf), str(folder / "calibration.csv"), "--tip-link", "flange",
                 "--coupling", "A3=0.5*A2", "--quiet", "--out", str(folder / "c.urdf"),
                 "--report", str(folder / "c.json")]) == 0
    return industrial_arm_urdf, folder


def test_a_coupling_that_follows_is_recorded_and_evaluated_as_it_was_decided(passive_a3, capsys):
    """--coupling A3=0.5*A2 on rows without A3's column: A3 follows A2 for the whole run, REPORT.json says so
    (couplings[].follows, chain.mimics), and evaluate computes A3 from A2 whether the evaluated file has A3's
    column (checked against eq M1) or not: the same errors, at the round-off."""
    _, folder = passive_a3
    report = json.loads((folder / "c.json").read_text(encoding="utf-8"))
    assert report["couplings"] == [{"joint": "A3", "factor": 0.5, "driver": "A2", "follows": True}]
    assert report["chain"]["mimics"] == [{"joint": "A3", "driver": "A2", "multiplier": 0.5, "offset": 0.0}]
    errors = []
    for rows in ("validation.csv", "full_validation.csv"):
        assert main(["evaluate", str(folder / "c.urdf"), str(folder / "c.json"), str(folder / rows),
                     "--json", str(folder / f"e_{rows}.json")]) == 0
        evaluated = json.loads((folder / f"e_{rows}.json").read_text(encoding="utf-8"))
        assert evaluated["warnings"] == []
        errors.append(evaluated["position"]["rms_mm"])
    assert errors[0] < NOISE_FREE_MM and errors[1] == pytest.approx(errors[0], abs=1e-12)
    capsys.readouterr()


def test_effects_yaml_gives_a_follower_from_its_driver(passive_a3):
    from pincal.report.effects_file import effects_path, read_effects_file

    _, folder = passive_a3
    document = yaml.safe_load(effects_path(folder / "c.urdf").read_text(encoding="utf-8"))
    (entry,) = document["couplings"]
    assert entry["follows"] is True and entry["equation"].startswith("q[A3] = factor x r[A2] (eq M1: A3 has no "
                                                                     "reading")
    assert any(line.startswith("an entry of couplings with follows") for line in document["apply"])
    assert read_effects_file(effects_path(folder / "c.urdf")).couplings == (
        ReadingCoupling("A3", 0.5, "A2", follows=True),)


def test_plan_takes_a_follower_from_the_files_and_gives_it_no_column(passive_a3, tmp_path):
    """plan --coupling A3=0.5*A2: a candidate file without A3's column is read (A3 from A2), and so are drawn
    candidates beside --existing rows without it; PLAN.csv has no A3 column (the controller has no reading),
    so calibrate on its rows decides the same; PLAN.json records follows."""
    urdf, folder = passive_a3
    common = ["plan", str(urdf), "--tip-link", "flange", "--count", "9", "--coupling", "A3=0.5*A2", "--quiet"]
    for name, source in (("c", ["--candidates", str(folder / "validation.csv")]),
                         ("e", ["--existing", str(folder / "calibration.csv"), "--sample", "100"])):
        assert main([*common, *source, "--out", str(tmp_path / f"{name}.csv"),
                     "--report", str(tmp_path / f"{name}.json")]) == 0
        header = (tmp_path / f"{name}.csv").read_text(encoding="utf-8").splitlines()[0]
        assert header == "A1,A2,A4,A5,A6,priority,candidate"
        sources = json.loads((tmp_path / f"{name}.json").read_text(encoding="utf-8"))["sources"]
        assert sources["couplings"] == [{"joint": "A3", "factor": 0.5, "driver": "A2", "follows": True}]
