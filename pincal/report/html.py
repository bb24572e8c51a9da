"""The HTML report: one self-contained page from a REPORT.json document.

:func:`render_html` turns a report of any kind pincal writes — the paper's
methods, ``calibrate --level registration|offsets|full``, ``diagnose`` — or
the metrics of ``evaluate --json`` into one HTML file: styles, the sorting
script and every figure are inside it (figures as ``data:`` URIs, SVG drawn
from the document by :mod:`pincal.report.figures`, the PNGs of ``diagnose``
read from disk), and its Content-Security-Policy forbids any network request.
The page is laid out by the Jinja2 template ``templates/report.html.j2``
(autoescaped); this module only prepares the values it shows (numbers
formatted, in mm and mrad where the document has m and rad).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any, cast

from jinja2 import UndefinedError

from pincal.errors import PincalError
from pincal.fit.outliers import OUTLIER_THRESHOLD
from pincal.outputs import write_text
from pincal.palette import CALIBRATED, FLAG, LEGEND, NOMINAL, model_colour
from pincal.report import figures
from pincal.report.camera_html import camera_page, camera_title, is_camera
from pincal.report.fixture_html import fixture_section
from pincal.report.plan_html import is_plan, plan_context
from pincal.report.prior_scale import prior_scale_line
from pincal.report.sections import (
    change_text,
    effects_section,
    fixed,
    generic,
    num,
    parameter_section,
    rotation_text,
    sessions_section,
)
from pincal.report.templating import environment as _environment
from pincal.report.tree_html import tree_section

__all__ = [
    "TEMPLATE", "PLAN_TEMPLATE", "KNOWN_KEYS", "headline", "evaluated_sessions",
    "orientations_measured", "render_html", "write_html",
]

TEMPLATE = "report.html.j2"
PLAN_TEMPLATE = "plan.html.j2"

#: Top-level REPORT.json keys the page lays out itself; any other key (for example
#: ``sessions``) is shown as it is, under "More in this report".
KNOWN_KEYS = frozenset({
    "pincal_version", "report_version", "method", "weight_mm2_per_deg2", "model", "sources", "chain",
    "parameters", "registration", "tool", "fit", "notes", "urdf_sha256", "level", "identifiability", "noise",
    "outliers", "removed_lines", "effects", "payload_kg", "time_column", "time_reference_s",
    "approach_context", "diagnosis", "row_errors", "warnings",
})


def headline(value: Any) -> str:
    """Three significant digits, trailing zeros kept (4.20, 0.188, 163): the summary's numbers."""
    if num(value) != "—" and 1000.0 <= abs(value) < 1e7:
        return f"{value:.0f}"
    text = num(value, 3) if num(value, 3) == "—" else f"{value + 0.0:#.3g}"
    return text.rstrip(".") if "e" not in text else text


def _text(value: Any) -> str:
    """A path or a list of paths (a report of several files) as one line."""
    return ", ".join(map(str, value)) if isinstance(value, list) else "" if value is None else str(value)


def _errors_row(label: str, model: str, errors: dict | None, points: int) -> dict[str, Any] | None:
    """A row of the errors table from an eq 24 summary ``{"rows", "position", ...}``."""
    if not isinstance(errors, dict) or not isinstance(errors.get("position"), dict):
        return None
    position, rotation = errors["position"], errors.get("orientation") or {}
    per_point = [num(p.get("rms_mm"), 3) for p in errors.get("position_per_point") or []]
    return {
        "set": label, "model": model, "rows": errors.get("rows", "—"),
        "pos": [num(position.get(k), 4) for k in ("mean_mm", "rms_mm", "max_mm")],
        "rot": [num(rotation.get(k), 4) for k in ("mean_deg", "rms_deg", "max_deg")] if rotation else None,
        "points": per_point + [""] * (points - len(per_point)),
    }


