"""The mounted frame's relative pose between images (pincal.fit.camera_motion): measured by PnP against the
simulation's truth, its floor against a Monte Carlo of the corners' noise, and nothing of the world frame in it.

The data: pincal.workflows.camera_simulation's UR5 in memory, noise-free corners of 5 images per arrangement, the
noise added here.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from pincal.fit.camera_calibration import mounted_frames
from pincal.fit.camera_motion import measured_motions, motion_errors, relative_motions, within_floor
from pincal.simulation.camera_scene import view_corners
from pincal.workflows.camera_simulation import INTRINSICS, SESSION_MOVE, CameraSimulationSettings, simulate_camera

ARRANGEMENTS = ("eye_in_hand", "eye_to_hand")


@pytest.fixture(scope="module", params=ARRANGEMENTS)
def scene(request):
    """Noise-free corners of 5 images and the truth's motion of the mounted frame between consecutive ones."""
    sim = simulate_camera(CameraSimulationSettings(request.param, images=3, held_out=2, noise_px=0.0, seed=5))
    with sim.chain.placed(list(sim.placements)):
        frames = mounted_frames(sim.chain, sim.corners, sim.scene.mount)
    return request.param, sim, frames


def _noisy(sim, noise_px: float, seed: int):
    rng = np.random.default_rng(seed)
    return replace(sim.corners, pixels=sim.corners.pixels + rng.normal(0.0, noise_px, sim.corners.pixels.shape))


def test_noise_free_corners_measure_the_true_motion_and_no_floor(scene):
    arrangement, sim, frames = scene
    measured = measured_motions(sim.corners, INTRINSICS, arrangement)
    assert measured.pairs.tolist() == [[0, 1], [1, 2], [2, 3], [3, 4]] and not measured.unplaced
    errors = motion_errors(relative_motions(frames, measured.pairs), measured.motions)
    assert errors.max() < 1e-6  # [mm, deg]: PnP refined to the rounding of the rendered pixels
    assert measured.noise_px is not None and measured.noise_px < 1e-9 and measured.floor.max() < 1e-6


def test_the_floor_is_the_noise_s_spread_of_the_measured_motion_and_scales_with_it(scene):
    """The floor (eqs R4-R6) against 24 draws of 0.2 px noise: the RMS error of the measured motions against the
    truth's is the RMS floor to the draws' spread (~3 pairs' 3 coordinates x 24: ~10 %); the same draw scaled by 4
    gives a floor 4 times larger (to the linearisation's ~1 %)."""
    arrangement, sim, frames = scene
    errors, floors = [], []
    for seed in range(24):
        measured = measured_motions(_noisy(sim, 0.2, seed), INTRINSICS, arrangement)
        errors.append(motion_errors(relative_motions(frames, measured.pairs), measured.motions))
        floors.append(measured.floor)
        assert measured.noise_px is not None and 0.15 < measured.noise_px < 0.25
    spread = np.sqrt(np.mean(np.square(errors), axis=(0, 1)))
    floor = np.sqrt(np.mean(np.square(floors), axis=(0, 1)))
    assert np.all(floor > 0.0) and np.all(np.abs(spread / floor - 1.0) < 0.25), (spread, floor)
    small, large = (measured_motions(_noisy(sim, s, 0), INTRINSICS, arrangement) for s in (0.05, 0.2))
    assert np.allclose(large.floor / small.floor, 4.0, rtol=0.02)


def test_a_perfect_model_is_within_the_floor_and_an_offset_one_is_not(scene):
    arrangement, sim, frames = scene
    measured = measured_motions(_noisy(sim, 0.2, 0), INTRINSICS, arrangement)
    assert within_floor(motion_errors(relative_motions(frames, measured.pairs), measured.motions), measured.floor)
    mount = np.eye(4)
    mount[0, 3] = 0.05  # the mounted frame 5 cm off along its x axis: the motions' translations off by centimetres
    wrong = motion_errors(relative_motions(frames @ mount, measured.pairs), measured.motions)
    assert not within_floor(wrong, measured.floor)
    assert not within_floor(np.zeros((0, 2)), np.zeros((0, 2)))  # no pairs: nothing to say


def test_moving_the_world_frame_changes_no_measured_motion(scene):
    """The board (eye in hand) or the camera (eye to hand) moved by 3.6 cm and 5.7 degrees: other pixels, the same
    motions measured (eq R2 holds no world frame)."""
    arrangement, sim, _ = scene
    moved = sim.scene.worlds[0] @ SESSION_MOVE if arrangement == "eye_in_hand" else SESSION_MOVE @ sim.scene.worlds[0]
    with sim.chain.placed(list(sim.placements)):
        other = view_corners(sim.chain, replace(sim.scene, worlds=moved[None]), sim.q, 0.0, np.random.default_rng(0))
    assert np.abs(other.pixels[:10] - sim.corners.pixels[:10]).max() > 1.0
    first, second = (measured_motions(c, INTRINSICS, arrangement) for c in (sim.corners, other))
    assert np.array_equal(first.pairs, second.pairs)
    assert motion_errors(first.motions, second.motions).max() < 1e-6


def test_pairs_are_consecutive_images_of_one_session_and_unplaced_images_are_skipped(scene):
    arrangement, sim, _ = scene
    corners = replace(sim.corners, sessions=np.array(["a", "b", "a", "a", "c"], dtype=object))
    one_row = np.flatnonzero(corners.image_of == 2)[:3]  # image 2 keeps 3 corners: too few for PnP
    keep = np.ones(len(corners.image_of), dtype=bool)
    keep[np.setdiff1d(np.flatnonzero(corners.image_of == 2), one_row)] = False
    corners = replace(corners, image_of=corners.image_of[keep], pixels=corners.pixels[keep],
                      board_points=corners.board_points[keep], corners=corners.corners[keep], lines=corners.lines[keep])
    measured = measured_motions(corners, INTRINSICS, arrangement)
    assert measured.pairs.tolist() == [[0, 3]] and measured.unplaced == ("image_002.png",)
