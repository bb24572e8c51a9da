"""DH tables from CSV files: one row per joint, checked cell by cell.

Columns (header names are case-insensitive, order free):

====================  ==========================================================
``joint``             joint name (becomes the URDF joint name)
``a``                 link length [m]
``alpha``             link twist [rad, or deg with ``degrees=True``]
``d``                 link offset [m]
``theta``             joint angle offset [rad, or deg]
``type`` (optional)   ``revolute`` (default, also for an empty cell), ``prismatic`` or
                      ``continuous`` (a revolute joint without position limits)
``lower``, ``upper``  position limits [rad or deg for revolute joints, m for
(optional)            prismatic]; default :data:`pincal.model.dh.robot.DEFAULT_LIMITS`
``velocity``          velocity limit [rad/s or m/s]; default
(optional)            :data:`pincal.model.dh.robot.DEFAULT_VELOCITY`
``effort``            effort limit [N·m or N]; default
(optional)            :data:`pincal.model.dh.robot.DEFAULT_EFFORT`
====================  ==========================================================

What a row means depends on the convention (:mod:`pincal.model.dh.robot`): in the
``modified`` convention the row of joint i holds alpha_{i-1} and a_{i-1} (Craig's
table layout). Every problem raises :class:`~pincal.errors.ModelError` with one
line naming the file, the line (the header is line 1), the joint and the column,
and what to do; soft findings (defaults used, ignored columns) are returned as
notes. This module never prints.
"""

from __future__ import annotations

import math
import os
from typing import Any

from pincal.errors import ModelError
from pincal.measurements.csv_v1 import MAX_POSITION, CsvTable, read_table
from pincal.measurements.data import JOINT_SANITY
from pincal.model.dh.conventions import MAX_ANGLE_RAD, is_right_angles_in_radians
from pincal.model.dh.robot import (
    DEFAULT_EFFORT,
    DEFAULT_LIMITS,
    DEFAULT_VELOCITY,
    DH_JOINT_TYPES,
    DHRobot,
)
from pincal.model.dh.table import check_convention
from pincal.model.dh.urdf import DH_FLANGE_JOINT

__all__ = [
    "REQUIRED_COLUMNS", "OPTIONAL_COLUMNS", "RESERVED_JOINT_NAMES", "MAX_ANGLE_RAD", "MAX_LENGTH_M", "MAX_PRISMATIC_M",
    "read_dh_csv",
]

#: Columns every DH table must have.
REQUIRED_COLUMNS = ("joint", "a", "alpha", "d", "theta")
#: Columns a DH table may have.
OPTIONAL_COLUMNS = ("type", "lower", "upper", "velocity", "effort")
#: Joint names the URDF writer uses itself (the fixed joint carrying the flange).
RESERVED_JOINT_NAMES = (DH_FLANGE_JOINT,)
#: A DH length beyond this [m] is taken for millimetres: the measurement reader's
#: bound on target coordinates (:data:`pincal.measurements.csv_v1.MAX_POSITION`).
MAX_LENGTH_M = MAX_POSITION
#: A prismatic limit beyond this [m] is taken for millimetres: the measurement
#: reader's bound on prismatic joint readings.
MAX_PRISMATIC_M = JOINT_SANITY["prismatic"][0]


def _read_rows(path: str | os.PathLike[str]) -> CsvTable:
    """The table's cells (header names case-insensitive), with every required column present."""
    table = read_table(path, rows_are="joint", error_type=ModelError, lowercase=True)
    missing = [c for c in REQUIRED_COLUMNS if c not in table.names]
    if missing:
        hint = "; is the file comma-separated?" if len(table.names) == 1 else ""
        raise table.error(f"missing column(s) {', '.join(missing)}; a DH table needs "
                          f"{', '.join(REQUIRED_COLUMNS)} (optional: {', '.join(OPTIONAL_COLUMNS)}){hint}",
                          table.header_line)
    return table