def _summary(doc: dict, evaluation: dict | None, more: list[tuple[str, str]]) -> dict[str, Any]:
    """Headline cards, the errors table and the facts about the run (then ``more``: a camera's)."""
    sets = list(doc.get("row_errors") or [])
    if evaluation and evaluation.get("row_errors"):
        sets += evaluation["row_errors"]
    cards, table, stages = [], [], []
    for entry in sets:
        models = entry.get("models") or []
        if not models:
            continue
        chain = [(m["model"], m["errors"]["position"].get("rms_mm"),
                  (m["errors"].get("orientation") or {}).get("rms_deg")) for m in models]
        stages.append({"set": entry["set"], "models": chain})
        first, last = chain[0][1], chain[-1][1]
        change = change_text(first, last) if len(chain) > 1 else None
        cards.append({
            "set": entry["set"], "file": _text(entry.get("file")), "rows": len(entry.get("lines") or []),
            "final": headline(last), "final_rot": headline(chain[-1][2]) if chain[-1][2] is not None else None,
            "steps": [{"model": name, "value": headline(rms)} for name, rms, _ in chain],
            "colours": figures.model_colours([name for name, _, _ in chain]),
            "colour": model_colour(chain[-1][0]), "change": change and f"{change} from {chain[0][0]}",
            "notes": _registration_notes(evaluation) if entry.get("set") == "evaluated" else [],
        })
        for m in models:
            table.append(_errors_row(entry["set"], m["model"], m["errors"], 0))
    if not sets:  # older reports, and evaluate JSON: the summaries they have
        fit = doc.get("fit") or {}
        table.append(_errors_row("calibration", "calibrated", fit.get("calibration_errors"), 0))
        diag = doc.get("diagnosis") or {}
        table.append(_errors_row("held-out", "calibrated", diag.get("heldout_errors"), 0))
        if evaluation:
            table.append(_errors_row("evaluated", "reported model", evaluation.get("errors"), 0))
        for row in table:
            if row is not None:
                cards.append({"set": row["set"], "file": None, "rows": row["rows"], "final": row["pos"][1],
                              "final_rot": row["rot"][1] if row["rot"] else None, "steps": [], "colours": [],
                              "colour": model_colour(row["model"]), "change": None,
                              "notes": _registration_notes(evaluation) if row["set"] == "evaluated" else []})
    kept = [row for row in table if row is not None]
    points = max((len(row["points"]) for row in kept), default=0)
    for row in kept:
        row["points"] += [""] * (points - len(row["points"]))
    return {"cards": cards, "errors": kept, "points": points, "has_rotation": any(r["rot"] for r in kept),
            "figure": figures.overview_figure(stages), "facts": _facts(doc, evaluation) + more}


def evaluated_sessions(evaluation: dict | None) -> list[dict[str, Any]]:
    """Each evaluated session (``evaluate --json`` ``sessions``): its rows, where its registration
    came from, and — re-estimated — its residuals, degrees of freedom left and the factor
    sqrt((N − 6) / N) its errors understate the true error by (pincal/workflows/evaluation.py)."""
    out = []
    for entry in (evaluation or {}).get("sessions") or []:
        if not isinstance(entry, dict):
            continue
        errors = entry.get("errors") or {}
        residuals, dof = entry.get("residuals"), entry.get("registration_dof")
        shrink = (math.sqrt(max(dof, 0) / residuals) if isinstance(dof, int) and isinstance(residuals, int)
                  and residuals > 0 else None)
        out.append({
            "name": entry.get("name"), "rows": entry.get("rows"), "source": entry.get("registration_source"),
            "reestimated": bool(entry.get("registration_reestimated")), "residuals": residuals, "dof": dof,
            "shrink": num(shrink, 2),
            "pos_rms": num((errors.get("position") or {}).get("rms_mm"), 4),
            "rot_rms": num((errors.get("orientation") or {}).get("rms_deg"), 4),
        })
    return out


