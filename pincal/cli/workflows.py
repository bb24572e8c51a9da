"""End-to-end jobs behind the command line: simulate, calibrate, evaluate, diagnose, demo.

Each function takes paths and options, does the whole job, and returns what
happened; the CLI (:mod:`pincal.cli.commands`) only parses arguments and prints.
The workflows of urdf-from-dh and plan are in :mod:`pincal.cli.preparation`,
the output path policy of all of them in :mod:`pincal.cli.paths`.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from pincal._version import __version__
from pincal.cli.paths import ensure_directory, refuse_overwrite
from pincal.diagnosis.diagnose import Diagnosis, diagnose
from pincal.errors import CalibrationError, PincalError
from pincal.fit.chain_calibration import ChainCalibration, calibrate_chain
from pincal.fit.metrics import PoseErrors, pose_errors
from pincal.fit.paper_methods import PaperCalibration, calibrate_paper
from pincal.fit.registration import register_orientations, register_points
from pincal.measurements.csv_v1 import read_measurements, write_measurements
from pincal.measurements.data import MeasurementSet
from pincal.model.chain import KinematicChain, pose_from_xyz_rpy, xyz_rpy_from_pose
from pincal.model.corrected_urdf import write_corrected_urdf
from pincal.model.dh import DEVIATION_SETS, KUKA_LWR4_DH
from pincal.model.dh_parameters import DHParameterSet
from pincal.model.effects import (
    TIME_COLUMNS,
    effect_from_dict,
    effect_inputs,
    effect_to_dict,
    joint_shifts,
    parse_effect,
    time_column,
)
from pincal.outputs import file_sha256, write_text
from pincal.report.document import (
    chain_report,
    diagnosis_report,
    paper_report,
    read_report,
    write_report,
)
from pincal.robots import KUKA_FLANGE_LINK, kuka_lwr4plus_urdf
from pincal.simulation.paper import (
    SimulatedExperiment,
    SimulationSettings,
    simulate_experiment,
)

#: Reloading a written URDF must reproduce the calibrated TCP to this [m, rad].
RELOAD_TOLERANCE = 1e-9


# --- simulate ----------------------------------------------------------------


def simulate_to_directory(
    out_dir: str | Path, deviations: str, settings: SimulationSettings, effects: Sequence[str] = ()
) -> tuple[SimulatedExperiment, dict[str, Any]]:
    """Simulate the paper's experiment on the packaged KUKA LWR 4+ and write
    ``calibration.csv``, ``validation.csv`` and ``truth.json`` into ``out_dir``.

    ``effects`` (``TYPE:JOINT:VALUE`` strings, see :func:`pincal.model.effects.parse_effect`)
    are injected into the data without being declared in it; truth.json records them.
    """
    if deviations not in DEVIATION_SETS:
        raise PincalError(f"unknown deviation set '{deviations}'; use one of {sorted(DEVIATION_SETS)}")
    urdf = kuka_lwr4plus_urdf()
    chain = KinematicChain.from_urdf(urdf, KUKA_FLANGE_LINK)
    injected = [parse_effect(text) for text in effects]
    for effect, _ in injected:
        if effect.joint is not None and effect.joint not in chain.joint_names:
            raise PincalError(f"effect '{effect.label}': no joint '{effect.joint}'; joints are: "
                              f"{', '.join(chain.joint_names)}")
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
        report: the REPORT.json document written.
        errors: eq 24 errors on the calibration rows.
        notes: reader and method notes for the user.
        seconds: wall time of the calibration itself [s].
        reload_error: largest TCP difference after reloading the written URDF [m].
    """

    result: PaperCalibration | ChainCalibration
    report: dict[str, Any]
    errors: PoseErrors
    notes: list[str]
    seconds: float
    reload_error: float