def read_dh_csv(path: str | os.PathLike[str], convention: str, degrees: bool = False) -> tuple[DHRobot, list[str]]:
    """Read a DH table file (see the module docstring for its columns).

    Args:
        path: CSV file, one row per joint in chain order.
        convention: ``standard`` or ``modified``.
        degrees: read alpha, theta and the limits of revolute joints in degrees.

    Returns:
        The robot (angles converted to radians) and notes for the caller to
        print (defaults used, columns ignored).

    Raises:
        ModelError: one line naming the file, line, joint and column of the
            first problem and what to do.
    """
    check_convention(convention)  # before reading the table
    table = _read_rows(path)
    to_rad = math.radians if degrees else float
    names: list[str] = []
    kinds: list[str] = []
    columns: dict[str, list[float]] = {c: [] for c in ("a", "alpha", "d", "theta", "lower", "upper", "velocity",
                                                       "effort")}
    seen: dict[str, int] = {}
    defaulted_limits: list[str] = []
    defaulted_velocity: list[str] = []
    defaulted_effort: list[str] = []
    for k, line in enumerate(table.lines):
        name = table.cell(k, "joint")
        if not name:
            raise table.error("empty joint name; name every joint", line, "joint")
        if name in seen:
            raise table.error(f"joint name '{name}' already used on line {table.lines[seen[name]]}; "
                              "joint names must be distinct", line, "joint")
        if name in RESERVED_JOINT_NAMES:
            raise table.error(f"'{name}' is the name of the fixed joint pincal adds for the flange; "
                              "rename the joint", line, "joint")
        seen[name] = k
        kind = table.cell(k, "type").lower() or "revolute"
        if kind not in DH_JOINT_TYPES:
            raise table.error(f"unknown joint type '{table.cell(k, 'type')}'; use "
                              f"{', '.join(DH_JOINT_TYPES[:-1])} or {DH_JOINT_TYPES[-1]} (empty = revolute)",
                              line, "type", name)
        row: dict[str, Any] = {}  # a float, or None for an empty limit cell
        for column in ("a", "alpha", "d", "theta"):
            value = table.number(k, column, name)
            if value is None:
                raise table.error("empty cell; give a number (0 if the parameter is zero)", line, column, name)
            row[column] = value
        angles = ["alpha", "theta"] + (["lower", "upper"] if kind == "revolute" else [])
        for column in ("lower", "upper", "velocity", "effort"):
            row[column] = table.number(k, column, name)  # None = default
            if kind == "continuous" and column in ("lower", "upper") and row[column] is not None:
                raise table.error("a continuous joint has no position limits; leave the cell empty, or make the "
                                  "joint revolute", line, column, name)
        for column in angles:
            if row[column] is not None and not degrees and abs(row[column]) > MAX_ANGLE_RAD:
                raise table.error(f"{row[column]:g} looks like degrees (more than one turn, "
                                  f"|value| > 2π rad); give radians, or pass --degrees if the "
                                  "table's angles are in degrees", line, column, name)
            if row[column] is not None and degrees and is_right_angles_in_radians(row[column]):
                raise table.error(f"{row[column]:g} looks like radians (a multiple of π/2 = 90°, not a "
                                  "plausible angle in degrees); drop --degrees if the table's angles are in "
                                  "radians", line, column, name)
        lengths = ["a", "d"] + (["lower", "upper"] if kind == "prismatic" else [])
        for column in lengths:
            bound = MAX_LENGTH_M if column in ("a", "d") else MAX_PRISMATIC_M
            if row[column] is not None and abs(row[column]) > bound:
                raise table.error(f"{row[column]:g} looks like millimetres (|value| > {bound:g} m); "
                                  "give metres", line, column, name)
        for column in ("velocity", "effort"):
            if row[column] is not None and row[column] < 0:
                raise table.error(f"{row[column]:g} is negative; give a limit >= 0", line, column, name)
        limits = []
        for i, column in enumerate(("lower", "upper")):
            if row[column] is None:
                limits.append(DEFAULT_LIMITS[kind][i])
            else:
                limits.append(to_rad(row[column]) if kind == "revolute" else row[column])
        if (row["lower"] is None or row["upper"] is None) and kind != "continuous":
            defaulted_limits.append(name)
        if limits[0] > limits[1]:
            shown = [f"{row[c]:g}" if row[c] is not None else f"{v:g} (default)"
                     for c, v in zip(("lower", "upper"), limits)]
            raise table.error(f"lower limit {shown[0]} > upper limit {shown[1]}; "
                              "swap them or fix the limits", line, "lower", name)
        if row["velocity"] is None:
            defaulted_velocity.append(name)
        if row["effort"] is None:
            defaulted_effort.append(name)
        names.append(name)
        kinds.append(kind)
        columns["alpha"].append(to_rad(row["alpha"]))
        columns["theta"].append(to_rad(row["theta"]))
        columns["a"].append(row["a"])
        columns["d"].append(row["d"])
        columns["lower"].append(limits[0])
        columns["upper"].append(limits[1])
        columns["velocity"].append(DEFAULT_VELOCITY if row["velocity"] is None else row["velocity"])
        columns["effort"].append(DEFAULT_EFFORT if row["effort"] is None else row["effort"])
    robot = DHRobot(
        convention=convention, names=tuple(names), alpha=columns["alpha"], a=columns["a"],
        theta=columns["theta"], d=columns["d"], types=tuple(kinds), lower=columns["lower"],
        upper=columns["upper"], velocity=columns["velocity"], effort=columns["effort"],
    )
    return robot, _notes(table, defaulted_limits, defaulted_velocity, defaulted_effort)


def _notes(table: CsvTable, limits: list[str], velocity: list[str], effort: list[str]) -> list[str]:
    notes = []
    ignored = [n for n in table.names if n not in REQUIRED_COLUMNS + OPTIONAL_COLUMNS]
    if ignored:
        notes.append(f"{table.source}: ignored column(s) {', '.join(ignored)}; DH columns are "
                     f"{', '.join(REQUIRED_COLUMNS + OPTIONAL_COLUMNS)}")
    if limits:
        rev, pri = DEFAULT_LIMITS["revolute"], DEFAULT_LIMITS["prismatic"]
        notes.append(f"{table.source}: no lower/upper limit for joint(s) {', '.join(limits)}; "
                     f"default [{rev[0]:.6g}, {rev[1]:.6g}] rad (revolute), [{pri[0]:g}, {pri[1]:g}] m "
                     "(prismatic) used where absent")
    placeholders = {"velocity": (velocity, f"{DEFAULT_VELOCITY:g} rad/s (m/s)"),
                    "effort": (effort, f"{DEFAULT_EFFORT:g} N·m (N)")}
    if velocity and velocity == effort:
        notes.append(f"{table.source}: no velocity or effort limit for joint(s) {', '.join(velocity)}; "
                     f"placeholders {placeholders['velocity'][1]} and {placeholders['effort'][1]} written")
    else:
        for column, (joints, value) in placeholders.items():
            if joints:
                notes.append(f"{table.source}: no {column} limit for joint(s) {', '.join(joints)}; "
                             f"placeholder {value} written")
    return notes
