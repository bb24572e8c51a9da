"""A camera in the fit (pincal.residuals.camera, pincal.fit.camera_start, pincal.fit.camera_calibration).

A UR5 of example-robot-data with a link added on tool0 by a fixed joint: the camera (eye in hand) or the
board (eye to hand). The true joint placements are off the URDF's by 0.5 mm / 0.5 mrad (per coordinate), the
true mount 10 cm and 30 degrees off the URDF's; the corners are projected through the truth
(pincal.simulation.camera_scene) with seeded pixel noise. The start is from nothing: solvePnP, then
OpenCV's hand-eye on the nominal kinematics.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest

from pincal.errors import CalibrationError
from pincal.fit.camera_calibration import CameraFitOptions, calibrate_camera, images_of, reprojection_errors
from pincal.fit.camera_start import HAND_EYE_METHODS, ROBOT_WORLD_METHODS, hand_eye_start
from pincal.measurements.camera_csv import read_corners
from pincal.measurements.charuco import parse_board
from pincal.model.camera_view import pose
from pincal.model.chain import KinematicChain
from pincal.model.corrected_urdf import write_corrected_urdf
from pincal.model.parameter_sets import JointOffsets, PlacementErrors
from pincal.model.pinhole import INTRINSIC_NAMES, CameraIntrinsics
from pincal.residuals.base import KinematicsCache
from pincal.residuals.camera import CameraResidual
from pincal.robots import example_robot_data_urdf
from pincal.simulation.board_images import BoardView, render_board
from pincal.simulation.camera_scene import facing_scene, view_configurations, view_corners, with_fixed_link
from pincal.workflows.detection import DetectSettings, detect_files

ARRANGEMENTS = ("eye_in_hand", "eye_to_hand")
#: 1280x960 px, a wide-angle lens's distortion (OpenCV's sample calibrations: |k1| ~ 0.1-0.3).
INTRINSICS = CameraIntrinsics(1000.0, 1000.0, 640.0, 480.0, (-0.1, 0.05, 1e-3, -5e-4, 0.0), 1280, 960)
BOARD = parse_board("charuco:7x5:0.04:0.03:DICT_5X5_100")
#: A posture of the UR5 with its tool0 pointing sideways, the board 0.5 m ahead of the camera.
Q0 = np.array([0.3, -1.2, 1.4, -1.6, -1.57, 0.2])
#: The true mount on the added link: 10 cm and 30 degrees off the URDF's (the identity).
TRUE_MOUNT = pose(pin.exp3(np.radians(30.0) * np.array([0.6, 0.0, 0.8])), np.array([0.06, 0.0, 0.08]))
#: Pixel noise per coordinate [px]: ChArUco corners found to ~0.1-0.2 px (docs/camera.md's rendered images).
NOISE_PX = 0.2
N_CALIBRATION, N_VALIDATION = 20, 6


def _chain(arrangement: str) -> KinematicChain:
    text = example_robot_data_urdf("ur_description/urdf/ur5_robot.urdf").read_text()
    link = "camera_link" if arrangement == "eye_in_hand" else "board_link"
    return KinematicChain(pin.buildModelFromXML(with_fixed_link(text, "tool0", link)), link, source="<ur5 + camera>")


class _Case:
    """One arrangement's truth and its images: calibration (noise-free and noisy) and validation."""

    def __init__(self, arrangement: str, seed: int, truth_kind: str = "full") -> None:
        rng = np.random.default_rng(seed)
        self.arrangement = arrangement
        self.chain = _chain(arrangement)
        params = PlacementErrors(self.chain)
        self.truth = np.zeros(params.size)
        if truth_kind == "full":  # every joint placement off by 0.5 mm / 0.5 mrad per coordinate, not the mount
            self.truth[: 6 * self.chain.n_joints] = rng.normal(0.0, 0.5e-3, 6 * self.chain.n_joints)
            self.placements = params.placements(self.truth)
        else:  # the joints' zeros only
            offsets = JointOffsets(self.chain)
            self.truth = rng.normal(0.0, 0.5e-3, offsets.size)
            self.placements = offsets.placements(self.truth)
        with self.chain.placed(self.placements):
            self.scene = facing_scene(self.chain, arrangement, Q0, TRUE_MOUNT, INTRINSICS, BOARD)
            q = view_configurations(self.chain, self.scene, Q0, N_CALIBRATION + N_VALIDATION, rng)
            roles = ["calibration"] * N_CALIBRATION + ["validation"] * N_VALIDATION
            self.exact = view_corners(self.chain, self.scene, q, 0.0, rng, roles=roles)
            self.noisy = view_corners(self.chain, self.scene, q, NOISE_PX, rng, roles=roles)


