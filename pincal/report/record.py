"""What a REPORT.json records of the run beside what the fit found: the corrected URDF written with it, the
xacro arguments, each row's error, the plausibility warnings, the level choice and the couplings — one
value the workflows build and every report builder (:func:`pincal.report.document.chain_report`,
:func:`~pincal.report.document.paper_report`, :func:`pincal.report.diagnosis.diagnosis_report`,
:func:`pincal.report.fixture.fixture_report`) takes."""

from __future__ import annotations

from dataclasses import dataclass, field

from pincal.report.model import CouplingsPart, Finding, RowErrorSet
from pincal.report.model_level_choice import LevelChoicePart

__all__ = ["ReportRecord"]


@dataclass(frozen=True)
class ReportRecord:
    """The keys of a REPORT.json that describe the run rather than the fit.

    Attributes:
        urdf_sha256: SHA-256 of the corrected URDF's bytes written with the report (``urdf_sha256``).
        xacro_args: ``{NAME: VALUE}`` the ``.xacro`` URDF was expanded with (``xacro_args``; ``{}`` for a URDF).
        row_errors: each row's error by file line (``row_errors``; a socket fixture's report has none).
        warnings: the plausibility findings (``warnings``; a paper method's report has none).
        level_choice: :func:`pincal.report.model_level_choice.level_choice_part` (``level_choice`` with
            ``--level auto``; a paper method's report has none).
        couplings: :func:`pincal.report.model.couplings_part` of ``--coupling`` (None without; a paper
            method's report has none).
    """

    urdf_sha256: str
    xacro_args: dict[str, str]
    row_errors: list[RowErrorSet] = field(default_factory=list)
    warnings: list[Finding] = field(default_factory=list)
    level_choice: LevelChoicePart = field(default_factory=lambda: LevelChoicePart())
    couplings: CouplingsPart | None = None
