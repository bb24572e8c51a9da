"""End-to-end jobs behind the command line: simulate, calibrate, evaluate, diagnose, demo.

Each function takes paths and options, does the whole job, and returns what
happened; the CLI (:mod:`pincal.cli.commands`) only parses arguments and prints.
The workflows of urdf-from-dh and plan are in :mod:`pincal.cli.preparation`,
the output path policy of all of them in :mod:`pincal.cli.paths`.
"""

from __future__ import annotations

import json
import time
from collections.abc import Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from pincal._version import __version__
from pincal.cli.evaluation import Evaluation, SessionEvaluation, evaluate_files  # noqa: F401 (re-exported)
from pincal.cli.paths import (
    description_inputs,
    ensure_directory,
    input_paths,
    refuse_overwrite,
    refuse_overwrite_matching,
)
from pincal.cli.settings import CalibrateSettings, DiagnoseSettings, expect
from pincal.cli.verdict import (  # noqa: F401 (RELOAD_TOLERANCE and write_checked_urdf re-exported)
    RELOAD_TOLERANCE,
    Verdict,
    diagnose_command,
    judged,
    unmodelled_notes,
    withhold,
    write_checked_urdf,
)
from pincal.errors import PincalError, did_you_mean
from pincal.fit.chain_calibration import ChainCalibration, calibrate_chain
from pincal.fit.metrics import PoseErrors, pose_errors
from pincal.fit.plausibility import calibration_findings, reach_m
from pincal.fit.sessions import (
    check_registrable,
    session_pose_errors,
    session_rows,
    where,
)
from pincal.measurements.couplings import apply_couplings
from pincal.measurements.csv_v1 import (
    read_measurements,
    read_sessions,
    write_measurements,
)
from pincal.measurements.data import MeasurementSet
from pincal.model.chain import KinematicChain, xyz_rpy_from_pose
from pincal.model.description import xacro_arguments
from pincal.model.dh.parameters import DHParameterSet
from pincal.model.dh.table import DEVIATION_SETS, KUKA_LWR4_DH
from pincal.model.drift import TIME_COLUMNS, time_column
from pincal.model.effects import effect_to_dict, parse_effect
from pincal.outputs import write_text
from pincal.progress import Progress, Stages
from pincal.report.diagnosis import diagnosis_report
from pincal.report.document import (
    chain_head,
    chain_report,
    fit_rows,
    paper_report,
    write_report,
)
from pincal.report.effects_file import effects_path, write_effects_file
from pincal.report.model import (
    CalibrationReport,
    PaperReport,
    Sources,
    couplings_part,
    level_choice_part,
)
from pincal.report.model_diagnosis import DiagnosisReport
from pincal.report.row_errors import (
    chain_row_errors,
    diagnosis_row_errors,
    paper_row_errors,
)
from pincal.report.sessions import drift_spans, session_entries, session_errors
from pincal.robots import KUKA_FLANGE_LINK, kuka_lwr4plus_urdf

if TYPE_CHECKING:  # imported where used, so `pincal calibrate` loads none of these
    from pincal.diagnosis.diagnose import Diagnosis
    from pincal.fit.level_choice import LevelChoice
    from pincal.paper.methods import PaperCalibration
    from pincal.simulation.paper import SimulatedExperiment, SimulationSettings

__all__ = [
    "RELOAD_TOLERANCE", "simulate_to_directory", "CalibrationRun", "calibrate_chain_dh", "calibrate_files",
    "unfitted_sessions", "write_checked_urdf", "DiagnoseRun", "diagnose_files",
]


# --- simulate ----------------------------------------------------------------


