"""``pincal calibrate --fixture`` and ``pincal evaluate --fixture``'s jobs: socket-fixture data, no sensor.

calibrate: the data files (:mod:`pincal.measurements.fixture`) and the
fixture file → :func:`pincal.fit.fixture_calibration.calibrate_fixture` → the
corrected URDF (the writer and reload check of every calibration) and
REPORT.json (:mod:`pincal.report.fixture`). evaluate: the consistency and
distortion (:mod:`pincal.fit.socket_metrics`) of the corrected URDF with the
reported ball centre on placements the fit has not seen — no registration,
nothing re-estimated — and of the nominal URDF with the ball centre fitted to
it ("before"), when that URDF is at hand. Both judge placements the model has
not seen against the nominal model (:mod:`pincal.fit.placement_check`: calibrate
leaves each out in turn, evaluate takes the evaluated ones), their warnings in
REPORT.json / ``--json`` ``warnings`` for ``--strict``; evaluate writes its ``--json`` and ``--html`` as the
sensor path does (:mod:`pincal.workflows.evaluation_outputs`). What the commands print, calibrate's ``--html``
page and the refusal of a sensor's flags: :mod:`pincal.cli.fixture`.
"""


from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, cast

import numpy as np

from pincal._version import __version__
from pincal.errors import PincalError
from pincal.fit.fixture_calibration import FixtureCalibration, calibrate_fixture
from pincal.fit.level_choice import choose_fixture_level, fixture_heldout_error
from pincal.fit.placement_check import (
    PlacementCheck,
    PlacementPrediction,
    check_placements,
    evaluation_findings,
    one_placement_note,
    placement_findings,
    predictions,
)
from pincal.fit.plausibility import Finding, gross_misfit, reach_m
from pincal.fit.socket_metrics import FixtureMetrics, fixture_metrics
from pincal.measurements.couplings import corrected_angles, couplings_from_report
from pincal.measurements.fixture import Fixture, read_fixture, read_fixture_data
from pincal.model.chain import KinematicChain
from pincal.model.description import is_xacro, xacro_arguments
from pincal.model.parameter_sets import ChainLevel
from pincal.outputs import file_sha256
from pincal.report.document import write_report
from pincal.report.effects_file import effects_path, write_effects_file
from pincal.report.fixture import fixture_report, read_fixture_block
from pincal.report.model import Sources, couplings_part, findings_json
from pincal.report.model_fixture import (
    FixtureEvaluationJson,
    FixtureReport,
    PlacementPredictionJson,
    fixture_metrics_json,
)
from pincal.report.model_level_choice import level_choice_part
from pincal.report.reading import load_report
from pincal.report.record import ReportRecord
from pincal.workflows.evaluation_outputs import EvaluateOutputs, write_outputs
from pincal.workflows.paths import description_inputs, refuse_overwrite
from pincal.workflows.report_page import refuse_page, render_page, write_page
from pincal.workflows.settings import CalibrateSettings, expect
from pincal.workflows.verdict import UrdfWrite, withhold, withholding, write_checked_urdf

__all__ = ["SAME_FIXTURE_M", "FixtureRun", "calibrate_fixture_files", "FixtureEvaluation", "evaluate_fixture_files",
           "fixture_paths"]

#: Largest difference between a socket distance of the evaluated fixture file and the
#: calibration's [m]: far below any fixture's manufacturing tolerance (~1e-5 m for a
#: 3D print), far above the rounding of distances rebuilt by classical scaling (~1e-16 m).
SAME_FIXTURE_M = 1e-9


def fixture_paths(data: str | Path | Sequence[str | Path]) -> list[Path]:
    paths = data if isinstance(data, (list, tuple)) else [cast(str | Path, data)]
    return [Path(p) for p in paths]