def _registration_notes(evaluation: dict | None) -> list[str]:
    """The evaluated card's lines on registrations re-estimated on the evaluated rows, on
    rows a drift was not extrapolated to (``drift`` of ``evaluate --json``), and evaluate's "before"."""
    drift = (evaluation or {}).get("drift")
    held = drift.get("rows_held") if isinstance(drift, dict) else None
    sessions = evaluated_sessions(evaluation)
    notes = [f"session {s['name']}: registration re-estimated on these rows — {s['residuals']} residuals, "
             f"{s['dof']} degrees of freedom left: errors about {s['shrink']} × the true error"
             for s in sessions if s["reestimated"]]
    if isinstance(held, int) and held > 0:  # where evaluate held it (pincal.model.drift.drift_offsets)
        assert drift is not None  # held comes from it
        kinds = {s["reestimated"] for s in sessions}
        at = ("at zero offset (no span recorded)" if not drift.get("time_spans_s")
              else "held at the nearer end of the span (registration re-estimated)" if kinds == {True}
              else "held at its session's mean time" if kinds == {False}
              else "held at its session's mean time (a re-estimated registration: at the nearer end of the span)")
        notes.append(f"drift not extrapolated: {held} row(s) outside the time span it was fitted on are evaluated "
                     f"with it {at}")
    before = (evaluation or {}).get("before")
    if isinstance(before, dict) and isinstance(before.get("position_rms_mm"), (int, float)):
        # evaluate's before -> after, which registers the nominal URDF to these rows
        notes.append(f"before: {before['position_rms_mm']:.3f} mm RMS — the nominal URDF with its registration and "
                     "target fitted to these rows (evaluate's before -> after; the nominal geometry of the "
                     "calibration rows is registered to those)")
    return notes + _condition_notes(evaluation)


def _condition_notes(evaluation: dict | None) -> list[str]:
    """The evaluated card's lines on the report's thermal expansion (eq T1) and pause steps (eq T2) as
    ``evaluate`` applied them to these rows (``thermal``, ``pause_steps`` of ``evaluate --json``)."""
    thermal, steps = (evaluation or {}).get("thermal"), (evaluation or {}).get("pause_steps")
    notes = []
    if isinstance(thermal, dict):
        span = thermal.get("temperature_range_c") or {}
        held, alpha = thermal.get("rows_held"), thermal.get("alpha_per_k")
        alpha = 1e6 * alpha if isinstance(alpha, (int, float)) else None  # µm/m/K
        notes.append(f"thermal expansion applied (eq T1): α = {num(alpha, 3)} µm/m/K, each row "
                     f"at its temperature in column '{thermal.get('temperature_column')}' against "
                     f"{num(span.get('mean'), 4)} °C: {thermal.get('rows_applied')} row(s) inside the fitted range "
                     f"{num(span.get('min'), 4)}–{num(span.get('max'), 4)} °C"
                     + (f", {held} outside it held at its nearer end (not extrapolated)" if held else ""))
    if isinstance(steps, dict):
        pauses = [p for p in steps.get("pauses") or [] if isinstance(p, dict)]
        stepped = steps.get("rows_stepped")
        outside = steps.get("rows_outside")
        named = ", ".join(f"pause {p.get('pause')} of session '{p.get('session')}'" for p in pauses)
        notes.append(f"pause steps applied (eq T2): {'rows' if stepped is None else f'{stepped} row(s)'} after a "
                     f"pause of their session ({named}) take its registration step"
                     + (f"; {outside} row(s) outside the fitted time span take the nearest segment's" if outside
                        else ""))
    return notes


