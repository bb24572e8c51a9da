"""A --tip-link short of the link the target is on, or on another branch than the data's joints.

The data name their joints; the URDF says where each is. Columns of joints below the tip link that move
(the target may have moved with joints the chain lacks) are a plausibility warning when the calibration is
doubtful too, else a note (pincal.fit.plausibility: fingers below a wrist move what the target is not on);
columns of another branch (TIAGo's head in an arm's file) are not; a file whose joints are all of another
branch than the chain is refused naming that, not with a rename guess.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import said

from pincal.cli.commands import EXIT_WARNING, main
from pincal.errors import MeasurementError
from pincal.fit.plausibility import MOVED_MIN, Finding, tip_link_findings, tip_link_verdict
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
    (finding,) = tip_link_findings(chain, [("a.csv", moving)])
    assert finding.code == "tip_link"
    assert "lwr_joint_6, lwr_joint_7" in finding.message and "e.g. lwr_link_7" in finding.message
    # a joint held still is a fixed transform the fitted tool absorbs exactly: nothing to say; nor of
    # encoder jitter (1e-5 rad) on a joint held still
    assert tip_link_findings(chain, [("a.csv", {"lwr_joint_6": np.array([0.1, 0.1, np.nan])})]) == []
    jitter = 0.3 + np.random.default_rng(1).normal(0.0, 1e-5, 50)
    assert np.ptp(jitter) < MOVED_MIN and tip_link_findings(chain, [("a.csv", {"lwr_joint_6": jitter})]) == []
    # several session files: each is judged before the join drops the columns the others lack
    (finding,) = tip_link_findings(chain, [("a.csv", {}), ("b.csv", moving)])
    assert finding.message.startswith("b.csv: ")


def test_a_moving_joint_below_the_tip_warns_only_beside_another_finding():
    """Fingers below a wrist tip move while the markers sit on the palm: the fit is plausible, so a note;
    with another finding (the residual a short tip leaves) it is a warning that explains it."""
    tip = [Finding("tip_link", "f.csv: column(s) hand_thumb_joint ...")]
    residual = [Finding("residual", "the calibrated model misses ...")]
    assert tip_link_verdict(tip, []) == ([], [tip[0].message])
    assert tip_link_verdict(tip, residual) == (tip + residual, [])
    assert tip_link_verdict([], residual) == (residual, [])


@pytest.mark.parametrize("path", TIAGO_FILES, ids=lambda p: p.name)
def test_tiago_files_other_branches_do_not_warn_a_short_tip_does(tiago_urdf, path):
    wrist = KinematicChain.from_urdf(tiago_urdf, "wrist_ft_tool_link")
    data, _ = read_measurements(path, wrist.joint_specs, other_branches=wrist.other_branch_joints)
    head = {"head_1_joint": np.array([0.0, 0.5]), "head_2_joint": np.array([0.1, -0.2])}
    assert tip_link_findings(wrist, [(data.source, {**data.extra, **head})]) == []
    short = KinematicChain.from_urdf(tiago_urdf, "arm_4_link")
    data, _ = read_measurements(path, short.joint_specs)
    (finding,) = tip_link_findings(short, [(data.source, data.extra)])
    assert "arm_5_joint, arm_6_joint, arm_7_joint" in finding.message and "arm_7_link" in finding.message


def test_a_file_of_another_branch_is_said_to_be_so(tiago_urdf):
    head = KinematicChain.from_urdf(tiago_urdf, "head_2_link")
    with pytest.raises(MeasurementError) as error:
        read_measurements(TIAGO_FILES[0], head.joint_specs, other_branches=head.other_branch_joints)
    message = str(error.value)
    assert "missing joint column(s) head_1_joint, head_2_joint" in message
    assert "arm_1_joint, arm_2_joint" in message and "another branch" in message and "--tip-link" in message
    assert "rename" not in message  # the guess a misspelt column gets (tests/test_did_you_mean.py)


def test_one_misspelt_column_beside_another_branchs_keeps_the_rename_guess(tiago_urdf, tmp_path):
    """A joint_states export holds the head's joints too: a misspelt arm joint is still a rename."""
    arm = KinematicChain.from_urdf(tiago_urdf, "wrist_ft_tool_link")
    header, *rows = TIAGO_FILES[0].read_text(encoding="utf-8").splitlines()
    typo = tmp_path / "typo.csv"
    typo.write_text("\n".join([header.replace("arm_3_joint", "arm_3_jiont") + ",head_1_joint"]
                              + [row + ",0.1" for row in rows]) + "\n", encoding="utf-8")
    with pytest.raises(MeasurementError, match="rename the file's column 'arm_3_jiont' to 'arm_3_joint'"):
        read_measurements(typo, arm.joint_specs, other_branches=arm.other_branch_joints)


def test_calibrate_and_plan_warn_on_a_short_tip(tmp_path, simulated, kuka_urdf, capsys):
    report = tmp_path / "REPORT.json"
    code = main(["calibrate", str(kuka_urdf), str(simulated), "--tip-link", "lwr_link_5", "--out",
                 str(tmp_path / "c.urdf"), "--report", str(report), "--strict", "--quiet"])
    err = capsys.readouterr().err
    warnings = json.loads(report.read_text())["warnings"]
    assert code == EXIT_WARNING and said(err) == [w["message"] for w in warnings]
    warning = warnings[0]
    assert warning["code"] == "tip_link"
    assert warning["message"].startswith(f"{simulated}: column(s) lwr_joint_6, lwr_joint_7 are joints")
    for flag in ("--existing", "--candidates"):
        assert main(["plan", str(kuka_urdf), "--tip-link", "lwr_link_5", flag, str(simulated), "--count", "8",
                     "--out", str(tmp_path / f"p{flag}.csv"), "--report", str(tmp_path / f"p{flag}.json"),
                     "--quiet"]) == 0
        # no calibration to judge by: a note
        notes = said(capsys.readouterr().err, "note")  # PLAN.json's notes do not hold it
        assert any(n.startswith(f"{simulated}: column(s) lwr_joint_6, lwr_joint_7") for n in notes), notes


def test_diagnose_warns_on_a_short_tip(tmp_path, simulated, kuka_urdf, capsys):
    report = tmp_path / "diag" / "REPORT.json"
    code = main(["diagnose", str(kuka_urdf), str(simulated), "--tip-link", "lwr_link_5", "--out",
                 str(tmp_path / "d.urdf"), "--report", str(report), "--strict", "--quiet"])
    warnings = json.loads(report.read_text())["warnings"]
    assert code == EXIT_WARNING and said(capsys.readouterr().err) == [w["message"] for w in warnings]
    warning = warnings[0]
    assert warning["code"] == "tip_link"
    assert "column(s) lwr_joint_6, lwr_joint_7 are joints of the URDF below --tip-link" in warning["message"]
