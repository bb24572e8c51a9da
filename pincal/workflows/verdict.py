"""What calibrate and diagnose do with their plausibility findings: the run's warnings and notes, whether
its corrected URDF is written, and the ``pincal diagnose`` command a note points to.

A model that misses its rows grossly (:func:`pincal.fit.plausibility.gross_misfit`: beyond what any
physical effect of a robot that size produces) is no correction of the robot. Its corrected URDF and
effects.yaml are withheld unless ``--force``: REPORT.json (with the ``gross_misfit`` warning), the HTML
and diagnose's plots are written, and the command exits 3. A URDF an earlier run left at the ``--out``
path is removed (and that run's effects.yaml beside it): a script that checks the exit code stops, and
one that checks the file finds none, rather than an older model passing for this run's; the path was
given for this run's URDF, which a run with a plausible model would have replaced anyway, and the
report and console say what was removed. The withheld URDF still passes its reload check, and the
report's ``urdf_sha256`` is of its bytes (those ``--force`` writes): ``evaluate`` refuses any other
file with this report.

A model that misses moderately, or whose estimated noise is over 3× the stated
(:func:`pincal.fit.plausibility.unmodelled_reason`), gets a note naming the ``pincal diagnose``
command to run: calibrate's URDF, data and flags, with outputs beside calibrate's (:func:`diagnose_command`).
"""

from __future__ import annotations

import shlex
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from pincal.errors import CalibrationError
from pincal.fit.plausibility import (
    UNMODELLED_CAUSES,
    Finding,
    Fitted,
    tip_link_findings,
    tip_link_verdict,
    unmodelled_reason,
)
from pincal.fit.prior import Prior
from pincal.measurements.csv_v1 import file_columns
from pincal.model.chain import KinematicChain, xyz_rpy_from_pose
from pincal.model.corrected_urdf import write_corrected_urdf
from pincal.model.urdf import write_urdf_with_origins
from pincal.outputs import file_sha256
from pincal.report.effects_file import remove_effects_file
from pincal.report.model import Finding as FindingJson
from pincal.report.model import findings_json
from pincal.workflows.settings import CalibrateSettings, default_selection

__all__ = ["RELOAD_TOLERANCE", "GROSS_CODE", "Verdict", "judged", "withholding", "withhold", "urdf_line",
           "UrdfWrite", "write_checked_urdf", "write_urdf_checked_by", "unmodelled_notes", "diagnose_command"]

#: Reloading a written URDF must reproduce the calibrated TCP to this [m, rad].
RELOAD_TOLERANCE = 1e-9
#: The warning whose model is no correction of the robot (:func:`pincal.fit.plausibility.gross_misfit`).
GROSS_CODE = "gross_misfit"


@dataclass(frozen=True)
class Verdict:
    """A run's plausibility, as it acts on the outputs.

    Attributes:
        warnings: REPORT.json ``warnings`` (the ``gross_misfit`` one saying what became of the URDF).
        notes: notes for the console and REPORT.json ``notes`` (tip-link findings that are no warning).
        withheld: the corrected URDF and effects.yaml are not written (a gross misfit, no ``--force``).
    """

    warnings: list[FindingJson]
    notes: list[str]
    withheld: bool


def judged(chain: KinematicChain, data_paths: Sequence[str | Path], findings: list[Finding], force: bool) -> Verdict:
    """The verdict on a calibration of the files ``data_paths``: its plausibility ``findings``, the
    tip-link check of each file (:func:`pincal.fit.plausibility.tip_link_verdict`), and whether a gross
    misfit withholds the corrected URDF (not with ``force``)."""
    warned, notes = tip_link_verdict(tip_link_findings(chain, file_columns(data_paths, chain.joint_names)), findings)
    warned, withheld = withholding(warned, force)
    return Verdict(findings_json(warned), notes, withheld)


def withholding(findings: list[Finding], force: bool) -> tuple[list[Finding], bool]:
    """The ``findings`` with the ``gross_misfit`` one saying what becomes of the corrected URDF, and
    whether it is withheld (a gross misfit without ``force``)."""
    withheld = not force and any(f.code == GROSS_CODE for f in findings)
    said = ("the corrected URDF is not written (nor its effects.yaml; the report is): give --force to write them "
            "all the same" if withheld else "the corrected URDF is written all the same (--force)")
    return [replace(f, message=f"{f.message}; {said}") if f.code == GROSS_CODE else f for f in findings], withheld


def withhold(out_urdf: Path) -> list[str]:
    """Remove what an earlier run left at a withheld URDF's path ``out_urdf`` — the file there and the
    effects.yaml pincal wrote beside it — so that neither passes for this run's output; the notes saying so."""
    removed = []
    if out_urdf.is_file() or out_urdf.is_symlink():
        out_urdf.unlink()
        removed.append(str(out_urdf))
    effects = remove_effects_file(out_urdf)
    if effects is not None:
        removed.append(str(effects))
    return [f"removed {' and '.join(removed)}, left by an earlier run, so that no file there passes for this run's "
            "output (the corrected URDF is withheld: see the warning)"] if removed else []


def urdf_line(out: Path, withheld: bool, reload_error: float | None = None) -> str:
    """The console's line on the corrected URDF ``out``: written (with its reload check), or withheld."""
    if withheld:
        return f"not written: {out} (the model misses its rows grossly: see the warning; --force writes it)"
    return f"wrote {out}" + ("" if reload_error is None else f" (reload check: TCP reproduced to {reload_error:.1e} m)")


class _Withheld(Exception):
    """Raised by a withheld URDF's check once it passed: cancels the write (:func:`pincal.outputs.replacing`)."""


