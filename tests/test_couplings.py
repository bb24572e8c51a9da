"""--coupling JOINT=FACTOR*DRIVER: readings taken against another joint (pincal.measurements.couplings, eq C1).

The cell: the 6-axis arm of tests/conftest.py (A2 ∥ A3) whose controller reads A3 from the horizontal —
the reading is A3 − A2 — measured by a laser tracker 3 m away in 6D (20 µm, 0.003°), 150 calibration
and 60 held-out postures. Noise floor of the held-out RMS point distance: √3 · 20 µm = 35 µm; bound
1.3× it (the scenario suite's, scripts/scenarios.py), the estimation error of 27 unknowns from 900
coordinates adding ~10 %.
"""

from __future__ import annotations

import io
import json
from contextlib import redirect_stderr, redirect_stdout
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from pincal.cli.commands import main
from pincal.errors import MeasurementError, PincalError
from pincal.measurements.couplings import (
    ReadingCoupling,
    apply_couplings,
    check_couplings,
    corrected_angles,
    parse_coupling,
    readings_of,
)
from pincal.measurements.csv_v1 import write_measurements
from pincal.model.chain import KinematicChain
from pincal.model.parameter_sets import PlacementErrors
from pincal.simulation.cells import measure_truth, sensor_at
from pincal.simulation.sensor import SimulatedSensor, random_configurations

NOISE_M = 20e-6
BOUND_MM = 1.3 * np.sqrt(3) * NOISE_M * 1000.0


def test_the_flag_reads_joint_factor_and_driver():
    assert parse_coupling("A3=-1*A2") == ReadingCoupling("A3", -1.0, "A2")
    assert parse_coupling(" joint_3 = 0.5e-2 * joint_2 ") == ReadingCoupling("joint_3", 0.005, "joint_2")
    for bad in ("A3=-1", "A3=A2", "A3=0*A2", "A3=-1*A3", "A3=x*A2", "=-1*A2", "A3=nan*A2"):
        with pytest.raises(PincalError, match="JOINT=FACTOR\\*DRIVER"):
            parse_coupling(bad)


def test_eq_c1_takes_every_driver_as_read(industrial_arm_urdf):
    chain = KinematicChain.from_urdf(industrial_arm_urdf, "flange")
    data = measure_truth(PlacementErrors(chain), np.zeros(PlacementErrors(chain).size),
                         np.arange(12.0).reshape(2, 6) / 10, sensor_at(3.0), np.random.default_rng(0),
                         SimulatedSensor(0.0, 0.0))
    couplings = [parse_coupling("A3=-1*A2"), parse_coupling("A2=0.5*A3")]  # each from the readings, in any order
    for order in (couplings, couplings[::-1]):
        q = apply_couplings(data, order).q
        assert np.allclose(q[:, 2], data.q[:, 2] + data.q[:, 1]) and np.allclose(q[:, 1], data.q[:, 1] - 0.5 * data.q[:, 2])
    assert apply_couplings(data, []) is data and np.array_equal(data.q, np.arange(12.0).reshape(2, 6) / 10)
    with pytest.raises(MeasurementError, match="no joint 'A7' on the chain; joints: A1, A2"):
        check_couplings([parse_coupling("A3=-1*A7")], chain.joint_names)
    with pytest.raises(MeasurementError, match="joint 'A3' is given twice"):
        check_couplings([parse_coupling("A3=-1*A2"), parse_coupling("A3=0.1*A4")], chain.joint_names)


@pytest.fixture(scope="module")
def horizontal_j3(industrial_arm_urdf, tmp_path_factory):
    """CSV files of the cell of the module docstring: calibration and held-out rows."""
    chain = KinematicChain.from_urdf(industrial_arm_urdf, "flange")
    params = PlacementErrors(chain)
    rng = np.random.default_rng(21)
    truth = rng.normal(0.0, 3e-4, params.size)
    folder = tmp_path_factory.mktemp("horizontal_j3")
    paths = []
    for count, role, name in ((150, "calibration", "cal.csv"), (60, "validation", "val.csv")):
        read = random_configurations(chain, rng, count)
        actual = read.copy()
        actual[:, 2] += read[:, 1]  # the reading of A3 is A3 - A2
        rows = measure_truth(params, truth, actual, sensor_at(3.0), rng,
                             SimulatedSensor(NOISE_M, np.radians(0.003), points=np.array([[0.03, 0.0, 0.1]])), role)
        write_measurements(folder / name, replace(rows, q=read))
        paths.append(folder / name)
    return industrial_arm_urdf, *paths


