"""The command line as a user runs it: simulate → calibrate → evaluate, and bad input."""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from pincal.cli.commands import main
from pincal.measurements.csv_v1 import read_measurements
from pincal.model.chain import KinematicChain, pose_from_xyz_rpy
from pincal.model.dh.table import DHTable
from pincal.model.urdf import read_joint_origins
from pincal.robots import KUKA_FLANGE_LINK, kuka_lwr4plus_urdf

#: Sensor noise of ``pincal simulate`` and ``pincal demo`` (the paper's Figure 2): sigma_p [mm], sigma_a [deg].
SIGMA = 0.055
#: The paper's tolerances (Section 9): with v ≈ 4 sigma_p and the three-sigma rule a
#: calibrated robot's position error stays below 12 sigma_p; its orientation error
#: below 4 beta_997, beta_997 the 0.997 quantile of the noise rotation angle
#: (|xi| of a 3D Gaussian with sigma_a per component: sigma_a sqrt(chi²_3(0.997))).
PAPER_MAX_POS_MM = 12 * SIGMA
PAPER_MAX_ROT_DEG = 4 * SIGMA * np.sqrt(chi2.ppf(0.997, 3))
#: Printed values have four decimals.
PRINTED = 0.5e-4 + 1e-9


def _noise_floor(sigma, rows):
    """Lower bound on a mean eq 24 error against noisy measurements.

    Each error is |e_j + n_j| with n_j the test row's 3D Gaussian noise (sigma
    per component; for orientations the noise rotation's vector, whose norm is
    its angle), independent of the model error e_j; |e + n| is
    stochastically larger than |n|, whose mean is sigma 2 sqrt(2/pi) and
    standard deviation sigma sqrt(3 − 8/pi). Four standard errors below that mean.
    """
    return sigma * (2 * np.sqrt(2 / np.pi) - 4 * np.sqrt(3 - 8 / np.pi) / np.sqrt(rows))


def _eq24(urdf, report, data_path, role=None):
    """Eq 24 per row [mm], [deg], computed here: FK of ``urdf`` with the report's tool
    and registrations (read from the JSON), against the rows of ``data_path``."""
    tool = pose_from_xyz_rpy(report["tool"]["xyz_m"], report["tool"]["rpy_rad"])
    chain = KinematicChain.from_urdf(urdf, report["tool"]["parent_link"], tool=tool)
    data, _ = read_measurements(data_path, chain.joint_specs)
    data = data.select(data.roles == role if role else data.roles != "cpa")
    poses = chain.poses(data.q)

    def registration(key):
        entry = report["registration"][key]
        return Rotation.from_quat(entry["rotation_xyzw"]).as_matrix(), np.array(entry["translation_m"])

    (omega1, tau1), (omega2, _) = registration("position"), registration("orientation")
    position = np.linalg.norm(poses.tool_positions @ omega1.T + tau1 - data.points[:, 0], axis=1)
    relative = data.rotations.transpose(0, 2, 1) @ omega2 @ poses.tool_rotations  # G_j⁻¹ Ω R_j
    rotation = Rotation.from_matrix(relative).magnitude()
    return position * 1000.0, np.degrees(rotation)


def _summary(values):
    return np.array([values.mean(), np.sqrt(np.mean(values**2)), values.max()])


def _printed_row(text, label):
    """The six numbers printed after ``label``: position mean, RMS, max, orientation mean, RMS, max."""
    (line,) = [line for line in text.splitlines() if line.startswith(label)]
    return np.array([float(v) for v in line[len(label):].split()[:6]])


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
    # (written with 17 significant digits: equal to rounding, 1e-12 rad or m)
    origins = read_joint_origins(out)
    table = DHTable.from_joint_origins([origins[f"lwr_joint_{i}"] for i in range(1, 8)] + [origins["lwr_flange_joint"]])
    for p in doc["parameters"]:
        if p["calibrated"] is not None:
            field, joint = p["name"].rsplit("_", 1)
            assert abs(getattr(table, field)[int(joint) - 1] - p["calibrated"]) < 1e-12, p["name"]
    # the printed errors on the calibration rows are those of this URDF and report
    position, rotation = _eq24(out, doc, simulated / "calibration.csv", role="calibration")
    printed = _printed_row(capsys.readouterr().out, "calibration rows")
    assert np.abs(printed - np.concatenate([_summary(position), _summary(rotation)])).max() <= PRINTED
    # and they make a calibrated robot in the paper's sense: every held-out pose
    # within its tolerances (the URDF with the report's registrations, through evaluate)
    assert main(["evaluate", str(out), str(report), str(simulated / "validation.csv"),
                 "--max-pos-mm", str(PAPER_MAX_POS_MM), "--max-rot-deg", str(PAPER_MAX_ROT_DEG)]) == 0