def simulate_to_directory(
    out_dir: str | Path, deviations: str, settings: SimulationSettings, effects: Sequence[str] = ()
) -> tuple[SimulatedExperiment, dict[str, Any]]:
    """Simulate the paper's experiment on the packaged KUKA LWR 4+ and write
    ``calibration.csv``, ``validation.csv`` and ``truth.json`` into ``out_dir``.

    ``effects`` (``TYPE:JOINT:VALUE`` strings, see :func:`pincal.model.effects.parse_effect`)
    are injected into the data without being declared in it; truth.json records them.
    """
    from pincal.simulation.paper import simulate_experiment

    if deviations not in DEVIATION_SETS:
        raise PincalError(f"unknown deviation set '{deviations}'; use one of {sorted(DEVIATION_SETS)}")
    urdf = kuka_lwr4plus_urdf()
    chain = KinematicChain.from_urdf(urdf, KUKA_FLANGE_LINK)
    injected = [parse_effect(text) for text in effects]
    for effect, _ in injected:
        for name in (effect.joint, effect.driver):
            if name is not None and name not in chain.joint_names:
                raise PincalError(f"effect '{effect.label}': no joint '{name}'; "
                                  f"{did_you_mean(name, chain.joint_names, 'joints')}")
    experiment = simulate_experiment(chain, KUKA_LWR4_DH, DEVIATION_SETS[deviations], settings, effects=injected)
    out = ensure_directory(out_dir)
    write_measurements(out / "calibration.csv", experiment.calibration)
    write_measurements(out / "validation.csv", experiment.validation)
    xyz, rpy = xyz_rpy_from_pose(experiment.tool)
    tool_arg = ",".join(repr(float(v)) for v in (*xyz, *rpy))
    truth = {
        "pincal_version": __version__,
        "robot": "KUKA LWR 4+ (Franaszek & Marvel 2022, Table 1)",
        "deviations": deviations,
        "settings": {
            "sigma_pos_mm": settings.sigma_pos_mm,
            "sigma_rot_deg": settings.sigma_rot_deg,
            "seed": settings.seed,
            "cpa_rows_per_joint": settings.n_cpa,
            "calibration_rows": settings.n_calibration,
            "validation_rows": settings.n_validation,
        },
        "dh": {
            "alpha_rad": experiment.truth.alpha.tolist(),
            "epsilon_rad": experiment.truth.epsilon.tolist(),
            "r_m": experiment.truth.r.tolist(),
            "d_m": experiment.truth.d.tolist(),
        },
        "registration": experiment.registration.as_dict(),
        "tool": {"parent_link": KUKA_FLANGE_LINK, "xyz_m": xyz.tolist(), "rpy_rad": rpy.tolist()},
        "effects": [effect_to_dict(e, v) for e, v in injected],
        "calibrate_command": (
            f"pincal calibrate {urdf} {out / 'calibration.csv'} --method 2 "
            f"--tool {tool_arg} --tool-parent {KUKA_FLANGE_LINK} "
            f"--out corrected.urdf --report REPORT.json"
        ),
    }
    write_text(out / "truth.json", json.dumps(truth, indent=2) + "\n")
    return experiment, truth