def _held_out_mm(tmp_path, urdf, report, validation) -> float:
    out = tmp_path / "e.json"
    assert main(["evaluate", str(urdf), str(report), str(validation), "--json", str(out)]) == 0
    return json.loads(out.read_text(encoding="utf-8"))["position"]["rms_mm"]


@pytest.fixture(scope="module")
def coupled(horizontal_j3, tmp_path_factory):
    """calibrate --coupling A3=-1*A2 on the cell's calibration rows, and evaluate of its URDF and report on
    the held-out rows (once for the module: the tests that judge the flag's model read the same run): the
    REPORT.json, evaluate's --json document and what evaluate printed."""
    urdf, calibration, validation = horizontal_j3
    folder = tmp_path_factory.mktemp("coupled")
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):  # a module fixture has no capsys
        assert main(["calibrate", str(urdf), str(calibration), "--tip-link", "flange", "--quiet", "--coupling",
                     "A3=-1*A2", "--out", str(folder / "coupled.urdf"), "--report", str(folder / "coupled.json")]) in (
            0, 3), err.getvalue()
        out.seek(0), out.truncate()
        assert main(["evaluate", str(folder / "coupled.urdf"), str(folder / "coupled.json"), str(validation),
                     "--json", str(folder / "e.json")]) == 0, err.getvalue()
    return (json.loads((folder / "coupled.json").read_text(encoding="utf-8")),
            json.loads((folder / "e.json").read_text(encoding="utf-8")), out.getvalue())


def test_diagnose_corrects_it_itself_and_the_flag_brings_the_model_to_the_noise(horizontal_j3, coupled, tmp_path,
                                                                                capsys):
    """diagnose finds A3 read against A2, corrects the readings by the convention exactly, calibrates the
    geometry again on them and goes on: REPORT.json records it under couplings (as --coupling would), and
    evaluate on the written report is at the noise; calibrate with the flag is too, without it far off."""
    urdf, calibration, validation = horizontal_j3
    common = ["--tip-link", "flange", "--quiet"]
    assert main(["diagnose", str(urdf), str(calibration), "--validation", str(validation), *common,
                 "--out", str(tmp_path / "d.urdf"), "--report", str(tmp_path / "d" / "REPORT.json")]) == 0
    printed = capsys.readouterr().out
    assert ("A3 is read against A2 (as parallelogram arms read J3 from the horizontal): its reading is A3 − A2"
            in printed)
    document = json.loads((tmp_path / "d" / "REPORT.json").read_text(encoding="utf-8"))
    assert document["couplings"] == [{"joint": "A3", "factor": -1.0, "driver": "A2"}]
    assert not [e for e in document["effects"] if e["type"] == "coupling"]
    (step, *_) = document["diagnosis"]["steps"]
    assert step["convention"] == document["couplings"][0] and step["effect"]["value"] == 1.0
    assert _held_out_mm(tmp_path, tmp_path / "d.urdf", tmp_path / "d" / "REPORT.json", validation) == pytest.approx(
        document["diagnosis"]["heldout_errors"]["position"]["rms_mm"], rel=1e-9)  # evaluate: diagnose's model
    assert document["diagnosis"]["heldout_errors"]["position"]["rms_mm"] < BOUND_MM
    assert main(["report", str(tmp_path / "d" / "REPORT.json"), "--out", str(tmp_path / "d.html")]) == 0
    assert "A3 is read against A2" in (tmp_path / "d.html").read_text(encoding="utf-8")  # the page says it
    # plain: the readings as they are miss by ~1 m, a model no URDF is written of unless --force
    assert main(["calibrate", str(urdf), str(calibration), *common, "--force", "--out", str(tmp_path / "plain.urdf"),
                 "--report", str(tmp_path / "plain.json")]) in (0, 3)
    report, evaluated, _ = coupled  # with the flag (the module's one run of it)
    assert report["couplings"] == [{"joint": "A3", "factor": -1.0, "driver": "A2"}]
    assert "couplings" not in json.loads((tmp_path / "plain.json").read_text(encoding="utf-8"))
    capsys.readouterr()
    assert evaluated["position"]["rms_mm"] < BOUND_MM
    assert _held_out_mm(tmp_path, tmp_path / "plain.urdf", tmp_path / "plain.json", validation) > 10.0  # mm


