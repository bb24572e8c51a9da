"""Reading and writing URDF joint origins, everything else preserved.

lxml reads and writes: the file is written in the form yourdfpy 0.0.60 gave it
(:func:`pincal.model.urdf_elements.render`: links, then joints, then materials,
numbers in their shortest round-trip form), which pincal wrote through yourdfpy
until it stopped importing it on the calibrate path; the bytes are the same.
Three steps on that tree make the result faithful:

* **Origins at full precision.** The replaced origins are written with
  :func:`format_floats` (shortest round-trip ``repr``, i.e. all 17 significant
  digits when needed) from a gimbal-safe RPY extraction (:func:`rpy_from_matrix`),
  so that reading them back reproduces the matrix to about 1e-15. Every origin
  that was *not* replaced (other joints, inertials, visuals, collisions) keeps
  its original attribute text verbatim.
* **What the form drops is put back.** yourdfpy 0.0.60 parses only ``<link>``,
  ``<joint>`` and ``<material>`` under ``<robot>`` (so ``<transmission>``,
  ``<gazebo>``, ``<ros2_control>`` ... are lost), its writer omits a joint's
  ``<mimic>``, ``<calibration>`` and ``<safety_controller>``, and it keeps only the
  attributes it models (e.g. panda's ``<dynamics D=.. K=.. mu_coulomb=..>`` lose
  all but ``damping``/``friction``; ``<geometry name=..>`` loses its name). The
  output tree is therefore merged with the source: for every element yourdfpy
  writes (links and joints matched by name, their children by tag and position),
  attributes it omitted are copied back, and children it does not model are
  deep-copied back; top-level extras are appended after the materials in their
  original order. Attributes of ``<robot>`` other than ``name`` are restored too.
* **What the form adds is removed.** yourdfpy writes ``<axis xyz="1 0 0"/>`` for a
  joint that had no ``<axis>`` (the URDF default); it is removed again.

What is *not* preserved: XML comments (yourdfpy stripped them), the interleaving of
links/joints/extras (yourdfpy writes all links, then all joints, then materials;
URDF semantics do not depend on order), unused namespace declarations such as
``xmlns:xacro``, and the textual form of numbers outside origins (e.g. ``1e3``
becomes ``1000.0``; the values are identical).

Units: lengths in metres, angles in radians, 4x4 homogeneous matrices
``parent_T_child`` as in the URDF ``<origin>`` element.
"""

from __future__ import annotations

import copy
import io
import os
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
from lxml import etree

from pincal.errors import ModelError
from pincal.model.description import RobotDescription, read_description
from pincal.model.urdf_elements import joint_origins, render
from pincal.outputs import replacing

if TYPE_CHECKING:
    import yourdfpy

__all__ = [
    "RIGID_TOLERANCE", "format_floats", "rpy_matrix", "rpy_from_matrix", "origin_attributes", "check_rigid_transform",
    "XacroArgs", "load_urdf", "read_joint_origins", "same_file", "write_urdf_with_origins",
]

#: Tolerance [-] on ``R^T R - I`` and on the homogeneous row for an origin to be a
#: proper rigid transform.
RIGID_TOLERANCE = 1e-9


# What yourdfpy models (and writes back) under each element; any other child found
# in the source is copied back verbatim, and so is any attribute yourdfpy omits.
_MODELLED_CHILDREN: dict[str, frozenset[str]] = {
    "robot": frozenset({"link", "joint", "material"}),
    "joint": frozenset({"parent", "child", "origin", "axis", "limit", "dynamics"}),
    "link": frozenset({"inertial", "visual", "collision"}),
    "inertial": frozenset({"origin", "mass", "inertia"}),
    "visual": frozenset({"origin", "geometry", "material"}),
    "collision": frozenset({"origin", "geometry"}),
    "geometry": frozenset({"box", "cylinder", "sphere", "mesh"}),
    "material": frozenset({"color", "texture"}),
}
# Top-level elements matched by name rather than by position.
_NAMED_TOP_LEVEL = ("link", "joint")


# --------------------------------------------------------------------------- numbers


def format_floats(values: npt.ArrayLike) -> str:
    """Space-separated shortest round-trip representation of ``values``.

    ``repr(float)`` gives the shortest string that parses back to the same double
    (at most 17 significant digits), so no precision is lost. ``-0.0`` is written
    as ``0.0``.
    """
    return " ".join(repr(float(v) + 0.0) for v in np.asarray(values, dtype=float).ravel())


