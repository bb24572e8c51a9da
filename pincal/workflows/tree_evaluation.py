"""``pincal evaluate`` of a calibration of several targets (a REPORT.json with ``targets``,
:mod:`pincal.report.model_tree`): eq 24's position error of every point seen in every non-CPA row,
each target's points in their tip link as reported, each row through its session's registration
(:func:`evaluate_tree_files`). A target whose orientation the rows measure (``qxN,qyN,qzN,qwN``) and
the report calibrated (its ``rotation_xyzw``) adds eq 24's orientation error, the angle of
G_ktᵀ Omega R_k,t R_T,t, on the rows where it was seen (``--max-rot-deg`` judges the largest).

The registration of a row is the report's session's of the same name, the report's only one for rows
of a session it has not seen (held-out rows of the same setup), or — with ``--new-session`` — each
session of the data registered anew with the model and the points fixed (Arun et al. 1987 on the seen
points: the least-squares rigid registration of equally weighted points). What evaluate does with one
chain and not yet with a tree — ``--fixed-registration``, ``--temperature-column`` — is refused in one line;
``--json`` writes :class:`pincal.report.model_tree.TreeEvaluationJson`, ``--html`` the report's page
(:mod:`pincal.report.tree_html`) with each target's errors on the evaluated rows beside its own, both made
before either is written.

The report's ``couplings`` (``--coupling``) are applied to the rows as the calibration did: a reading taken against
another joint corrected (eq C1 of :mod:`pincal.measurements.couplings`), a joint it made follow its driver computed
from it (its column, if any, checked).

A report of ``diagnose`` carries its effects (``effects``, as its effects.yaml): each joint effect shifts its
joint's reading, at the loads of the evaluated rows' readings (:func:`pincal.model.tree_effects.tree_inputs`), a
lateral compliance bends every target's chain that has its joint (eq L1 of :mod:`pincal.model.lateral`), a
sensor scale scales the sensed points; a drift is the calibration's sensor, not applied (a note says so).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, cast

import numpy as np
from scipy.spatial.transform import Rotation

from pincal.errors import PincalError
from pincal.fit.registration import register_points
from pincal.fit.sessions import session_rows
from pincal.fit.tree_calibration import tree_rows
from pincal.measurements.couplings import couplings_from_report
from pincal.measurements.csv_v1 import read_measurements
from pincal.measurements.data import MeasurementSet
from pincal.model.effects import BEND_EFFECTS, JOINT_EFFECTS, effect_from_dict, joint_shifts
from pincal.model.lateral import bend_angles
from pincal.model.sensor import Registration
from pincal.model.tree import KinematicTree, TargetSpec
from pincal.model.tree_effects import TreeBody, target_inputs, tree_inputs
from pincal.outputs import file_sha256
from pincal.report.document import write_evaluation
from pincal.report.model_tree import TargetErrors, TreeEvaluationJson
from pincal.report.reading import load_report, value_at
from pincal.report.tree import target_errors
from pincal.residuals.tree import TreeRows
from pincal.workflows.paths import description_inputs, refuse_overwrite
from pincal.workflows.report_page import refuse_page, write_page
from pincal.workflows.settings import EvaluateSettings

__all__ = ["TreeEvaluation", "evaluate_tree_files"]


@dataclass(frozen=True)
class TreeEvaluation:
    """Outcome of :func:`evaluate_tree_files`.

    Attributes:
        targets: each target's link and its points' errors on the evaluated rows (:class:`TargetErrors`, of
            its points seen in some row; None: no point of it seen).
        rows: how many rows were evaluated.
        registrations: how each session of the data was registered (``session: source``).
        max_mm: the largest error of any point [mm] (``--max-pos-mm`` judges it).
        notes: the reader's notes and what the user should know.
        points: each target's point numbers.
        max_deg: the largest orientation error of any target [deg] (``--max-rot-deg`` judges it); None: no
            orientation evaluated.
        html: the page written (``--html``), or None.
    """

    targets: tuple[tuple[str, TargetErrors | None], ...]
    rows: int
    registrations: tuple[str, ...]
    max_mm: float
    notes: tuple[str, ...]
    points: tuple[tuple[int, ...], ...] = ()
    max_deg: float | None = None
    html: Path | None = None

    def as_dict(self) -> TreeEvaluationJson:
        """``evaluate --json``'s document (:class:`pincal.report.model_tree.TreeEvaluationJson`)."""
        out: TreeEvaluationJson = {
            "rows": self.rows, "registrations": list(self.registrations),
            "evaluated_targets": [{"tip_link": link, "points": list(points), "errors": errors}
                                  for (link, errors), points in zip(self.targets, self.points)],
            "max_mm": self.max_mm, "notes": list(self.notes)}
        if self.max_deg is not None:
            out["max_deg"] = self.max_deg
        return out


