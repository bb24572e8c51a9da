"""PNG figures of a diagnosis: each adopted effect against its driver, and the
error distributions before and after (matplotlib's object API on the Agg
canvas: no pyplot, no global figure state, no GUI backend)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from pincal.diagnosis.diagnose import Diagnosis
from pincal.outputs import replacing


def _joint_unit(label: str) -> str:
    return "rad" if "torso" not in label else "m"


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
        fig = Figure(figsize=(6.4, 4.2), layout="tight")
        ax = fig.subplots()
        order = np.argsort(step.driver, kind="stable")
        unit = _joint_unit(step.effect.joint or "")
        ax.plot(step.driver, step.joint_residual * 1000.0, "o", ms=4, alpha=0.7,
                label="fitted shift + remaining residual, per row")
        ax.plot(step.driver[order], step.fitted_shift[order] * 1000.0, "-", lw=2, label=f"fitted {step.effect.type}")
        ax.set_xlabel(step.driver_label)
        ax.set_ylabel(f"joint shift of {step.effect.joint} [m{unit}]")
        ax.set_title(f"step {number}: {step.effect.label} (ΔBIC {step.delta_bic:.0f})")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
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
    fig = Figure(figsize=(6.0 * len(panels), 4.0), layout="tight")
    axes = fig.subplots(1, len(panels), squeeze=False)
    for ax, (title, before, after) in zip(axes[0], panels):
        b, a = before.position_m.ravel() * 1000.0, after.position_m.ravel() * 1000.0
        bins = np.linspace(0.0, max(b.max(), a.max()) * 1.05, 30)
        ax.hist(b, bins=bins, alpha=0.5, label=f"geometry only (RMS {before.position.rms:.3f} mm)")
        ax.hist(a, bins=bins, alpha=0.5, label=f"with effects (RMS {after.position.rms:.3f} mm)")
        ax.set_xlabel("point position error [mm]")
        ax.set_ylabel("count")
        ax.set_title(title)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    path = out / "diagnose_errors_before_after.png"
    _save(fig, path)
    return path


def _save(fig: Figure, path: Path) -> None:
    """Draw ``fig`` once (the tight layout is applied during that draw) into ``path``."""
    FigureCanvasAgg(fig)
    with replacing(path, "wb") as handle:
        fig.savefig(handle, format="png", dpi=120)