@dataclass(frozen=True)
class FixtureRun:
    """Outcome of :func:`calibrate_fixture_files`."""

    result: FixtureCalibration
    report: FixtureReport
    seconds: float
    reload_error: float
    effects_file: Path | None = None
    check: PlacementCheck | None = None
    withheld: bool = False
    html: Path | None = None  # the report's page written (--html), or None


def calibrate_fixture_files(
    urdf: str | Path,
    data_paths: Sequence[str | Path],
    fixture_path: str | Path,
    out_urdf: str | Path,
    report_path: str | Path,
    settings: CalibrateSettings,
    html: str | Path | None = None,
) -> FixtureRun:
    """Calibrate ``urdf`` on socket-fixture data as ``settings`` say (its tip link carries the
    ball; level, selection, xacro arguments and ``--coupling``, eq C1 on the joint readings as for sensor
    data; nothing of a sensor); write the corrected URDF, the report and, with couplings, the
    effects.yaml beside the URDF (:mod:`pincal.report.effects_file`). Level ``auto``: the level
    cross-validation over the placements supports
    (:func:`pincal.fit.level_choice.choose_fixture_level`; REPORT.json ``level_choice``). Each placement
    left out in turn is predicted by the level's calibration of the others against the nominal model
    (:func:`pincal.fit.placement_check.check_placements`; REPORT.json ``fixture.held_out_placements`` and
    ``warnings``); one placement gets a note instead. A calibrated model that misses the sockets grossly
    (:func:`pincal.fit.plausibility.gross_misfit`) is no correction of the robot: its URDF and effects.yaml
    are withheld, as on the sensor path (:mod:`pincal.workflows.verdict`), unless ``settings.force``.

    Raises:
        PincalError: settings of a sensor (a tool, method, row weights, outlier rejection, a
            stated noise) or level ``dh``.
    """
    expect(settings, CalibrateSettings, "calibrate_fixture_files")
    sensor = [name for name, value in (("tool_pose", settings.tool_pose), ("method", settings.method),
                                       ("sigma_column", settings.sigma_column),
                                       ("sigma_pos_mm", settings.sigma_pos_mm)) if value is not None]
    sensor += ["reject_outliers"] if settings.reject_outliers else []
    if sensor or settings.level == "dh":
        raise PincalError(f"socket-fixture data have no sensor: {', '.join(sensor) or 'level dh'} do(es) not apply")
    tip_link, selection, xacro_args = settings.tip_link, settings.criterion, settings.xacro_args
    level: str = settings.level  # "auto" becomes the level cross-validation chooses

    urdf, fixture_path, out_urdf, report_path = Path(urdf), Path(fixture_path), Path(out_urdf), Path(report_path)
    data_paths = fixture_paths(data_paths)
    inputs = [*description_inputs(urdf, xacro_args), fixture_path, *data_paths]  # a xacro's includes too
    refuse_overwrite(out_urdf, *inputs)
    refuse_overwrite(report_path, *inputs, outputs=[out_urdf])
    refuse_overwrite(effects_path(out_urdf), *inputs, outputs=[out_urdf, report_path])
    html = refuse_page(html, inputs, [out_urdf, report_path, effects_path(out_urdf)])  # --html: the report's page
    chain = KinematicChain.from_urdf(urdf, tip_link, xacro_args=xacro_args or None)
    fixture = read_fixture(fixture_path)
    data = read_fixture_data(data_paths, chain.joint_specs, fixture)
    data = replace(data, q=corrected_angles(data.q, settings.couplings, data.joint_names))  # eq C1, as sensor data
    nominal_placements = chain.placements()
    started = time.perf_counter()
    choice = None
    if level == "auto":  # leave-one-placement-out (or folds of rows) on the calibration data
        choice = choose_fixture_level(chain, data, selection=selection)
        level = choice.chosen
    chain_level = cast(ChainLevel, level)  # registration, offsets or full: dh is refused above, auto chose one
    result = calibrate_fixture(chain, data, chain_level, selection=selection)
    # each placement predicted by the level's fit of the others, against the nominal model's (plausibility)
    check = check_placements(chain, data, chain_level, selection, choice)
    warnings, notes = placement_findings(check)
    notes += [note for note in [one_placement_note(data)] if note is not None]
    # eq F1's residual per coordinate, as a point distance: the sensor path's RMS point residual
    gross = gross_misfit(result.rms_m * np.sqrt(3.0), reach_m(chain, data.q))
    warnings, withheld = withholding(([] if gross is None else [gross]) + warnings, settings.force)
    seconds = time.perf_counter() - started
    sources: Sources = {"urdf": str(urdf), "data": [str(p) for p in data_paths], "fixture": str(fixture_path),
                        "corrected_urdf": str(out_urdf)}
    if withheld:
        sources["corrected_urdf_withheld"] = True  # the path names no file of this run
    names = ", ".join(p.name for p in data_paths)
    comment = (f"Calibrated by pincal {__version__} (socket fixture, level {level}) from {urdf.name}, {names} and "
               f"{fixture_path.name}. Ball centre and placements: see the report.")
    reload_error, urdf_sha256 = write_checked_urdf(UrdfWrite(urdf, out_urdf, comment, xacro_args, keep=not withheld),
                                                   chain, result.chain_placements, nominal_placements, data.q)
    if withheld:
        notes += withhold(out_urdf)
    with chain.placed(result.chain_placements):
        record = ReportRecord(urdf_sha256, dict(xacro_arguments(xacro_args)),  # evaluate --fixture rebuilds with them
                              warnings=findings_json(warnings), level_choice=level_choice_part(choice),
                              couplings=couplings_part(settings.couplings))
        report = fixture_report(result, chain, data, sources, notes, file_sha256(urdf), record=record, held_out=check)
    page = render_page(html, report, report_path)  # made before the report is written
    # the couplings, which a URDF cannot carry (none beside a withheld URDF)
    effects_file = None if withheld else write_effects_file(out_urdf, report_path, report)
    write_report(report_path, report)
    return FixtureRun(result, report, seconds, reload_error, effects_file, check, withheld, write_page(html, page))


