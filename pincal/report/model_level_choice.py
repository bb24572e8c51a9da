"""The typed model of REPORT.json's ``level_choice``: how ``--level auto`` chose the level by
cross-validation (:mod:`pincal.fit.level_choice`), in every kind of report that calibrates at a level."""

from __future__ import annotations

from typing import TYPE_CHECKING, TypedDict, cast

if TYPE_CHECKING:
    from pincal.fit.level_choice import LevelChoice

__all__ = ["Fold", "LevelScore", "LevelChoiceJson", "LevelChoicePart", "level_choice_part"]


class Fold(TypedDict):
    name: str
    held_out_rows: int
    training_rows: int


class LevelScore(TypedDict):
    """One level's cross-validation error (null where its fits failed)."""

    level: str
    cv_error_mm: float | None
    standard_error_mm: float | None
    fold_errors_mm: list[float | None]
    kept_parameters: list[int | None]
    failures: list[str]


class LevelChoiceJson(TypedDict):
    """How ``--level auto`` chose the level (:meth:`pincal.fit.level_choice.LevelChoice.as_dict`)."""

    rule: str
    scheme: str
    error: str
    selection: str
    folds: list[Fold]
    levels: list[LevelScore]
    lowest: str
    threshold_mm: float
    chosen: str
    seconds: float


class LevelChoicePart(TypedDict, total=False):
    """``level_choice`` where a report has it (``--level auto``), to unpack into a report."""

    level_choice: LevelChoiceJson


def level_choice_part(choice: LevelChoice | None) -> LevelChoicePart:
    """``{"level_choice": ...}`` of ``--level auto``, ``{}`` for a level given."""
    return {} if choice is None else {"level_choice": cast(LevelChoiceJson, choice.as_dict())}
