"""The types of the ``pincal`` command line's values (argparse ``type=`` callables): each checks its text
and refuses it in one argparse line, so a bad number never reaches a command.

No numpy, scipy or Pinocchio at import (``--help`` and refusals in 0.06 s; tests/test_cli_start.py): a type
returning a library value imports it for a valid one."""

from __future__ import annotations

import argparse
import math
import re
from pathlib import Path
from typing import TYPE_CHECKING, cast

from pincal.errors import PincalError
from pincal.fit.prior_defaults import SCALE_RANGE
from pincal.model.dh.conventions import MAX_ANGLE_RAD

if TYPE_CHECKING:
    import numpy as np

    from pincal.fit.prior import Prior
    from pincal.fit.selection import SelectionCriterion
    from pincal.planning.information import SensorModel

__all__ = [
    "TipLinks", "tool_pose", "prior_scale", "selection_criterion", "package_dir", "measure", "target_points",
    "xacro_arg", "coupling_arg", "joint_names", "number", "non_negative", "count_or_zero", "count", "seconds",
    "positive",
]


class TipLinks(argparse.Action):
    """``--tip-link``, repeatable: one value stays the string it is (one chain, as ever); a second makes the
    values a list, the targets ``LINK:POINTS`` of one calibration (:func:`pincal.model.tree.parse_targets`)."""

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: object,
                 option_string: str | None = None) -> None:
        current = getattr(namespace, self.dest, None)
        if current is None:
            setattr(namespace, self.dest, values)
        else:
            setattr(namespace, self.dest, [*([current] if isinstance(current, str) else current), values])