def evaluate_tree_files(urdf: str | Path, report_path: str | Path, data_path: str | Path,
                        settings: EvaluateSettings | None = None, json_path: str | Path | None = None,
                        html_path: str | Path | None = None) -> TreeEvaluation:
    """Eq 24's position errors of the model of a tree's report on the non-CPA rows of ``data_path``; with
    ``json_path``, written there too (``evaluate --json``: :meth:`TreeEvaluation.as_dict`); with ``html_path``,
    the report's page with each target's errors on these rows (``evaluate --html``).

    Raises:
        PincalError: a setting a tree does not take yet; ``urdf`` not the file written with the report (its
            SHA-256), unless ``settings.allow_other_urdf``; anything :func:`pincal.fit.tree_calibration.tree_rows`
            refuses; rows of a session the report does not have while it has several (``--new-session``).
    """
    settings = EvaluateSettings() if settings is None else settings
    for refused, flag in ((settings.fixed_registration is not None, "--fixed-registration"),
                          (settings.temperature_column is not None, "--temperature-column")):
        if refused:
            raise PincalError(f"several --tip-link: {flag} is not yet supported by evaluate; leave it out")
    inputs = [*description_inputs(urdf, settings.xacro_args), report_path, data_path]
    if json_path is not None:
        refuse_overwrite(json_path, *inputs)
    page_path = refuse_page(html_path, inputs, [] if json_path is None else [json_path])
    document = cast(dict[str, Any], load_report(report_path, ("tree",)))
    notes: list[str] = []
    if file_sha256(urdf) != value_at(document, "urdf_sha256", report_path):
        if not settings.allow_other_urdf:
            raise PincalError(f"{urdf}: not the URDF {report_path} was written with (its SHA-256 differs from the "
                              "report's urdf_sha256); evaluate the pair calibrate wrote, or pass --allow-other-urdf if "
                              "you changed it on purpose")
        notes.append(f"{urdf}: not the URDF {report_path} was written with (--allow-other-urdf)")
    targets = value_at(document, "targets", report_path, _targets)
    frames = value_at(document, "targets", report_path, _frames)
    tree = KinematicTree.from_urdf(urdf, [spec for spec, _ in targets], xacro_args=settings.xacro_args)
    couplings = couplings_from_report(document.get("couplings"), str(report_path))
    tree.follow(couplings)  # a joint the calibration made follow its driver (couplings[].follows)
    data, read_notes = read_measurements(data_path, tree.joint_specs, couplings, tree.other_branch_joints,
                                         occlusion=True)
    if couplings:
        notes.append(f"{data_path}: readings corrected as {report_path} says (couplings: "
                     f"{', '.join(c.label for c in couplings)})")
    data = data.select(data.roles != "cpa")
    names, reported = value_at(document, "sessions", report_path, _sessions)
    rows = tree_rows(tree, data)
    if not rows.seen.any():
        raise PincalError(f"{data_path}: no measured point in a row that is not role=cpa ({data.n_rows} such rows); "
                          "nothing to evaluate: give rows where a target's point is measured")
    q, scale, bends, effect_notes = _with_effects(tree, data, document.get("effects") or [])
    notes += effect_notes
    world = tree.target_points(q, [points for _, points in targets], bends)  # (K, P, 3) [m]
    if settings.new_session:
        for s, name in enumerate(data.session_names):  # a rigid registration needs three points (Arun et al. 1987)
            if (count := int(rows.seen[rows.sessions == s].sum())) < 3:
                raise PincalError(f"{data_path}: session '{name}' has {count} measured point(s) in rows that are not "
                                  "role=cpa; --new-session registers each session on at least 3: leave its rows "
                                  "out, or evaluate without --new-session")
        registrations = [register_points(world[rows.sessions == s][rows.seen[rows.sessions == s]],
                                         rows.points[rows.sessions == s][rows.seen[rows.sessions == s]])
                         for s in range(len(data.session_names))]
        sessions = rows.sessions
        how = [f"{name}: re-estimated (--new-session)" for name in data.session_names]
    else:
        registrations, sessions = reported, session_rows(data, names)
        how = [f"{name}: the report's" + ("" if name in names else f" '{names[0]}'") for name in data.session_names]
    omega = np.stack([r.rotation for r in registrations])[sessions]
    tau = np.stack([r.translation for r in registrations])[sessions]
    sensed = (1.0 + scale) * (np.einsum("kij,kpj->kpi", omega, world) + tau[:, None, :])
    errors = np.linalg.norm(np.where(rows.seen[..., None], sensed - rows.points, np.nan), axis=2)  # (K, P) [m]
    turns, turn_notes = _orientation_errors(tree, rows, [frame for _, frame in frames], omega, (q, bends))
    notes += turn_notes
    if settings.max_rot_deg is not None and turns is None:
        raise PincalError(f"{data_path}: --max-rot-deg: no orientation of a target the report calibrated with its "
                          "orientation is measured in these rows (columns qxN,qyN,qzN,qwN); leave it out")
    seen = np.any(rows.seen, axis=0)  # (P,) each point seen in some row
    per_target: list[tuple[str, TargetErrors | None]] = []
    for t, (spec, _) in enumerate(targets):
        numbers = tuple(p for p in spec.points if seen[p - 1])
        mine = None if turns is None or frames[t][1] is None else turns[:, t]
        per_target.append((spec.link, target_errors(errors, numbers, mine) if numbers else None))
        if numbers and numbers != spec.points:
            missing = ", ".join(str(p) for p in spec.points if p not in numbers)
            notes.append(f"{data_path}: point(s) {missing} of {spec.link} not seen in any row; its errors are those "
                         f"of point(s) {', '.join(map(str, numbers))}")
    evaluation = TreeEvaluation(tuple(per_target), data.n_rows, tuple(how), float(np.nanmax(errors)) * 1000.0,
                                tuple(read_notes + notes), tuple(spec.points for spec, _ in targets),
                                None if turns is None else float(np.degrees(np.nanmax(turns))))
    page = None
    if page_path is not None:  # made before anything is written: a report it cannot show leaves no output
        from pincal.report.html import render_html  # Jinja2 and the figures only when a page is asked for

        shown = {"urdf": str(urdf), "data": str(data_path), **evaluation.as_dict()}
        page = render_html(document, evaluation=cast(dict[str, Any], shown), base=Path(report_path).parent,
                           source=report_path)
    if json_path is not None:
        write_evaluation(json_path, evaluation.as_dict())
    return replace(evaluation, html=write_page(page_path, page))


