"""Measurement files (CSV format v1): read, validate and write.

Format v1 has one row per robot configuration and these columns:

* one column per joint, named exactly as the URDF joint: radians for revolute and
  continuous joints, metres for prismatic joints;
* the target position in the sensor frame, ``x,y,z`` [m], or several points of
  one rigid target, ``x1,y1,z1,x2,y2,z2,...`` [m] (numbered 1..P, full triplets);
* optionally the target orientation in the sensor frame, ``qx,qy,qz,qw`` (unit
  quaternion, scalar last as in :class:`scipy.spatial.transform.Rotation`);
* optionally ``role``: ``cpa``, ``calibration`` (default, also for an empty cell)
  or ``validation``;
* optionally ``session``: a name (text) per row; rows of one session share one
  registration (the sensor did not move between them). Empty or absent: the
  file's name without extension. :func:`read_sessions` reads several files,
  each its own session (``STEM`` or ``STEM:VALUE``);
* any other column is an extra: kept when numeric, ignored otherwise.

Every problem raises :class:`~pincal.errors.MeasurementError` with a one-line
message naming the file and, where relevant, the line (the header is line 1) and
the column. Soft problems (joint limits, ignored columns) are returned as notes:
this module never prints.

:func:`read_table` is the one CSV table reader of pincal (:class:`CsvTable`:
cells, line numbers, one-line errors of the caller's kind): measurement files,
candidate configurations (:func:`read_joint_columns`) and DH tables
(:mod:`pincal.model.dh.files`) all go through it. Rows whose cells are all blank
are skipped.
"""

from __future__ import annotations

import csv
import difflib
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Literal, cast

import numpy as np
from scipy.spatial.transform import Rotation

from pincal.errors import MeasurementError, PincalError
from pincal.measurements.couplings import ReadingCoupling, corrected_angles, reading_couplings
from pincal.measurements.data import (
    DEFAULT_ROLE,
    JOINT_SANITY,
    POSITION_COLUMN_RE,
    QUAT_COLUMNS,
    ROLE_COLUMN,
    ROLES,
    SESSION_COLUMN,
    JointSpec,
    MeasurementSet,
    default_session_name,
    is_reserved,
    join_sets,
    refuse_given_twice,
)
from pincal.measurements.mimics import follower_angles
from pincal.measurements.target_orientations import read_target_rotations, target_quat_cells, target_quat_columns
from pincal.outputs import replacing

__all__ = [
    "JointKind", "QUAT_NORM_TOL", "MAX_POSITION", "CsvTable", "read_table", "read_joint_columns", "read_measurements",
    "read_sessions", "read_extra_columns", "file_columns", "write_measurements",
]

JointKind = Literal["revolute", "continuous", "prismatic"]


QUAT_NORM_TOL = 1e-3
#: Largest plausible |target coordinate| [m]; above it the file is likely in mm.
MAX_POSITION = 20.0


