"""Measurements in memory: the joint specification and one set of rows (CSV v1 in :mod:`pincal.measurements.csv_v1`)."""

from __future__ import annotations

import math
import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path, PurePath
from types import MappingProxyType
from typing import Literal, TypedDict, get_args

import numpy as np
import numpy.typing as npt

from pincal.errors import MeasurementError, ModelError, PincalError, did_you_mean

__all__ = [
    "ROLES", "DEFAULT_ROLE", "ROLE_COLUMN", "SESSION_COLUMN", "QUAT_COLUMNS", "JOINT_SANITY", "POSITION_COLUMN_RE",
    "JointMimic", "MimicJson", "JointSpec", "is_reserved", "default_session_name", "reported_session",
    "MeasurementSet", "join_sets", "SensorKind", "SENSOR_KINDS", "refuse_given_twice",
]

ROLES = ("cpa", "calibration", "validation")
DEFAULT_ROLE = "calibration"
ROLE_COLUMN = "role"
#: Optional text column naming each row's session (one registration per session).
SESSION_COLUMN = "session"
QUAT_COLUMNS = ("qx", "qy", "qz", "qw")

#: What a sensor reports per row: ``point`` (one point), ``points`` (several points of one rigid
#: target) or ``pose`` (one point and the target's orientation, :data:`QUAT_COLUMNS`).
SensorKind = Literal["point", "points", "pose"]
#: The values of :data:`SensorKind`, in order.
SENSOR_KINDS: tuple[SensorKind, ...] = get_args(SensorKind)


#: Largest plausible |joint value| per kind [rad or m], with the unit mistake it hints at.
JOINT_SANITY = {
    "revolute": (2 * math.pi + 0.5, "degrees", "radians"),
    "continuous": (100.0, "degrees", "radians"),
    "prismatic": (5.0, "millimetres", "metres"),
}
POSITION_COLUMN_RE = re.compile(r"([xyz])(0|[1-9][0-9]*)?")


@dataclass(frozen=True)
class JointMimic:
    """A joint that follows another (URDF ``<mimic>``): its angle is

        q = multiplier · q_driver + offset   [rad or m]                         (M1)

    so the data need no column for it (:mod:`pincal.measurements.mimics`).

    Attributes:
        driver: the joint it follows (on the chain or off it: then the data give its column).
        multiplier: [-] (URDF default 1; rad/m or m/rad between a revolute and a prismatic joint).
        offset: [rad or m] (URDF default 0).
    """

    driver: str
    multiplier: float = 1.0
    offset: float = 0.0


class MimicJson(TypedDict):
    """A chain joint that follows another, as REPORT.json gives it (``chain.mimics``): ``joint``'s angle is
    ``multiplier`` × ``driver``'s + ``offset`` (eq M1), computed from the driver's column, not read."""

    joint: str
    driver: str
    multiplier: float
    offset: float


@dataclass(frozen=True)
class JointSpec:
    """One joint the data must provide.

    Attributes:
        name: URDF joint name, also the CSV column name.
        kind: ``"revolute"``, ``"continuous"`` or ``"prismatic"``.
        lower: lower limit [rad or m]; ``-inf`` when unlimited.
        upper: upper limit [rad or m]; ``inf`` when unlimited.
        mimic: how the joint follows its driver (eq M1), None for a joint the data give.
    """

    name: str
    kind: str
    lower: float = -math.inf
    upper: float = math.inf
    mimic: JointMimic | None = None

    def __post_init__(self) -> None:
        if self.kind not in JOINT_SANITY:
            raise ModelError(
                f"joint '{self.name}' has kind '{self.kind}'; pincal measures only "
                f"{', '.join(JOINT_SANITY)} joints"
            )


def _frozen(values: npt.ArrayLike, dtype: npt.DTypeLike) -> np.ndarray:
    """Return a read-only copy of ``values`` as an array of ``dtype``."""
    out = np.array(values, dtype=dtype, copy=True)
    out.flags.writeable = False
    return out


def is_reserved(name: str, joint_names: Sequence[str]) -> bool:
    """Whether ``name`` is a column the format gives a meaning to (so not an extra)."""
    return (name in joint_names or name in QUAT_COLUMNS or name in (ROLE_COLUMN, SESSION_COLUMN)
            or POSITION_COLUMN_RE.fullmatch(name) is not None)


