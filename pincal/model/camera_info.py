"""A camera's intrinsics files: ROS's camera_info YAML and OpenCV's YAML read, camera_info YAML written.

ROS (``camera_calibration_parsers``; what ``camera_calibration`` writes and ``camera_info_url`` names)::

    image_width: 1280
    image_height: 960
    camera_matrix: {rows: 3, cols: 3, data: [fx, 0, cx, 0, fy, cy, 0, 0, 1]}
    distortion_model: plumb_bob
    distortion_coefficients: {rows: 1, cols: 5, data: [k1, k2, p1, p2, k3]}

OpenCV (``cv2.FileStorage``, as its ``calibration`` sample writes it: a ``%YAML:1.0`` header, matrices tagged
``!!opencv-matrix``) with ``camera_matrix`` (or ``cameraMatrix``, ``K``), ``distortion_coefficients`` (or
``dist_coeffs``, ``distCoeffs``, ``D``) and ``image_width``/``image_height``. Both give OpenCV's pinhole model
with its five distortion coefficients (:class:`pincal.model.pinhole.CameraIntrinsics`); fewer coefficients
are padded with zeros (4: k3 = 0), more are refused (the rational and thin-prism terms are not modelled).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from pincal.errors import ModelError
from pincal.model.pinhole import CameraIntrinsics
from pincal.outputs import replacing

__all__ = ["read_intrinsics", "write_camera_info", "check_image_size"]

_MATRIX_KEYS = ("camera_matrix", "cameraMatrix", "K")
_DISTORTION_KEYS = ("distortion_coefficients", "dist_coeffs", "distCoeffs", "D")


def _opencv_fields(path: Path) -> dict[str, Any]:
    """The nodes of an OpenCV FileStorage YAML file as numbers and arrays."""
    import cv2

    try:
        storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    except cv2.error as exc:
        raise ModelError(f"{path}: OpenCV cannot read this YAML file ({' '.join(str(exc).split())[-120:]})"
                               ) from None
    try:
        root = storage.root()
        out: dict[str, Any] = {}
        for key in root.keys():
            node = storage.getNode(key)
            out[key] = node.mat() if node.isMap() or node.isSeq() else node.real() if node.isReal() or node.isInt() \
                else node.string()
        return out
    finally:
        storage.release()


def _values(path: Path, fields: dict[str, Any], keys: tuple[str, ...], what: str) -> np.ndarray:
    key = next((k for k in keys if k in fields), None)
    if key is None:
        raise ModelError(f"{path}: no {what} ({' or '.join(keys)}); give a ROS camera_info or OpenCV YAML file")
    node = fields[key]
    data = node.get("data") if isinstance(node, dict) else node
    try:
        values = np.asarray(data, dtype=float).ravel()
    except (TypeError, ValueError):
        values = np.array([np.nan])
    if values.size == 0 or not np.all(np.isfinite(values)):
        raise ModelError(f"{path}: '{key}' is not a list of numbers; write its values as 'data: [...]'")
    return values


def read_intrinsics(path: str | os.PathLike[str]) -> CameraIntrinsics:
    """Read a ROS camera_info YAML or an OpenCV YAML file (see the module's docstring).

    Raises:
        ModelError: naming the file: unreadable, no camera matrix, a matrix that is not 3x3 with positive
            focal lengths, more than five distortion coefficients or a model other than plumb_bob, no image size.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ModelError(f"{path}: cannot read the intrinsics file ({exc})") from None
    if text.lstrip().startswith("%YAML"):  # OpenCV's FileStorage dialect, which PyYAML does not read
        fields = _opencv_fields(path)
    else:
        try:
            loaded = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise ModelError(f"{path}: not YAML ({' '.join(str(exc).split())})") from None
        if not isinstance(loaded, dict):
            raise ModelError(f"{path}: not a camera_info YAML file (no keys); give image_width, image_height, "
                                   "camera_matrix and distortion_coefficients")
        fields = loaded
    model = str(fields.get("distortion_model", "plumb_bob") or "plumb_bob")
    if model not in ("plumb_bob", "rational_polynomial"):
        raise ModelError(f"{path}: distortion model '{model}'; pincal models OpenCV's plumb_bob (k1, k2, p1, "
                               "p2, k3): calibrate the camera with that model")
    matrix = _values(path, fields, _MATRIX_KEYS, "camera matrix")
    if matrix.size != 9:
        raise ModelError(f"{path}: the camera matrix has {matrix.size} values; give its 9 (3x3, row by row)")
    distortion = _values(path, fields, _DISTORTION_KEYS, "distortion coefficients")
    if distortion.size > 5 and np.any(distortion[5:] != 0.0):
        raise ModelError(f"{path}: {distortion.size} distortion coefficients with rational or thin-prism "
                               "terms; pincal models the five of plumb_bob (k1, k2, p1, p2, k3)")
    coefficients = np.zeros(5)
    coefficients[: min(5, distortion.size)] = distortion[:5]
    size = [v for v in (fields.get(k) for k in ("image_width", "image_height")) if isinstance(v, (int, float))]
    if len(size) != 2 or not all(v == int(v) and v > 0 for v in size):
        raise ModelError(f"{path}: no image size; give image_width and image_height [px]")
    width, height = (int(v) for v in size)
    k = matrix.reshape(3, 3)
    if not (k[0, 0] > 0 and k[1, 1] > 0):
        raise ModelError(f"{path}: focal lengths {k[0, 0]:g}, {k[1, 1]:g} px; they must be positive")
    k1, k2, p1, p2, k3 = (float(c) for c in coefficients)
    return CameraIntrinsics(float(k[0, 0]), float(k[1, 1]), float(k[0, 2]), float(k[1, 2]), (k1, k2, p1, p2, k3),
                            width, height)


def write_camera_info(path: str | os.PathLike[str], intrinsics: CameraIntrinsics, camera_name: str = "camera") -> None:
    """Write ``intrinsics`` as a ROS camera_info YAML file, whole or not at all (rectification the identity,
    projection ``[K | 0]``: a monocular camera).

    Raises:
        ModelError: the file cannot be written.
    """
    k = intrinsics.matrix
    projection = np.hstack([k, np.zeros((3, 1))])
    document = {
        "image_width": int(intrinsics.width), "image_height": int(intrinsics.height), "camera_name": camera_name,
        "camera_matrix": {"rows": 3, "cols": 3, "data": [float(v) for v in k.ravel()]},
        "distortion_model": "plumb_bob",
        "distortion_coefficients": {"rows": 1, "cols": 5, "data": [float(v) for v in intrinsics.distortion]},
        "rectification_matrix": {"rows": 3, "cols": 3, "data": [float(v) for v in np.eye(3).ravel()]},
        "projection_matrix": {"rows": 3, "cols": 4, "data": [float(v) for v in projection.ravel()]},
    }
    try:
        with replacing(path, "w") as handle:
            yaml.safe_dump(document, handle, default_flow_style=None, sort_keys=False)
    except OSError as exc:
        raise ModelError(f"{path}: cannot write file ({exc.strerror or exc})") from None


def check_image_size(intrinsics: CameraIntrinsics, sizes: np.ndarray, images: tuple[str, ...], source: str,
                     intrinsics_source: str) -> None:
    """Refuse images (their (width, height) (K, 2) [px]) of another size than the intrinsics were estimated for.

    Raises:
        ModelError: naming the first such image and both sizes.
    """
    expected = np.array([intrinsics.width, intrinsics.height])
    wrong = np.flatnonzero(np.any(np.asarray(sizes) != expected, axis=1))
    if wrong.size:
        k = wrong[0]
        raise ModelError(f"{source}: image '{images[k]}' is {sizes[k][0]}x{sizes[k][1]} px but "
                               f"{intrinsics_source} is for {expected[0]}x{expected[1]} px; give the intrinsics "
                               "of this camera at this resolution, or estimate them with the rest")