@dataclass(frozen=True)
class CsvTable:
    """The cells of a CSV table file: stripped header names, data rows and their line numbers.

    Shared by every table pincal reads (measurements, candidate configurations,
    DH tables); its errors are one line naming the file, the line, the joint and
    the column, of the kind the caller chose (:func:`read_table`).
    """

    source: str
    names: tuple[str, ...]
    rows: list[list[str]]
    lines: list[int]
    header_line: int = 1
    error_type: type[PincalError] = MeasurementError

    def error(
        self, message: str, line: int | None = None, column: str | None = None, joint: str | None = None
    ) -> PincalError:
        """Build a one-line error naming the file and, if given, the line (and its joint) and column."""
        where = self.source
        if line is not None:
            where += f": line {line}" + (f" (joint '{joint}')" if joint else "")
        if column is not None:
            where += f", column '{column}'" if line is not None else f": column '{column}'"
        text = f"{where}: {message}"  # cells quoted in the message may hold line breaks: keep it one line
        return self.error_type(text.replace("\r", "\\r").replace("\n", "\\n"))

    def cell(self, k: int, name: str) -> str:
        """Stripped cell of data row ``k`` in column ``name``; empty if the table has no such column."""
        return self.rows[k][self.names.index(name)].strip() if name in self.names else ""

    def cells(self, name: str) -> list[str]:
        """Stripped cells of column ``name``, one per data row."""
        j = self.names.index(name)
        return [row[j].strip() for row in self.rows]

    def number(self, k: int, name: str, joint: str | None = None) -> float | None:
        """Cell (k, ``name``) as a finite float; None if it is empty or the column absent."""
        text = self.cell(k, name)
        if not text:
            return None
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not math.isfinite(value):
            raise self.error(f"{text!r} is not a finite number; give a number", self.lines[k], name, joint)
        return value

    def numbers(self, name: str, blank: float | None = None) -> np.ndarray:
        """Column ``name`` as finite floats; an empty cell is ``blank`` if given, else an error, as any other text."""
        out = np.empty(len(self.rows))
        for k in range(len(self.rows)):
            value = self.number(k, name)
            if value is None and blank is None:
                raise self.error("empty cell; expected a finite number", self.lines[k], name)
            out[k] = blank if value is None else value
        return out

    def matrix(self, names: Sequence[str], blank: float | None = None) -> np.ndarray:
        """Columns ``names`` as a (K, len(names)) float array (``blank``: as :meth:`numbers`)."""
        out = np.empty((len(self.rows), len(names)))
        for i, name in enumerate(names):
            out[:, i] = self.numbers(name, blank)
        return out

    def check_magnitude(self, name: str, values: np.ndarray, limit: float, found: str, expected: str) -> None:
        """Reject column ``name`` if a value exceeds ``limit`` in magnitude (a unit mistake)."""
        bad = np.flatnonzero(np.abs(values) > limit)
        if bad.size:
            raise self.error(
                f"value {values[bad[0]]:g} looks like {found}; pincal expects {expected} "
                f"(|value| > {limit:g} {expected}); convert the column", self.lines[bad[0]], name)


def read_table(
    path: str | os.PathLike[str],
    *,
    rows_are: str = "robot configuration",
    error_type: type[PincalError] = MeasurementError,
    lowercase: bool = False,
) -> CsvTable:
    """Read a CSV table's cells; reject unreadable, empty, header-only or ragged files.

    Rows whose cells are all blank are skipped; header names are stripped (and
    lower-cased with ``lowercase``) and must be present and distinct. Accepted as
    real files have them: a UTF-8 BOM, Windows (CRLF) line endings, quoted header
    names and cells, spaces around cells, and trailing commas (empty cells after
    the last named column, on the header or on data rows).

    Args:
        path: the CSV file.
        rows_are: what one data row describes, for the messages ("joint").
        error_type: the :class:`~pincal.errors.PincalError` kind raised.
        lowercase: compare header names case-insensitively.

    Raises:
        error_type: naming the file and, where relevant, the line and column.
    """
    source = str(path)
    records: list[tuple[int, list[str]]] = []
    reader = None
    try:
        with open(path, newline="", encoding="utf-8-sig") as handle:
            reader = csv.reader(handle, skipinitialspace=True)  # ' "x"' is x, as in '"x"'
            records = [(reader.line_num, row) for row in reader if any(c.strip() for c in row)]
    except FileNotFoundError:
        raise error_type(f"{source}: file not found; check the path") from None
    except IsADirectoryError:
        raise error_type(f"{source}: is a directory; give a CSV file") from None
    except OSError as exc:
        raise error_type(f"{source}: cannot read file ({exc.strerror or exc})") from None
    except UnicodeDecodeError:
        raise error_type(f"{source}: not a UTF-8 text file{_encoding_hint(path)}; save it as CSV (UTF-8)") from None
    except csv.Error as exc:
        line = getattr(reader, "line_num", 0)
        raise error_type(f"{source}: line {line}: malformed CSV ({exc}); fix or delete the line") from None
    if not records:
        raise error_type(f"{source}: file is empty; expected a header line and one row per {rows_are}")
    (header_line, header), data = records[0], records[1:]
    while len(header) > 1 and not header[-1].strip():  # trailing commas on the header line
        header = header[:-1]
    data = [(line, row[: len(header)] if not any(c.strip() for c in row[len(header):]) else row)
            for line, row in data]  # trailing commas on data rows
    names = tuple(h.strip().lower() if lowercase else h.strip() for h in header)
    table = CsvTable(source, names, [r for _, r in data], [n for n, _ in data], header_line, error_type)
    for i, name in enumerate(table.names, start=1):
        if not name:
            raise table.error(f"header column {i} has no name; name it or delete the column", header_line)
    duplicates = sorted({n for n in table.names if table.names.count(n) > 1})
    if duplicates:
        raise table.error(f"duplicate column(s) {', '.join(duplicates)}; keep one of each", header_line)
    if not data:
        raise table.error(f"header only, no data rows; add one row per {rows_are}")
    for line, row in data:
        if len(row) != len(header):
            raise table.error(
                f"{len(row)} fields but the header has {len(header)}; give one value per column", line)
    return table