def _facts(doc: dict, evaluation: dict | None) -> list[tuple[str, str]]:
    sources, chain, fit = doc.get("sources") or {}, doc.get("chain") or {}, doc.get("fit") or {}
    facts = []
    if sources.get("urdf"):
        facts.append(("robot (URDF)", str(sources["urdf"])))
    if chain:
        joints = chain.get("joints") or []
        facts.append(("chain", (f"{chain.get('root_link')} → {chain.get('tip_link') or _TIPS} ({len(joints)} joints: "
                               f"{', '.join(joints)})")))
    if doc.get("method") is not None:
        facts.append(("model", f"Method {doc['method']} of Franaszek & Marvel 2022 (DH parameters)"))
    elif doc.get("level"):
        facts.append(("model", f"level {doc['level']} ({doc.get('model', '')})"
                               + (", with effects (pincal diagnose)" if "diagnosis" in doc else "")))
    rows = fit.get("rows") or {}
    if sources.get("data"):
        counts = ", ".join(f"{n} {role}" for role, n in rows.items() if n)
        used = f"; {fit['rows_used']} used in the fit" if "rows_used" in fit else ""
        facts.append(("calibration data", f"{_text(sources['data'])} ({counts or 'rows'}{used})"))
    if sources.get("validation"):
        facts.append(("held-out data", _text(sources["validation"])))
    if evaluation and evaluation.get("data"):
        facts.append(("evaluated data", (f"{evaluation.get('data') or '—'} (evaluated model: "
                                         f"{evaluation.get('urdf') or '—'})")))
    if sources.get("corrected_urdf"):
        facts.append(("corrected URDF", f"not written (withheld: see the warning; --force writes it to "
                                        f"{sources['corrected_urdf']})" if sources.get("corrected_urdf_withheld")
                      else str(sources["corrected_urdf"])))
    scales = prior_scale_line((doc.get("identifiability") or {}).get("selection"))
    if scales:  # the scales the prior held the parameters to, and whether the rows chose them
        facts.append(("prior scales", scales.removeprefix("prior scales: ")))
    noise = doc.get("noise") or {}
    if noise.get("sigma_pos_mm") is not None:
        text = f"{num(noise['sigma_pos_mm'], 3)} mm per axis"
        if noise.get("sigma_rot_deg") is not None:
            text += f", {num(noise['sigma_rot_deg'], 3)} deg"
        facts.append(("noise (estimated from the residuals)", text))
    if "fit_seconds" in fit:
        facts.append(("time", (f"fit {num(fit['fit_seconds'] * 1000, 3)} ms, with selection "
                              f"{num(fit.get('total_seconds', math.nan) * 1000, 3)} ms")))
    return facts


def _rows(doc: dict, evaluation: dict | None) -> list[dict[str, Any]]:
    """Per row set: the sortable table's columns and rows, and its plot."""
    reported = {(o.get("file"), int(o["line"])): (o.get("robust_score"), o.get("by")) for o in doc.get("outliers") or []
                if "line" in o}
    sets = list(doc.get("row_errors") or []) + list((evaluation or {}).get("row_errors") or [])
    reestimated = {s["name"] for s in evaluated_sessions(evaluation) if s["reestimated"]}
    out = []
    for entry in sets:
        models, lines = entry.get("models") or [], entry.get("lines") or []
        if not models or not lines:
            continue
        files = [str(f) for f in entry.get("files") or []]
        files = files if len(files) == len(lines) else [_text(entry.get("file"))] * len(lines)
        sessions = [str(n) for n in entry.get("sessions") or []]
        several_files = len(set(files)) > 1
        texts = ["file"] if several_files else []
        texts += ["session"] if len(set(sessions)) > 1 and len(sessions) == len(lines) else []
        scores = entry.get("robust_score") or [None] * len(lines)
        points = entry.get("point_position_mm") or []
        rotation = models[-1].get("orientation_deg")
        flagged, labels, rows = [], [], []
        for i, line in enumerate(lines):
            score = scores[i]
            flag = ""
            outlier = reported.get((files[i], int(line)), None if several_files else reported.get((None, int(line))))
            if entry["set"] == "calibration" and outlier is not None:
                flag = f"outlier ({'orientation, ' if outlier[1] == 'orientation' else ''}score {num(outlier[0], 3)})"
            elif score is not None and score > OUTLIER_THRESHOLD:
                flag = f"> {OUTLIER_THRESHOLD:g} robust σ"
            if flag:
                flagged.append(i)
                labels.append(f"{Path(files[i]).name}:{int(line)}" if several_files else str(int(line)))
            text = [Path(files[i]).name] if several_files else []
            if "session" in texts:
                text.append(sessions[i] + (" (registration re-estimated)"
                                           if entry["set"] == "evaluated" and sessions[i] in reestimated else ""))
            cells: list[tuple[Any, str]] = [(int(line), str(line))]  # (sort value, text)
            cells += [(m["position_mm"][i], num(m["position_mm"][i], 4)) for m in models]
            if rotation is not None:
                cells.append((rotation[i], num(rotation[i], 4)))
            cells += [(v, num(v, 4)) for v in (points[i] if points else [])]
            cells.append((score if score is not None else 0.0, num(score, 3)))
            rows.append({"texts": text, "cells": cells, "flag": flag})
        columns = ["file line"] + [f"{m['model']} [mm]" for m in models]
        columns += ["orientation [deg]"] if rotation is not None else []
        columns += [f"point {p + 1} [mm]" for p in range(len(points[0]) if points else 0)]
        columns += ["robust score"]
        out.append({"set": entry["set"], "file": _text(entry.get("file")), "text_columns": texts, "columns": columns,
                    "rows": rows, "flagged": labels, "figure": figures.row_errors_figure(entry, flagged)})
    return out


