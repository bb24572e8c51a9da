"""A --tip-link short of the link the target is on, or on another branch than the data's joints.

The data name their joints; the URDF says where each is. Columns of joints below the tip link that move
(the target moved with joints the chain lacks) are a plausibility warning (pincal.fit.plausibility);
columns of another branch (TIAGo's head in an arm's file) are not; a file whose joints are all of another
branch than the chain is refused naming that, not with a rename guess.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from pincal.cli.commands import EXIT_WARNING, main
from pincal.errors import MeasurementError
from pincal.fit.plausibility import tip_link_findings
from pincal.measurements.csv_v1 import read_measurements
from pincal.model.chain import KinematicChain
from pincal.robots import example_robot_data_urdf

TIAGO_FILES = sorted((Path(__file__).resolve().parents[1] / "data" / "tiago_mocap").glob("*.csv"))


@pytest.fixture(scope="module")
def tiago_urdf():
    return example_robot_data_urdf("tiago_description/robots/tiago.urdf")


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim")
    assert main(["simulate", "--out", str(out), "--deviations", "small", "--seed", "5"]) == 0
    return out / "calibration.csv"


def test_joints_below_the_tip_and_on_other_branches(kuka_urdf, tiago_urdf):
    kuka = KinematicChain.from_urdf(kuka_urdf, "lwr_link_5")
    assert kuka.beyond_tip_joints == {"lwr_joint_6": "lwr_link_6", "lwr_joint_7": "lwr_link_7"}
    assert kuka.other_branch_joints == ()
    arm = KinematicChain.from_urdf(tiago_urdf, "arm_4_link")
    assert list(arm.beyond_tip_joints)[:3] == ["arm_5_joint", "arm_6_joint", "arm_7_joint"]
    assert {"head_1_joint", "head_2_joint"} <= set(arm.other_branch_joints)
    assert not {"head_1_joint", "arm_1_joint"} & set(arm.beyond_tip_joints)


def test_moving_columns_below_the_tip_warn_constant_ones_do_not(kuka_urdf):
    chain = KinematicChain.from_urdf(kuka_urdf, "lwr_link_5")
    moving = {"lwr_joint_6": np.array([0.1, 0.2]), "lwr_joint_7": np.array([0.0, -0.3])}
    (finding,) = tip_link_findings(chain, moving, "a.csv")
    assert finding.code == "tip_link"
    assert "lwr_joint_6, lwr_joint_7" in finding.message and "e.g. lwr_link_7" in finding.message
    # a joint held still is a fixed transform the fitted tool absorbs exactly: nothing to say
    assert tip_link_findings(chain, {"lwr_joint_6": np.array([0.1, 0.1, np.nan])}, "a.csv") == []


@pytest.mark.parametrize("path", TIAGO_FILES, ids=lambda p: p.name)
def test_tiago_files_other_branches_do_not_warn_a_short_tip_does(tiago_urdf, path):
    wrist = KinematicChain.from_urdf(tiago_urdf, "wrist_ft_tool_link")
    data, _ = read_measurements(path, wrist.joint_specs, other_branches=wrist.other_branch_joints)
    head = {"head_1_joint": np.array([0.0, 0.5]), "head_2_joint": np.array([0.1, -0.2])}
    assert tip_link_findings(wrist, {**data.extra, **head}, data.source) == []
    short = KinematicChain.from_urdf(tiago_urdf, "arm_4_link")
    data, _ = read_measurements(path, short.joint_specs)
    (finding,) = tip_link_findings(short, data.extra, data.source)
    assert "arm_5_joint, arm_6_joint, arm_7_joint" in finding.message and "arm_7_link" in finding.message


def test_a_file_of_another_branch_is_said_to_be_so(tiago_urdf):
    head = KinematicChain.from_urdf(tiago_urdf, "head_2_link")
    with pytest.raises(MeasurementError) as error:
        read_measurements(TIAGO_FILES[0], head.joint_specs, other_branches=head.other_branch_joints)
    message = str(error.value)
    assert "missing joint column(s) head_1_joint, head_2_joint" in message
    assert "arm_1_joint, arm_2_joint" in message and "another branch" in message and "--tip-link" in message
    assert "rename" not in message


def test_calibrate_and_plan_warn_on_a_short_tip(tmp_path, simulated, kuka_urdf, capsys):
    report = tmp_path / "REPORT.json"
    code = main(["calibrate", str(kuka_urdf), str(simulated), "--tip-link", "lwr_link_5", "--out",
                 str(tmp_path / "c.urdf"), "--report", str(report), "--strict", "--quiet"])
    err = capsys.readouterr().err
    assert code == EXIT_WARNING
    assert "pincal: warning: " + str(simulated) + ": column(s) lwr_joint_6, lwr_joint_7 are joints" in err
    assert json.loads(report.read_text())["warnings"][0]["code"] == "tip_link"
    for flag in ("--existing", "--candidates"):
        assert main(["plan", str(kuka_urdf), "--tip-link", "lwr_link_5", flag, str(simulated), "--count", "8",
                     "--out", str(tmp_path / f"p{flag}.csv"), "--report", str(tmp_path / f"p{flag}.json"),
                     "--quiet"]) == 0
        assert "pincal: warning: " + str(simulated) + ": column(s) lwr_joint_6, lwr_joint_7" in capsys.readouterr().err


def test_diagnose_warns_on_a_short_tip(tmp_path, simulated, kuka_urdf, capsys):
    report = tmp_path / "diag" / "REPORT.json"
    code = main(["diagnose", str(kuka_urdf), str(simulated), "--tip-link", "lwr_link_5", "--out",
                 str(tmp_path / "d.urdf"), "--report", str(report), "--strict", "--quiet"])
    assert code == EXIT_WARNING
    assert "column(s) lwr_joint_6, lwr_joint_7 are joints of the URDF below --tip-link" in capsys.readouterr().err
    assert json.loads(report.read_text())["warnings"][0]["code"] == "tip_link"
