"""A DH table file made into a URDF file, with its provenance and a check of its kinematics.

What ``pincal urdf-from-dh`` does below the command line: read the table
(:func:`pincal.model.dh.files.read_dh_csv`), write the URDF
(:func:`pincal.model.dh.urdf.urdf_from_dh`) with a comment saying which table
(path and SHA-256), which convention and which options made it, reload it with
Pinocchio and measure how far its forward kinematics is from the DH product at
seeded configurations within the limits.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pincal._version import __version__
from pincal.errors import ModelError
from pincal.model.chain import KinematicChain, xyz_rpy_from_pose
from pincal.model.dh.files import read_dh_csv
from pincal.model.dh.robot import (
    DEFAULT_EFFORT,
    DEFAULT_LIMITS,
    DEFAULT_VELOCITY,
    DHRobot,
)
from pincal.model.dh.urdf import (
    DH_BASE_LINK,
    DH_FLANGE_JOINT,
    DH_FLANGE_LINK,
    urdf_from_dh,
)
from pincal.outputs import file_sha256

__all__ = [
    "CHECK_CONFIGURATIONS", "CHECK_SEED", "FK_TOLERANCE", "DHUrdf", "urdf_from_dh_table", "fk_error", "provenance",
]

#: Seeded configurations at which the written URDF is compared with the DH product.
CHECK_CONFIGURATIONS = 20
#: Seed of those configurations.
CHECK_SEED = 0
#: Largest FK difference accepted between the written URDF and the DH product [m, -]:
#: a thousand times the rounding of a 1 m chain in double precision.
FK_TOLERANCE = 1e-9

_FORMULAS = {
    "standard": "F_n = Rz(theta_n + q_n) Tz(d_n) Tx(a_n) Rx(alpha_n) (distal; row n holds alpha_n, a_n)",
    "modified": "T_i = Rx(alpha_{i-1}) Tx(a_{i-1}) Rz(theta_i + q_i) Tz(d_i) (Craig; row i holds "
                "alpha_{i-1}, a_{i-1})",
}
_CHILD_LINKS = {
    "standard": "link_n (child of joint n) is DH frame n-1 moved by joint n, not DH frame n",
    "modified": "link_n (child of joint n) is DH frame n",
}


@dataclass(frozen=True)
class DHUrdf:
    """Outcome of :func:`urdf_from_dh_table`.

    Attributes:
        robot: the table as read, in rad and m.
        notes: reader notes (defaults used, ignored columns) for the user.
        flange: ``frameN_T_flange`` written (4, 4) [m].
        fk_error: largest difference between Pinocchio's forward kinematics of
            the written URDF (link :data:`~pincal.model.dh.urdf.DH_FLANGE_LINK`)
            and the DH product times ``flange``, over :data:`CHECK_CONFIGURATIONS`
            configurations [m for positions, unitless for rotation-matrix entries].
    """

    robot: DHRobot
    notes: list[str]
    flange: np.ndarray
    fk_error: float


def urdf_from_dh_table(
    table_path: str | os.PathLike[str],
    convention: str,
    out_urdf: str | os.PathLike[str],
    name: str | None = None,
    degrees: bool = False,
    flange: np.ndarray | None = None,
) -> DHUrdf:
    """Read a DH table CSV, write the URDF realising it and check it.

    Args:
        table_path: the DH table (:mod:`pincal.model.dh.files`); only read.
        convention: ``standard`` or ``modified``.
        out_urdf: URDF to write; its folder must exist (the command creates it).
        name: the robot's name (default: the output file's stem).
        degrees: the table's angle columns are in degrees.
        flange: pose (4, 4) [m] of the flange in the last DH frame (identity if None).

    Raises:
        ModelError: a problem with the table (file, line, joint and column named).
    """
    table_path, out_urdf = Path(table_path), Path(out_urdf)
    robot, notes = read_dh_csv(table_path, convention, degrees=degrees)
    flange_T = np.eye(4) if flange is None else np.asarray(flange, dtype=float)
    name = name or out_urdf.stem
    digest = file_sha256(table_path)
    comment = provenance(robot, table_path, digest, out_urdf, name, degrees, flange)
    checked: list[float] = []

    def verify(written: Path) -> None:  # before the file replaces out_urdf
        checked.append(fk_error(robot, written, flange_T))
        if checked[-1] > FK_TOLERANCE:
            raise ModelError(f"{out_urdf}: the URDF differs from the DH product by {checked[-1]:.3g} "
                             f"(> {FK_TOLERANCE:g}); not written; please report this as a bug")

    urdf_from_dh(robot, out_urdf, name=name, flange=None if flange is None else flange_T, comment=comment,
                 verify=verify)
    return DHUrdf(robot, notes, flange_T, checked[-1])


def fk_error(robot: DHRobot, urdf_path: str | os.PathLike[str], flange: np.ndarray) -> float:
    """Largest |Pinocchio FK of ``urdf_path`` − DH product · ``flange``| over
    :data:`CHECK_CONFIGURATIONS` seeded configurations drawn uniformly within the limits."""
    chain = KinematicChain.from_urdf(urdf_path, DH_FLANGE_LINK)
    rng = np.random.default_rng(CHECK_SEED)
    q = rng.uniform(robot.lower, robot.upper, (CHECK_CONFIGURATIONS, robot.n_joints))
    poses = chain.poses(q)
    worst = 0.0
    for k in range(len(q)):
        expected = robot.forward(q[k]) @ flange
        worst = max(worst, float(np.abs(poses.tool_positions[k] - expected[:3, 3]).max()),
                    float(np.abs(poses.tool_rotations[k] - expected[:3, :3]).max()))
    return worst


def provenance(robot: DHRobot, table_path: Path, digest: str, out_urdf: Path, name: str, degrees: bool,
               flange: np.ndarray | None) -> str:
    """The comment written at the top of the URDF: table, convention, options, layout, defaults.

    ``flange`` is the flange's pose (4, 4) [m] in the last DH frame, written as xyz [m] and URDF rpy [rad].
    """
    options = [f"convention {robot.convention}", f"out {out_urdf}", f"name {name}"]
    if degrees:
        options.append("degrees")
    xyz_rpy = None if flange is None else [float(v) for v in np.concatenate(xyz_rpy_from_pose(flange))]
    if xyz_rpy is not None:
        options.append("flange " + ",".join(repr(v) for v in xyz_rpy))
    columns = ("alpha", "a", "theta", "d", "lower", "upper")
    header = f"    {'joint':<12s} {'type':<9s} " + " ".join(f"{c:>13s}" for c in columns)
    rows = "\n".join(
        f"    {robot.names[n]:<12s} {robot.types[n]:<9s} "
        + " ".join(f"{'none':>13s}" if c in ("lower", "upper") and robot.types[n] == "continuous"
                   else f"{float(getattr(robot, c)[n]):>13.10g}" for c in columns)
        for n in range(robot.n_joints)
    )
    flange_text = "" if xyz_rpy is None else (
        f" times the flange transform xyz = {xyz_rpy[:3]} m, rpy = {xyz_rpy[3:]} rad")
    rev, pri = DEFAULT_LIMITS["revolute"], DEFAULT_LIMITS["prismatic"]
    return f"""
  Generated by pincal {__version__} from the DH table {table_path} (sha256 {digest})
  with: pincal urdf-from-dh {table_path}, options {'; '.join(options)}
  (the options are written without their leading dashes, which XML comments cannot hold).

  DH convention {robot.convention}: {_FORMULAS[robot.convention]};
  for a prismatic joint q adds to d instead. The value of each joint is its q.
  Table as read (rad, m; theta and d are the constant parts):
{header}
{rows}
  Links: {DH_BASE_LINK} is DH frame 0; {_CHILD_LINKS[robot.convention]};
  {DH_FLANGE_LINK} (fixed joint {DH_FLANGE_JOINT}) is DH frame {robot.n_joints}{flange_text}:
  the tip link to calibrate.
  Limits from the table; where it gives none: [{rev[0]:.6g}, {rev[1]:.6g}] rad (revolute),
  [{pri[0]:g}, {pri[1]:g}] m (prismatic), none for a continuous joint; velocity {DEFAULT_VELOCITY:g} rad/s (m/s) \
and effort
  {DEFAULT_EFFORT:g} N m (N) are placeholders where absent. No inertials.
"""