@dataclass(frozen=True)
class FixtureEvaluation:
    """Outcome of :func:`evaluate_fixture_files`: after (corrected URDF) and before (nominal, if at hand).

    Attributes:
        not_held_out: evaluated placements the calibration also used (their errors are not held out).
    """

    after: FixtureMetrics
    before: FixtureMetrics | None
    notes: list[str]
    not_held_out: tuple[str, ...] = ()
    held_out: tuple[PlacementPrediction, ...] = ()
    warnings: tuple[Finding, ...] = ()
    written: tuple[Path, ...] = ()  # the outputs written (--json first, then --html)

    def as_dict(self) -> FixtureEvaluationJson:
        """``pincal evaluate --fixture --json``."""
        return {"after": fixture_metrics_json(self.after),
                "before": None if self.before is None else fixture_metrics_json(self.before),
                "not_held_out": list(self.not_held_out), "notes": list(self.notes),
                "held_out_placements": [cast(PlacementPredictionJson, p.as_dict()) for p in self.held_out],
                "warnings": findings_json(list(self.warnings))}


def _reported_nominal(document: dict[str, Any], report_path: Path,
                      sha: str | None) -> tuple[Path | None, list[Path], str]:
    """The report's ``sources.urdf`` as written, else beside the report: the file with the recorded SHA-256.

    ``sources.urdf`` is the path calibrate was given, relative to where it ran; so it
    is looked for there (the current folder), then relative to the report's folder,
    then by name in the report's folder. Returns the match (or None), every
    candidate that exists (inputs all) and, for a None, why.
    """
    text = str((document.get("sources") or {}).get("urdf") or "")
    if not text:
        return None, [], "the report names no nominal URDF (sources.urdf)"
    given = Path(text)
    tried = list(dict.fromkeys([given] if given.is_absolute() else
                               [given, report_path.parent / given, report_path.parent / given.name]))
    existing = [p for p in tried if p.is_file()]
    match = next((p for p in existing if file_sha256(p) == sha), None)
    if existing:
        why = (f"the nominal URDF {existing[0]} (the report's sources.urdf) was changed since the calibration "
               "(its SHA-256 differs)")
    else:
        why = f"the nominal URDF {text} (the report's sources.urdf) is not at {' nor '.join(map(str, tried))}"
    return match, existing, why


