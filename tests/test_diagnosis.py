"""pincal diagnose on data with one undeclared effect, on clean data, and on the TIAGo sessions.

Simulated KUKA LWR 4+: ground truth = Table 1 + the zero-offset deviations of
Table 2 (so the ``offsets`` level is exact), 6D measurements with 0.02 mm /
0.02 deg noise, the tool known; the effect is injected without being declared.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from pincal.cli.commands import main
from pincal.diagnosis.diagnose import diagnose
from pincal.fit.chain_calibration import calibrate_chain
from pincal.model.chain import KinematicChain
from pincal.model.dh import KUKA_LWR4_DH, TABLE2_SMALL, DHDeviations, DHTable
from pincal.model.effects import parse_effect, time_column
from pincal.robots import KUKA_FLANGE_LINK

OFFSETS_ONLY = DHDeviations(
    "offsets",
    DHTable(alpha=np.zeros(7), epsilon=TABLE2_SMALL.delta.epsilon, r=np.zeros(7), d=np.zeros(7)),
)
SETTINGS = dict(sigma_pos_mm=0.02, sigma_rot_deg=0.02, n_cpa=8, n_calibration=80, n_validation=20,
                validation_noise=False)


def _run(kuka_urdf, effect_text, seed=3):
    from pincal.simulation.paper import SimulationSettings, simulate_experiment

    chain = KinematicChain.from_urdf(kuka_urdf, KUKA_FLANGE_LINK)
    effects = [parse_effect(effect_text)] if effect_text else []
    experiment = simulate_experiment(chain, KUKA_LWR4_DH, OFFSETS_ONLY, SimulationSettings(seed=seed, **SETTINGS),
                                     effects=effects)
    chain = KinematicChain.from_urdf(kuka_urdf, KUKA_FLANGE_LINK, tool=experiment.tool)
    calibration = calibrate_chain(chain, experiment.calibration, "offsets", tool_known=True)
    result = diagnose(chain, calibration, experiment.calibration, heldout=experiment.validation,
                      time=time_column(experiment.calibration), heldout_time=time_column(experiment.validation))
    return result, effects


@pytest.fixture(scope="module")
def effect_free_heldout_rms(kuka_urdf):
    result, _ = _run(kuka_urdf, None)
    return result.heldout_errors.position.rms


def test_clean_data_claims_nothing(kuka_urdf):
    result, _ = _run(kuka_urdf, None)
    assert result.effects == () and result.steps == ()
    assert result.unexplained is None


@pytest.mark.parametrize(
    "effect_text",
    [
        "compliance:lwr_joint_2:2e-4",
        "encoder_scale:lwr_joint_4:0.003",
        "cyclic:lwr_joint_3:2:0.002:-0.001",
        "backlash:lwr_joint_4:0.004:gravity",
        "backlash:lwr_joint_2:0.003:approach",
        "drift:1e-7:-2e-7:1e-7",
        "sensor_scale:0.0005",
    ],
)
def test_undeclared_effect_is_found_measured_and_removed(kuka_urdf, effect_free_heldout_rms, effect_text):
    result, [(truth, values)] = _run(kuka_urdf, effect_text)
    assert [e.label for e, _, _ in result.effects] == [truth.label]
    effect, found, std = result.effects[0]
    assert np.all(np.abs(found - values) <= 3.0 * std), f"{found} ± {std} vs {values}"
    ratio = result.heldout_errors.position.rms / effect_free_heldout_rms
    assert ratio <= 1.3, f"held-out RMS {ratio:.2f}× the effect-free calibration's"
    step = result.steps[0]
    assert step.heldout_after.position.rms < step.heldout_before.position.rms


def test_diagnose_command_writes_effects_that_evaluate_applies(tmp_path, kuka_urdf, capsys):
    sim = tmp_path / "sim"
    assert main(["simulate", "--out", str(sim), "--deviations", "small", "--sigma-pos", "0.02", "--sigma-rot",
                 "0.02", "--seed", "2", "--effect", "encoder_scale:lwr_joint_4:0.003"]) == 0
    truth = json.loads((sim / "truth.json").read_text())
    assert truth["effects"] == [{"type": "encoder_scale", "joint": "lwr_joint_4", "value": 0.003}]
    tool = ",".join(repr(v) for v in truth["tool"]["xyz_m"] + truth["tool"]["rpy_rad"])
    out, report = tmp_path / "k.urdf", tmp_path / "REPORT.json"
    code = main(["diagnose", str(kuka_urdf), str(sim / "calibration.csv"), "--validation", str(sim / "validation.csv"),
                 "--tip-link", KUKA_FLANGE_LINK, "--tool", tool, "--out", str(out), "--report", str(report)])
    assert code == 0, capsys.readouterr().err
    doc = json.loads(report.read_text())
    assert doc["effects"][0]["type"] == "encoder_scale" and doc["effects"][0]["joint"] == "lwr_joint_4"
    assert abs(doc["effects"][0]["value"] - 0.003) < 1e-4
    assert all(p.endswith(".png") for p in doc["diagnosis"]["plots"]) and len(doc["diagnosis"]["plots"]) == 2
    metrics = tmp_path / "m.json"
    assert main(["evaluate", str(out), str(report), str(sim / "validation.csv"), "--json", str(metrics)]) == 0
    with_effects = json.loads(metrics.read_text())["position"]["rms_mm"]
    doc["effects"] = []
    stripped = tmp_path / "no_effects.json"
    stripped.write_text(json.dumps(doc))
    assert main(["evaluate", str(out), str(stripped), str(sim / "validation.csv"), "--json", str(metrics)]) == 0
    without = json.loads(metrics.read_text())["position"]["rms_mm"]
    assert with_effects < 0.2 * without  # evaluate applies the effects the URDF cannot carry


def test_tiago_diagnose_beats_the_geometric_calibration(tmp_path):
    """Real data: the held-out error after diagnose is below the best of the URDF issue (3.22 mm)."""
    from pathlib import Path

    from pincal.robots import example_robot_data_urdf

    data = Path(__file__).resolve().parent.parent / "data" / "tiago_mocap"
    out, report = tmp_path / "t.urdf", tmp_path / "R.json"
    code = main(["diagnose", str(example_robot_data_urdf("tiago_description/robots/tiago.urdf")),
                 str(data / "qualisys_2021-11-30_static_postures.csv"),
                 "--validation", str(data / "qualisys_2021-11-26_static_postures.csv"),
                 "--tip-link", "wrist_ft_tool_link", "--out", str(out), "--report", str(report)])
    assert code == 0
    doc = json.loads(report.read_text())
    first = doc["effects"][0]
    assert (first["type"], first["joint"], first["source"]) == ("backlash", "arm_6_joint", "approach")
    held = doc["diagnosis"]["heldout_errors"]["position_per_point"][0]["rms_mm"]
    assert held < 3.22
    assert any("outside the physical range" in note for note in doc["diagnosis"]["notes"])
