"""``pincal detect``'s job: the ChArUco board's corners found in each image and written with the image's
joint readings as DATA.csv (:mod:`pincal.measurements.camera_csv`), whole or not at all.

Every image must have its row of JOINTS.csv and every row its image: a mismatch is an error, not a
skipped image (a reading without its image, or the reverse, is a slip of the recording). An image in
which the board is not found is listed in the notes and skipped; a board found in no image at all is an
error, the spec being the likelier slip.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from pincal.errors import MeasurementError, expect_value
from pincal.measurements.camera_csv import IMAGE_COLUMN, JointReadings, read_joint_readings, write_corners
from pincal.measurements.charuco import CharucoSpec
from pincal.measurements.images import CornerDetection, detect_corners, image_files, read_image
from pincal.progress import Counter, Progress
from pincal.workflows.paths import refuse_overwrite

__all__ = ["DetectSettings", "ImageCorners", "DetectRun", "detect_files"]


@dataclass(frozen=True)
class DetectSettings:
    """What ``pincal detect`` is asked to do.

    Attributes:
        images: image files and folders (a folder's PNG and JPEG files, by name).
        board: the board (``--board``'s text: :func:`~pincal.measurements.charuco.parse_board`).
        joints: JOINTS.csv, the joint readings of each image.
        out: DATA.csv to write.
    """

    images: tuple[Path, ...]
    board: CharucoSpec
    joints: Path
    out: Path

    def __post_init__(self) -> None:
        object.__setattr__(self, "images", tuple(map(Path, self.images)))  # a list or str paths: kept as given
        object.__setattr__(self, "joints", Path(self.joints))
        object.__setattr__(self, "out", Path(self.out))
        if not self.images:
            raise MeasurementError("no image given; give the board's image files or their folder")
        expect_value(self.board, CharucoSpec, "DetectSettings")


@dataclass(frozen=True)
class ImageCorners:
    """One image and what was found in it.

    Attributes:
        path: the image file.
        row: its row in :attr:`DetectRun.readings`.
        detection: the board's corners found (``ids`` empty: the board was not found).
    """

    path: Path
    row: int
    detection: CornerDetection

    @property
    def found(self) -> bool:
        """Whether the board's corners were found."""
        return len(self.detection.ids) > 0


@dataclass(frozen=True)
class DetectRun:
    """What :func:`detect_files` did.

    Attributes:
        out: DATA.csv, written.
        readings: JOINTS.csv as read.
        images: every image, in the order read.
        rows: corner rows written.
        notes: one line per image skipped (the board not found in it).
    """

    out: Path
    readings: JointReadings
    images: tuple[ImageCorners, ...]
    rows: int
    notes: tuple[str, ...] = field(default=())

    @property
    def skipped(self) -> tuple[ImageCorners, ...]:
        """The images in which the board was not found."""
        return tuple(image for image in self.images if not image.found)


def _matched_rows(files: Sequence[Path], readings: JointReadings) -> list[int]:
    """Each image's row of JOINTS.csv; every image has one and every row has its image."""
    names: dict[str, Path] = {}
    for path in files:
        if path.name in names:
            raise MeasurementError(f"{path}: two images are named {path.name} (also {names[path.name]}); "
                                   f"{readings.source} names images by file name: rename one")
        names[path.name] = path
    rows = []
    for path in files:
        row = readings.row_of(path)
        if row is None:
            raise MeasurementError(f"{path}: no row of {readings.source} names this image (column "
                                   f"'{IMAGE_COLUMN}'); add its joint readings or leave the image out")
        rows.append(row)
    for row, (name, line) in enumerate(zip(readings.images, readings.lines)):
        if row not in rows:
            raise MeasurementError(f"{readings.source}: line {line}, column '{IMAGE_COLUMN}': '{name}' is none of "
                                   f"the {len(files)} image(s) given; add the image or delete the row")
    return rows


def detect_files(settings: DetectSettings, progress: Progress | None = None) -> DetectRun:
    """Find the board in each image and write DATA.csv (the corners with the joint readings).

    Args:
        settings: the images, the board, JOINTS.csv and DATA.csv.
        progress: called with (images done, images) as each is read.

    Returns:
        What was found, written and skipped.

    Raises:
        MeasurementError: one line naming the file: a missing or unreadable image or folder, an image
            without its row of JOINTS.csv or a row without its image, a bad JOINTS.csv, a board found in
            no image (nothing written).
    """
    expect_value(settings, DetectSettings, "detect_files")
    files = image_files(settings.images)
    readings = read_joint_readings(settings.joints)
    refuse_overwrite(settings.out, settings.joints, *files)
    rows = _matched_rows(files, readings)
    counter = Counter(progress)
    counter.expect(len(files))
    images = []
    for path, row in zip(files, rows):
        images.append(ImageCorners(path, row, detect_corners(read_image(path), settings.board)))
        counter.tick()
    found = [image for image in images if image.found]
    spec = settings.board
    if not found:
        raise MeasurementError(
            f"--board {spec.text}: the board is found in none of the {len(images)} image(s) (markers found: "
            f"{max(image.detection.markers for image in images)} at most); check COLSxROWS (squares across, then "
            f"down: {spec.cols}x{spec.rows} is not {spec.rows}x{spec.cols}) and the dictionary; nothing written")
    notes = tuple(f"{image.path}: board not found ({image.detection.markers} of its {spec.n_markers} markers, "
                  "no corner); skipped" for image in images if not image.found)
    written = write_corners(settings.out, readings, [(image.row, image.detection) for image in found], spec)
    return DetectRun(settings.out, readings, tuple(images), written, notes)
