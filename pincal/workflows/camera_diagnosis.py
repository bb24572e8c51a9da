"""``pincal diagnose --camera-link``'s job: a camera's DATA.csv → the camera calibration
(:func:`pincal.workflows.camera_calibration.fit_camera`), the search for the joint effects its images show
(:func:`pincal.diagnosis.camera_diagnose.diagnose_camera`), then the final model written as calibrate writes one --
the corrected URDF, its camera_info YAML -- with the effects in ``CORRECTED.effects.yaml`` and REPORT.json
(:func:`diagnose_camera_files`), whole or not at all.

Held-out images (``--validation HELD_OUT.csv``, else DATA.csv's of role ``validation``) judge each effect and give
the reprojection errors before and after; ``pincal evaluate`` of the report applies the effects.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

from pincal.model.masses import Masses
from pincal.progress import Progress
from pincal.workflows.camera_calibration import (
    CameraCalibrateSettings,
    CameraCalibrationRun,
    CameraModel,
    CameraPaths,
    fit_camera,
    write_camera_run,
)
from pincal.workflows.settings import expect

if TYPE_CHECKING:
    from pincal.diagnosis.camera_diagnose import CameraDiagnosis

__all__ = ["CameraDiagnoseSettings", "CameraDiagnoseRun", "diagnose_camera_files"]


@dataclass(frozen=True)
class CameraDiagnoseSettings:
    """``pincal diagnose --camera-link`` without its paths.

    Attributes:
        camera: the camera calibration's settings (:class:`CameraCalibrateSettings`).
        masses: ``urdf``: compliances under the URDF's gravity torques; ``unknown``: under the carried links' mass
            moments (:mod:`pincal.diagnosis.moment_candidates`).
    """

    camera: CameraCalibrateSettings
    masses: Masses = "urdf"


@dataclass(frozen=True)
class CameraDiagnoseRun:
    """Outcome of :func:`diagnose_camera_files`: the written run (the final model's: URDF, camera_info, report) and
    the search."""

    run: CameraCalibrationRun
    diagnosis: CameraDiagnosis


def diagnose_camera_files(urdf: str | Path, data: str | Path, out_urdf: str | Path, report_path: str | Path,
                          settings: CameraDiagnoseSettings, validation: str | Path | None = None,
                          progress: Progress | None = None, html: str | Path | None = None) -> CameraDiagnoseRun:
    """Calibrate ``urdf`` from a camera's ``data`` as ``settings.camera`` say, search the images for joint effects,
    and write the final model (module docstring); ``validation``: held-out images of another file; ``html``: the
    report's page to write (:mod:`pincal.workflows.report_page`, the image drawn from ``settings.camera.images``).

    Raises:
        PincalError: calibrate's one-line errors (:func:`pincal.workflows.camera_calibration.fit_camera`).
    """
    from pincal.diagnosis.camera_diagnose import diagnose_camera
    from pincal.diagnosis.diagnose import DiagnoseOptions
    from pincal.report.camera_diagnosis import with_camera_diagnosis

    expect(settings, CameraDiagnoseSettings, "diagnose_camera_files")
    paths = CameraPaths(Path(urdf), Path(data), Path(out_urdf), Path(report_path),
                        None if validation is None else Path(validation), effects=True,
                        html=None if html is None else Path(html))
    fit = fit_camera(paths, settings.camera)
    held = fit.validation if len(fit.validation.images) else None
    diagnosis = diagnose_camera(fit.setup.chain, fit.result, fit.calibration, held,
                                DiagnoseOptions(masses=settings.masses), progress)
    final = replace(fit.result, vector=diagnosis.vector, std=diagnosis.std, estimate=diagnosis.estimate,
                    chain_placements=diagnosis.chain_placements, tip_placement=diagnosis.tip_placement,
                    rms_px=diagnosis.rms_px, notes=(*fit.result.notes, *diagnosis.notes))
    model = CameraModel(final, tuple((effect, values) for effect, values, _ in diagnosis.effects),
                        lambda report: with_camera_diagnosis(report, diagnosis))
    return CameraDiagnoseRun(write_camera_run(paths, settings.camera, fit, model), diagnosis)
