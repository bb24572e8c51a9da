"""``pincal calibrate``'s job on sensor rows: read the URDF and the data files, calibrate as a
:class:`~pincal.workflows.settings.CalibrateSettings` says, judge the model's plausibility, write the
corrected URDF (reloaded and checked), effects.yaml and REPORT.json (:func:`calibrate_files`).
Socket-fixture data: :mod:`pincal.workflows.fixture`; the output path policy: :mod:`pincal.workflows.paths`.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, cast

import numpy as np

from pincal._version import __version__
from pincal.errors import PincalError
from pincal.fit.chain_calibration import ChainCalibration, ChainFitOptions, calibrate_chain
from pincal.fit.metrics import PoseErrors, pose_errors
from pincal.fit.plausibility import calibration_findings, reach_m
from pincal.fit.sessions import check_registrable, session_pose_errors, session_rows, where
from pincal.measurements.csv_v1 import read_sessions
from pincal.measurements.data import MeasurementSet
from pincal.model.chain import KinematicChain
from pincal.model.description import xacro_arguments
from pincal.model.dh.parameters import DHParameterSet
from pincal.model.parameter_sets import ChainLevel
from pincal.progress import Progress, Stages
from pincal.report.document import chain_head, chain_report, fit_rows, paper_report, write_report
from pincal.report.effects_file import effects_path, write_effects_file
from pincal.report.model import CalibrationReport, PaperReport, Sources, couplings_part
from pincal.report.model_level_choice import level_choice_part
from pincal.report.record import ReportRecord
from pincal.report.row_errors import chain_row_errors, paper_row_errors
from pincal.report.sessions import session_entries, session_errors
from pincal.workflows.evaluation import SessionEvaluation
from pincal.workflows.paths import description_inputs, input_paths, refuse_overwrite
from pincal.workflows.report_page import refuse_page, render_page, write_page
from pincal.workflows.settings import CalibrateSettings, expect, follow_couplings
from pincal.workflows.verdict import (
    UrdfWrite,
    Verdict,
    diagnose_command,
    judged,
    unmodelled_notes,
    withhold,
    write_checked_urdf,
)

if TYPE_CHECKING:  # imported where used, so `pincal calibrate` loads none of these
    from pincal.fit.level_choice import LevelChoice
    from pincal.paper.methods import PaperCalibration

__all__ = ["CalibrationRun", "calibrate_chain_dh", "calibrate_files", "unfitted_sessions"]


@dataclass(frozen=True)
class CalibrationRun:
    """Outcome of :func:`calibrate_files`.

    Attributes:
        result: the paper method's or the chain calibration's result.
        report: the REPORT.json document written (:mod:`pincal.report.model`).
        errors: eq 24 errors on the calibration rows.
        notes: reader and method notes for the user.
        seconds: wall time of the calibration itself [s].
        reload_error: largest TCP difference after reloading the written URDF [m].
        sessions: each session's registration and errors (levels other than dh).
        level_choice: how ``--level auto`` chose the level (None for a level given).
        effects_file: the effects.yaml written beside the URDF (``--coupling``), or None
            (:mod:`pincal.report.effects_file`).
        withheld: the model misses its rows grossly: the corrected URDF and effects.yaml were not written
            (:mod:`pincal.workflows.verdict`; ``reload_error`` is of the URDF withheld).
        html: the report's page written (``--html``), or None.
    """

    result: PaperCalibration | ChainCalibration
    report: PaperReport | CalibrationReport
    errors: PoseErrors
    notes: list[str]
    seconds: float
    reload_error: float
    sessions: tuple[SessionEvaluation, ...] = ()
    level_choice: LevelChoice | None = None
    effects_file: Path | None = None
    withheld: bool = False
    html: Path | None = None


def calibrate_chain_dh(
    chain: KinematicChain, data: MeasurementSet, method: int, weight: float
) -> tuple[PaperCalibration, DHParameterSet, float]:
    """Run a paper method on a loaded chain; returns the result, the parameter set and the time [s]."""
    from pincal.paper.methods import calibrate_paper

    params = DHParameterSet(chain)
    start = time.perf_counter()
    result = calibrate_paper(chain, data, method, weight=weight, nominal=params.nominal)
    return result, params, time.perf_counter() - start


def calibrate_files(
    urdf: str | Path,
    data_path: str | Path | Sequence[str | Path],
    out_urdf: str | Path,
    report_path: str | Path,
    settings: CalibrateSettings,
    progress: Progress | None = None,
    html: str | Path | None = None,
) -> CalibrationRun:
    """Calibrate ``urdf`` on ``data_path`` as ``settings`` say; write the corrected URDF and the report
    (and, with ``--coupling``, the effects.yaml beside the URDF: :mod:`pincal.report.effects_file`).

    ``data_path`` may be several files: each is a session with its own registration
    (:func:`pincal.measurements.csv_v1.read_sessions`; levels other than dh).
    Level ``dh`` runs the paper's Method ``settings.paper_method`` (the tool known);
    ``registration``, ``offsets`` and ``full`` calibrate any chain
    (:func:`pincal.fit.chain_calibration.calibrate_chain`), estimating the target
    unless ``settings.tool_pose`` is given; ``auto`` is the one of those three that cross-validation
    on the calibration rows supports (:func:`pincal.fit.level_choice.choose_level`).
    ``progress(done, total)`` counts the fits of those levels (:mod:`pincal.progress`).
    ``html``: the report's page (``--html``, :mod:`pincal.workflows.report_page`), written after the report.
    """
    expect(settings, CalibrateSettings, "calibrate_files")
    level: str = settings.level  # "auto" becomes the level cross-validation chooses
    tool_pose, xacro_args = settings.tool_pose, settings.xacro_args
    sigma_column, reject_outliers, selection = settings.sigma_column, settings.reject_outliers, settings.criterion
    tool_parent, method = settings.tip_link, settings.paper_method
    urdf, data_paths = Path(urdf), input_paths(data_path)
    data_label = " + ".join(str(p) for p in data_paths)
    out_urdf, report_path = Path(out_urdf), Path(report_path)
    inputs = [*description_inputs(urdf, xacro_args), *data_paths]  # a xacro's included files too
    refuse_overwrite(out_urdf, *inputs)
    refuse_overwrite(report_path, *inputs, outputs=[out_urdf])
    refuse_overwrite(effects_path(out_urdf), *inputs, outputs=[out_urdf, report_path])
    html = refuse_page(html, inputs, [out_urdf, report_path, effects_path(out_urdf)])
    chain = KinematicChain.from_urdf(urdf, tool_parent, tool=tool_pose, xacro_args=xacro_args)
    couplings = follow_couplings(chain, settings.couplings, data_paths)  # a joint without a column follows (M1)
    # readings taken against another joint corrected (eq C1) before the joint limits are judged
    data, notes = read_sessions(data_paths, chain.joint_specs, couplings, chain.other_branch_joints)
    nominal_placements = chain.placements()
    n_rows = fit_rows(data.roles)
    sources: Sources = {"urdf": str(urdf),
                        "data": str(data_paths[0]) if len(data_paths) == 1 else [str(p) for p in data_paths],
                        "corrected_urdf": str(out_urdf)}
    choice = None
    paper: PaperCalibration | None = None
    verdict = Verdict([], [], withheld=False)  # the paper's methods are not judged
    if level == "dh":
        if len(data.session_names) > 1:
            raise PincalError(
                f"{data.source}: {len(data.session_names)} sessions ({', '.join(data.session_names)}); the paper's "
                "methods (--level dh) take one registration: calibrate several sessions with --level "
                "registration|offsets|full")
        check_registrable(data.with_role("calibration"), orientations=False)
        session_list: tuple[SessionEvaluation, ...] = ()
        paper, params, seconds = calibrate_chain_dh(chain, data, method, settings.weight)
        placements = paper.chain_placements
        with chain.placed(placements):
            errors = pose_errors(
                chain, data.with_role("calibration"), paper.registration_position, paper.registration_orientation
            )
            row_errors = paper_row_errors(chain, nominal_placements, data.with_role("calibration"), errors, data_label)
        result: PaperCalibration | ChainCalibration = paper
        what = f"Method {method} of Franaszek & Marvel 2022"
    else:
        start = time.perf_counter()
        stages = Stages(progress)
        options = ChainFitOptions(tool_known=tool_pose is not None, sigma_column=sigma_column,
                                  reject_outliers=reject_outliers, selection=selection)
        if level == "auto":
            from pincal.fit.level_choice import choose_level

            choice = choose_level(chain, data, options, progress=stages.next())
            level = choice.chosen
        # registration, offsets or full: CalibrateSettings checked the level, and auto chose one of them
        fitted = calibrate_chain(chain, data, cast(ChainLevel, level), options, progress=stages.next())
        seconds = time.perf_counter() - start
        placements = fitted.chain_placements
        with chain.placed(placements):
            notes += unfitted_sessions(data, fitted.session_names)
            used = data.select(fitted.used_index)
            sessions = session_rows(used, fitted.session_names)
            errors = session_pose_errors(chain, used, sessions, fitted.target.registrations,
                                         points=fitted.target.points, target_rotation=fitted.target.rotation)
            verdict = judged(chain, data_paths, calibration_findings(chain, fitted, used, sigma_column,
                                                                     settings.sigma_pos_m), settings.force)
            notes = notes + verdict.notes + unmodelled_notes(
                fitted, reach_m(chain, used.q), settings.sigma_pos_m,
                diagnose_command(urdf, data_paths, settings, out_urdf, report_path))
            entries = session_entries(fitted.session_names, fitted.target.registrations, used, sessions, errors)
            session_list = tuple(
                SessionEvaluation(entry["name"], entry["rows"], registration, registration,
                                  f"fitted on {entry['file']}", session_errors(errors, sessions == s))
                for s, (entry, registration) in enumerate(zip(entries, fitted.target.registrations)))
            report_notes = list(notes)
            if len(fitted.session_names) > 1:
                report_notes.append(f"registration: of the first session, '{fitted.session_names[0]}'; every "
                                    "session's registration and errors are under 'sessions'")
            row_errors = chain_row_errors(chain, nominal_placements, used, fitted, errors, data_label)
        result = fitted
        what = f"level {level}"
        if choice is not None:
            what += ", chosen by --level auto"
    comment = (f"Calibrated by pincal {__version__} ({what}) from {urdf.name} and "
               f"{', '.join(p.name for p in data_paths)}. Registration and tool: see the report.")
    reload_error, urdf_sha256 = write_checked_urdf(UrdfWrite(urdf, out_urdf, comment, xacro_args,
                                                             keep=not verdict.withheld),
                                                   chain, placements, nominal_placements, data.q)
    if verdict.withheld:
        removed = withhold(out_urdf)
        notes, report_notes = notes + removed, report_notes + removed
        sources["corrected_urdf_withheld"] = True  # the path names no file of this run
    xacro = dict(xacro_arguments(xacro_args))
    report: PaperReport | CalibrationReport
    if paper is not None:
        assert tool_pose is not None  # CalibrateSettings: level dh needs the tool
        report = paper_report(paper, params, tool_pose, errors, n_rows, sources, notes,
                              record=ReportRecord(urdf_sha256, xacro, row_errors))
    else:
        with chain.placed(placements):  # the report describes the calibrated model
            record = ReportRecord(urdf_sha256, xacro, row_errors, warnings=verdict.warnings,
                                  level_choice=level_choice_part(choice), couplings=couplings_part(couplings))
            report = chain_report(chain_head(fitted, chain, tool_parent, errors, n_rows, sources, report_notes),
                                  sessions=entries, record=record)
    # the couplings, which a URDF cannot carry, beside the URDF (none beside a withheld one)
    page = render_page(html, report, report_path)  # made before the report is written
    effects_file = None if verdict.withheld else write_effects_file(out_urdf, report_path, report)
    write_report(report_path, report)
    return CalibrationRun(result, report, errors, notes, seconds, reload_error, session_list, choice, effects_file,
                          verdict.withheld, write_page(html, page))


def unfitted_sessions(data: MeasurementSet, fitted: Sequence[str]) -> list[str]:
    """A note for each session of ``data`` the fit left out (``fitted``: the sessions it
    registered) — all of its rows have role ``validation`` — so none vanishes silently."""
    notes = []
    for name in data.session_names:
        if name not in fitted:
            rows = int(np.sum(data.sessions == name))
            how = ("evaluate re-estimates the registration of a session the fit has not seen" if len(fitted) > 1
                   else "pass --new-session, or evaluate uses the report's one registration")
            notes.append(f"{where(data, name)}: all {rows} row(s) have role 'validation', so this session is not "
                         f"in the fit and the report has no registration for it; to evaluate them, give its file to "
                         f"pincal evaluate ({how})")
    return notes
