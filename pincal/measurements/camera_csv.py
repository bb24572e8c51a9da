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
:func:`read_corners` reads DATA.csv back as a :class:`CornerSet`, checking that they do.
"""

from __future__ import annotations

import csv
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path, PurePath

import numpy as np

from pincal.errors import MeasurementError
from pincal.measurements.charuco import CharucoSpec
from pincal.measurements.csv_v1 import (
    CsvTable,
    _joint_matrix,
    _read_extras,
    _read_roles,
    _read_sessions,
    read_table,
)
from pincal.measurements.data import DEFAULT_ROLE, ROLE_COLUMN, ROLES, SESSION_COLUMN, JointSpec
from pincal.measurements.images import CornerDetection
from pincal.outputs import replacing

__all__ = ["IMAGE_COLUMN", "CORNER_COLUMNS", "JointReadings", "read_joint_readings", "write_joint_readings",
           "write_corners", "CornerSet", "read_corners", "write_corner_set"]

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


def write_joint_readings(path: str | os.PathLike[str], images: Sequence[str], joint_names: Sequence[str],
                         q: np.ndarray, extra: Mapping[str, np.ndarray]) -> None:
    """Write JOINTS.csv, whole or not at all: each image's name, its joint readings ``q`` (K, N) and the
    numeric ``extra`` columns (K,) each, floats in their shortest exact form (``pincal extract --image``).

    Raises:
        MeasurementError: the file cannot be written.
    """
    try:
        with replacing(path, "w", newline="") as handle:
            writer = csv.writer(handle, lineterminator="\n")
            writer.writerow([IMAGE_COLUMN, *joint_names, *extra])
            for k, name in enumerate(images):
                writer.writerow([name, *(repr(float(v)) for v in q[k]), *(repr(float(extra[n][k])) for n in extra)])
    except OSError as exc:
        raise MeasurementError(f"{path}: cannot write file ({exc.strerror or exc})") from None


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


@dataclass(frozen=True, eq=False)
class CornerSet:
    """DATA.csv read: K images (the robot configurations) and the M corners they show.

    Attributes:
        joint_names: N joint names, the column order of ``q``.
        images: each image's name (K,).
        q: each image's joint readings (K, N) [rad; m for prismatic joints].
        roles: each image's role (K,) object array.
        sessions: each image's session (K,) object array (the file's stem where the file names none).
        sizes: each image's (width, height) (K, 2) [px].
        image_of: each corner's image, an index into ``images`` (M,).
        corners: each corner's OpenCV id (M,).
        pixels: each corner's (u, v) (M, 2) [px].
        board_points: each corner on the board (M, 3) [m], z = 0.
        lines: each corner's line in the file (M,).
        extra: numeric extra columns, one value per image (K,) each.
        source: the file.
    """

    joint_names: tuple[str, ...]
    images: tuple[str, ...]
    q: np.ndarray
    roles: np.ndarray
    sessions: np.ndarray
    sizes: np.ndarray
    image_of: np.ndarray
    corners: np.ndarray
    pixels: np.ndarray
    board_points: np.ndarray
    lines: np.ndarray
    extra: Mapping[str, np.ndarray] = field(default_factory=dict)
    source: str = "<memory>"


def _same_per_image(table: CsvTable, first: np.ndarray, values: np.ndarray, name: str) -> None:
    """Refuse a cell of column ``name`` that differs from the first row of its image (``first``: that row)."""
    differs = np.flatnonzero(values != values[first])
    if differs.size:
        k = differs[0]
        here, there = (table.cell(row, name) or "(empty)" for row in (k, first[k]))
        raise table.error(f"image '{table.cell(k, IMAGE_COLUMN)}' has {here} here but {there} "
                          f"at line {table.lines[first[k]]}; the rows of one image share its {name}",
                          table.lines[k], name)


def read_corners(path: str | os.PathLike[str], joints: Sequence[JointSpec]) -> tuple[CornerSet, list[str]]:
    """Read DATA.csv (see the module's docstring), as ``pincal detect`` writes it.

    Args:
        path: the file.
        joints: the joints each image's readings must give, in the order of the returned ``q``.

    Returns:
        The corners, grouped by image in the order the images first appear, and notes (ignored columns).

    Raises:
        MeasurementError: naming the file, line and column: a missing column, a joint reading in degrees
            or millimetres, rows of one image that disagree (joints, size, role, session), a corner given
            twice for one image, a corner outside its image.
    """
    table = read_table(path, rows_are="corner")
    missing = [n for n in (IMAGE_COLUMN, *CORNER_COLUMNS) if n not in table.names]
    if missing:
        raise table.error(f"missing column(s) {', '.join(missing)}; a camera's DATA.csv (pincal detect) has "
                          f"{IMAGE_COLUMN}, {', '.join(CORNER_COLUMNS)}, the joint columns and role", table.header_line)
    names = table.cells(IMAGE_COLUMN)
    first_row: dict[str, int] = {}
    for k, name in enumerate(names):
        first_row.setdefault(name, k)
    order = list(first_row)
    index = {name: i for i, name in enumerate(order)}
    image_of = np.array([index[n] for n in names], dtype=int)
    first = np.array([first_row[n] for n in names], dtype=int)  # each row's image's first row
    joint_names = [j.name for j in joints]
    q = _joint_matrix(table, joints)
    roles, sessions = _read_roles(table), _read_sessions(table)
    numbers = {name: table.numbers(name) for name in CORNER_COLUMNS}
    for name in ("corner", "width", "height"):
        lowest = 0 if name == "corner" else 1
        bad = np.flatnonzero((numbers[name] != np.round(numbers[name])) | (numbers[name] < lowest))
        if bad.size:
            raise table.error(f"{numbers[name][bad[0]]:g} is not a {'corner id' if name == 'corner' else 'size'}; "
                              f"give a whole number >= {lowest}", table.lines[bad[0]], name)
    for n, joint in enumerate(joint_names):
        _same_per_image(table, first, q[:, n], joint)
    for name in ("width", "height"):
        _same_per_image(table, first, numbers[name], name)
    _same_per_image(table, first, roles, ROLE_COLUMN)
    _same_per_image(table, first, sessions, SESSION_COLUMN)
    pixels = np.column_stack([numbers["u"], numbers["v"]])
    sizes = np.column_stack([numbers["width"], numbers["height"]]).astype(int)
    outside = np.flatnonzero(np.any((pixels < -0.5) | (pixels > sizes - 0.5), axis=1))
    if outside.size:
        k = outside[0]
        raise table.error(f"corner at ({pixels[k, 0]:g}, {pixels[k, 1]:g}) px is outside its {sizes[k, 0]}x"
                          f"{sizes[k, 1]} image; check the u, v, width and height columns", table.lines[k])
    corners = numbers["corner"].astype(int)
    seen: dict[tuple[int, int], int] = {}
    for k, key in enumerate(zip(image_of.tolist(), corners.tolist())):
        if key in seen:
            raise table.error(f"corner {key[1]} of image '{names[k]}' given again (first at line {seen[key]}); "
                              "keep one row per corner", table.lines[k], "corner")
        seen[key] = table.lines[k]
    reserved = {IMAGE_COLUMN, *CORNER_COLUMNS, *joint_names, ROLE_COLUMN, SESSION_COLUMN}
    extra, ignored = _read_extras(table, [n for n in table.names if n not in reserved])
    firsts = np.array(list(first_row.values()), dtype=int)
    board = np.column_stack([numbers["board_x"], numbers["board_y"], np.zeros(len(names))])
    notes = [f"{table.source}: ignored non-numeric column(s): {', '.join(ignored)}"] if ignored else []
    data = CornerSet(tuple(joint_names), tuple(order), q[firsts], roles[firsts], sessions[firsts], sizes[firsts],
                     image_of, corners, pixels, board, np.array(table.lines), {n: v[firsts] for n, v in extra.items()},
                     table.source)
    return data, notes


def write_corner_set(path: str | os.PathLike[str], corners: CornerSet) -> int:
    """Write ``corners`` as DATA.csv, whole or not at all, in :func:`write_corners`' columns, every number in its
    shortest exact form (a simulation's corners read back bit for bit: :func:`read_corners`).

    Returns:
        The number of corner rows written.

    Raises:
        MeasurementError: the file cannot be written.
    """
    header = [IMAGE_COLUMN, *CORNER_COLUMNS, *corners.joint_names, *corners.extra, ROLE_COLUMN, SESSION_COLUMN]
    try:
        with replacing(path, "w", newline="") as handle:
            writer = csv.writer(handle, lineterminator="\n")
            writer.writerow(header)
            for m, k in enumerate(corners.image_of):
                width, height = (int(v) for v in corners.sizes[k])
                writer.writerow([corners.images[k], int(corners.corners[m]),
                                 *(repr(float(v)) for v in corners.pixels[m]),
                                 *(repr(float(v)) for v in corners.board_points[m, :2]), width, height,
                                 *(repr(float(v)) for v in corners.q[k]),
                                 *(repr(float(corners.extra[n][k])) for n in corners.extra),
                                 corners.roles[k], corners.sessions[k]])
    except OSError as exc:
        raise MeasurementError(f"{path}: cannot write file ({exc.strerror or exc})") from None
    return len(corners.image_of)
