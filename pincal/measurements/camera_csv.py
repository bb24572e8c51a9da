"""A camera's measurement files: JOINTS.csv (the joint readings of each image) in, DATA.csv (the corners
each image shows) out.

JOINTS.csv has an ``image`` column naming each image file (its file name; a path's folders are ignored),
then one column per joint as in format v1 (named as the URDF's joints: radians, metres for prismatic
joints), optionally ``role`` and ``session`` as in format v1. Every column but these three is copied to
DATA.csv as it is written (numbers, checked finite), so a numeric extra such as ``temperature_c`` travels
with its image too.

DATA.csv has one row per detected corner:

* ``image``: the image's name as JOINTS.csv gives it;
* ``corner``: OpenCV's ChArUco corner id (:mod:`pincal.measurements.charuco`);
* ``u,v``: where the corner is in the image [px], OpenCV's convention (centre of the top-left pixel
  (0, 0), u right, v down);
* ``board_x,board_y``: the corner on the board [m] (z = 0, OpenCV's board frame);
* ``width,height``: the image's size [px];
* the joint columns of JOINTS.csv, as written there;
* ``role`` (``calibration`` where JOINTS.csv gives none) and ``session`` when JOINTS.csv has one.

One row per corner rather than per image because the camera's residual is per corner (its u and v
reprojected), and each image shows its own subset of the board: a row per corner needs no empty cells
and no columns that depend on the board's size, a corner can be dropped by deleting its line, and an
error of the fit can name the line of the corner. The rows of one image share its name, size, joint
readings, role and session: the image is the robot configuration, as one row is in format v1.
"""

from __future__ import annotations

import csv
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path, PurePath

from pincal.errors import MeasurementError
from pincal.measurements.charuco import CharucoSpec
from pincal.measurements.csv_v1 import read_table
from pincal.measurements.data import DEFAULT_ROLE, ROLE_COLUMN, ROLES, SESSION_COLUMN
from pincal.measurements.images import CornerDetection
from pincal.outputs import replacing

__all__ = ["IMAGE_COLUMN", "CORNER_COLUMNS", "JointReadings", "read_joint_readings", "write_corners"]

#: JOINTS.csv's and DATA.csv's column naming each image.
IMAGE_COLUMN = "image"
#: DATA.csv's columns of a corner, after ``image``.
CORNER_COLUMNS = ("corner", "u", "v", "board_x", "board_y", "width", "height")


@dataclass(frozen=True)
class JointReadings:
    """JOINTS.csv: the joint readings of each image, as its cells say them.

    Attributes:
        source: the file.
        images: each row's ``image`` cell (K,).
        lines: each row's line in the file (K,).
        columns: the columns copied to DATA.csv (joints and numeric extras), in the file's order.
        cells: each row's cells of ``columns`` (K, len(columns)), checked to be finite numbers.
        roles: each row's role (``calibration`` for an empty cell) (K,).
        sessions: each row's ``session`` cell (K,); None when the file has no such column.
    """

    source: str
    images: tuple[str, ...]
    lines: tuple[int, ...]
    columns: tuple[str, ...]
    cells: tuple[tuple[str, ...], ...]
    roles: tuple[str, ...]
    sessions: tuple[str, ...] | None

    def row_of(self, image: Path) -> int | None:
        """The row naming the file ``image`` (by file name); None if no row does."""
        names = [PurePath(name.replace("\\", "/")).name for name in self.images]
        return names.index(image.name) if image.name in names else None


def read_joint_readings(path: str | os.PathLike[str]) -> JointReadings:
    """Read JOINTS.csv (see the module's docstring).

    Raises:
        MeasurementError: naming the file, line and column: no ``image`` column, an empty or repeated
            image name, a column DATA.csv reserves, an unknown role, a cell that is not a finite number.
    """
    table = read_table(path, rows_are="image")
    if IMAGE_COLUMN not in table.names:
        raise table.error(f"no '{IMAGE_COLUMN}' column; JOINTS.csv names each image file in a column "
                          f"'{IMAGE_COLUMN}', then gives its joint readings", table.header_line)
    reserved = [n for n in table.names if n in CORNER_COLUMNS]
    if reserved:
        raise table.error(f"column(s) {', '.join(reserved)} are DATA.csv's own ({', '.join(CORNER_COLUMNS)}); "
                          "rename or delete them", table.header_line)
    images = table.cells(IMAGE_COLUMN)
    seen: dict[str, int] = {}
    for name, line in zip(images, table.lines):
        key = PurePath(name.replace("\\", "/")).name
        if not key:
            raise table.error("empty image name; name the image file of this row", line, IMAGE_COLUMN)
        if key in seen:
            raise table.error(f"image '{key}' named again (first at line {seen[key]}); give each image one row",
                              line, IMAGE_COLUMN)
        seen[key] = line
    columns = tuple(n for n in table.names if n not in (IMAGE_COLUMN, ROLE_COLUMN, SESSION_COLUMN))
    for name in columns:
        table.numbers(name)  # a joint reading or a numeric extra: a finite number in every row
    roles = []
    for k, line in enumerate(table.lines):
        role = table.cell(k, ROLE_COLUMN).lower() or DEFAULT_ROLE
        if role not in ROLES:
            raise table.error(f"unknown role {table.cell(k, ROLE_COLUMN)!r}; allowed: {', '.join(ROLES)} "
                              f"(empty means {DEFAULT_ROLE})", line, ROLE_COLUMN)
        roles.append(role)
    sessions = tuple(table.cells(SESSION_COLUMN)) if SESSION_COLUMN in table.names else None
    cells = tuple(tuple(table.cell(k, n) for n in columns) for k in range(len(table.rows)))
    return JointReadings(table.source, tuple(images), tuple(table.lines), columns, cells, tuple(roles), sessions)


def write_corners(path: str | os.PathLike[str], readings: JointReadings,
                  detections: Sequence[tuple[int, CornerDetection]], spec: CharucoSpec) -> int:
    """Write DATA.csv, whole or not at all: the corners of each ``(row of readings, detection)``.

    Returns:
        The number of corner rows written.

    Raises:
        MeasurementError: the file cannot be written.
    """
    header = [IMAGE_COLUMN, *CORNER_COLUMNS, *readings.columns, ROLE_COLUMN]
    if readings.sessions is not None:
        header.append(SESSION_COLUMN)
    written = 0
    try:
        with replacing(path, "w", newline="") as handle:
            writer = csv.writer(handle, lineterminator="\n")
            writer.writerow(header)
            for row, found in detections:
                image = [readings.images[row]]
                after = [*readings.cells[row], readings.roles[row]]
                if readings.sessions is not None:
                    after.append(readings.sessions[row])
                for corner, (u, v) in zip(found.ids, found.pixels):
                    x, y = spec.corner_position(int(corner))
                    writer.writerow([*image, int(corner), f"{u:.4f}", f"{v:.4f}", f"{x:.10g}", f"{y:.10g}",
                                     *found.size, *after])
                    written += 1
    except OSError as exc:
        raise MeasurementError(f"{path}: cannot write file ({exc.strerror or exc})") from None
    return written