def _identifiability(doc: dict) -> dict[str, Any] | None:
    ident = doc.get("identifiability")
    stages = (doc.get("fit") or {}).get("stages") or []
    if not ident and not stages:
        return None
    out: dict[str, Any] = {"stages": [
        {"name": s.get("error_function"), "count": len(s.get("parameters") or []),
         "rms": f"{num(s.get('rms'), 4)} {s.get('unit', '')}", "evaluations": s.get("evaluations"),
         "condition": num(s.get("jacobian_condition"), 3)} for s in stages]}
    if ident:
        selection = ident.get("selection") or {}
        out.update(
            rank=ident.get("rank"), condition=num(ident.get("jacobian_condition"), 4),
            criterion=selection.get("criterion"), kept=selection.get("kept"), value=num(selection.get("value"), 5),
            candidates=[(c.get("kept"), num(c.get("value"), 5), c.get("kept") == selection.get("kept"))
                        for c in selection.get("candidates") or []],
            pairs=[(p.get("a"), p.get("b"), num(p.get("correlation"), 3))
                   for p in ident.get("correlated_pairs") or []],
            dropped=[(d.get("name"), d.get("reason"),
                      ", ".join(f"{num(a.get('coefficient'), 3)} × {a.get('name')}"
                                for a in d.get("absorbed_into") or [])
                      or "—") for d in ident.get("dropped") or []],
            not_determined=[(n.get("name"), n.get("held_at_m"), n.get("reason"))
                            for n in ident.get("not_determined") or []]
            + [(n.get("name"), "—", n.get("reason")) for n in ident.get("not_determined_rotations") or []],
        )
    return out


def orientations_measured(doc: dict) -> bool | None:
    """Whether the report's rows had orientations: an eq 24 summary with a ``position`` and
    no ``orientation`` says they had not; None when the report has no summary."""
    summaries = [(doc.get("fit") or {}).get("calibration_errors"),
                 (doc.get("diagnosis") or {}).get("calibration_errors")]
    summaries += [(e.get("models") or [{}])[-1].get("errors")
                  for e in doc.get("row_errors") or [] if isinstance(e, dict)]
    known = [s for s in summaries if isinstance(s, dict) and "position" in s]
    return any(s.get("orientation") is not None for s in known) if known else None


