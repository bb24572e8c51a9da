"""Values of the HTML report's parameter and effect sections, and of keys it
does not know (shown as they are), prepared for the template (:mod:`pincal.report.html`)."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from pincal.model.effect_units import shift_unit, value_unit

__all__ = [
    "DISPLAY", "num", "change_text", "parameter_section", "effect_label", "effects_section", "fixed", "rotation_text",
    "sessions_section", "generic",
]

#: Display units of a REPORT.json unit: (title, value scale and unit — nominal and
#: calibrated —, change scale and unit — change and standard deviation). Lengths in
#: mm throughout; angles in deg (values) and mrad (changes, spreads).
DISPLAY = {
    "m": ("Lengths", 1000.0, "mm", 1000.0, "mm"),
    "rad": ("Angles", 180.0 / math.pi, "deg", 1000.0, "mrad"),
}


def num(value: Any, digits: int = 4) -> str:
    """``value`` with ``digits`` significant digits; an em dash for None and non-numbers."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return "—"
    return f"{value + 0.0:.{digits}g}"  # + 0.0: no negative zero


def change_text(before: Any, after: Any) -> str | None:
    """A change of a non-negative error from ``before`` to ``after``, as the page shows it.

    (after − before) / before in % while ``after`` is between half and twice ``before``
    (``−23 %``, ``+8.4 %``); beyond, the ratio (``4210× smaller``, ``3.2× larger``),
    so an error that falls 4000-fold does not read −100 %: −100 % only when ``after``
    is exactly 0. None when ``before`` is not a positive number (no relative change).
    """
    a, b = _finite(before), _finite(after)
    if a is None or b is None or a <= 0.0 or b < 0.0:
        return None
    if b == 0.0:
        return "−100 %"
    ratio = b / a

    def factor(value: float) -> str:
        return f"{value:,.0f}" if value >= 1000.0 else f"{value:#.3g}".rstrip(".")

    if ratio < 0.5:
        return factor(1.0 / ratio) + "× smaller"
    if ratio > 2.0:
        return factor(ratio) + "× larger"
    percent = 100.0 * (ratio - 1.0)
    text = f"{percent:+.0f} %" if abs(percent) >= 9.5 else f"{percent:+.1f} %"
    return text.replace("-", "−")


def _finite(value: Any) -> float | None:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return None
    return float(value)


def parameter_section(doc: dict, figure: Callable) -> dict[str, Any] | None:
    """Determined parameters (nominal, calibrated, change, std, |change|/std), one table per
    unit (:data:`DISPLAY`: each column in one unit, named in its header), and the others, with why."""
    parameters = doc.get("parameters")
    if not isinstance(parameters, list):
        return None
    dropped = {d.get("name"): d for d in (doc.get("identifiability") or {}).get("dropped") or []}
    groups: dict[str, dict[str, Any]] = {}
    undetermined, plotted = [], []
    for p in parameters:
        unit = str(p.get("unit", ""))
        title, value_scale, value_unit, scale, shown = DISPLAY.get(unit, (f"In {unit or 'no unit'}", 1.0, unit,
                                                                          1.0, unit))
        calibrated, nominal, std = _finite(p.get("calibrated")), _finite(p.get("nominal")), _finite(p.get("std"))
        if calibrated is None:
            absorbed = (dropped.get(p.get("name")) or {}).get("absorbed_into") or []
            undetermined.append({
                "name": p.get("name"), "joint": p.get("joint"), "status": p.get("status"),
                "absorbed": ", ".join(f"{num(a.get('coefficient'), 3)} × {a.get('name')}" for a in absorbed),
            })
            continue
        change = None if nominal is None else (calibrated - nominal) * scale
        std_shown = None if std is None else std * scale
        ratio = None if change is None or not std_shown else abs(change) / std_shown
        group = groups.setdefault(unit, {"title": title, "unit": unit, "value_unit": value_unit,
                                         "change_unit": shown, "rows": []})
        group["rows"].append({
            "name": p.get("name"), "joint": p.get("joint"),
            "nominal": _decimals(nominal, value_scale, value_unit),
            "calibrated": _decimals(calibrated, value_scale, value_unit),
            "nominal_value": (nominal or 0.0) * value_scale, "calibrated_value": calibrated * value_scale,
            "change": num(change, 4), "change_value": change if change is not None else 0.0,
            "std": num(std_shown, 2), "std_value": std_shown if std_shown is not None else -1.0,
            "ratio": num(ratio, 3), "ratio_value": ratio if ratio is not None else -1.0,
            "status": p.get("status"),
        })
        plotted.append({"name": p.get("name"), "change": change, "std": std_shown, "unit": shown})
    return {"groups": list(groups.values()), "determined": [r for g in groups.values() for r in g["rows"]],
            "undetermined": undetermined, "total": len(parameters), "figure": figure(plotted)}


