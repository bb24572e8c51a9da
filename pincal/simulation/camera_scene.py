"""A camera and a ChArUco board around a chain, simulated: where the corners fall in each image (eqs C1-C3).

The scene is the truth of a calibration from images: the arrangement, the world frame W and the mount M of
:mod:`pincal.model.camera_view`, the camera's intrinsics and the board. :func:`facing_scene` places W so
that at one configuration the board is seen straight on at a given distance; :func:`view_configurations`
draws configurations around it whose images show enough of the board; :func:`view_corners` projects the
board's corners (OpenCV's ids and positions, :class:`pincal.measurements.charuco.CharucoSpec`) into the
images with Gaussian pixel noise, as ``pincal detect`` would write them (a
:class:`pincal.measurements.camera_csv.CornerSet`). The chain is evaluated as it is: place it at the truth
first (``chain.placed``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from pincal.measurements.camera_csv import CornerSet
from pincal.measurements.charuco import CharucoSpec
from pincal.model.camera_view import Arrangement, camera_points, pose
from pincal.model.chain import KinematicChain
from pincal.model.pinhole import CameraIntrinsics, project

__all__ = ["MAX_VIEW_ANGLE_DEG", "CameraScene", "with_fixed_link", "board_corners", "facing_scene", "view_corners",
           "view_configurations"]

#: The steepest view of the board an image is drawn with and a plan uses (:mod:`pincal.planning.camera_views`): the
#: angle between the board's normal and the camera's optical axis [deg]. Beyond about 60 degrees the markers
#: foreshorten until the detector loses them and the corners' sub-pixel refinement degrades (OpenCV's calibration
#: tutorials and calib.io's "Calibration Best Practices" tilt boards by up to about 45-60 degrees).
MAX_VIEW_ANGLE_DEG = 60.0


@dataclass(frozen=True)
class CameraScene:
    """The truth behind simulated images.

    Attributes:
        arrangement: ``eye_in_hand`` or ``eye_to_hand``.
        worlds: W per session (S, 4, 4) [m] (:mod:`pincal.model.camera_view`).
        mount: M (4, 4) [m].
        intrinsics: the camera's (with its image size).
        board: the ChArUco board.
    """

    arrangement: Arrangement
    worlds: np.ndarray
    mount: np.ndarray
    intrinsics: CameraIntrinsics
    board: CharucoSpec


def with_fixed_link(urdf_text: str, parent: str, link: str) -> str:
    """``urdf_text`` with a link ``link`` added on ``parent`` by a fixed joint ``<link>_joint`` at the identity:
    where a camera or a board is mounted, its true placement left to the scene's mount."""
    added = (f'<link name="{link}"/><joint name="{link}_joint" type="fixed"><parent link="{parent}"/>'
             f'<child link="{link}"/><origin xyz="0 0 0" rpy="0 0 0"/></joint></robot>')
    head, tail = urdf_text.rsplit("</robot>", 1)
    return head + added + tail


def board_corners(board: CharucoSpec) -> np.ndarray:
    """Every inner corner of ``board`` by its OpenCV id (P, 3) [m], z = 0."""
    return np.array([(*board.corner_position(c), 0.0) for c in range(board.n_corners)])


def facing_scene(chain: KinematicChain, arrangement: Arrangement, q0: np.ndarray, mount: np.ndarray,
                 intrinsics: CameraIntrinsics, board: CharucoSpec, distance: float = 0.5) -> CameraScene:
    """The scene whose world frame puts the board's centre ``distance`` [m] ahead of the camera at the
    configuration ``q0`` (N,), the board's plane facing it, turned 10 degrees about the camera's x axis."""
    rotations, positions = chain.tool_poses(np.asarray(q0, dtype=float)[None, :])
    tip = pose(rotations[0], positions[0])
    centre = board_corners(board).mean(axis=0)
    turn = pin.exp3(np.array([np.radians(10.0), 0.0, 0.0]))
    camera_T_board = pose(turn, np.array([0.0, 0.0, distance]) - turn @ centre)
    if arrangement == "eye_in_hand":  # W = base_T_board
        world = tip @ mount @ camera_T_board
    else:  # W = camera_T_base
        world = camera_T_board @ np.linalg.inv(tip @ mount)
    return CameraScene(arrangement, world[None], mount, intrinsics, board)


