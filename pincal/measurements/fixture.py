"""Socket-fixture measurements: a ball on the robot seated in sockets of a fixture, joints only.

No sensor sees the robot. A fixture with sockets at known positions (or known
mutual distances) stands in front of it; the robot is moved by hand until a
ball fixed to its last link sits in one socket, and the joint readings are
recorded, many times per socket. The fixture is then moved to another
*placement* and the recording repeated. Two files describe such data:

* the **fixture file** (:func:`read_fixture`), one row per socket, either
  ``point,x,y,z`` — the socket centres in a frame of the fixture [m] — or
  ``point_a,point_b,distance`` — the distances between socket centres [m],
  every pair once (coordinates are then found by classical multidimensional
  scaling; the fixture frame is arbitrary, as its pose is unknown anyway);
* the **data files** (:func:`read_fixture_data`), CSV v1's joint columns
  (:func:`pincal.measurements.csv_v1.read_joint_columns`), a ``point`` column
  naming the socket the ball sits in, and a ``placement`` column (or
  ``session``, its synonym) naming the fixture placement. Without either
  column, each file is one placement, named by its file name. Other columns
  are ignored.

Every placement must use at least two sockets (one socket fixes no distance
and no direction) and each socket of a placement needs
:data:`MIN_ROWS_PER_SOCKET` rows. Errors are one line naming the file, line and
column (:class:`~pincal.errors.MeasurementError`).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pincal.errors import MeasurementError
from pincal.measurements.csv_v1 import CsvTable, read_joint_columns, read_table
from pincal.measurements.data import (  # session: read as a synonym of placement
    SESSION_COLUMN,
    JointSpec,
)

__all__ = [
    "POINT_COLUMN", "PLACEMENT_COLUMN", "COORDINATE_COLUMNS", "DISTANCE_COLUMNS", "MIN_ROWS_PER_SOCKET",
    "MAX_FIXTURE_SIZE", "MIN_SOCKET_DISTANCE", "DISTANCE_TOLERANCE", "Fixture", "FixtureData", "read_fixture",
    "read_fixture_data", "check_placements",
]

POINT_COLUMN = "point"
PLACEMENT_COLUMN = "placement"
COORDINATE_COLUMNS = ("x", "y", "z")
DISTANCE_COLUMNS = ("point_a", "point_b", "distance")
#: Rows per socket and placement: two rows in a socket are matched exactly by a
#: ball centre and a socket centre (6 equations, 6 unknowns); the third is the
#: first that can disagree, so the first that says anything about the robot.
MIN_ROWS_PER_SOCKET = 3
#: Largest plausible fixture coordinate or distance [m]; above it, millimetres.
MAX_FIXTURE_SIZE = 5.0
#: Sockets closer than this are the same socket [m].
MIN_SOCKET_DISTANCE = 1e-4
#: Distances a fixture frame cannot reproduce by more than this are inconsistent [m].
DISTANCE_TOLERANCE = 1e-6


@dataclass(frozen=True)
class Fixture:
    """Socket centres of a fixture in its own frame.

    Attributes:
        names: socket names, as the data's ``point`` column gives them.
        points: (M, 3) socket centres [m] in the fixture frame.
        source: the fixture file.
    """

    names: tuple[str, ...]
    points: np.ndarray
    source: str = "<memory>"

    def __post_init__(self) -> None:
        points = np.array(self.points, dtype=float)
        points.flags.writeable = False
        object.__setattr__(self, "points", points)
        object.__setattr__(self, "names", tuple(str(n) for n in self.names))
        if points.shape != (len(self.names), 3):
            raise MeasurementError(f"{self.source}: {len(self.names)} names but points of shape {points.shape}")

    def distance(self, a: int, b: int) -> float:
        """Distance between sockets ``a`` and ``b`` [m]."""
        return float(np.linalg.norm(self.points[a] - self.points[b]))


@dataclass(frozen=True, eq=False)
class FixtureData:
    """K joint readings with the ball in a socket, in one of S placements.

    Attributes:
        joint_names: N joint names, the column order of ``q``.
        q: (K, N) joint readings [rad or m].
        socket: (K,) index into ``fixture.names`` of the socket of each row.
        placement: (K,) index into ``placements`` of each row.
        placements: S placement names, in order of first appearance.
        fixture: the fixture.
        lines: (K,) line of each row in its file (header is line 1).
        files: (K,) index into ``sources`` of each row's file.
        sources: the data files.
    """

    joint_names: tuple[str, ...]
    q: np.ndarray
    socket: np.ndarray
    placement: np.ndarray
    placements: tuple[str, ...]
    fixture: Fixture
    lines: np.ndarray
    files: np.ndarray
    sources: tuple[str, ...]

    @property
    def n_rows(self) -> int:
        return int(self.q.shape[0])

    @property
    def socket_points(self) -> np.ndarray:
        """f_i of each row: its socket's centre in the fixture frame [m], (K, 3)."""
        return self.fixture.points[self.socket]

    def where(self, k: int) -> str:
        """``file: line n`` of row ``k``, for messages."""
        return f"{self.sources[self.files[k]]}: line {self.lines[k]}"

    def select_placements(self, names: Sequence[str]) -> FixtureData:
        """The rows of the placements ``names`` (in that order of placements)."""
        unknown = [n for n in names if n not in self.placements]
        if unknown:
            raise MeasurementError(f"{', '.join(self.sources)}: no placement(s) {', '.join(unknown)}; "
                                   f"the data have {', '.join(self.placements)}")
        old = [self.placements.index(n) for n in names]
        keep = np.isin(self.placement, old)
        remap = {o: i for i, o in enumerate(old)}
        return FixtureData(self.joint_names, self.q[keep], self.socket[keep],
                           np.array([remap[int(p)] for p in self.placement[keep]], dtype=int),
                           tuple(names), self.fixture, self.lines[keep], self.files[keep], self.sources)


