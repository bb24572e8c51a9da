"""REPORT.json of ``diagnose --camera-link`` (:class:`pincal.report.model_camera.CameraReport` with ``effects`` and
``diagnosis``): the camera calibration's report of the final model, the effects and the search, each step's
reprojection RMS before and after on the calibration and held-out images."""

from __future__ import annotations

import numpy as np

from pincal.diagnosis.camera_diagnose import CameraDiagnosis
from pincal.diagnosis.verdicts import CRITERION
from pincal.report.diagnosis import effect_entries
from pincal.report.model_camera import CameraDiagnosisJson, CameraReport, RmsPair
from pincal.report.tree_diagnosis import candidate_entries

__all__ = ["with_camera_diagnosis"]


def _rms(errors: np.ndarray) -> float:
    """RMS per coordinate [px] of corner distances (K, P) [px], NaN where not seen."""
    return float(np.sqrt(np.nanmean(errors**2) / 2.0))


def _pair(before: np.ndarray | None, after: np.ndarray | None) -> RmsPair | None:
    return None if before is None or after is None else {"before_px": _rms(before), "after_px": _rms(after)}


def with_camera_diagnosis(report: CameraReport, diagnosis: CameraDiagnosis) -> CameraReport:
    """``report`` (:func:`pincal.report.camera.camera_report` of the final model) with the effects and the search of
    ``diagnosis``."""
    kinds = dict(zip(report["chain"]["joints"], report["chain"]["joint_kinds"]))
    inputs = diagnosis.inputs
    held = None
    if diagnosis.heldout_before_px is not None and diagnosis.heldout_after_px is not None:
        held = RmsPair(before_px=diagnosis.heldout_before_px, after_px=diagnosis.heldout_after_px)
    section: CameraDiagnosisJson = {
        "criterion": CRITERION,
        "masses": "unknown" if diagnosis.masses_unknown else "urdf",
        "steps": [{
            "effect": effect_entries([(step.effect, step.values, step.std)], inputs, kinds, {})[0],
            "delta_bic": step.delta_bic,
            "calibration": {"before_px": _rms(step.calibration_before), "after_px": _rms(step.calibration_after)},
            "heldout": _pair(step.heldout_before, step.heldout_after),
            "candidates": candidate_entries(step.candidates, inputs, kinds),
        } for step in diagnosis.steps],
        "last_candidates": candidate_entries(diagnosis.last_candidates, inputs, kinds),
        "untestable": [e.label for e in diagnosis.untestable],
        "heldout": held,
    }
    return {**report, "effects": effect_entries(diagnosis.effects, inputs, kinds, {}), "diagnosis": section}