def _calibrate_full(tmp_path, simulated, kuka_urdf):
    """``pincal calibrate`` at its default level (full, tool given) on the simulated rows."""
    out, report = tmp_path / "c.urdf", tmp_path / "R.json"
    assert main(["calibrate", str(kuka_urdf), str(simulated / "calibration.csv"), *_tool_args(simulated),
                 "--out", str(out), "--report", str(report)]) == 0
    return out, report


def test_evaluate_thresholds_and_json(tmp_path, simulated, kuka_urdf, capsys):
    out, report = _calibrate_full(tmp_path, simulated, kuka_urdf)
    capsys.readouterr()
    metrics = tmp_path / "metrics.json"
    validation = simulated / "validation.csv"
    assert main(["evaluate", str(out), str(report), str(validation), "--json", str(metrics)]) == 0
    printed = _printed_row(capsys.readouterr().out, "50 rows")
    # the numbers printed and written are eq 24 of this URDF and report, recomputed here
    position, rotation = _eq24(out, json.loads(report.read_text()), validation)
    expected = np.concatenate([_summary(position), _summary(rotation)])
    assert np.abs(printed - expected).max() <= PRINTED, (printed, expected)
    doc = json.loads(metrics.read_text())
    written = [doc["position"][k] for k in ("mean_mm", "rms_mm", "max_mm")]
    written += [doc["orientation"][k] for k in ("mean_deg", "rms_deg", "max_deg")]
    assert doc["rows"] == 50
    assert np.abs(np.array(written) - expected).max() <= 1e-9  # same FK and registrations: rounding only
    # against noisy test rows the mean error cannot fall below the test noise's own,
    # and a calibrated robot keeps every pose within the paper's tolerances
    assert position.mean() > _noise_floor(SIGMA, 50) and rotation.mean() > _noise_floor(SIGMA, 50)
    assert position.max() <= PAPER_MAX_POS_MM and rotation.max() <= PAPER_MAX_ROT_DEG
    # thresholds apply to the largest error: just above it passes, just below it fails
    args = ["evaluate", str(out), str(report), str(validation)]
    assert main(args + ["--max-pos-mm", f"{position.max() + 1e-4}", "--max-rot-deg", f"{rotation.max() + 1e-4}"]) == 0
    capsys.readouterr()
    assert main(args + ["--max-pos-mm", f"{position.max() - 1e-4}"]) == 1
    assert "FAIL: max position error" in capsys.readouterr().err
    assert main(args + ["--max-rot-deg", f"{rotation.max() - 1e-4}"]) == 1
    assert "FAIL: max orientation error" in capsys.readouterr().err


def test_nominal_model_evaluates_worse_than_calibrated(tmp_path, simulated, kuka_urdf):
    """evaluate uses the URDF it is given: the nominal one with the same report (allowed on
    purpose) gives the nominal model's errors, worse than the calibrated model's row by row on
    average by more than three standard errors of the paired differences."""
    out, report = _calibrate_full(tmp_path, simulated, kuka_urdf)
    validation = simulated / "validation.csv"
    results = {}
    for name, urdf in (("calibrated", out), ("nominal", kuka_urdf)):
        metrics = tmp_path / f"{name}.json"
        assert main(["evaluate", str(urdf), str(report), str(validation), "--json", str(metrics),
                     "--allow-other-urdf"]) == 0
        position, _ = _eq24(urdf, json.loads(report.read_text()), validation)
        assert abs(json.loads(metrics.read_text())["position"]["mean_mm"] - position.mean()) <= 1e-9
        results[name] = position
    gain = results["nominal"] - results["calibrated"]
    assert gain.mean() > 3 * gain.std(ddof=1) / np.sqrt(len(gain)), gain.mean()


