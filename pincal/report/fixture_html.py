"""Values of the HTML report's socket-fixture sections (``calibrate --fixture``, ``evaluate --fixture``).

A socket-fixture REPORT.json (:mod:`pincal.report.fixture`) has no registration
and no eq-24 errors; what it has is prepared here for the template partial
``templates/fixture.html.j2``: the consistency and distortion of each placement
before (nominal URDF) and after (calibrated), on the calibration placements and,
from ``evaluate --fixture``, on the evaluated ones; the ball centre with its
standard deviation; the sockets and their distances; and of each placement what
its sockets determine — each socket's centre in the URDF root frame, and the
socket line's direction where the turn about it is not determined; and each
placement predicted by models that have not seen it — left out in turn by the
calibration (``fixture.held_out_placements``), or evaluated — nominal → calibrated,
flagged where worse (:mod:`pincal.fit.placement_check`). Lengths are
shown in mm with three decimals (the CLI's), angles in degrees.
"""

from __future__ import annotations

import math
from typing import Any

from scipy.spatial.transform import Rotation

__all__ = ["fixture_section"]


def _mm(value: Any) -> str:
    """A length [m] in mm, three decimals; an em dash for what is missing."""
    return _decimals(None if value is None else float(value) * 1000.0)


def _decimals(value: Any, digits: int = 3) -> str:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return "—"
    return f"{round(float(value), digits) + 0.0:.{digits}f}"


def _vector_mm(values: Any) -> list[str]:
    return [_mm(v) for v in values] if isinstance(values, list) else ["—", "—", "—"]


def _metric_set(label: str, before: dict | None, after: dict | None, not_held_out=()) -> dict[str, Any] | None:
    """Per placement and over all: consistency and distortion before → after [mm]."""
    if not isinstance(after, dict):
        return None
    earlier = {p.get("placement"): p for p in (before or {}).get("placements") or []}
    rows = []
    for placement in after.get("placements") or []:
        name = placement.get("placement")
        b = earlier.get(name) or {}
        rows.append({
            "placement": name, "rows": placement.get("rows"), "held_out": name not in not_held_out,
            "consistency": (_decimals(b.get("consistency_mm")), _decimals(placement.get("consistency_mm"))),
            "distortion": (_decimals(b.get("distortion_mm")), _decimals(placement.get("distortion_mm"))),
            "distances": [f"{d.get('a')}–{d.get('b')}: {_decimals(d.get('computed_mm'))} mm (fixture "
                          f"{_decimals(d.get('fixture_mm'))} mm)" for d in placement.get("socket_distances") or []],
        })
    before = before or {}
    return {
        "label": label, "rows": rows, "has_before": bool(before),
        "all": {"consistency": (_decimals(before.get("consistency_mm")), _decimals(after.get("consistency_mm"))),
                "distortion": (_decimals(before.get("distortion_mm")), _decimals(after.get("distortion_mm")))},
    }


def _placement(entry: dict) -> dict[str, Any]:
    """A placement's rows, its sockets in the root frame and the part of its pose the sockets determine."""
    sockets = [{"name": s.get("name"), "position": _vector_mm(s.get("position_m")), "std": _vector_mm(s.get("std_m"))}
               for s in entry.get("sockets") or []]
    line = entry.get("line_direction")
    if isinstance(line, list):
        determined = ("position and the direction of the socket line, (" + ", ".join(_decimals(v, 4) for v in line)
                      + ") in the root frame")
        undetermined = entry.get("not_determined") or "the turn about the socket line"
    else:
        quaternion = entry.get("rotation_xyzw")
        rpy = (Rotation.from_quat(quaternion).as_euler("xyz", degrees=True) if isinstance(quaternion, list)
               else [None] * 3)
        determined = ("the whole pose: translation (" + ", ".join(_vector_mm(entry.get("translation_m")))
                      + ") mm, roll, pitch, yaw (" + ", ".join(_decimals(float(v)) if v is not None else "—"
                                                          for v in rpy) + ") deg")
        undetermined = None
    return {"name": entry.get("name"), "rows": entry.get("rows"), "sockets": sockets, "determined": determined,
            "undetermined": undetermined}


def _predictions(label: str, entries: Any) -> dict[str, Any] | None:
    """Placements predicted without them: nominal → calibrated [mm], ratio and bound, worse or not."""
    if not isinstance(entries, list) or not entries:
        return None
    rows = [{"placement": e.get("placement"), "rows": e.get("rows"),
             "errors": (_decimals(e.get("nominal_mm")), _decimals(e.get("calibrated_mm"))),
             "ratio": _decimals(e.get("ratio"), 2), "bound": _decimals(e.get("bound"), 2),
             "worse": bool(e.get("worse")), "failure": e.get("failure")} for e in entries if isinstance(e, dict)]
    return {"label": label, "rows": rows}


def fixture_section(doc: dict[str, Any], evaluation: dict[str, Any] | None = None) -> dict[str, Any]:
    """Everything the fixture partial shows, from a fixture REPORT.json ``doc``.

    Args:
        doc: the report (its ``fixture`` block, ``tool`` and ``sources``).
        evaluation: what ``evaluate --fixture`` measured with it, ``{"urdf", "data",
            "fixture": FixtureEvaluation.as_dict()}`` (:mod:`pincal.cli.fixture`), or None.
    """
    block = doc["fixture"]
    training = block.get("training") or {}
    sets = [_metric_set("calibration placements", training.get("before"), training.get("after"))]
    measured = (evaluation or {}).get("fixture")
    if isinstance(measured, dict):
        seen = tuple(measured.get("not_held_out") or ())
        label = "evaluated placements" + (" (not held out: used in the calibration)" if seen else " (held out)")
        sets.append(_metric_set(label, measured.get("before"), measured.get("after"), seen))
    shown = [s for s in sets if s is not None]
    check = block.get("held_out_placements") or {}
    predicted = [_predictions(f"each calibration placement left out, predicted by level {check.get('level')} "
                              "fitted on the others", check.get("placements")),
                 _predictions("evaluated placements the calibration has not seen",
                              (measured or {}).get("held_out_placements") if isinstance(measured, dict) else None)]
    nominal = block.get("nominal") or {}
    ball, std = block.get("ball_centre_m"), block.get("ball_centre_std_m")
    return {
        "file": block.get("file"),
        "tip_link": (doc.get("tool") or {}).get("parent_link"),
        "sets": shown,
        "predicted": [p for p in predicted if p is not None],
        "cards": [{"label": s["label"], "consistency": s["all"]["consistency"], "distortion": s["all"]["distortion"],
                   "has_before": s["has_before"]} for s in shown],
        "ball": [{"axis": axis, "value": _mm(v), "std": _mm(s)}
                 for axis, v, s in zip("xyz", ball or [None] * 3, std or [None] * 3)],
        "nominal_ball": ", ".join(_vector_mm(nominal.get("ball_centre_m"))),
        "nominal_rms": _decimals(nominal.get("rms_point_error_mm")),
        "sockets": [{"name": s.get("name"), "xyz": _vector_mm(s.get("xyz_m"))} for s in block.get("sockets") or []],
        "distances": [(d.get("a"), d.get("b"), _decimals(d.get("mm"))) for d in block.get("distances_mm") or []],
        "placements": [_placement(p) for p in block.get("placements") or []],
        "notes": [str(n) for n in (measured or {}).get("notes") or []],
    }
