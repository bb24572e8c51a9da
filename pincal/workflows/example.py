"""``pincal example NAME --out DIR``: copy a measurement set shipped with pincal out of the installed package.

The docs' commands read ``data/tiago_mocap/…``, ``data/mukca/…`` and ``data/lwr_bag/…``; in a clone ``data/`` is
there, after ``pip install`` it is not: ``pincal example tiago_mocap --out data`` puts the set (its
CSV files, README with the provenance, licence) at the same relative path, so those commands run
as written; ``pincal example examples --out .`` puts the example scripts at ``./examples/``, beside
that ``data/``, where they look. The set is copied into a temporary sibling folder and renamed into place: it appears
whole or not at all, and an existing folder is never overwritten.
"""

from __future__ import annotations

import importlib.resources
import os
import shutil
import tempfile
from pathlib import Path

from pincal.errors import PincalError

__all__ = ["EXAMPLES", "dataset_folder", "copy_example"]

#: The shipped sets and what each holds.
EXAMPLES = {
    "tiago_mocap": "TIAGo arm, two Qualisys motion-capture sessions (4 markers): calibrate, evaluate, diagnose, plan",
    "mukca": "KUKA LBR iiwa 14 and Franka Panda on a socket fixture (MUKCa): calibrate --fixture, evaluate --fixture",
    "lwr_bag": "KUKA LWR 4+ simulated session as a ROS 2 bag (MCAP) and held-out rows: extract, calibrate, evaluate",
    "urdf": "the packaged KUKA LWR 4+ URDF (the paper's Table 1), as urdf/kuka_lwr4plus.urdf of a clone",
    "examples": "the example scripts (Python API; they read ./data): --out . gives the docs' examples/*.py",
}


def dataset_folder(name: str) -> Path:
    """The installed folder of the shipped set ``name`` (:data:`EXAMPLES`)."""
    if name not in EXAMPLES:
        raise PincalError(f"no example '{name}'; the examples are: {', '.join(EXAMPLES)}")
    if name == "urdf":  # the robots pincal ships (pincal.robots): the docs' urdf/ of a clone
        return Path(str(importlib.resources.files("pincal.robots")))
    return Path(str(importlib.resources.files("pincal.datasets"))) / name


def copy_example(name: str, out_dir: str | Path) -> tuple[Path, list[Path]]:
    """Copy the set ``name`` to ``out_dir/name``; returns that folder and its files (relative).

    Raises:
        PincalError: an unknown name, or ``out_dir/name`` already exists (never overwritten).
    """
    source = dataset_folder(name)
    target = Path(out_dir) / name
    if target.exists() or target.is_symlink():
        raise PincalError(f"{target}: exists; refusing to overwrite it: remove it or give another --out")
    target.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{name}.", dir=target.parent))
    try:
        shutil.copytree(source, staging / name, ignore=shutil.ignore_patterns("__pycache__", "__init__.py"))
        os.replace(staging / name, target)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return target, sorted(p.relative_to(target) for p in target.rglob("*") if p.is_file())