def calibrate_chain_dh(
    chain: KinematicChain, data: MeasurementSet, method: int, weight: float
) -> tuple[PaperCalibration, DHParameterSet, float]:
    """Run a paper method on a loaded chain; returns the result, the parameter set and the time [s]."""
    params = DHParameterSet(chain)
    start = time.perf_counter()
    result = calibrate_paper(chain, data, method, weight=weight, nominal=params.nominal)
    return result, params, time.perf_counter() - start


def calibrate_files(
    urdf: str | Path,
    data_path: str | Path,
    method: int,
    weight: float,
    tool_pose: np.ndarray | None,
    tool_parent: str,
    out_urdf: str | Path,
    report_path: str | Path,
    level: str = "dh",
    sigma_column: str | None = None,
    reject_outliers: bool = False,
    selection: str = "aic",
) -> CalibrationRun:
    """Calibrate ``urdf`` on ``data_path`` and write the corrected URDF and the report.

    ``level`` ``dh`` runs the paper's Method ``method`` (needs ``tool_pose``);
    ``registration``, ``offsets`` and ``full`` calibrate any chain
    (:func:`pincal.fit.chain_calibration.calibrate_chain`), estimating the target
    unless ``tool_pose`` is given.
    """
    urdf, data_path = Path(urdf), Path(data_path)
    out_urdf, report_path = Path(out_urdf), Path(report_path)
    refuse_overwrite(out_urdf, urdf, data_path)
    refuse_overwrite(report_path, urdf, data_path, outputs=[out_urdf])
    if level == "dh" and tool_pose is None:
        raise PincalError(
            "the paper's methods (--level dh) need the tool: --tool X,Y,Z,ROLL,PITCH,YAW; "
            "or use --level registration|offsets|full to estimate the target"
        )
    chain = KinematicChain.from_urdf(urdf, tool_parent, tool=tool_pose)
    data, notes = read_measurements(data_path, chain.joint_specs)
    nominal_placements = chain.placements()
    n_rows = {role: int(np.sum(data.roles == role)) for role in ("cpa", "calibration", "validation")}
    sources = {"urdf": str(urdf), "data": str(data_path), "corrected_urdf": str(out_urdf)}
    if level == "dh":
        result, params, seconds = calibrate_chain_dh(chain, data, method, weight)
        errors = pose_errors(
            chain, data.with_role("calibration"), result.registration_position, result.registration_orientation
        )
        report = paper_report(result, params, tool_parent, tool_pose, errors, n_rows, sources, notes)
        what = f"Method {method} of Franaszek & Marvel 2022"
    else:
        start = time.perf_counter()
        result = calibrate_chain(
            chain, data, level, tool_known=tool_pose is not None, sigma_column=sigma_column,
            reject_outliers=reject_outliers, selection=selection,
        )
        seconds = time.perf_counter() - start
        registration = result.target.registration
        used = data.select(np.isin(data.lines, result.rows_used))
        errors = pose_errors(
            chain, used, registration, registration, points=result.target.points,
            target_rotation=result.target.rotation,
        )
        report = chain_report(result, chain, tool_parent, errors, n_rows, sources, notes)
        what = f"level {level}"
    reload_error, report["urdf_sha256"] = write_checked_urdf(
        urdf, out_urdf, chain, nominal_placements, data.q,
        f"Calibrated by pincal {__version__} ({what}) from {urdf.name} and {data_path.name}. "
        "Registration and tool: see the report.",
    )
    write_report(report_path, report)
    return CalibrationRun(result, report, errors, notes, seconds, reload_error)


