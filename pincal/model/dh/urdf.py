"""DH tables in and out of URDF joint origins: the DH→URDF adapter and its inverse for DH-shaped chains.

Two writers share one path: :func:`apply_dh_table` (the paper's distal table into
an existing URDF, used by ``scripts/generate_kuka_urdf.py``) and
:func:`urdf_from_dh` (a whole URDF from a :class:`~pincal.model.dh.robot.DHRobot`
of either convention, behind ``pincal urdf-from-dh``). Both take their joint
origins from :func:`pincal.model.dh.table.dh_chain_origins` (one closed-form DH row →
joint origin, :func:`pincal.model.dh.table.dh_origin_rows`) and write them with
:func:`pincal.model.urdf.write_urdf_with_origins` through :func:`_write_chain_origins`.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from pincal.errors import ModelError, PincalError
from pincal.model.dh.robot import DEFAULT_LIMITS, DH_JOINT_TYPES, DHRobot
from pincal.model.dh.table import DHTable, dh_chain_from_origins
from pincal.model.urdf import load_urdf, write_urdf_with_origins

if TYPE_CHECKING:
    import yourdfpy

__all__ = [
    "DH_BASE_LINK", "DH_FLANGE_LINK", "DH_FLANGE_JOINT", "dh_link_name", "DH_SHAPE_TOLERANCE", "apply_dh_table",
    "urdf_from_dh", "dh_table_from_urdf", "dh_robot_from_urdf",
]

#: Root link of a URDF written by :func:`urdf_from_dh`: DH frame 0.
DH_BASE_LINK = "base_link"
#: Tip link of a URDF written by :func:`urdf_from_dh`: the last DH frame (times
#: the flange transform, if one is given); the natural ``--tip-link``.
DH_FLANGE_LINK = "flange"
#: The fixed joint carrying :data:`DH_FLANGE_LINK`.
DH_FLANGE_JOINT = "flange_joint"


def dh_link_name(n: int) -> str:
    """Child link of the ``n``-th joint (1-based) in a URDF written by :func:`urdf_from_dh`."""
    return f"link_{n}"


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
    _write_chain_origins(source, destination, table.joint_origins(), joint_names, flange_joint, comment)


def _write_chain_origins(
    source: str | os.PathLike[str],
    destination: str | os.PathLike[str],
    origins: Sequence[np.ndarray],
    joint_names: Sequence[str],
    flange_joint: str,
    comment: str | None,
    verify: Callable[[Path], None] | None = None,
) -> None:
    """Copy ``source`` to ``destination`` with the N + 1 chain ``origins`` written
    into the joints ``joint_names`` and ``flange_joint``."""
    names = [str(n) for n in joint_names]
    if len(names) != len(origins) - 1:
        raise ModelError(
            f"the DH table has {len(origins) - 1} joints but {len(names)} joint names were given"
        )
    all_names = names + [str(flange_joint)]
    if len(set(all_names)) != len(all_names):
        raise ModelError(f"joint names must be distinct, got {all_names}")
    write_urdf_with_origins(source, destination, dict(zip(all_names, origins)), comment=comment, verify=verify)


def urdf_from_dh(
    robot: DHRobot,
    destination: str | os.PathLike[str],
    name: str = "robot",
    flange: npt.ArrayLike | None = None,
    comment: str | None = None,
    verify: Callable[[Path], None] | None = None,
) -> None:
    """Write a URDF realising ``robot``'s DH table.

    Links: :data:`DH_BASE_LINK` (DH frame 0, the root), ``link_1`` … ``link_N``
    (the child of joint n, see :func:`pincal.model.dh.table.dh_chain_origins`: DH
    frame n in the modified convention, DH frame n-1 moved by joint n in the
    standard one), and :data:`DH_FLANGE_LINK` on the fixed joint
    :data:`DH_FLANGE_JOINT`: the last DH frame times ``flange``. Joints are named
    and limited as in ``robot``, turn or slide about their z axis, and their value
    is the DH ``q`` (the table's theta or d is the constant part). No inertials.

    Args:
        robot: the DH table.
        destination: URDF file to write; its folder must exist.
        name: the ``<robot name>``.
        flange: constant ``frameN_T_flange`` (4x4) [m]; identity if None.
        comment: provenance text written as an XML comment before ``<robot>``.
        verify: checks the complete file before it replaces ``destination``.

    Raises:
        ModelError: a joint is named like the flange joint, or the file cannot be written.
    """
    import yourdfpy  # the template's object model; imported here, not on the calibrate path

    if DH_FLANGE_JOINT in robot.names:
        raise ModelError(f"joint name '{DH_FLANGE_JOINT}' is reserved for the flange joint; rename the joint")
    links = [yourdfpy.Link(name=DH_BASE_LINK)]
    links += [yourdfpy.Link(name=dh_link_name(n)) for n in range(1, robot.n_joints + 1)]
    links.append(yourdfpy.Link(name=DH_FLANGE_LINK))
    joints = []
    for n, joint in enumerate(robot.names):
        joints.append(
            yourdfpy.Joint(
                name=joint,
                type=robot.types[n],
                parent=DH_BASE_LINK if n == 0 else dh_link_name(n),
                child=dh_link_name(n + 1),
                origin=np.eye(4),
                axis=np.array([0.0, 0.0, 1.0]),
                limit=yourdfpy.Limit(
                    effort=float(robot.effort[n]),
                    velocity=float(robot.velocity[n]),
                    lower=None if robot.types[n] == "continuous" else float(robot.lower[n]),
                    upper=None if robot.types[n] == "continuous" else float(robot.upper[n]),
                ),
            )
        )
    joints.append(
        yourdfpy.Joint(name=DH_FLANGE_JOINT, type="fixed", parent=dh_link_name(robot.n_joints),
                       child=DH_FLANGE_LINK, origin=np.eye(4))
    )
    template = yourdfpy.URDF(robot=yourdfpy.Robot(name=str(name), links=links, joints=joints),
                             build_scene_graph=False, load_meshes=False)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "template.urdf"
        template.write_xml().write(str(path), xml_declaration=True, encoding="utf-8", pretty_print=True)
        _write_chain_origins(path, destination, robot.joint_origins(flange), robot.names,
                             DH_FLANGE_JOINT, comment, verify)


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


def dh_robot_from_urdf(
    urdf_path: str | os.PathLike[str],
    convention: str,
    flange: npt.ArrayLike | None = None,
    tol: float = DH_SHAPE_TOLERANCE,
) -> DHRobot:
    """Read back the DH table of a URDF written by :func:`urdf_from_dh` (the inverse).

    The chain is the joints from :data:`DH_BASE_LINK` to :data:`DH_FLANGE_LINK`;
    names, types and limits come from the joints, the DH parameters from their
    origins (angles in (-pi, pi]).

    Args:
        urdf_path: URDF file.
        convention: the convention it was written with.
        flange: the flange transform it was written with (identity if None).
        tol: largest deviation of an origin from the DH shape [m, -].

    Raises:
        ModelError: a link is missing, a joint is neither revolute nor prismatic
            about +z, or an origin is not of the convention's shape; the message
            names the joint.
    """
    urdf = load_urdf(urdf_path)
    by_child = {joint.child: joint for joint in urdf.robot.joints}
    chain: list[yourdfpy.Joint] = []  # flange first
    link = DH_FLANGE_LINK
    while link != DH_BASE_LINK:
        if link not in by_child:
            raise ModelError(f"{urdf_path}: no chain from '{DH_BASE_LINK}' to '{DH_FLANGE_LINK}' "
                             f"(link '{link}' has no parent joint); was it written by urdf_from_dh?")
        chain.insert(0, by_child[link])
        link = by_child[link].parent
    *joints, flange_joint = chain
    if not joints or flange_joint.type != "fixed":
        raise ModelError(f"{urdf_path}: expected joints then the fixed joint '{DH_FLANGE_JOINT}' "
                         f"before '{DH_FLANGE_LINK}'")
    for joint in joints:
        axis = np.asarray(joint.axis if joint.axis is not None else (1.0, 0.0, 0.0), dtype=float)
        if joint.type not in DH_JOINT_TYPES or np.abs(axis - (0.0, 0.0, 1.0)).max() > tol:
            raise ModelError(f"{urdf_path}: joint '{joint.name}' is {joint.type} about {axis.tolist()}; "
                             "a DH joint is revolute, prismatic or continuous about [0, 0, 1]")
    origins = [np.eye(4) if j.origin is None else np.asarray(j.origin, dtype=float) for j in chain]
    if flange is not None:
        origins[-1] = origins[-1] @ np.linalg.inv(np.asarray(flange, dtype=float))
    try:
        alpha, a, theta, d = dh_chain_from_origins(
            convention, origins, tol=tol, names=[f"{urdf_path}: origin of joint '{j.name}'" for j in chain])
    except PincalError as exc:
        raise ModelError(str(exc)) from None
    limits = [j.limit for j in joints]
    for joint, lim in zip(joints, limits):
        needed = (lim.velocity, lim.effort) if lim is not None and joint.type == "continuous" else (
            None if lim is None else (lim.lower, lim.upper, lim.velocity, lim.effort))
        if needed is None or None in needed:
            raise ModelError(f"{urdf_path}: joint '{joint.name}' has no complete <limit>; "
                             "was it written by urdf_from_dh?")
    continuous = DEFAULT_LIMITS["continuous"]  # a continuous joint's range where it is checked, never written
    limits = [replace(lim, lower=continuous[0], upper=continuous[1]) if joint.type == "continuous" else lim
              for joint, lim in zip(joints, limits)]
    return DHRobot(
        convention=convention, names=tuple(j.name for j in joints), alpha=alpha, a=a, theta=theta, d=d,
        types=tuple(j.type for j in joints),
        lower=[lim.lower for lim in limits], upper=[lim.upper for lim in limits],
        velocity=[lim.velocity for lim in limits], effort=[lim.effort for lim in limits],
    )
