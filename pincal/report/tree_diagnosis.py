"""REPORT.json of ``diagnose`` with several ``--tip-link LINK:POINTS`` (:class:`pincal.report.model_tree.TreeReport`
with ``effects`` and ``diagnosis``): the calibration's report of the final model, each target's errors before
and after the effects on the calibration and held-out rows, the effects and the search."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import cast

import numpy as np

from pincal.diagnosis.tree_diagnose import TreeCandidate, TreeDiagnosis
from pincal.diagnosis.verdicts import CRITERION
from pincal.model.effects import EffectInputs
from pincal.model.tree import KinematicTree
from pincal.report.diagnosis import effect_entries
from pincal.report.model_tree import (
    TargetErrors,
    TargetJson,
    TreeBeforeAfter,
    TreeCandidateJson,
    TreeDiagnosisJson,
    TreeReport,
)
from pincal.report.tree import orientation_of, target_errors

__all__ = ["with_diagnosis", "candidate_entries"]


def _held(errors: np.ndarray | None, points: tuple[int, ...], turns: np.ndarray | None = None) -> TargetErrors | None:
    """A target's errors on the held-out rows (K_h, P) [m], of its points seen there (None: none, or no rows);
    ``turns``: its orientation errors there (K_h,) [rad], or None."""
    numbers = () if errors is None else tuple(p for p in points if np.isfinite(errors[:, p - 1]).any())
    return target_errors(errors, numbers, turns) if errors is not None and numbers else None


def _all_points(errors: np.ndarray, turns: np.ndarray | None = None) -> TargetErrors:
    """Every seen point's errors (K, P) [m] as one target's (its points: those seen in some row); ``turns``: every
    measured orientation's errors (K, T) [rad], NaN where not seen, or None."""
    measured = turns if turns is not None and np.isfinite(turns).any() else None  # rows that measure none: no key
    return target_errors(errors, tuple(int(p) + 1 for p in np.flatnonzero(np.isfinite(errors).any(axis=0))),
                         measured)


def _before_after(before: np.ndarray | None, after: np.ndarray | None,
                  turns: tuple[np.ndarray, np.ndarray] | None = None) -> TreeBeforeAfter | None:
    """A step's errors before and after it: every seen point's and, with ``turns`` (before, after), every
    measured orientation's."""
    if before is None or after is None:
        return None
    turned = (None, None) if turns is None else turns
    return {"before": _all_points(before, turned[0]), "after": _all_points(after, turned[1])}


def candidate_entries(candidates: Sequence[TreeCandidate], inputs: EffectInputs, kinds: Mapping[str, str]
                ) -> list[TreeCandidateJson]:
    """Each candidate's effect (its values when fitted in full, its type and joint when screened out), ΔBIC and
    verdict."""
    out = []
    for candidate in candidates:
        entry = cast(TreeCandidateJson, effect_entries([(candidate.effect, candidate.values, np.full(
            candidate.values.shape, np.nan))], inputs, kinds, {})[0])
        for key in ("std", "sin_std", "cos_std", "advice", "combinations") + (
                ("value", "sin", "cos") if candidate.screened else ()):
            entry.pop(key, None)  # type: ignore[misc]
        entry["delta_bic"], entry["screened"] = candidate.delta_bic, candidate.screened
        entry["verdict"] = candidate.verdict
        out.append(entry)
    return out


def with_diagnosis(report: TreeReport, diagnosis: TreeDiagnosis,
                   geometry_errors: tuple[np.ndarray, np.ndarray | None], tree: KinematicTree) -> TreeReport:
    """``report`` (:func:`pincal.report.tree.tree_report` of the final model) with each target's errors of the
    geometric calibration (``geometry_errors``: its calibration rows' point errors (K, P) [m] and orientation
    errors (K, T) [rad], None without orientations) and on the held-out rows, the effects and the search of
    ``diagnosis``."""
    kinds = dict(zip(report["chain"]["joints"], report["chain"]["joint_kinds"]))
    out: TreeReport = {**report, "targets": [TargetJson(**t) for t in report["targets"]]}
    points, turns = geometry_errors
    for t, (target, entry) in enumerate(zip(tree.targets, out["targets"])):
        entry["geometry_errors"] = target_errors(points, target.spec.points, orientation_of(turns, t))
        held = (None, None) if diagnosis.heldout_turns is None else diagnosis.heldout_turns
        entry["validation_geometry_errors"] = _held(diagnosis.heldout_before, target.spec.points,
                                                    orientation_of(held[0], t))
        entry["validation_errors"] = _held(diagnosis.heldout_after, target.spec.points, orientation_of(held[1], t))
    section: TreeDiagnosisJson = {
        "criterion": CRITERION,
        "masses": "unknown" if diagnosis.masses_unknown else "urdf",
        "steps": [{
            "effect": effect_entries([(step.effect, step.values, step.std)], diagnosis.inputs, kinds, {})[0],
            "delta_bic": step.delta_bic,
            "calibration": cast(TreeBeforeAfter, _before_after(step.calibration_before, step.calibration_after,
                                                               step.calibration_turns)),
            "heldout": _before_after(step.heldout_before, step.heldout_after, step.heldout_turns),
            "candidates": candidate_entries(step.candidates, diagnosis.inputs, kinds),
        } for step in diagnosis.steps],
        "last_candidates": candidate_entries(diagnosis.last_candidates, diagnosis.inputs, kinds),
        "untestable": [e.label for e in diagnosis.untestable],
    }
    out["effects"] = effect_entries(diagnosis.effects, diagnosis.inputs, kinds, {})
    out["diagnosis"] = section
    return out


