"""Before/after figures of docs/diagnose.md's walk-through of temperature and pauses.

Usage (after the walk-through's ``pincal simulate`` commands wrote ``warm/`` and ``paused/``)::

    python scripts/thermal_plots.py warm paused --out docs/diagnose

Each folder is diagnosed as ``pincal diagnose`` does (level full, the tool known, its
``validation.csv`` held out) and drawn from the final model:

* ``diagnose_thermal_before_after.png`` — per calibration row, the residual along the direction
  from the robot base to the measured point (in the sensor frame), per metre of that distance
  [µm/m], against the row's temperature: without the fitted expansion (the same model, α = 0) it
  follows α (T − T_ref); with it, the noise;
* ``diagnose_pause_before_after.png`` — per calibration row, the residual along the sensor's y
  [µm] against the time, without and with the fitted step.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from pincal.diagnosis.conditions import read_readings
from pincal.diagnosis.diagnose import DiagnoseOptions, diagnose
from pincal.fit.chain_calibration import ChainFitOptions, calibrate_chain
from pincal.measurements.csv_v1 import read_measurements
from pincal.model.chain import KinematicChain, pose_from_xyz_rpy
from pincal.model.drift import time_column
from pincal.palette import CALIBRATED, WITH_EFFECTS
from pincal.robots import KUKA_FLANGE_LINK, kuka_lwr4plus_urdf
from pincal.simulation.paper import DEFAULT_TOOL_RPY, DEFAULT_TOOL_XYZ


def _diagnosed(folder: Path):
    """diagnose's final fit of ``folder``'s simulated session, its rows and their times [s]."""
    chain = KinematicChain.from_urdf(kuka_lwr4plus_urdf(), KUKA_FLANGE_LINK,
                                     tool=pose_from_xyz_rpy(DEFAULT_TOOL_XYZ, DEFAULT_TOOL_RPY))
    data, _ = read_measurements(folder / "calibration.csv", chain.joint_specs)
    held, _ = read_measurements(folder / "validation.csv", chain.joint_specs)
    calibration = calibrate_chain(chain, data, "full", ChainFitOptions(tool_known=True))
    result = diagnose(chain, calibration, data, heldout=held,
                      options=DiagnoseOptions(time=time_column(data), heldout_time=time_column(held),
                                              readings=read_readings(data, held, None)))
    return result, time_column(data)[calibration.used_index]


def _residuals(result, kind: str) -> tuple[np.ndarray, np.ndarray]:
    """Measured − modelled points (K, 3) [m] of the final model without and with the effect ``kind``."""
    objective, x = result.objective, result.solution_x
    index = next(i for i, (effect, _, _) in enumerate(result.effects) if effect.type == kind)
    without = x.copy()
    without[objective.effect_slices[index]] = 0.0
    return tuple((objective.g - objective.predicted_points(v))[:, 0, :] for v in (without, x))


def _thermal(folder: Path, out: Path) -> Path:
    result, _ = _diagnosed(folder)
    objective, x = result.objective, result.solution_x
    _, _, target, world = objective.state(x)
    omega, _ = objective.row_frames(target)
    radial = world[:, 0, :] @ np.asarray(omega).T  # base origin → point, in the sensor frame [m]
    length = np.linalg.norm(radial, axis=1)
    temperature = result.conditions.temperature
    alpha = float(next(v for e, v, _ in result.effects if e.type == "thermal")[0])
    fig, ax = _before_after(temperature, [np.einsum("ki,ki->k", r, radial) / length**2 * 1e6
                                          for r in _residuals(result, "thermal")], "the expansion")
    grid = np.linspace(temperature.min(), temperature.max(), 50)
    ax.plot(grid, alpha * (grid - result.conditions.temperature_range.mean) * 1e6, "-", color="black",
            label=f"α (T − T_ref), α = {alpha * 1e6:.2f} µm/m/K")
    return _save(fig, ax, out / "diagnose_thermal_before_after.png", "row temperature [°C]",
                 "residual along base → point [µm per m]", "thermal expansion: calibration rows")


def _pause(folder: Path, out: Path) -> Path:
    result, time = _diagnosed(folder)
    hours = (time - time.min()) / 3600.0
    fig, ax = _before_after(hours, [r[:, 1] * 1e6 for r in _residuals(result, "pause_step")], "the step")
    for pause in result.conditions.pauses:
        ax.axvspan((pause.before - time.min()) / 3600.0, (pause.after - time.min()) / 3600.0, color="0.9",
                   label=f"pause {pause.number} (no rows)")
    return _save(fig, ax, out / "diagnose_pause_before_after.png", "time [h]", "residual along the sensor's y [µm]",
                 "a registration step across a pause: calibration rows")


def _before_after(x: np.ndarray, residuals, what: str):
    """A figure of the rows' residuals without and with the fitted ``what`` against ``x``."""
    fig = Figure(figsize=(6.4, 4.2), layout="tight")
    ax = fig.subplots()
    for y, colour, label in zip(residuals, (CALIBRATED, WITH_EFFECTS), (f"without {what}", f"with {what} fitted")):
        ax.plot(x, y, "o", ms=3, alpha=0.6, color=colour, label=label)
    return fig, ax


def _save(fig: Figure, ax, path: Path, xlabel: str, ylabel: str, title: str) -> Path:
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    FigureCanvasAgg(fig)
    fig.savefig(path, format="png", dpi=110)
    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("warm", type=Path, help="pincal simulate --effect thermal:... output folder")
    parser.add_argument("paused", type=Path, help="pincal simulate --effect pause_step:... output folder")
    parser.add_argument("--out", type=Path, default=Path("."), help="folder of the PNGs (default: here)")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    for path in (_thermal(args.warm, args.out), _pause(args.paused, args.out)):
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
