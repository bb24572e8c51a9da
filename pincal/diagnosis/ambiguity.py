"""Candidates that correct the same poses alike, in words: what the one taken stands for.

When the rows cannot tell two effects apart (:mod:`pincal.diagnosis.verdicts` takes one of them), the user reads
which effects they were, of which joints, and what to measure to separate them (:func:`ambiguity_words`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, cast

import numpy as np

from pincal.model.effects import BEND_EFFECTS, Effect

if TYPE_CHECKING:
    from pincal.diagnosis.screening import FitObjective
    from pincal.fit.solver import Solution

__all__ = ["ambiguity_words", "ordinal", "basis_correlation", "alike_correlation"]


def basis_correlation(a: np.ndarray | None, b: np.ndarray | None) -> float:
    """The correlation of two effects' bases over the rows (their first columns, (K, n) each; 0 without one)."""
    if a is None or b is None:
        return 0.0
    a, b = a[:, 0] - a[:, 0].mean(), b[:, 0] - b[:, 0].mean()
    denominator = np.sqrt((a @ a) * (b @ b))
    return float(a @ b / denominator) if denominator > 0 else 0.0


def alike_correlation(effects: tuple[Effect, Effect], bases: tuple[np.ndarray | None, np.ndarray | None],
                      fits: tuple[tuple[FitObjective, Solution] | None, ...]) -> float:
    """How alike two candidates correct the poses: their bases' correlation (:func:`basis_correlation`) when both
    shift a joint reading or the sensor by a per-row series; with a lateral compliance, whose deflection turns
    the chain about another axis than any reading's, the cosine of what each fit changes in the measured
    coordinates (its whitened Jacobian columns times its values, the data rows), 0 without both fits."""
    if not any(e.type in BEND_EFFECTS for e in effects):
        return basis_correlation(*bases)
    if fits[0] is None or fits[1] is None:
        return 0.0
    changes = []
    for objective, solution in (fits[0], fits[1]):
        data = getattr(objective, "objective", objective)  # a prior-wrapped objective's sensor residual
        sl = data.effect_slices[-1]
        changes.append((objective.jacobian(solution.x)[:, sl] @ solution.x[sl])[: data.row_indices().size])
    denominator = np.linalg.norm(changes[0]) * np.linalg.norm(changes[1])
    return float(changes[0] @ changes[1] / denominator) if denominator > 0 else 0.0


def ordinal(n: int) -> str:
    """``1st``, ``2nd``, ``3rd``, ``4th`` … ``11th``, ``12th``, ``13th``, ``21st``: English ordinals."""
    suffix = "th" if n % 100 in (11, 12, 13) else {1: "st", 2: "nd", 3: "rd"}.get(n % 10, "th")
    return f"{n}{suffix}"


#: What each joint effect is, in words, for the alternatives of an ambiguous one (:func:`ambiguity_words`).
_WORDS = {"compliance": "a compliance", "lateral": "a lateral (bending) compliance",
          "encoder_scale": "an encoder scale", "coupling": "a coupling",
          "backlash": "a backlash", "drift": "a drift", "sensor_scale": "the sensor's scale",
          "thermal": "a thermal expansion", "pause_step": "a step at a pause"}


def _words(effect: Effect) -> str:
    """``a 2nd harmonic``, ``a backlash on the approach flank``, ``a coupling to A2``, ``a drift``."""
    if effect.type == "cyclic":
        return f"a {ordinal(cast(int, effect.harmonic))} harmonic"
    text = _WORDS[effect.type]
    if effect.source:
        text += f" on the {effect.source} flank"
    if effect.driver:
        text += f" to {effect.driver}'s {'reading' if effect.type == 'coupling' else 'torque'}"
    return text


def ambiguity_words(taken: Effect, others: Sequence[Effect], why: str) -> str:
    """The alternatives of an effect taken among candidates that correct the same poses alike, in words:
    ``A2's error: a 1st or a 2nd harmonic — these poses cannot tell; move A2 over more of its range to separate
    them; cyclic:A2:h1 is taken (…) and applied``; effects of several joints, each joint's, then to move them over
    more of their ranges and in other combinations; effects of the sensor, to measure where they differ."""
    effects = [taken, *others]
    joints = list(dict.fromkeys(e.joint for e in effects))
    what = "; or ".join((f"{joint}'s error: " if joint else "") + " or ".join(_words(e) for e in effects
                                                                              if e.joint == joint) for joint in joints)
    if None in joints:
        move = "measure where they differ (at other times, temperatures or postures)"
    elif len(joints) == 1:
        move = f"move {joints[0]} over more of its range"
    else:
        move = f"move {' and '.join(str(j) for j in joints)} over more of their ranges, and in other combinations,"
    return f"{what} — these poses cannot tell; {move} to separate them; {taken.label} is taken ({why}) and applied"