# --- the fixture file ------------------------------------------------------------------


def read_fixture(path: str | os.PathLike[str]) -> Fixture:
    """Read a fixture file: ``point,x,y,z`` rows or ``point_a,point_b,distance`` rows [m].

    Raises:
        MeasurementError: missing columns, a duplicate or unnamed socket, a cell
            that is not a number, millimetres, fewer than two sockets, two sockets
            at one place, or distances no arrangement of points reproduces.
    """
    table = read_table(path, rows_are="socket")
    if POINT_COLUMN in table.names:
        return _coordinates(table)
    if all(c in table.names for c in DISTANCE_COLUMNS):
        return _from_distances(table)
    raise table.error(f"expected columns {POINT_COLUMN},{','.join(COORDINATE_COLUMNS)} (socket centres "
                      f"[m]) or {','.join(DISTANCE_COLUMNS)} (distances between sockets [m])")


def _coordinates(table: CsvTable) -> Fixture:
    missing = [c for c in COORDINATE_COLUMNS if c not in table.names]
    if missing:
        raise table.error(f"missing column(s) {', '.join(missing)}; give each socket's centre as "
                          f"{POINT_COLUMN},{','.join(COORDINATE_COLUMNS)} in metres")
    names = _names(table, table.cells(POINT_COLUMN), POINT_COLUMN)
    if len(set(names)) != len(names):
        k = next(k for k, n in enumerate(names) if names.index(n) != k)
        raise table.error(f"socket '{names[k]}' is listed twice; list each socket once", table.lines[k],
                          POINT_COLUMN)
    points = table.matrix(COORDINATE_COLUMNS)
    for i, name in enumerate(COORDINATE_COLUMNS):
        table.check_magnitude(name, points[:, i], MAX_FIXTURE_SIZE, "millimetres", "metres")
    return _checked(table, names, points)


def _from_distances(table: CsvTable) -> Fixture:
    a = _names(table, table.cells(DISTANCE_COLUMNS[0]), DISTANCE_COLUMNS[0])
    b = _names(table, table.cells(DISTANCE_COLUMNS[1]), DISTANCE_COLUMNS[1])
    distance = table.numbers(DISTANCE_COLUMNS[2])
    table.check_magnitude(DISTANCE_COLUMNS[2], distance, MAX_FIXTURE_SIZE, "millimetres", "metres")
    names = list(dict.fromkeys(a + b))
    matrix = np.full((len(names), len(names)), np.nan)
    np.fill_diagonal(matrix, 0.0)
    for k, (p, r, d) in enumerate(zip(a, b, distance)):
        i, j = names.index(p), names.index(r)
        if i == j or d <= 0 or not np.isnan(matrix[i, j]):
            problem = ("a socket's distance to itself" if i == j else "a distance <= 0" if d <= 0
                       else f"the pair {p}, {r} a second time")
            raise table.error(f"{problem}; give each pair of different sockets once, with a positive "
                              "distance", table.lines[k])
        matrix[i, j] = matrix[j, i] = d
    if np.isnan(matrix).any():
        i, j = np.argwhere(np.isnan(matrix))[0]
        raise table.error(f"no distance between '{names[i]}' and '{names[j]}'; give every pair once "
                          "(or the socket centres as point,x,y,z)")
    # classical multidimensional scaling (Torgerson 1952): B = -J D² J / 2 = X Xᵀ
    centring = np.eye(len(names)) - 1.0 / len(names)
    gram = -0.5 * centring @ matrix**2 @ centring
    values, vectors = np.linalg.eigh(gram)
    top = np.argsort(values)[::-1][:3]
    points = vectors[:, top] * np.sqrt(np.clip(values[top], 0.0, None))
    points = np.hstack([points, np.zeros((len(names), 3 - points.shape[1]))])
    rebuilt = np.linalg.norm(points[:, None] - points[None], axis=2)
    worst = np.abs(rebuilt - matrix).max()
    if worst > DISTANCE_TOLERANCE:
        raise table.error(f"no arrangement of the sockets in space has these distances (off by "
                          f"{worst * 1000:.3g} mm; check the triangle inequality); fix the distances")
    return _checked(table, names, points)


