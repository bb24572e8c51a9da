"""The chain a camera calibration fits, from the URDF links that carry the camera and the board.

The camera's link (its optical frame: x right, y down, z ahead) is attached by a fixed joint. Where it
hangs from the root through fixed joints only, the camera is fixed in the world (**eye to hand**): the
board's link, attached by a fixed joint on the chain, ends the chain. Otherwise the camera rides on the
chain (**eye in hand**) and ends it; the board is fixed in the world and its pose is estimated. Either way
the fixed joint of the chain's end link is the mount :mod:`pincal.fit.camera_calibration` calibrates and
:func:`pincal.model.corrected_urdf.write_corrected_urdf` writes.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from pincal.errors import ModelError, did_you_mean
from pincal.model.camera_view import Arrangement
from pincal.model.chain import KinematicChain
from pincal.model.description import RobotDescription
from pincal.model.urdf_elements import parent_joint

__all__ = ["camera_chain", "world_link_origin"]


def _fixed_link(description: RobotDescription, model: pin.Model, link: str, what: str) -> int:
    """The Pinocchio joint ``link`` rides on (0: the root) after checking it is a link attached by a fixed joint."""
    body = pin.FrameType.BODY
    if not model.existFrame(link, body):
        links = sorted(f.name for f in model.frames if f.type == body)
        raise ModelError(f"{description.source}: no link named '{link}' for the {what}; "
                         f"{did_you_mean(link, links, 'links')}")
    joint, fixed = parent_joint(description.root(), link)
    if joint is None or not fixed:
        how = "is the root link" if joint is None else f"is attached by the movable joint '{joint}'"
        raise ModelError(f"{description.source}: the {what}'s link '{link}' {how}; give the link attached to it by "
                         "a fixed joint (add one to the URDF if there is none)")
    return int(model.frames[model.getFrameId(link, body)].parentJoint)


def camera_chain(description: RobotDescription, camera_link: str, board_link: str | None = None
                 ) -> tuple[KinematicChain, Arrangement]:
    """The chain to calibrate and the arrangement (module docstring), its tool the identity.

    Args:
        description: the robot (:func:`pincal.model.description.read_description`).
        camera_link: the link of the camera's optical frame.
        board_link: the link of the board's frame (OpenCV's: its first corner's square at the origin, z out of
            the board's back), needed when the camera is fixed in the world and refused when it is not.

    Raises:
        ModelError: one line naming the URDF: a link that is not there or not attached by a fixed joint, a
            camera fixed in the world without the board's link, a camera on the chain with one, a board's
            link off the chain.
    """
    try:
        model = pin.buildModelFromXML(description.text)
    except Exception as exc:  # Pinocchio raises plain RuntimeError/ValueError
        raise ModelError(f"{description.source}: Pinocchio cannot read this URDF ({' '.join(str(exc).split())})"
                         ) from None
    on_chain = _fixed_link(description, model, camera_link, "camera") != 0
    if on_chain:
        if board_link is not None:
            raise ModelError(f"{description.source}: the camera's link '{camera_link}' rides on the chain (eye in "
                             "hand): the board is then fixed in the world and its pose is estimated; "
                             "give no board link")
        return KinematicChain(model, camera_link, source=description.source), "eye_in_hand"
    if board_link is None:
        raise ModelError(f"{description.source}: the camera's link '{camera_link}' hangs from the root (eye to hand): "
                         "name the link on the chain that carries the board")
    if _fixed_link(description, model, board_link, "board") == 0:
        raise ModelError(f"{description.source}: the board's link '{board_link}' hangs from the root like the "
                         "camera's; one of them must ride on the chain")
    return KinematicChain(model, board_link, source=description.source), "eye_to_hand"


def world_link_origin(description: RobotDescription, link: str, base_T_link: np.ndarray) -> tuple[str, np.ndarray]:
    """The fixed joint and its origin (4, 4) [m] that put ``link``, hanging from the root through fixed joints
    (the camera eye to hand, the board eye in hand), at ``base_T_link`` in the root link's frame: the
    calibrated world frame W (``inv(W)`` eye to hand, ``W`` eye in hand) for a corrected URDF
    (:func:`pincal.model.urdf.write_urdf_with_origins`). The link's parent keeps its place.

    Raises:
        ModelError: the link is not there, not attached by a fixed joint, or rides on the chain.
    """
    model = pin.buildModelFromXML(description.text)
    if _fixed_link(description, model, link, "world frame") != 0:
        raise ModelError(f"{description.source}: link '{link}' rides on the chain; the world frame's link hangs "
                         "from the root")
    root = description.root()
    joint, _ = parent_joint(root, link)
    parent = next(j.find("parent").get("link") for j in root.findall("joint") if j.get("name") == joint)
    root_T_parent = model.frames[model.getFrameId(parent)].placement.homogeneous  # fixed to the root: its pose
    return str(joint), np.linalg.inv(root_T_parent) @ np.asarray(base_T_link, dtype=float)