def test_the_flag_is_refused_where_it_does_not_apply(horizontal_j3, tmp_path, capsys):
    urdf, calibration, _ = horizontal_j3
    assert main(["calibrate", str(urdf), str(calibration), "--tip-link", "flange", "--coupling", "A3=-1*A9",
                 "--out", str(tmp_path / "o.urdf"), "--report", str(tmp_path / "r.json")]) == 2
    assert "--coupling A3=-1*A9: no joint 'A9' on the chain" in capsys.readouterr().err
    with pytest.raises(SystemExit) as usage:  # argparse's usage error
        main(["calibrate", str(urdf), str(calibration), "--tip-link", "flange", "--coupling", "A3=-1",
              "--out", str(tmp_path / "o.urdf"), "--report", str(tmp_path / "r.json")])
    assert usage.value.code == 2 and "argument --coupling: use JOINT=FACTOR*DRIVER" in capsys.readouterr().err
    assert not (tmp_path / "o.urdf").exists()


def test_a_report_coupling_is_checked_like_the_flag():
    from pincal.measurements.couplings import couplings_from_report

    assert couplings_from_report([{"joint": "A3", "factor": -1, "driver": "A2"}], "r.json") == (
        ReadingCoupling("A3", -1.0, "A2"),)
    for bad in ([{"joint": "A3", "factor": 0, "driver": "A2"}], [{"joint": "A3", "factor": 1, "driver": "A3"}],
                [{"joint": "A3"}], {"joint": "A3"}):
        with pytest.raises(PincalError, match="r.json: couplings must be a list"):
            couplings_from_report(bad, "r.json")
    for bad in ("A3=.*A2", "A3=1.2.3*A2"):
        with pytest.raises(PincalError, match="JOINT=FACTOR"):
            parse_coupling(bad)


def test_a_wrong_factor_given_is_named_with_the_one_that_fits(horizontal_j3, tmp_path, capsys):
    """--coupling A3=1*A2 where the readings need -1: the readings still include a coupling, which the
    advice reports against the factor given (F − c), not as "a transmission coupling"."""
    from pincal.diagnosis.verdicts import coupling_advice
    from pincal.model.effects import Effect

    effect = Effect("coupling", "A3", driver="A2")
    assert "that factor looks wrong; run again with --coupling A3=-1*A2," in coupling_advice(effect, 2.0, given=1.0)
    assert "run again with --coupling A3=0.5*A2," in coupling_advice(effect, 0.1, given=0.6)  # F − value
    urdf, calibration, validation = horizontal_j3
    assert main(["diagnose", str(urdf), str(calibration), "--validation", str(validation), "--tip-link", "flange",
                 "--coupling", "A3=1*A2", "--quiet", "--out", str(tmp_path / "d.urdf"),
                 "--report", str(tmp_path / "d" / "REPORT.json")]) in (0, 3)
    printed = capsys.readouterr().out
    assert "corrected by --coupling A3=1*A2, still include" in printed and "--coupling A3=-1*A2" in printed


def test_eq_c1_and_its_inverse_round_trip():
    names = ["A1", "A2", "A3"]
    couplings = [parse_coupling("A3=-1*A2"), parse_coupling("A2=0.25*A1")]
    readings = np.random.default_rng(1).normal(size=(5, 3))
    actual = corrected_angles(readings, couplings, names)
    assert np.allclose(actual[:, 2], readings[:, 2] + readings[:, 1])
    assert np.allclose(readings_of(actual, couplings, names), readings, rtol=0, atol=1e-12)