def tool_pose(text: str) -> np.ndarray:
    """argparse type of ``--tool`` and ``--flange``: ``X,Y,Z,ROLL,PITCH,YAW`` (metres, then URDF
    roll-pitch-yaw [rad]) as a 4x4 pose; angles beyond one turn are refused as degrees given as radians."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != 6 or not all(map(math.isfinite, values)):
        raise argparse.ArgumentTypeError(
            f"'{text}' is not X,Y,Z,ROLL,PITCH,YAW (six numbers: metres, then radians)"
        )
    if max(abs(v) for v in values[3:]) > MAX_ANGLE_RAD:
        raise argparse.ArgumentTypeError(
            f"'{text}': roll/pitch/yaw beyond one turn look like degrees; give radians"
        )
    from pincal.model.chain import pose_from_xyz_rpy  # Pinocchio: a valid --tool, the command runs

    return pose_from_xyz_rpy(values[:3], values[3:])


def prior_scale(text: str) -> tuple[float, ...]:
    """argparse type of ``--prior-scale``: ``MM,DEG[,DEG]``, the prior std of placement translations [mm],
    rotations [deg] and revolute joint zeros [deg] (two or three numbers within
    :data:`pincal.fit.prior.SCALE_RANGE`; with two, joint zeros take the rotations')."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    low, high = SCALE_RANGE
    if len(values) not in (2, 3) or not all(math.isfinite(v) and low <= v <= high for v in values):
        raise argparse.ArgumentTypeError(
            f"'{text}' is not MM,DEG[,DEG] (two or three numbers from {low:g} to {high:g}: the prior std of "
            "translations in mm, of rotations in degrees, and of revolute joint zeros in degrees)")
    return tuple(values)


def selection_criterion(args: argparse.Namespace) -> SelectionCriterion | Prior:
    """``--select`` as the fits take it: with ``prior``, a :class:`pincal.fit.prior.Prior` of ``--prior-scale``.

    Raises:
        PincalError: ``--prior-scale`` without ``--select prior``; ``--select prior`` or
            ``--prior-scale`` with ``--level registration`` or ``dh`` (``--method``), which fit no
            kinematic parameter a prior could hold (refused rather than silently ignored).
    """
    scale = getattr(args, "prior_scale", None)
    select = args.select
    level = getattr(args, "level", None) or ("dh" if getattr(args, "method", None) is not None else None)
    if level in ("registration", "dh") and (select == "prior" or scale is not None):
        from pincal.workflows.settings import no_prior

        raise no_prior("--select prior" if select == "prior" else "--prior-scale", level)
    if select is None:  # the default: the prior wherever kinematic parameters are fitted (docs/defaults.md)
        from pincal.workflows.settings import default_selection

        select = str(default_selection(level))
    if select != "prior":
        if scale is not None:
            raise PincalError(f"--prior-scale applies to --select prior only (got --select {select})")
        return cast("SelectionCriterion", select)  # one of --select's choices, or the default
    from pincal.fit.prior import Prior

    return Prior(*scale) if scale is not None else Prior()


def package_dir(text: str) -> tuple[str, Path]:
    """argparse type of ``--package-dir``: ``NAME=DIR``, DIR an existing folder (the package itself)."""
    name, sep, folder = text.partition("=")
    if not sep or not name or not folder:
        raise argparse.ArgumentTypeError(f"'{text}' is not NAME=DIR (a ROS package's name and its folder)")
    if not Path(folder).is_dir():
        raise argparse.ArgumentTypeError(f"'{folder}' is not a folder (--package-dir {name}=DIR)")
    return name, Path(folder)


def measure(text: str) -> SensorModel:
    """argparse type of ``--measure``: ``point``, ``points:M`` (M >= 2) or ``pose``."""
    match = re.fullmatch(r"points:([0-9]+)", text)
    if text not in ("point", "pose") and not (match and int(match[1]) >= 2):
        raise argparse.ArgumentTypeError(
            f"'{text}': use point, points:M (M >= 2 points of one rigid target) or pose"
        )
    from pincal.planning.information import SensorModel  # the planner's modules: a valid --measure

    return SensorModel("points", int(match[1])) if match else SensorModel("pose" if text == "pose" else "point", 1)


def target_points(text: str) -> np.ndarray:
    """argparse type of ``--target-points``: ``X,Y,Z[;X,Y,Z...]`` [m] as (P, 3)."""
    try:
        points = [[float(v) for v in point.split(",")] for point in text.split(";")]
    except ValueError:
        points = []
    if not points or any(len(point) != 3 or not all(map(math.isfinite, point)) for point in points):
        raise argparse.ArgumentTypeError(f"'{text}': give X,Y,Z[;X,Y,Z...] in metres, in the tip link")
    import numpy as np

    return np.array(points)


def xacro_arg(text: str) -> tuple[str, str]:
    """argparse type of ``--xacro-arg``: ``NAME:=VALUE`` as ``(NAME, VALUE)``."""
    from pincal.model.description import parse_xacro_arg  # lxml

    try:
        return parse_xacro_arg(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def coupling_arg(text: str):
    """argparse type of ``--coupling``: ``JOINT=FACTOR*DRIVER`` (:mod:`pincal.measurements.couplings`)."""
    from pincal.measurements.couplings import parse_coupling

    try:
        return parse_coupling(text)
    except PincalError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix(f"--coupling '{text}': ")) from None


def joint_names(text: str) -> tuple[str, ...]:
    """argparse type of ``--alternate``: ``JOINT[,JOINT...]``, at least one name."""
    names = tuple(name.strip() for name in text.split(",") if name.strip())
    if not names:
        raise argparse.ArgumentTypeError(f"'{text}': give JOINT[,JOINT...]")
    return names


def number(kind: type, minimum: float, what: str):
    """argparse type: a finite ``kind`` (float or int) >= ``minimum``; ``what`` names it in errors."""

    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"'{text}' is not {what}") from None
        if not ((kind is int or math.isfinite(value)) and value >= minimum):  # an int is finite
            raise argparse.ArgumentTypeError(f"'{text}' must be >= {minimum:g} (a finite {what})")
        return value

    return parse


#: argparse types of a number >= 0, an integer >= 0 and an integer >= 1.
non_negative = number(float, 0.0, "number")
count_or_zero = number(int, 0, "integer")
count = number(int, 1, "integer")


def seconds(text: str) -> float:
    """argparse type of ``--clock-offset``: a finite number of seconds, of either sign."""
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"'{text}' is not a finite number of seconds")
    return value


def positive(text: str) -> float:
    value = non_negative(text)
    if value == 0:
        raise argparse.ArgumentTypeError(f"'{text}' must be > 0")
    return value