def _check_same_fixture(fixture: Fixture, document: dict[str, Any], fixture_path: Path, report_path: Path) -> None:
    """Refuse a fixture file whose sockets or socket distances differ from the calibration's (REPORT.json)."""
    block = document["fixture"]
    if "sockets" not in block or "distances_mm" not in block:
        return
    recorded = [str(s["name"]) for s in block["sockets"]]
    if sorted(recorded) != sorted(fixture.names):
        raise PincalError(f"{fixture_path}: sockets {', '.join(fixture.names)}, but the calibration's fixture "
                          f"({report_path}) has {', '.join(recorded)}; evaluate with the fixture file the "
                          "calibration used")
    index = {name: i for i, name in enumerate(fixture.names)}
    for pair in block["distances_mm"]:
        mm = fixture.distance(index[str(pair["a"])], index[str(pair["b"])]) * 1000.0
        if abs(mm - float(pair["mm"])) > SAME_FIXTURE_M * 1000.0:
            raise PincalError(f"{fixture_path}: sockets {pair['a']} and {pair['b']} are {mm:.6f} mm apart, in the "
                              f"calibration's fixture ({report_path}) {float(pair['mm']):.6f} mm; evaluate with the "
                              f"fixture file the calibration used (tolerance {SAME_FIXTURE_M:g} m)")


