"""A camera's calibration files simulated: a UR5 with a camera (eye in hand) or a board (eye to hand) on tool0,
the corners of a ChArUco board as detect writes them, and the camera's intrinsics
(:func:`simulate_camera_files`).

The truth: every joint placement of the UR5 (example-robot-data) off the URDF's by ``error_mm`` / ``error_mrad`` per
coordinate (Gaussian), the mount 10 cm and 30 degrees off the URDF's (the identity), the board 0.5 m ahead of the
camera at a posture with tool0 sideways, a 1280x960 camera with a wide-angle lens's distortion
(:mod:`pincal.simulation.camera_scene`). The URDF written is the nominal one with the links added: eye in hand
``camera_link`` on tool0; eye to hand ``board_link`` on tool0 and ``camera_link`` on the root ``world``, at the
identity. The docs' walk-throughs (docs/camera.md) and the tests make their data here.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pinocchio as pin

from pincal.errors import PincalError
from pincal.fit.camera_calibration import images_of
from pincal.measurements.camera_csv import CornerSet, write_corner_set
from pincal.measurements.charuco import parse_board
from pincal.measurements.data import MeasurementSet
from pincal.model.camera_info import write_camera_info
from pincal.model.camera_view import ARRANGEMENTS, Arrangement, pose
from pincal.model.chain import KinematicChain
from pincal.model.effects import Effect, effect_inputs, joint_basis
from pincal.model.parameter_sets import PlacementErrors
from pincal.model.pinhole import CameraIntrinsics
from pincal.outputs import write_text
from pincal.robots import example_robot_data_urdf
from pincal.simulation.camera_scene import CameraScene, facing_scene, view_configurations, view_corners, with_fixed_link
from pincal.workflows.paths import ensure_directory

__all__ = ["INTRINSICS", "BOARD_SPEC", "TRUE_MOUNT", "SESSION_MOVE", "Q0", "CameraSimulationSettings",
           "CameraSimulation", "SimulatedCamera", "simulate_camera", "simulate_camera_files"]

#: 1280x960 px, a wide-angle lens's distortion (OpenCV's sample calibrations: |k1| ~ 0.1-0.3).
INTRINSICS = CameraIntrinsics(1000.0, 1000.0, 640.0, 480.0, (-0.1, 0.05, 1e-3, -5e-4, 0.0), 1280, 960)
#: The board (docs/camera.md's).
BOARD_SPEC = "charuco:7x5:0.04:0.03:DICT_5X5_100"
#: A posture of the UR5 with its tool0 pointing sideways, the board 0.5 m ahead of the camera.
Q0 = np.array([0.3, -1.2, 1.4, -1.6, -1.57, 0.2])
#: The true mount on the added link: 10 cm and 30 degrees off the URDF's (the identity).
TRUE_MOUNT = pose(pin.exp3(np.radians(30.0) * np.array([0.6, 0.0, 0.8])), np.array([0.06, 0.0, 0.08]))
#: How the board (eye in hand, in its own frame) or the camera (eye to hand, in its own frame) moved between two
#: sessions: 3.6 cm and 5.7 degrees, as a board put back on the table or a tripod nudged.
SESSION_MOVE = pose(pin.exp3(np.array([0.0, 0.0, 0.1])), np.array([0.03, 0.02, 0.0]))


@dataclass(frozen=True)
class CameraSimulationSettings:
    """What :func:`simulate_camera_files` simulates.

    Attributes:
        arrangement: ``eye_in_hand`` or ``eye_to_hand``.
        images: calibration images; held_out: images of role ``validation``.
        noise_px: Gaussian noise of each corner's u and v [px].
        error_mm / error_mrad: the joint placements' true errors, per coordinate (σ) [mm, mrad].
        seed: the random seed.
        effects: joint effects the readings lack, with their true values (:mod:`pincal.model.effects`): the
            images are taken at the readings plus each effect's shift, the calibration images' and the held-out
            ones' each over their own set (an approach flank follows its set's order); default none.
        sessions: sessions the images are dealt to in turn (``s0``, ``s1`` ...): between two, the board
            (eye in hand) or the camera (eye to hand) moved by :data:`SESSION_MOVE`.
    """

    arrangement: Arrangement = "eye_in_hand"
    images: int = 20
    held_out: int = 6
    noise_px: float = 0.2
    error_mm: float = 0.5
    error_mrad: float = 0.5
    seed: int = 1
    effects: tuple[tuple[Effect, tuple[float, ...]], ...] = ()
    sessions: int = 1

    def __post_init__(self) -> None:
        if self.arrangement not in ARRANGEMENTS:
            raise PincalError(f"arrangement must be one of {', '.join(ARRANGEMENTS)}, got '{self.arrangement}'")
        if self.sessions < 1 or self.images < 3 * self.sessions:
            raise PincalError(f"give 1 session or more and 3 calibration images per session, got {self.sessions} "
                              f"session(s) and {self.images} images")
        if self.images < 3 or self.held_out < 0:
            raise PincalError(f"give 3 calibration images or more and no negative count, got {self.images}, "
                              f"{self.held_out}")


@dataclass(frozen=True)
class CameraSimulation:
    """The files written and the truth behind them.

    Attributes:
        urdf / data / intrinsics: the nominal URDF, DATA.csv (every image, the held-out ones of role
            ``validation``) and the camera_info YAML of the true intrinsics.
        held_out: ``held_out.csv``, the held-out images alone (None without any), for ``pincal evaluate``.
        camera_link / board_link: the links to name (board_link None eye in hand).
        placements: the chain's true joint and tip placements (as :meth:`KinematicChain.placements`).
        mount: the true mount (4, 4) [m]; world: the true world frame W (4, 4) [m] of the first session
            (:mod:`pincal.model.camera_view`).
    """

    urdf: Path
    data: Path
    intrinsics: Path
    held_out: Path | None
    camera_link: str
    board_link: str | None
    placements: tuple[np.ndarray, ...]
    mount: np.ndarray
    world: np.ndarray


@dataclass(frozen=True)
class SimulatedCamera:
    """The scene of :func:`simulate_camera`, in memory.

    Attributes:
        urdf_text: the nominal URDF with the links added; chain: from its root to the camera's (eye in hand) or
            the board's link (eye to hand), placed nominally.
        placements: the chain's true placements; scene: the true mount, world frame, intrinsics and board.
        q: each image's configuration (K, 6) [rad]; corners: what each image shows, with the pixel noise.
    """

    urdf_text: str
    chain: KinematicChain
    placements: tuple[np.ndarray, ...]
    scene: CameraScene
    q: np.ndarray
    corners: CornerSet


def simulate_camera(settings: CameraSimulationSettings = CameraSimulationSettings()) -> SimulatedCamera:
    """The truth and the corners of the module docstring, in memory."""
    rng = np.random.default_rng(settings.seed)
    text = example_robot_data_urdf("ur_description/urdf/ur5_robot.urdf").read_text(encoding="utf-8")
    if settings.arrangement == "eye_in_hand":
        text, tip = with_fixed_link(text, "tool0", "camera_link"), "camera_link"
    else:
        text, tip = with_fixed_link(with_fixed_link(text, "tool0", "board_link"), "world", "camera_link"), "board_link"
    chain = KinematicChain(pin.buildModelFromXML(text), tip, source="<ur5 + camera>")
    params = PlacementErrors(chain)
    truth = np.zeros(params.size)
    errors = rng.normal(0.0, 1.0, (chain.n_joints, 6)) * np.r_[[settings.error_mm * 1e-3] * 3,
                                                                 [settings.error_mrad * 1e-3] * 3]
    truth[: 6 * chain.n_joints] = errors.ravel()
    placements = params.placements(truth)
    with chain.placed(placements):
        scene = facing_scene(chain, settings.arrangement, Q0, TRUE_MOUNT, INTRINSICS, parse_board(BOARD_SPEC))
        q = view_configurations(chain, scene, Q0, settings.images + settings.held_out, rng)
        roles = ["calibration"] * settings.images + ["validation"] * settings.held_out
        moves = [np.linalg.matrix_power(SESSION_MOVE, s) for s in range(settings.sessions)]
        # W = base_T_board eye in hand (the board moved in its frame), camera_T_base eye to hand (the camera in its)
        worlds = [scene.worlds[0] @ m if settings.arrangement == "eye_in_hand" else np.linalg.inv(m) @ scene.worlds[0]
                  for m in moves]
        scene = replace(scene, worlds=np.array(worlds))
        sessions = [k % settings.sessions for k in range(settings.images)] + [
            k % settings.sessions for k in range(settings.held_out)]
        corners = view_corners(chain, scene, _actual(chain, q, settings), settings.noise_px, rng, sessions=sessions,
                               roles=roles)
    return SimulatedCamera(text, chain, tuple(placements), scene, q, replace(corners, q=q))


def _actual(chain: KinematicChain, q: np.ndarray, settings: CameraSimulationSettings) -> np.ndarray:
    """The joint angles of readings ``q`` (K, N) under ``settings.effects`` [rad]: each set's own shifts."""
    actual = np.array(q, dtype=float)
    for rows in (np.arange(settings.images), np.arange(settings.images, settings.images + settings.held_out)):
        if settings.effects and rows.size:
            k = len(rows)
            inputs = effect_inputs(chain, MeasurementSet(chain.joint_names, q[rows], np.zeros((k, 1, 3)), None,
                                                         np.full(k, "calibration", dtype=object), np.arange(k) + 2,
                                                         {}, "<simulated>"))
            for effect, values in settings.effects:
                j = chain.joint_names.index(str(effect.joint))
                actual[rows, j] += joint_basis(effect, inputs, j) @ np.asarray(values, dtype=float)
    return actual


def simulate_camera_files(out: str | Path, settings: CameraSimulationSettings = CameraSimulationSettings()
                          ) -> CameraSimulation:
    """Write ``ur5_camera.urdf``, ``DATA.csv``, ``held_out.csv`` and ``camera_info.yaml`` into the folder ``out``
    (module docstring)."""
    folder = ensure_directory(out)
    simulated = simulate_camera(settings)
    corners = simulated.corners
    urdf, data, intrinsics = folder / "ur5_camera.urdf", folder / "DATA.csv", folder / "camera_info.yaml"
    write_text(urdf, simulated.urdf_text)
    write_corner_set(data, corners)
    held_out = None
    if settings.held_out:
        held_out = folder / "held_out.csv"
        write_corner_set(held_out, images_of(corners, np.arange(settings.images, len(corners.images))))
    write_camera_info(intrinsics, INTRINSICS, camera_name="camera_link")
    board_link = None if settings.arrangement == "eye_in_hand" else "board_link"
    return CameraSimulation(urdf, data, intrinsics, held_out, "camera_link", board_link, simulated.placements,
                            TRUE_MOUNT, simulated.scene.worlds[0])
