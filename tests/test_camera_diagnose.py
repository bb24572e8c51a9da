"""Joint effects seen through a camera (eq C4 of pincal.residuals.camera) and diagnose on a camera's images
(pincal.diagnosis.camera_diagnose).

A UR5 of example-robot-data, eye in hand (pincal.workflows.camera_simulation's scene: the joint placements off by
0.5 mm / 0.5 mrad, the mount 10 cm and 30 degrees off); the corners are projected at the true joint angles, the
readings being those minus the true effect.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml

from pincal.cli.commands import main
from pincal.diagnosis.camera_diagnose import CameraDiagnosis, diagnose_camera
from pincal.fit.camera_calibration import CameraProblem, calibrate_camera, images_of
from pincal.fit.camera_start import hand_eye_start
from pincal.model.effects import Effect, effect_inputs
from pincal.model.parameter_sets import PlacementErrors
from pincal.model.pinhole import INTRINSIC_NAMES
from pincal.residuals.base import KinematicsCache
from pincal.residuals.camera import CameraResidual
from pincal.residuals.sensor_values import ModelledEffects
from pincal.workflows.camera_simulation import (
    INTRINSICS,
    CameraSimulationSettings,
    simulate_camera,
    simulate_camera_files,
)

EFFECTS = (Effect("backlash", "elbow_joint", source="approach"), Effect("cyclic", "wrist_1_joint", harmonic=2),
           Effect("compliance", "shoulder_lift_joint"), Effect("encoder_scale", "wrist_2_joint"))


@pytest.mark.parametrize("arrangement", ["eye_in_hand", "eye_to_hand"])
def test_effect_columns_match_central_differences(arrangement: str):
    rng = np.random.default_rng(4)
    simulated = simulate_camera(CameraSimulationSettings(arrangement, images=4, held_out=0, seed=2))
    chain, corners = simulated.chain, simulated.corners
    params = PlacementErrors(chain)
    start, _ = hand_eye_start(chain, corners, arrangement, INTRINSICS)
    problem = CameraProblem(chain, params, corners, start, np.zeros(len(corners.images), dtype=np.intp))
    inputs = effect_inputs(chain, problem.rows_view())
    cache = KinematicsCache(params, np.arange(params.size), rng.normal(0.0, 1e-3, params.size), corners.q)
    objective = CameraResidual(cache, corners, start, tuple(range(len(INTRINSIC_NAMES))),
                               effects=ModelledEffects(EFFECTS, inputs))
    x = objective.start_vector() + rng.normal(0.0, 1e-3, objective.n_params)
    x[objective.blocks["effects"]] = rng.normal(0.0, 3e-3, objective.blocks["effects"].stop
                                                 - objective.blocks["effects"].start)
    analytic = objective.jacobian(x)
    step = 1e-6  # central differences: truncation ~1e-12 relative, rounding ~1e-10 px / 1e-6
    numeric = np.array([(objective.residual(x + step * e) - objective.residual(x - step * e)) / (2 * step)
                        for e in np.eye(objective.n_params)]).T
    scale = np.abs(numeric).max(axis=0)
    assert np.all(scale[objective.blocks["effects"]] > 1.0)  # every effect moves some corner by a pixel per unit
    assert np.max(np.abs(analytic - numeric).max(axis=0) / scale) < 1e-5
    # a candidate's columns (its values zero) are the Jacobian's of the residual with it, at zero
    plain = CameraResidual(cache, corners, start, tuple(range(len(INTRINSIC_NAMES))),
                           effects=ModelledEffects((), inputs))
    x0 = x[: plain.n_params]
    with_zero = np.r_[x0, np.zeros(objective.n_params - plain.n_params)]
    columns = np.hstack(plain.effect_columns(x0, EFFECTS))
    assert np.allclose(columns, objective.jacobian(with_zero)[:, objective.blocks["effects"]], rtol=1e-12, atol=1e-9)


#: The true backlash of the elbow's approach flank [rad]: 3 mrad turn the camera 0.5 m from the board by ~1.5 mm,
#: several pixels (the held-out images' RMS ~5 px against 0.2 px of noise).
BACKLASH = Effect("backlash", "elbow_joint", source="approach")
N_CALIBRATION, N_HELD = 20, 8
NOISE_PX = 0.2


def _settings(value: float) -> CameraSimulationSettings:
    return CameraSimulationSettings("eye_in_hand", images=N_CALIBRATION, held_out=N_HELD, noise_px=NOISE_PX, seed=3,
                                    effects=((BACKLASH, (value,)),))


def _images(value: float) -> tuple:
    """The scene's chain, its calibration and held-out images with the true backlash ``value`` [rad] on the elbow,
    and the camera calibration of the former (level full, from OpenCV's hand-eye on the nominal kinematics)."""
    simulated = simulate_camera(_settings(value))
    chain, corners = simulated.chain, simulated.corners
    used, held = images_of(corners, corners.roles != "validation"), images_of(corners, corners.roles == "validation")
    start, names = hand_eye_start(chain, used, "eye_in_hand", INTRINSICS)
    return chain, corners, held, calibrate_camera(chain, used, start, "full", session_names=names)


@pytest.fixture(scope="module")
def with_backlash() -> CameraDiagnosis:
    chain, corners, held, calibration = _images(3e-3)
    return diagnose_camera(chain, calibration, corners, held)


def test_diagnose_names_the_backlash_and_the_held_out_images_reach_the_noise(with_backlash: CameraDiagnosis):
    diagnosis = with_backlash
    assert [effect for effect, _, _ in diagnosis.effects] == [BACKLASH]
    (_, value, std), = diagnosis.effects
    assert abs(value[0] - 3e-3) < max(3 * std[0], 1e-4)  # its value to 0.1 mrad
    assert diagnosis.calibration_rms_px > 5 * NOISE_PX  # the geometry alone cannot explain it
    assert diagnosis.heldout_before_px > 10 * NOISE_PX
    # the noise floor: the pixel noise and what 20 images leave undetermined of the geometry (24 of its 42
    # parameters), which the held-out images see
    assert diagnosis.rms_px < 1.1 * NOISE_PX and diagnosis.heldout_after_px < 1.2 * NOISE_PX
    assert diagnosis.steps[0].candidates[0].verdict == "adopted"


def test_without_the_effect_nothing_is_claimed():
    chain, corners, held, calibration = _images(0.0)
    diagnosis = diagnose_camera(chain, calibration, corners, held)
    assert diagnosis.effects == ()
    assert diagnosis.heldout_after_px == diagnosis.heldout_before_px < 1.2 * NOISE_PX
    assert all(candidate.delta_bic > -10.0 for candidate in diagnosis.last_candidates)


def test_cli_writes_the_effects_and_evaluate_applies_them(tmp_path, capsys):
    """... and --html writes the report's page, as calibrate --camera-link and pincal report do."""
    files = simulate_camera_files(tmp_path, _settings(3e-3))
    out, report_path, page = tmp_path / "C.urdf", tmp_path / "REPORT.json", tmp_path / "REPORT.html"
    camera = ["--camera-link", "camera_link", "--intrinsics", str(files.intrinsics)]
    assert main(["diagnose", str(files.urdf), str(files.data), *camera, "--validation", str(files.held_out),
                 "--out", str(out), "--report", str(report_path), "--quiet", "--html", str(page),
                 "--images", str(tmp_path)]) == 0
    assert f"wrote {page}" in capsys.readouterr().out and "backlash" in page.read_text()
    report = json.loads(report_path.read_text())
    assert [(e["type"], e["joint"], e["source"]) for e in report["effects"]] == [("backlash", "elbow_joint",
                                                                                  "approach")]
    held = report["diagnosis"]["heldout"]
    assert held["before_px"] > 10 * NOISE_PX and held["after_px"] < 1.2 * NOISE_PX
    assert report["camera"]["reprojection"]["validation"]["after"]["rms_px"] == pytest.approx(held["after_px"])
    effects = yaml.safe_load((tmp_path / "C.effects.yaml").read_text())["effects"]
    assert effects[0]["value"] == pytest.approx(report["effects"][0]["value"])
    assert (tmp_path / "C.camera_info.yaml").is_file()
    evaluation = tmp_path / "evaluation.json"
    assert main(["evaluate", str(out), str(report_path), str(files.held_out), "--json", str(evaluation)]) == 0
    after = json.loads(evaluation.read_text())["reprojection"]["after"]["rms_px"]
    assert after == pytest.approx(held["after_px"], rel=1e-6)  # the effects applied to the held-out images
    # and to the camera's motions between them: the backlash's 3 mrad moves the camera by millimetres, above
    # PnP's floor, which the diagnosed model's motions reach
    motion = json.loads(evaluation.read_text())["relative_pose"]
    assert motion["after_within_floor"] and not motion["before_within_floor"], motion


def test_cli_refusals_name_the_flag(tmp_path, capsys):
    files = simulate_camera_files(tmp_path, CameraSimulationSettings(images=4, held_out=0))
    out = ["--out", str(tmp_path / "C.urdf"), "--report", str(tmp_path / "R.json")]
    assert main(["diagnose", str(files.urdf), str(files.data), "--camera-link", "camera_link", "--intrinsics",
                 str(files.intrinsics), "--lateral", *out]) == 2
    assert "--lateral does not apply to diagnose on a camera's images" in capsys.readouterr().err
    assert main(["diagnose", str(files.urdf), str(files.data), *out]) == 2
    assert "--camera-link" in capsys.readouterr().err
    assert not any(tmp_path.glob("C.*")) and not (tmp_path / "R.json").exists()