# --- calibrate -----------------------------------------------------------------


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
            (:mod:`pincal.cli.verdict`; ``reload_error`` is of the URDF withheld).
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
    """
    expect(settings, CalibrateSettings, "calibrate_files")
    level, tool_pose, xacro_args = settings.level, settings.tool_pose, settings.xacro_args
    sigma_column, reject_outliers, selection = settings.sigma_column, settings.reject_outliers, settings.criterion
    tool_parent, method = settings.tip_link, settings.paper_method
    urdf, data_paths = Path(urdf), input_paths(data_path)
    data_label = " + ".join(str(p) for p in data_paths)
    out_urdf, report_path = Path(out_urdf), Path(report_path)
    inputs = [*description_inputs(urdf, xacro_args), *data_paths]  # a xacro's included files too
    refuse_overwrite(out_urdf, *inputs)
    refuse_overwrite(report_path, *inputs, outputs=[out_urdf])
    refuse_overwrite(effects_path(out_urdf), *inputs, outputs=[out_urdf, report_path])
    chain = KinematicChain.from_urdf(urdf, tool_parent, tool=tool_pose, xacro_args=xacro_args)
    # readings taken against another joint corrected (eq C1) before the joint limits are judged
    data, notes = read_sessions(data_paths, chain.joint_specs, settings.couplings, chain.other_branch_joints)
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
        if level == "auto":
            from pincal.fit.level_choice import choose_level

            choice = choose_level(chain, data, tool_known=tool_pose is not None, sigma_column=sigma_column,
                                  reject_outliers=reject_outliers, selection=selection, progress=stages.next())
            level = choice.chosen
        fitted = calibrate_chain(
            chain, data, level, tool_known=tool_pose is not None, sigma_column=sigma_column,
            reject_outliers=reject_outliers, selection=selection, progress=stages.next(),
        )
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
    reload_error, urdf_sha256 = write_checked_urdf(
        urdf, out_urdf, chain, placements, nominal_placements, data.q,
        f"Calibrated by pincal {__version__} ({what}) from {urdf.name} and {', '.join(p.name for p in data_paths)}. "
        "Registration and tool: see the report.", xacro_args, keep=not verdict.withheld,
    )
    if verdict.withheld:
        removed = withhold(out_urdf)
        notes, report_notes = notes + removed, report_notes + removed
    xacro = dict(xacro_arguments(xacro_args))
    report: PaperReport | CalibrationReport
    if paper is not None:
        assert tool_pose is not None  # CalibrateSettings: level dh needs the tool
        report = paper_report(paper, params, tool_parent, tool_pose, errors, n_rows, sources, notes,
                              row_errors=row_errors, urdf_sha256=urdf_sha256, xacro_args=xacro)
    else:
        with chain.placed(placements):  # the report describes the calibrated model
            report = chain_report(chain_head(fitted, chain, tool_parent, errors, n_rows, sources, report_notes),
                                  warnings=verdict.warnings, sessions=entries, row_errors=row_errors,
                                  level_choice=level_choice_part(choice), urdf_sha256=urdf_sha256, xacro_args=xacro,
                                  couplings=couplings_part(settings.couplings))
    # the couplings, which a URDF cannot carry, beside the URDF (none beside a withheld one)
    effects_file = None if verdict.withheld else write_effects_file(out_urdf, report_path, report)
    write_report(report_path, report)
    return CalibrationRun(result, report, errors, notes, seconds, reload_error, session_list, choice, effects_file,
                          verdict.withheld)


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


# --- evaluate: pincal.cli.evaluation (re-exported here) ----------------------------------


# --- diagnose --------------------------------------------------------------------------


@dataclass(frozen=True)
class DiagnoseRun:
    """Outcome of :func:`diagnose_files` (``effects_file``: the effects.yaml written beside the URDF, or None;
    ``withheld``: the final model misses its rows grossly, the URDF and effects.yaml were not written)."""

    calibration: ChainCalibration
    diagnosis: Diagnosis
    report: DiagnosisReport
    notes: list[str]
    plots: list[Path]
    seconds: float
    level_choice: LevelChoice | None = None
    effects_file: Path | None = None
    withheld: bool = False


def diagnose_files(
    urdf: str | Path,
    data_path: str | Path | Sequence[str | Path],
    out_urdf: str | Path,
    report_path: str | Path,
    settings: DiagnoseSettings,
    validation_path: str | Path | None = None,
    plots_dir: str | Path | None = None,
    progress: Progress | None = None,
) -> DiagnoseRun:
    """Calibrate as ``settings`` say, search the residuals for missing effects, write the corrected
    URDF, the report (with ``effects``), the plots (into ``plots_dir``; None: none) and, with effects or
    couplings, the effects.yaml beside the URDF (:mod:`pincal.report.effects_file`); held-out
    rows from ``validation_path``.
    ``progress(done, total)`` counts the calibration's fits, then the search's (:mod:`pincal.progress`).
    Several ``data_path`` files are sessions (one registration each; see :func:`calibrate_files`)."""
    expect(settings, DiagnoseSettings, "diagnose_files")
    tip_link, level, tool_pose, xacro_args = settings.tip_link, settings.level, settings.tool_pose, settings.xacro_args
    sigma_column, selection, payload_kg = settings.sigma_column, settings.criterion, settings.payload_kg
    time_column_name, sigma_pos_m = settings.time_column, settings.sigma_pos_m
    from pincal.diagnosis.conditions import read_readings
    from pincal.diagnosis.diagnose import diagnose
    from pincal.fit.level_choice import choose_level

    urdf, data_paths, out_urdf, report_path = Path(urdf), input_paths(data_path), Path(out_urdf), Path(report_path)
    inputs = [*description_inputs(urdf, xacro_args), *data_paths] + ([Path(validation_path)] if validation_path else [])
    refuse_overwrite(out_urdf, *inputs)
    refuse_overwrite(report_path, *inputs, outputs=[out_urdf])
    refuse_overwrite(effects_path(out_urdf), *inputs, outputs=[out_urdf, report_path])
    if plots_dir is not None:  # the names pincal.diagnosis.plots gives its figures
        refuse_overwrite_matching(plots_dir, "diagnose_*.png", *inputs)
    if level == "dh":
        raise PincalError("diagnose works on --level registration, offsets or full")
    started = time.perf_counter()
    chain = KinematicChain.from_urdf(urdf, tip_link, tool=tool_pose, xacro_args=xacro_args)
    # readings taken against another joint corrected (eq C1) before the joint limits are judged
    data, notes = read_sessions(data_paths, chain.joint_specs, settings.couplings, chain.other_branch_joints)
    heldout = held_time = None
    if validation_path:
        heldout, held_notes = read_measurements(validation_path, chain.joint_specs, settings.couplings,
                                                 chain.other_branch_joints)
        notes += held_notes
        held_time = time_column(heldout, time_column_name)
    readings = read_readings(data, heldout, settings.temperature_column, settings.pause_s)  # thermal, pauses
    nominal_placements = chain.placements()
    stages = Stages(progress)
    choice = None
    if level == "auto":  # the geometric level by cross-validation of the geometric calibration
        choice = choose_level(chain, data, tool_known=tool_pose is not None, sigma_column=sigma_column,
                              selection=selection, progress=stages.next())
        level = choice.chosen
    # the geometric calibration, made again by diagnose on readings it corrects (a joint read against another)
    recalibrate = partial(calibrate_chain, chain, level=level, tool_known=tool_pose is not None,
                          sigma_column=sigma_column, selection=selection, refit_offered=False)
    calibration = recalibrate(data, progress=stages.next())
    notes += unfitted_sessions(data, calibration.session_names)
    row_time = time_column(data, time_column_name)
    diagnosis = diagnose(chain, calibration, data, heldout=heldout, sigma_column=sigma_column,
                         payload_kg=payload_kg, time=row_time, heldout_time=held_time, progress=stages.next(),
                         readings=readings, recalibrate=recalibrate, couplings=settings.couplings,
                         stated_sigma_pos_m=sigma_pos_m)
    # the final model: on the readings corrected by the conventions diagnose found, from their calibration
    data, calibration = apply_couplings(data, diagnosis.couplings), diagnosis.calibration or calibration
    heldout = None if heldout is None else apply_couplings(heldout, diagnosis.couplings)
    final = diagnosis.final_calibration()  # the model with its effects, as the report and its checks see it
    used = data.select(calibration.used_index)
    with chain.placed(final.chain_placements):  # judged: the final model, with the effects it adopted
        verdict = judged(chain, data_paths, calibration_findings(chain, final, used, sigma_column, sigma_pos_m,
                                                                 press_of=calibration, diagnosed=True), settings.force)
        notes += verdict.notes + unmodelled_notes(final, reach_m(chain, used.q), sigma_pos_m)
    _, urdf_sha256 = write_checked_urdf(
        urdf, out_urdf, chain, final.chain_placements, nominal_placements, data.q,
        f"Calibrated by pincal {__version__} (diagnose, level {level}) from {urdf.name} and "
        f"{', '.join(p.name for p in data_paths)}. "
        "Registration, tool and effects (which a URDF cannot carry): see the report.", xacro_args,
        keep=not verdict.withheld,
    )
    if verdict.withheld:
        notes += withhold(out_urdf)
    sources: Sources = {"urdf": str(urdf),
                        "data": str(data_paths[0]) if len(data_paths) == 1 else [str(p) for p in data_paths],
                        "corrected_urdf": str(out_urdf),
                        "validation": None if validation_path is None else str(validation_path)}
    plots = []
    if plots_dir is not None:
        from pincal.diagnosis.plots import plot_diagnosis  # matplotlib only when drawing

        plots = plot_diagnosis(diagnosis, ensure_directory(plots_dir))
    with chain.placed(final.chain_placements):  # the report describes the final model
        head = chain_head(final, chain, tip_link, diagnosis.calibration_errors, fit_rows(data.roles), sources, notes)
        report = diagnosis_report(
            head, diagnosis, payload_kg, time_column_name or _time_name(data), warnings=verdict.warnings,
            sessions=session_entries(final.session_names, final.target.registrations, used,
                                     session_rows(used, final.session_names), diagnosis.calibration_errors),
            time_spans=drift_spans(diagnosis, row_time, calibration, used),  # where a drift holds (evaluate)
            row_errors=diagnosis_row_errors(chain, nominal_placements, data, heldout, calibration, diagnosis,
                                            (" + ".join(str(p) for p in data_paths),
                                             None if validation_path is None else str(validation_path))),
            urdf_sha256=urdf_sha256, xacro_args=dict(xacro_arguments(xacro_args)),
            level_choice=level_choice_part(choice), plots=[str(p) for p in plots],
            couplings=couplings_part((*settings.couplings, *diagnosis.couplings)),
        )
    # what the URDF cannot carry, for a controller (nothing beside a withheld URDF)
    effects_file = None if verdict.withheld else write_effects_file(out_urdf, report_path, report)
    write_report(report_path, report)
    return DiagnoseRun(calibration, diagnosis, report, notes, plots, time.perf_counter() - started, choice,
                       effects_file, verdict.withheld)


def _time_name(data: MeasurementSet) -> str | None:
    return next((n for n in TIME_COLUMNS if n in data.extra), None)
