"""``package://NAME/PATH`` mesh files of a URDF: which folder holds package NAME.

Only the collision geometry reads meshes (``plan --min-distance``); the kinematics never do. A
package is looked for, in this order:

1. ``--package-dir NAME=DIR`` (DIR is the package's own folder);
2. each folder of ``ROS_PACKAGE_PATH`` (``:``-separated): the folder itself if its name is NAME,
   else NAME inside it, else NAME one level further down (as catkin workspaces hold ``src/NAME``);
3. the ament index of each prefix of ``AMENT_PREFIX_PATH``: a marker
   ``PREFIX/share/ament_index/resource_index/packages/NAME`` means ``PREFIX/share/NAME``;
4. the folders above the URDF: one named NAME, or NAME beside one (a URDF inside its package);
5. the ament index of this Python's install prefixes, ``cmeel.prefix`` in each folder of ``sys.path``:
   where pip installs the ROS-style packages of PyPI (example-robot-data, Pinocchio) with their
   ament markers, so a URDF copied out of example-robot-data (``pincal example talos``) finds its
   meshes where pip put them. Last, so that a package the user names or sources wins.

``package:///NAME/PATH`` (an empty authority: TALOS's ``talos_full_v2.urdf`` in example-robot-data
writes its meshes so) is read as ``package://NAME/PATH``, as Pinocchio reads it: its
``retrieveResourcePath`` joins what follows ``package://`` to each package folder, the leading ``/``
adding nothing. ROS's ``resource_retriever`` refuses it ("Package name must not be empty").

Every mesh is resolved to an absolute path before Pinocchio reads the file, so a missing one is
named exactly, with where it was looked for.
"""

from __future__ import annotations

import os
import re
import sys
from collections.abc import Mapping
from pathlib import Path

from lxml import etree

from pincal.errors import ModelError

__all__ = ["PACKAGE_URI", "installed_prefixes", "package_folders", "resolve_mesh", "with_resolved_meshes"]

#: ``package://NAME/PATH``, or ``package:///NAME/PATH`` read alike (module docstring).
PACKAGE_URI = re.compile(r"^package:///?([^/]+)/(.*)$")


def installed_prefixes() -> list[Path]:
    """This Python's install prefixes of ROS-style packages: ``cmeel.prefix`` in each folder of ``sys.path``."""
    found = {Path(entry) / "cmeel.prefix" for entry in sys.path if entry and (Path(entry) / "cmeel.prefix").is_dir()}
    return sorted(found)


def package_folders(name: str, urdf: Path, given: Mapping[str, Path] | None = None) -> list[Path]:
    """The folders that may be package ``name``, in search order (module docstring); not checked to exist."""
    out = [Path(given[name])] if given and name in given else []
    for entry in filter(None, os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep)):
        root = Path(entry)
        out += [root] if root.name == name else [root / name]
        if root.is_dir():
            out += sorted(child / name for child in root.iterdir() if child.is_dir())
    ament = os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)
    out += _ament_packages(name, [Path(prefix) for prefix in filter(None, ament)])
    for parent in Path(urdf).resolve().parents:
        out += [parent] if parent.name == name else [parent / name]
    return out + _ament_packages(name, installed_prefixes())


def _ament_packages(name: str, prefixes: list[Path]) -> list[Path]:
    """``PREFIX/share/NAME`` of each prefix whose ament index marks package ``name``."""
    return [prefix / "share" / name for prefix in prefixes
            if (prefix / "share" / "ament_index" / "resource_index" / "packages" / name).exists()]


def resolve_mesh(filename: str, urdf: Path, given: Mapping[str, Path] | None = None) -> Path | list[Path]:
    """The file a mesh ``filename`` of ``urdf`` names, or the paths tried when none exists."""
    match = PACKAGE_URI.match(filename)
    if match is None:
        path = Path(filename[len("file://"):] if filename.startswith("file://") else filename)
        candidates = [path if path.is_absolute() else Path(urdf).resolve().parent / path]
    else:
        name, relative = match.groups()
        candidates = [folder / relative for folder in package_folders(name, urdf, given)]
    for candidate in candidates:
        if candidate.is_file():
            return candidate.resolve()
    return candidates


def with_resolved_meshes(text: str, urdf: Path, given: Mapping[str, Path] | None = None,
                         element: str = "collision") -> str:
    """The URDF ``text`` (of file ``urdf``) with every mesh of its ``element``s as an absolute path.

    Raises:
        ModelError: a mesh that is in none of the places searched, named as the URDF writes it.
    """
    root = etree.fromstring(text.encode("utf-8"))
    for mesh in root.iter("mesh"):
        if mesh.getparent() is None or mesh.getparent().getparent() is None:
            continue
        if mesh.getparent().getparent().tag != element or not mesh.get("filename"):
            continue
        found = resolve_mesh(mesh.get("filename"), urdf, given)
        if isinstance(found, list):
            match = PACKAGE_URI.match(mesh.get("filename"))
            hint = (f"; give --package-dir {match.group(1)}=DIR (the package's folder), or set ROS_PACKAGE_PATH"
                    if match else "")
            tried = ", ".join(str(p) for p in found[:4]) + (f" and {len(found) - 4} more" if len(found) > 4 else "")
            raise ModelError(f"{urdf}: {element} mesh '{mesh.get('filename')}' not found (looked at {tried}){hint}")
        mesh.set("filename", str(found))
    return etree.tostring(root, encoding="unicode")
