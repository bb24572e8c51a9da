"""REPORT.json of ``diagnose``: a calibration's report of the final model, with the effects and the
diagnosis (:class:`pincal.report.model_diagnosis.DiagnosisReport`)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, cast

import numpy as np

from pincal.report.model import (
    ChainHead,
    PoseErrorsJson,
    SessionEntry,
    errors_json,
)
from pincal.report.model_diagnosis import (
    ApproachContext,
    CandidateJson,
    ConditionsPart,
    DiagnosisJson,
    DiagnosisReport,
    DiagnosisStep,
    EffectJson,
    TargetChangeJson,
    TimeSpansPart,
)
from pincal.report.record import ReportRecord

if TYPE_CHECKING:
    from pincal.diagnosis.diagnose import Diagnosis
    from pincal.model.effects import Effect, EffectInputs

__all__ = ["diagnosis_report", "effect_entries", "compliance_words", "moment_compliance_words"]


def compliance_words(joint: str, value: float, unit: str) -> str:
    """A joint compliance c in words, with its sign convention (:mod:`pincal.model.effects`): the joint is at
    its reading + c · τ, τ its gravity torque (force, for a prismatic joint) as Pinocchio gives it — what holds
    the link against gravity — so a joint that gives way under its load has c < 0, its stiffness 1 / |c|."""
    force = unit.endswith("/N")
    load, stiffness = ("gravity force", "N/m") if force else ("gravity torque", "N·m/rad")
    if value == 0.0:
        return f"{joint}: c = 0 {unit}"
    what = (f"a stiffness of {1.0 / abs(value):.3g} {stiffness}: it gives way under its load, as a gearbox's or a "
            "link's elasticity does" if value < 0 else
            f"c > 0: it moves against the {load} the URDF predicts (an overcompensating counterbalance or spring, "
            "or the URDF's masses wrong), no stiffness")
    return (f"{joint} is at its reading + c x its {load} (what holds it against gravity, as Pinocchio computes "
            f"it), so c < 0 is a joint that sags: here c = {value:.3g} {unit}, {what}")


def moment_compliance_words(joint: str, unit: str) -> str:
    """A compliance of unknown masses in words, with its sign convention (:mod:`pincal.model.mass_moments`)."""
    return (f"{joint} is at its reading + the sum of each value x its load per unit of g x mass moment (the load "
            "that holds the carried links against gravity, as Pinocchio computes it, eq M2): each value is g x a "
            f"combination of the carried links' mass moments / {joint}'s stiffness [{unit}], the combinations the "
            "rows determine (listed in combinations), x c, c < 0 for a joint that sags: a sagging joint's values have "
            "the opposite sign to its combinations")


def lateral_words(joint: str, values: list[float] | None, unit: str) -> str:
    """A lateral compliance in words, with its sign convention (eq L1–L3 of :mod:`pincal.model.lateral`); its
    values ``values`` (c_u, c_v; None: of unknown masses, per combination)."""
    per = ("c_u x its gravity moment about u, then about v by c_v x the one about v" if values else
           "the sum of each u/ value x its moment per unit of g x mass moment, then about v likewise (eq M3)")
    text = (f"{joint} turns, right after its motion, about its lateral axis u by {per} (the moments that hold the "
            f"carried links against gravity, as Pinocchio computes them; u, v orthogonal to its axis, in its frame), "
            f"so c < 0 is a joint that bends under its load, its lateral stiffness 1 / |c| [{unit}]")
    return text + (f": here c_u = {values[0]:.3g}, c_v = {values[1]:.3g}" if values else "")


def effect_entries(effects: Sequence[tuple[Effect, np.ndarray, np.ndarray]], inputs: EffectInputs,
                   kinds: Mapping[str, str], given: Mapping[tuple[str, str], float]) -> list[EffectJson]:
    """REPORT.json's ``effects`` of adopted ``effects`` (values, standard deviations): each
    :func:`~pincal.model.effects.effect_to_dict` with what to do about it (``advice``), and a compliance of
    unknown masses what each value stands for (``combinations``, over the rows of ``inputs``); ``kinds``: each
    joint's kind, ``given``: the factor of each ``--coupling`` (joint, driver)."""
    from pincal.diagnosis.moment_candidates import combination_words
    from pincal.diagnosis.verdicts import coupling_advice, torque_coupling_advice
    from pincal.model.effect_units import effect_unit
    from pincal.model.effects import effect_to_dict

    out = [cast(EffectJson, effect_to_dict(e, v, s)) for e, v, s in effects]
    for entry, (effect, values, _) in zip(out, effects):
        if effect.type == "coupling":  # what to do: correct the readings (±1), or keep it in the model
            factor = given.get((str(effect.joint), str(effect.driver)))
            entry["advice"] = coupling_advice(effect, float(values[0]), factor)
        elif effect.driver:  # a compliance under another joint's torque: what links them
            entry["advice"] = torque_coupling_advice(effect, float(values[0]), effect_unit(effect, kinds))
        elif effect.type == "lateral":  # its sign convention, and without masses what each value stands for
            if effect.moments:
                entry["combinations"] = combination_words(effect, inputs, False)
            entry["advice"] = lateral_words(str(effect.joint), None if effect.moments else [float(v) for v in values],
                                            effect_unit(effect, kinds))
        elif effect.moments:  # a compliance of unknown masses: what each value stands for, its sign convention
            entry["combinations"] = combination_words(effect, inputs, kinds[str(effect.joint)] == "prismatic")
            entry["advice"] = moment_compliance_words(str(effect.joint), effect_unit(effect, kinds))
        elif effect.type == "compliance":  # its sign convention, where the value is read
            entry["advice"] = compliance_words(str(effect.joint), float(values[0]), effect_unit(effect, kinds))
    return out


