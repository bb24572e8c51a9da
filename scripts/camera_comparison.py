"""pincal's camera calibration against every OpenCV hand-eye method on the nominal kinematics, side by side.

A UR5 of example-robot-data with a link added on tool0 (the camera, eye in hand; the board, eye to hand), its
joint placements truly off the URDF's by ``--error-mm`` / ``--error-mrad`` per coordinate (0 for exact
kinematics), the true mount 10 cm and 30 degrees off the URDF's; the corners of a 7x5 ChArUco board projected
through the truth into 1280x960 images with ``--noise-px`` of Gaussian pixel noise
(:mod:`pincal.simulation.camera_scene`). Each method is given the same calibration images:

* OpenCV: solvePnP per image, then ``cv2.calibrateHandEye`` (TSAI, PARK, HORAUD, ANDREFF, DANIILIDIS) or
  ``cv2.calibrateRobotWorldHandEye`` (SHAH, LI) on the nominal kinematics (:mod:`pincal.fit.camera_start`);
* pincal at each level: from TSAI's answer, the joint fit (:func:`pincal.fit.camera_calibration.calibrate_camera`;
  level ``registration`` is OpenCV's answer refined by reprojection, the kinematics nominal).

On held-out images: the reprojection RMS per coordinate [px] (its floor: the pixel noise), and the error of the
mounted frame's relative pose between consecutive held-out configurations, ``inv(T_j M) T_k M`` against the
truth's [mm, deg] (the camera's motion eye in hand, the board's eye to hand; no world frame enters it).

    python scripts/camera_comparison.py [--images 30] [--held-out 20] [--noise-px 0.2] [--error-mm 0.5]
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass, replace

import numpy as np
import pinocchio as pin

from pincal.fit.camera_calibration import (
    CameraFitOptions,
    calibrate_camera,
    images_of,
    mounted_frames,
    reprojection_errors,
)
from pincal.fit.camera_motion import image_pairs, motion_errors, relative_motions
from pincal.fit.camera_start import HAND_EYE_METHODS, ROBOT_WORLD_METHODS, hand_eye_start
from pincal.measurements.camera_csv import CornerSet
from pincal.measurements.charuco import parse_board
from pincal.model.camera_view import Arrangement, pose
from pincal.model.chain import KinematicChain
from pincal.model.parameter_sets import CHAIN_LEVELS, PlacementErrors
from pincal.model.pinhole import CameraIntrinsics
from pincal.robots import example_robot_data_urdf
from pincal.simulation.camera_scene import facing_scene, view_configurations, view_corners, with_fixed_link

INTRINSICS = CameraIntrinsics(1000.0, 1000.0, 640.0, 480.0, (-0.1, 0.05, 1e-3, -5e-4, 0.0), 1280, 960)
BOARD = parse_board("charuco:7x5:0.04:0.03:DICT_5X5_100")
Q0 = np.array([0.3, -1.2, 1.4, -1.6, -1.57, 0.2])
TRUE_MOUNT = pose(pin.exp3(np.radians(30.0) * np.array([0.6, 0.0, 0.8])), np.array([0.06, 0.0, 0.08]))


@dataclass(frozen=True)
class Row:
    """One method's numbers: held-out reprojection RMS [px], relative-pose errors (RMS) [mm, deg], time [s]."""

    method: str
    held_out_px: float
    relative_mm: float
    relative_deg: float
    seconds: float


def _relative_errors(chain: KinematicChain, placements: list[np.ndarray], mount: np.ndarray, corners: CornerSet,
                     true_placements: list[np.ndarray]) -> tuple[float, float]:
    """RMS over consecutive pairs of the error of inv(T_j M) T_k M [mm, deg] (pincal.fit.camera_motion, eqs R1, R3)."""
    pairs = image_pairs(corners, np.ones(len(corners.images), dtype=bool))
    with chain.placed(placements):
        model = relative_motions(mounted_frames(chain, corners, mount), pairs)
    with chain.placed(true_placements):
        truth = relative_motions(mounted_frames(chain, corners, TRUE_MOUNT), pairs)
    mm, deg = np.sqrt(np.mean(motion_errors(model, truth) ** 2, axis=0))
    return float(mm), float(deg)