def default_session_name(source: str) -> str:
    """The session of rows that name none: their file's name without its extension."""
    return PurePath(source).stem or str(source)


def reported_session(value: object, where: str, key: str) -> str:
    """The ``session`` of a REPORT.json entry of ``key`` (``time_spans_s``, ``pause_spans_s``, ``pauses``).

    Raises:
        PincalError: not a non-empty string, which would name no session and so apply to no row (``where``
            names the report).
    """
    if isinstance(value, str) and value:
        return value
    raise PincalError(f"{where}: {key}[].session must be a session's name (a non-empty string), got {value!r}: "
                      "such an entry applies to no row; rewrite it with pincal diagnose")


@dataclass(frozen=True, eq=False)
class MeasurementSet:
    """K measured robot configurations; arrays are read-only copies.

    Attributes:
        joint_names: N joint names, the column order of ``q``.
        q: (K, N) joint readings [rad for revolute/continuous, m for prismatic].
        points: (K, P, 3) target points in the sensor frame [m].
        rotations: (K, 3, 3) target orientations in the sensor frame, or None.
        roles: (K,) object array of ``"cpa"``, ``"calibration"`` or ``"validation"``.
        lines: (K,) 1-based line numbers in the source file (header is line 1).
        extra: numeric extra columns by name, each (K,).
        source: file path the data came from, or ``"<memory>"`` (several files: joined by ``" + "``).
        sessions: (K,) object array, each row's session name (rows of one session
            share one registration, sensor_T_base); default: every row in one
            session named after ``source`` (:func:`default_session_name`).
        files: (K,) object array, the file each row came from (``lines`` count in it);
            default: ``source``.
        dropped_extra: the extra columns a join of several files left out because some of
            the files lack them (:func:`join_sets`): each name with the files without it.
        target_rotations: with several targets, each target's measured orientation in the sensor frame by
            the number N of its columns ``qxN,qyN,qzN,qwN`` (:mod:`pincal.measurements.target_orientations`),
            (K, 3, 3) each, NaN in a row where it was not seen; empty otherwise.
    """

    joint_names: tuple[str, ...]
    q: np.ndarray
    points: np.ndarray
    rotations: np.ndarray | None
    roles: np.ndarray
    lines: np.ndarray
    extra: Mapping[str, np.ndarray] = field(default_factory=dict)
    source: str = "<memory>"
    # None (the default) is replaced by the default labels in __post_init__: arrays once constructed
    sessions: np.ndarray = None  # type: ignore[assignment]  # None: replaced in __post_init__
    files: np.ndarray = None  # type: ignore[assignment]  # None: replaced in __post_init__
    dropped_extra: Mapping[str, tuple[str, ...]] = field(default_factory=dict)
    target_rotations: Mapping[int, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        names = tuple(str(n) for n in self.joint_names)
        values = {
            "joint_names": names,
            "q": _frozen(self.q, float),
            "points": _frozen(self.points, float),
            "rotations": None if self.rotations is None else _frozen(self.rotations, float),
            "roles": _frozen(self.roles, object),
            "lines": _frozen(self.lines, np.int64),
            "extra": MappingProxyType({str(k): _frozen(v, float) for k, v in self.extra.items()}),
            "dropped_extra": MappingProxyType({str(k): tuple(map(str, v)) for k, v in self.dropped_extra.items()}),
            "target_rotations": MappingProxyType({int(n): _frozen(r, float) for n, r in self.target_rotations.items()}),
        }
        for key, value in values.items():
            object.__setattr__(self, key, value)
        k = self.q.shape[0] if self.q.ndim == 2 else -1
        for key, default in (("sessions", default_session_name(self.source)), ("files", self.source)):
            given = getattr(self, key)
            labels = np.full(max(k, 0), default, dtype=object) if given is None else given
            object.__setattr__(self, key, _frozen([str(v) for v in np.ravel(labels)], object))
        problems = [
            (self.q.shape != (k, len(names)), f"q has shape {self.q.shape}, expected (K, {len(names)})"),
            (self.points.ndim != 3 or self.points.shape[0] != k or self.points.shape[2] != 3
             or self.points.shape[1] < 1, f"points has shape {self.points.shape}, expected ({k}, P>=1, 3)"),
            (self.rotations is not None and self.rotations.shape != (k, 3, 3),
             f"rotations has shape {getattr(self.rotations, 'shape', None)}, expected ({k}, 3, 3)"),
            (self.roles.shape != (k,), f"roles has shape {self.roles.shape}, expected ({k},)"),
            (self.lines.shape != (k,), f"lines has shape {self.lines.shape}, expected ({k},)"),
            (self.sessions.shape != (k,), f"sessions has {self.sessions.size} labels, expected {k}"),
            (self.files.shape != (k,), f"files has {self.files.size} labels, expected {k}"),
            (any(not label for label in self.sessions), "a session name is empty"),
            (len(set(names)) != len(names), "joint names are not unique"),
            (not set(self.roles.ravel().tolist()) <= set(ROLES), f"roles must be among {', '.join(ROLES)}"),
        ]
        for number, turns in self.target_rotations.items():
            problems.append((turns.shape != (k, 3, 3), f"target_rotations[{number}] has shape {turns.shape}, "
                             f"expected ({k}, 3, 3)"))
        for name, column in self.extra.items():
            problems.append((column.shape != (k,), f"extra '{name}' has shape {column.shape}, expected ({k},)"))
            problems.append((is_reserved(name, names), f"extra column name '{name}' is reserved"))
        for failed, message in problems:
            if failed:
                raise MeasurementError(f"{self.source}: invalid measurement set: {message}")

    @property
    def n_rows(self) -> int:
        """Number K of configurations."""
        return int(self.q.shape[0])

    @property
    def n_points(self) -> int:
        """Number P of target points per configuration."""
        return int(self.points.shape[1])

    @property
    def has_orientation(self) -> bool:
        """Whether target orientations were measured."""
        return self.rotations is not None

    @property
    def session_names(self) -> tuple[str, ...]:
        """The sessions, in the order of their first row."""
        return tuple(dict.fromkeys(self.sessions.tolist()))

    @property
    def session_index(self) -> np.ndarray:
        """Each row's session as an index into :attr:`session_names`, (K,)."""
        order = {name: i for i, name in enumerate(self.session_names)}
        return np.array([order[name] for name in self.sessions], dtype=np.intp)

    def reading_column(self, name: str | None, defaults: Sequence[str], quantity: str, needs: str, flag: str,
                       unit: str = "") -> tuple[str, np.ndarray] | None:
        """A per-row reading from a numeric extra column: the one ``flag`` names (``name``), else the first
        of ``defaults`` present, with its name; None without one. ``quantity`` ("time", "temperature")
        and ``unit`` (" (°C)") word the errors.

        Raises:
            PincalError: a named column in some of several session files only (the join dropped it:
                naming the files without it, and that ``needs`` every row's value) or in none (with the
                closest names); an empty or non-finite cell (file, line and column).
        """
        if name and name in self.dropped_extra:
            lacking = self.dropped_extra[name]
            raise PincalError(f"{', '.join(lacking)}: no {quantity} column '{name}', which the other session "
                              f"file(s) have; {needs}: add the column to "
                              f"{'this file' if len(lacking) == 1 else 'these files'}, or leave out {flag}")
        if name and name not in self.extra:
            raise PincalError(f"{self.source}: no {quantity} column '{name}'; "
                              f"{did_you_mean(name, self.extra, 'numeric extra columns')}")
        found = name or next((n for n in defaults if n in self.extra), None)
        if found is None:
            return None
        values = np.asarray(self.extra[found], dtype=float)
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            raise PincalError(f"{self.source}, line {int(self.lines[bad[0]])}, column '{found}': empty or "
                              f"non-finite {quantity}; fill it in{unit} or choose another column with {flag}")
        return found, values

    def select(self, mask: np.ndarray) -> MeasurementSet:
        """Return the rows picked by a boolean mask of shape (K,) or an index array."""
        index = np.asarray(mask)
        if index.dtype != bool:
            index = index.astype(np.intp)
        rows = {
            "joint_names": self.joint_names,
            "q": self.q[index],
            "points": self.points[index],
            "rotations": None if self.rotations is None else self.rotations[index],
            "roles": self.roles[index],
            "lines": self.lines[index],
            "extra": {name: column[index] for name, column in self.extra.items()},
            "source": self.source,
            "sessions": self.sessions[index],
            "files": self.files[index],
            "dropped_extra": self.dropped_extra,
            "target_rotations": {n: turns[index] for n, turns in self.target_rotations.items()},
        }
        if index.ndim != 1:  # not a choice of rows: the constructor says what is wrong
            return MeasurementSet(**rows)
        # rows of a valid set are a valid set, not checked again: NumPy's indexing made new
        # arrays, frozen here in place of the constructor's read-only copies
        for array in (rows["q"], rows["points"], rows["rotations"], rows["roles"], rows["lines"],
                      rows["sessions"], rows["files"], *rows["extra"].values(), *rows["target_rotations"].values()):
            if array is not None:
                array.flags.writeable = False
        rows["extra"] = MappingProxyType(rows["extra"])
        rows["target_rotations"] = MappingProxyType(rows["target_rotations"])
        subset = object.__new__(MeasurementSet)
        for key, value in rows.items():
            object.__setattr__(subset, key, value)
        return subset

    def with_role(self, *roles: str) -> MeasurementSet:
        """Return the rows whose role is one of ``roles``, in file order."""
        unknown = sorted(set(roles) - set(ROLES))
        if unknown:
            raise MeasurementError(
                f"{self.source}: unknown role(s) {', '.join(unknown)}; allowed: {', '.join(ROLES)}"
            )
        return self.select(np.isin(self.roles, roles))


def join_sets(sets: Sequence[MeasurementSet]) -> MeasurementSet:
    """The rows of several measurement sets, in order, as one set (each row keeps its
    session, file and line); extra columns missing from one of them are dropped, and
    named with the files that lack them in :attr:`MeasurementSet.dropped_extra`.

    Raises:
        MeasurementError: the sets differ in joints, in target points per row,
            or in whether orientations were measured — naming the two files.
    """
    if not sets:
        raise MeasurementError("no measurement files given")
    first = sets[0]
    for other in sets[1:]:
        differs = [
            (other.joint_names != first.joint_names, "joint columns"),
            (other.n_points != first.n_points,
             f"target points per row ({other.n_points} against {first.n_points})"),
            (other.has_orientation != first.has_orientation, "orientation columns qx,qy,qz,qw"),
            (sorted(other.target_rotations) != sorted(first.target_rotations), "orientation columns qxN,qyN,qzN,qwN"),
        ]
        for failed, what in differs:
            if failed:
                raise MeasurementError(
                    f"{other.source}: differs from {first.source} in its {what}; the sessions of one "
                    "calibration measure the same target the same way")
    common = [name for name in first.extra if all(name in s.extra for s in sets)]
    dropped = {name: tuple(s.source for s in sets if name not in s.extra)
               for name in dict.fromkeys(n for s in sets for n in s.extra) if name not in common}
    return MeasurementSet(
        joint_names=first.joint_names,
        q=np.concatenate([s.q for s in sets]),
        points=np.concatenate([s.points for s in sets]),
        rotations=None if first.rotations is None else np.concatenate([s.rotations for s in sets]),
        roles=np.concatenate([s.roles for s in sets]),
        lines=np.concatenate([s.lines for s in sets]),
        extra={name: np.concatenate([s.extra[name] for s in sets]) for name in common},
        source=" + ".join(s.source for s in sets),
        sessions=np.concatenate([s.sessions for s in sets]),
        files=np.concatenate([s.files for s in sets]),
        dropped_extra=dropped,
        target_rotations={n: np.concatenate([s.target_rotations[n] for s in sets]) for n in first.target_rotations},
    )


def refuse_given_twice(files: Sequence[Path], what: str) -> None:
    """Refuse a file given twice (by any path to it): ``what`` names the files in the message ("give
    each session's file once")."""
    seen: dict[str, Path] = {}
    for path in files:
        key = os.path.normcase(os.path.abspath(path))
        if key in seen:
            raise MeasurementError(f"{path}: given twice (also as {seen[key]}); give {what} once")
        seen[key] = path
