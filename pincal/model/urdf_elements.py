"""URDF elements with lxml alone: joint origins as matrices, and the element tree pincal writes.

pincal reads and writes URDF joint origins without a URDF object model, so the
calibrate path imports neither yourdfpy nor what it pulls in (trimesh, networkx;
~0.3 s of a 1 s run). The form of the written file is the one pincal has always
written, which was yourdfpy 0.0.60's (``URDF.write_xml``) of the same file:

* ``<robot name>``, then every ``<link>``, every ``<joint>``, every top-level
  ``<material>``, each in its file order;
* a link: ``<inertial>`` (origin, mass, inertia), its visuals, its collisions;
  a visual: geometry, origin, material; a collision: geometry, origin; a joint:
  parent, child, origin, axis (``1 0 0`` when absent), limit, dynamics;
* numbers parsed and written back in Python's shortest round-trip form
  (``1e3`` → ``1000.0``; an inertia's six, a box size, an axis, a colour or a
  mesh scale as numpy float64), ``<dynamics>`` values verbatim.

:func:`render` builds that tree; :mod:`pincal.model.urdf` then puts back what
this form leaves out (origins' own text, extra elements and attributes) and sets
the calibrated origins. ``tests/test_urdf_elements.py`` checks both functions
against yourdfpy on every URDF of example-robot-data: the same bytes, the same
origin matrices bit for bit.

Units: metres, radians, kilograms, as in URDF; 4x4 homogeneous ``parent_T_child``.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from lxml import etree

from pincal.errors import ModelError
from pincal.measurements.data import JointMimic

__all__ = ["origin_matrix", "joint_origins", "parent_joint", "joint_mimics", "render"]


def _floats(text: str) -> np.ndarray:
    return np.array(list(map(float, text.split())))


def origin_matrix(origin: etree._Element | None) -> np.ndarray | None:
    """The 4x4 ``parent_T_child`` of an ``<origin xyz rpy>`` element [m, rad]; None without one.

    URDF's rotation is ``Rz(yaw) Ry(pitch) Rx(roll)``. The matrix is built with the
    arithmetic of ``trimesh.transformations.compose_matrix`` (through which pincal
    used to read origins): numpy sines and cosines, the 3x3 block from their
    products, then identity · translation · rotation, so every origin — and every
    corrected origin computed from it — is the same double as before, bit for bit.
    """
    if origin is None:
        return None
    xyz = _floats(origin.get("xyz", default="0 0 0"))
    roll, pitch, yaw = _floats(origin.get("rpy", default="0 0 0"))[:3]
    s_r, s_p, s_y = np.sin(roll), np.sin(pitch), np.sin(yaw)
    c_r, c_p, c_y = np.cos(roll), np.cos(pitch), np.cos(yaw)
    rotation = np.eye(4)
    rotation[:3, :3] = [
        [c_p * c_y, s_p * (s_r * c_y) - c_r * s_y, s_p * (c_r * c_y) + s_r * s_y],
        [c_p * s_y, s_p * (s_r * s_y) + c_r * c_y, s_p * (c_r * s_y) - s_r * c_y],
        [-s_p, c_p * s_r, c_p * c_r],
    ]
    translation = np.identity(4)
    translation[:3, 3] = xyz[:3]
    matrix = np.dot(np.dot(np.identity(4), translation), rotation)
    matrix /= matrix[3, 3]
    return matrix


def joint_origins(robot: etree._Element) -> dict[str, np.ndarray]:
    """``{joint name: 4x4 origin}`` of every ``<joint>`` of ``<robot>`` (identity without ``<origin>``)."""
    out = {}
    for joint in robot.findall("joint"):
        matrix = origin_matrix(joint.find("origin"))
        out[joint.get("name")] = np.eye(4) if matrix is None else matrix
    return out


def parent_joint(robot: etree._Element, link: str) -> tuple[str | None, bool]:
    """Name of the joint whose child is ``link`` (None if none) and whether it is fixed."""
    for joint in robot.findall("joint"):
        if joint.find("child").get("link") == link:
            return joint.get("name"), joint.get("type") == "fixed"
    return None, False


def joint_mimics(robot: etree._Element) -> dict[str, JointMimic]:
    """``{joint name: how it follows its driver}`` of every ``<joint>`` with a ``<mimic joint>`` (URDF
    defaults: multiplier 1, offset 0; eq M1 of :mod:`pincal.measurements.mimics`), as written: whether the
    driver exists is the chain's to check, for its own joints (published URDFs name missing drivers on
    branches nobody calibrates, e.g. example-robot-data's alex_psyonic_hands fingers)."""
    out = {}
    for joint in robot.findall("joint"):
        mimic = joint.find("mimic")
        if mimic is not None and mimic.get("joint"):
            out[joint.get("name")] = JointMimic(mimic.get("joint"), float(mimic.get("multiplier", 1.0)),
                                                float(mimic.get("offset", 0.0)))
    return out


# --------------------------------------------------------------------------- the written form


def _number(text: str) -> str:
    return str(float(text))


def _numbers(text: str) -> str:
    return " ".join(map(str, _floats(text)))


def _sub(parent: etree._Element, tag: str, attributes: dict[str, str | None], where: str) -> etree._Element:
    missing = [key for key, value in attributes.items() if value is None]
    if missing:
        raise ModelError(f"{where}: <{tag}> has no {', '.join(missing)}; add it")
    return etree.SubElement(parent, tag, attrib=attributes)


