"""DH tables in and out of URDF joint origins: the DH→URDF adapter and its inverse for DH-shaped chains."""

from __future__ import annotations

import os
from typing import Sequence

import numpy as np

from pincal.errors import ModelError, PincalError
from pincal.model.dh import DHTable
from pincal.model.urdf import load_urdf, write_urdf_with_origins

#: Tolerance [m, -] for an origin to be of the DH shape in :func:`dh_table_from_urdf`.
DH_SHAPE_TOLERANCE = 1e-9


def apply_dh_table(
    source: str | os.PathLike[str],
    destination: str | os.PathLike[str],
    table: DHTable,
    joint_names: Sequence[str],
    flange_joint: str,
    comment: str | None = None,
) -> None:
    """Write a URDF whose chain realises ``table`` (the DH → URDF adapter).

    The N+1 matrices of :meth:`DHTable.joint_origins` become the origins of the N
    revolute joints ``joint_names`` (in chain order) and of the fixed
    ``flange_joint``; everything else is copied from ``source``. With the joint
    values equal to the encoder angles theta_n [rad], the flange link's pose in
    the chain's root link equals ``table.forward(theta)``.

    Raises:
        ModelError: ``len(joint_names) != table.n_joints``, a name is repeated,
            or any condition of :func:`write_urdf_with_origins`.
    """
    names = [str(n) for n in joint_names]
    if len(names) != table.n_joints:
        raise ModelError(
            f"the DH table has {table.n_joints} joints but {len(names)} joint names were given"
        )
    all_names = names + [str(flange_joint)]
    if len(set(all_names)) != len(all_names):
        raise ModelError(f"joint names must be distinct, got {all_names}")
    origins = dict(zip(all_names, table.joint_origins()))
    write_urdf_with_origins(source, destination, origins, comment=comment)


def _nearest_branch(angle: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """``angle`` shifted by multiples of 2*pi to lie nearest ``reference`` [rad]."""
    return angle + 2.0 * np.pi * np.round((reference - angle) / (2.0 * np.pi))


def dh_table_from_urdf(
    urdf_path: str | os.PathLike[str],
    joint_names: Sequence[str],
    flange_joint: str,
    reference: DHTable | None = None,
) -> DHTable:
    """Read back the DH table realised by a URDF written by :func:`apply_dh_table`.

    The origin of the first joint must be ``Rz(eps_1)``; the origin of joint n+1
    ``Tz(d_n) Tx(r_n) Rx(alpha_n) Rz(eps_{n+1})`` and that of the flange joint
    ``Tz(d_N) Tx(r_N) Rx(alpha_N)``. The joints must form a chain (parent of each
    joint = child of the previous one), the revolute joints must turn about +z.

    Args:
        urdf_path: URDF file.
        joint_names: the N revolute joints in chain order.
        flange_joint: the fixed joint carrying the last DH row.
        reference: if given, each angle is shifted by a multiple of 2*pi to lie
            nearest the reference's; otherwise angles are in (-pi, pi].

    Returns:
        The table (rad, m).

    Raises:
        ModelError: a joint is missing, the chain or axis is wrong, or an origin
            is not of the DH shape (tolerance :data:`DH_SHAPE_TOLERANCE`); the
            message names the joint.
    """
    names = [str(n) for n in joint_names]
    if not names:
        raise ModelError("at least one revolute joint name is required")
    if reference is not None and reference.n_joints != len(names):
        raise ModelError(
            f"reference table has {reference.n_joints} joints but {len(names)} joint names were given"
        )
    urdf = load_urdf(urdf_path)
    joint_map = {joint.name: joint for joint in urdf.robot.joints}
    chain = names + [str(flange_joint)]
    missing = [n for n in chain if n not in joint_map]
    if missing:
        raise ModelError(
            f"joint(s) {', '.join(repr(n) for n in missing)} not found in {urdf_path}; "
            f"its joints are: {', '.join(joint_map)}"
        )
    for previous, name in zip(chain, chain[1:]):
        if joint_map[name].parent != joint_map[previous].child:
            raise ModelError(
                f"joint '{name}' does not follow joint '{previous}': its parent link is "
                f"'{joint_map[name].parent}', not '{joint_map[previous].child}'"
            )
    for name in names:
        joint = joint_map[name]
        if joint.type not in ("revolute", "continuous"):
            raise ModelError(f"joint '{name}' is {joint.type}, expected revolute or continuous")
        axis = np.asarray(joint.axis, dtype=float)
        if np.max(np.abs(axis - (0.0, 0.0, 1.0))) > DH_SHAPE_TOLERANCE:
            raise ModelError(f"joint '{name}' turns about {axis.tolist()}, expected the DH axis [0, 0, 1]")
    if joint_map[chain[-1]].type != "fixed":
        raise ModelError(f"flange joint '{chain[-1]}' is {joint_map[chain[-1]].type}, expected fixed")

    origins = {
        n: (np.eye(4) if joint_map[n].origin is None else np.asarray(joint_map[n].origin, dtype=float))
        for n in chain
    }

    try:
        table = DHTable.from_joint_origins(
            [origins[n] for n in chain],
            tol=DH_SHAPE_TOLERANCE,
            names=[f"origin of joint '{n}'" for n in chain],
        )
    except PincalError as exc:
        raise ModelError(f"{exc}; was this URDF written by apply_dh_table?") from None
    if reference is None:
        return table
    vector = table.to_vector()
    angles = slice(0, 2 * table.n_joints)  # alpha and epsilon
    vector[angles] = _nearest_branch(vector[angles], reference.to_vector()[angles])
    return DHTable.from_vector(vector)