@dataclass(frozen=True)
class UrdfWrite:
    """A corrected URDF to write: from ``source`` (the URDF or ``.xacro`` calibrated, expanded with
    ``xacro_args``) to ``destination``, with ``comment`` at its top; ``keep`` False: checked and hashed but
    not put in place (a withheld URDF; ``destination`` is left as it was)."""

    source: Path
    destination: Path
    comment: str
    xacro_args: Sequence[tuple[str, str]] = ()
    keep: bool = True


def write_checked_urdf(
    write: UrdfWrite, chain: KinematicChain, placements: Sequence[np.ndarray],
    nominal_placements: Sequence[np.ndarray], q: np.ndarray,
) -> tuple[float, str]:
    """Write the URDF of ``chain`` with ``placements`` (a calibration's ``chain_placements``) as ``write``
    says, checking before it replaces ``write.destination`` that reloading it reproduces that model's tool
    poses at ``q`` to :data:`RELOAD_TOLERANCE` (a failed check leaves the old file). The chain is left as
    it was.

    Returns:
        The largest difference [m, -] and the SHA-256 (hex) of the bytes written
        (the report's ``urdf_sha256``).
    """
    destination, keep = write.destination, write.keep
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
        if not keep:
            raise _Withheld

    with chain.placed(placements):
        try:
            write_corrected_urdf(write.source, destination, chain, nominal_placements, comment=write.comment,
                                 verify=verify, xacro_args=write.xacro_args)
        except _Withheld:
            pass
    return checked[-1], digest[-1]


def write_urdf_checked_by(write: UrdfWrite, origins: Mapping[str, np.ndarray],
                          difference: Callable[[Path], float], what: str) -> tuple[float, str]:
    """Write ``write.source`` with the joint ``origins`` as ``write`` says, checking before it replaces
    ``write.destination`` that ``difference(written file)`` -- the reloaded model against the calibrated one
    [m, -] -- is within :data:`RELOAD_TOLERANCE` (``what`` moved, the message says otherwise). Returns that
    difference and the SHA-256 of the bytes written (the report's ``urdf_sha256``)."""
    checked: list[float] = []
    digest: list[str] = []

    def verify(written: Path) -> None:
        checked.append(float(difference(written)))
        if checked[-1] > RELOAD_TOLERANCE:
            raise CalibrationError(f"{write.destination}: reloading the written URDF moves {what} by {checked[-1]:.3g} "
                                   f"(> {RELOAD_TOLERANCE:g}); not written; please report this as a bug")
        digest.append(file_sha256(written))
        if not write.keep:
            raise _Withheld

    try:
        write_urdf_with_origins(write.source, write.destination, origins, comment=write.comment, verify=verify,
                                xacro_args=write.xacro_args or None)
    except _Withheld:
        pass
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


def unmodelled_notes(result: Fitted, reach_m: float, stated_sigma_pos_m: float | None,
                     command: str | None = None) -> list[str]:
    """The note on a model ``result`` (of a robot of ``reach_m`` [m]) that likely lacks an effect
    (:func:`pincal.fit.plausibility.unmodelled_reason`), or none: with the ``pincal diagnose`` ``command``
    to run (calibrate's), else (diagnose's final model) that the effects diagnose tries do not explain it."""
    reason = unmodelled_reason(result, reach_m, stated_sigma_pos_m)
    if reason is None:
        return []
    if command is None:
        return [f"{reason}: the model with its effects leaves something unmodelled that the effects pincal diagnose "
                "tries do not explain"]
    return [f"{reason}: the geometry leaves something unmodelled ({UNMODELLED_CAUSES}); to look for it: {command}"]


def diagnose_command(urdf: Path, data_paths: Sequence[Path], settings: CalibrateSettings, out_urdf: Path,
                     report_path: Path, tip_links: Sequence[str] = ()) -> str:
    """The ``pincal diagnose`` command line (POSIX shell quoting) of the calibration ``settings`` of
    ``urdf`` on ``data_paths``: the same level, tool, noise column, selection, stated noise, couplings and
    xacro arguments (diagnose rejects no outliers: ``--reject-outliers`` has no counterpart), writing
    ``STEM_diagnosed.urdf`` beside ``out_urdf`` and ``STEM_diagnose.json`` beside ``report_path``;
    ``tip_links``: several targets' ``LINK:POINTS`` (default: the settings' one tip link)."""
    words = ["pincal", "diagnose", str(urdf), *map(str, data_paths)]
    for tip_link in tip_links or (settings.tip_link,):
        words += ["--tip-link", tip_link]
    words += ["--level", settings.level]
    if settings.tool_pose is not None:
        words += ["--tool", ",".join(repr(float(v)) for v in np.concatenate(xyz_rpy_from_pose(settings.tool_pose)))]
    if settings.sigma_column is not None:
        words += ["--sigma-column", settings.sigma_column]
    selection = settings.criterion
    if selection != default_selection(settings.level):
        words += ["--select", str(selection)]
        if isinstance(selection, Prior):
            words += ["--prior-scale", ",".join(repr(v) for v in selection.scales)]
    if settings.sigma_pos_mm is not None:
        words += ["--sigma-pos", repr(settings.sigma_pos_mm)]
    for coupling in settings.couplings:
        words += ["--coupling", f"{coupling.joint}={coupling.factor!r}*{coupling.driver}"]
    for name, value in settings.xacro_args:
        words += ["--xacro-arg", f"{name}:={value}"]
    words += ["--out", str(out_urdf.with_name(f"{out_urdf.stem}_diagnosed.urdf")),
              "--report", str(report_path.with_name(f"{report_path.stem}_diagnose.json"))]
    return shlex.join(words)

