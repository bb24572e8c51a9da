"""The colours of pincal's figures and pages, one per model, defined once.

Every figure that shows a model — the HTML report's summary bars, cards,
per-row plots and parameter plot (:mod:`pincal.report.figures`), the plots of
``diagnose`` (:mod:`pincal.diagnosis.plots`) and the plan page — takes its
colour from :func:`model_colour`, so a model keeps its colour across the page:
the nominal geometry grey, the calibrated geometry (geometry only) blue, the
geometry with its effects orange, what ``evaluate`` measured purple; flagged
rows red.
"""

from __future__ import annotations

__all__ = ["NOMINAL", "CALIBRATED", "WITH_EFFECTS", "EVALUATED", "FLAG", "MODEL_COLOURS", "LEGEND", "model_colour"]

NOMINAL = "#9aa5b1"
CALIBRATED = "#2563eb"
WITH_EFFECTS = "#d97706"
EVALUATED = "#7c3aed"
FLAG = "#d1342f"

#: Model name (``row_errors`` ``model``) → colour. Aliases name the same model in other
#: figures: "geometry only" is the calibrated geometry of ``diagnose``'s plots.
MODEL_COLOURS: dict[str, str] = {
    "nominal geometry": NOMINAL,
    "calibrated geometry": CALIBRATED,
    "geometry only": CALIBRATED,
    "calibrated": CALIBRATED,
    "geometry and effects": WITH_EFFECTS,
    "with effects": WITH_EFFECTS,
    "reported model": EVALUATED,
}

#: The legend of the page: each model once, in the order a run produces them.
LEGEND: tuple[tuple[str, str], ...] = (
    ("nominal geometry", NOMINAL),
    ("calibrated geometry (geometry only)", CALIBRATED),
    ("geometry and effects", WITH_EFFECTS),
    ("reported model (evaluate)", EVALUATED),
)


def model_colour(name: str) -> str:
    """The colour of the model ``name``; the calibrated geometry's for a name not listed."""
    return MODEL_COLOURS.get(str(name).strip().lower(), CALIBRATED)