def _decimals(value: float | None, scale: float, unit: str) -> str:
    """A nominal or calibrated value in its column's unit: 4 decimals in mm and deg (0.1 µm,
    2 µrad), 7 significant digits otherwise."""
    if value is None:
        return "—"
    if unit in ("mm", "deg"):
        return f"{round(value * scale, 4) + 0.0:.4f}"
    return num(value * scale, 7)


def _effect_value(entry: dict, kinds: dict[Any, str]) -> tuple[str, str]:
    """(value ± std with its unit, |value|/std) of one ``effects`` entry, its joints of the kinds ``kinds``."""
    kind: Any = entry.get("type")  # a JSON value: a string, or None when absent
    length = kinds.get(entry.get("joint")) == "prismatic"
    driver = None if entry.get("driver") is None else kinds.get(entry.get("driver")) == "prismatic"

    def pm(value, std, scale, unit):
        text = f"{num(_finite(value) * scale if _finite(value) is not None else None, 4)}"
        if _finite(std) is not None:
            text += f" ± {num(std * scale, 2)}"
        return f"{text} {unit}"

    if kind == "cyclic":
        sin, cos = _finite(entry.get("sin")), _finite(entry.get("cos"))
        amplitude = math.hypot(sin, cos) * 1000.0 if sin is not None and cos is not None else None
        unit = "m" + shift_unit(length)  # mm or mrad
        text = (f"sin {pm(sin, entry.get('sin_std'), 1000.0, unit)}, cos {pm(cos, entry.get('cos_std'), 1000.0, unit)}"
                f" (amplitude {num(amplitude, 3)} {unit})")
        return text, ""
    value, std = entry.get("value"), entry.get("std")
    if entry.get("moments"):  # a compliance of unknown masses: one value per mass moment, in mrad (µm prismatic)
        values, stds = value if isinstance(value, list) else [value], std if isinstance(std, list) else [None]
        # a combination led by a mass (m:...) has a lever arm for basis: mrad/m (combination_words' units)
        units = ["µm" if length else "mrad/m" if str(name).rpartition("/")[2].startswith("m:") else "mrad"
                 for name in entry["moments"]]  # a lateral compliance's names start u/ or v/
        scale = 1e6 if length else 1000.0
        return ", ".join(pm(v, s, scale, u) for v, s, u in zip(values, stds + [None] * len(values), units)), ""
    if kind == "lateral":  # [c_u, c_v] rad/(N·m): mrad/(N·m) about each lateral axis
        values, stds = value if isinstance(value, list) else [value], std if isinstance(std, list) else [None, None]
        return ", ".join(f"{axis} {pm(v, s, 1000.0, 'mrad/(N·m)')}" for axis, v, s in zip("uv", values, stds)), ""
    if kind in ("drift", "pause_step"):  # [vx, vy, vz] m/s; a step's [dx, dy, dz] m
        values = value if isinstance(value, list) else [value]
        stds = std if isinstance(std, list) else [None] * len(values)
        name, scale, unit = ("v", 1000.0, "mm/s") if kind == "drift" else ("d", 1e6, "µm")
        return ", ".join(f"{name}{axis} {pm(v, s, scale, unit)}" for axis, v, s in zip("xyz", values, stds)), ""
    reading = value_unit("coupling", length, driver)  # rad/m or m/rad between a revolute and a prismatic joint
    scale, unit = {
        "compliance": (1000.0, "m" + value_unit("compliance", length, driver)),  # mrad/(N·m), mm/N, mrad/N, ...
        "encoder_scale": (100.0, "%"),
        "coupling": (1.0, f"× {entry.get('driver')}'s reading" if reading == "(relative)" else reading),
        "sensor_scale": (100.0, "%"),
        "backlash": (1000.0, f"m{shift_unit(length)} per flank"),
        "thermal": (1e6, "µm/m/K"),
    }.get(kind, (1.0, ""))
    v, s = _finite(value), _finite(std)
    return pm(v, s, scale, unit), num(abs(v) / s, 3) if v is not None and s else ""


