"""``pincal diagnose``'s job: calibrate as a :class:`~pincal.workflows.settings.DiagnoseSettings`
says, search the residuals for effects the geometry lacks (:func:`pincal.diagnosis.diagnose.diagnose`),
write the final model's URDF, effects.yaml, REPORT.json and plots (:func:`diagnose_files`).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, cast

from pincal._version import __version__
from pincal.errors import PincalError
from pincal.fit.chain_calibration import ChainCalibration, ChainFitOptions, calibrate_chain
from pincal.fit.plausibility import calibration_findings, reach_m
from pincal.fit.sessions import session_rows
from pincal.measurements.couplings import apply_couplings
from pincal.measurements.csv_v1 import read_measurements, read_sessions
from pincal.measurements.data import MeasurementSet
from pincal.model.chain import KinematicChain
from pincal.model.description import xacro_arguments
from pincal.model.drift import TIME_COLUMNS, time_column
from pincal.model.parameter_sets import ChainLevel
from pincal.progress import Progress, Stages
from pincal.report.diagnosis import diagnosis_report
from pincal.report.document import chain_head, fit_rows, write_report
from pincal.report.effects_file import effects_path, write_effects_file
from pincal.report.model import Sources, couplings_part
from pincal.report.model_diagnosis import DiagnosisReport
from pincal.report.model_level_choice import level_choice_part
from pincal.report.record import ReportRecord
from pincal.report.row_errors import diagnosis_row_errors
from pincal.report.sessions import drift_spans, session_entries
from pincal.workflows.calibration import unfitted_sessions
from pincal.workflows.paths import (
    description_inputs,
    ensure_directory,
    input_paths,
    paths_in,
    refuse_overwrite,
    refuse_overwrite_matching,
)
from pincal.workflows.report_page import refuse_page, render_page, write_page
from pincal.workflows.settings import DiagnoseSettings, expect, follow_couplings
from pincal.workflows.verdict import UrdfWrite, judged, unmodelled_notes, withhold, write_checked_urdf

if TYPE_CHECKING:  # imported where used, so `pincal calibrate` loads none of these
    from pincal.diagnosis.diagnose import Diagnosis
    from pincal.fit.level_choice import LevelChoice

__all__ = ["DiagnoseOutputs", "DiagnoseRun", "diagnose_files"]


@dataclass(frozen=True)
class DiagnoseOutputs:
    """What ``pincal diagnose`` writes besides the corrected URDF, REPORT.json and effects.yaml: the
    figures (``--plots``, into ``plots_dir``: :mod:`pincal.diagnosis.plots`) and the report's page
    (``--html``: :mod:`pincal.workflows.report_page`); None: not written."""

    plots_dir: Path | None = None
    html: Path | None = None

    def __post_init__(self) -> None:
        paths_in(self, "plots_dir", "html")


@dataclass(frozen=True)
class DiagnoseRun:
    """Outcome of :func:`diagnose_files` (``effects_file``: the effects.yaml written beside the URDF, or None;
    ``withheld``: the final model misses its rows grossly, the URDF and effects.yaml were not written;
    ``html``: the report's page written, or None)."""

    calibration: ChainCalibration
    diagnosis: Diagnosis
    report: DiagnosisReport
    notes: list[str]
    plots: list[Path]
    seconds: float
    level_choice: LevelChoice | None = None
    effects_file: Path | None = None
    withheld: bool = False
    html: Path | None = None


def diagnose_files(
    urdf: str | Path,
    data_path: str | Path | Sequence[str | Path],
    out_urdf: str | Path,
    report_path: str | Path,
    settings: DiagnoseSettings,
    validation_path: str | Path | None = None,
    outputs: DiagnoseOutputs | None = None,
    progress: Progress | None = None,
) -> DiagnoseRun:
    """Calibrate as ``settings`` say, search the residuals for missing effects, write the corrected
    URDF, the report (with ``effects``), with effects or couplings the effects.yaml beside the URDF
    (:mod:`pincal.report.effects_file`), and the plots and page ``outputs`` asks for (None: neither);
    held-out rows from ``validation_path``.
    ``progress(done, total)`` counts the calibration's fits, then the search's (:mod:`pincal.progress`).
    Several ``data_path`` files are sessions (one registration each; see :func:`calibrate_files`)."""
    expect(settings, DiagnoseSettings, "diagnose_files")
    outputs = DiagnoseOutputs() if outputs is None else outputs
    expect(outputs, DiagnoseOutputs, "diagnose_files")  # a folder in the former plots_dir's place: refused
    plots_dir = outputs.plots_dir
    tip_link, tool_pose, xacro_args = settings.tip_link, settings.tool_pose, settings.xacro_args
    level: str = settings.level  # "auto" becomes the level cross-validation chooses
    sigma_column, selection, payload_kg = settings.sigma_column, settings.criterion, settings.payload_kg
    time_column_name, sigma_pos_m = settings.time_column, settings.sigma_pos_m
    from pincal.diagnosis.conditions import read_readings
    from pincal.diagnosis.diagnose import DiagnoseOptions, diagnose
    from pincal.fit.level_choice import choose_level

    urdf, data_paths, out_urdf, report_path = Path(urdf), input_paths(data_path), Path(out_urdf), Path(report_path)
    inputs = [*description_inputs(urdf, xacro_args), *data_paths] + ([Path(validation_path)] if validation_path else [])
    refuse_overwrite(out_urdf, *inputs)
    refuse_overwrite(report_path, *inputs, outputs=[out_urdf])
    refuse_overwrite(effects_path(out_urdf), *inputs, outputs=[out_urdf, report_path])
    if plots_dir is not None:  # the names pincal.diagnosis.plots gives its figures
        refuse_overwrite_matching(plots_dir, "diagnose_*.png", *inputs)
    html = refuse_page(outputs.html, inputs, [out_urdf, report_path, effects_path(out_urdf)])
    if level == "dh":
        raise PincalError("diagnose works on --level registration, offsets or full")
    started = time.perf_counter()
    chain = KinematicChain.from_urdf(urdf, tip_link, tool=tool_pose, xacro_args=xacro_args)
    couplings = follow_couplings(chain, settings.couplings, data_paths)  # a joint without a column follows (M1)
    # readings taken against another joint corrected (eq C1) before the joint limits are judged
    data, notes = read_sessions(data_paths, chain.joint_specs, couplings, chain.other_branch_joints)
    heldout = held_time = None
    if validation_path:
        heldout, held_notes = read_measurements(validation_path, chain.joint_specs, couplings,
                                                 chain.other_branch_joints)
        notes += held_notes
        held_time = time_column(heldout, time_column_name)
    readings = read_readings(data, heldout, settings.temperature_column, settings.pause_s)  # thermal, pauses
    nominal_placements = chain.placements()
    stages = Stages(progress)
    choice = None
    fit_options = ChainFitOptions(tool_known=tool_pose is not None, sigma_column=sigma_column, selection=selection)
    if level == "auto":  # the geometric level by cross-validation of the geometric calibration
        choice = choose_level(chain, data, fit_options, progress=stages.next())
        level = choice.chosen
    # the geometric calibration, made again by diagnose on readings it corrects (a joint read against another);
    # the level: registration, offsets or full (refused above otherwise), or the one auto chose
    recalibrate = partial(calibrate_chain, chain, level=cast(ChainLevel, level),
                          options=replace(fit_options, refit_offered=False))
    calibration = recalibrate(data, progress=stages.next())
    notes += unfitted_sessions(data, calibration.session_names)
    row_time = time_column(data, time_column_name)
    options = DiagnoseOptions(sigma_column=sigma_column, payload_kg=payload_kg, time=row_time, heldout_time=held_time,
                              readings=readings, recalibrate=recalibrate, couplings=couplings,
                              stated_sigma_pos_m=sigma_pos_m, masses=settings.masses, lateral=settings.lateral)
    diagnosis = diagnose(chain, calibration, data, heldout, options, progress=stages.next())
    # the final model: on the readings corrected by the conventions diagnose found, from their calibration
    data, calibration = apply_couplings(data, diagnosis.couplings), diagnosis.calibration or calibration
    heldout = None if heldout is None else apply_couplings(heldout, diagnosis.couplings)
    final = diagnosis.final_calibration()  # the model with its effects, as the report and its checks see it
    used = data.select(calibration.used_index)
    with chain.placed(final.chain_placements):  # judged: the final model, with the effects it adopted
        verdict = judged(chain, data_paths, calibration_findings(chain, final, used, sigma_column, sigma_pos_m,
                                                                 press_of=calibration, diagnosed=True), settings.force)
        notes += verdict.notes + unmodelled_notes(final, reach_m(chain, used.q), sigma_pos_m)
    comment = (f"Calibrated by pincal {__version__} (diagnose, level {level}) from {urdf.name} and "
               f"{', '.join(p.name for p in data_paths)}. "
               "Registration, tool and effects (which a URDF cannot carry): see the report.")
    _, urdf_sha256 = write_checked_urdf(UrdfWrite(urdf, out_urdf, comment, xacro_args, keep=not verdict.withheld),
                                        chain, final.chain_placements, nominal_placements, data.q)
    if verdict.withheld:
        notes += withhold(out_urdf)
    sources: Sources = {"urdf": str(urdf),
                        "data": str(data_paths[0]) if len(data_paths) == 1 else [str(p) for p in data_paths],
                        "corrected_urdf": str(out_urdf),
                        "validation": None if validation_path is None else str(validation_path)}
    if verdict.withheld:
        sources["corrected_urdf_withheld"] = True  # the path names no file of this run
    plots = []
    if plots_dir is not None:
        from pincal.diagnosis.plots import plot_diagnosis  # matplotlib only when drawing

        plots = plot_diagnosis(diagnosis, ensure_directory(plots_dir))
    with chain.placed(final.chain_placements):  # the report describes the final model
        head = chain_head(final, chain, tip_link, diagnosis.calibration_errors, fit_rows(data.roles), sources, notes)
        row_errors = diagnosis_row_errors(chain, nominal_placements, data, heldout, calibration, diagnosis,
                                          (" + ".join(str(p) for p in data_paths),
                                           None if validation_path is None else str(validation_path)))
        record = ReportRecord(urdf_sha256, dict(xacro_arguments(xacro_args)), row_errors, warnings=verdict.warnings,
                              level_choice=level_choice_part(choice),
                              couplings=couplings_part((*couplings, *diagnosis.couplings)))
        report = diagnosis_report(
            head, diagnosis, payload_kg, time_column_name or _time_name(data),
            sessions=session_entries(final.session_names, final.target.registrations, used,
                                     session_rows(used, final.session_names), diagnosis.calibration_errors),
            time_spans=drift_spans(diagnosis, row_time, calibration, used),  # where a drift holds (evaluate)
            plots=[str(p) for p in plots], record=record,
        )
    # what the URDF cannot carry, for a controller (nothing beside a withheld URDF)
    page = render_page(html, report, report_path)  # made before the report is written (the plots are)
    effects_file = None if verdict.withheld else write_effects_file(out_urdf, report_path, report)
    write_report(report_path, report)
    return DiagnoseRun(calibration, diagnosis, report, notes, plots, time.perf_counter() - started, choice,
                       effects_file, verdict.withheld, write_page(html, page))


def _time_name(data: MeasurementSet) -> str | None:
    return next((n for n in TIME_COLUMNS if n in data.extra), None)