def rpy_matrix(rpy: npt.ArrayLike) -> np.ndarray:
    """URDF rotation ``Rz(yaw) · Ry(pitch) · Rx(roll)`` for ``rpy = (roll, pitch, yaw)`` [rad]."""
    r, p, y = (float(v) for v in np.asarray(rpy, dtype=float).ravel())
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def _wrap(angle: float) -> float:
    """Angle [rad] wrapped into (-pi, pi]."""
    wrapped = float(np.arctan2(np.sin(angle), np.cos(angle)))
    return np.pi if wrapped == -np.pi else wrapped


def rpy_from_matrix(rotation: npt.ArrayLike) -> np.ndarray:
    """URDF ``(roll, pitch, yaw)`` [rad] of a rotation matrix, accurate near gimbal lock.

    The closed-form extraction is ill-conditioned when ``cos(pitch)`` is small
    (only ``roll ± yaw`` is then well determined); the initial guess uses that
    combination and two to four Gauss–Newton steps on the body-frame rotation
    error bring ``rpy_matrix(rpy)`` to within a few ulp of ``rotation``.

    Args:
        rotation: 3x3 rotation matrix (the top-left block of a 4x4 is accepted).

    Returns:
        ``(roll, pitch, yaw)`` with pitch in [-pi/2, pi/2] and roll, yaw in (-pi, pi].
    """
    R = np.asarray(rotation, dtype=float)[:3, :3]
    h = float(np.hypot(R[0, 0], R[1, 0]))
    pitch = float(np.arctan2(-R[2, 0], h))
    # At (numerically) exact gimbal lock only roll -/+ yaw matters: put it all in roll.
    yaw = float(np.arctan2(R[1, 0], R[0, 0])) if h > 4e-16 else 0.0
    if h > 1e-3:
        roll = float(np.arctan2(R[2, 1], R[2, 2]))
    elif R[2, 0] < 0.0:  # pitch ~ +pi/2: R01 = sin(roll - yaw), R11 = cos(roll - yaw)
        roll = yaw + float(np.arctan2(R[0, 1], R[1, 1]))
    else:  # pitch ~ -pi/2: R01 = -sin(roll + yaw), R11 = cos(roll + yaw)
        roll = float(np.arctan2(-R[0, 1], R[1, 1])) - yaw
    rpy = np.array([_wrap(roll), pitch, _wrap(yaw)])
    for _ in range(4):
        err = rpy_matrix(rpy).T @ R
        omega = 0.5 * np.array(
            [err[2, 1] - err[1, 2], err[0, 2] - err[2, 0], err[1, 0] - err[0, 1]]
        )
        if np.max(np.abs(omega)) < 1e-17:
            break
        r, p = rpy[0], rpy[1]
        # Body-frame angular velocity per unit (roll, pitch, yaw) rate.
        jac = np.array(
            [
                [1.0, 0.0, -np.sin(p)],
                [0.0, np.cos(r), np.cos(p) * np.sin(r)],
                [0.0, -np.sin(r), np.cos(p) * np.cos(r)],
            ]
        )
        rpy = rpy + np.linalg.lstsq(jac, omega, rcond=1e-10)[0]
    rpy = np.array([_wrap(rpy[0]), rpy[1], _wrap(rpy[2])])
    # Angles of order 1e-17 are refinement noise: zero them when that costs nothing.
    tidy = np.where(np.abs(rpy) < 1e-15, 0.0, rpy)
    if np.max(np.abs(rpy_matrix(tidy) - R)) <= np.max(np.abs(rpy_matrix(rpy) - R)) + 1e-16:
        rpy = tidy
    return rpy + 0.0


def origin_attributes(matrix: npt.ArrayLike) -> dict[str, str]:
    """``{"xyz": ..., "rpy": ...}`` attribute strings of a 4x4 origin at full precision."""
    T = np.asarray(matrix, dtype=float)
    return {"xyz": format_floats(T[:3, 3]), "rpy": format_floats(rpy_from_matrix(T[:3, :3]))}


