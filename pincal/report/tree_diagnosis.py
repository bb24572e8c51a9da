"""REPORT.json of ``diagnose`` with several ``--tip-link LINK:POINTS`` (:class:`pincal.report.model_tree.TreeReport`
with ``effects`` and ``diagnosis``): the calibration's report of the final model, each target's errors before
and after the effects on the calibration and held-out rows, the effects and the search."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from pincal.diagnosis.tree_diagnose import TreeCandidate, TreeDiagnosis
from pincal.diagnosis.verdicts import CRITERION
from pincal.model.tree import KinematicTree
from pincal.report.diagnosis import effect_entries
from pincal.report.model_tree import TargetErrors, TargetJson, TreeCandidateJson, TreeDiagnosisJson, TreeReport
from pincal.report.tree import target_errors

__all__ = ["with_diagnosis"]


def _rms_mm(errors: np.ndarray | None) -> float | None:
    return None if errors is None else float(np.sqrt(np.nanmean(errors**2)) * 1000.0)


def _held(errors: np.ndarray | None, points: tuple[int, ...]) -> TargetErrors | None:
    """A target's errors on the held-out rows (K_h, P) [m], of its points seen there (None: none, or no rows)."""
    numbers = () if errors is None else tuple(p for p in points if np.isfinite(errors[:, p - 1]).any())
    return target_errors(errors, numbers) if errors is not None and numbers else None


def _candidates(candidates: Sequence[TreeCandidate]) -> list[TreeCandidateJson]:
    return [{"effect": c.effect.label, "delta_bic": c.delta_bic, "screened": c.screened, "verdict": c.verdict}
            for c in candidates]


def with_diagnosis(report: TreeReport, diagnosis: TreeDiagnosis, geometry_errors: np.ndarray,
                   tree: KinematicTree) -> TreeReport:
    """``report`` (:func:`pincal.report.tree.tree_report` of the final model) with each target's errors of the
    geometric calibration (``geometry_errors``, its calibration rows' point errors (K, P) [m]) and on the
    held-out rows, the effects and the search of ``diagnosis``."""
    kinds = dict(zip(report["chain"]["joints"], report["chain"]["joint_kinds"]))
    out: TreeReport = {**report, "targets": [TargetJson(**t) for t in report["targets"]]}
    for target, entry in zip(tree.targets, out["targets"]):
        entry["geometry_errors"] = target_errors(geometry_errors, target.spec.points)
        entry["validation_geometry_errors"] = _held(diagnosis.heldout_before, target.spec.points)
        entry["validation_errors"] = _held(diagnosis.heldout_after, target.spec.points)
    section: TreeDiagnosisJson = {
        "criterion": CRITERION,
        "masses": "unknown" if diagnosis.masses_unknown else "urdf",
        "steps": [{
            "effect": effect_entries([(step.effect, step.values, step.std)], diagnosis.inputs, kinds, {})[0],
            "delta_bic": step.delta_bic,
            "calibration_rms_mm": [float(_rms_mm(step.calibration_before) or 0.0),
                                   float(_rms_mm(step.calibration_after) or 0.0)],
            "validation_rms_mm": None if step.heldout_before is None or step.heldout_after is None else [
                float(_rms_mm(step.heldout_before) or 0.0), float(_rms_mm(step.heldout_after) or 0.0)],
            "candidates": _candidates(step.candidates),
        } for step in diagnosis.steps],
        "last_candidates": _candidates(diagnosis.last_candidates),
        "untestable": [e.label for e in diagnosis.untestable],
    }
    out["effects"] = effect_entries(diagnosis.effects, diagnosis.inputs, kinds, {})
    out["diagnosis"] = section
    return out