def _views(chain: KinematicChain, scene: CameraScene, q: np.ndarray, sessions: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each image's corners in the camera frame (K, P, 3) [m], their pixels (K, P, 2) and whether each is
    seen (K, P): ahead of the camera, inside the image, the board at most MAX_VIEW_ANGLE_DEG from facing it."""
    corners = board_corners(scene.board)
    k, n = len(q), len(corners)
    rotations, positions = chain.tool_poses(q)
    rows = np.repeat(np.arange(k), n)
    board = np.tile(corners, (k, 1))
    _, p = camera_points(scene.arrangement, (rotations[rows], positions[rows]), scene.worlds[sessions[rows]],
                         scene.mount, board)
    p = p.reshape(k, n, 3)
    pixels = project(scene.intrinsics, p.reshape(-1, 3)).reshape(k, n, 2)
    size = np.array([scene.intrinsics.width, scene.intrinsics.height])
    inside = np.all((pixels >= 0.0) & (pixels <= size - 1.0), axis=2) & (p[:, :, 2] > 0.0)
    normal = np.cross(p[:, 1] - p[:, 0], p[:, scene.board.cols - 1] - p[:, 0])  # the board's normal, camera frame
    facing = np.abs(normal[:, 2]) / np.linalg.norm(normal, axis=1) >= np.cos(np.radians(MAX_VIEW_ANGLE_DEG))
    return p, pixels, inside & facing[:, None]


def view_configurations(chain: KinematicChain, scene: CameraScene, q0: np.ndarray, count: int,
                        rng: np.random.Generator, spread: float = 0.25, min_corners: int = 12) -> np.ndarray:
    """``count`` configurations (count, N) drawn uniformly within ``spread`` [rad or m] of ``q0`` on every
    joint, kept where the image shows at least ``min_corners`` corners (session 0's world frame)."""
    kept: list[np.ndarray] = []
    while len(kept) < count:
        q = np.asarray(q0, dtype=float) + rng.uniform(-spread, spread, (4 * count, len(q0)))
        _, _, seen = _views(chain, scene, q, np.zeros(len(q), dtype=np.intp))
        kept.extend(q[seen.sum(axis=1) >= min_corners])
    return np.array(kept[:count])


def view_corners(chain: KinematicChain, scene: CameraScene, q: np.ndarray, noise_px: float, rng: np.random.Generator,
                 sessions: Sequence[int] | None = None, roles: Sequence[str] | None = None) -> CornerSet:
    """The corners images at configurations ``q`` (K, N) show, with N(0, ``noise_px``²) [px] added to u and v.

    ``sessions``: each image's session, an index into ``scene.worlds`` (default: 0); ``roles``: each image's
    role (default: ``calibration``). Images are named ``image_000.png`` ...; an image showing no corner is kept
    with none (the caller draws configurations that show the board, :func:`view_configurations`).
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    k = len(q)
    session = np.zeros(k, dtype=np.intp) if sessions is None else np.asarray(sessions, dtype=np.intp)
    _, pixels, seen = _views(chain, scene, q, session)
    image_of, corner = np.nonzero(seen)
    measured = pixels[image_of, corner] + rng.normal(0.0, noise_px, (len(image_of), 2))
    size = (scene.intrinsics.width, scene.intrinsics.height)
    return CornerSet(
        joint_names=chain.joint_names,
        images=tuple(f"image_{i:03d}.png" for i in range(k)),
        q=q,
        roles=np.array(["calibration"] * k if roles is None else list(roles), dtype=object),
        sessions=np.array([f"s{s}" for s in session], dtype=object),
        sizes=np.tile(size, (k, 1)),
        image_of=image_of,
        corners=corner,
        pixels=measured,
        board_points=board_corners(scene.board)[corner],
        lines=np.arange(2, len(image_of) + 2),
        source="<simulated>",
    )
