"""The page of a PLAN.json (``pincal plan --report``): ``pincal report PLAN.json --out PLAN.html``.

Same look as the report page (the shared ``templates/style.css.j2``): the
predicted accuracy PLAN.json reports — the plan's and random choices' mean and
max error over the workspace sample, the condition number —, the chosen poses
in visiting order with their joint values (read from the PLAN.csv beside
PLAN.json whose SHA-256 PLAN.json records; revolute joints in deg, prismatic in
mm), and the plan's coverage: per joint, the span of the poses against the
joint's limits in the URDF. PLAN.json is only read.
"""

from __future__ import annotations

import csv
import hashlib
import math
from pathlib import Path
from typing import Any
from xml.etree import ElementTree

from pincal.report.sections import generic, num

__all__ = ["is_plan", "find_plan_csv", "joint_limits", "plan_context"]


def is_plan(document: dict[str, Any]) -> bool:
    """Whether ``document`` is a PLAN.json (it has ``plan_version``)."""
    return isinstance(document, dict) and "plan_version" in document


def _sha256(path: Path) -> str | None:
    try:
        return hashlib.sha256(path.read_bytes()).hexdigest()
    except OSError:
        return None


def find_plan_csv(document: dict[str, Any], base: Path) -> Path | None:
    """The PLAN.csv of ``document``: a CSV in ``base`` whose SHA-256 is ``plan_csv_sha256``
    (PLAN.csv first, then the others by name); None if none matches."""
    digest = document.get("plan_csv_sha256")
    if not digest or not base.is_dir():
        return None
    files = sorted(base.glob("*.csv"), key=lambda p: (p.name != "PLAN.csv", p.name))
    return next((p for p in files if _sha256(p) == digest), None)


def joint_limits(urdf: Any, joints: list[str]) -> dict[str, tuple[str, float | None, float | None]]:
    """Per joint: (type, lower, upper) from the URDF's ``<limit>`` (None where not given,
    or the URDF is not readable XML — a .xacro, a missing file)."""
    out: dict[str, tuple[str, float | None, float | None]] = {}
    try:
        root = ElementTree.parse(str(urdf)).getroot()
    except (OSError, ElementTree.ParseError, TypeError):
        return out
    for joint in root.findall("joint"):  # the robot's joints, not a <transmission>'s <joint name=…>
        name = joint.get("name")
        if name not in joints:
            continue
        limit = joint.find("limit")
        kind = joint.get("type", "revolute")

        def bound(key: str) -> float | None:
            try:
                return float(limit.get(key))  # type: ignore[union-attr, arg-type]
            except (AttributeError, TypeError, ValueError):
                return None
        out[name] = (kind, bound("lower"), bound("upper")) if kind != "continuous" else (kind, -math.pi, math.pi)
    return out


def _unit(kind: str) -> tuple[float, str]:
    return (1000.0, "mm") if kind == "prismatic" else (180.0 / math.pi, "deg")


def _poses(path: Path | None, joints: list[str], kinds: dict[str, str]) -> tuple[list[dict[str, Any]], dict]:
    """The rows of PLAN.csv in visiting order, joint values in display units, and each joint's values."""
    if path is None:
        return [], {}
    with path.open(newline="", encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle))
    values: dict[str, list[float]] = {j: [] for j in joints}
    poses = []
    for number, row in enumerate(rows, start=1):
        cells = []
        for joint in joints:
            scale, _ = _unit(kinds.get(joint, "revolute"))
            try:
                value = float(row[joint])
            except (KeyError, TypeError, ValueError):
                cells.append("—")
                continue
            values[joint].append(value)
            cells.append(f"{round(value * scale, 3) + 0.0:.3f}")
        poses.append({"order": number, "priority": row.get("priority", "—"), "candidate": row.get("candidate", "—"),
                      "cells": cells})
    return poses, values


def _coverage(joints, values, limits) -> list[dict[str, Any]]:
    """Per joint: the poses' span against the URDF limits (fraction, None without limits)."""
    out = []
    for joint in joints:
        kind, lower, upper = limits.get(joint, ("revolute", None, None))
        scale, unit = _unit(kind)
        shown = values.get(joint) or []
        low, high = (min(shown), max(shown)) if shown else (None, None)
        fraction = None
        if low is not None and high is not None and lower is not None and upper is not None and upper > lower:
            fraction = (min(high, upper) - max(low, lower)) / (upper - lower)
        def shown_in(value: float | None) -> float | None:
            return None if value is None else value * scale

        out.append({"joint": joint, "unit": unit, "values": [v * scale for v in shown],
                    "lower": shown_in(lower), "upper": shown_in(upper),
                    "low": num(shown_in(low), 4), "high": num(shown_in(high), 4),
                    "fraction": fraction, "percent": "—" if fraction is None else f"{100.0 * fraction:.0f} %"})
    return out


