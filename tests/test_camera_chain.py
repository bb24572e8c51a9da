"""The chain of a camera calibration from the camera's and the board's links (pincal.model.camera_chain)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from pincal.errors import ModelError
from pincal.model.camera_chain import camera_chain, world_link_origin
from pincal.model.camera_view import pose
from pincal.model.description import read_description
from pincal.model.urdf import format_floats, rpy_from_matrix
from pincal.robots import example_robot_data_urdf
from pincal.simulation.camera_scene import with_fixed_link


@pytest.fixture(scope="module")
def description(tmp_path_factory):
    """A UR5 with a camera on tool0, a camera hanging from the root and a board on tool0, a second board
    hanging from the root, and a camera on the UR's "base" link (turned by pi from base_link)."""
    text = example_robot_data_urdf("ur_description/urdf/ur5_robot.urdf").read_text()
    for parent, link in (("tool0", "wrist_camera"), ("world", "room_camera"), ("tool0", "board"),
                         ("world", "table_board"), ("base", "base_camera")):
        text = with_fixed_link(text, parent, link)
    path = tmp_path_factory.mktemp("camera_chain") / "robot.urdf"
    path.write_text(text)
    return read_description(path)


def test_the_arrangement_follows_the_links(description):
    chain, arrangement = camera_chain(description, "wrist_camera")
    assert (arrangement, chain.tip_link, chain.n_joints) == ("eye_in_hand", "wrist_camera", 6)
    chain, arrangement = camera_chain(description, "room_camera", "board")
    assert (arrangement, chain.tip_link, chain.n_joints) == ("eye_to_hand", "board", 6)


@pytest.mark.parametrize("camera, board, words", [
    ("wrist_cam", None, "no link named 'wrist_cam' for the camera"),
    ("wrist_3_link", None, "attached by the movable joint 'wrist_3_joint'"),
    ("world", None, "'world' is the root link"),
    ("wrist_camera", "board", "rides on the chain \\(eye in hand\\)"),
    ("room_camera", None, "hangs from the root \\(eye to hand\\): name the link on the chain that carries the board"),
    ("room_camera", "table_board", "hangs from the root like the camera's"),
])
def test_bad_links_are_one_line_errors(description, camera, board, words):
    with pytest.raises(ModelError, match=words) as error:
        camera_chain(description, camera, board)
    assert "\n" not in str(error.value) and "robot.urdf" in str(error.value)


@pytest.mark.parametrize("parent, link", [("world", "room_camera"), ("base", "base_camera")])
def test_the_world_link_goes_where_the_fit_puts_it(description, parent, link):
    placed = pose(pin.exp3(np.array([0.1, -0.2, 0.3])), np.array([1.0, 0.5, 0.8]))
    joint, origin = world_link_origin(description, link, placed)
    assert joint == f"{link}_joint"
    element = (f'<joint name="{link}_joint" type="fixed"><parent link="{parent}"/><child link="{link}"/>'
               '<origin xyz="0 0 0" rpy="0 0 0"/>')
    text = description.text.replace(element, element.replace(
        'xyz="0 0 0" rpy="0 0 0"',
        f'xyz="{format_floats(origin[:3, 3])}" rpy="{format_floats(rpy_from_matrix(origin[:3, :3]))}"'))
    model = pin.buildModelFromXML(text)
    data = model.createData()
    pin.framesForwardKinematics(model, data, pin.neutral(model))
    assert np.abs(data.oMf[model.getFrameId(link)].homogeneous - placed).max() < 1e-12
    with pytest.raises(ModelError, match="rides on the chain"):
        world_link_origin(description, "board", placed)
