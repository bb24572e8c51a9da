"""``pincal demo``: the paper's experiment simulated, calibrated with Methods 1–3 and evaluated."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from pincal.fit.metrics import PoseErrors, pose_errors
from pincal.fit.registration import register_orientations, register_points
from pincal.model.chain import KinematicChain, pose_from_xyz_rpy
from pincal.robots import KUKA_FLANGE_LINK, kuka_lwr4plus_urdf
from pincal.workflows.calibration import calibrate_files
from pincal.workflows.evaluation import evaluate_files
from pincal.workflows.settings import CalibrateSettings
from pincal.workflows.simulation import simulate_to_directory

if TYPE_CHECKING:
    from pincal.simulation.paper import SimulatedExperiment, SimulationSettings

__all__ = ["DemoRow", "run_demo"]


@dataclass(frozen=True)
class DemoRow:
    """One line of the demo's comparison table."""

    label: str
    calibration: PoseErrors
    validation: PoseErrors
    seconds: float


def run_demo(out_dir: str | Path, settings: SimulationSettings, deviations: str = "large") -> list[DemoRow]:
    """Simulate → calibrate with Methods 1–3 → evaluate on held-out poses.

    Writes the simulated data, one corrected URDF and report per method into
    ``out_dir``; returns the comparison rows (nominal model first).
    """
    out = Path(out_dir)
    experiment, truth = simulate_to_directory(out, deviations, settings)
    urdf = kuka_lwr4plus_urdf()
    tool = pose_from_xyz_rpy(truth["tool"]["xyz_m"], truth["tool"]["rpy_rad"])
    rows = [_nominal_row(urdf, experiment, tool)]
    for method in (1, 2, 3):
        run = calibrate_files(
            urdf,
            out / "calibration.csv",
            out / f"kuka_lwr4plus_method{method}.urdf",
            out / f"REPORT_method{method}.json",
            CalibrateSettings(KUKA_FLANGE_LINK, level="dh", method=method, tool_pose=tool),
        )
        evaluation = evaluate_files(
            out / f"kuka_lwr4plus_method{method}.urdf",
            out / f"REPORT_method{method}.json",
            out / "validation.csv",
        )
        rows.append(DemoRow(f"Method {method}", run.errors, evaluation.errors, run.seconds))
    return rows


def _nominal_row(urdf: Path, experiment: SimulatedExperiment, tool: np.ndarray) -> DemoRow:
    """The uncalibrated model, registered to the data like Method 2 would."""
    chain = KinematicChain.from_urdf(urdf, KUKA_FLANGE_LINK, tool=tool)
    cal = experiment.calibration.with_role("calibration")
    poses = chain.poses(cal.q)
    points = cal.points[:, 0, :]
    reg1 = register_points(poses.tool_positions, points)
    reg2 = register_orientations(poses.tool_rotations, cal.rotations, poses.tool_positions, points)
    return DemoRow(
        "nominal (Table 1)",
        pose_errors(chain, cal, reg1, reg2),
        pose_errors(chain, experiment.validation, reg1, reg2),
        0.0,
    )