def write_checked_urdf(
    source: Path, destination: Path, chain: KinematicChain, nominal_placements, q: np.ndarray, comment: str
) -> tuple[float, str]:
    """Write the corrected URDF, checking before it replaces ``destination`` that
    reloading it reproduces the chain's tool poses at ``q`` to :data:`RELOAD_TOLERANCE`
    (a failed check leaves the old file).

    Returns:
        The largest difference [m, -] and the SHA-256 (hex) of the bytes written
        (the report's ``urdf_sha256``).
    """
    checked: list[float] = []
    digest: list[str] = []

    def verify(written: Path) -> None:
        checked.append(_reload_error(written, chain, q))
        if checked[-1] > RELOAD_TOLERANCE:
            raise CalibrationError(
                f"{destination}: reloading the written URDF moves the tool by {checked[-1]:.3g} "
                f"(> {RELOAD_TOLERANCE:g}); not written; please report this as a bug"
            )
        digest.append(file_sha256(written))

    write_corrected_urdf(source, destination, chain, nominal_placements, comment=comment, verify=verify)
    return checked[-1], digest[-1]


def _reload_error(urdf: Path, chain: KinematicChain, q: np.ndarray) -> float:
    reloaded = KinematicChain.from_urdf(urdf, chain.tip_link, tool=chain.tool)
    a, b = chain.poses(q), reloaded.poses(q)
    return float(
        max(
            np.abs(a.tool_positions - b.tool_positions).max(),
            np.abs(a.tool_rotations - b.tool_rotations).max(),
        )
    )


# --- evaluate --------------------------------------------------------------------


@dataclass(frozen=True)
class Evaluation:
    """Outcome of :func:`evaluate_files`: eq 24 errors on the evaluated rows."""

    errors: PoseErrors
    n_skipped_cpa: int
    notes: list[str]

    def as_dict(self) -> dict[str, Any]:
        return {**self.errors.as_dict(), "skipped_cpa_rows": self.n_skipped_cpa}


def evaluate_files(
    urdf: str | Path, report_path: str | Path, data_path: str | Path, allow_other_urdf: bool = False
) -> Evaluation:
    """Eq 24 on every non-CPA row of ``data_path`` with the model and registrations of a report.

    When the report records the SHA-256 of the URDF written with it
    (``urdf_sha256``), ``urdf`` must be that file — a run killed between
    writing the URDF and the report, or a report of another run, is refused —
    unless ``allow_other_urdf`` (the URDF was edited on purpose; a note says so).
    """
    report = read_report(report_path)
    chain = KinematicChain.from_urdf(urdf, report.tool_parent)
    notes: list[str] = []
    if report.urdf_sha256 is not None and file_sha256(urdf) != report.urdf_sha256:
        if not allow_other_urdf:
            raise PincalError(
                f"{urdf}: not the URDF {report_path} was written with (its SHA-256 differs from the report's "
                "urdf_sha256); evaluate the pair calibrate wrote, or pass --allow-other-urdf if you changed it "
                "on purpose"
            )
        notes.append(f"{urdf}: not the URDF {report_path} was written with (--allow-other-urdf)")
    data, read_notes = read_measurements(data_path, chain.joint_specs)
    notes += read_notes
    if data.n_points != len(report.points):
        raise PincalError(
            f"{data_path}: {data.n_points} target point(s) per row, but the report's tool has "
            f"{len(report.points)}; evaluate with data of the same target"
        )
    rows = data.roles != "cpa"
    if not np.any(rows):
        raise PincalError(f"{data_path}: no rows to evaluate (all rows have role 'cpa')")
    data = data.select(rows)
    corrections = _effect_corrections(chain, data, report.effects, report.points)
    errors = pose_errors(
        chain,
        data,
        report.registration_position,
        report.registration_orientation,
        points=report.points,
        target_rotation=report.rotation,
        **corrections,
    )
    return Evaluation(errors=errors, n_skipped_cpa=int(np.sum(~rows)), notes=notes)


