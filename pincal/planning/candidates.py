"""Candidate configurations: drawn within the URDF's joint limits, or read from a file, and the range
of each joint they span (what ``pincal plan`` says it sampled).

A candidate file is CSV with a header and one row per configuration; the joint
columns are named as in CSV v1 (the URDF joint names; rad, m for prismatic
joints); any other column is ignored, so a measurement file serves as is.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal, TypedDict

import numpy as np

from pincal.errors import MeasurementError, PincalError
from pincal.measurements.csv_v1 import read_joint_columns
from pincal.model.chain import KinematicChain
from pincal.model.tree import KinematicTree
from pincal.planning.defaults import DEFAULT_SAMPLE, WORKSPACE_SIZE
from pincal.simulation.sensor import random_configurations, sampling_limits

__all__ = [
    "LIMIT_SLACK", "DEFAULT_SAMPLE", "WORKSPACE_SIZE", "sample_candidates", "read_candidates", "check_within_limits",
    "RangeSource", "JointRangeJson", "JointRange", "joint_ranges",
]

#: Readings this far outside a limit are accepted as on it [rad or m]: a joint driven to its
#: stop reads slightly beyond it (TIAGo's torso reads 0.35018 m at its 0.35 m limit in
#: data/tiago_mocap), so 1 mrad / 1 mm, the sessions' own joint-reading tolerance.
LIMIT_SLACK = 1e-3
# DEFAULT_SAMPLE, WORKSPACE_SIZE: pincal.planning.defaults (the parser reads them)


def sample_candidates(chain: KinematicChain | KinematicTree, count: int, seed: int) -> np.ndarray:
    """``count`` configurations uniform within the joint limits (±π for continuous joints), (count, N)."""
    if count < 1:
        raise PincalError(f"--sample {count}: draw at least one configuration")
    return random_configurations(chain, np.random.default_rng(seed), count)


def read_candidates(path: str | Path, chain: KinematicChain | KinematicTree) -> tuple[np.ndarray, np.ndarray]:
    """Joint readings of a candidate file (:func:`pincal.measurements.csv_v1.read_joint_columns`).

    Returns:
        q (K, N) [rad or m] in the chain's joint order, and each row's line in the file (K,).

    Raises:
        MeasurementError: unreadable or ragged file, missing joint column, a cell
            that is not a finite number, a value in degrees or millimetres, or a
            value outside the joint's limits — naming the file, line and column.
    """
    q, lines = read_joint_columns(path, chain.joint_specs, chain.other_branch_joints)
    check_within_limits(q, chain, str(path), lines)
    return q, lines


def check_within_limits(q: np.ndarray, chain: KinematicChain | KinematicTree, source: str, lines: np.ndarray) -> None:
    """Reject readings outside the joint limits (beyond :data:`LIMIT_SLACK`), naming the first one."""
    for n, joint in enumerate(chain.joints):
        unit = "m" if joint.kind == "prismatic" else "rad"
        values = q[:, n]
        outside = np.flatnonzero((values < joint.lower - LIMIT_SLACK) | (values > joint.upper + LIMIT_SLACK))
        if outside.size:
            k = outside[0]
            raise MeasurementError(
                f"{source}: line {lines[k]}, column '{joint.name}': {values[k]:.6g} {unit} is outside the "
                f"joint limits [{joint.lower:.6g}, {joint.upper:.6g}] {unit} ({outside.size} row(s)); "
                "remove or correct those rows"
            )


#: Where a joint's range comes from: the URDF's ``<limit>``, one turn for a continuous joint (no limit to
#: read), what its driver's range gives a joint that follows another (URDF ``<mimic>``, within its own
#: limits: :func:`pincal.simulation.sensor.sampling_limits`), or the candidates of a file (their span).
RangeSource = Literal["URDF limits", "continuous: one turn", "follows its driver", "candidate file"]


class JointRangeJson(TypedDict):
    """A joint's range of the candidates (PLAN.json ``candidates.joint_ranges``), in the joint's unit."""

    joint: str
    kind: str
    unit: str
    lower: float
    upper: float
    source: RangeSource


@dataclass(frozen=True)
class JointRange:
    """The range one joint's candidates were drawn from (or span, read from a file).

    Attributes:
        joint / kind: the joint and its kind (revolute, continuous, prismatic).
        lower / upper: the range [deg, mm for a prismatic joint].
        source: where it comes from (:data:`RangeSource`).
    """

    joint: str
    kind: str
    lower: float
    upper: float
    source: RangeSource

    @property
    def unit(self) -> str:
        return "mm" if self.kind == "prismatic" else "deg"

    def as_dict(self) -> JointRangeJson:
        return {"joint": self.joint, "kind": self.kind, "unit": self.unit, "lower": self.lower, "upper": self.upper,
                "source": self.source}


def joint_ranges(chain: KinematicChain | KinematicTree, read: np.ndarray | None = None) -> tuple[JointRange, ...]:
    """Each joint's range of the candidates: drawn (``read`` None) within :func:`pincal.simulation.sensor.
    sampling_limits` (the URDF's limits, one turn for a continuous joint), else the span of the ``read``
    candidates (K, N) [rad or m]; in deg (mm for a prismatic joint)."""
    if read is None:
        lower, upper = sampling_limits(chain)
    else:
        lower, upper = np.min(read, axis=0), np.max(read, axis=0)
    out = []
    for n, joint in enumerate(chain.joints):
        scale = 1000.0 if joint.kind == "prismatic" else 180.0 / np.pi
        follows = joint.mimic is not None and joint.mimic.driver in chain.joint_names
        source: RangeSource = ("candidate file" if read is not None else "follows its driver" if follows
                               else "continuous: one turn" if joint.kind == "continuous" else "URDF limits")
        out.append(JointRange(joint.name, joint.kind, float(lower[n] * scale), float(upper[n] * scale), source))
    return tuple(out)