def _encoding_hint(path: str | os.PathLike[str]) -> str:
    """`` (it is UTF-16)`` when the file starts with a UTF-16 or UTF-32 byte order mark, else empty."""
    try:
        with open(path, "rb") as handle:
            head = handle.read(4)
    except OSError:
        return ""
    if head.startswith((b"\xff\xfe\x00\x00", b"\x00\x00\xfe\xff")):
        return " (it is UTF-32)"
    return " (it is UTF-16, e.g. Excel's 'Unicode text')" if head.startswith((b"\xff\xfe", b"\xfe\xff")) else ""


def _joint_matrix(table: CsvTable, joints: Sequence[JointSpec], other_branches: Sequence[str] = (),
                  couplings: Sequence[ReadingCoupling] = ()) -> np.ndarray:
    """The joint columns as (K, N) [rad or m], in ``joints``' order, checked for a unit mistake; a joint
    that follows another, from its driver (eq M1, :mod:`pincal.measurements.mimics`).

    ``other_branches``: joints of the same robot description on other branches than ``joints``' chain;
    a file with columns for them is of another chain, not misspelt (the error says so)."""
    joint_names = [j.name for j in joints]
    followed = follower_angles(table, joints, couplings)
    missing = [n for n in joint_names if n not in table.names and n not in followed]
    if missing:
        hint = "; is the file comma-separated?" if len(table.names) == 1 else ""
        branch = [n for n in table.names if n in other_branches]
        extra = [n for n in table.names if n not in joint_names and n not in branch]  # a misspelt joint is here
        close = [f"'{c[0]}' to '{m}'" for m in missing if (c := difflib.get_close_matches(m, extra, n=1))]
        guess = f" (rename the file's column {', '.join(close)}?)" if close else ""
        if branch and 2 * len(missing) > len(joint_names):  # most of the chain absent: another chain's file
            guess = (f"; the file's column(s) {', '.join(branch)} are joints of the URDF on another branch than "
                     "the chain to the tip link: is --tip-link right?")
        raise table.error(f"missing joint column(s) {', '.join(missing)}{guess}; the URDF expects "
                          f"{', '.join(joint_names)}{hint}")
    q = np.column_stack([followed[n] if n in followed else table.numbers(n) for n in joint_names])
    for n, joint in enumerate(joints):
        table.check_magnitude(joint.name, q[:, n], *JOINT_SANITY[joint.kind])
    return q


def read_joint_columns(path: str | os.PathLike[str], joints: Sequence[JointSpec], other_branches: Sequence[str] = ()
                       ) -> tuple[np.ndarray, np.ndarray]:
    """The joint readings of a CSV table: the joint columns of format v1, every other column ignored.

    So a measurement file serves as a list of configurations as is. ``other_branches``: as for
    :func:`read_measurements`.

    Returns:
        q (K, N) [rad or m] in ``joints``' order, and each row's line in the file (K,).

    Raises:
        MeasurementError: unreadable or ragged file, missing joint column, a cell
            that is not a finite number, a value in degrees or millimetres —
            naming the file, line and column.
    """
    table = read_table(path)
    return _joint_matrix(table, joints, other_branches), np.array(table.lines)