def _effect_corrections(chain: KinematicChain, data: MeasurementSet, effects: dict, points: np.ndarray) -> dict:
    """Joint readings corrected by the report's effects, and its sensor terms."""
    entries = effects.get("effects", [])
    if not entries:
        return {}
    parsed = [effect_from_dict(e) for e in entries]
    needs_time = any(e.type == "drift" for e, _ in parsed)
    row_time = time_column(data, effects.get("time_column")) if needs_time else time_column(data)
    if needs_time and row_time is None:
        raise PincalError(f"{data.source}: the report has a drift effect; the data need its time column")
    reference = effects.get("time_reference_s")
    context = effects.get("approach_context") or {}
    try:
        payload = float(effects.get("payload_kg", 0.0))
        context_q = np.asarray(context["q"], dtype=float) if context else None
        context_time = np.asarray(context["time_s"], dtype=float) if context else None
    except (KeyError, TypeError, ValueError):
        raise PincalError(f"{data.source}: the report's payload_kg or approach_context is malformed") from None
    inputs = effect_inputs(chain, data, payload, points.mean(axis=0), row_time,
                           time_reference=reference if row_time is not None else None,
                           context_q=context_q, context_time=context_time)
    q = data.q + joint_shifts([e for e, _ in parsed], [v for _, v in parsed], inputs, chain.joint_names)
    out: dict = {"q": q}
    for effect, value in parsed:
        if effect.type == "sensor_scale":
            out["sensor_scale"] = float(value[0])
        elif effect.type == "drift":
            out["drift"] = inputs.time[:, None] * value
    return out


# --- demo ----------------------------------------------------------------------------


@dataclass(frozen=True)
class DemoRow:
    """One line of the demo's comparison table."""

    label: str
    calibration: PoseErrors
    validation: PoseErrors
    seconds: float


def run_demo(out_dir: str | Path, settings: SimulationSettings, deviations: str = "large") -> list[DemoRow]:
    """Simulate → calibrate with Methods 1–3 → evaluate on held-out poses.

    Writes the simulated data, one corrected URDF and report per method into
    ``out_dir``; returns the comparison rows (nominal model first).
    """
    out = Path(out_dir)
    experiment, truth = simulate_to_directory(out, deviations, settings)
    urdf = kuka_lwr4plus_urdf()
    tool = pose_from_xyz_rpy(truth["tool"]["xyz_m"], truth["tool"]["rpy_rad"])
    rows = [_nominal_row(urdf, experiment, tool)]
    for method in (1, 2, 3):
        run = calibrate_files(
            urdf,
            out / "calibration.csv",
            method,
            1.0,
            tool,
            KUKA_FLANGE_LINK,
            out / f"kuka_lwr4plus_method{method}.urdf",
            out / f"REPORT_method{method}.json",
        )
        evaluation = evaluate_files(
            out / f"kuka_lwr4plus_method{method}.urdf",
            out / f"REPORT_method{method}.json",
            out / "validation.csv",
        )
        rows.append(DemoRow(f"Method {method}", run.errors, evaluation.errors, run.seconds))
    return rows


def _nominal_row(urdf: Path, experiment: SimulatedExperiment, tool: np.ndarray) -> DemoRow:
    """The uncalibrated model, registered to the data like Method 2 would."""
    chain = KinematicChain.from_urdf(urdf, KUKA_FLANGE_LINK, tool=tool)
    cal = experiment.calibration.with_role("calibration")
    poses = chain.poses(cal.q)
    points = cal.points[:, 0, :]
    reg1 = register_points(poses.tool_positions, points)
    reg2 = register_orientations(poses.tool_rotations, cal.rotations, poses.tool_positions, points)
    return DemoRow(
        "nominal (Table 1)",
        pose_errors(chain, cal, reg1, reg2),
        pose_errors(chain, experiment.validation, reg1, reg2),
        0.0,
    )


# --- diagnose --------------------------------------------------------------------------


@dataclass(frozen=True)
class DiagnoseRun:
    """Outcome of :func:`diagnose_files`."""

    calibration: ChainCalibration
    diagnosis: Diagnosis
    report: dict[str, Any]
    notes: list[str]
    plots: list[Path]
    seconds: float