def _names(table: CsvTable, cells: list[str], column: str) -> list[str]:
    for k, cell in enumerate(cells):
        if not cell:
            raise table.error("empty socket name; name every socket", table.lines[k], column)
    return cells


def _checked(table: CsvTable, names: list[str], points: np.ndarray) -> Fixture:
    if len(names) < 2:
        raise table.error("one socket only; a fixture needs at least two (their distance sets the scale)")
    gaps = np.linalg.norm(points[:, None] - points[None], axis=2) + np.eye(len(names))
    i, j = np.unravel_index(np.argmin(gaps), gaps.shape)
    if gaps[i, j] < MIN_SOCKET_DISTANCE:
        raise table.error(f"sockets '{names[i]}' and '{names[j]}' are {gaps[i, j] * 1000:.3g} mm apart; "
                          "give sockets at different places")
    return Fixture(tuple(names), points, table.source)


# --- the data files ----------------------------------------------------------------------


def read_fixture_data(
    paths: str | os.PathLike[str] | Sequence[str | os.PathLike[str]], joints: Sequence[JointSpec], fixture: Fixture
) -> FixtureData:
    """Read socket-fixture data files (see the module docstring).

    Args:
        paths: one data file or several (their rows are concatenated).
        joints: the joints every row must give, in the order of ``q``.
        fixture: the fixture the ``point`` column refers to.

    Raises:
        MeasurementError: a CSV v1 joint-column problem, a missing ``point``
            column, an unknown socket, an empty placement, both a ``placement``
            and a ``session`` column, a placement using one socket only or a
            socket of a placement with fewer than :data:`MIN_ROWS_PER_SOCKET` rows.
    """
    paths = [paths] if isinstance(paths, (str, os.PathLike)) else list(paths)
    q_parts, sockets, placements, lines, files = [], [], [], [], []
    names: list[str] = []
    for f, path in enumerate(paths):
        q, line = read_joint_columns(path, joints)
        table = read_table(path)
        column = _placement_column(table)
        if POINT_COLUMN not in table.names:
            raise table.error(f"no '{POINT_COLUMN}' column; name the socket of each row "
                              f"({', '.join(fixture.names)}, from {fixture.source})")
        for k, cell in enumerate(table.cells(POINT_COLUMN)):
            if cell not in fixture.names:
                raise table.error(f"unknown socket {cell!r}; {fixture.source} has {', '.join(fixture.names)}",
                                  table.lines[k], POINT_COLUMN)
            sockets.append(fixture.names.index(cell))
        for k in range(len(table.rows)):
            name = table.cell(k, column) if column else Path(path).stem
            if not name:
                raise table.error("empty placement; name the fixture placement of every row",
                                  table.lines[k], column)
            if name not in names:
                names.append(name)
            placements.append(names.index(name))
        q_parts.append(q)
        lines.append(line)
        files.append(np.full(len(q), f))
    data = FixtureData(tuple(j.name for j in joints), np.vstack(q_parts), np.array(sockets, dtype=int),
                       np.array(placements, dtype=int), tuple(names), fixture, np.concatenate(lines),
                       np.concatenate(files), tuple(str(p) for p in paths))
    check_placements(data)
    return data


def _placement_column(table: CsvTable) -> str | None:
    present = [c for c in (PLACEMENT_COLUMN, SESSION_COLUMN) if c in table.names]
    if len(present) == 2:
        raise table.error(f"both '{PLACEMENT_COLUMN}' and '{SESSION_COLUMN}' columns; keep one "
                          "(they mean the same: the fixture placement)")
    return present[0] if present else None


def check_placements(data: FixtureData) -> None:
    """Every placement uses two sockets or more, each with :data:`MIN_ROWS_PER_SOCKET` rows.

    Raises:
        MeasurementError: naming the files, the placement and the socket.
    """
    for s, name in enumerate(data.placements):
        rows = np.flatnonzero(data.placement == s)
        used, counts = np.unique(data.socket[rows], return_counts=True)
        where = ", ".join(sorted({data.sources[f] for f in data.files[rows]}))
        if len(used) < 2:
            raise MeasurementError(
                f"{where}: placement '{name}' has the ball in socket '{data.fixture.names[used[0]]}' only; "
                "a placement needs two sockets or more (one fixes no distance); record the other socket "
                "too, or name the placement of each row in a 'placement' column")
        few = np.flatnonzero(counts < MIN_ROWS_PER_SOCKET)
        if few.size:
            socket = data.fixture.names[used[few[0]]]
            raise MeasurementError(
                f"{where}: placement '{name}' has {counts[few[0]]} row(s) in socket '{socket}'; "
                f"record at least {MIN_ROWS_PER_SOCKET} joint configurations per socket and placement")