def _with_effects(tree: KinematicTree, data: MeasurementSet, entries: Any
                  ) -> tuple[np.ndarray, float, list[np.ndarray | None] | None, list[str]]:
    """The rows' tree joint values with a report's joint effects applied (actual = reading + shift, followers
    moved with their drivers, eq M1), its sensor scale s, each target's lateral deflections (K, 2 N_t) [rad] of
    its lateral compliances (eq L1-L3 of :mod:`pincal.model.lateral`; None without one), and notes on what is not
    applied."""
    effects = [effect_from_dict(entry) for entry in entries]
    if not effects:
        return data.q, 0.0, None, []
    body = TreeBody(tree)
    inputs = tree_inputs(tree, data, loads=any(e.moments for e, _ in effects))
    joint = [(e, v) for e, v in effects if e.type in JOINT_EFFECTS]
    shifts = joint_shifts([e for e, _ in joint], [v for _, v in joint], inputs, tree.joint_names)
    scale = sum(float(v[0]) for e, v in effects if e.type == "sensor_scale")
    lateral = [(e, v) for e, v in effects if e.type in BEND_EFFECTS]
    bends = [bend_angles([e for e, _ in lateral if e.joint in t.chain.joint_names],
                         [v for e, v in lateral if e.joint in t.chain.joint_names], target_inputs(inputs, t),
                         t.chain.joint_names) for t in tree.targets] if lateral else None
    others = [e.label for e, _ in effects if e.type not in (*JOINT_EFFECTS, *BEND_EFFECTS, "sensor_scale")]
    notes = [f"the report's {', '.join(others)}: the calibration sensor's, not applied to these rows"] if others else []
    return data.q + body.followed_shifts(shifts), scale, bends, notes