def diagnose_files(
    urdf: str | Path,
    data_path: str | Path,
    out_urdf: str | Path,
    report_path: str | Path,
    tip_link: str,
    level: str = "full",
    tool_pose: np.ndarray | None = None,
    validation_path: str | Path | None = None,
    sigma_column: str | None = None,
    selection: str = "aic",
    payload_kg: float = 0.0,
    time_column_name: str | None = None,
    plots_dir: str | Path | None = None,
) -> DiagnoseRun:
    """Calibrate, search the residuals for missing effects, write the corrected
    URDF, the report (with ``effects``) and the plots."""
    urdf, data_path, out_urdf, report_path = Path(urdf), Path(data_path), Path(out_urdf), Path(report_path)
    inputs = [urdf, data_path] + ([Path(validation_path)] if validation_path else [])
    refuse_overwrite(out_urdf, *inputs)
    refuse_overwrite(report_path, *inputs, outputs=[out_urdf])
    if level == "dh":
        raise PincalError("diagnose works on --level registration, offsets or full")
    started = time.perf_counter()
    chain = KinematicChain.from_urdf(urdf, tip_link, tool=tool_pose)
    data, notes = read_measurements(data_path, chain.joint_specs)
    heldout = held_time = None
    if validation_path:
        heldout, held_notes = read_measurements(validation_path, chain.joint_specs)
        notes += held_notes
        held_time = time_column(heldout, time_column_name)
    nominal_placements = chain.placements()
    calibration = calibrate_chain(chain, data, level, tool_known=tool_pose is not None,
                                  sigma_column=sigma_column, selection=selection)
    row_time = time_column(data, time_column_name)
    diagnosis = diagnose(chain, calibration, data, heldout=heldout, sigma_column=sigma_column,
                         payload_kg=payload_kg, time=row_time, heldout_time=held_time)
    objective, x = diagnosis.objective, diagnosis.solution_x
    kinematic = objective.blocks["kinematic"]
    vector = calibration.vector.copy()
    vector[calibration.kept] = x[kinematic]
    std = np.full(vector.size, np.nan)
    std[calibration.kept] = diagnosis.solution_std[kinematic]
    if calibration.params is not None:
        calibration.params.apply(vector)
    final = replace(  # the model with its effects: values, spreads, noise and fit of the final fit
        calibration, vector=vector, std=std, target=objective.estimate(x),
        target_std=diagnosis.solution_std[kinematic.stop : objective.blocks["effects"].start],
        sigma_pos_m=diagnosis.sigma_pos_m, sigma_rot_rad=diagnosis.sigma_rot_rad,
        rms_m=float(np.sqrt(np.mean(diagnosis.calibration_errors.position_m**2))),
    )
    _, urdf_sha256 = write_checked_urdf(
        urdf, out_urdf, chain, nominal_placements, data.q,
        f"Calibrated by pincal {__version__} (diagnose, level {level}) from {urdf.name} and {data_path.name}. "
        "Registration, tool and effects (which a URDF cannot carry): see the report.",
    )
    n_rows = {role: int(np.sum(data.roles == role)) for role in ("cpa", "calibration", "validation")}
    sources = {"urdf": str(urdf), "data": str(data_path), "corrected_urdf": str(out_urdf),
               "validation": None if validation_path is None else str(validation_path)}
    report = chain_report(final, chain, tip_link, diagnosis.calibration_errors, n_rows, sources, notes)
    report.update(diagnosis_report(diagnosis, payload_kg, time_column_name or _time_name(data)))
    report["urdf_sha256"] = urdf_sha256
    plots = []
    if plots_dir is not None:
        from pincal.diagnosis.plots import plot_diagnosis  # matplotlib only when drawing

        plots = plot_diagnosis(diagnosis, ensure_directory(plots_dir))
    report["diagnosis"]["plots"] = [str(p) for p in plots]
    write_report(report_path, report)
    return DiagnoseRun(calibration, diagnosis, report, notes, plots, time.perf_counter() - started)


def _time_name(data: MeasurementSet) -> str | None:
    return next((n for n in TIME_COLUMNS if n in data.extra), None)
