"""The command line as a user runs it: simulate → calibrate → evaluate, and bad input."""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest

from pincal.cli.commands import main
from pincal.model.chain import KinematicChain, pose_from_xyz_rpy
from pincal.model.dh import DHTable
from pincal.model.urdf import read_joint_origins
from pincal.robots import KUKA_FLANGE_LINK


def _sha(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim")
    assert main(["simulate", "--out", str(out), "--deviations", "small", "--seed", "5"]) == 0
    return out


def _tool_args(sim_dir):
    truth = json.loads((sim_dir / "truth.json").read_text())
    tool = truth["tool"]
    return ["--tool", ",".join(repr(v) for v in tool["xyz_m"] + tool["rpy_rad"]), "--tool-parent", tool["parent_link"]]


def test_simulate_writes_data_and_truth(simulated):
    truth = json.loads((simulated / "truth.json").read_text())
    assert set(truth) >= {"dh", "registration", "tool", "settings"}
    assert truth["settings"]["sigma_pos_mm"] == 0.055
    header = (simulated / "calibration.csv").read_text().splitlines()[0].split(",")
    assert header[:7] == [f"lwr_joint_{i}" for i in range(1, 8)]
    assert {"x", "y", "z", "qx", "qy", "qz", "qw", "role"} <= set(header)
    assert len((simulated / "calibration.csv").read_text().splitlines()) == 1 + 7 * 40 + 100
    assert len((simulated / "validation.csv").read_text().splitlines()) == 1 + 50


def test_simulate_is_reproducible(tmp_path, simulated):
    assert main(["simulate", "--out", str(tmp_path), "--deviations", "small", "--seed", "5"]) == 0
    assert _sha(tmp_path / "calibration.csv") == _sha(simulated / "calibration.csv")


@pytest.mark.parametrize("method", ["1", "2", "3"])
def test_calibrate_writes_corrected_urdf_and_report(tmp_path, simulated, kuka_urdf, method, capsys):
    before = _sha(kuka_urdf)
    out, report = tmp_path / "corrected.urdf", tmp_path / "REPORT.json"
    code = main(["calibrate", str(kuka_urdf), str(simulated / "calibration.csv"), "--method", method,
                 *_tool_args(simulated), "--out", str(out), "--report", str(report)])
    assert code == 0, capsys.readouterr().err
    assert _sha(kuka_urdf) == before
    doc = json.loads(report.read_text())
    assert doc["method"] == int(method)
    assert set(doc["registration"]["position"]) == {"rotation_xyzw", "translation_m"}
    assert set(doc["registration"]["orientation"]) >= {"rotation_xyzw"}
    assert doc["tool"]["parent_link"] == KUKA_FLANGE_LINK
    assert len(doc["tool"]["xyz_m"]) == 3 and len(doc["tool"]["rpy_rad"]) == 3
    assert "stages" in doc["fit"]
    by_name = {p["name"]: p for p in doc["parameters"]}
    assert len(by_name) == 28
    assert set(by_name["r_3"]) >= {"name", "joint", "nominal", "calibrated", "std"}
    assert by_name["d_1"]["calibrated"] is None and by_name["epsilon_1"]["std"] is None
    # the corrected URDF carries the calibrated parameters in its joint placements
    origins = read_joint_origins(out)
    table = DHTable.from_joint_origins([origins[f"lwr_joint_{i}"] for i in range(1, 8)] + [origins["lwr_flange_joint"]])
    for p in doc["parameters"]:
        if p["calibrated"] is not None:
            field, joint = p["name"].rsplit("_", 1)
            assert abs(getattr(table, field)[int(joint) - 1] - p["calibrated"]) < 1e-12, p["name"]


def test_evaluate_thresholds_and_json(tmp_path, simulated, kuka_urdf, capsys):
    out, report = tmp_path / "c.urdf", tmp_path / "R.json"
    main(["calibrate", str(kuka_urdf), str(simulated / "calibration.csv"), *_tool_args(simulated),
          "--out", str(out), "--report", str(report)])
    capsys.readouterr()
    metrics = tmp_path / "metrics.json"
    assert main(["evaluate", str(out), str(report), str(simulated / "validation.csv"), "--json", str(metrics)]) == 0
    printed = capsys.readouterr().out
    assert "50 rows" in printed and "[mm]" in printed and "[deg]" in printed
    doc = json.loads(metrics.read_text())
    assert doc["rows"] == 50 and 0 < doc["position"]["mean_mm"] < 0.5 and 0 < doc["orientation"]["mean_deg"] < 0.2
    args = ["evaluate", str(out), str(report), str(simulated / "validation.csv")]
    assert main(args + ["--max-pos-mm", "5", "--max-rot-deg", "1"]) == 0
    assert main(args + ["--max-pos-mm", "0.001"]) == 1
    assert main(args + ["--max-rot-deg", "0.0001"]) == 1
    assert "FAIL" in capsys.readouterr().err


def test_nominal_model_evaluates_worse_than_calibrated(tmp_path, simulated, kuka_urdf, capsys):
    out, report = tmp_path / "c.urdf", tmp_path / "R.json"
    main(["calibrate", str(kuka_urdf), str(simulated / "calibration.csv"), *_tool_args(simulated),
          "--out", str(out), "--report", str(report)])
    calibrated, nominal = tmp_path / "cal.json", tmp_path / "nom.json"
    main(["evaluate", str(out), str(report), str(simulated / "validation.csv"), "--json", str(calibrated)])
    main(["evaluate", str(kuka_urdf), str(report), str(simulated / "validation.csv"), "--json", str(nominal)])
    assert json.loads(nominal.read_text())["position"]["mean_mm"] > 5 * json.loads(calibrated.read_text())["position"]["mean_mm"]


def test_reloaded_corrected_urdf_reproduces_calibrated_fk(tmp_path, simulated, kuka_urdf):
    from pincal.cli.workflows import calibrate_files
    from pincal.measurements.csv_v1 import read_measurements

    tool = json.loads((simulated / "truth.json").read_text())["tool"]
    pose = pose_from_xyz_rpy(tool["xyz_m"], tool["rpy_rad"])
    run = calibrate_files(kuka_urdf, simulated / "calibration.csv", 2, 1.0, pose, KUKA_FLANGE_LINK,
                          tmp_path / "c.urdf", tmp_path / "r.json")
    assert run.reload_error < 1e-9
    chain = KinematicChain.from_urdf(tmp_path / "c.urdf", KUKA_FLANGE_LINK, tool=pose)
    direct = DHTable.from_joint_origins(chain.placements())
    assert np.abs(direct.to_vector() - run.result.table.to_vector()).max() < 1e-12
    data, _ = read_measurements(simulated / "validation.csv", chain.joint_specs)
    fk = chain.poses(data.q).tool_positions
    expected = np.stack([run.result.table.forward(q) @ pose for q in data.q])[:, :3, 3]
    assert np.abs(fk - expected).max() < 1e-9


@pytest.mark.parametrize(
    "argv_tail, message",
    [
        (["--out", "{urdf}"], "refusing to overwrite"),
        (["--out", "{data}"], "refusing to overwrite"),
        (["--tool-parent", "no_such_link"], "no link named 'no_such_link'"),
    ],
)
def test_calibrate_rejects_bad_requests_with_one_line(tmp_path, simulated, kuka_urdf, capsys, argv_tail, message):
    data = simulated / "calibration.csv"
    args = ["calibrate", str(kuka_urdf), str(data), *_tool_args(simulated), "--out", str(tmp_path / "o.urdf"),
            "--report", str(tmp_path / "r.json")]
    tail = [a.format(urdf=kuka_urdf, data=data) for a in argv_tail]
    args = args + tail  # later flags win in argparse
    before = _sha(kuka_urdf), _sha(data)
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1 and "Traceback" not in err
    assert (_sha(kuka_urdf), _sha(data)) == before


def test_bad_tool_argument_is_a_usage_error(tmp_path, simulated, kuka_urdf, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["calibrate", str(kuka_urdf), str(simulated / "calibration.csv"), "--tool", "1,2,3",
              "--tool-parent", KUKA_FLANGE_LINK, "--out", str(tmp_path / "o.urdf"), "--report", str(tmp_path / "r.json")])
    assert exit_info.value.code == 2
    assert "X,Y,Z,ROLL,PITCH,YAW" in capsys.readouterr().err


def test_missing_joint_column_is_reported(tmp_path, simulated, kuka_urdf, capsys):
    lines = (simulated / "calibration.csv").read_text().splitlines()
    header = lines[0].split(",")
    drop = header.index("lwr_joint_4")
    bad = tmp_path / "bad.csv"
    bad.write_text("\n".join(",".join(c for i, c in enumerate(l.split(",")) if i != drop) for l in lines) + "\n")
    code = main(["calibrate", str(kuka_urdf), str(bad), *_tool_args(simulated), "--out", str(tmp_path / "o.urdf"),
                 "--report", str(tmp_path / "r.json")])
    assert code == 2
    err = capsys.readouterr().err
    assert "lwr_joint_4" in err and "bad.csv" in err and not (tmp_path / "o.urdf").exists()


def test_demo_runs_and_prints_the_comparison(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path / "demo")]) == 0
    printed = capsys.readouterr().out
    for label in ("nominal", "Method 1", "Method 2", "Method 3"):
        assert label in printed
    assert (tmp_path / "demo" / "kuka_lwr4plus_method2.urdf").exists()
    assert (tmp_path / "demo" / "REPORT_method2.json").exists()
