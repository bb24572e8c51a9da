"""Images of a ChArUco board: the files given, each read, and the board's corners found in it (OpenCV).

Detection is OpenCV's ``cv2.aruco.CharucoDetector`` with its default parameters: the ArUco markers
are found, the chessboard corners between them interpolated and refined to sub-pixel accuracy by
``cornerSubPix``. Pixel coordinates are OpenCV's: the centre of the top-left pixel is (0, 0), u to
the right, v down [px]. On rendered 640x480 images with Gaussian noise of sigma 2 grey levels the
corners land within 0.2 px of their true projection, 0.07 px RMS (tests/test_detect.py).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from pincal.errors import MeasurementError
from pincal.measurements.charuco import CharucoSpec
from pincal.measurements.data import refuse_given_twice

if TYPE_CHECKING:
    import cv2

__all__ = ["IMAGE_SUFFIXES", "CornerDetection", "image_files", "read_image", "opencv_board", "detect_corners"]

#: The image files a folder given to ``pincal detect`` contributes (any case).
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")


@dataclass(frozen=True)
class CornerDetection:
    """The board's corners found in one image.

    Attributes:
        ids: OpenCV's corner ids, ascending (M,).
        pixels: each corner's (u, v) [px] (M, 2).
        markers: ArUco markers of the board found in the image.
        size: the image's (width, height) [px].
    """

    ids: np.ndarray
    pixels: np.ndarray
    markers: int
    size: tuple[int, int]


def image_files(paths: Sequence[str | os.PathLike[str]]) -> list[Path]:
    """The image files of ``paths``: a file as given, a folder's PNG and JPEG files sorted by name.

    Raises:
        MeasurementError: a path that does not exist, a folder without images, an image given twice.
    """
    files: list[Path] = []
    for given in map(Path, paths):
        if given.is_dir():
            found = sorted(p for p in given.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)
            if not found:
                raise MeasurementError(f"{given}: folder without PNG or JPEG images ({', '.join(IMAGE_SUFFIXES)}); "
                                       "give the folder of the board's images")
            files += found
        elif given.is_file():
            files.append(given)
        else:
            raise MeasurementError(f"{given}: no such image file or folder; check the path")
    refuse_given_twice(files, "each image")
    return files


def read_image(path: str | os.PathLike[str]) -> np.ndarray:
    """The image at ``path`` in grey levels (H, W) uint8.

    Read as bytes and decoded by OpenCV (``imdecode``: any path the system opens, PNG and JPEG among
    the formats). Raises MeasurementError naming the file when it cannot be read or decoded."""
    import cv2

    try:
        data = np.fromfile(path, dtype=np.uint8)
    except OSError as exc:
        raise MeasurementError(f"{path}: cannot read file ({exc.strerror or exc})") from None
    image = cv2.imdecode(data, cv2.IMREAD_GRAYSCALE) if data.size else None
    if image is None:
        raise MeasurementError(f"{path}: not an image OpenCV can decode (PNG or JPEG expected); "
                               "replace the file or leave it out")
    return image


@cache
def opencv_board(spec: CharucoSpec) -> cv2.aruco.CharucoBoard:
    """OpenCV's board of ``spec`` (made once per spec)."""
    import cv2

    dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, spec.dictionary))
    return cv2.aruco.CharucoBoard((spec.cols, spec.rows), spec.square, spec.marker, dictionary)


@cache
def _detector(spec: CharucoSpec) -> cv2.aruco.CharucoDetector:
    import cv2

    return cv2.aruco.CharucoDetector(opencv_board(spec))


def detect_corners(image: np.ndarray, spec: CharucoSpec) -> CornerDetection:
    """The corners of board ``spec`` in ``image`` (grey levels, (H, W)); none found: ``ids`` empty."""
    corners, ids, _, marker_ids = _detector(spec).detectBoard(image)
    markers = 0 if marker_ids is None else len(marker_ids)
    height, width = image.shape[:2]
    if ids is None or corners is None or len(ids) == 0:
        return CornerDetection(np.empty(0, dtype=int), np.empty((0, 2)), markers, (width, height))
    ids = np.asarray(ids, dtype=int).ravel()
    order = np.argsort(ids)
    pixels = np.asarray(corners, dtype=float).reshape(-1, 2)[order]
    return CornerDetection(ids[order], pixels, markers, (width, height))
