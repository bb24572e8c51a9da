"""Candidates that correct the same poses alike, in words: what the one taken stands for.

When the rows cannot tell two effects apart (:mod:`pincal.diagnosis.verdicts` takes one of them), the user reads
which effects they were, of which joints, and what to measure to separate them (:func:`ambiguity_words`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import cast

from pincal.model.effects import Effect

__all__ = ["ambiguity_words", "ordinal"]


def ordinal(n: int) -> str:
    """``1st``, ``2nd``, ``3rd``, ``4th`` … ``11th``, ``12th``, ``13th``, ``21st``: English ordinals."""
    suffix = "th" if n % 100 in (11, 12, 13) else {1: "st", 2: "nd", 3: "rd"}.get(n % 10, "th")
    return f"{n}{suffix}"


#: What each joint effect is, in words, for the alternatives of an ambiguous one (:func:`ambiguity_words`).
_WORDS = {"compliance": "a compliance", "encoder_scale": "an encoder scale", "coupling": "a coupling",
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