def test_plan_reads_and_writes_the_controllers_joint_space(horizontal_j3, tmp_path):
    """plan --existing with A3 read against A2: the recorded rows are corrected (the same prediction as
    from corrected readings without the flag), and PLAN.csv is written as the controller reads A3
    (A3 − A2), PLAN.json recording the coupling."""
    from pincal.measurements.csv_v1 import read_measurements

    urdf, calibration, _ = horizontal_j3
    chain = KinematicChain.from_urdf(urdf, "flange")
    corrected = tmp_path / "corrected.csv"
    write_measurements(corrected, apply_couplings(read_measurements(calibration, chain.joint_specs)[0],
                                                  [parse_coupling("A3=-1*A2")]))
    common = ["--tip-link", "flange", "--count", "4", "--sample", "200", "--quiet"]
    assert main(["plan", str(urdf), *common, "--existing", str(calibration), "--coupling", "A3=-1*A2",
                 "--out", str(tmp_path / "c.csv"), "--report", str(tmp_path / "c.json")]) == 0
    assert main(["plan", str(urdf), *common, "--existing", str(corrected),
                 "--out", str(tmp_path / "p.csv"), "--report", str(tmp_path / "p.json")]) == 0
    coupled, plain = (json.loads((tmp_path / f"{n}.json").read_text(encoding="utf-8")) for n in ("c", "p"))
    assert coupled["sources"]["couplings"] == [{"joint": "A3", "factor": -1.0, "driver": "A2"}]
    assert "couplings" not in plain["sources"]
    assert coupled["predicted"]["recorded_only"] == pytest.approx(plain["predicted"]["recorded_only"], rel=1e-9)
    rows = [np.loadtxt(tmp_path / f"{n}.csv", delimiter=",", skiprows=1, usecols=range(6)) for n in ("c", "p")]
    assert np.allclose(rows[0][:, 2], rows[1][:, 2] - rows[1][:, 1]) and np.allclose(rows[0][:, :2], rows[1][:, :2])


def test_evaluate_says_before_and_after_on_the_rows_it_evaluates(horizontal_j3, coupled):
    """Evaluate's before -> after. Before: the URDF the calibration started from
    (REPORT.json sources.urdf), its registration and target fitted to the evaluated rows — recomputed
    here with the library; after: the evaluated error. The readings corrected first (the report's coupling)."""
    import re

    from pincal.fit.chain_calibration import calibrate_chain
    from pincal.measurements.csv_v1 import read_measurements

    urdf, _, validation = horizontal_j3
    _, evaluated, printed = coupled  # calibrate --coupling A3=-1*A2, evaluate on the held-out rows
    after = evaluated["position"]["rms_mm"]
    line = next(x for x in printed.splitlines() if x.startswith("before -> after, these rows"))
    before_mm, after_mm = map(float, re.findall(r"([0-9.]+) -> ([0-9.]+) mm", line)[0])
    chain = KinematicChain.from_urdf(urdf, "flange")
    rows = apply_couplings(read_measurements(validation, chain.joint_specs)[0], [parse_coupling("A3=-1*A2")])
    rows = replace(rows, roles=np.full(rows.n_rows, "calibration", dtype=object))
    assert before_mm == pytest.approx(1000 * calibrate_chain(chain, rows, "registration").rms_m, abs=6e-4)
    assert after_mm == pytest.approx(after, abs=6e-4) and before_mm > 10 * after_mm  # printed to 3 decimals
    before = evaluated["before"]  # --json: the same before
    assert before["position_rms_mm"] == pytest.approx(before_mm, abs=6e-4) and before["urdf"] == str(urdf)
    assert before["registration"] == "fitted to the evaluated rows"


def test_joint_limits_are_judged_on_the_corrected_angles(industrial_arm_urdf, tmp_path):
    """A3 read from the horizontal: a reading of 160° (beyond A3's 154° limit) with A2 at −50° is the
    actual angle 110°, inside; a reading of −100° with A2 at −50° is −150°, beyond the −130° limit."""
    from pincal.measurements.csv_v1 import read_measurements

    chain = KinematicChain.from_urdf(industrial_arm_urdf, "flange")
    read = np.radians([[0.0, -50.0, 160.0, 0.0, 30.0, 0.0], [0.0, -50.0, -100.0, 0.0, 30.0, 0.0]])
    actual = read.copy()
    actual[:, 2] += read[:, 1]
    params = PlacementErrors(chain)
    rows = measure_truth(params, np.zeros(params.size), actual, sensor_at(3.0), np.random.default_rng(0),
                         SimulatedSensor(0.0, 0.0))
    write_measurements(tmp_path / "rows.csv", replace(rows, q=read))
    _, raw_notes = read_measurements(tmp_path / "rows.csv", chain.joint_specs)
    data, notes = read_measurements(tmp_path / "rows.csv", chain.joint_specs, [parse_coupling("A3=-1*A2")])
    assert [n for n in raw_notes if "limits" in n] == [
        f"{tmp_path / 'rows.csv'}: joint 'A3' is outside its limits [-2.26893, 2.68781] rad in 1 of 2 rows; "
        "first at line 2: 2.79253 rad"]
    assert [n for n in notes if "limits" in n] == [
        f"{tmp_path / 'rows.csv'}: joint 'A3' (its reading corrected by --coupling, eq C1) is outside its limits "
        "[-2.26893, 2.68781] rad in 1 of 2 rows; first at line 3: -2.61799 rad"]
    assert np.allclose(data.q, actual)


