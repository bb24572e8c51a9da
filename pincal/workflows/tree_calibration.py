"""``pincal calibrate`` with several ``--tip-link LINK:POINTS``: every target's chain in one calibration
(:func:`calibrate_tree_files`), the corrected URDF carrying every calibrated chain and a REPORT.json with
each target's errors (:mod:`pincal.report.model_tree`).

A gross misfit (:func:`pincal.fit.plausibility.gross_misfit` of every seen point's RMS error) withholds the
corrected URDF unless ``--force``, as with one chain (:mod:`pincal.workflows.verdict`); the other checks of one
chain warn as there (:func:`pincal.fit.plausibility.fit_findings`: the residual, against ``--sigma-pos`` too,
each target's points, each registration, the corrections; not the leave-one-row-out comparison nor the
tip-link check). ``--level auto`` chooses the tree's level by cross-validation
(:func:`pincal.fit.tree_level_choice.choose_tree_level`, REPORT.json ``level_choice``); ``--coupling``
corrects every row read (eq C1 of :mod:`pincal.measurements.couplings`) or, on a joint without a column,
makes it follow its driver, as with one chain (REPORT.json ``couplings``, and effects.yaml beside the URDF,
which cannot carry them). What the single chain's run adds and a tree's does not yet: ``--level dh`` (a tree
has no DH table), a known ``--tool``, unnumbered orientation columns (``qx,qy,qz,qw``: whose?); each is
refused with one line, never run differently.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, cast

import numpy as np

from pincal._version import __version__
from pincal.errors import CalibrationError, PincalError
from pincal.fit.chain_calibration import ChainFitOptions
from pincal.fit.plausibility import Finding, fit_findings, reach_m
from pincal.fit.tree_calibration import TreeCalibration, calibrate_tree
from pincal.measurements.csv_v1 import read_sessions
from pincal.measurements.data import MeasurementSet
from pincal.model.corrected_urdf import corrected_origins
from pincal.model.description import xacro_arguments
from pincal.model.parameter_sets import ChainLevel
from pincal.model.tree import KinematicTree, TargetSpec, TreePlacements
from pincal.model.urdf import write_urdf_with_origins
from pincal.outputs import file_sha256
from pincal.progress import Progress, Stages
from pincal.report.document import write_report
from pincal.report.effects_file import effects_path, write_effects_file
from pincal.report.model import Sources, findings_json
from pincal.report.model_tree import TreeReport
from pincal.report.tree import tree_report
from pincal.workflows.paths import description_inputs, input_paths, refuse_overwrite
from pincal.workflows.report_page import refuse_page, render_page, write_page
from pincal.workflows.settings import CalibrateSettings, follow_couplings
from pincal.workflows.verdict import RELOAD_TOLERANCE, diagnose_command, unmodelled_notes, withhold, withholding

if TYPE_CHECKING:
    from pincal.fit.level_choice import LevelChoice

__all__ = ["TreeCalibrationRun", "calibrate_tree_files", "write_tree_urdf", "refuse_tree_level", "tree_level",
           "tree_findings"]


@dataclass(frozen=True)
class TreeCalibrationRun:
    """Outcome of :func:`calibrate_tree_files`.

    Attributes:
        result: the calibration; nominal: the nominal model registered to the same rows (the errors before).
        report: the REPORT.json written.
        notes: the reader's notes and the fit's.
        seconds: the calibration's wall time [s].
        reload_error: the largest difference of any target's tool pose after reloading the written URDF [m, -].
        withheld: the corrected URDF is not written (a gross misfit without ``--force``:
            :mod:`pincal.workflows.verdict`); REPORT.json says so in ``warnings``.
        html: the report's page written (``--html``), or None.
        choice: how ``--level auto`` chose the level, or None (a level given).
        effects_file: the effects.yaml written beside the URDF (``--coupling``), or None.
    """

    result: TreeCalibration
    nominal: TreeCalibration
    report: TreeReport
    notes: list[str]
    seconds: float
    reload_error: float
    withheld: bool = False
    html: Path | None = None
    choice: LevelChoice | None = None
    effects_file: Path | None = None


def refuse_tree_level(level: str, tool_pose: object) -> None:
    """Refuse what a tree's calibration and diagnosis do not take, in one line each: ``--level dh`` (the paper's
    methods fit one serial chain's DH table with a known tool; a tree has several chains and no such table) and a
    known ``--tool`` (each target's points are estimated in its tip link)."""
    if level == "dh":
        raise PincalError("several --tip-link: --level dh fits one serial chain's DH table (Franaszek & Marvel 2022) "
                          "and a tree of several chains has none; use --level auto, registration, offsets or full")
    if tool_pose is not None:
        raise PincalError("several --tip-link: --tool is not yet supported; leave it out: each target's points are "
                          "estimated in its tip link")


def calibrate_tree_files(urdf: str | Path, data_path: str | Path | Sequence[str | Path], out_urdf: str | Path,
                         report_path: str | Path, targets: Sequence[TargetSpec], settings: CalibrateSettings,
                         progress: Progress | None = None, html: str | Path | None = None) -> TreeCalibrationRun:
    """Calibrate every one of ``targets`` (:func:`pincal.model.tree.parse_targets` of the ``--tip-link``
    values) on ``data_path`` in one fit, as ``settings`` say (its ``tip_link`` is not read); write the
    corrected URDF (every calibrated chain's joint origins, checked by reloading it) and the report, and with
    ``html`` the report's page (each target's errors before and after: :mod:`pincal.report.tree_html`).

    An empty cell of a point is that point not seen in the row (occlusion): only it is left out.
    """
    refuse_tree_level(settings.level, settings.tool_pose)
    urdf, data_paths = Path(urdf), input_paths(data_path)
    out_urdf, report_path = Path(out_urdf), Path(report_path)
    inputs = [*description_inputs(urdf, settings.xacro_args), *data_paths]
    refuse_overwrite(out_urdf, *inputs)
    refuse_overwrite(report_path, *inputs, outputs=[out_urdf])
    refuse_overwrite(effects_path(out_urdf), *inputs, outputs=[out_urdf, report_path])
    page_path = refuse_page(html, inputs, [out_urdf, report_path, effects_path(out_urdf)])
    tree = KinematicTree.from_urdf(urdf, targets, xacro_args=settings.xacro_args)
    couplings = follow_couplings(tree, settings.couplings, data_paths)  # a joint without a column follows (M1)
    data, notes = read_sessions(data_paths, tree.joint_specs, couplings, tree.other_branch_joints, occlusion=True)
    options = ChainFitOptions(sigma_column=settings.sigma_column, selection=settings.criterion,
                              reject_outliers=settings.reject_outliers)
    start = time.perf_counter()
    stages = Stages(progress)
    choice, level = tree_level(tree, data, settings.level, options, stages)
    result = calibrate_tree(tree, data, level, options, stages.next())
    seconds = time.perf_counter() - start
    # the errors before: the nominal model registered to the rows of the fit (outliers removed, if they were)
    nominal = calibrate_tree(tree, data.select(result.used_index), "registration",
                             ChainFitOptions(sigma_column=settings.sigma_column))
    chosen = ", chosen by --level auto" if choice is not None else ""
    comment = (f"Calibrated by pincal {__version__} (level {level}{chosen}, {len(tree.targets)} targets) from "
               f"{urdf.name} and {', '.join(p.name for p in data_paths)}. Registration and targets: see the report.")
    reach, findings = tree_findings(tree, result, data.q, settings.sigma_pos_m)
    warnings, withheld = withholding(findings, settings.force)
    reload_error, digest = write_tree_urdf(urdf, out_urdf, tree, result.tree_placements,
                                           (comment, settings.xacro_args), data.q, keep=not withheld)
    sources: Sources = {"urdf": str(urdf),
                        "data": str(data_paths[0]) if len(data_paths) == 1 else [str(p) for p in data_paths],
                        "corrected_urdf": str(out_urdf)}
    command = diagnose_command(urdf, data_paths, settings, out_urdf, report_path,
                               [f"{t.link}:{','.join(map(str, t.spec.points))}" for t in tree.targets])
    notes = notes + list(result.notes) + unmodelled_notes(result, reach, settings.sigma_pos_m, command)
    held = int(np.sum(data.roles == "validation"))
    if held:  # not in the fit, and not judged here: evaluate gives their errors per target
        notes.append(f"{held} row(s) with role 'validation' are not in the fit; pincal evaluate {out_urdf} "
                     f"{report_path} with their file gives each target's errors on them")
    if withheld:
        sources["corrected_urdf_withheld"] = True  # the path names no file of this run
        notes += withhold(out_urdf)
    report = tree_report(result, nominal, tree, sources, notes,
                         (digest, dict(xacro_arguments(settings.xacro_args))), couplings, choice)
    report["warnings"] = findings_json(warnings)
    page = render_page(page_path, report, report_path)
    # the couplings, which a URDF cannot carry, beside the URDF (none beside a withheld one)
    effects_file = None if withheld else write_effects_file(out_urdf, report_path, report)
    write_report(report_path, report)
    return TreeCalibrationRun(result, nominal, report, notes, seconds, reload_error, withheld,
                              write_page(page_path, page), choice, effects_file)


def tree_level(tree: KinematicTree, data: MeasurementSet, level: str, options: ChainFitOptions, stages: Stages
               ) -> tuple[LevelChoice | None, ChainLevel]:
    """The level a tree is calibrated at: ``level`` as given, or with ``auto`` the one cross-validation chooses
    (:func:`pincal.fit.tree_level_choice.choose_tree_level`, its fits counted on the first of ``stages``) and how."""
    if level != "auto":
        return None, cast(ChainLevel, level)  # registration, offsets or full: the settings checked it, dh refused
    from pincal.fit.tree_level_choice import choose_tree_level

    choice = choose_tree_level(tree, data, options, progress=stages.next())
    return choice, choice.chosen


def tree_findings(tree: KinematicTree, result: TreeCalibration, q: np.ndarray, sigma_pos_m: float | None,
                  diagnosed: bool = False) -> tuple[float, list[Finding]]:
    """The reach of the farthest tip link at joint readings ``q`` [m] and the plausibility findings of one chain
    on ``result`` (:func:`pincal.fit.plausibility.fit_findings`): its RMS distance of every seen point from the
    model against the reach (a gross misfit) and the stated noise ``sigma_pos_m`` [m], each target's points
    against the reach, each registration, the corrections (``diagnosed``: the model with diagnose's effects)."""
    reach = max(reach_m(t.chain, q[:, t.columns]) for t in tree.targets)
    points = [(t.link, float(np.max(np.linalg.norm(result.target.points[np.array(t.spec.points) - 1], axis=1))))
              for t in tree.targets]
    return reach, fit_findings(result, reach, points, len(result.used_index), sigma_pos_m, None, diagnosed)


class _Withheld(Exception):
    """Raised by a withheld URDF's check once it passed: cancels the write (as pincal.workflows.verdict's)."""


def write_tree_urdf(urdf: Path, out: Path, tree: KinematicTree, tree_placements: TreePlacements,
                    text: tuple[str, Sequence[tuple[str, str]]], q: np.ndarray, keep: bool = True) -> tuple[float, str]:
    """Write ``urdf`` with every target chain's joint origins at ``tree_placements`` (the calibrated model; a
    joint shared by several chains has the same placement in each) and return the reload check's largest
    difference and the file's SHA-256;
    ``keep`` False: checked and hashed but not put in place (a withheld URDF, ``out`` left as it was).

    Raises:
        CalibrationError: reloading the written file moves a target's tool beyond :data:`RELOAD_TOLERANCE`
            (the file is then not put in place).
    """
    comment, xacro_args = text
    nominal = tree.placements()
    origins: dict[str, np.ndarray] = {}
    with tree.placed(tree_placements):
        for target, placements in zip(tree.targets, nominal):
            origins.update(corrected_origins(urdf, target.chain, placements, xacro_args))
        calibrated = [t.chain.tool_poses(q[:, t.columns]) for t in tree.targets]
    checked: list[float] = []
    digest: list[str] = []

    def verify(written: Path) -> None:
        reloaded = KinematicTree.from_urdf(written, [t.spec for t in tree.targets])
        errors = [max(np.abs(a[0] - b[0]).max(), np.abs(a[1] - b[1]).max()) for a, b in
                  zip(calibrated, (t.chain.tool_poses(q[:, t.columns]) for t in reloaded.targets))]
        checked.append(float(max(errors)))
        if checked[-1] > RELOAD_TOLERANCE:
            raise CalibrationError(f"{out}: reloading the written URDF moves a target by {checked[-1]:.3g} "
                                   f"(> {RELOAD_TOLERANCE:g}); not written; please report this as a bug")
        digest.append(file_sha256(written))
        if not keep:
            raise _Withheld

    try:
        write_urdf_with_origins(urdf, out, origins, comment=comment, verify=verify, xacro_args=xacro_args)
    except _Withheld:
        pass
    return checked[-1], digest[-1]

