"""The HTML report's per-row bars (pincal.report.figures._bars) are what ``Axes.bar`` draws, as one artist."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from pincal.report.figures import _bars


def _raster(draw) -> tuple[np.ndarray, tuple[float, ...]]:
    """The Agg pixels of one axes that ``draw`` filled, and its limits after autoscaling."""
    fig = Figure(figsize=(6.0, 2.0), dpi=100)
    ax = fig.subplots()
    draw(ax)
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    return np.asarray(canvas.buffer_rgba()).copy(), (*ax.get_xlim(), *ax.get_ylim())


def test_the_bars_are_axes_bar_pixel_for_pixel_with_its_limits():
    """Uneven lines (bar width from the closest two), a flagged colour, and a row of no value, which gets no bar."""
    lines = np.array([2.0, 3.0, 5.0, 6.0, 9.0, 10.0, 11.0])
    heights = np.array([0.3, 0.1, np.nan, 0.45, 0.2, 0.05, 0.38])
    colours = ["#1f5fbf", "#1f5fbf", "#1f5fbf", "#c0392b", "#1f5fbf", "#1f5fbf", "#c0392b"]
    width = 0.8
    by_bar = _raster(lambda ax: ax.bar(lines, heights, width=width, color=colours, zorder=2))
    by_collection = _raster(lambda ax: ax.add_collection(_bars(lines, heights, width, colours)) and ax.autoscale_view())
    # the limits to rounding: Axes.bar converts the width through the first bar's position (0.8 → 0.7999999999999998)
    assert by_collection[1] == pytest.approx(by_bar[1], rel=1e-12, abs=1e-12)
    assert np.array_equal(by_collection[0], by_bar[0])