def evaluate_fixture_files(
    urdf: str | Path,
    report_path: str | Path,
    data_paths: Sequence[str | Path],
    fixture_path: str | Path,
    nominal_urdf: str | Path | None = None,
    allow_other_urdf: bool = False,
    xacro_args: Sequence[tuple[str, str]] = (),
    outputs: EvaluateOutputs | None = None,
) -> FixtureEvaluation:
    """Consistency and distortion of a fixture calibration on socket-fixture data.

    The "before" uses ``nominal_urdf`` or, when not given, the report's
    ``sources.urdf`` (found as :func:`_reported_nominal` says) if that file is
    still the one calibrated (same SHA-256); otherwise it is left out with a note.
    The fixture file must have the calibration's sockets and distances (to
    :data:`SAME_FIXTURE_M`). ``xacro_args`` apply to whichever URDF is a ``.xacro``
    (the nominal found through the report gets the report's ``xacro_args``).
    ``outputs``: ``--json`` (:meth:`FixtureEvaluation.as_dict`) and ``--html`` (the report's page with the
    evaluation beside it), written whole once the evaluation is done
    (:func:`pincal.workflows.evaluation_outputs.write_outputs`); each is checked first against every input
    (the URDFs, what a xacro includes, the report, the fixture and data files) and the other.
    """
    urdf, report_path, fixture_path = Path(urdf), Path(report_path), Path(fixture_path)
    data_paths = fixture_paths(data_paths)
    document = cast(dict[str, Any], load_report(report_path, ("fixture",),
                                                hint="pass the REPORT.json written by 'pincal calibrate --fixture'"))
    tip, ball, nominal_ball, nominal_sha = read_fixture_block(document, report_path)
    notes: list[str] = []
    recorded = document.get("urdf_sha256")
    if recorded is not None and file_sha256(urdf) != recorded:
        if not allow_other_urdf:
            raise PincalError(
                f"{urdf}: not the URDF {report_path} was written with (its SHA-256 differs from the report's "
                "urdf_sha256); evaluate the pair calibrate wrote, or pass --allow-other-urdf if you changed it "
                "on purpose")
        notes.append(f"{urdf}: not the URDF {report_path} was written with (--allow-other-urdf)")
    candidates: list[Path] = []
    why: str | None = None  # why there is no nominal URDF to compare with
    if nominal_urdf is not None:
        nominal: Path | None = Path(nominal_urdf)
        nominal_args = tuple(xacro_args)
    else:
        nominal, candidates, missing = _reported_nominal(document, report_path, nominal_sha)
        nominal_args = tuple(xacro_args) or tuple((document.get("xacro_args") or {}).items())
        if nominal is None:
            why = missing
            notes.append(f"no 'before': {why}; pass --nominal URDF")
    if xacro_args and not (is_xacro(urdf) or (nominal is not None and is_xacro(nominal))):
        raise PincalError("--xacro-arg applies to a .xacro URDF, and neither the evaluated nor the nominal URDF "
                          "is one; drop --xacro-arg")

    def args_of(path: Path) -> tuple[tuple[str, str], ...]:
        return (nominal_args if path == nominal else tuple(xacro_args)) if is_xacro(path) else ()

    inputs = [*description_inputs(urdf, args_of(urdf)), report_path, fixture_path, *data_paths, *candidates]
    if nominal is not None:
        inputs += description_inputs(nominal, args_of(nominal))
    outputs = EvaluateOutputs() if outputs is None else outputs
    written = [o for o in (outputs.json, outputs.html) if o is not None]
    for n, output in enumerate(written):
        refuse_overwrite(output, *inputs, outputs=[o for m, o in enumerate(written) if m != n])
    fixture = read_fixture(fixture_path)
    _check_same_fixture(fixture, document, fixture_path, report_path)
    chain = KinematicChain.from_urdf(urdf, tip, xacro_args=args_of(urdf) or None)
    data = read_fixture_data(data_paths, chain.joint_specs, fixture)
    couplings = couplings_from_report(document.get("couplings"), str(report_path))
    if couplings:  # the readings corrected as the calibration's were (eq C1)
        data = replace(data, q=corrected_angles(data.q, couplings, data.joint_names))
        notes.append(f"{', '.join(map(str, data_paths))}: readings corrected as {report_path} says (couplings: "
                     f"{', '.join(c.label for c in couplings)})")
    trained = {str(p.get("name")) for p in document["fixture"].get("placements") or []}
    seen = tuple(name for name in data.placements if name in trained)
    if seen:
        notes.append(f"not held out: placement(s) {', '.join(seen)} of the calibration's ({report_path}); "
                     "their errors are not those of new placements")
    after = fixture_metrics(chain, data, ball)
    predicted, before = fixture_heldout_error(chain, data, ball), None
    nominal_error = np.full(len(data.placements), np.nan)
    if nominal is not None:
        if file_sha256(nominal) != nominal_sha:
            notes.append(f"{nominal}: not the URDF the calibration started from (SHA-256 differs)")
        nominal_chain = KinematicChain.from_urdf(nominal, tip, xacro_args=args_of(nominal) or None)
        before = fixture_metrics(nominal_chain, data, nominal_ball)
        nominal_error = fixture_heldout_error(nominal_chain, data, nominal_ball)
    held_out = tuple(p for p in predictions(data, predicted, nominal_error) if p.placement not in seen)
    evaluation = FixtureEvaluation(after, before, notes, seen, held_out, tuple(evaluation_findings(held_out, why)))
    metrics = evaluation.as_dict()  # --json
    shown = {"urdf": str(urdf), "data": ", ".join(str(p) for p in data_paths), "fixture": metrics,
             "warnings": metrics["warnings"]}  # the evaluation beside the report on the page
    return replace(evaluation, written=write_outputs(outputs, metrics, report_path, shown))
