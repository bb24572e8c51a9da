"""Joint readings taken against another joint: ``--coupling J=C*I``.

Some controllers report a joint's angle measured from another link rather than from its own
joint: on parallelogram arms (FANUC, ABB and KUKA heavy arms) J3 is read from the horizontal, so
the reading of J3 is J3 − J2. ``--coupling A3=-1*A2`` states it: joint J's reading includes
C × joint I's reading, and the actual angle is

    q_J = reading_J − C · reading_I                                               (C1)

applied to every row read (calibration, validation and evaluated rows) before anything else
sees them; REPORT.json records it (``couplings``), and ``pincal evaluate`` applies it to the rows
it evaluates. ``pincal diagnose`` finds such a coupling (the ``coupling`` effect of
:mod:`pincal.model.effects`, value −C) and names this flag. Every driver is taken as read, before
any correction, so the order of several couplings does not matter.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import TypedDict

import numpy as np

from pincal.errors import MeasurementError, PincalError, did_you_mean
from pincal.measurements.data import MeasurementSet

__all__ = ["CouplingJson", "ReadingCoupling", "apply_couplings", "check_couplings", "corrected_angles",
           "couplings_from_report", "decide_followers", "parse_coupling", "reading_couplings", "readings_of"]

_FORM = re.compile(r"^\s*([^=\s]+)\s*=\s*([-+]?[0-9.]+(?:[eE][-+]?[0-9]+)?)\s*\*\s*([^=*\s]+)\s*$")


class _CouplingKeys(TypedDict):
    joint: str
    factor: float
    driver: str


class CouplingJson(_CouplingKeys, total=False):
    """A joint reading taken against another, as REPORT.json and PLAN.json give it (``couplings``):
    ``joint``'s reading includes ``factor`` × ``driver``'s; ``follows`` (true only, absent otherwise): the
    joint has no reading and follows its driver, q = factor × q_driver (eq M1 of
    :mod:`pincal.measurements.mimics`, offset 0), as the run that wrote it decided."""

    follows: bool


@dataclass(frozen=True)
class ReadingCoupling:
    """Joint ``joint``'s reading includes ``factor`` × joint ``driver``'s reading (eq C1); with ``follows``,
    ``joint`` has no reading at all and its angle is ``factor`` × ``driver``'s (eq M1, offset 0): decided
    once per run, where the calibration data has no column for the joint (:func:`decide_followers`)."""

    joint: str
    factor: float
    driver: str
    follows: bool = False

    def __post_init__(self) -> None:
        """Raises ValueError: a factor that is not a finite non-zero number, or a joint read against itself
        (the flag's and the report's readers say it their way)."""
        if not (math.isfinite(self.factor) and self.factor != 0.0 and self.joint != self.driver):
            raise ValueError(f"not a coupling: {self.joint}, {self.factor!r}, {self.driver}")

    @property
    def label(self) -> str:
        """The flag's form: ``A3=-1*A2``."""
        return f"{self.joint}={self.factor:g}*{self.driver}"

    def as_dict(self) -> CouplingJson:
        """REPORT.json and PLAN.json ``couplings`` entry."""
        out: CouplingJson = {"joint": self.joint, "factor": self.factor, "driver": self.driver}
        if self.follows:
            out["follows"] = True
        return out


def parse_coupling(text: str) -> ReadingCoupling:
    """``J=C*I`` → :class:`ReadingCoupling`.

    Raises:
        PincalError: another form, a factor that is not a finite non-zero number, or J = I.
    """
    match = _FORM.match(text)
    try:  # float() refuses "." or "1.2.3", the coupling a zero factor or J = I
        if match:
            return ReadingCoupling(match.group(1), float(match.group(2)), match.group(3))
    except ValueError:
        pass
    raise PincalError(f"--coupling '{text}': use JOINT=FACTOR*DRIVER with two different joints and a non-zero "
                      "factor, e.g. A3=-1*A2 (A3's reading includes -1 x A2's: J3 read from the horizontal)")


