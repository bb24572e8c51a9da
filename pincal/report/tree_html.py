"""Values of the HTML report's section of several targets (``calibrate`` and ``diagnose`` with several
``--tip-link LINK:POINTS``, :mod:`pincal.report.model_tree`).

A tree's REPORT.json has each target's errors under ``targets`` rather than one chain's eq-24 summary; they are
prepared here for the template partial ``templates/tree.html.j2``: per target its link, points and seen (row,
point) pairs, the RMS and largest distance [mm] of its points from the nominal model (registered to the
calibration rows), from the geometric calibration and, after ``diagnose``, from the final model with its effects;
on the held-out rows, the geometric calibration's and the final model's; on the rows ``evaluate --html`` evaluated
(its ``evaluated_targets``, :class:`pincal.report.model_tree.TreeEvaluationJson`), the reported model's.
"""

from __future__ import annotations

import math
from typing import Any

__all__ = ["tree_section"]


def _mm(errors: Any, key: str = "rms_mm") -> str:
    """A TargetErrors' mean/RMS/max over its points [mm], three decimals; an em dash for what is missing."""
    value = ((errors or {}).get("position") or {}).get(key) if isinstance(errors, dict) else None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return "—"
    return f"{round(float(value), 3) + 0.0:.3f}"


def tree_section(doc: dict[str, Any], evaluation: dict[str, Any] | None = None) -> dict[str, Any] | None:
    """Everything the tree partial shows, from a REPORT.json ``doc`` with ``targets``; None for any other.
    ``evaluation``: what ``evaluate --html`` measured (``evaluated_targets``, ``registrations``, ``rows``,
    ``data``), each target's errors on those rows shown beside its own; None: none."""
    targets = doc.get("targets")
    if not isinstance(targets, list):
        return None
    evaluated = {(e.get("tip_link"), tuple(e.get("points") or ())): e.get("errors")
                 for e in (evaluation or {}).get("evaluated_targets") or [] if isinstance(e, dict)}
    diagnosed = any("geometry_errors" in t for t in targets if isinstance(t, dict))
    held = any(t.get("validation_errors") for t in targets if isinstance(t, dict))
    rows = []
    for target in targets:
        if not isinstance(target, dict):
            continue
        calibrated = target.get("geometry_errors") if diagnosed else target.get("calibration_errors")
        steps = [("nominal", _mm(target.get("nominal_errors"))), ("calibrated geometry", _mm(calibrated))]
        if diagnosed:
            steps.append(("with effects", _mm(target.get("calibration_errors"))))
        rows.append({
            "link": target.get("tip_link"), "points": ", ".join(str(p) for p in target.get("points") or []),
            "joints": len(target.get("joints") or []), "seen": (target.get("calibration_errors") or {}).get("seen"),
            "steps": steps, "max": _mm(target.get("calibration_errors"), "max_mm"),
            "held": (_mm(target.get("validation_geometry_errors")), _mm(target.get("validation_errors")))
            if held else None,
            "held_seen": (target.get("validation_errors") or {}).get("seen") if held else None,
            "evaluated": _evaluated(evaluated.get((target.get("tip_link"), tuple(target.get("points") or ()))))
            if evaluated else None,
        })
    shown = None
    if evaluated:  # the evaluated file, its row count and how each of its sessions was registered
        shown = {"data": (evaluation or {}).get("data"), "rows": (evaluation or {}).get("rows"),
                 "registrations": [str(r) for r in (evaluation or {}).get("registrations") or []]}
    return {"rows": rows, "diagnosed": diagnosed, "held": held, "evaluated": shown,
            "shared": [j for j in (doc.get("chain") or {}).get("joints") or []
                       if sum(j in (t.get("joints") or []) for t in targets if isinstance(t, dict)) > 1]}


def _evaluated(errors: Any) -> tuple[int | str, str, str]:
    """A target's (seen pairs, RMS, max [mm]) on the evaluated rows; "not seen" where none of its points was."""
    if not isinstance(errors, dict):
        return 0, "not seen", "—"
    return int(errors.get("seen") or 0), _mm(errors), _mm(errors, "max_mm")
