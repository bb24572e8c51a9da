"""What a study returns: its rows, summaries, restarts and findings."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from pincal.study.protocol import (
    StudyConfig,
)

__all__ = ["StudyResult"]


@dataclass(frozen=True)
class StudyResult:
    """Everything a study produced.

    Attributes:
        config: what was run.
        rows: one dict per (deviations, level, repeat, method, weight, registration), sorted.
        limits: the noise limit at unit sigma, one dict per (deviations, estimator, pose set).
        restarts: one dict per restart, sorted by (case, estimator, start).
        restart_summary: per restart case and estimator, the starts reaching the same solution.
        figure2: per-pose errors of Methods 1 and 2 (Figure 2).
        summary: eq 25 per (deviations, level, method, weight, registration), with the noise limit.
        findings: the paper's findings checked on this run.
        executor: what ran the tasks.
        wall_s: wall time of the study [s].
    """

    config: StudyConfig
    rows: list[dict[str, Any]]
    limits: list[dict[str, Any]]
    restarts: list[dict[str, Any]]
    restart_summary: list[dict[str, Any]]
    figure2: list[dict[str, Any]]
    summary: list[dict[str, Any]]
    findings: list[dict[str, Any]]
    executor: str
    wall_s: float
