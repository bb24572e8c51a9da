"""Joints that follow another: their angles computed from the driver's column (eq M1).

A URDF ``<mimic joint="D" multiplier="m" offset="o">`` on joint J says J moves with D:

    q_J = m · q_D + o   [rad or m]                                            (M1)

(:class:`pincal.measurements.data.JointMimic`). The measurement file then needs no column for J: its
angle is computed from D's column, D on the chain or off it (another branch's joint the file holds).
A column for J, if present, is checked against eq M1 row by row and the computed value is used, so a
file with a consistent column gives the same numbers as one without. ``--coupling J=C*D`` naming a
joint J the run's calibration data has no column for means the same: J follows D with m = C, o = 0
(:func:`pincal.measurements.couplings.decide_followers`, recorded as ``couplings[].follows``; a joint
with a column is a reading taken against D, eq C1 of :mod:`pincal.measurements.couplings`). The driver
is taken as read, as every driver of eq C1 is.

The check's tolerance is the rounding of the cells themselves: half a unit in the last digit printed
in J's cell, plus |m| times that of D's cell (what eq M1 carries of it), plus a few double-precision
rounding steps (:data:`ROUNDING_STEPS`). A file written at full precision (``repr``, as pincal writes
CSV v1) is so held to ~1e-16 rad; one written with 4 decimals to ~5e-5 rad. A larger difference is a
joint that does not follow its ``<mimic>`` as written, and the message names the row and the column.
"""

from __future__ import annotations

import re
import sys
from collections.abc import Sequence
from typing import Protocol

import numpy as np

from pincal.errors import MeasurementError, PincalError
from pincal.measurements.couplings import ReadingCoupling
from pincal.measurements.data import JointMimic, JointSpec

__all__ = ["ROUNDING_STEPS", "coupling_mimic", "followers", "follower_angles", "last_digit"]

#: Double-precision rounding steps allowed in eq M1 beside the cells' own rounding: one product, one
#: sum and the two decimal-to-binary conversions, each at most half an ulp (IEEE 754).
ROUNDING_STEPS = 4

_NUMBER = re.compile(r"\s*[-+]?(?:\d*)(?:\.(\d*))?(?:[eE]([-+]?\d+))?\s*")


class _Table(Protocol):
    """What is read of a CSV table (:class:`pincal.measurements.csv_v1.CsvTable`)."""

    @property
    def source(self) -> str: ...

    @property
    def names(self) -> tuple[str, ...]: ...

    @property
    def lines(self) -> list[int]: ...

    def cell(self, k: int, name: str) -> str: ...

    def numbers(self, name: str) -> np.ndarray: ...

    def error(self, message: str, line: int | None = None, column: str | None = None,
              joint: str | None = None) -> PincalError: ...


def last_digit(text: str) -> float:
    """The unit of the last digit printed in a number's text: ``"0.125"`` → 0.001, ``"1.5e-3"`` → 1e-4,
    ``"2"`` → 1; 0 for a form this does not read (``"1_000"``, which float() takes: the doubles' rounding only)."""
    match = _NUMBER.fullmatch(text)
    if match is None:
        return 0.0
    return 10.0 ** (int(match[2] or 0) - len(match[1] or ""))


def followers(joints: Sequence[JointSpec], couplings: Sequence[ReadingCoupling]) -> dict[str, JointMimic]:
    """The joints of ``joints`` whose angle comes from eq M1: each with a URDF ``<mimic>`` (or one a run put on
    the chain, :meth:`pincal.model.chain.KinematicChain.follow`), and each a ``--coupling`` the run decided
    ``follows`` (:func:`pincal.measurements.couplings.decide_followers`), of ``joints``: decided once per
    run, never again by a file's columns.

    Raises:
        MeasurementError: a ``--coupling`` on a joint the URDF already makes follow another.
    """
    out = {j.name: j.mimic for j in joints if j.mimic is not None}
    for coupling in couplings:
        mimic = out.get(coupling.joint)
        if mimic is not None and not (coupling.follows and mimic == coupling_mimic(coupling)):
            raise MeasurementError(
                f"--coupling {coupling.label}: joint '{coupling.joint}' follows '{mimic.driver}' by the URDF's "
                f"<mimic> (multiplier {mimic.multiplier:g}, offset {mimic.offset:g}); drop the flag, or the "
                "<mimic> tag to calibrate the joint as read")
        if coupling.follows and any(j.name == coupling.joint for j in joints):
            out[coupling.joint] = coupling_mimic(coupling)
    return out


def coupling_mimic(coupling: ReadingCoupling) -> JointMimic:
    """Eq M1 of a ``--coupling J=C*D`` on a joint without a reading: J follows D with m = C, o = 0."""
    return JointMimic(coupling.driver, coupling.factor, 0.0)


def follower_angles(table: _Table, joints: Sequence[JointSpec], couplings: Sequence[ReadingCoupling] = ()
                    ) -> dict[str, np.ndarray]:
    """Eq M1 for every follower whose driver has a column: its angles (K,) [rad or m] by name.

    A follower with a column of its own and no driver column is read as any joint (not returned).

    Raises:
        MeasurementError: a follower whose column and driver's column both are missing (naming the joint
            and the column to add), a driver that follows another joint itself, or a follower's column
            that differs from eq M1 by more than the cells' rounding (naming the line and column).
    """
    mimics = followers(joints, couplings)
    out: dict[str, np.ndarray] = {}
    for name, mimic in mimics.items():
        if mimic.driver in mimics:
            raise table.error(f"joint '{name}' follows '{mimic.driver}', which follows "
                              f"'{mimics[mimic.driver].driver}' itself; make '{name}' follow "
                              f"'{mimics[mimic.driver].driver}' directly (multiply the multipliers)")
        if mimic.driver not in table.names:
            if name in table.names:
                continue
            raise table.error(f"no column for joint '{name}' nor for '{mimic.driver}', which it follows "
                              f"(q = {mimic.multiplier:g} x {mimic.driver} + {mimic.offset:g}); add a column "
                              f"'{mimic.driver}' (or '{name}')")
        driver = table.numbers(mimic.driver)
        angles = mimic.multiplier * driver + mimic.offset
        if name in table.names:
            _check(table, name, mimic, driver, angles)
        out[name] = angles
    return out


def _check(table: _Table, name: str, mimic: JointMimic, driver: np.ndarray, angles: np.ndarray) -> None:
    """Raise for the first row where ``name``'s column differs from eq M1 beyond the cells' rounding."""
    read = table.numbers(name)
    for k in map(int, np.flatnonzero(np.abs(read - angles) > 0.0)):
        rounding = 0.5 * (last_digit(table.cell(k, name)) + abs(mimic.multiplier) *
                          last_digit(table.cell(k, mimic.driver)))
        rounding += ROUNDING_STEPS * sys.float_info.epsilon * (abs(read[k]) + abs(angles[k]) + abs(mimic.offset))
        if abs(read[k] - angles[k]) > rounding:
            raise table.error(
                f"{read[k]:.9g} is not what its <mimic> gives, {mimic.multiplier:g} x {mimic.driver} "
                f"({driver[k]:.9g}) + {mimic.offset:g} = {angles[k]:.9g}: they differ by "
                f"{abs(read[k] - angles[k]):.3g}, more than the cells' rounding ({rounding:.3g}); drop the "
                f"column (the joint then follows '{mimic.driver}') or correct the URDF's <mimic>",
                table.lines[k], name)