def _targets(entries: Any) -> list[tuple[TargetSpec, np.ndarray]]:
    """REPORT.json ``targets`` as (link and points, the points in the link (P_t, 3) [m])."""
    out = []
    for entry in entries:
        points = np.asarray(entry["points_m"], dtype=float).reshape(-1, 3)
        spec = TargetSpec(str(entry["tip_link"]), tuple(int(p) for p in entry["points"]))
        if points.shape[0] != len(spec.points):
            raise ValueError(f"{spec.link}: {len(spec.points)} points but {points.shape[0]} positions")
        out.append((spec, points))
    return out


def _frames(entries: Any) -> list[tuple[str, np.ndarray | None]]:
    """REPORT.json ``targets``' frame rotations in their links R_T,t (``rotation_xyzw``), None for a target
    calibrated without its orientation."""
    return [(str(e["tip_link"]), None if "rotation_xyzw" not in e else
             Registration.from_dict({"rotation_xyzw": e["rotation_xyzw"], "translation_m": [0.0, 0.0, 0.0]}).rotation)
            for e in entries]


def _orientation_errors(tree: KinematicTree, rows: TreeRows, frames: list[np.ndarray | None], omega: np.ndarray,
                        model: tuple[np.ndarray, list[np.ndarray | None] | None]
                        ) -> tuple[np.ndarray | None, list[str]]:
    """Each target's orientation error in each row [rad], the angle of G_ktᵀ Omega R_k,t R_T,t (eq 24), NaN where
    not seen or not calibrated (K, T), or None when no such pair is seen; notes on orientations measured that the
    report did not calibrate. ``model``: the rows' joint values with the effects and each target's bends."""
    if rows.rotation_seen is None or rows.rotations is None:
        return None, []
    seen = rows.rotation_seen.copy()
    uncalibrated = [t for t, frame in enumerate(frames) if frame is None and seen[:, t].any()]
    seen[:, uncalibrated] = False
    notes = [f"{tree.targets[t].link}: its orientation is measured, but the report calibrated it without; not "
             "evaluated" for t in uncalibrated]
    if not seen.any():
        return None, notes
    model_frames = tree.target_rotations(model[0], [np.eye(3) if f is None else f for f in frames], model[1])
    relative = rows.rotations.transpose(0, 1, 3, 2) @ omega[:, None] @ model_frames  # G_ktᵀ Omega R_k,t R_T,t
    angles = np.linalg.norm(Rotation.from_matrix(relative.reshape(-1, 3, 3)).as_rotvec(), axis=1)
    return np.where(seen, angles.reshape(seen.shape), np.nan), notes


def _sessions(entries: Any) -> tuple[list[str], list[Registration]]:
    """REPORT.json ``sessions`` as their names and registrations (Registration 1)."""
    return ([str(e["name"]) for e in entries],
            [Registration.from_dict(e["registration"]["position"]) for e in entries])