def effect_label(entry: dict) -> str:
    """``backlash of arm_6_joint (approach flank)``, ``cyclic error of arm_3_joint (harmonic 2)``."""
    kind, joint = entry.get("type", "?"), entry.get("joint")
    name = {"cyclic": "cyclic error", "encoder_scale": "encoder scale", "sensor_scale": "sensor scale",
            "lateral": "lateral (bending) compliance"}.get(kind, kind)
    text = f"{name} of {joint}" if joint else f"{name} of the sensor" if kind == "sensor_scale" else str(name)
    if kind == "cyclic":
        text += f" (harmonic {entry.get('harmonic')})"
    if kind == "coupling":
        text = f"coupling of {joint} to {entry.get('driver')}'s reading"
    if kind == "compliance" and entry.get("driver"):
        text = f"compliance of {joint} to {entry.get('driver')}'s gravity torque"
    elif kind in ("thermal", "pause_step"):
        text = ("thermal expansion of the arm" if kind == "thermal"
                else f"step of the registration at pause {entry.get('pause')}")
    if kind == "backlash" and entry.get("source"):
        text += f" ({entry['source']} flank)" if entry["source"] == "approach" else f" ({entry['source']})"
    return text


def _rms(errors: dict | None) -> str:
    return num(((errors or {}).get("position") or {}).get("rms_mm"), 4)


def effects_section(doc: dict, kinds: dict[Any, str], base: Path, png: Callable) -> dict[str, Any] | None:
    """Adopted effects, each step's ΔBIC and errors before → after, the candidates
    reported but not adopted, the remaining structure, and the plots of ``diagnose``."""
    diagnosis = doc.get("diagnosis")
    if not isinstance(diagnosis, dict):
        return None

    from pincal.diagnosis.verdicts import POSITION_ONLY  # loaded only for a diagnose report

    final = []
    for entry in doc.get("effects") or []:
        value, ratio = _effect_value(entry, kinds)
        change = entry.get("target_change") or {}  # how far it moves the target (mm; mrad with 6D rows)
        turns = "rms_mrad" in change and entry.get("type") not in POSITION_ONLY  # an expansion turns nothing
        moves = "" if "rms_mm" not in change else (
            f"{num(change['rms_mm'], 3)} mm RMS ({num(change.get('max_mm'), 3)} at most)"
            + (f", {num(change['rms_mrad'], 3)} mrad RMS" if turns else ""))
        final.append({"label": effect_label(entry), "value": value, "ratio": ratio, "moves": moves,
                      "advice": entry.get("advice") or ""})
    steps = []
    for number, step in enumerate(diagnosis.get("steps") or [], start=1):
        effect = step.get("effect") or {}
        cal, held = step.get("calibration") or {}, step.get("heldout") or {}
        steps.append({
            "number": number, "label": effect_label(effect), "value": _effect_value(effect, kinds)[0],
            "delta_bic": num(step.get("delta_bic"), 4),
            "cal": (_rms(cal.get("before")), _rms(cal.get("after"))),
            "held": (_rms(held.get("before")), _rms(held.get("after"))) if held.get("before") else None,
        })
    candidates = [{
        "label": effect_label(c), "value": _effect_value(c, kinds)[0], "delta_bic": num(c.get("delta_bic"), 4),
        "delta_bic_value": _finite(c.get("delta_bic")) or 0.0, "heldout": num(c.get("heldout_rms_mm"), 4),
        "verdict": c.get("verdict"),
    } for c in diagnosis.get("last_candidates") or []]
    plots: list = []  # (name, data URI) of each plot found
    missing: list = []  # the paths of those not found
    for text in diagnosis.get("plots") or []:
        path = Path(str(text))
        tried = [path, base / path, base / path.name, base / path.parent.name / path.name]
        uri = next((u for u in (png(p) for p in tried) if u), None)
        (plots if uri else missing).append((path.name, uri) if uri else str(path))
    return {
        "criterion": diagnosis.get("criterion"), "final": final, "steps": steps, "candidates": candidates,
        "unexplained": diagnosis.get("unexplained"), "notes": [str(n) for n in diagnosis.get("notes") or []],
        "has_heldout": any(s["held"] for s in steps), "plots": plots, "missing": missing,
        "payload_kg": doc.get("payload_kg"), "time_column": doc.get("time_column"),
    }


