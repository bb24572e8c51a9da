"""Fixed figure margins sized to the labels, for the figures pincal draws: the HTML report's
(:mod:`pincal.report.figures`) and ``diagnose``'s plots (:mod:`pincal.diagnosis.plots`).

matplotlib's layout engines (``tight``, ``constrained``) fit the margins to the text by drawing the
figure once more; the figures here know which labels they hold, so the widest one is measured from the
font's metrics (no draw) and the margins are set from it: about half of a figure's drawing time saved.
"""

from __future__ import annotations

from collections.abc import Sequence

from matplotlib.font_manager import FontProperties
from matplotlib.textpath import text_to_path

__all__ = ["BOTTOM_IN", "BOTTOM_10PT_IN", "RIGHT_IN", "TITLE_IN", "TOP_IN", "fixed_margins", "label_width_in"]

#: Below the axes [in]: tick labels and one line of axis label at 9 pt, with the ticks and pads (~29 pt).
BOTTOM_IN = 0.5
#: The same at matplotlib's default 10 pt, with room for the descenders of a long axis label.
BOTTOM_10PT_IN = 0.6
#: Above the axes [in] with no title, and with a one-line title.
TOP_IN, TITLE_IN = 0.12, 0.4
#: Right of the axes [in]: half of a last tick label that ends at the axes' edge.
RIGHT_IN = 0.2


def label_width_in(labels: Sequence[str], size_pt: float, family: str = "sans-serif") -> float:
    """Width [in] of the widest of ``labels`` at ``size_pt`` points in ``family``, from matplotlib's font metrics
    (the widths its text layout uses). A page showing the text as text in another font differs as that
    font's widths differ."""
    font = FontProperties(family=family, size=size_pt)
    widths = [text_to_path.get_text_width_height_descent(label, font, ismath=False)[0] for label in labels]
    return max(widths, default=0.0) / 72.0


def fixed_margins(width_in: float, height_in: float, left_in: float, *, gap_in: float = 0.0, panels: int = 1,
                  across: bool = False, top_in: float = TOP_IN, bottom_in: float = BOTTOM_IN) -> dict[str, float]:
    """A grid's ``left``, ``right``, ``bottom``, ``top`` and its panels' spacing as fractions of a
    ``width_in`` × ``height_in`` figure: ``left_in`` for the y tick labels and axis label, ``gap_in`` [in]
    between ``panels`` side by side (``across``: ``wspace``) or stacked (``hspace``). The left margin is held
    to half the figure, so labels wider than that are cut rather than the figure refused."""
    left = min(left_in, 0.5 * width_in)
    inner = (width_in - left - RIGHT_IN) if across else (height_in - bottom_in - top_in)
    panel = (inner - (panels - 1) * gap_in) / panels  # the mean panel's extent, which the gap is a fraction of
    return {"left": left / width_in, "right": 1.0 - RIGHT_IN / width_in, "bottom": bottom_in / height_in,
            "top": 1.0 - top_in / height_in, ("wspace" if across else "hspace"): gap_in / panel}
