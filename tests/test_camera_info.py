"""A camera's intrinsics files (pincal.model.camera_info): ROS camera_info and OpenCV YAML in,
camera_info out."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from pincal.errors import ModelError
from pincal.model.camera_info import check_image_size, read_intrinsics, write_camera_info
from pincal.model.pinhole import CameraIntrinsics

CAMERA = CameraIntrinsics(1100.0, 1095.0, 641.5, 478.2, (-0.21, 0.12, 1.5e-3, -8e-4, -0.03), 1280, 960)

ROS = """image_width: 1280
image_height: 960
camera_name: wrist
camera_matrix:
  rows: 3
  cols: 3
  data: [1100.0, 0.0, 641.5, 0.0, 1095.0, 478.2, 0.0, 0.0, 1.0]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [-0.21, 0.12, 0.0015, -0.0008, -0.03]
"""


def test_camera_info_round_trip(tmp_path):
    write_camera_info(tmp_path / "camera.yaml", CAMERA)
    assert read_intrinsics(tmp_path / "camera.yaml") == CAMERA
    (tmp_path / "ros.yaml").write_text(ROS)
    assert read_intrinsics(tmp_path / "ros.yaml") == CAMERA


def test_opencv_yaml(tmp_path):
    storage = cv2.FileStorage(str(tmp_path / "opencv.yaml"), cv2.FILE_STORAGE_WRITE)
    storage.write("image_width", 1280)
    storage.write("image_height", 960)
    storage.write("cameraMatrix", CAMERA.matrix)
    storage.write("distCoeffs", np.array([list(CAMERA.distortion[:4])]))  # four: k3 = 0
    storage.release()
    read = read_intrinsics(tmp_path / "opencv.yaml")
    assert read.vector()[:8] == pytest.approx(CAMERA.vector()[:8], abs=1e-12) and read.distortion[4] == 0.0


@pytest.mark.parametrize("change, words", [
    (("data: [-0.21, 0.12, 0.0015, -0.0008, -0.03]", "data: [-0.21, 0.12, 0.0015, -0.0008, -0.03, 0.1, 0, 0]"),
     "rational or thin-prism"),
    (("camera_matrix:", "matrix:"), "no camera matrix"),
    (("image_width: 1280\n", ""), "no image size"),
    (("plumb_bob", "equidistant"), "distortion model 'equidistant'"),
    (("1100.0, 0.0", "-1100.0, 0.0"), "focal lengths"),
])
def test_bad_files_are_one_line_errors(tmp_path, change, words):
    (tmp_path / "bad.yaml").write_text(ROS.replace(*change))
    with pytest.raises(ModelError, match=words) as error:
        read_intrinsics(tmp_path / "bad.yaml")
    assert "\n" not in str(error.value) and "bad.yaml" in str(error.value)


def test_images_of_another_size_are_refused():
    check_image_size(CAMERA, np.array([[1280, 960]] * 2), ("a.png", "b.png"), "DATA.csv", "camera.yaml")
    with pytest.raises(ModelError, match="'b.png' is 640x480 px but camera.yaml is for 1280x960 px; give"):
        check_image_size(CAMERA, np.array([[1280, 960], [640, 480]]), ("a.png", "b.png"), "DATA.csv", "camera.yaml")