@pytest.fixture(scope="module", params=ARRANGEMENTS)
def case(request: pytest.FixtureRequest) -> _Case:
    return _Case(request.param, seed=7)


def _validation(corners):
    return images_of(corners, corners.roles == "validation")


def test_jacobian_matches_central_differences(case: _Case):
    rng = np.random.default_rng(3)
    params = PlacementErrors(case.chain)
    three = images_of(case.exact, np.arange(3))
    cache = KinematicsCache(params, np.arange(params.size), rng.normal(0.0, 1e-3, params.size), three.q)
    start, _ = hand_eye_start(case.chain, three, case.arrangement, INTRINSICS)
    objective = CameraResidual(cache, three, start, tuple(range(len(INTRINSIC_NAMES))))
    x = objective.start_vector() + rng.normal(0.0, 1e-3, objective.n_params)
    analytic = objective.jacobian(x)
    step = 1e-6  # central differences: truncation ~1e-12 relative, rounding ~1e-10 px / 1e-6
    numeric = np.array([(objective.residual(x + step * e) - objective.residual(x - step * e)) / (2 * step)
                        for e in np.eye(objective.n_params)]).T
    scale = np.abs(numeric).max(axis=0)
    assert np.max(np.abs(analytic - numeric).max(axis=0) / scale) < 1e-5


@pytest.mark.parametrize("arrangement", ARRANGEMENTS)
def test_every_opencv_method_finds_the_mount_when_the_kinematics_are_exact(arrangement: str):
    chain = _chain(arrangement)
    rng = np.random.default_rng(5)
    scene = facing_scene(chain, arrangement, Q0, TRUE_MOUNT, INTRINSICS, BOARD)
    corners = view_corners(chain, scene, view_configurations(chain, scene, Q0, 6, rng), 0.0, rng)
    for method in HAND_EYE_METHODS + ROBOT_WORLD_METHODS:
        start, _ = hand_eye_start(chain, corners, arrangement, INTRINSICS, method)
        # exact corners and kinematics: solvePnP's and the closed forms' rounding, ~1e-7 m
        assert np.abs(start.mount - TRUE_MOUNT).max() < 1e-5, method
        assert np.abs(start.worlds[0] - scene.worlds[0]).max() < 1e-5, method


@pytest.fixture(scope="module")
def exact_fit(case: _Case):
    start, _ = hand_eye_start(case.chain, case.exact, case.arrangement, INTRINSICS)
    return calibrate_camera(case.chain, case.exact, start, "full", CameraFitOptions(selection="all"))


def test_noise_free_images_give_the_truth_from_a_mount_10_cm_and_30_deg_off(case: _Case, exact_fit):
    off_m, off_deg = np.linalg.norm(TRUE_MOUNT[:3, 3]), np.degrees(np.linalg.norm(pin.log3(TRUE_MOUNT[:3, :3])))
    assert off_m > 0.1 - 1e-12 and off_deg > 30.0 - 1e-9
    result = exact_fit
    assert result.rms_px < 1e-7
    assert result.nominal_rms_px > 0.1  # the nominal kinematics cannot explain the images
    # 4 per revolute joint + 6 of the world frame + 6 of the mount, minus those two frames (Everett et al. 1987)
    assert result.rank == 4 * 6 + 6 - 12
    dropped = {case.chain.tip_link + s for s in (".tx", ".ty", ".tz", ".rx", ".ry", ".rz")}
    tip = [d for d in result.dropped if result.params.info[d.index].name in dropped]
    assert len(tip) == 6 and all(name.startswith("mount.") for d in tip for name, _ in d.absorbed_into)
    held_out = reprojection_errors(case.chain, result, _validation(case.exact))
    assert np.sqrt(np.mean(held_out**2)) < 1e-6
    true_tip = case.placements[-1] @ TRUE_MOUNT  # the URDF's tip placement with the true mount folded in
    assert np.abs(result.tip_placement - true_tip).max() < 1e-2  # not identifiable apart from wrist 3's placement