def _prediction_rows(predicted: dict) -> list[dict[str, Any]]:
    rows = []
    for key, label in (("plan", "this plan"), ("random", "random choices (median over draws)"),
                       ("recorded_only", "the recorded rows alone")):
        entry = predicted.get(key)
        if isinstance(entry, dict):
            rows.append({"key": key, "label": label,
                         **{k: num(entry.get(k), 4) for k in ("mean_position_mm", "max_position_mm",
                                                               "mean_rotation_deg", "max_rotation_deg", "condition")},
                         "mean_value": entry.get("mean_position_mm"), "max_value": entry.get("max_position_mm")})
    return rows


def _targets(predicted: dict) -> list[dict[str, Any]]:
    """Each target's predicted errors (several ``--tip-link``: ``predicted.targets``), for its table."""
    rows = []
    for target in predicted.get("targets") or []:
        plan, random = target.get("plan") or {}, target.get("random") or {}
        rows.append({"link": target.get("tip_link"), "points": ",".join(map(str, target.get("points") or [])),
                     "plan_mean": num(plan.get("mean_position_mm"), 4), "plan_max": num(plan.get("max_position_mm"), 4),
                     "random_mean": num(random.get("mean_position_mm"), 4),
                     "random_max": num(random.get("max_position_mm"), 4)})
    return rows


def plan_context(document: dict[str, Any], base: Path, figures) -> dict[str, Any]:
    """The values of ``templates/plan.html.j2``; ``figures``: :mod:`pincal.report.figures`."""
    chain = document.get("chain") or {}
    joints = [str(j) for j in chain.get("joints") or []]
    sources = document.get("sources") or {}
    urdf = sources.get("urdf")
    if urdf and not Path(str(urdf)).is_absolute() and not Path(str(urdf)).exists():
        urdf = base / str(urdf)  # a path as plan was given it: relative to where it ran, or to PLAN.json
    limits = joint_limits(urdf, joints)
    kinds = {j: limits[j][0] for j in limits}
    csv_path = find_plan_csv(document, base)
    poses, values = _poses(csv_path, joints, kinds)
    coverage = _coverage(joints, values, limits)
    predicted = document.get("predicted") or {}
    settings = document.get("settings") or {}
    plan = predicted.get("plan") or {}
    robot = Path(str(sources["urdf"])).name if sources.get("urdf") else None
    prediction = _prediction_rows(predicted)
    facts = [(k, str(settings.get(k))) for k in ("count", "level", "measure", "criterion", "select",
                                                 "sigma_pos_mm", "sigma_rot_deg", "sigma_source", "seed")
             if settings.get(k) is not None]
    facts += [("robot (URDF)", str(sources.get("urdf")))] if sources.get("urdf") else []
    candidates = document.get("candidates") or {}
    if candidates:
        facts.append(("candidates", f"{candidates.get('usable')} usable of {candidates.get('count')}"))
        if candidates.get("collision_check"):  # a PLAN.json written before the key was has none
            facts.append(("collision check", str(candidates["collision_check"])))
        ranges = [r for r in candidates.get("joint_ranges") or [] if isinstance(r, dict)]
        if ranges:
            facts.append(("joint ranges", "; ".join(
                f"{r.get('joint')} {num(r.get('lower'), 4)} to {num(r.get('upper'), 4)} {r.get('unit')}"
                for r in ranges) + f" ({', '.join(dict.fromkeys(str(r.get('source')) for r in ranges))})"))
    order = document.get("order") or {}
    if order:
        facts.append(("order", f"{order.get('method')}, {num(order.get('travel_s'), 3)} s of moves"))
    shown = {"pincal_version", "plan_version", "sources", "plan_csv_sha256", "chain", "settings", "predicted",
             "additions", "notes", "order", "candidates"}
    return {
        "title": "Measurement plan" + (f" — {robot}" if robot else ""),
        "chain": {"root": chain.get("root_link", "?"), "tip": chain.get("tip_link", "?"), "joints": len(joints)},
        "version": document.get("pincal_version"), "plan_version": document.get("plan_version"),
        "count": len(poses) or settings.get("count"),
        "mean": num(plan.get("mean_position_mm"), 3), "max": num(plan.get("max_position_mm"), 3),
        "condition": num(plan.get("condition"), 3),
        "ratio": num(predicted.get("plan_over_random_mean_position"), 2),
        "random_mean": num((predicted.get("random") or {}).get("mean_position_mm"), 3),
        "what": predicted.get("what"), "workspace": predicted.get("workspace_configurations"),
        "criterion": document.get("criterion") or {},
        "targets": _targets(predicted),
        "prediction": prediction, "has_rotation": any(r["mean_rotation_deg"] != "—" for r in prediction),
        "prediction_figure": figures.prediction_figure(prediction),
        "joints": [(j, _unit(kinds.get(j, "revolute"))[1]) for j in joints], "poses": poses,
        "csv": str(csv_path) if csv_path else None, "csv_sha256": document.get("plan_csv_sha256"),
        "additions": document.get("additions") or [],
        "coverage": coverage, "coverage_figure": figures.coverage_figure(coverage) if poses else None,
        "balance": order.get("approach_balance") or [], "facts": facts,
        "identifiability": document.get("identifiability") or {},
        "notes": [str(n) for n in document.get("notes") or []],
        "extra": [(k, generic(v)) for k, v in document.items() if k not in shown and k != "identifiability"
                  and v not in (None, {}, [], "")],
    }