def check_rigid_transform(matrix: npt.ArrayLike, what: str) -> np.ndarray:
    """Return ``matrix`` as a float (4, 4) array or raise :class:`ModelError`.

    A proper rigid transform is finite, has the homogeneous last row
    ``[0, 0, 0, 1]`` and a rotation block with ``R^T R = I`` and ``det R = +1``
    (both to :data:`RIGID_TOLERANCE`).

    Args:
        matrix: candidate homogeneous transform.
        what: name used in the error message (e.g. ``"origin of joint 'j1'"``).
    """
    try:
        T = np.array(matrix, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ModelError(f"{what} is not a numeric 4x4 matrix: {exc}") from None
    if T.shape != (4, 4):
        raise ModelError(f"{what} must be a 4x4 homogeneous matrix, got shape {T.shape}")
    if not np.all(np.isfinite(T)):
        raise ModelError(f"{what} has non-finite entries")
    if np.max(np.abs(T[3] - (0.0, 0.0, 0.0, 1.0))) > RIGID_TOLERANCE:
        raise ModelError(f"{what} is not a rigid transform: last row is {T[3].tolist()}, not [0, 0, 0, 1]")
    R = T[:3, :3]
    ortho = float(np.max(np.abs(R.T @ R - np.eye(3))))
    if ortho > RIGID_TOLERANCE:
        raise ModelError(
            f"{what} is not a rigid transform: rotation block is not orthonormal (|R^T R - I| = {ortho:.3g})")
    if np.linalg.det(R) < 0.0:
        raise ModelError(f"{what} is not a proper rigid transform: rotation block is a reflection (det = -1)")
    return T


# --------------------------------------------------------------------------- loading


XacroArgs = Mapping[str, str] | Iterable[tuple[str, str]] | None


def load_urdf(urdf_path: str | os.PathLike[str], xacro_args: XacroArgs = None) -> yourdfpy.URDF:
    """Load a URDF with yourdfpy without touching meshes (for :mod:`pincal.model.dh.urdf`;
    yourdfpy, trimesh and networkx are imported on the first call).

    No scene graph is built and no mesh is loaded; mesh file names (including
    unresolvable ``package://`` ones) are kept exactly as written. A ``*.xacro``
    file is expanded in memory with ``xacro_args``
    (:func:`pincal.model.description.read_description`).

    Raises:
        ModelError: if the file does not exist, cannot be parsed or expanded, or
            is not a kinematic tree.
    """
    return _load(read_description(urdf_path, xacro_args))


def _load(description: RobotDescription) -> yourdfpy.URDF:
    import yourdfpy

    try:
        return yourdfpy.URDF.load(
            io.BytesIO(description.xml),
            build_scene_graph=False,
            build_collision_scene_graph=False,
            load_meshes=False,
            load_collision_meshes=False,
            filename_handler=yourdfpy.filename_handler_null,
        )
    except Exception as exc:  # yourdfpy raises assorted exceptions on bad XML
        raise ModelError(f"cannot read URDF {description.source}: {' '.join(str(exc).split())}") from None


def read_joint_origins(urdf_path: str | os.PathLike[str], xacro_args: XacroArgs = None) -> dict[str, np.ndarray]:
    """Origins of all joints of a URDF.

    Args:
        urdf_path: URDF file (or ``*.xacro``, expanded with ``xacro_args``).

    Returns:
        ``{joint name: 4x4 parent_T_child origin}`` [m, rad]; a joint without an
        ``<origin>`` element has the identity.
    """
    return joint_origins(read_description(urdf_path, xacro_args).root())


# --------------------------------------------------------------------------- writing


def same_file(a: Path, b: Path) -> bool:
    """Whether two paths name the same file (symlinks and ``..`` resolved)."""
    if b.exists():
        try:
            return os.path.samefile(a, b)
        except OSError:
            pass
    return a.resolve() == b.resolve()


def _is_element(node: object) -> bool:
    return isinstance(node, etree._Element) and isinstance(node.tag, str)


def _elements(parent: etree._Element, tag: str) -> list[etree._Element]:
    return [child for child in parent if _is_element(child) and child.tag == tag]


def _merge(src: etree._Element, out: etree._Element) -> None:
    """Make ``out`` (yourdfpy's rendering of ``src``) carry everything ``src`` has.

    Attributes missing from ``out`` are copied; children yourdfpy models are
    matched by tag and position and merged recursively (``<origin>`` gets the
    source's attribute text verbatim); other children are deep-copied.
    """
    for key, value in src.attrib.items():
        if key not in out.attrib:
            out.set(key, value)
    if src.tag == "origin":
        out.attrib.clear()
        out.attrib.update(dict(src.attrib))
        return
    modelled = _MODELLED_CHILDREN.get(src.tag, frozenset())
    seen: dict[str, int] = {}
    for child in src:
        if not _is_element(child):
            continue
        if child.tag not in modelled:
            out.append(copy.deepcopy(child))
            continue
        index = seen.get(child.tag, 0)
        seen[child.tag] = index + 1
        candidates = _elements(out, child.tag)
        if index < len(candidates):
            _merge(child, candidates[index])


def _postprocess(
    src_root: etree._Element, out_root: etree._Element, replaced: Mapping[str, np.ndarray]
) -> None:
    """Fix yourdfpy's output tree in place, see the module docstring."""
    for key, value in src_root.attrib.items():
        if key not in out_root.attrib:
            out_root.set(key, value)
    for tag in _NAMED_TOP_LEVEL:
        out_by_name = {e.get("name"): e for e in _elements(out_root, tag)}
        for src_el in _elements(src_root, tag):
            out_el = out_by_name.get(src_el.get("name"))
            if out_el is not None:
                _merge(src_el, out_el)
    for src_el, out_el in zip(_elements(src_root, "material"), _elements(out_root, "material")):
        _merge(src_el, out_el)
    for child in src_root:
        if _is_element(child) and child.tag not in _MODELLED_CHILDREN["robot"]:
            out_root.append(copy.deepcopy(child))

    out_joints = {e.get("name"): e for e in _elements(out_root, "joint")}
    src_joints = {e.get("name"): e for e in _elements(src_root, "joint")}
    for name, out_joint in out_joints.items():
        src_joint = src_joints.get(name)
        if src_joint is not None and src_joint.find("axis") is None:
            for axis in _elements(out_joint, "axis"):
                out_joint.remove(axis)
        if name in replaced:
            origins = _elements(out_joint, "origin")
            origin = origins[0] if origins else etree.SubElement(out_joint, "origin")
            origin.attrib.clear()
            origin.attrib.update(origin_attributes(replaced[name]))


def _xml_comment(text: str) -> etree._Comment:
    """An XML comment holding ``text``; ``--`` (illegal in comments) becomes ``- -``."""
    body = text.rstrip()
    while "--" in body:
        body = body.replace("--", "- -")
    return etree.Comment(f" {body} ")


def write_urdf_with_origins(
    source: str | os.PathLike[str],
    destination: str | os.PathLike[str],
    origins: Mapping[str, npt.ArrayLike],
    comment: str | None = None,
    verify: Callable[[Path], None] | None = None,
    xacro_args: XacroArgs = None,
) -> None:
    """Copy a URDF, replacing the origins of the named joints.

    Everything else is preserved (see the module docstring for the exact
    guarantees and for what yourdfpy cannot keep: comments and element order).
    A ``*.xacro`` source is expanded in memory with ``xacro_args``; the output is
    plain URDF whose comment also says which xacro file and arguments it came from.

    Args:
        source: input URDF; never modified.
        destination: output URDF; must not be the same file as ``source``.
        origins: ``{joint name: 4x4 parent_T_child}`` [m]; each must be a proper
            rigid transform.
        comment: optional text written as an XML comment just before ``<robot>``
            (e.g. provenance); multi-line text is kept.
        verify: called with the complete written file before it replaces
            ``destination`` (see :func:`pincal.outputs.replacing`); what it
            raises cancels the write.
        xacro_args: arguments of a ``*.xacro`` source (``{"prefix": "left_"}``).

    Raises:
        ModelError: the destination is the source file, a named joint does not
            exist (the message lists the joints that do), an origin is not a
            proper rigid transform, or the source cannot be read.
    """
    description = read_description(source, xacro_args)
    src_path, dst_path = description.path, Path(destination)
    if same_file(src_path, dst_path):
        raise ModelError(f"refusing to write {dst_path}: it is the input URDF; never overwrite the input")
    if any(same_file(Path(f), dst_path) for f in description.included):
        raise ModelError(f"refusing to write {dst_path}: {src_path} includes it; never overwrite an input")
    checked = {
        str(name): check_rigid_transform(matrix, f"origin of joint '{name}'")
        for name, matrix in origins.items()
    }
    src_root = description.root()
    joints = [joint.get("name") for joint in src_root.findall("joint")]
    unknown = [name for name in checked if name not in joints]
    if unknown:
        raise ModelError(
            f"joint(s) {', '.join(repr(n) for n in unknown)} not found in {src_path}; "
            f"its joints are: {', '.join(joints)}"
        )
    for joint in src_root.findall("joint"):  # a replaced origin sits where the form puts one
        if joint.get("name") in checked and joint.find("origin") is None:
            etree.SubElement(joint, "origin")
    out_root = render(src_root, description.source)
    _postprocess(src_root, out_root, checked)
    comment = "\n".join(text for text in (comment, description.provenance()) if text)
    if comment:
        out_root.addprevious(_xml_comment(comment))
    tree = out_root.getroottree()
    if not dst_path.parent.exists():
        raise ModelError(f"cannot write {dst_path}: directory {dst_path.parent} does not exist")
    with replacing(dst_path, "wb", verify=verify) as handle:  # the old file or the whole new one, never half
        tree.write(handle, xml_declaration=True, encoding="utf-8", pretty_print=True)
