"""PNG figures of a diagnosis: each adopted effect against its driver, and the
error distributions before and after (matplotlib's object API on the Agg
canvas: no pyplot, no global figure state, no GUI backend).

An effect is drawn as its function — evaluated by :func:`effect_curve` on
:data:`GRID_POINTS` values over its driver's range in the data (the joint
reading for ``cyclic`` and ``encoder_scale``, the gravity torque for
``compliance`` and a gravity backlash, the approach flank −1/+1 for an approach
backlash) — so a backlash is a step at the flank change and a cyclic error a
smooth curve, with each row's partial residual over it. Colours are
:mod:`pincal.palette`'s, as on the HTML report."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from pincal.diagnosis.diagnose import Diagnosis
from pincal.figure_margins import BOTTOM_10PT_IN, TITLE_IN, fixed_margins, y_label_room_in
from pincal.model.effects import Effect
from pincal.outputs import replacing
from pincal.palette import CALIBRATED, WITH_EFFECTS

__all__ = ["DATA_COLOUR", "GRID_POINTS", "effect_curve", "plot_diagnosis"]

#: The rows' partial residuals: data, not a model.
DATA_COLOUR = "#33404d"

#: Values of the driver an effect's function is evaluated at, over its range in the data.
GRID_POINTS = 400


def _basis(effect: Effect, driver: np.ndarray) -> np.ndarray:
    """The effect's basis as a function of its driver (:func:`pincal.model.effects.joint_basis`
    with the driver of :func:`pincal.diagnosis.structure.partial_residual`), (n, n_values)."""
    if effect.type == "cyclic":
        return np.column_stack([np.sin(effect.harmonic * driver), np.cos(effect.harmonic * driver)])
    if effect.type == "backlash":
        return np.sign(driver)[:, None]
    return np.asarray(driver, dtype=float)[:, None]  # compliance, encoder_scale: linear in the driver


def effect_curve(effect: Effect, driver: np.ndarray, fitted: np.ndarray,
                 points: int = GRID_POINTS) -> tuple[np.ndarray, np.ndarray]:
    """The adopted effect's shift as a function of its driver on ``points`` values spanning
    the driver's range in the data (5 % beyond each end; an approach flank: −1.25 … 1.25),
    with the values that give the rows' ``fitted`` shifts."""
    driver = np.asarray(driver, dtype=float)
    low, high = float(np.min(driver)), float(np.max(driver))
    pad = 0.25 if effect.type == "backlash" and effect.source == "approach" else 0.05 * max(high - low, 1e-9)
    if effect.type == "backlash":  # the step sits at 0: the grid always spans it
        low, high = min(low, -pad), max(high, pad)
    grid = np.linspace(low - pad, high + pad, points)
    values = np.linalg.lstsq(_basis(effect, driver), np.asarray(fitted, dtype=float), rcond=None)[0]
    return grid, _basis(effect, grid) @ values


def plot_diagnosis(diagnosis: Diagnosis, out_dir: str | Path) -> list[Path]:
    """Write one figure per adopted joint effect and one of error distributions; return the paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for number, step in enumerate(diagnosis.steps, start=1):
        if step.driver is None:
            continue
        # set together with the driver (pincal.diagnosis.structure.partial_residual)
        assert step.joint_residual is not None and step.fitted_shift is not None
        fig = Figure(figsize=(6.4, 4.2))
        ax = fig.subplots()
        grid, curve = effect_curve(step.effect, step.driver, step.fitted_shift)
        ax.plot(step.driver, step.joint_residual * 1000.0, "o", ms=4, alpha=0.6, color=DATA_COLOUR,
                label="fitted shift + remaining residual, per row")
        ax.plot(grid, curve * 1000.0, "-", lw=2, color=WITH_EFFECTS, label=f"fitted {step.effect.type}")
        ax.set_xlabel(step.driver_label)
        ax.set_ylabel(f"joint shift of {step.effect.joint} [m{step.shift_unit}]")
        ax.set_title(f"step {number}: {step.effect.label} (ΔBIC {step.delta_bic:.0f})")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        fig.subplots_adjust(**fixed_margins(6.4, 4.2, y_label_room_in(ax), top_in=TITLE_IN, bottom_in=BOTTOM_10PT_IN))
        path = out / f"diagnose_step{number}_{step.effect.label.replace(':', '_')}.png"
        _save(fig, path)
        paths.append(path)
    paths.append(_error_distributions(diagnosis, out))
    return paths


def _error_distributions(diagnosis: Diagnosis, out: Path) -> Path:
    first = diagnosis.steps[0] if diagnosis.steps else None
    panels = [("calibration rows", first.calibration_before if first else diagnosis.calibration_errors,
               diagnosis.calibration_errors)]
    if diagnosis.heldout_errors is not None:
        held_before = first.heldout_before if first else diagnosis.heldout_errors
        assert held_before is not None  # every step has held-out errors when the diagnosis has
        panels.append(("held-out rows", held_before, diagnosis.heldout_errors))
    width = 6.0 * len(panels)
    fig = Figure(figsize=(width, 4.0))
    axes = fig.subplots(1, len(panels), squeeze=False)
    for ax, (title, before, after) in zip(axes[0], panels):
        b, a = before.position_m.ravel() * 1000.0, after.position_m.ravel() * 1000.0
        bins = np.linspace(0.0, max(b.max(), a.max()) * 1.05, 30)
        # one filled outline per histogram: the look of touching bars, at one patch instead of one per bin
        ax.hist(b, bins=bins, histtype="stepfilled", alpha=0.5,
                color=CALIBRATED, label=f"geometry only (RMS {before.position.rms:.3f} mm)")
        ax.hist(a, bins=bins, histtype="stepfilled", alpha=0.5,
                color=WITH_EFFECTS, label=f"with effects (RMS {after.position.rms:.3f} mm)")
        ax.set_xlabel("point position error [mm]")
        ax.set_ylabel("count")
        ax.set_title(title)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    room = max(y_label_room_in(ax) for ax in axes[0])  # each panel's y labels: the left margin, and between panels
    fig.subplots_adjust(**fixed_margins(width, 4.0, room, gap_in=room + 0.1, panels=len(panels), across=True,
                                        top_in=TITLE_IN, bottom_in=BOTTOM_10PT_IN))
    path = out / "diagnose_errors_before_after.png"
    _save(fig, path)
    return path


def _save(fig: Figure, path: Path) -> None:
    """Draw ``fig`` once into ``path``."""
    FigureCanvasAgg(fig)
    with replacing(path, "wb") as handle:
        fig.savefig(handle, format="png", dpi=120)