def test_the_corrected_urdf_carries_the_mount(case: _Case, exact_fit, tmp_path):
    source = tmp_path / "robot.urdf"
    link = case.chain.tip_link
    source.write_text(with_fixed_link(example_robot_data_urdf("ur_description/urdf/ur5_robot.urdf").read_text(),
                                      "tool0", link))
    result = exact_fit
    nominal = case.chain.placements()
    with case.chain.placed(list(result.corrected_placements)) as calibrated:
        write_corrected_urdf(source, tmp_path / "corrected.urdf", calibrated, nominal)
    corrected = KinematicChain.from_urdf(tmp_path / "corrected.urdf", link)
    unmounted = replace(result, params=None, vector=np.zeros(0),
                        estimate=replace(result.estimate, mount=np.eye(4)))
    held_out = reprojection_errors(corrected, unmounted, _validation(case.exact))
    assert np.sqrt(np.mean(held_out**2)) < 1e-5  # the URDF's 6 decimals of metres and radians


@pytest.mark.parametrize("arrangement", ARRANGEMENTS)
def test_noise_free_joint_zeros_come_out_exactly(arrangement: str):
    case = _Case(arrangement, seed=11, truth_kind="offsets")
    start, _ = hand_eye_start(case.chain, case.exact, arrangement, INTRINSICS)
    result = calibrate_camera(case.chain, case.exact, start, "offsets", CameraFitOptions(selection="all"))
    assert result.rms_px < 1e-7
    assert np.abs(result.vector[result.kept] - case.truth[result.kept]).max() < 1e-9
    # the first joint turns the whole chain as the world frame does, the last the mount about its axis
    not_kept = sorted(set(range(6)) - set(result.kept.tolist()))
    assert not_kept == [0, 5]
    absorbed = {d.index: d.absorbed_into[0][0] for d in result.dropped}
    assert absorbed[0].split(".")[0] in ("camera", "board") and absorbed[5].startswith("mount.")


@pytest.fixture(scope="module")
def noisy_fit(case: _Case):
    start, _ = hand_eye_start(case.chain, case.noisy, case.arrangement, INTRINSICS)
    return start, calibrate_camera(case.chain, case.noisy, start, "full", CameraFitOptions(selection="all"))


def test_held_out_reprojection_is_at_the_noise_floor(case: _Case, noisy_fit):
    _, result = noisy_fit
    held_out = np.sqrt(np.mean(reprojection_errors(case.chain, result, _validation(case.noisy)) ** 2))
    # the floor: the pixel noise itself, N(0, 0.2 px) per coordinate on every held-out corner; the
    # estimate's own error adds in quadrature (0.03-0.09 px, below, against the noise-free corners), and
    # 6 images' ~300 coordinates give the RMS a sampling spread of ~4 %
    assert NOISE_PX * 0.9 < held_out < NOISE_PX * 1.15
    to_truth = np.sqrt(np.mean(reprojection_errors(case.chain, result, _validation(case.exact)) ** 2))
    before = calibrate_camera(case.chain, case.noisy, noisy_fit[0], "registration")
    nominal = np.sqrt(np.mean(reprojection_errors(case.chain, before, _validation(case.exact)) ** 2))
    # OpenCV's hand-eye on the nominal kinematics, refined by reprojection, misses the true corners by
    # 0.16-0.27 px here (0.5 mm / 0.5 mrad seen from 0.5 m); the joint fit by about 0.03-0.09 px
    assert to_truth < 0.5 * NOISE_PX and nominal > 2 * to_truth


def test_moving_the_board_frame_or_the_world_start_changes_nothing(case: _Case, noisy_fit):
    start, result = noisy_fit
    moved = pose(pin.exp3(np.array([0.0, 0.0, 1.0])), np.array([0.1, -0.05, 0.0]))  # a turn about the board normal
    corners = replace(case.noisy, board_points=case.noisy.board_points @ moved[:3, :3].T + moved[:3, 3])
    moved_start, _ = hand_eye_start(case.chain, corners, case.arrangement, INTRINSICS)
    shifted = replace(start, worlds=start.worlds @ pose(pin.exp3(np.array([0.05, -0.1, 0.1])), np.array([0.02, 0, 0])))
    for again in (calibrate_camera(case.chain, corners, moved_start, "full", CameraFitOptions(selection="all")),
                  calibrate_camera(case.chain, case.noisy, shifted, "full", CameraFitOptions(selection="all"))):
        assert np.array_equal(again.kept, result.kept)
        assert abs(again.rms_px - result.rms_px) < 1e-9
        assert np.abs(again.vector - result.vector).max() < 1e-8  # [m, rad]: the solver's tolerance