def fixed(values, decimals: int, scale: float = 1.0) -> str:
    """Comma-separated fixed-point numbers, never a negative zero."""
    return ", ".join(f"{round(float(v) * scale, decimals) + 0.0:.{decimals}f}" for v in values)


def rotation_text(entry: dict) -> dict[str, str]:
    """A registration ``{rotation_xyzw, translation_m}`` as the page shows it."""
    try:
        rotation = Rotation.from_quat(np.asarray(entry["rotation_xyzw"], dtype=float))
        translation = np.asarray(entry["translation_m"], dtype=float)
    except (KeyError, TypeError, ValueError):
        return {"quaternion": "—", "rpy": "—", "angle": "—", "translation": "—"}
    return {
        "quaternion": fixed(entry["rotation_xyzw"], 6),
        "rpy": fixed(rotation.as_euler("xyz", degrees=True), 4),
        "angle": f"{np.degrees(rotation.magnitude()):.4f}",
        "translation": fixed(translation, 5),
    }


def sessions_section(doc: dict) -> list[dict[str, Any]] | None:
    """Per-session registrations and errors (``sessions``), or None if absent or not in the known form."""
    sessions = doc.get("sessions")
    if not isinstance(sessions, list) or not sessions or not all(isinstance(s, dict) for s in sessions):
        return None
    rows = []
    for entry in sessions:
        registration = entry.get("registration") or {}
        position = registration.get("position") if isinstance(registration, dict) else None
        if not isinstance(position, dict):
            return None
        errors = entry.get("calibration_errors") or {}
        files = entry.get("file")
        rows.append({
            "name": entry.get("name"), "file": ", ".join(map(str, files)) if isinstance(files, list) else files,
            "rows": entry.get("rows"), "registration": rotation_text(position),
            "pos_rms": num((errors.get("position") or {}).get("rms_mm"), 4),
            "rot_rms": num((errors.get("orientation") or {}).get("rms_deg"), 4),
        })
    return rows


def _cell(value: Any) -> str:
    if isinstance(value, float):
        return num(value, 6)
    if isinstance(value, (dict, list)):
        text = json.dumps(value, ensure_ascii=False)
        return text if len(text) <= 160 else text[:157] + "…"
    return "—" if value is None else str(value)


def generic(value: Any, depth: int = 0) -> dict[str, Any]:
    """A JSON value the page does not know, as nested tables: ``{"kind": "pairs" | "table" | "text"}``."""
    if isinstance(value, dict) and depth < 3:
        return {"kind": "pairs", "items": [(str(k), generic(v, depth + 1)) for k, v in value.items()]}
    if isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
        columns = list(dict.fromkeys(k for v in value for k in v))
        return {"kind": "table", "columns": columns, "rows": [[_cell(v.get(c)) for c in columns] for v in value]}
    if isinstance(value, list) and all(not isinstance(v, (dict, list)) for v in value):
        return {"kind": "text", "text": ", ".join(_cell(v) for v in value) if value else "(none)"}
    return {"kind": "text", "text": _cell(value)}
