"""The settings of calibrate, diagnose and evaluate: frozen values checked once, when made.

Each combination the commands refuse is refused by the settings object itself, in one line
naming the flag, so a script that builds the object gets the command's message; the commands
build these objects and the workflows take them with the paths.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from pincal.cli.commands import main
from pincal.errors import PincalError
from pincal.fit.prior import Prior
from pincal.robots import KUKA_FLANGE_LINK, kuka_lwr4plus_urdf
from pincal.workflows.settings import CalibrateSettings, DiagnoseSettings, EvaluateSettings

TOOL = np.eye(4)


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda: CalibrateSettings("tip", level="fancy"), "--level must be one of registration, offsets, full, auto"),
        (lambda: CalibrateSettings("tip", level="full", method=2), "--method applies to --level dh only"),
        (lambda: CalibrateSettings("tip", level="dh", method=4, tool_pose=TOOL), "--method must be 1, 2 or 3"),
        (lambda: CalibrateSettings("tip", level="dh"), "the paper's methods (--level dh) need the tool"),
        (lambda: CalibrateSettings("tip", level="dh", tool_pose=TOOL, sigma_pos_mm=0.1),
         "--sigma-pos applies to --level registration, offsets, full or auto"),
        (lambda: CalibrateSettings("tip", level="dh", tool_pose=TOOL, force=True),
         "--force applies to --level registration, offsets, full or auto"),
        (lambda: CalibrateSettings("tip", level="registration", selection=Prior()),
         "--select prior does not apply to --level registration (it fits no kinematic parameter)"),
        (lambda: CalibrateSettings("tip", level="dh", tool_pose=TOOL, selection="prior"),
         "--select prior does not apply to --level dh"),
        (lambda: CalibrateSettings("tip", selection="best"), "--select must be one of aic, bic, press, all, prior"),
        (lambda: CalibrateSettings("tip", level="dh", method=3, weight=0.0, tool_pose=TOOL),
         "--weight must be a positive number"),
        (lambda: CalibrateSettings("tip", sigma_pos_mm=-0.1), "--sigma-pos must be a positive number"),
        (lambda: CalibrateSettings("tip", tool_pose=np.eye(3)), "--tool must be a finite 4x4 pose"),
        (lambda: DiagnoseSettings("tip", level="dh"), "--level must be one of registration, offsets, full, auto"),
        (lambda: DiagnoseSettings("tip", payload_kg=-1.0), "--payload-kg must be a non-negative number"),
        (lambda: DiagnoseSettings("tip", level="registration", selection="prior"),
         "--select prior does not apply to --level registration"),
        (lambda: EvaluateSettings(fixed_registration="a", new_session=True),
         "--fixed-registration and --new-session exclude each other"),
    ],
)
def test_a_refused_combination_is_refused_when_the_settings_are_made(make, message):
    with pytest.raises(PincalError) as caught:
        make()
    assert message in str(caught.value) and "\n" not in str(caught.value)


def test_settings_are_frozen_values_with_the_commands_defaults():
    settings = CalibrateSettings("tip", level="dh", tool_pose=TOOL.tolist(), xacro_args=[["a", 1]])
    assert settings.paper_method == 2 and settings.weight == 1.0 and settings.sigma_pos_m is None
    assert isinstance(settings.tool_pose, np.ndarray) and settings.xacro_args == (("a", "1"),)
    with pytest.raises(dataclasses.FrozenInstanceError):
        settings.level = "full"  # type: ignore[misc]
    assert CalibrateSettings("tip", sigma_pos_mm=0.05).sigma_pos_m == pytest.approx(5e-5)
    assert DiagnoseSettings("tip").level == "full" and EvaluateSettings().fixed_registration is None
    # the commands' default selection (docs/defaults.md): the prior where kinematics are fitted, else AIC
    assert CalibrateSettings("tip").criterion == "prior" and DiagnoseSettings("tip", level="auto").criterion == "prior"
    assert CalibrateSettings("tip", level="registration").criterion == "aic"
    assert CalibrateSettings("tip", level="dh", tool_pose=TOOL).criterion == "aic"
    # the tool is the settings' own read-only copy; settings with equal values are equal and hash alike
    pose = np.eye(4)
    held = CalibrateSettings("tip", tool_pose=pose)
    pose[0, 3] = np.nan
    assert np.isfinite(held.tool_pose).all() and not held.tool_pose.flags.writeable
    assert held == CalibrateSettings("tip", tool_pose=np.eye(4)) and hash(held) == hash(CalibrateSettings("tip"))


def test_a_call_of_the_former_signature_is_refused_by_name(tmp_path):
    from pincal.workflows.calibration import calibrate_files
    from pincal.workflows.evaluation import evaluate_files

    with pytest.raises(TypeError, match="calibrate_files\\(\\) takes a pincal.workflows.settings.CalibrateSettings"):
        calibrate_files("a.urdf", "d.csv", "o.urdf", "r.json", "tip")  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="EvaluateSettings where it got bool"):
        evaluate_files("a.urdf", "r.json", "d.csv", True)  # type: ignore[arg-type]
    from pincal.workflows.diagnosis import diagnose_files

    with pytest.raises(TypeError, match=r"diagnose_files\(\) takes a pincal.workflows.diagnosis.DiagnoseOutputs "
                                        "where it got str"):  # the former plots_dir, where the outputs now go
        diagnose_files("a.urdf", "d.csv", "o.urdf", "r.json", DiagnoseSettings("tip"), None,
                       "plots")  # type: ignore[arg-type]


def test_a_library_call_of_the_former_signature_is_refused_by_name():
    """calibrate_chain, choose_level, diagnose and plan_files took their options one by one; a script
    passing the former fourth (or fifth) argument gets one TypeError naming the value to build, not an
    AttributeError from deep inside the fit."""
    from pincal.diagnosis.diagnose import diagnose
    from pincal.fit.chain_calibration import calibrate_chain
    from pincal.fit.level_choice import choose_level
    from pincal.planning.planner import PlanSettings
    from pincal.workflows.preparation import plan_files

    with pytest.raises(TypeError, match=r"calibrate_chain\(\) takes a pincal.fit.chain_calibration.ChainFitOptions "
                                        "where it got bool"):
        calibrate_chain(None, None, "full", True)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match=r"choose_level\(\) takes a .*ChainFitOptions where it got str"):
        choose_level(None, None, "w")  # type: ignore[arg-type]
    with pytest.raises(TypeError, match=r"diagnose\(\) takes a pincal.diagnosis.diagnose.DiagnoseOptions where it "
                                        "got str"):
        diagnose(None, None, None, None, "w")  # type: ignore[arg-type]
    with pytest.raises(TypeError, match=r"plan_files\(\) takes a .*PlanInputs where it got dict"):
        plan_files("a.urdf", "tip", PlanSettings(count=5), "p.csv", "p.json", {})  # type: ignore[arg-type]


def test_the_command_prints_the_settings_message(tmp_path, capsys):
    """The command line and a script get the same line: the command builds the settings."""
    data = tmp_path / "data.csv"
    data.write_text("lwr_joint_1\n0\n", encoding="utf-8")
    code = main(["calibrate", str(kuka_lwr4plus_urdf()), str(data), "--tip-link", KUKA_FLANGE_LINK, "--level", "dh",
                 "--out", str(tmp_path / "o.urdf"), "--report", str(tmp_path / "r.json")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "the paper's methods (--level dh) need the tool" in err and len(err.splitlines()) == 1