def compare(arrangement: Arrangement, images: int = 30, held_out: int = 20, noise_px: float = 0.2,
            error_mm: float = 0.5, error_mrad: float = 0.5, seed: int = 1) -> list[Row]:
    """The rows of the module docstring's table for one arrangement."""
    rng = np.random.default_rng(seed)
    link = "camera_link" if arrangement == "eye_in_hand" else "board_link"
    text = with_fixed_link(example_robot_data_urdf("ur_description/urdf/ur5_robot.urdf").read_text(), "tool0", link)
    chain = KinematicChain(pin.buildModelFromXML(text), link, source="<ur5 + camera>")
    params = PlacementErrors(chain)
    truth = np.zeros(params.size)
    errors = rng.normal(0.0, 1.0, (chain.n_joints, 6)) * np.r_[[error_mm * 1e-3] * 3, [error_mrad * 1e-3] * 3]
    truth[: 6 * chain.n_joints] = errors.ravel()
    true_placements = params.placements(truth)
    with chain.placed(true_placements):
        scene = facing_scene(chain, arrangement, Q0, TRUE_MOUNT, INTRINSICS, BOARD)
        q = view_configurations(chain, scene, Q0, images + held_out, rng)
        roles = ["calibration"] * images + ["validation"] * held_out
        corners = view_corners(chain, scene, q, noise_px, rng, roles=roles)
    calibration = images_of(corners, corners.roles != "validation")
    validation = images_of(corners, corners.roles == "validation")
    nominal = chain.placements()
    rows = []
    for method in HAND_EYE_METHODS + ROBOT_WORLD_METHODS:
        started = time.perf_counter()
        start, _ = hand_eye_start(chain, calibration, arrangement, INTRINSICS, method)
        seconds = time.perf_counter() - started
        # OpenCV's answer as a calibration at level registration without the refinement: its frames as they are
        as_is = calibrate_camera(chain, calibration, start, "registration")
        pixels = reprojection_errors(chain, replace(as_is, estimate=start), validation)
        rows.append(Row(f"OpenCV {method}", float(np.sqrt(np.mean(pixels**2))),
                        *_relative_errors(chain, nominal, start.mount, validation, true_placements), seconds))
    start, _ = hand_eye_start(chain, calibration, arrangement, INTRINSICS)
    for level in CHAIN_LEVELS:
        started = time.perf_counter()
        result = calibrate_camera(chain, calibration, start, level, CameraFitOptions())
        seconds = time.perf_counter() - started
        pixels = reprojection_errors(chain, result, validation)
        rows.append(Row(f"pincal {level}", float(np.sqrt(np.mean(pixels**2))),
                        *_relative_errors(chain, list(result.chain_placements), result.estimate.mount, validation,
                                          true_placements), seconds))
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--images", type=int, default=30)
    parser.add_argument("--held-out", type=int, default=20)
    parser.add_argument("--noise-px", type=float, default=0.2)
    parser.add_argument("--error-mm", type=float, default=0.5)
    parser.add_argument("--error-mrad", type=float, default=0.5)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    for arrangement in ("eye_in_hand", "eye_to_hand"):
        print(f"\n{arrangement}: {args.images} calibration images, {args.held_out} held out, {args.noise_px} px "
              f"noise, joints off by {args.error_mm} mm / {args.error_mrad} mrad")
        print(f"{'method':<22} {'held-out px':>11} {'rel. mm':>8} {'rel. deg':>9} {'time s':>7}")
        for row in compare(arrangement, args.images, args.held_out, args.noise_px, args.error_mm, args.error_mrad,
                           args.seed):
            print(f"{row.method:<22} {row.held_out_px:>11.3f} {row.relative_mm:>8.3f} {row.relative_deg:>9.4f} "
                  f"{row.seconds:>7.2f}")


if __name__ == "__main__":
    main()
