"""``pincal diagnose`` with several ``--tip-link LINK:POINTS``: calibrate every target's chain in one fit, search
the tree's residuals for effects the geometry lacks (:func:`pincal.diagnosis.tree_diagnose.diagnose_tree`), write
the final model's URDF (every calibrated chain), effects.yaml beside it and REPORT.json with each target's errors
before and after (:func:`diagnose_tree_files`).

A gross misfit of the final model withholds its URDF and effects.yaml unless ``--force``, and the other checks of
one chain warn, as calibrate's (:func:`pincal.workflows.tree_calibration.tree_findings`).
``--level auto`` and ``--coupling`` are calibrate's (:mod:`pincal.workflows.tree_calibration`): the geometry under
the effects at the level cross-validation chooses, every row read (held-out rows too) corrected or followed as the
couplings say. What the single chain's diagnose adds and a tree's does not yet: a known ``--tool``,
``--payload-kg``, ``--plots``, thermal and pause steps; each is refused with one line, never run differently.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

from pincal._version import __version__
from pincal.errors import PincalError
from pincal.fit.chain_calibration import ChainFitOptions
from pincal.fit.tree_calibration import TreeCalibration, calibrate_tree
from pincal.measurements.csv_v1 import read_measurements, read_sessions
from pincal.model.description import xacro_arguments
from pincal.model.drift import time_column
from pincal.model.thermal import PAUSE_S
from pincal.model.tree import KinematicTree, TargetSpec
from pincal.progress import Stages
from pincal.report.document import write_report
from pincal.report.effects_file import effects_path, write_effects_file
from pincal.report.model import Sources, findings_json
from pincal.report.model_tree import TreeReport
from pincal.report.tree import tree_report
from pincal.report.tree_diagnosis import with_diagnosis
from pincal.workflows.diagnosis import DiagnoseOutputs
from pincal.workflows.paths import description_inputs, input_paths, refuse_overwrite
from pincal.workflows.report_page import refuse_page, render_page, write_page
from pincal.workflows.settings import DiagnoseSettings, follow_couplings
from pincal.workflows.tree_calibration import tree_findings, tree_level, write_tree_urdf
from pincal.workflows.verdict import unmodelled_notes, withhold, withholding

if TYPE_CHECKING:  # imported where used, so `pincal calibrate` loads none of the search
    from pincal.diagnosis.tree_diagnose import TreeDiagnosis

__all__ = ["TreeDiagnoseRun", "diagnose_tree_files"]


@dataclass(frozen=True)
class TreeDiagnoseRun:
    """Outcome of :func:`diagnose_tree_files`.

    Attributes:
        calibration: the geometric calibration the effects were added to; final: the final model as a calibration
            (its geometry, registrations, points and errors, with the effects).
        diagnosis: the search (:class:`pincal.diagnosis.tree_diagnose.TreeDiagnosis`).
        report: the REPORT.json written.
        notes: the reader's notes, the calibration's and the search's.
        seconds: the whole run's wall time [s].
        effects_file: the effects.yaml written beside the URDF, or None (no effect, or withheld).
        withheld: the final model misses its rows grossly: the URDF and effects.yaml were not written.
        html: the report's page written, or None.
    """

    calibration: TreeCalibration
    final: TreeCalibration
    diagnosis: TreeDiagnosis
    report: TreeReport
    notes: list[str]
    seconds: float
    effects_file: Path | None = None
    withheld: bool = False
    html: Path | None = None


def _refused(settings: DiagnoseSettings, outputs: DiagnoseOutputs) -> None:
    for refused, flag in ((settings.tool_pose is not None, "--tool"),
                          (settings.payload_kg > 0, "--payload-kg"), (outputs.plots_dir is not None, "--plots"),
                          (settings.temperature_column is not None, "--temperature-column"),
                          (settings.pause_s != PAUSE_S, "--pause-s")):
        if refused:
            raise PincalError(f"several --tip-link: diagnose {flag} is not yet supported; leave it out")


def diagnose_tree_files(urdf: str | Path, data_path: str | Path | Sequence[str | Path], out_urdf: str | Path,
                        report_path: str | Path, targets: Sequence[TargetSpec], settings: DiagnoseSettings,
                        validation_path: str | Path | None = None, outputs: DiagnoseOutputs | None = None
                        ) -> TreeDiagnoseRun:
    """Calibrate every one of ``targets`` on ``data_path`` in one fit, search for missing effects as ``settings``
    say (its ``tip_link`` is not read), write the final model's URDF, effects.yaml (with effects) and the report,
    and the page ``outputs.html`` asks for; held-out rows from ``validation_path`` judge each effect and give each
    target's errors before and after."""
    from pincal.diagnosis.diagnose import DiagnoseOptions
    from pincal.diagnosis.tree_diagnose import diagnose_tree

    outputs = DiagnoseOutputs() if outputs is None else outputs
    _refused(settings, outputs)
    started = time.perf_counter()
    urdf, data_paths, out_urdf, report_path = Path(urdf), input_paths(data_path), Path(out_urdf), Path(report_path)
    inputs = [*description_inputs(urdf, settings.xacro_args), *data_paths] + (
        [Path(validation_path)] if validation_path else [])
    refuse_overwrite(out_urdf, *inputs)
    refuse_overwrite(report_path, *inputs, outputs=[out_urdf])
    refuse_overwrite(effects_path(out_urdf), *inputs, outputs=[out_urdf, report_path])
    html = refuse_page(outputs.html, inputs, [out_urdf, report_path, effects_path(out_urdf)])
    tree = KinematicTree.from_urdf(urdf, targets, xacro_args=settings.xacro_args)
    couplings = follow_couplings(tree, settings.couplings, data_paths)  # a joint without a column follows (M1)
    data, notes = read_sessions(data_paths, tree.joint_specs, couplings, tree.other_branch_joints, occlusion=True)
    heldout = held_time = None
    if validation_path:
        heldout, held_notes = read_measurements(validation_path, tree.joint_specs, couplings,
                                                tree.other_branch_joints, occlusion=True)
        notes += held_notes
        held_time = time_column(heldout, settings.time_column)
    options = ChainFitOptions(sigma_column=settings.sigma_column, selection=settings.criterion, refit_offered=False)
    choice, level = tree_level(tree, data, settings.level, options, Stages(None))
    calibration = calibrate_tree(tree, data, level, options)
    nominal = calibrate_tree(tree, data, "registration", ChainFitOptions(sigma_column=settings.sigma_column))
    diagnosis = diagnose_tree(tree, calibration, data, heldout, DiagnoseOptions(
        sigma_column=settings.sigma_column, time=time_column(data, settings.time_column), heldout_time=held_time,
        stated_sigma_pos_m=settings.sigma_pos_m, masses=settings.masses, lateral=settings.lateral))
    final = replace(calibration, vector=diagnosis.vector, std=diagnosis.std, target=diagnosis.target,
                    point_errors=diagnosis.point_errors, sigma_pos_m=diagnosis.sigma_pos_m,
                    tree_placements=diagnosis.tree_placements, orientation_errors=diagnosis.orientation_errors,
                    sigma_rot_rad=diagnosis.sigma_rot_rad)
    used_q = data.q[calibration.used_index]
    reach, findings = tree_findings(tree, final, used_q, settings.sigma_pos_m, diagnosed=True)
    warnings, withheld = withholding(findings, settings.force)
    comment = (f"Calibrated by pincal {__version__} (diagnose, level {level}, {len(tree.targets)} targets) from "
               f"{urdf.name} and {', '.join(p.name for p in data_paths)}. Registration, targets and effects (which "
               "a URDF cannot carry): see the report.")
    _, digest = write_tree_urdf(urdf, out_urdf, tree, final.tree_placements, (comment, settings.xacro_args), data.q,
                                keep=not withheld)
    sources: Sources = {"urdf": str(urdf),
                        "data": str(data_paths[0]) if len(data_paths) == 1 else [str(p) for p in data_paths],
                        "corrected_urdf": str(out_urdf),
                        "validation": None if validation_path is None else str(validation_path)}
    notes = notes + list(calibration.notes) + list(diagnosis.notes) + unmodelled_notes(final, reach,
                                                                                       settings.sigma_pos_m)
    if withheld:
        sources["corrected_urdf_withheld"] = True  # the path names no file of this run
        notes += withhold(out_urdf)
    report = tree_report(final, nominal, tree, sources, notes, (digest, dict(xacro_arguments(settings.xacro_args))),
                         couplings, choice)
    report["warnings"] = findings_json(warnings)
    report = with_diagnosis(report, diagnosis, (calibration.point_errors, calibration.orientation_errors), tree)
    page = render_page(html, report, report_path)
    effects_file = None if withheld else write_effects_file(out_urdf, report_path, report)
    write_report(report_path, report)
    return TreeDiagnoseRun(calibration, final, diagnosis, report, notes, time.perf_counter() - started, effects_file,
                           withheld, write_page(html, page))
