"""Each target's orientation in a file of several targets: columns ``qxN,qyN,qzN,qwN``.

With several ``--tip-link LINK:POINTS`` a row measures several targets, each a rigid body on its own
tip link. A 6D tracker (a motion-capture rigid body) reports its body's position and orientation
together; the position is one of the numbered points, ``xN,yN,zN``, and its orientation goes in
``qxN,qyN,qzN,qwN`` (unit quaternion, scalar last, in the sensor frame, as ``qx,qy,qz,qw`` of one
chain). The orientation is the target link's, not the point's: a rigid target has one orientation
however many of its points are measured, so a target takes at most one such group of columns,
numbered with any one of its points (the one its tracker reports with it). The number ties the
columns to the file's own points, as ``xN,yN,zN`` are, not to the order of the ``--tip-link``
flags: reordering the flags cannot give a target another's orientation. Which target a number
belongs to is the tree's business (:func:`pincal.fit.tree_calibration.tree_rows`); this module reads
the cells.

An empty row of the four cells is the orientation not seen in that row (occlusion), as an empty
point is; some of the four empty, a cell that is no number, or a quaternion that is not of unit
norm is one line naming the file, the line and the column.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from typing import Protocol

import numpy as np
from scipy.spatial.transform import Rotation

from pincal.errors import PincalError

__all__ = ["TARGET_QUAT_RE", "CellTable", "target_quat_columns", "read_target_rotations", "target_quat_cells"]

#: A numbered orientation column: ``qxN``, ``qyN``, ``qzN`` or ``qwN`` (N = 1, 2, ...).
TARGET_QUAT_RE = re.compile(r"q([xyzw])([1-9][0-9]*)")


class CellTable(Protocol):
    """What is read of a table here (:class:`pincal.measurements.csv_v1.CsvTable` is one)."""

    @property
    def names(self) -> tuple[str, ...]: ...

    @property
    def lines(self) -> list[int]: ...

    def matrix(self, names: Sequence[str], blank: float | None = None) -> np.ndarray: ...

    def error(self, message: str, line: int | None = None, column: str | None = None,
              joint: str | None = None) -> PincalError: ...


def target_quat_columns(number: int) -> tuple[str, str, str, str]:
    """The four columns of the orientation numbered ``number``: ``qxN,qyN,qzN,qwN``."""
    return f"qx{number}", f"qy{number}", f"qz{number}", f"qw{number}"


def read_target_rotations(table: CellTable, norm_tolerance: float) -> dict[int, np.ndarray]:
    """Every orientation group ``qxN,qyN,qzN,qwN`` of ``table``: N → (K, 3, 3) rotations in the sensor frame,
    normalised, NaN in the rows where all four cells are empty (not seen); {} without such columns.

    ``norm_tolerance``: the largest | |q| − 1 | accepted (the reader's, for ``qx,qy,qz,qw`` too).

    Raises:
        MeasurementError (the table's kind): a group missing some of its four columns, a row with some of
            its four cells empty, a cell that is not a finite number, a quaternion not of unit norm —
            one line naming the file, the line and the column(s).
    """
    numbers = sorted({int(m[2]) for name in table.names if (m := TARGET_QUAT_RE.fullmatch(name))})
    out: dict[int, np.ndarray] = {}
    for number in numbers:
        names = target_quat_columns(number)
        missing = [c for c in names if c not in table.names]
        if missing:
            raise table.error(f"partial orientation columns: missing {','.join(missing)}; give all of "
                              f"{','.join(names)} (the orientation of the target measured with point {number}) "
                              "or none")
        quats = table.matrix(names, np.nan)
        empty = np.isnan(quats)
        partial = np.flatnonzero(empty.any(axis=1) & ~empty.all(axis=1))
        if partial.size:
            k = int(partial[0])
            raise table.error(f"some of {','.join(names)} empty; leave all four empty (the orientation not seen "
                              "in this row) or give all four", table.lines[k],
                              names[int(np.flatnonzero(empty[k])[0])])
        seen = ~empty.any(axis=1)
        norms = np.linalg.norm(quats, axis=1)
        bad = np.flatnonzero(seen & (np.abs(norms - 1.0) > norm_tolerance))
        if bad.size:
            k = int(bad[0])
            raise table.error(f"quaternion {','.join(names)} has norm {norms[k]:.6g}; expected a unit quaternion "
                              f"(within {norm_tolerance:g})", table.lines[k])
        rotations = np.full((len(quats), 3, 3), np.nan)
        if seen.any():
            rotations[seen] = Rotation.from_quat(quats[seen] / norms[seen, None]).as_matrix()
        out[number] = rotations
    return out


def target_quat_cells(rotations: Mapping[int, np.ndarray], n_rows: int) -> tuple[list[str], np.ndarray]:
    """The columns ``qxN,qyN,qzN,qwN`` of each target's orientation (N → (K, 3, 3), NaN where not seen), in
    increasing N, and their values (K, 4·groups): unit quaternions, scalar last, NaN where not seen (an empty
    group, what :func:`read_target_rotations` reads back)."""
    names: list[str] = []
    quats = [np.empty((n_rows, 0))]
    for number in sorted(rotations):
        turns = np.asarray(rotations[number], dtype=float).reshape(n_rows, 3, 3)
        seen = np.isfinite(turns).all(axis=(1, 2))
        group = np.full((n_rows, 4), np.nan)
        if seen.any():
            group[seen] = Rotation.from_matrix(turns[seen]).as_quat()
        names += target_quat_columns(number)
        quats.append(group)
    return names, np.hstack(quats)
