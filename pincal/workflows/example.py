"""``pincal example NAME --out DIR``: copy a measurement set shipped with pincal out of the installed package.

The docs' commands read ``data/tiago_mocap/…``, ``data/mukca/…`` and ``data/lwr_bag/…``; in a clone ``data/`` is
there, after ``pip install`` it is not: ``pincal example tiago_mocap --out data`` puts the set (its
CSV files, README with the provenance, licence) at the same relative path, so those commands run
as written; ``pincal example examples --out .`` puts the example scripts at ``./examples/``, beside
that ``data/``, where they look. ``pincal example talos`` is generated, not shipped: TALOS's upper body
(example-robot-data) measured by a simulated motion capture, a marker on each gripper (:func:`write_talos`).
The set is made in a temporary sibling folder and renamed into place: it appears
whole or not at all, and an existing folder is never overwritten.
"""

from __future__ import annotations

import importlib.resources
import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

from pincal._version import __version__
from pincal.errors import PincalError
from pincal.outputs import write_text

if TYPE_CHECKING:
    from pincal.simulation.humanoid import HumanoidSettings

__all__ = ["EXAMPLES", "GENERATED", "dataset_folder", "copy_example", "write_talos"]

#: The shipped sets and what each holds.
EXAMPLES = {
    "tiago_mocap": "TIAGo arm, two Qualisys motion-capture sessions (4 markers): calibrate, evaluate, diagnose, plan",
    "mukca": "KUKA LBR iiwa 14 and Franka Panda on a socket fixture (MUKCa): calibrate --fixture, evaluate --fixture",
    "lwr_bag": "KUKA LWR 4+ simulated session as a ROS 2 bag (MCAP) and held-out rows: extract, calibrate, evaluate",
    "urdf": "the packaged KUKA LWR 4+ URDF (the paper's Table 1), as urdf/kuka_lwr4plus.urdf of a clone",
    "examples": "the example scripts (Python API; they read ./data): --out . gives the docs' examples/*.py",
    "talos": "TALOS's upper body (example-robot-data) and simulated motion capture of a marker on each gripper, "
             "joint placements off and joints giving under unmodelled loads: calibrate and evaluate several targets",
}
#: The sets made on the spot (nothing shipped: simulated, from a URDF of example-robot-data).
GENERATED = ("talos",)


def dataset_folder(name: str) -> Path:
    """The installed folder of the shipped set ``name`` (:data:`EXAMPLES`)."""
    if name not in EXAMPLES or name in GENERATED:
        shipped = [n for n in EXAMPLES if n not in GENERATED]
        raise PincalError(f"no shipped example '{name}'; the shipped examples are: {', '.join(shipped)}")
    if name == "urdf":  # the robots pincal ships (pincal.robots): the docs' urdf/ of a clone
        return Path(str(importlib.resources.files("pincal.robots")))
    return Path(str(importlib.resources.files("pincal.datasets"))) / name


def copy_example(name: str, out_dir: str | Path) -> tuple[Path, list[Path]]:
    """Copy the set ``name`` to ``out_dir/name`` (make it, for a :data:`GENERATED` one); returns that folder and its
    files (relative).

    Raises:
        PincalError: an unknown name, or ``out_dir/name`` already exists (never overwritten).
    """
    source = None if name in GENERATED else dataset_folder(name)
    target = Path(out_dir) / name
    if target.exists() or target.is_symlink():
        raise PincalError(f"{target}: exists; refusing to overwrite it: remove it or give another --out")
    target.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{name}.", dir=target.parent))
    try:
        if source is None:
            write_talos(staging / name)
        else:
            shutil.copytree(source, staging / name, ignore=shutil.ignore_patterns("__pycache__", "__init__.py"))
        os.replace(staging / name, target)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return target, sorted(p.relative_to(target) for p in target.rglob("*") if p.is_file())


def write_talos(folder: Path) -> None:
    """Make ``folder`` and write TALOS's simulated set into it (:mod:`pincal.simulation.humanoid`, its defaults):
    the URDF (``talos_full_v2.urdf``, as example-robot-data ships it), ``calibration.csv`` and ``validation.csv``
    (held-out rows), ``truth.json`` (what was simulated, the true values) and ``README.md``."""
    from pincal.measurements.csv_v1 import write_measurements
    from pincal.simulation.humanoid import HumanoidSettings, simulate_humanoid, talos_description

    settings = HumanoidSettings()
    data = simulate_humanoid(settings)
    folder.mkdir(parents=True)
    shutil.copyfile(talos_description().path, folder / "talos_full_v2.urdf")
    write_measurements(folder / "calibration.csv", data.calibration)
    write_measurements(folder / "validation.csv", data.validation)
    truth = {
        "pincal_version": __version__,
        "robot": "TALOS (PAL Robotics), example-robot-data talos_data/robots/talos_full_v2.urdf",
        "targets": list(settings.targets),
        "rows": {"calibration": settings.rows, "validation": settings.held_out_rows},
        "sigma_pos_mm": settings.sigma_pos_mm,
        "compliance_rad_per_nm": dict(settings.compliance),
        "payload_kg_per_marker": settings.payload_kg,
        "marker_m": list(settings.marker_m),
        "deflection_mm": {"rms": data.deflection_mm[0], "max": data.deflection_mm[1]},
        "registration": {"rotation": data.registration.rotation.tolist(),
                         "translation_m": data.registration.translation.tolist()},
        "placement_errors": dict(zip(data.parameter_names, data.truth.tolist())),
        "seed": settings.seed,
    }
    write_text(folder / "truth.json", json.dumps(truth, indent=2) + "\n")
    write_text(folder / "README.md", _talos_readme(settings))


def _talos_readme(settings: HumanoidSettings) -> str:
    """The README of ``pincal example talos``: provenance, what was simulated and the commands to run."""
    joints = ", ".join(f"{name} {value:g}" for name, value in settings.compliance)
    return f"""# TALOS upper body, simulated motion capture (pincal example talos)

Made by `pincal example talos` with `pincal.simulation.humanoid` (seed {settings.seed}): nothing here was measured.

- `talos_full_v2.urdf`: TALOS as example-robot-data ships it (robots/talos_data; upstream
  https://github.com/pal-robotics/talos_robot, PAL Robotics, licence Apache-2.0), unchanged.
- `calibration.csv` ({settings.rows} rows) and `validation.csv` ({settings.held_out_rows} held-out rows, role
  `validation`): the joint readings of the torso (2 joints), both arms (7 each) and both grippers
  (`gripper_*_joint`; the finger joints follow it by `<mimic>` and have no column), and a marker on each
  gripper's first fingertip seen by a motion capture (point 1 left, point 2 right; {settings.sigma_pos_mm} mm
  per axis).
- The true robot: every joint placement off by N(0, {settings.deviation_mm} mm) and N(0, {settings.deviation_mrad}
  mrad); joints giving under their gravity load, c [rad/(N·m)]: {joints}, loaded by the URDF's masses plus
  {settings.payload_kg} kg at each marker the URDF does not have. `truth.json` has every value.

Calibrate both arms in one fit and check it on the held-out rows (the set made with the default `--out data`):

    pincal calibrate data/talos/talos_full_v2.urdf data/talos/calibration.csv \\
        --tip-link gripper_left_fingertip_1_link:1 --tip-link gripper_right_fingertip_1_link:2 \\
        --out talos_calibrated.urdf --report talos_report/REPORT.json
    pincal evaluate talos_calibrated.urdf talos_report/REPORT.json data/talos/validation.csv

(pincal's docs, "Whole robots", walk through it.)
"""
