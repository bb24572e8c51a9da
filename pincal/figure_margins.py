"""Fixed figure margins sized to the labels, for the figures pincal draws: the HTML report's
(:mod:`pincal.report.figures`), ``diagnose``'s plots (:mod:`pincal.diagnosis.plots`) and the study's
(:mod:`pincal.study.figures`).

matplotlib's layout engines (``tight``, ``constrained``) fit the margins to the text by drawing the
figure once more; the figures here know which labels they hold, so the widest one is measured from the
font's metrics (no draw) and the margins are set from it: about half of a figure's drawing time saved.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache
from typing import TYPE_CHECKING

from matplotlib import rcParams
from matplotlib.font_manager import FontProperties, findfont
from matplotlib.textpath import text_to_path

if TYPE_CHECKING:
    from matplotlib.axes import Axes

__all__ = ["BOTTOM_IN", "BOTTOM_10PT_IN", "RIGHT_IN", "TITLE_IN", "TOP_IN", "fixed_margins", "grid_margins",
           "label_width_in", "y_label_room_in"]

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
    font_file = findfont(FontProperties(family=family, size=size_pt))  # the font drawn now, as rcParams choose it
    return max((_width_pt(label, size_pt, family, font_file) for label in labels), default=0.0) / 72.0


@lru_cache(maxsize=4096)  # tick labels recur across panels and figures ("0.00", "0.05" ...); ~0.5 ms a layout
def _width_pt(label: str, size_pt: float, family: str, font_file: str) -> float:
    """The width [pt] of ``label``; ``font_file``, the font ``family`` resolves to, keys the cache only."""
    font = FontProperties(family=family, size=size_pt)
    return float(text_to_path.get_text_width_height_descent(label, font, ismath=False)[0])


def y_label_room_in(ax: Axes) -> float:
    """Room [in] left of ``ax`` for its y tick labels as they will be drawn (formatted now, without a draw: all the
    locator's ticks, as matplotlib formats them, then only those in the view, as it draws them), the ticks and pads
    (7 pt), one line of axis label and the padding a tight layout leaves (0.45 in in all). The ticks are the
    locator's for the axes' present size: set the margins first where they change it."""
    ticks = ax.get_yticks()
    labels = ax.yaxis.get_major_formatter().format_ticks(ticks.tolist())
    low, high = sorted(ax.get_ylim())
    slack = 1e-10 * (high - low)  # a tick on a limit, less rounding, is drawn (matplotlib's Axis._update_ticks)
    shown = [label for tick, label in zip(ticks, labels) if low - slack <= tick <= high + slack]
    return label_width_in(shown, FontProperties(size=rcParams["ytick.labelsize"]).get_size_in_points()) + 0.45


def grid_margins(size_in: tuple[float, float], grid: tuple[int, int], *, left_in: float, right_in: float = RIGHT_IN,
                 top_in: float = TOP_IN, bottom_in: float = BOTTOM_IN,
                 gaps_in: tuple[float, float] = (0.0, 0.0)) -> dict[str, float]:
    """A ``grid`` of (rows, columns) panels' ``left``, ``right``, ``bottom``, ``top``, ``wspace`` and ``hspace``
    as fractions of a figure of ``size_in`` (width, height) [in]: the margins [in] at each edge and ``gaps_in``
    (between columns, between rows) [in]; matplotlib takes a gap as a fraction of the mean panel's extent. The
    left margin is held to half the figure, so labels wider than that are cut rather than the figure refused."""
    (width, height), (rows, cols) = size_in, grid
    left = min(left_in, 0.5 * width)
    panel_width = (width - left - right_in - (cols - 1) * gaps_in[0]) / cols
    panel_height = (height - bottom_in - top_in - (rows - 1) * gaps_in[1]) / rows
    return {"left": left / width, "right": 1.0 - right_in / width, "bottom": bottom_in / height,
            "top": 1.0 - top_in / height, "wspace": gaps_in[0] / panel_width, "hspace": gaps_in[1] / panel_height}


def fixed_margins(width_in: float, height_in: float, left_in: float, *, gap_in: float = 0.0, panels: int = 1,
                  across: bool = False, top_in: float = TOP_IN, bottom_in: float = BOTTOM_IN) -> dict[str, float]:
    """A row or column of ``panels`` (:func:`grid_margins`): ``left_in`` for the y tick labels and axis label,
    ``gap_in`` [in] between panels side by side (``across``: ``wspace``) or stacked (``hspace``)."""
    margins = grid_margins((width_in, height_in), (1, panels) if across else (panels, 1), left_in=left_in,
                           top_in=top_in, bottom_in=bottom_in, gaps_in=(gap_in, gap_in))
    return {key: margins[key] for key in ("left", "right", "bottom", "top", "wspace" if across else "hspace")}
