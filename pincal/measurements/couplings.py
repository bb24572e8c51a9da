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
           "couplings_from_report", "parse_coupling", "readings_of"]

_FORM = re.compile(r"^\s*([^=\s]+)\s*=\s*([-+]?[0-9.]+(?:[eE][-+]?[0-9]+)?)\s*\*\s*([^=*\s]+)\s*$")


class CouplingJson(TypedDict):
    """A joint reading taken against another, as REPORT.json and PLAN.json give it (``couplings``):
    ``joint``'s reading includes ``factor`` × ``driver``'s."""

    joint: str
    factor: float
    driver: str


@dataclass(frozen=True)
class ReadingCoupling:
    """Joint ``joint``'s reading includes ``factor`` × joint ``driver``'s reading (eq C1)."""

    joint: str
    factor: float
    driver: str

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
        return {"joint": self.joint, "factor": self.factor, "driver": self.driver}


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
        return tuple(ReadingCoupling(str(e["joint"]), float(e["factor"]), str(e["driver"])) for e in entries)
    except (KeyError, TypeError, ValueError):
        raise PincalError(f"{where}: couplings must be a list of {{joint, factor, driver}} with two different "
                          "joints and a non-zero factor; rewrite it with pincal calibrate or diagnose") from None


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
    """M of eq C1 for rows: actual = readings @ M.T (N, N)."""
    check_couplings(couplings, joint_names)
    names = list(joint_names)
    matrix = np.eye(len(names))
    for c in couplings:
        matrix[names.index(c.joint), names.index(c.driver)] -= c.factor
    return matrix


def corrected_angles(readings: np.ndarray, couplings: Sequence[ReadingCoupling],
                     joint_names: Sequence[str]) -> np.ndarray:
    """Eq C1 on joint readings (K, N) in the order of ``joint_names``: the actual angles [rad or m]."""
    return np.asarray(readings, dtype=float) if not couplings else readings @ _matrix(couplings, joint_names).T


def readings_of(angles: np.ndarray, couplings: Sequence[ReadingCoupling], joint_names: Sequence[str]) -> np.ndarray:
    """The inverse of eq C1: what the controller reads (and is commanded in) at actual angles (K, N)."""
    if not couplings:
        return np.asarray(angles, dtype=float)
    return np.linalg.solve(_matrix(couplings, joint_names), np.asarray(angles, dtype=float).T).T


def apply_couplings(data: MeasurementSet, couplings: Sequence[ReadingCoupling]) -> MeasurementSet:
    """The rows of ``data`` with eq C1 applied to their joint readings (``data`` itself unchanged)."""
    if not couplings:
        return data
    return replace(data, q=corrected_angles(data.q, couplings, data.joint_names))