def _point_columns(table: CsvTable, joint_names: Sequence[str]) -> list[tuple[str, str, str]]:
    """Names of the x,y,z columns of each target point, point 1 first."""
    axes: dict[int | None, set[str]] = {}
    for name in table.names:
        match = POSITION_COLUMN_RE.fullmatch(name)
        if match and name not in joint_names:
            index = None if match[2] is None else int(match[2])
            axes.setdefault(index, set()).add(match[1])
    if not axes:
        fixture_hint = (
            "; it has a 'point' column: socket-fixture data is read with --fixture FIXTURE.csv"
            if "point" in table.names else ""
        )
        raise table.error("no target position columns; expected x,y,z (one point) "
                          "or x1,y1,z1,x2,y2,z2,... (several points), in metres" + fixture_hint)
    if None in axes and len(axes) > 1:
        raise table.error("both x,y,z and numbered x1,y1,z1,... columns; keep one form (ambiguous)")
    for index, present in axes.items():
        suffix = "" if index is None else str(index)
        missing = [f"{a}{suffix}" for a in "xyz" if a not in present]
        if missing:
            raise table.error(f"incomplete point columns: missing {','.join(missing)}; "
                              f"each point needs x{suffix},y{suffix},z{suffix}")
    if None in axes:
        return [("x", "y", "z")]
    numbered = cast("dict[int, set[str]]", axes)  # no None key: returned above
    if sorted(numbered) != list(range(1, len(axes) + 1)):
        raise table.error(f"point columns numbered {sorted(numbered)}; number them 1..P without gaps")
    return [(f"x{i}", f"y{i}", f"z{i}") for i in range(1, len(axes) + 1)]


def _read_rotations(table: CsvTable) -> np.ndarray | None:
    """Target orientations from qx,qy,qz,qw, normalised, as (K, 3, 3); None if absent."""
    present = [c for c in QUAT_COLUMNS if c in table.names]
    if not present:
        return None
    if len(present) < len(QUAT_COLUMNS):
        missing = [c for c in QUAT_COLUMNS if c not in present]
        raise table.error(f"partial orientation columns: missing {','.join(missing)}; "
                          "give all of qx,qy,qz,qw or none")
    quats = table.matrix(QUAT_COLUMNS)
    norms = np.linalg.norm(quats, axis=1)
    bad = np.flatnonzero(np.abs(norms - 1.0) > QUAT_NORM_TOL)
    if bad.size:
        raise table.error(f"quaternion qx,qy,qz,qw has norm {norms[bad[0]]:.6g}; "
                          f"expected a unit quaternion (within {QUAT_NORM_TOL:g})", table.lines[bad[0]])
    return Rotation.from_quat(quats / norms[:, None]).as_matrix()


def _read_roles(table: CsvTable) -> np.ndarray:
    """The role of each row; ``calibration`` when the column or the cell is empty."""
    if ROLE_COLUMN not in table.names:
        return np.full(len(table.rows), DEFAULT_ROLE, dtype=object)
    roles = np.empty(len(table.rows), dtype=object)
    for k, (text, line) in enumerate(zip(table.cells(ROLE_COLUMN), table.lines)):
        roles[k] = text.lower() or DEFAULT_ROLE
        if roles[k] not in ROLES:
            raise table.error(f"unknown role {text!r}; allowed: {', '.join(ROLES)} "
                              f"(empty means {DEFAULT_ROLE})", line, ROLE_COLUMN)
    return roles


def _read_sessions(table: CsvTable) -> np.ndarray:
    """The session of each row: the ``session`` cell, or the file's stem where empty or absent."""
    default = default_session_name(table.source)
    if SESSION_COLUMN not in table.names:
        return np.full(len(table.rows), default, dtype=object)
    return np.array([text or default for text in table.cells(SESSION_COLUMN)], dtype=object)


def _read_extras(table: CsvTable, names: Sequence[str]) -> tuple[dict[str, np.ndarray], list[str]]:
    """Numeric extra columns (empty cells become NaN) and the names of the ignored ones."""
    kept: dict[str, np.ndarray] = {}
    ignored: list[str] = []
    for name in names:
        cells = table.cells(name)
        try:
            values = [float(c) if c else math.nan for c in cells]
        except ValueError:
            values = None
        if values is None or not any(cells):
            ignored.append(name)
        else:
            kept[name] = np.array(values)
    return kept, ignored