def couplings_from_report(entries: object, where: str) -> tuple[ReadingCoupling, ...]:
    """REPORT.json ``couplings`` back (absent: none).

    Raises:
        PincalError: a malformed entry (``where`` names the report).
    """
    if entries is None:
        return ()
    try:
        if not isinstance(entries, list) or not all(isinstance(e, Mapping) for e in entries):
            raise TypeError("not a list of objects")
        if not all(isinstance(e.get("follows", False), bool) for e in entries):
            raise TypeError("follows is not true or false")
        return tuple(ReadingCoupling(str(e["joint"]), float(e["factor"]), str(e["driver"]), e.get("follows", False))
                     for e in entries)
    except (KeyError, TypeError, ValueError):
        raise PincalError(f"{where}: couplings must be a list of {{joint, factor, driver[, follows]}} with two "
                          "different joints and a non-zero factor; rewrite it with pincal calibrate or diagnose"
                          ) from None


def decide_followers(couplings: Sequence[ReadingCoupling], joint_names: Iterable[str],
                     columns: Iterable[Iterable[str]]) -> tuple[ReadingCoupling, ...]:
    """``couplings`` with ``follows`` set on each whose joint is on the chain (``joint_names``) and lacks a
    column in one of the files read (``columns``: each file's column names): that joint has no reading, it
    follows its driver (eq M1, offset 0). Decided once, from the run's calibration data; every later file
    (held-out rows, ``evaluate``'s, effects.yaml) uses what was decided, a column of it checked to eq M1."""
    names, files = set(joint_names), [set(c) for c in columns]
    return tuple(replace(c, follows=True) if c.follows or (c.joint in names and any(c.joint not in f for f in files))
                 else c for c in couplings)


def reading_couplings(couplings: Sequence[ReadingCoupling]) -> tuple[ReadingCoupling, ...]:
    """The couplings of eq C1: those of a joint with a reading (not ``follows``)."""
    return tuple(c for c in couplings if not c.follows)


def check_couplings(couplings: Sequence[ReadingCoupling], joint_names: Iterable[str]) -> None:
    """Every joint named is on the chain, and no joint is coupled twice.

    Raises:
        MeasurementError: a joint not on the chain (did you mean), or one corrected twice.
    """
    names = list(joint_names)
    for coupling in couplings:
        for name in (coupling.joint, coupling.driver):
            if name not in names:
                raise MeasurementError(f"--coupling {coupling.label}: no joint '{name}' on the chain; "
                                       f"{did_you_mean(name, names, 'joints')}")
    joints = [c.joint for c in couplings]
    twice = sorted({j for j in joints if joints.count(j) > 1})
    if twice:
        raise MeasurementError(f"--coupling: joint '{twice[0]}' is given twice; give one factor per joint")


def _matrix(couplings: Sequence[ReadingCoupling], joint_names: Sequence[str]) -> np.ndarray:
    """M of eq C1 for rows: actual = readings @ M.T (N, N); a follower's (``follows``) angle is eq M1's,
    computed where it is read (:mod:`pincal.measurements.mimics`), not a row of M."""
    check_couplings(couplings, joint_names)
    names = list(joint_names)
    matrix = np.eye(len(names))
    for c in reading_couplings(couplings):
        matrix[names.index(c.joint), names.index(c.driver)] -= c.factor
    return matrix


def corrected_angles(readings: np.ndarray, couplings: Sequence[ReadingCoupling],
                     joint_names: Sequence[str]) -> np.ndarray:
    """Eq C1 on joint readings (K, N) in the order of ``joint_names``: the actual angles [rad or m]."""
    return np.asarray(readings, dtype=float) if not reading_couplings(couplings) \
        else readings @ _matrix(couplings, joint_names).T


def readings_of(angles: np.ndarray, couplings: Sequence[ReadingCoupling], joint_names: Sequence[str]) -> np.ndarray:
    """The inverse of eq C1: what the controller reads (and is commanded in) at actual angles (K, N)."""
    if not reading_couplings(couplings):
        return np.asarray(angles, dtype=float)
    return np.linalg.solve(_matrix(couplings, joint_names), np.asarray(angles, dtype=float).T).T


def apply_couplings(data: MeasurementSet, couplings: Sequence[ReadingCoupling]) -> MeasurementSet:
    """The rows of ``data`` with eq C1 applied to their joint readings (``data`` itself unchanged)."""
    if not reading_couplings(couplings):
        return data
    return replace(data, q=corrected_angles(data.q, couplings, data.joint_names))