def test_socket_fixture_rows_are_corrected_as_by_hand(tmp_path, capsys):
    """calibrate --fixture --coupling (the fixture reader takes the joint columns through the CSV v1
    reader, then eq C1): the same fit as the files corrected by hand, and evaluate --fixture corrects its
    rows as the report says. The MUKCA iiwa's readings made to include 0.5 x joint_a3 in joint_a4."""
    import csv

    from pincal.report.effects_file import effects_path, read_effects_file

    mukca = Path(__file__).resolve().parents[1] / "data" / "mukca"
    files = {}
    for name in ("front", "left_back", "raised_left"):
        with open(mukca / "kuka_14" / f"{name}.csv", newline="", encoding="utf-8") as handle:
            rows = list(csv.DictReader(handle))
        for kind, shift in (("coupled", 0.5), ("by_hand", 0.0)):  # by hand: the coupled reading minus 0.5 x a3
            out = tmp_path / kind / f"{name}.csv"
            out.parent.mkdir(exist_ok=True)
            with open(out, "w", newline="", encoding="utf-8") as handle:
                writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
                writer.writeheader()
                for row in rows:
                    coupled = float(row["joint_a4"]) + 0.5 * float(row["joint_a3"])
                    reading = coupled if shift else coupled - 0.5 * float(row["joint_a3"])
                    writer.writerow({**row, "joint_a4": repr(reading)})
            files[kind, name] = out
    flags = {"coupled": ["--coupling", "joint_a4=0.5*joint_a3"], "by_hand": []}
    reports, evaluations = {}, {}
    for kind, given in flags.items():
        assert main(["calibrate", str(mukca / "urdf" / "iiwa14.urdf"), str(files[kind, "front"]),
                     str(files[kind, "left_back"]), "--fixture", str(mukca / "fixture.csv"), "--tip-link", "tool0",
                     "--level", "offsets", *given, "--out", str(tmp_path / f"{kind}.urdf"),
                     "--report", str(tmp_path / f"{kind}.json")]) == 0
        reports[kind] = json.loads((tmp_path / f"{kind}.json").read_text(encoding="utf-8"))
        assert main(["evaluate", str(tmp_path / f"{kind}.urdf"), str(tmp_path / f"{kind}.json"),
                     str(files[kind, "raised_left"]), "--fixture", str(mukca / "fixture.csv"),
                     "--json", str(tmp_path / f"{kind}_eval.json")]) == 0
        evaluations[kind] = json.loads((tmp_path / f"{kind}_eval.json").read_text(encoding="utf-8"))
    printed = capsys.readouterr()
    assert "the URDF cannot carry 1 coupling: written to" in printed.out and "readings corrected as" in printed.err
    assert reports["coupled"]["couplings"] == [{"joint": "joint_a4", "factor": 0.5, "driver": "joint_a3"}]
    assert "couplings" not in reports["by_hand"] and not effects_path(tmp_path / "by_hand.urdf").exists()
    assert [c.label for c in read_effects_file(effects_path(tmp_path / "coupled.urdf")).couplings] == [
        "joint_a4=0.5*joint_a3"]
    values = [[p["calibrated"] for p in reports[k]["parameters"] if p["calibrated"] is not None] for k in flags]
    assert np.allclose(values[0], values[1], rtol=0, atol=1e-12)  # m, rad: rounding of the correction only
    assert np.allclose(reports["coupled"]["fixture"]["ball_centre_m"], reports["by_hand"]["fixture"]["ball_centre_m"],
                       rtol=0, atol=1e-12)
    after = [evaluations[k]["after"]["consistency_mm"] for k in flags]
    assert after[0] == pytest.approx(after[1], abs=1e-9)  # mm