def read_extra_columns(path: str | os.PathLike[str], joint_names: Sequence[str]) -> dict[str, np.ndarray]:
    """The numeric extra columns of a CSV table, as :func:`read_measurements` keeps them (name -> (K,))."""
    table = read_table(path)
    return _read_extras(table, [n for n in table.names if not is_reserved(n, joint_names)])[0]


def file_columns(paths: Sequence[str | os.PathLike[str]], joint_names: Sequence[str]
                 ) -> list[tuple[str, dict[str, np.ndarray]]]:
    """(file, its numeric extra columns) of each file of several sessions, before the join keeps only
    the columns every file has (``joint_names``: the joint columns)."""
    return [(str(path), read_extra_columns(path, joint_names)) for path in paths]


def _limit_notes(
    table: CsvTable, q: np.ndarray, joints: Sequence[JointSpec], corrected: Sequence[str] = ()
) -> list[str]:
    """One note per joint with values ``q`` outside its limits (``corrected``: joints whose ``q`` is the
    reading corrected by eq C1)."""
    notes = []
    for n, joint in enumerate(joints):
        what = " (its reading corrected by --coupling, eq C1)" if joint.name in corrected else ""
        outside = np.flatnonzero((q[:, n] < joint.lower) | (q[:, n] > joint.upper))
        if outside.size:
            k, unit = outside[0], "m" if joint.kind == "prismatic" else "rad"
            notes.append(
                f"{table.source}: joint '{joint.name}'{what} is outside its limits [{joint.lower:.6g}, "
                f"{joint.upper:.6g}] {unit} in {outside.size} of {len(q)} rows; "
                f"first at line {table.lines[k]}: {q[k, n]:.6g} {unit}")
    return notes


def read_measurements(
    path: str | os.PathLike[str], joints: Sequence[JointSpec], couplings: Sequence[ReadingCoupling] = (),
    other_branches: Sequence[str] = (), occlusion: bool = False,
) -> tuple[MeasurementSet, list[str]]:
    """Read and validate a measurement file (format v1); with ``occlusion`` (several targets), an empty cell of a
    point is NaN (the point not seen in that row: :func:`pincal.fit.tree_calibration.tree_rows`), else an error,
    and each target's ``qxN,qyN,qzN,qwN`` are read (:mod:`pincal.measurements.target_orientations`).

    Args:
        path: CSV file.
        joints: the joints the rows must provide, in the order of the returned ``q``.
        couplings: readings taken against another joint: ``q`` holds the actual
            values (eq C1, :mod:`pincal.measurements.couplings`), and the joint-limit
            notes judge those, not the readings.
        other_branches: joints of the same URDF off the chain of ``joints`` (other branches, e.g. a
            head's joints for an arm): a file lacking a joint of ``joints`` but holding these is said to
            be of another chain (a wrong tip link), not to have a misspelt column.

    Returns:
        The measurement set and notes (joint limits, ignored or extra columns) for
        the caller to print.

    Raises:
        MeasurementError: naming the file, line and column of the first problem.
    """
    table = read_table(path)
    joint_names = [j.name for j in joints]
    read_against = reading_couplings(couplings)  # the others follow their driver (eq M1)
    q = corrected_angles(_joint_matrix(table, joints, other_branches, couplings), read_against, joint_names)
    point_names = _point_columns(table, joint_names)
    points = table.matrix([c for triplet in point_names for c in triplet], math.nan if occlusion else None)
    for i, name in enumerate(c for triplet in point_names for c in triplet):
        table.check_magnitude(name, points[:, i], MAX_POSITION, "millimetres", "metres")
    rotations = _read_rotations(table)
    targets = read_target_rotations(table, QUAT_NORM_TOL) if occlusion else {}  # each target's qxN,qyN,qzN,qwN
    roles = _read_roles(table)
    reserved = [*joint_names, *(j.mimic.driver for j in joints if j.mimic), *(c for n in targets
                                                                             for c in target_quat_columns(n))]
    extra, ignored = _read_extras(table, [n for n in table.names if not is_reserved(n, reserved)])
    notes = _limit_notes(table, q, joints, corrected=[c.joint for c in read_against])
    if ignored:
        notes.append(f"{table.source}: ignored non-numeric column(s): {', '.join(ignored)}")
    if extra:
        notes.append(f"{table.source}: kept numeric extra column(s): {', '.join(extra)}")
    data = MeasurementSet(tuple(joint_names), q, points.reshape(len(q), len(point_names), 3),
                          rotations, roles, np.array(table.lines), extra, table.source,
                          sessions=_read_sessions(table), target_rotations=targets)
    return data, notes


