"""Candidates that correct the same poses alike: one group, decided once, and never nothing when one of it passes.

The judge's logic (:class:`pincal.diagnosis.verdicts.Judge`) on stand-in fits, so that each case is exactly the one
it names: three candidates whose bases are one joint's reading (correlated 1.00), their calibration and held-out
errors given row by row. A real cell with candidates that correct alike is tests/test_read_against.py's.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from pincal.diagnosis import verdicts
from pincal.diagnosis.ambiguity import ambiguity_words, ordinal
from pincal.diagnosis.verdicts import Judge
from pincal.fit.metrics import PoseErrors
from pincal.model.effects import Effect, EffectInputs

ROWS = 12
JOINTS = ("J1", "J2", "J3")
SCALE = Effect("encoder_scale", "J2")  # basis: J2's reading
FOLLOWS = Effect("coupling", "J1", driver="J2")  # basis: J2's reading
THIRD = Effect("coupling", "J3", driver="J2")  # basis: J2's reading
NOISE = 1e-3  # the current model's noise [m and rad]: the held-out rows' errors below are in its units


class Fit:
    """A candidate's fit as the judge reads it: its effect's value moves the measured points by 100 × its value
    in noise units (far above :data:`NEGLIGIBLE`); ``errors`` on its own rows, ``held`` on the held-out rows."""

    effect_slices = [slice(0, 1)]
    G = None  # the size of its change is judged on positions

    def __init__(self, held: PoseErrors, errors: PoseErrors | None = None) -> None:
        self.held, self.errors = held, errors
        self.g, self.w = np.zeros((ROWS, 1, 3)), np.full(ROWS, 1.0 / NOISE)

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        return np.full((3 * ROWS, 1), 100.0)  # whitened: noise units per unit of value


def errors(position_mm: float | list[float], rotation_mrad: float | None = None) -> PoseErrors:
    """Errors of every row: one distance [mm] (or one per row) and, with 6D rows, one angle [mrad]."""
    position = np.broadcast_to(np.asarray(position_mm, float) * 1e-3, (ROWS,))[:, None].copy()
    return PoseErrors(position, None if rotation_mrad is None else np.full(ROWS, rotation_mrad * 1e-3))


def judge_of(before: PoseErrors) -> Judge:
    q = np.random.default_rng(4).uniform(-1.5, 1.5, (ROWS, len(JOINTS)))
    inputs = EffectInputs(q=q, gravity=np.zeros_like(q), time=None, order=np.arange(ROWS), joint_names=JOINTS)
    chain = SimpleNamespace(joint_names=list(JOINTS), joint_kinds=dict.fromkeys(JOINTS, "revolute"))
    rotation = None if before.rotation_rad is None else NOISE
    return Judge(inputs, chain, lambda objective, x: objective.held, Fit(before), np.zeros(1),  # type: ignore[arg-type]
                 noise=(NOISE, rotation), catalogue=[SCALE, FOLLOWS, THIRD])


@pytest.fixture(autouse=True)
def own_errors(monkeypatch):
    """A fit's errors on its own rows are its ``errors`` (default: twice the noise, so the current model's noise
    is the smallest and the held-out test is judged in it)."""
    monkeypatch.setattr(verdicts, "pose_errors_of", lambda objective, x: objective.errors or errors(2.0))


def ranked(judge: Judge, candidates: list[tuple[float, Effect, PoseErrors, PoseErrors | None]]):
    tried = [(delta, effect, Fit(held, own), SimpleNamespace(x=np.array([0.01]), std=np.array([1e-3])))
             for delta, effect, held, own in sorted(candidates, key=lambda c: c[0])]
    ranking, chosen, rejected, _ = judge.rank(tried)
    return {c.effect: c.verdict for c in ranking}, None if chosen is None else chosen[1], rejected


# held-out rows at 5 mm; better by 1.2 mm each: passes (every row better by more than its noise); six to 0 and
# six worse by 2 mm: the least sum (42 against 45.6 mm), but the signed-rank test cannot tell it better (p 0.08)
BEFORE, EVEN, SPLIT = errors(5.0), errors(3.8), errors([0.0] * 6 + [7.0] * 6)


@pytest.mark.parametrize("split_first", [False, True], ids=["best-ΔBIC-passes", "best-ΔBIC-is-preferred"])
def test_the_preferred_one_failing_the_held_out_test_leaves_the_next_that_passes(split_first):
    """The one that predicts the held-out rows best (the least sum) fails the signed-rank test, the other passes:
    the other is adopted, whichever ΔBIC is the better, and the first named as its alternative (before, the first
    refused the other as "preferred" and then failed itself: nothing adopted)."""
    deltas = (-48.0, -50.0) if split_first else (-50.0, -48.0)
    verdict, chosen, rejected = ranked(judge_of(BEFORE), [(deltas[0], SCALE, EVEN, None),
                                                          (deltas[1], FOLLOWS, SPLIT, None)])
    assert chosen == SCALE and verdict[SCALE] == "adopted"
    assert verdict[FOLLOWS].startswith(f"{SCALE.label} corrects the same poses the same way (bases correlated +1.00)")
    assert "this one: it does not improve the held-out rows beyond their noise" in verdict[FOLLOWS]
    words = rejected[f"{SCALE.label}:alternatives"]
    assert words.startswith("J2's error: an encoder scale; or J1's error: a coupling to J2's reading")
    assert "(of those the held-out test adopts, it predicts the held-out rows best) and applied" in words


def test_a_group_none_of_which_passes_is_refused_whole():
    """Both fail the held-out test: neither is adopted, each refused with its own verdict, the other named."""
    verdict, chosen, rejected = ranked(judge_of(BEFORE), [(-50.0, SCALE, SPLIT, None), (-48.0, FOLLOWS, SPLIT, None)])
    assert chosen is None and not any(key.endswith(":alternatives") for key in rejected)
    assert verdict[SCALE].startswith("it does not improve the held-out rows beyond their noise")
    assert verdict[SCALE].endswith(f"the held-out test refuses {FOLLOWS.label} too (the same correction)")


def test_two_that_would_prefer_each_other_adopt_one():
    """6D rows, three alike at ΔBIC −50, −48, −43: the first's group ({−50, −48}: −43 is 7 from it) is judged in
    the noise of its fits (1 mm, 1 mrad) and prefers the second (1 mm + 2 mrad against 4 mm + 1 mrad per row); the
    second's ({−50, −48, −43}) would have been judged in the third's orientation noise (0.012 mrad) and preferred
    the first back — both refused, before. Each group is decided once: the second is adopted, exactly one."""
    before = errors(5.0, 5.0)
    tight = errors(2.0, 0.02)  # the third fits its own rows' orientations a hundred times better
    verdict, chosen, rejected = ranked(judge_of(before), [(-50.0, SCALE, errors(4.0, 1.0), None),
                                                          (-48.0, FOLLOWS, errors(1.0, 2.0), None),
                                                          (-43.0, THIRD, errors(5.5, 5.0), tight)])
    assert chosen == FOLLOWS and [e for e, v in verdict.items() if v == "adopted"] == [FOLLOWS]
    assert verdict[SCALE].startswith(f"{FOLLOWS.label} corrects the same poses the same way")
    assert "(it predicts the held-out rows best) and applied" in rejected[f"{FOLLOWS.label}:alternatives"]


def test_without_held_out_rows_the_simpler_is_taken_and_the_others_named():
    judge = judge_of(BEFORE)
    judge._held_errors = None  # no --validation rows
    verdict, chosen, rejected = ranked(judge, [(-50.0, FOLLOWS, EVEN, None), (-48.0, SCALE, EVEN, None)])
    assert chosen == SCALE  # one value each: the catalogue's order
    assert verdict[FOLLOWS].startswith(f"{SCALE.label} corrects the same poses the same way")
    assert "(the simpler: fewest values, then the catalogue's order)" in rejected[f"{SCALE.label}:alternatives"]


def test_harmonics_are_named_with_english_ordinals():
    assert [ordinal(n) for n in (1, 2, 3, 4, 11, 12, 13, 21, 22, 23, 101, 111)] == [
        "1st", "2nd", "3rd", "4th", "11th", "12th", "13th", "21st", "22nd", "23rd", "101st", "111th"]
    words = ambiguity_words(Effect("cyclic", "A2", harmonic=1), [Effect("cyclic", "A2", harmonic=2)], "why")
    assert words.startswith("A2's error: a 1st harmonic or a 2nd harmonic — these poses cannot tell")


def test_the_member_taken_from_below_the_shown_candidates_is_listed_adopted(monkeypatch):
    """The best-ΔBIC candidate hands over to a member of its group ranked below the candidates the step shows
    (here one shown): the adopted one is still in the step's table (REPORT.json steps[].candidates), adopted."""
    monkeypatch.setattr(verdicts, "SHOWN", 1)
    verdict, chosen, _ = ranked(judge_of(BEFORE), [(-50.0, FOLLOWS, SPLIT, None), (-48.0, SCALE, EVEN, None)])
    assert chosen == SCALE and verdict[SCALE] == "adopted"
    assert verdict[FOLLOWS].startswith(f"{SCALE.label} corrects the same poses the same way")