def test_evaluate_refuses_a_urdf_the_report_does_not_describe(tmp_path, simulated, kuka_urdf, capsys):
    """REPORT.json records the SHA-256 of the URDF written with it. A URDF from another run beside it
    (e.g. a kill between the two renames) is refused in one line, unless --allow-other-urdf says it was
    changed on purpose; a report without the key (older pincal) still evaluates."""
    out, report = _calibrate_full(tmp_path, simulated, kuka_urdf)
    doc = json.loads(report.read_text())
    assert doc["urdf_sha256"] == _sha(out)
    validation = simulated / "validation.csv"
    capsys.readouterr()
    other = tmp_path / "other.urdf"
    other.write_bytes(out.read_bytes().replace(b"<robot", b"<!-- another run -->\n<robot", 1))
    assert main(["evaluate", str(other), str(report), str(validation)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "not the URDF" in err and "--allow-other-urdf" in err, err
    assert main(["evaluate", str(other), str(report), str(validation), "--allow-other-urdf"]) == 0
    assert "not the URDF" in capsys.readouterr().err
    old = tmp_path / "old.json"
    old.write_text(json.dumps({k: v for k, v in doc.items() if k != "urdf_sha256"}))
    assert main(["evaluate", str(other), str(old), str(validation)]) == 0


def test_reloaded_corrected_urdf_reproduces_calibrated_fk(tmp_path, simulated, kuka_urdf):
    from pincal.measurements.csv_v1 import read_measurements
    from pincal.workflows.calibration import calibrate_files
    from pincal.workflows.settings import CalibrateSettings

    tool = json.loads((simulated / "truth.json").read_text())["tool"]
    pose = pose_from_xyz_rpy(tool["xyz_m"], tool["rpy_rad"])
    run = calibrate_files(kuka_urdf, simulated / "calibration.csv", tmp_path / "c.urdf", tmp_path / "r.json",
                          CalibrateSettings(KUKA_FLANGE_LINK, level="dh", method=2, tool_pose=pose))
    assert run.reload_error < 1e-9  # the README's promise: reloading reproduces the TCP to 1e-9 m
    chain = KinematicChain.from_urdf(tmp_path / "c.urdf", KUKA_FLANGE_LINK, tool=pose)
    direct = DHTable.from_joint_origins(chain.placements())
    # origins are written with repr() (17 significant digits): the table comes back to rounding
    assert np.abs(direct.to_vector() - run.result.table.to_vector()).max() < 1e-12
    data, _ = read_measurements(simulated / "validation.csv", chain.joint_specs)
    fk = chain.poses(data.q).tool_positions
    expected = np.stack([run.result.table.forward(q) @ pose for q in data.q])[:, :3, 3]
    assert np.abs(fk - expected).max() < 1e-9  # the same promise, against the DH table's own FK


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
    if "--tool-parent" in tail:  # replaced: a second --tip-link asks for several targets (LINK:POINTS each)
        del args[args.index("--tool-parent"):args.index("--tool-parent") + 2]
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


def _registration_1(robot_points, sensor_points):
    """Registration 1 with plain numpy (Arun et al. 1987): Ω, τ minimising Σ ‖g_k − Ω t_k − τ‖²."""
    robot_mean, sensor_mean = robot_points.mean(axis=0), sensor_points.mean(axis=0)
    u, _, vt = np.linalg.svd((robot_points - robot_mean).T @ (sensor_points - sensor_mean))
    omega = vt.T @ np.diag([1.0, 1.0, np.sign(np.linalg.det(vt.T @ u.T))]) @ u.T
    return omega, sensor_mean - omega @ robot_mean


def test_demo_table_is_eq24_of_the_files_it_wrote_within_the_paper_tolerances(tmp_path, capsys):
    """Each Method row of the demo's table is eq 24 on validation.csv computed here from the files
    the demo wrote (the corrected URDF's kinematics, REPORT_method*.json's tool and registrations,
    numpy for the errors), between the noise floor and the paper's tolerances (Section 9); the
    nominal row's positions are Table 1's URDF registered to the calibration rows by numpy's SVD,
    far beyond the tolerance (Table 2's large deviations)."""
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert f"sigma_p = {SIGMA} mm, sigma_a = {SIGMA} deg" in printed
    for method in (1, 2, 3):
        report = json.loads((out / f"REPORT_method{method}.json").read_text())
        assert report["method"] == method
        position, rotation = _eq24(out / f"kuka_lwr4plus_method{method}.urdf", report, out / "validation.csv")
        expected = np.concatenate([_summary(position), _summary(rotation)])
        shown = _printed_row(printed, f"Method {method}")
        assert len(position) == 50 and np.abs(shown - expected).max() <= PRINTED, \
            f"Method {method}: printed {shown}, computed {expected}"
        assert expected[0] > _noise_floor(SIGMA, 50) and expected[3] > _noise_floor(SIGMA, 50), method
        assert expected[2] <= PAPER_MAX_POS_MM and expected[5] <= PAPER_MAX_ROT_DEG, method
    truth = json.loads((out / "truth.json").read_text())
    chain = KinematicChain.from_urdf(kuka_lwr4plus_urdf(), KUKA_FLANGE_LINK,
                                     tool=pose_from_xyz_rpy(truth["tool"]["xyz_m"], truth["tool"]["rpy_rad"]))
    calibration = read_measurements(out / "calibration.csv", chain.joint_specs)[0].with_role("calibration")
    validation, _ = read_measurements(out / "validation.csv", chain.joint_specs)
    omega, tau = _registration_1(chain.poses(calibration.q).tool_positions, calibration.points[:, 0])
    nominal = np.linalg.norm(chain.poses(validation.q).tool_positions @ omega.T + tau - validation.points[:, 0], axis=1)
    shown = _printed_row(printed, "nominal (Table 1)")
    assert np.abs(shown[:3] - _summary(nominal * 1000.0)).max() <= PRINTED, f"printed {shown}"
    assert shown[0] > 10 * PAPER_MAX_POS_MM