def test_intrinsics_estimated_with_the_rest(case: _Case):
    off = INTRINSICS.with_vector(INTRINSICS.vector() + np.array([20.0, -15.0, 8.0, -6.0, 0.03, -0.02, 0, 0, 0]))
    start, _ = hand_eye_start(case.chain, case.exact, case.arrangement, off)
    result = calibrate_camera(case.chain, case.exact, start, "full",
                              CameraFitOptions(intrinsics=INTRINSIC_NAMES, selection="all"))
    assert result.rms_px < 1e-7
    assert np.abs(result.estimate.intrinsics.vector() - INTRINSICS.vector()).max() < 1e-6


def test_bad_options_are_one_line_errors(case: _Case):
    start, _ = hand_eye_start(case.chain, case.exact, case.arrangement, INTRINSICS)
    for options, words in ((CameraFitOptions(intrinsics=("fz",)), "no intrinsic named fz"),
                           (CameraFitOptions(selection="press"), "selection must be one of")):
        with pytest.raises(CalibrationError, match=words) as error:
            calibrate_camera(case.chain, case.exact, start, "offsets", options)
        assert "\n" not in str(error.value)
    two = replace(case.exact, roles=np.array(["calibration"] * 2 + ["validation"] * (len(case.exact.images) - 2),
                                             dtype=object))
    with pytest.raises(CalibrationError, match="at least 3"):
        calibrate_camera(case.chain, two, start, "offsets")


def test_rendered_images_detected_read_and_fitted(tmp_path):
    """End to end at 640x480: images rendered through the truth (pincal.simulation.board_images), pincal
    detect's corners in DATA.csv, read back, the start from nothing and the fit: the pixel conventions and
    corner ids of detection, file and residual agree."""
    import cv2

    chain = _chain("eye_in_hand")
    small = CameraIntrinsics(600.0, 600.0, 320.0, 240.0, INTRINSICS.distortion, 640, 480)
    rng = np.random.default_rng(2)
    scene = facing_scene(chain, "eye_in_hand", Q0, TRUE_MOUNT, small, BOARD)
    q = view_configurations(chain, scene, Q0, 6, rng, spread=0.15, min_corners=20)
    rotations, positions = chain.tool_poses(q)
    names = [f"view_{k}.png" for k in range(len(q))]
    (tmp_path / "images").mkdir()
    for name, r, t in zip(names, rotations, positions):
        camera_T_board = np.linalg.inv(pose(r, t) @ TRUE_MOUNT) @ scene.worlds[0]
        view = BoardView(small.matrix, np.array(small.distortion), (640, 480), cv2.Rodrigues(camera_T_board[:3, :3])[0]
                         .ravel(), camera_T_board[:3, 3])
        cv2.imwrite(str(tmp_path / "images" / name), render_board(BOARD, view, 2.0, rng))
    with open(tmp_path / "joints.csv", "w") as handle:
        handle.write(",".join(["image", *chain.joint_names]) + "\n")
        handle.writelines(",".join([name, *(repr(float(v)) for v in row)]) + "\n" for name, row in zip(names, q))
    detect_files(DetectSettings((tmp_path / "images",), BOARD, tmp_path / "joints.csv", tmp_path / "data.csv"))
    corners, _ = read_corners(tmp_path / "data.csv", chain.joint_specs)
    start, _ = hand_eye_start(chain, corners, "eye_in_hand", small)
    result = calibrate_camera(chain, corners, start, "registration")
    # detection's own error on rendered images: 0.07 px RMS (tests/test_detect.py)
    assert len(corners.images) == len(q) and result.rms_px < 0.1
    # measured: 0.15 mrad; half a pixel off in the pixel convention turns the mount by 1.0 mrad (0.5 px / 600 px)
    assert np.linalg.norm(pin.log3(result.estimate.mount[:3, :3].T @ TRUE_MOUNT[:3, :3])) < 0.5e-3
    assert np.abs(result.estimate.mount[:3, 3] - TRUE_MOUNT[:3, 3]).max() < 5e-4  # measured: 0.09 mm