def _registration(doc: dict) -> dict[str, Any] | None:
    registration, tool = doc.get("registration") or {}, doc.get("tool") or {}
    if not registration and not tool:
        return None
    measured = orientations_measured(doc)
    entries = []
    position, orientation = registration.get("position"), registration.get("orientation")
    sessions = cast(list, doc.get("sessions")) if isinstance(doc.get("sessions"), list) else []
    whose = ""
    if len(sessions) > 1 and isinstance(sessions[0], dict):  # the top-level registration is the first session's
        whose = f"session '{sessions[0].get('name')}' (the first of {len(sessions)}; each one's below): "
    if position:
        same = orientation is None or orientation == position
        what = {True: "registration (positions and orientations)", False: "registration (positions; no orientations "
                "measured)", None: "registration"}[measured]
        entries.append((whose + ("Registration 1 (positions)" if not same else what), rotation_text(position)))
    if orientation and orientation != position:
        entries.append((whose + "Registration 2 (orientations)", rotation_text(orientation)))
    xyz, rpy = tool.get("xyz_m") or [], tool.get("rpy_rad") or []
    estimated = "points_m" in tool
    return {
        "entries": entries,
        "tool_parent": tool.get("parent_link"),
        "tool_xyz": fixed(xyz, 3, 1000.0),
        "tool_rpy": fixed(rpy, 5),
        "tool_rpy_deg": fixed(rpy, 3, 180.0 / math.pi),
        "points": [fixed(p, 3, 1000.0).split(", ") for p in tool.get("points_m") or []],
        "estimated": estimated,
        # without orientations the fit has no rotation of the target to estimate: the tip frame's is shown
        "status": ("given" if not estimated else "estimated" if measured is not False
                   else "points estimated; its rotation is not: no orientations were measured"),
        "rotation_note": ("the tip frame's, not estimated: the data have no orientations"
                          if estimated and measured is False else None),
    }


def render_html(document: dict[str, Any], evaluation: dict[str, Any] | None = None,
                base: str | Path | None = None, source: str | Path | None = None,
                camera: dict[str, Any] | None = None) -> str:
    """The report page of ``document`` (a REPORT.json, or ``evaluate --json`` metrics) as HTML.

    Args:
        document: the parsed JSON.
        evaluation: what ``pincal evaluate`` measured with this report, shown beside it:
            ``{"urdf", "data", "errors", "row_errors"}``
            (:func:`pincal.report.row_errors.evaluation_document`).
        base: folder of the report; relative plot paths of ``diagnose`` are also looked up there.
        source: the file ``document`` was read from, named in the error of a malformed one.
        camera: a camera's section, its reprojection errors per image and a picture of one image
            (:func:`pincal.report.camera_figures.camera_section`); None: none shown.
    """
    try:
        if is_plan(document):  # a PLAN.json: its own page, the same look
            context = plan_context(document, Path(base) if base is not None else Path.cwd(), figures)
            context["colours"] = {"nominal": NOMINAL, "calibrated": CALIBRATED, "flag": FLAG}
            return _environment().get_template(PLAN_TEMPLATE).render(**context)
        return _render(document, evaluation, base, camera)
    except (LookupError, TypeError, ValueError, AttributeError, UndefinedError) as exc:
        where = f"{source}: " if source is not None else ""
        raise PincalError(f"{where}the report has an unexpected form ({type(exc).__name__}: {exc}); "
                          "pass a REPORT.json written by pincal calibrate or diagnose") from None