def read_sessions(
    paths: Sequence[str | os.PathLike[str]], joints: Sequence[JointSpec], couplings: Sequence[ReadingCoupling] = (),
    other_branches: Sequence[str] = (), occlusion: bool = False,
) -> tuple[MeasurementSet, list[str]]:
    """Read one or several measurement files as the sessions of one calibration.

    One file: :func:`read_measurements` (``couplings``, ``other_branches``, ``occlusion`` as there; its
    sessions are the values of its ``session`` column, the file's stem where empty or absent).
    Several files:
    each row's session is its file's stem — or the path as given when two files
    share a stem — followed by ``:VALUE`` for a ``session`` value of its own;
    every row keeps its file and line (:attr:`MeasurementSet.files`, ``lines``).

    Raises:
        MeasurementError: a file given twice, files that measure differently
            (:func:`pincal.measurements.data.join_sets`), or any problem of one file.
    """
    files = [Path(p) for p in paths]
    if len(files) == 1:
        return read_measurements(files[0], joints, couplings, other_branches, occlusion)
    refuse_given_twice(files, "each session's file")
    stems = [p.stem for p in files]
    sets, notes = [], []
    for path, stem in zip(files, stems):
        data, file_notes = read_measurements(path, joints, couplings, other_branches, occlusion)
        notes += file_notes
        name = stem if stems.count(stem) == 1 else str(path)
        own = default_session_name(data.source)
        labels = [name if label == own else f"{name}:{label}" for label in data.sessions]
        sets.append(replace(data, sessions=np.array(labels, dtype=object)))
    return join_sets(sets), notes


def write_measurements(path: str | os.PathLike[str], data: MeasurementSet) -> None:
    """Write ``data`` in format v1, exactly readable back by :func:`read_measurements`.

    Columns: joints, ``x,y,z`` (one point) or ``x1,y1,z1,...``, ``qx,qy,qz,qw`` if orientations
    were measured, each target's ``qxN,qyN,qzN,qwN`` if measured, ``role``, ``session`` when the rows
    belong to several sessions, then the extras. Floats are written with ``repr`` (shortest exact
    form), so q, points and extras round-trip bit for bit and rotations to ~1e-15; a point or a
    target's orientation not seen (NaN) is empty cells, as read with ``occlusion``.

    Raises:
        MeasurementError: if the file cannot be written.
    """
    p = data.n_points
    point_names = ["x", "y", "z"] if p == 1 else [f"{a}{i}" for i in range(1, p + 1) for a in "xyz"]
    numeric = [data.q, data.points.reshape(data.n_rows, 3 * p)]
    header = [*data.joint_names, *point_names]
    if data.rotations is not None and data.n_rows:
        numeric.append(Rotation.from_matrix(data.rotations).as_quat())
        header += QUAT_COLUMNS
    names, quats = target_quat_cells(data.target_rotations, data.n_rows)
    numeric, header = [*numeric, quats], [*header, *names, ROLE_COLUMN]
    labelled = len(data.session_names) > 1
    header += [*([SESSION_COLUMN] if labelled else []), *data.extra]
    numbers = np.hstack(numeric)
    extras = np.column_stack([data.extra[n] for n in data.extra]) if data.extra else np.empty((data.n_rows, 0))
    try:
        with replacing(path, "w", newline="") as handle:
            writer = csv.writer(handle, lineterminator="\n")
            writer.writerow(header)
            for k in range(data.n_rows):
                labels = [data.sessions[k]] if labelled else []
                writer.writerow([*(_format(v) if np.isfinite(v) else "" for v in numbers[k]), data.roles[k], *labels,
                                 *map(_format, extras[k])])
    except OSError as exc:
        raise MeasurementError(f"{path}: cannot write file ({exc.strerror or exc})") from None


def _format(value: float) -> str:
    """Shortest text that reads back as exactly ``value``."""
    return repr(float(value))
