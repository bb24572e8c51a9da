"""What the calibration summaries print about the level: ``--level auto``'s table (each level's
cross-validated error and the level chosen), the parameters a prior holds near nominal and the
prior's scales."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from pincal.report.prior_scale import prior_scale_line

__all__ = ["level_choice_lines", "held_by_prior", "prior_scale_line"]


def level_choice_lines(choice: Mapping[str, Any]) -> list[str]:
    """The table of REPORT.json's ``level_choice`` (:meth:`pincal.fit.level_choice.LevelChoice.as_dict`)."""
    folds = choice["folds"]
    lines = [(f"level auto: {choice['scheme']}, {len(folds)} folds ({choice['seconds']:.1f} s); "
             f"held-out error: {choice['error']}"),
             f"{'level':14s} {'CV error [mm]':>14s} {'± SE [mm]':>10s}  {'kept per fold':>15s}  fold errors [mm]"]
    for entry in choice["levels"]:
        kept = [k for k in entry["kept_parameters"] if k is not None]
        kept_text = f"{min(kept)}-{max(kept)}" if kept and min(kept) != max(kept) else (str(kept[0]) if kept else "-")
        folds_text = " ".join("failed" if e is None else f"{e:.3f}" for e in entry["fold_errors_mm"])
        if entry["cv_error_mm"] is None:
            lines.append(f"{entry['level']:14s} {'not fitted on every fold':>25s}  {kept_text:>15s}  {folds_text}")
        else:
            lines.append(f"{entry['level']:14s} {entry['cv_error_mm']:14.4f} {entry['standard_error_mm']:10.4f}  "
                         f"{kept_text:>15s}  {folds_text}")
    lines.append(f"chosen: {choice['chosen']} (lowest: {choice['lowest']}; {choice['rule']}: "
                 f"<= {choice['threshold_mm']:.4f} mm)")
    return lines


def held_by_prior(ident: Mapping[str, Any], kept: int) -> str:
    """What the summary adds when the prior holds fitted parameters near nominal (not reported as kept)."""
    fitted = (ident.get("selection") or {}).get("kept", kept)
    return f"; {fitted - kept} more fitted, held near nominal by the prior" if fitted > kept else ""
