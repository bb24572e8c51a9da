"""Values of the HTML report's section of several targets (``calibrate`` and ``diagnose`` with several
``--tip-link LINK:POINTS``, :mod:`pincal.report.model_tree`).

A tree's REPORT.json has each target's errors under ``targets`` rather than one chain's eq-24 summary; they are
prepared here for the template partial ``templates/tree.html.j2``: per target its link, points and seen (row,
point) pairs, the RMS and largest distance [mm] of its points from the nominal model (registered to the
calibration rows), from the geometric calibration and, after ``diagnose``, from the final model with its effects;
on the held-out rows, the geometric calibration's and the final model's; on the rows ``evaluate --html`` evaluated
(its ``evaluated_targets``, :class:`pincal.report.model_tree.TreeEvaluationJson`), the reported model's. A target
whose orientation is measured (``qxN,qyN,qzN,qwN``) shows its orientation errors [deg] the same way.
"""

from __future__ import annotations

import math
from typing import Any

__all__ = ["tree_section"]


def _mm(errors: Any, key: str = "rms_mm", part: str = "position") -> str:
    """A TargetErrors' mean/RMS/max over its points [mm] (``part`` "orientation", ``key`` "rms_deg": of its
    orientation [deg]), three decimals; an em dash for what is missing."""
    value = ((errors or {}).get(part) or {}).get(key) if isinstance(errors, dict) else None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return "—"
    return f"{round(float(value), 3) + 0.0:.3f}"


def _turns(target: dict[str, Any], diagnosed: bool, held: bool) -> dict[str, Any] | None:
    """A target's orientation errors [deg] as its points' (RMS per step, max, held out), None where its
    orientation is not measured (no ``orientation_seen`` in its errors)."""
    final = target.get("calibration_errors") or {}
    if "orientation_seen" not in final:
        return None
    steps = [_mm(target.get(key), "rms_deg", "orientation") for key in
             ("nominal_errors", "geometry_errors" if diagnosed else "calibration_errors")]
    if diagnosed:
        steps.append(_mm(final, "rms_deg", "orientation"))
    return {"seen": final["orientation_seen"], "steps": steps, "max": _mm(final, "max_deg", "orientation"),
            "held": tuple(_mm(target.get(key), "rms_deg", "orientation")
                          for key in ("validation_geometry_errors", "validation_errors")) if held else None}


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
            "turns": _turns(target, diagnosed, held),
            "evaluated": _evaluated(evaluated.get((target.get("tip_link"), tuple(target.get("points") or ()))))
            if evaluated else None,
        })
    shown = None
    if evaluated:  # the evaluated file, its row count and how each of its sessions was registered
        shown = {"data": (evaluation or {}).get("data"), "rows": (evaluation or {}).get("rows"),
                 "registrations": [str(r) for r in (evaluation or {}).get("registrations") or []]}
    return {"rows": rows, "diagnosed": diagnosed, "held": held, "evaluated": shown,
            "oriented": any(r["turns"] for r in rows),
            "shared": [j for j in (doc.get("chain") or {}).get("joints") or []
                       if sum(j in (t.get("joints") or []) for t in targets if isinstance(t, dict)) > 1]}


def _evaluated(errors: Any) -> tuple[int | str, str, str]:
    """A target's (seen pairs, RMS, max [mm]) on the evaluated rows; "not seen" where none of its points was."""
    if not isinstance(errors, dict):
        return 0, "not seen", "—"
    return int(errors.get("seen") or 0), _mm(errors), _mm(errors, "max_mm")