def _render(document: dict[str, Any], evaluation: dict[str, Any] | None, base: str | Path | None,
            camera: dict[str, Any] | None = None) -> str:
    if "parameters" not in document and "position" in document:  # evaluate --json alone
        evaluation = {"errors": document, "data": None, "urdf": None, "sessions": document.get("sessions") or [],
                      "drift": document.get("drift"), "thermal": document.get("thermal"),
                      "pause_steps": document.get("pause_steps"), **(evaluation or {})}
        document = {}
    base = Path(base) if base is not None else Path.cwd()
    kinds = dict(zip((document.get("chain") or {}).get("joints") or [],
                     (document.get("chain") or {}).get("joint_kinds") or []))
    params = parameter_section(document, figures.parameter_figure)
    sessions = sessions_section(document) if document.get("registration") else None
    fixture = fixture_section(document, evaluation) if isinstance(document.get("fixture"), dict) else None
    tree = tree_section(document, evaluation)  # several targets: each one's errors instead of one chain's
    if camera is None and is_camera(document):  # a camera's REPORT.json: its section from the report alone
        camera = camera_page(document)
    shown = KNOWN_KEYS | ({"sessions"} if sessions else set()) | ({"fixture", "measurement"} if fixture else set()) | (
        {"targets"} if tree else set()) | ({"camera", "measurement", "fit_seconds", "xacro_args"} if is_camera(
        document) else set())
    extra = [(key, generic(value)) for key, value in document.items()
             if key not in shown and value not in (None, {}, [], "")]
    sources = document.get("sources") or {}
    if is_camera(document):
        kind = camera_title(document)
    elif document.get("method") is not None:
        kind = f"Method {document['method']} calibration"
    elif "diagnosis" in document:
        kind = "Diagnosis" + (f" of {len(tree['rows'])} targets" if tree else "")
    elif fixture is not None:
        kind = f"Socket-fixture calibration ({document.get('level')})"
    elif document.get("level"):
        kind = f"Calibration ({document['level']})" + (f" of {len(tree['rows'])} targets" if tree else "")
    else:
        kind = "Evaluation"
    robot = Path(str(sources["urdf"])).name if sources.get("urdf") else None
    context = {
        "title": f"{kind}" + (f" — {robot}" if robot else ""),
        "kind": kind,
        "robot": robot,
        "chain": _chain(document.get("chain")),
        "summary": _summary(document, evaluation, (camera or {}).get("facts") or []),
        "rows": _rows(document, evaluation),
        "params": params,
        "ident": _identifiability(document),
        "registration": None if fixture else _registration(document),  # a fixture has no sensor
        "fixture": fixture,
        "camera": camera,
        "tree": tree,
        "sessions": sessions if sessions and len(sessions) > 1 else None,  # one session: the registration above
        "effects": effects_section(document, kinds, base, figures.png_uri),
        "notes": [str(n) for n in document.get("notes") or []],
        "warnings": [str(w.get("message", w)) if isinstance(w, dict) else str(w)  # the evaluation's after the fit's
                     for w in [*(document.get("warnings") or []), *((evaluation or {}).get("warnings") or [])]],
        "extra": extra,
        "version": document.get("pincal_version"),
        "report_version": document.get("report_version"),
        "urdf_sha256": document.get("urdf_sha256"),
        "evaluation": evaluation,
        "evaluated_sessions": evaluated_sessions(evaluation),
        "colours": {"nominal": NOMINAL, "calibrated": CALIBRATED, "flag": FLAG},
        "legend": _legend(document, evaluation),
    }
    return _environment().get_template(TEMPLATE).render(**context)


def _legend(doc: dict, evaluation: dict | None) -> list[tuple[str, str]]:
    """The page's one colour key (:data:`pincal.palette.LEGEND`): the models this report shows."""
    sets = list(doc.get("row_errors") or []) + list((evaluation or {}).get("row_errors") or [])
    names = {str(m.get("model")) for e in sets for m in e.get("models") or [] if isinstance(m, dict)}
    names = names or {"calibrated geometry"}
    return [(label, colour) for label, colour in LEGEND if any(model_colour(n) == colour for n in names)]


#: The tip of a tree's chain, which has one per target (REPORT.json ``targets``).
_TIPS = "each target's tip link"


def _chain(chain: Any) -> dict[str, Any] | None:
    if not isinstance(chain, dict):
        return None
    return {"root": chain.get("root_link", "?"), "tip": chain.get("tip_link") or _TIPS,
            "joints": len(chain.get("joints") or [])}


def write_html(path: str | Path, document: Mapping[str, Any], evaluation: dict[str, Any] | None = None,
               base: str | Path | None = None, source: str | Path | None = None,
               camera: dict[str, Any] | None = None) -> None:
    """Render ``document`` (read from ``source``; with a ``camera`` section, :func:`render_html`) and write it
    to ``path`` atomically (:func:`pincal.outputs.write_text`)."""
    write_text(path, render_html(dict(document), evaluation, base, source, camera))
