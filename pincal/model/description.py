"""The URDF of a robot description: a URDF file as written, or a xacro file expanded in memory.

Every URDF pincal reads goes through :func:`read_description`: a file whose name
ends in ``.xacro`` (``robot.urdf.xacro``) is expanded with the ``xacro`` package
(arguments ``NAME:=VALUE`` as on xacro's command line, given as a mapping); any
other file is read as URDF. Nothing is written anywhere: the expanded document
lives in memory only. The result is then checked as a kinematic tree
(:func:`check_urdf_tree`) before Pinocchio or yourdfpy see it, so a broken file is
one :class:`~pincal.errors.ModelError` line naming the file, the element and what
to do — urdfdom would print its reasons on stderr and raise a message-less error,
and yourdfpy silently recovers truncated XML.

Units of the numbers checked: metres, radians, kilograms, as in URDF.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib.metadata
import io
import math
import os
import re
import threading
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

from lxml import etree

from pincal.errors import ModelError

__all__ = [
    "XACRO_SUFFIX", "XACRO_NAMESPACE", "XACRO_ARG_RE", "JOINT_TYPES", "RobotDescription", "is_xacro", "parse_xacro_arg",
    "xacro_arguments", "read_description", "check_urdf_tree",
]

#: File-name ending of the descriptions :func:`read_description` expands with xacro.
XACRO_SUFFIX = ".xacro"
#: XML namespace of xacro's elements.
XACRO_NAMESPACE = "http://www.ros.org/wiki/xacro"
#: ``NAME:=VALUE``: a xacro argument as xacro's command line takes it.
XACRO_ARG_RE = re.compile(r"([A-Za-z_][A-Za-z0-9_]*):=(.*)", re.DOTALL)
#: Joint types of the URDF specification.
JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar")

# Numeric attributes of URDF elements: (parent tag, tag) -> {attribute: number of values}.
# Each must be finite, except joint limits, which may be +-inf (never NaN).
_NUMERIC: dict[tuple[str, str], dict[str, int]] = {
    ("joint", "origin"): {"xyz": 3, "rpy": 3},
    ("joint", "axis"): {"xyz": 3},
    ("joint", "limit"): {"lower": 1, "upper": 1, "effort": 1, "velocity": 1},
    ("joint", "dynamics"): {"damping": 1, "friction": 1},
    ("joint", "mimic"): {"multiplier": 1, "offset": 1},
    ("joint", "safety_controller"): {"soft_lower_limit": 1, "soft_upper_limit": 1, "k_position": 1,
                                     "k_velocity": 1},
    ("inertial", "origin"): {"xyz": 3, "rpy": 3},
    ("inertial", "mass"): {"value": 1},
    ("inertial", "inertia"): {n: 1 for n in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")},
    ("visual", "origin"): {"xyz": 3, "rpy": 3},
    ("collision", "origin"): {"xyz": 3, "rpy": 3},
    ("geometry", "box"): {"size": 3},
    ("geometry", "cylinder"): {"radius": 1, "length": 1},
    ("geometry", "sphere"): {"radius": 1},
    ("geometry", "mesh"): {"scale": 3},
}
_MAY_BE_INFINITE = {("joint", "limit")}


@dataclass(frozen=True)
class RobotDescription:
    """A checked URDF document and where it came from.

    Attributes:
        path: the file read (the ``.xacro`` file for an expanded description).
        xml: the URDF document, UTF-8 encoded (the expansion, for a xacro file).
        xacro_args: the xacro arguments given, ``((name, value), ...)`` in the
            order given; empty for a plain URDF (xacro's defaults apply to the rest).
        xacro_notes: what xacro warned about while expanding, one line each.
        included: the files the xacro file included (inputs too: never to be overwritten).
    """

    path: Path
    xml: bytes
    xacro_args: tuple[tuple[str, str], ...] = ()
    xacro_notes: tuple[str, ...] = ()
    included: tuple[Path, ...] = ()

    @property
    def is_xacro(self) -> bool:
        return is_xacro(self.path)

    @property
    def source(self) -> str:
        """The file's name for messages: ``robot.urdf.xacro (expanded with xacro)``."""
        return f"{self.path} (expanded with xacro)" if self.is_xacro else str(self.path)

    @property
    def text(self) -> str:
        """The URDF document as text (what Pinocchio's ``buildModelFromXML`` takes)."""
        return self.xml.decode("utf-8")

    def root(self) -> etree._Element:
        """A fresh parse of the document's ``<robot>`` element (callers may change it)."""
        return etree.fromstring(self.xml, _parser(remove_comments=True))

    def link_names(self) -> tuple[str, ...]:
        """The names of the document's links, in its order."""
        return tuple(_name_of(link) for link in self.root() if link.tag == "link")

    def provenance(self) -> str | None:
        """One line saying which xacro file and arguments this URDF was expanded from; None for a URDF."""
        if not self.is_xacro:
            return None
        args = ", ".join(f"{n}:={v}" for n, v in self.xacro_args) or "none"
        return (f"Expanded from the xacro file {self.path.resolve()} with xacro {_xacro_version()}, "
                f"arguments: {args} (defaults of the file otherwise).")


def is_xacro(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` names a xacro file (its name ends in ``.xacro``)."""
    return str(path).endswith(XACRO_SUFFIX)


def parse_xacro_arg(text: str) -> tuple[str, str]:
    """``NAME:=VALUE`` → ``(NAME, VALUE)``; NAME is an identifier, VALUE any text (may be empty).

    Raises:
        ValueError: ``text`` is not of that form (the message says what is expected).
    """
    match = XACRO_ARG_RE.fullmatch(text)
    if match is None:
        raise ValueError(f"'{text}' is not NAME:=VALUE (a xacro argument, e.g. prefix:=left_)")
    return match[1], match[2]


def xacro_arguments(args: Mapping[str, str] | Iterable[tuple[str, str]] | None) -> tuple[tuple[str, str], ...]:
    """Normalise xacro arguments to ``((name, value), ...)``; a name given twice is refused.

    Raises:
        ModelError: a name given twice with different values, or a name that is not an identifier.
    """
    pairs = list(args.items()) if isinstance(args, Mapping) else list(args or ())
    seen: dict[str, str] = {}
    for name, value in pairs:
        name, value = str(name), str(value)
        if XACRO_ARG_RE.fullmatch(f"{name}:=") is None:
            raise ModelError(f"xacro argument name {name!r} is not an identifier (letters, digits, _)")
        if name in seen and seen[name] != value:
            raise ModelError(f"xacro argument '{name}' given twice ({seen[name]!r} and {value!r}); give it once")
        seen[name] = value
    return tuple(seen.items())


def read_description(
    path: str | os.PathLike[str], xacro_args: Mapping[str, str] | Iterable[tuple[str, str]] | None = None
) -> RobotDescription:
    """Read ``path`` as a URDF, expanding it with xacro if its name ends in ``.xacro``; check the tree.

    A description read before in this process, with the same bytes (the same expansion),
    is returned as it was, not parsed and checked again (:data:`_CHECKED`).

    Args:
        path: a URDF file, or a xacro file (``*.xacro``).
        xacro_args: arguments of the xacro file (``{"prefix": "left_"}``); only for a xacro file.

    Raises:
        ModelError: one line naming the file: missing, not XML, a xacro that does not
            expand (missing include, undefined or unknown argument, ``$(find pkg)``
            without ROS), arguments given for a plain URDF, or a URDF that is not a
            kinematic tree (see :func:`check_urdf_tree`).
    """
    p = Path(path)
    if not p.is_file():
        raise ModelError(f"{p}: no such URDF file; check the path")
    args = xacro_arguments(xacro_args)
    if is_xacro(p):
        xml, notes, included = _expand_cached(p, args)
        key = (str(p), str(p.resolve()), args, xml)
        if key in _CHECKED:
            return _CHECKED[key]
        description = RobotDescription(p, xml, args, notes, included)
    else:
        if args:
            raise ModelError(f"{p}: xacro arguments ({', '.join(n for n, _ in args)}) apply to .xacro files "
                             "only; drop --xacro-arg, or give the .xacro file")
        try:
            raw = p.read_bytes()
        except OSError as exc:
            raise ModelError(f"{p}: cannot read the URDF ({exc.strerror or exc})") from None
        key = (str(p), str(p.resolve()), args, raw)
        if key in _CHECKED:
            return _CHECKED[key]
        root = _parse_xml(raw, str(p))
        description = RobotDescription(p, etree.tostring(root, encoding="utf-8", xml_declaration=True))
    check_urdf_tree(description.root(), description.source, plain=not description.is_xacro)
    if len(_CHECKED) >= _CACHE_SIZE:
        _CHECKED.pop(next(iter(_CHECKED)))
    _CHECKED[key] = description
    return description


#: Descriptions already read and checked in this process, by (path as given, resolved,
#: xacro arguments, the file's bytes or the expansion): one calibrate run reads its URDF
#: for the chain, the corrected origins, the tip joint and the writer, and parses and
#: checks it once. Keyed by content, not modification time, so a rewritten file is read again.
_CHECKED: dict[tuple[str, str, tuple[tuple[str, str], ...], bytes], RobotDescription] = {}


# --------------------------------------------------------------------------- XML


def _parser(remove_comments: bool = False) -> etree.XMLParser:
    # No entity expansion or network access: a URDF needs neither.
    return etree.XMLParser(resolve_entities=False, no_network=True, remove_comments=remove_comments,
                           remove_blank_text=True)


def _parse_xml(raw: bytes, source: str) -> etree._Element:
    """The root element of an XML document, or a one-line ModelError."""
    try:
        return etree.fromstring(raw, _parser())
    except etree.XMLSyntaxError as exc:
        detail = str(exc).splitlines()[0] if str(exc) else "empty or not XML"
        raise ModelError(f"{source}: not a well-formed XML file ({detail}); fix or re-export the URDF") from None
    except ValueError as exc:  # e.g. a str with an encoding declaration, or NUL bytes
        raise ModelError(f"{source}: not a well-formed XML file ({exc}); fix or re-export the URDF") from None


# --------------------------------------------------------------------------- xacro


_XACRO_LOCK = threading.Lock()  # xacro keeps its state in module globals
_Stamps = tuple[tuple[str, str | None], ...]  # (file, SHA-256 of its bytes or None when unreadable)
_CACHE: dict[tuple[str, tuple[tuple[str, str], ...]], tuple[_Stamps, bytes, tuple[str, ...]]] = {}
_CACHE_SIZE = 8


class _RecordingArgs(dict[str, str]):
    """xacro's argument table that remembers which names the description asked for."""

    def __init__(self, pairs: Iterable[tuple[str, str]]) -> None:
        super().__init__(pairs)
        self.asked: set[str] = set()

    def __getitem__(self, key: str) -> str:
        self.asked.add(key)
        return super().__getitem__(key)

    def __contains__(self, key: object) -> bool:
        self.asked.add(str(key))  # xacro asks by name
        return super().__contains__(key)


def _xacro_version() -> str:
    try:
        return importlib.metadata.version("xacro")
    except importlib.metadata.PackageNotFoundError:
        return "(unknown version)"


def _stamps(files: Iterable[str]) -> _Stamps:
    """(file, SHA-256 of its bytes) of every file an expansion read: the cache holds while they are unchanged.

    Contents, not modification times: a file rewritten within the clock's resolution
    still counts as changed; reading a description's few files costs far less than xacro.
    """
    out: list[tuple[str, str | None]] = []
    for name in sorted(set(files)):
        try:
            out.append((name, hashlib.sha256(Path(name).read_bytes()).hexdigest()))
        except OSError:
            out.append((name, None))
    return tuple(out)


def _expand_cached(
    path: Path, args: tuple[tuple[str, str], ...]
) -> tuple[bytes, tuple[str, ...], tuple[Path, ...]]:
    """Expand ``path`` once per process while neither it nor what it includes changes."""
    key = (str(path.resolve()), args)
    with _XACRO_LOCK:
        hit = _CACHE.get(key)
        if hit is not None and _stamps(name for name, _ in hit[0]) == hit[0]:
            return hit[1], hit[2], _included(hit[0], key[0])
        xml, notes, files = _expand(path, args)
        if len(_CACHE) >= _CACHE_SIZE:
            _CACHE.pop(next(iter(_CACHE)))
        _CACHE[key] = stamped = (_stamps(files), xml, notes)
        return xml, notes, _included(stamped[0], key[0])


def _included(stamps: _Stamps, top: str) -> tuple[Path, ...]:
    return tuple(Path(name) for name, _ in stamps if name != top)


def _expand(path: Path, args: tuple[tuple[str, str], ...]) -> tuple[bytes, tuple[str, ...], list[str]]:
    """Run xacro on ``path`` in memory: the UTF-8 URDF, xacro's warnings and the files it read."""
    import xml.parsers.expat

    import xacro

    resolved = str(path.resolve())
    mappings = _RecordingArgs(args)
    messages = io.StringIO()
    xacro.all_includes.clear()  # xacro appends every file it includes to this global list
    try:
        with contextlib.redirect_stderr(messages):
            document = xacro.process_file(resolved, mappings=mappings)
            text = document.toxml()
    except xml.parsers.expat.ExpatError as exc:
        where = (xacro.filestack or [resolved])[-1]
        raise ModelError(f"{path}: xacro cannot expand it: {where} is not well-formed XML ({exc}); "
                         "fix the XML") from None
    except Exception as exc:  # xacro raises XacroException, NameError, ... with assorted messages
        raise _xacro_error(path, exc, (xacro.filestack or [resolved])[-1]) from None
    finally:
        xacro.filestack = None
    files = [resolved, *xacro.all_includes]
    unused = [name for name, _ in args if name not in mappings.asked]
    if unused:
        known = sorted(mappings.asked) or ["none"]
        raise ModelError(f"{path}: xacro argument(s) {', '.join(unused)} not used by this description "
                         f"(its arguments: {', '.join(known)}); check the names given with --xacro-arg")
    root = _parse_xml(text.encode("utf-8"), f"{path} (expanded with xacro)")
    notes = tuple(line.strip() for line in messages.getvalue().splitlines() if line.strip())
    return etree.tostring(root, encoding="utf-8", xml_declaration=True), notes, files


def _xacro_error(path: Path, exc: BaseException, where: str) -> ModelError:
    """A one-line ModelError for what xacro raised while expanding ``path``."""
    detail = "; ".join(line.strip() for line in str(exc).splitlines() if line.strip()) or type(exc).__name__
    cause = getattr(exc, "exc", None) or exc.__cause__ or exc.__context__
    in_file = "" if Path(where).resolve() == path.resolve() else f" (in {where})"
    if "ament_index_python" in detail:
        return ModelError(f"{path}: xacro cannot resolve $(find PKG){in_file}: it needs ROS 2's package index "
                          "(ament_index_python), which is not installed; replace $(find PKG)/... by a path "
                          "relative to the xacro file, or run pincal where ROS 2 is sourced")
    if type(cause).__name__ == "PackageNotFoundError":
        return ModelError(f"{path}: xacro cannot resolve $(find ...){in_file}: {detail}; source the ROS 2 "
                          "workspace that has the package, or replace $(find PKG)/... by a relative path")
    if isinstance(cause, OSError):
        missing = getattr(cause, "filename", None) or detail
        return ModelError(f"{path}: xacro cannot expand it{in_file}: include {missing} not found; check the "
                          "include's filename (relative to the including file; package:// needs ROS)")
    match = re.match(r"Undefined substitution argument (\S+)", detail)
    if match:
        return ModelError(f"{path}: the xacro needs argument '{match[1]}'{in_file}, which has no default; "
                          f"give it with --xacro-arg {match[1]}:=VALUE")
    return ModelError(f"{path}: xacro cannot expand it{in_file}: {detail}; fix the xacro or its arguments")


# --------------------------------------------------------------------------- tree check


def _name_of(element: etree._Element) -> str:
    return element.get("name") or ""


def _check_numbers(element: etree._Element, source: str, rules: Mapping[str, int], finite: bool) -> None:
    for attribute, count in rules.items():
        text = element.get(attribute)
        if text is None:
            continue
        try:
            values = [float(v) for v in text.split()]
        except ValueError:
            values = []
        ok = len(values) == count and all(not math.isnan(v) and (math.isfinite(v) or not finite) for v in values)
        if not ok:
            expected = "a finite number" if count == 1 else f"{count} finite numbers"
            owner = next((a for a in element.iterancestors() if a.tag in ("joint", "link")), None)
            where = source if owner is None else f"{source}: {owner.tag} '{_name_of(owner)}'"
            raise ModelError(f"{where}: <{element.tag} {attribute}=\"{text}\"> is not {expected}; fix the value")


def _check_numeric_attributes(robot: etree._Element, source: str) -> None:
    for element in robot.iter():
        parent = element.getparent()
        if parent is None or not isinstance(element.tag, str) or not isinstance(parent.tag, str):
            continue
        rules = _NUMERIC.get((parent.tag, element.tag))
        if rules is None:
            continue
        _check_numbers(element, source, rules, (parent.tag, element.tag) not in _MAY_BE_INFINITE)


def _single_link(joint: etree._Element, role: str, where: str) -> str:
    found = [e for e in joint if e.tag == role]
    if len(found) != 1 or not found[0].get("link"):
        raise ModelError(f"{where}: needs exactly one <{role} link=\"...\"/>, found {len(found)}; fix the joint")
    return found[0].get("link")


def check_urdf_tree(robot: etree._Element, source: str, plain: bool = True) -> None:
    """Check that ``robot`` is a URDF ``<robot>`` whose links and joints form one tree.

    Checks: the root element is ``<robot>``; no xacro markup is left (``plain``: the
    file was not expanded, so a ``.urdf`` holding xacro is named as such); every link
    and joint has a distinct name; each joint has a known type, one parent and one child
    link that exist, and (revolute, prismatic) a ``<limit>`` and a non-zero axis; no link
    has two parents; exactly one link has none and every link hangs below it (no loop);
    the numeric attributes of origins, axes, limits, inertials and geometry are numbers
    (finite; limits may be infinite).

    Raises:
        ModelError: naming ``source``, the link or joint, and what to fix.
    """
    if not isinstance(robot.tag, str) or robot.tag != "robot":
        raise ModelError(f"{source}: the root element is <{robot.tag}>, not <robot>; is this a URDF file?")
    if not robot.get("name"):
        raise ModelError(f"{source}: the <robot> element has no name; add name=\"...\" (URDF requires it)")
    markup = next((e for e in robot.iter() if isinstance(e.tag, str) and e.tag.startswith(f"{{{XACRO_NAMESPACE}}}")),
                  None)
    if markup is not None:
        hint = "name the file *.xacro so pincal expands it" if plain else "the expansion left it; fix the xacro"
        raise ModelError(f"{source}: contains xacro markup (<xacro:{etree.QName(markup).localname}>); {hint}")
    links = [e for e in robot if e.tag == "link"]
    joints = [e for e in robot if e.tag == "joint"]
    link_names: set[str] = set()
    for link in links:
        name = _name_of(link)
        if not name:
            raise ModelError(f"{source}: a <link> has no name; name every link")
        if name in link_names:
            raise ModelError(f"{source}: link name '{name}' is used twice; link names must be distinct")
        link_names.add(name)
    if not links:
        raise ModelError(f"{source}: no <link> in this URDF; a robot needs links and joints")
    parent_of: dict[str, tuple[str, str]] = {}
    children: dict[str, list[str]] = {}
    joint_names: set[str] = set()
    for joint in joints:
        name = _name_of(joint)
        if not name:
            raise ModelError(f"{source}: a <joint> has no name; name every joint")
        if name in joint_names:
            raise ModelError(f"{source}: joint name '{name}' is used twice; joint names must be distinct")
        joint_names.add(name)
        where = f"{source}: joint '{name}'"
        kind = joint.get("type")
        if kind not in JOINT_TYPES:
            raise ModelError(f"{where}: type {kind!r} is not a URDF joint type ({', '.join(JOINT_TYPES)})")
        parent, child = _single_link(joint, "parent", where), _single_link(joint, "child", where)
        for role, link in (("parent", parent), ("child", child)):
            if link not in link_names:
                raise ModelError(f"{where}: {role} link '{link}' is not a link of this URDF; "
                                 f"add <link name=\"{link}\"/> or fix the joint")
        if child in parent_of:
            raise ModelError(f"{where}: link '{child}' already has the parent joint '{parent_of[child][0]}'; "
                             "a URDF is a tree (no kinematic loops): remove one of the joints")
        parent_of[child] = (name, parent)
        children.setdefault(parent, []).append(child)
        if kind in ("revolute", "prismatic") and joint.find("limit") is None:
            raise ModelError(f"{where}: a {kind} joint needs <limit lower=.. upper=.. effort=.. velocity=..>")
    _check_numeric_attributes(robot, source)
    for joint in joints:
        axis = joint.find("axis")
        moving = joint.get("type") in ("revolute", "continuous", "prismatic")
        if moving and axis is not None and axis.get("xyz") and all(float(v) == 0 for v in axis.get("xyz").split()):
            raise ModelError(f"{source}: joint '{_name_of(joint)}': axis is zero; give a direction")
    roots = [name for name in (_name_of(link) for link in links) if name not in parent_of]
    if len(roots) != 1:
        what = "none (every link has a parent: a loop)" if not roots else ", ".join(roots[:5])
        raise ModelError(f"{source}: a URDF has exactly one root link (without a parent joint); found {what}; "
                         "connect the links into one tree")
    reached, stack = {roots[0]}, [roots[0]]
    while stack:
        for child in children.get(stack.pop(), []):
            if child not in reached:
                reached.add(child)
                stack.append(child)
    cut = sorted(link_names - reached)
    if cut:
        raise ModelError(f"{source}: link(s) {', '.join(cut[:5])} are not below the root '{roots[0]}' "
                         "(their joints form a loop); remove the loop")
