"""``pincal evaluate``: eq 24 errors of a calibrated model on measured rows, session by session.

Which registration (sensor_T_base) the rows of DATA are evaluated through — the
rule, in order:

1. ``--fixed-registration [NAME]``: the reported registration of session NAME
   (default: the report's only or first session) for every row.
2. ``--new-session``: every session of DATA is new; its registration is re-estimated.
3. A report of one session (and reports older than ``sessions``): its
   registration for every row, as before several sessions existed — whatever
   the file is called and whatever its ``session`` column says (a note says so
   when DATA names sessions of its own: pass ``--new-session`` if the sensor moved).
4. A report of several sessions, per session of DATA: rows whose ``session``
   cell names a reported session in full (``A``, ``BC:B``) use its
   registration; so do the rows of a file whose path is the one a reported
   session was read from (REPORT.json ``sessions[].file``, as given to
   calibrate): rows without a ``session`` cell take that file's session, rows
   with a cell VALUE the session ``STEM:VALUE`` (or ``VALUE``) of that file.
   Any other session — a file merely named like a session (``val/A.csv``) —
   is one the fit has not seen: its registration is re-estimated.

A ``drift`` effect of the report is never extrapolated: a row outside the time
span of the rows it was fitted on in the session whose registration it uses
(another day) is evaluated with the drift held at that session's mean time —
for a one-session fit, without the drift term; a re-estimated registration
(which absorbs any constant offset) holds it at the nearer end of one span for
the whole session, the span nearest its median time
(:func:`pincal.model.drift.drift_offsets`); a note says how many rows,
and ``drift`` in ``--json`` records it.

A ``thermal`` expansion and ``pause_step`` effects are never extrapolated either: a row outside
the fitted temperature range is held at its nearer end, a row outside the fitted time span takes
its nearest segment (:mod:`pincal.workflows.conditions`).

Re-estimated means only its 6 parameters, with the model and the target fixed
(:func:`pincal.fit.sessions.register_session`), on the evaluated rows: those
errors then leave out the error of a registration, and are optimistic — after
fitting 6 parameters to N residuals (3 per target point of a row, 3 more with
an orientation) the RMS of what is left is about sqrt((N − 6) / N) of the true
error. Each re-estimated session reports N and its degrees of freedom N − 6
(``registration_dof``); a threshold (``--max-pos-mm``, ``--max-rot-deg``) is
refused when a re-estimated session has fewer than :data:`MIN_THRESHOLD_DOF`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, cast

import numpy as np

from pincal.errors import PincalError
from pincal.fit.metrics import PoseErrors, RowCorrections
from pincal.fit.plausibility import Finding, check_evaluation
from pincal.fit.sessions import register_session, session_pose_errors
from pincal.measurements.csv_v1 import read_measurements, read_table
from pincal.measurements.data import (
    SESSION_COLUMN,
    MeasurementSet,
    default_session_name,
)
from pincal.model.chain import KinematicChain
from pincal.model.description import RobotDescription, read_description
from pincal.model.drift import drift_offsets, read_time_spans, time_column
from pincal.model.effects import RowContext, effect_from_dict, effect_inputs, joint_shifts, with_loads
from pincal.model.lateral import bend_angles
from pincal.model.sensor import Registration
from pincal.outputs import file_sha256
from pincal.report.document import ReportModel, read_report
from pincal.report.model import TimeSpanJson, errors_json, findings_json, registration_pair
from pincal.report.model_evaluation import DriftUse, EvaluatedSession, EvaluationJson, PauseStepUse, ThermalUse
from pincal.report.sessions import session_errors
from pincal.workflows.conditions import applied_conditions
from pincal.workflows.settings import EvaluateSettings, expect

__all__ = [
    "REESTIMATED", "REGISTRATION_PARAMETERS", "MIN_THRESHOLD_DOF", "THE_REGISTRATION", "HELD_DRIFT",
    "SessionEvaluation", "Evaluation", "evaluate_files",
]

REESTIMATED = "re-estimated on these rows (6 parameters; model and target fixed)"
#: Registration parameters a re-estimated session fits to its own rows.
REGISTRATION_PARAMETERS = 6
#: Fewest degrees of freedom (residuals − 6) a re-estimated session must leave for a
#: threshold check: below 6 the errors are under sqrt(1/2) ≈ 0.71 of the true error
#: (the factor sqrt((N − 6) / N) at N = 12), too optimistic to pass or fail a robot on.
MIN_THRESHOLD_DOF = 6
#: The session a report without ``sessions`` holds a drift in: no session name (not None, which is
#: a re-estimated registration): :func:`drift_offsets` takes the span nearest the rows (its only one).
THE_REGISTRATION = ""
#: One session of the evaluated rows as the module's rule plans it: its name, its rows, and (source, Registration 1,
#: Registration 2, reported session name) of the reported registration it uses, or None: re-estimated.
SessionPlan = tuple[str, np.ndarray, "tuple[str, Registration, Registration, str] | None"]
#: How rows outside the fitted time spans are evaluated (``drift.held_rule`` in ``--json``).
HELD_DRIFT = ("drift not extrapolated: a row outside the time span it was fitted on in its registration's session "
              "uses the drift at that session's mean time (no drift term for a one-session fit); a re-estimated "
              "registration, at the nearer end of the span nearest its session's median time; without time_spans_s "
              "(older reports) every row "
              "uses offset 0")


@dataclass(frozen=True)
class SessionEvaluation:
    """One session of the evaluated rows.

    Attributes:
        name: the session in DATA.
        rows: rows evaluated.
        registration: the registration used (Registration 1; ``orientation`` Registration 2).
        source: ``reported session 'NAME'``, ``the report's registration`` or :data:`REESTIMATED`.
        errors: eq 24 on its rows.
        residuals: scalar residuals of its rows (3 per target point, 3 more with an orientation).
    """

    name: str
    rows: int
    registration: Registration
    orientation: Registration
    source: str
    errors: PoseErrors
    residuals: int = 0

    @property
    def reestimated(self) -> bool:
        return self.source == REESTIMATED

    @property
    def dof(self) -> int | None:
        """Degrees of freedom left by a re-estimated registration: residuals − 6 (None if reported)."""
        return self.residuals - REGISTRATION_PARAMETERS if self.reestimated else None

    @property
    def shrink(self) -> float | None:
        """sqrt((N − 6) / N): about how much smaller than the true error its errors are (re-estimated only)."""
        if not self.reestimated or self.residuals <= 0:
            return None
        return float(np.sqrt(max(self.residuals - REGISTRATION_PARAMETERS, 0) / self.residuals))

    def as_dict(self) -> EvaluatedSession:
        return {"name": self.name, "rows": self.rows, "registration_source": self.source,
                "registration_reestimated": self.reestimated,
                "residuals": self.residuals, "registration_dof": self.dof,
                "registration": registration_pair(self.registration, self.orientation),
                "errors": errors_json(self.errors)}


@dataclass(frozen=True)
class Evaluation:
    """Outcome of :func:`evaluate_files`: eq 24 errors on the evaluated rows."""

    errors: PoseErrors
    n_skipped_cpa: int
    notes: list[str]
    lines: tuple[int, ...] = ()  # file line of each evaluated row (the HTML report's row table)
    sessions: tuple[SessionEvaluation, ...] = ()
    files: tuple[str, ...] = ()  # the file of each evaluated row
    row_sessions: tuple[str, ...] = ()  # the session (in DATA) of each evaluated row
    drift: DriftUse | None = None  # how the report's drift was applied (_effect_corrections); None without
    # the nominal model's RMS point error on these rows, its registration and target fitted to them [mm],
    # and its URDF; None where the report's sources.urdf is not readable here (before -> after)
    nominal_rms_mm: float | None = None
    nominal_urdf: str | None = None
    thermal: ThermalUse | None = None  # how the report's thermal expansion was applied (pincal.workflows.conditions)
    pause_steps: PauseStepUse | None = None  # ... and its pause steps
    warnings: tuple[Finding, ...] = ()  # the evaluated error against the calibration's (check_evaluation)

    def as_dict(self) -> EvaluationJson:
        """``pincal evaluate --json``."""
        out: EvaluationJson = {**errors_json(self.errors), "skipped_cpa_rows": self.n_skipped_cpa,
                               "sessions": [s.as_dict() for s in self.sessions], "drift": self.drift,
                               "warnings": findings_json(list(self.warnings))}
        if self.nominal_rms_mm is not None and self.nominal_urdf is not None:
            out["before"] = {"position_rms_mm": self.nominal_rms_mm, "urdf": self.nominal_urdf,
                             "registration": "fitted to the evaluated rows"}
        if self.thermal is not None:
            out["thermal"] = self.thermal
        if self.pause_steps is not None:
            out["pause_steps"] = self.pause_steps
        return out

    def threshold_problem(self) -> str | None:
        """Why a threshold cannot judge these errors (a re-estimated session with fewer than
        :data:`MIN_THRESHOLD_DOF` degrees of freedom left), with what to do; None if it can."""
        for session in self.sessions:
            if session.dof is not None and session.dof < MIN_THRESHOLD_DOF:  # re-estimated only
                per_row = session.residuals // max(session.rows, 1)
                needed = -(-(REGISTRATION_PARAMETERS + MIN_THRESHOLD_DOF) // max(per_row, 1))
                return (f"session '{session.name}': its registration is re-estimated from its own "
                        f"{session.residuals} residuals ({session.dof} degree(s) of freedom left, fewer than "
                        f"{MIN_THRESHOLD_DOF}), so its errors are about {session.shrink:.2f} of the true ones: too "
                        f"optimistic for a threshold; measure at least {needed} rows in the session, or reuse a "
                        "reported registration (--fixed-registration NAME)")
        return None


def evaluate_files(
    urdf: str | Path, report_path: str | Path, data_path: str | Path, settings: EvaluateSettings | None = None,
) -> Evaluation:
    """Eq 24 on every non-CPA row of ``data_path`` with the model of a report, each
    session through the registration the module's rule gives it (``settings``:
    :class:`pincal.workflows.settings.EvaluateSettings`; None: its defaults).

    When the report records the SHA-256 of the URDF written with it
    (``urdf_sha256``), ``urdf`` must be that file — a run killed between
    writing the URDF and the report, or a report of another run, is refused —
    unless ``settings.allow_other_urdf`` (the URDF was edited on purpose; a note says so).
    """
    settings = EvaluateSettings() if settings is None else settings
    expect(settings, EvaluateSettings, "evaluate_files")
    allow_other_urdf, xacro_args = settings.allow_other_urdf, settings.xacro_args
    fixed_registration, new_session = settings.fixed_registration, settings.new_session
    report = read_report(report_path)
    description = read_description(urdf, xacro_args)
    _check_pair(description, urdf, report, report_path)  # before the chain: say the report is another URDF's
    notes: list[str] = []
    if report.urdf_sha256 is not None and file_sha256(urdf) != report.urdf_sha256:
        if not allow_other_urdf:
            raise PincalError(
                f"{urdf}: not the URDF {report_path} was written with (its SHA-256 differs from the report's "
                "urdf_sha256); evaluate the pair calibrate wrote, or pass --allow-other-urdf if you changed it "
                "on purpose"
            )
        notes.append(f"{urdf}: not the URDF {report_path} was written with (--allow-other-urdf)")
    chain = KinematicChain.from_description(description, report.tool_parent)
    chain.follow(report.couplings)  # a joint the calibration made follow its driver (couplings[].follows)
    # the readings corrected as the calibration's were (eq C1), before the joint limits are judged
    data, read_notes = read_measurements(data_path, chain.joint_specs, report.couplings, chain.other_branch_joints)
    notes += read_notes
    if report.couplings:
        notes.append(f"{data_path}: readings corrected as {report_path} says (couplings: "
                     f"{', '.join(c.label for c in report.couplings)})")
    if report.not_determined:  # rows at another tool orientation meet the held target's error
        notes.append(f"{report_path}: the calibration could not place its target ({len(report.not_determined)} "
                     "direction(s) held at the tip link's origin, identifiability.not_determined): rows at another "
                     "tool orientation than the calibration's carry that error; calibrate with --tool to use the "
                     "model there")
    if report.held_rotations:  # rows off the calibration's line meet the held rotation's error
        notes.append(f"{report_path}: the calibration rows lay on one line, so the sensor's rotation about it was "
                     "held (identifiability.not_determined_rotations): rows off that line, or in a registration "
                     "re-estimated on them, test a geometry the calibration did not check")
    if data.n_points != len(report.points):
        raise PincalError(
            f"{data_path}: {data.n_points} target point(s) per row, but the report's tool has "
            f"{len(report.points)}; evaluate with data of the same target"
        )
    rows = data.roles != "cpa"
    if not np.any(rows):
        raise PincalError(f"{data_path}: no rows to evaluate (all rows have role 'cpa')")
    data = data.select(rows)
    plan, plan_notes = _registrations(report, data, _labelled(data_path, data), fixed_registration, new_session,
                                      report_path, data_path)
    notes += plan_notes
    held = np.empty(data.n_rows, dtype=object)  # the session whose time span holds a drift (None: re-estimated)
    group = np.empty(data.n_rows, dtype=np.intp)  # the evaluated session of each row: one span each
    for g, (_, members, reported) in enumerate(plan):
        held[members] = None if reported is None else reported[3]
        group[members] = g
    corrections, drift_use = _effect_corrections(chain, data, report.effects, report.points, (held, group),
                                                 report_path)
    applied = applied_conditions([effect_from_dict(e) for e in report.effects.get("effects", [])], report.effects,
                                 data, (held, group), settings.temperature_column, report_path)
    notes += applied.notes
    if applied.conditions is not None:  # thermal expansion, pause steps (eq T1-T2 of pincal.model.thermal)
        corrections = replace(corrections, conditions=applied.conditions)
    if drift_use is not None and drift_use["rows_held"]:
        notes.append(_drift_note(data_path, drift_use))
    index = np.empty(data.n_rows, dtype=np.intp)
    positions, orientations, sources = [], [], []
    for s, (_, members, reported) in enumerate(plan):
        index[members] = s
        if reported is None:
            sigma_pos_mm = report.noise.get("sigma_pos_mm")
            sigma_rot_deg = report.noise.get("sigma_rot_deg")
            registration = register_session(
                chain, data.select(members), report.points, report.rotation, corrections.select(members),
                sigma_pos_m=sigma_pos_mm / 1000.0 if sigma_pos_mm else 1e-3,
                sigma_rot_rad=np.radians(sigma_rot_deg) if sigma_rot_deg else 1e-3,
            )
            used = (REESTIMATED, registration, registration)
        else:
            used = reported[:3]
        sources.append(used[0])
        positions.append(used[1])
        orientations.append(used[2])
    errors = session_pose_errors(chain, data, index, positions, orientations, points=report.points,
                                 target_rotation=report.rotation, corrections=corrections)
    per_row = 3 * data.n_points + (3 if data.has_orientation else 0)  # scalar residuals of a row
    sessions = tuple(
        SessionEvaluation(name, len(members), positions[s], orientations[s], sources[s],
                          session_errors(errors, members), per_row * len(members))
        for s, (name, members, _) in enumerate(plan)
    )
    for session in sessions:
        if session.reestimated:
            notes.append(
                f"{data_path}: session '{session.name}': errors are after fitting {REGISTRATION_PARAMETERS} "
                f"registration parameters to {session.residuals} residuals ({session.dof} degree(s) of freedom "
                f"left); expect them about sqrt(({session.residuals}−{REGISTRATION_PARAMETERS})/{session.residuals}) "
                f"= {session.shrink:.2f} of the true error")
    nominal_rms, nominal_urdf = _nominal_rms(report, report_path, data, xacro_args)
    warnings = check_evaluation(errors.position.rms / 1000.0, None if report.calibration_rms_mm is None
                                else report.calibration_rms_mm / 1000.0, any(not s.reestimated for s in sessions))
    return Evaluation(errors=errors, n_skipped_cpa=int(np.sum(~rows)), notes=notes, warnings=tuple(warnings),
                      nominal_rms_mm=nominal_rms, nominal_urdf=nominal_urdf,
                      lines=tuple(int(line) for line in data.lines), sessions=sessions,
                      files=tuple(str(f) for f in data.files), row_sessions=tuple(str(n) for n in data.sessions),
                      drift=drift_use, thermal=applied.thermal, pause_steps=applied.pause_steps)


def _check_pair(description: RobotDescription, urdf: str | Path, report: ReportModel, report_path: str | Path
                ) -> None:
    """Refuse, in one line, a report whose chain ends at a link the URDF ``urdf`` (read: ``description``)
    does not have: it was written for another URDF (another robot's calibration in the same folder),
    whatever ``--allow-other-urdf`` says."""
    if report.tool_parent not in description.link_names():
        written = f" ({report.corrected_urdf})" if report.corrected_urdf else ""
        raise PincalError(f"{report_path}: written for another URDF{written}: its chain ends at link "
                          f"'{report.tool_parent}', which {urdf} does not have; evaluate {urdf} with the "
                          "REPORT.json calibrate wrote with it")


def _nominal_rms(report: ReportModel, report_path: str | Path, data: MeasurementSet,
                 xacro_args: Sequence[tuple[str, str]]) -> tuple[float | None, str | None]:
    """The "before" of evaluate's before -> after: the RMS point error [mm] of the URDF the calibration
    started from (REPORT.json ``sources.urdf``, as given or beside the report) on ``data``, with its
    registration and target fitted to these rows — as calibrate's before line on its own rows; (None,
    None) where that URDF is not here or not readable (the line is then left out)."""
    if not report.nominal_urdf:
        return None, None
    given = Path(report.nominal_urdf)
    path = next((p for p in (given, Path(report_path).parent / given) if p.is_file()), None)
    if path is None:
        return None, None
    from pincal.fit.chain_calibration import calibrate_chain  # only for this line

    try:
        chain = KinematicChain.from_urdf(path, report.tool_parent, xacro_args=xacro_args)
        chain.follow(report.couplings)
        nominal = calibrate_chain(chain, replace(data, roles=np.full(data.n_rows, "calibration", dtype=object)),
                                  "registration")
    except PincalError:
        return None, None
    return nominal.rms_m * 1000.0, str(path)


def _labelled(path: str | Path, data: MeasurementSet) -> np.ndarray:
    """Whether each row of ``data`` (read from ``path``) names its session in a ``session`` cell (K,)."""
    table = read_table(path)
    if SESSION_COLUMN not in table.names:
        return np.zeros(data.n_rows, dtype=bool)
    given = dict(zip(table.lines, (bool(cell) for cell in table.cells(SESSION_COLUMN))))
    return np.array([given.get(int(line), False) for line in data.lines], dtype=bool)


def _same_path(a: str | Path, b: str | Path) -> bool:
    """Whether two paths name one file (relative paths from the current folder)."""
    try:
        return Path(a).resolve() == Path(b).resolve() or Path(a).samefile(b)
    except OSError:
        return False


def _registrations(report: ReportModel, data: MeasurementSet, labelled: np.ndarray, fixed: str | None,
                   new_session: bool, report_path: str | Path, data_path: str | Path
                   ) -> tuple[list[SessionPlan], list[str]]:
    """The module's rule: (session name, its rows, (source, Registration 1, Registration 2,
    reported session name or None) or None to re-estimate) for each session of ``data``, and the notes it gives.

    Args:
        labelled: (K,) whether each row names its session in a ``session`` cell.
    """
    reported = {name: (f"reported session '{name}'", position, orientation, name)
                for name, position, orientation in report.sessions}
    if not reported:  # a report without ``sessions``: one session, its top-level registration
        reported = {"": ("the report's registration", report.registration_position, report.registration_orientation,
                         THE_REGISTRATION)}
    first = next(iter(reported.values()))
    index = data.session_index
    groups = [(name, np.flatnonzero(index == s)) for s, name in enumerate(data.session_names)]
    if fixed is not None:
        if fixed and fixed not in reported:
            raise PincalError(f"--fixed-registration {fixed}: {report_path} has no session '{fixed}'; its sessions "
                              f"are: {', '.join(n for n in reported if n) or '(one, unnamed: give no NAME)'}")
        chosen = reported[fixed] if fixed else first
        return [(name, members, chosen) for name, members in groups], []
    if new_session:
        return [(name, members, None) for name, members in groups], []
    if len(reported) == 1:  # one registration: every row's, as before sessions existed
        own = [name for name, members in groups if labelled[members].any() and name not in reported]
        notes = []
        if own:
            notes.append(f"{data_path}: session(s) {', '.join(repr(n) for n in own)} evaluated through "
                         f"{first[0]} (a one-session report's registration is kept); pass --new-session if the "
                         "sensor moved")
        return [(name, members, first) for name, members in groups], notes
    # several: a reported session named in full by a ``session`` cell, or the sessions of the file it was read from
    stem = default_session_name(str(data_path))
    files = dict(zip(reported, report.session_files))
    here = {n for n, paths in files.items() if any(_same_path(f, data_path) for f in paths)}
    prefixes = {stem} | {f for n in here for f in files[n]}  # how calibrate named this file's sessions
    plan = []
    for name, members in groups:
        known: tuple[str, Registration, Registration, str] | None
        if labelled[members].any() and name in reported:
            known = reported[name]
        else:  # rows of the file a session was read from: its own name for it (STEM, STEM:VALUE or VALUE)
            names = prefixes if name == stem else {name} | {f"{prefix}:{name}" for prefix in prefixes}
            known = next((reported[n] for n in reported if n in here and n in names), None)
        plan.append((name, members, known))
    return plan, []


def _effect_corrections(chain: KinematicChain, data: MeasurementSet, effects: Mapping[str, Any], points: np.ndarray,
                        held: tuple[np.ndarray, np.ndarray], report_path: str | Path
                        ) -> tuple[RowCorrections, DriftUse | None]:
    """Joint readings corrected by the report's effects, and its sensor terms; with a
    drift, how it was applied (``rows_applied`` inside the fitted span of the session
    ``held`` = (names (K,), evaluated sessions (K,)) gives each row
    (:func:`drift_offsets`), ``rows_held`` outside it).
    """
    entries = effects.get("effects", [])
    if not entries:
        return RowCorrections(), None
    parsed = [effect_from_dict(e) for e in entries]
    has_drift = any(e.type == "drift" for e, _ in parsed)
    reference = effects.get("time_reference_s")
    if (has_drift or reference is not None) and (isinstance(reference, bool) or not isinstance(reference, (int, float))
                                                 or not np.isfinite(reference)):
        raise PincalError(f"{report_path}: time_reference_s must be the time [s] a drift's offset is zero at "
                          f"(a finite number), not {reference!r}; rewrite the report with pincal diagnose")
    spans = read_time_spans(effects.get("time_spans_s"), str(report_path)) if has_drift else None
    needs_time = has_drift and spans is not None  # without spans (older reports) no row gets the drift
    named = effects.get("time_column") if has_drift and (needs_time or effects.get("time_column") in data.extra) \
        else None
    row_time = time_column(data, named)
    if needs_time and row_time is None:
        raise PincalError(f"{data.source}: the report has a drift effect; the data need its time column")
    context = effects.get("approach_context") or {}
    try:
        payload = float(effects.get("payload_kg", 0.0))
        context_q = np.asarray(context["q"], dtype=float) if context else None
        context_time = np.asarray(context["time_s"], dtype=float) if context else None
    except (KeyError, TypeError, ValueError):
        raise PincalError(f"{report_path}: payload_kg or approach_context is malformed; rewrite the report with "
                          "pincal diagnose") from None
    if context_q is not None and context_time is not None and not (
            context_q.ndim == 2 and context_q.shape[1] == chain.n_joints and len(context_q) > 0
            and context_time.shape == (len(context_q),) and np.isfinite(context_q).all()
            and np.isfinite(context_time).all()):
        raise PincalError(f"{report_path}: approach_context must hold q, rows of {chain.n_joints} finite joint "
                          "values, and time_s, one finite time [s] per row; rewrite the report with pincal diagnose")
    inputs = effect_inputs(chain, data, payload, points.mean(axis=0), row_time,
                           time_reference=reference if row_time is not None else None,
                           context=None if context_q is None or context_time is None
                           else RowContext(context_q, context_time))
    if any(e.moments for e, _ in parsed):  # a compliance of unknown masses follows the loads per mass moment
        inputs = with_loads(inputs, chain)
    q = data.q + chain.followed_shifts(joint_shifts([e for e, _ in parsed], [v for _, v in parsed], inputs,
                                                    chain.joint_names))
    out = RowCorrections(q, bends=bend_angles([e for e, _ in parsed], [v for _, v in parsed], inputs,
                                              chain.joint_names))  # lateral compliances (eq L1-L3)
    drift: DriftUse | None = None
    for effect, value in parsed:
        if effect.type == "sensor_scale":
            out = replace(out, sensor_scale=float(value[0]))
        elif effect.type == "drift":
            if value.size != 3:
                raise PincalError(f"{report_path}: a drift's value is [vx, vy, vz] in m/s; it has {value.size} "
                                  "number(s)")
            time = np.full(data.n_rows, np.nan) if row_time is None else row_time  # None: no spans, offset 0
            assert reference is not None  # has_drift: checked to be a finite number above
            offsets = drift_offsets(time, value, float(reference), spans, held[0], held[1])
            out = replace(out, drift=offsets.offsets)
            outside = ~offsets.inside
            drift = {"velocity_m_per_s": value.tolist(), "time_column": effects.get("time_column"),
                     "time_reference_s": reference,
                     "time_spans_s": None if spans is None else [cast(TimeSpanJson, s.as_dict()) for s in spans],
                     "rows_applied": int(np.sum(offsets.inside)), "rows_held": int(np.sum(outside)),
                     "max_gap_s": float(np.max(offsets.gap[outside])) if outside.any() and spans else None,
                     "held_rule": HELD_DRIFT}
    return out, drift


def _duration(seconds: float) -> str:
    """A time gap in its readable unit (s, min, h or days)."""
    for unit, size in (("days", 86400.0), ("h", 3600.0), ("min", 60.0)):
        if seconds >= size:
            return f"{seconds / size:.3g} {unit}"
    return f"{seconds:.3g} s"


def _drift_note(data_path: str | Path, drift: DriftUse) -> str:
    """The one note on rows a drift was not extrapolated to (``drift`` from :func:`_effect_corrections`)."""
    held = drift["rows_held"]
    total = held + drift["rows_applied"]
    spans = drift["time_spans_s"]
    if spans is None:
        where = ("the report does not record the time span the drift was fitted on (written before pincal recorded "
                 "time_spans_s; rerun diagnose to record it), so no row is known to lie inside it")
    else:
        ranges = ", ".join(f"{span['first']:.10g}–{span['last']:.10g} s" for span in spans)
        gap = cast(float, drift["max_gap_s"])  # a float when rows lie outside the spans
        where = (f"{held} of {total} row(s) lie outside the time span of the rows it was fitted on "
                 f"({ranges} in column '{drift['time_column'] or 'time'}'), up to {_duration(gap)} away")
    held_at = ("its session's mean time (no drift term for a one-session fit; a re-estimated registration: the "
               "nearer end of the span)" if spans is not None else "zero offset (its time_reference_s)")
    return (f"{data_path}: the report's drift is not extrapolated: {where}; those rows are evaluated with the "
            f"drift held at {held_at}: a drift describes the session it was measured in")