def diagnosis_report(
    head: ChainHead,
    diagnosis: Diagnosis,
    payload_kg: float,
    time_column: str | None,
    *,
    sessions: list[SessionEntry],
    time_spans: TimeSpansPart,
    plots: list[str],
    record: ReportRecord,
) -> DiagnosisReport:
    """Build the REPORT.json document of ``diagnose``: the final model's :func:`~pincal.report.document.chain_head`
    (its errors: ``diagnosis.calibration_errors``), with the ``effects`` and the ``diagnosis`` section;
    ``time_spans``: :func:`pincal.report.sessions.drift_spans`; ``record``: what the run records beside the fit
    (:class:`pincal.report.record.ReportRecord`)."""
    couplings = record.couplings
    from pincal.diagnosis.verdicts import CRITERION

    def errors(e) -> PoseErrorsJson | None:
        return None if e is None else errors_json(e)

    approach = any(e.source == "approach" for e, _, _ in diagnosis.effects)
    context: ApproachContext | None = None
    inputs = diagnosis.inputs
    if approach and inputs.time is not None:  # the session's motion, for the flanks of interleaved rows
        moves = [(inputs.time, inputs.q)]  # the calibration rows, and the held-out rows that set their flanks
        if inputs.context_time is not None and inputs.context_q is not None:
            moves.append((inputs.context_time, inputs.context_q))
        context = {
            "time_s": (np.concatenate([t for t, _ in moves]) + diagnosis.time_reference).tolist(),
            "q": np.vstack([q for _, q in moves]).tolist(),
        }
    section: DiagnosisJson = {
        "criterion": CRITERION,
        "steps": [_step(step, errors) for step in diagnosis.steps],
        "last_candidates": [_candidate(c) for c in diagnosis.last_candidates],
        "unexplained": diagnosis.unexplained,
        "calibration_errors": errors(diagnosis.calibration_errors),
        "heldout_errors": errors(diagnosis.heldout_errors),
        "notes": list(diagnosis.notes),
        "plots": plots,
    }
    kinds = dict(zip(head["chain"]["joints"], head["chain"]["joint_kinds"]))
    given = {(c["joint"], c["driver"]): c["factor"] for c in (couplings or {}).get("couplings", [])}
    effects = effect_entries(diagnosis.effects, diagnosis.inputs, kinds, given)
    for entry, change in zip(effects, diagnosis.target_changes):  # how far each moves the target (mm, mrad)
        entry["target_change"] = cast(TargetChangeJson, change.as_dict())
    return {
        **head,
        "warnings": record.warnings,
        "sessions": sessions,
        "effects": effects,
        "payload_kg": payload_kg,
        "time_column": time_column,
        "time_reference_s": diagnosis.time_reference,
        "approach_context": context,
        "diagnosis": section,
        **time_spans,
        "row_errors": record.row_errors,
        "urdf_sha256": record.urdf_sha256,
        "xacro_args": record.xacro_args,
        **record.level_choice,
        **(couplings or {}),
        **_conditions(diagnosis),
    }


def _conditions(diagnosis: Diagnosis) -> ConditionsPart:
    """What evaluate needs of an adopted thermal effect or pause step (:class:`ConditionsPart`); {} without."""
    found, types = diagnosis.conditions, {effect.type for effect, _, _ in diagnosis.effects}
    out: dict = {}
    if found is not None and "thermal" in types and found.temperature_range is not None:
        out.update(temperature_column=found.column, temperature_range_c=found.temperature_range.as_dict())
    if found is not None and "pause_step" in types:
        out.update(pause_s=found.pause_s, pauses=[p.as_dict() for p in found.pauses],
                   pause_spans_s=[s.as_dict() for s in found.spans])
    return cast(ConditionsPart, out)


def _step(step, errors) -> DiagnosisStep:
    """A diagnosis step's REPORT.json entry (``errors``: PoseErrors or None → its JSON); a coupling found to be a
    joint read against another with its ``convention``."""
    from pincal.model.effects import effect_to_dict

    entry: DiagnosisStep = {
        "effect": cast(EffectJson, effect_to_dict(step.effect, step.values, step.std)),
        "delta_bic": step.delta_bic,
        "calibration": {"before": errors(step.calibration_before), "after": errors(step.calibration_after)},
        "heldout": {"before": errors(step.heldout_before), "after": errors(step.heldout_after)},
        "candidates": [_candidate(c) for c in step.candidates],
    }
    if step.convention is not None:
        entry["convention"] = step.convention.as_dict()
    return entry


def _candidate(candidate) -> CandidateJson:
    from pincal.model.effects import effect_to_dict

    return {
        **cast(EffectJson, effect_to_dict(candidate.effect, candidate.values, candidate.std)),
        "delta_bic": candidate.delta_bic,
        "heldout_rms_mm": candidate.heldout_rms_mm,
        "verdict": candidate.verdict,
    }