def _material(parent: etree._Element, material: etree._Element | None) -> None:
    if material is None:
        return
    name = material.get("name")
    out = etree.SubElement(parent, "material", attrib={} if name is None else {"name": name})
    color, texture = material.find("color"), material.find("texture")
    if color is not None:
        etree.SubElement(out, "color", attrib={"rgba": _numbers(color.get("rgba", default="1 1 1 1"))})
    if texture is not None:  # yourdfpy failed on a <texture/> without filename (iCub's); kept as written
        filename = texture.get("filename")
        etree.SubElement(out, "texture", attrib={} if filename is None else {"filename": filename})


def _geometry(parent: etree._Element, geometry: etree._Element | None, where: str) -> None:
    if geometry is None or len(geometry) == 0:
        raise ModelError(f"{where}: a <visual> or <collision> without a shape in <geometry>; add one")
    shape = geometry[0]
    out = etree.SubElement(parent, "geometry")
    if shape.tag == "box":
        size = shape.get("size", "").replace(",", " ").split()
        _sub(out, "box", {"size": " ".join(map(str, np.array(size, dtype=np.float64))) or None}, where)
    elif shape.tag == "cylinder":
        radius, length = shape.get("radius"), shape.get("length")
        _sub(out, "cylinder", {"radius": radius and _number(radius), "length": length and _number(length)}, where)
    elif shape.tag == "sphere":
        _sub(out, "sphere", {"radius": shape.get("radius") and _number(shape.get("radius"))}, where)
    elif shape.tag == "mesh":
        mesh = _sub(out, "mesh", {"filename": shape.get("filename")}, where)
        scale = shape.get("scale", "").replace(",", " ").split()
        if len(scale) == 1:
            mesh.set("scale", " ".join([_number(scale[0])] * 3))
        elif scale:
            mesh.set("scale", " ".join(map(str, np.array(list(map(float, scale))))))
    else:
        raise ModelError(f"{where}: <geometry> holds <{shape.tag}>, not box, cylinder, sphere or mesh; fix it")


def _origin(parent: etree._Element, element: etree._Element) -> None:
    """An ``<origin>`` where the source has one; its attributes are the source's text (set by the caller)."""
    if element.find("origin") is not None:
        etree.SubElement(parent, "origin")


def _inertial(parent: etree._Element, inertial: etree._Element | None) -> None:
    if inertial is None:
        return
    out = etree.SubElement(parent, "inertial")
    _origin(out, inertial)
    mass, inertia = inertial.find("mass"), inertial.find("inertia")
    if mass is not None:
        etree.SubElement(out, "mass", attrib={"value": str(float(mass.get("value", default=0.0)))})
    if inertia is not None:
        diagonal = {"ixx": 1.0, "iyy": 1.0, "izz": 1.0}
        values = np.array([inertia.get(key, default=diagonal.get(key, 0.0))
                           for key in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")], dtype=np.float64)
        etree.SubElement(out, "inertia", attrib={key: str(value) for key, value in
                                                 zip(("ixx", "ixy", "ixz", "iyy", "iyz", "izz"), values)})


def _link(robot: etree._Element, link: etree._Element, source: str) -> None:
    where = f"{source}: link '{link.get('name')}'"
    out = etree.SubElement(robot, "link", attrib={"name": link.get("name")})
    _inertial(out, link.find("inertial"))
    for tag in ("visual", "collision"):
        for element in link.findall(tag):
            name = element.get("name")
            part = etree.SubElement(out, tag, attrib={} if name is None else {"name": name})
            _geometry(part, element.find("geometry"), where)
            _origin(part, element)
            if tag == "visual":
                _material(part, element.find("material"))


def _joint(robot: etree._Element, joint: etree._Element) -> None:
    out = etree.SubElement(robot, "joint", attrib={"name": joint.get("name"), "type": joint.get("type")})
    for role in ("parent", "child"):
        etree.SubElement(out, role, attrib={"link": joint.find(role).get("link")})
    _origin(out, joint)
    axis = joint.find("axis")
    etree.SubElement(out, "axis", attrib={"xyz": _numbers("1 0 0" if axis is None else axis.get("xyz", "1 0 0"))})
    _attributes(out, joint.find("limit"), "limit", ("effort", "velocity", "lower", "upper"), _number)
    _attributes(out, joint.find("dynamics"), "dynamics", ("damping", "friction"), str)


def _attributes(parent: etree._Element, element: etree._Element | None, tag: str, keys: tuple[str, ...],
                form: Callable[[str], str]) -> None:
    if element is not None:
        etree.SubElement(parent, tag, attrib={key: form(element.get(key)) for key in keys
                                              if element.get(key) is not None})


def render(robot: etree._Element, source: str) -> etree._Element:
    """The written form (module docstring) of a checked ``<robot>`` (comments removed).

    Origins are empty ``<origin/>`` elements where the source has one: the writer
    gives each the source's attribute text or the calibrated value.

    Raises:
        ModelError: naming ``source`` and the link, for what the form cannot hold:
            a visual or collision without a shape, an unknown shape, a shape or mesh
            without its size or file, or a colour that is not numbers.
    """
    out = etree.Element("robot", attrib={"name": robot.get("name")})
    try:
        for link in robot.findall("link"):
            _link(out, link, source)
        for joint in robot.findall("joint"):
            _joint(out, joint)
        for material in robot.findall("material"):
            _material(out, material)
    except ValueError as exc:  # a number that is not one, outside what check_urdf_tree checks (colours)
        raise ModelError(f"cannot read URDF {source}: {' '.join(str(exc).split())}; fix the value") from None
    return out
