"""Figures of the HTML report, drawn from a REPORT.json document alone.

Each figure is an SVG (matplotlib's object API on its SVG canvas: no pyplot,
no global state) returned as a ``data:`` URI, so the page embeds it and needs
nothing else; text stays text (``svg.fonttype = none``) and the output is
deterministic (fixed hash salt, no date).
"""

from __future__ import annotations

import base64
import io
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from matplotlib import rc_context
from matplotlib.backends.backend_svg import FigureCanvasSVG
from matplotlib.collections import PolyCollection
from matplotlib.figure import Figure
from matplotlib.patches import Patch

from pincal.figure_margins import fixed_margins, label_width_in
from pincal.fit.outliers import OUTLIER_THRESHOLD
from pincal.palette import CALIBRATED, FLAG, NOMINAL, model_colour

if TYPE_CHECKING:
    from matplotlib.typing import RcKeyType  # matplotlib >= 3.9

__all__ = [
    "NOMINAL_COLOUR", "FLAG_COLOUR", "model_colours", "png_uri", "overview_figure", "row_errors_figure",
    "parameter_figure", "PLAN_COLOURS", "prediction_figure", "coverage_figure",
]

#: Model colours: :mod:`pincal.palette` (the page's CSS and legend use the same).
NOMINAL_COLOUR = NOMINAL
FLAG_COLOUR = FLAG
_STYLE: dict[RcKeyType, Any] = {
    "svg.fonttype": "none",
    "svg.hashsalt": "pincal-report",
    "font.family": "sans-serif",
    "font.size": 9,
    "axes.edgecolor": "#c5ccd3",
    "axes.labelcolor": "#33404d",
    "xtick.color": "#52606d",
    "ytick.color": "#52606d",
    "axes.spines.top": False,
    "axes.spines.right": False,
    "axes.grid": True,
    "grid.color": "#e4e8ec",
    "grid.linewidth": 0.8,
    "legend.frameon": False,
}


def model_colours(names: Sequence[str]) -> list[str]:
    """The colour of each model of ``names`` (:func:`pincal.palette.model_colour`): a model
    has one colour on the whole page, wherever it stands in a set's chain."""
    return [model_colour(name) for name in names]


def _svg_uri(fig: Figure) -> str:
    FigureCanvasSVG(fig)
    buffer = io.BytesIO()
    fig.savefig(buffer, format="svg", metadata={"Date": None})
    return "data:image/svg+xml;base64," + base64.b64encode(buffer.getvalue()).decode("ascii")


def png_uri(path: Path) -> str | None:
    """A PNG file as a ``data:`` URI, or None if ``path`` is not a readable PNG."""
    try:
        data = path.read_bytes()
    except OSError:
        return None
    if not data.startswith(b"\x89PNG\r\n\x1a\n"):
        return None
    return "data:image/png;base64," + base64.b64encode(data).decode("ascii")


def overview_figure(stages: Sequence[dict[str, Any]]) -> str | None:
    """RMS position (and orientation) error of each row set under each model, as bars.

    Args:
        stages: per row set, ``{"set": name, "models": [(model, rms_mm, rms_deg or None), ...]}``.
    """
    if not stages:
        return None
    has_rotation = any(m[2] is not None for s in stages for m in s["models"])
    with rc_context(_STYLE):
        size = (7.2 if has_rotation else 5.2, 0.5 + 0.62 * sum(len(s["models"]) for s in stages))
        names = [f"{stage['set']}: {model[0]}" for stage in stages for model in stage["models"]]
        fig = Figure(figsize=size)
        # tick labels at the style's font size (matplotlib's "medium")
        left = label_width_in(names, _STYLE["font.size"], _STYLE["font.family"]) + 0.25  # + the ticks, pads, hinting
        # the gap: half of each panel's last x tick label, and a value printed past a bar's end
        grid = fixed_margins(*size, left, gap_in=0.6, panels=2 if has_rotation else 1, across=True)
        axes = fig.subplots(1, 2 if has_rotation else 1, squeeze=False, gridspec_kw=grid)[0]
        for ax, column, unit in zip(axes, (1, 2), ("mm", "deg")):
            labels, values, colours, y = [], [], [], 0.0
            ticks = []
            for stage in stages:
                for (model, *rms), colour in zip(stage["models"], model_colours([m[0] for m in stage["models"]])):
                    value = rms[column - 1]
                    labels.append(f"{stage['set']}: {model}")
                    values.append(np.nan if value is None else value)
                    colours.append(colour)
                    ticks.append(y)
                    y += 1.0
                y += 0.5
            finite = [v for v in values if np.isfinite(v) and v > 0]
            spread = max(finite) / min(finite) if finite else 1.0
            if spread > 30.0:  # nominal errors hundreds of times the calibrated ones: both stay readable
                ax.set_xscale("log")
            ax.barh(ticks, values, color=colours, height=0.8)
            for tick, value in zip(ticks, values):
                if np.isfinite(value):
                    ax.text(value, tick, f" {value:#.3g}".rstrip("."), va="center", fontsize=8, color="#33404d")
            ax.set_yticks(ticks, labels if column == 1 else [""] * len(labels))
            ax.invert_yaxis()
            ax.set_xlabel(f"RMS {'position' if unit == 'mm' else 'orientation'} error [{unit}]"
                          + (" (log scale)" if spread > 30.0 else ""))
            ax.grid(axis="y", visible=False)
            if spread > 30.0:
                ax.set_xlim(min(finite) / 3.0, max(finite) * 4.0)
            else:
                ax.set_xlim(0, 1.18 * max(finite) if finite else 1)
        return _svg_uri(fig)


def _bars(centres: np.ndarray, heights: np.ndarray, width: float, colours: Sequence[str]) -> PolyCollection:
    """Bars from 0 to ``heights`` of ``width`` at ``centres`` (data units), as one artist: ``Axes.bar`` makes a
    patch per bar, each laid out and written apart (~1 ms a bar, most of a page's time for a thousand rows).
    Bars of non-finite height are left out, as ``Axes.bar`` draws nothing for them."""
    shown = np.isfinite(heights)
    x0, x1 = centres[shown] - 0.5 * width, centres[shown] + 0.5 * width
    top, ground = heights[shown], np.zeros(int(shown.sum()))
    corners = np.stack([np.column_stack(pair) for pair in ((x0, ground), (x0, top), (x1, top), (x1, ground))], axis=1)
    faces = [colour for colour, keep in zip(colours, shown) if keep]
    bars = PolyCollection(list(corners), facecolors=faces, edgecolors="none", zorder=2)
    bars.sticky_edges.y.append(0.0)  # as Axes.bar: autoscaling leaves no margin below the bars' ground
    return bars


def row_errors_figure(entry: dict[str, Any], flagged: Sequence[int]) -> str:
    """Per-row errors of one ``row_errors`` set against file line: bars for the reported
    model, markers for the earlier ones, the 5-robust-σ line, flagged rows in red.

    Args:
        entry: the ``row_errors`` set.
        flagged: the flagged rows, as indices into ``entry["lines"]``.
    """
    files = [str(f) for f in entry.get("files") or []]
    several = len(set(files)) > 1 and len(files) == len(entry["lines"])
    # rows of several files share line numbers: then each row is drawn at its place in the set
    lines = np.arange(1.0, len(files) + 1.0) if several else np.asarray(entry["lines"], dtype=float)
    labels = [f"{Path(f).name}:{int(n)}" for f, n in zip(files, entry["lines"])] if several else \
        [str(int(n)) for n in entry["lines"]]
    models = entry["models"]
    has_rotation = models[-1].get("orientation_deg") is not None
    colours = model_colours([m["model"] for m in models])
    flagged_set = {int(f) for f in flagged}
    width = 0.8 * (float(np.min(np.diff(np.sort(lines)))) if lines.size > 1 else 1.0)
    with rc_context(_STYLE):
        height = 3.0 + (2.4 if has_rotation else 0.0)
        fig = Figure(figsize=(11.0, height))  # fixed margins [in]: a layout engine would draw it twice
        axes = fig.subplots(2 if has_rotation else 1, 1, squeeze=False, sharex=True,
                            gridspec_kw={"left": 0.8 / 11.0, "right": 1.0 - 0.15 / 11.0, "bottom": 0.5 / height,
                                         "top": 1.0 - 0.4 / height, "hspace": 0.12})[:, 0]
        for ax, key, unit in zip(axes, ("position_mm", "orientation_deg"), ("mm", "deg")):
            final = np.asarray(models[-1][key], dtype=float)
            bar_colours = [FLAG_COLOUR if k in flagged_set else colours[-1] for k in range(len(lines))]
            ax.add_collection(_bars(lines, final, width, bar_colours))
            ax.autoscale_view()  # before matplotlib 3.11, adding a collection leaves the limits to the caller
            median = float(np.median(final))
            scale = 1.4826 * float(np.median(np.abs(final - median)))
            threshold = median + OUTLIER_THRESHOLD * scale
            top = max(float(np.max(final)), threshold if scale > 0 else 0.0)
            off_scale = []
            for model, colour in zip(models[:-1], colours[:-1]):
                values = None if model.get(key) is None else np.asarray(model[key], dtype=float)
                if values is None:
                    continue
                if np.max(values) > 3.0 * top:  # would flatten the reported model's bars: say so instead
                    off_scale.append(f"{model['model']} off scale (up to {np.max(values):.3g} {unit})")
                    continue
                ax.plot(lines, values, "o" if colour == NOMINAL_COLOUR else "_", ms=4 if colour ==
                        NOMINAL_COLOUR else 7, mew=1.6, color=colour, label=model["model"], zorder=3)
                top = max(top, float(np.max(values)))
            if scale > 0:
                ax.axhline(threshold, color=FLAG_COLOUR, lw=0.9, ls="--",
                           label=f"median + {OUTLIER_THRESHOLD:g} robust σ", zorder=1)
            if off_scale:
                ax.text(0.995, 0.97, "; ".join(off_scale), transform=ax.transAxes, ha="right", va="top",
                        fontsize=8, color="#52606d")
            for k, (line, value) in enumerate(zip(lines, final)):
                if k in flagged_set:
                    ax.annotate(labels[k], (line, value), textcoords="offset points", xytext=(0, 3),
                                ha="center", fontsize=7, color=FLAG_COLOUR)
            ax.set_ylabel("position error [mm]\n(RMS over the target's points)" if key == "position_mm"
                          else "orientation error [deg]")
            ax.set_ylim(0, 1.15 * top if top > 0 else None)
        shown = list(dict.fromkeys(files)) if several else entry.get("file") or "the data file"
        names = ", ".join(Path(str(f)).name for f in (shown if isinstance(shown, list) else [shown]))
        axes[-1].set_xlabel(f"row of {names}, in file and line order" if several else f"line in {names}")
        handles, labels = axes[0].get_legend_handles_labels()  # earlier models, then the threshold line
        bars = [Patch(color=colours[-1], label=models[-1]["model"])]
        if flagged_set:
            bars.append(Patch(color=FLAG_COLOUR, label="flagged rows"))
        threshold_line = [h for h, label in zip(handles, labels) if label.startswith("median")]
        handles = [h for h, label in zip(handles, labels) if not label.startswith("median")] + bars + threshold_line
        fig.legend(handles=handles, loc="upper left", bbox_to_anchor=(0.7 / 11.0, 1.0), ncols=len(handles),
                   fontsize=8)
        return _svg_uri(fig)


def parameter_figure(rows: Sequence[dict[str, Any]]) -> str | None:
    """Calibrated change ± 2σ of every determined parameter, one panel per display unit.

    Args:
        rows: ``{"name", "change", "std", "unit"}`` in display units (mm, mrad, ...).
    """
    rows = [r for r in rows if r["change"] is not None]
    if not rows:
        return None
    units = list(dict.fromkeys(r["unit"] for r in rows))
    heights = [sum(1 for r in rows if r["unit"] == u) for u in units]
    with rc_context(_STYLE):
        size = (7.2, 0.9 + 0.2 * sum(heights) + 0.5 * len(units))
        fig = Figure(figsize=size)
        names = [r["name"] for r in rows]
        left = label_width_in(names, 7.5, _STYLE["font.family"]) + 0.25  # + the ticks, pads, hinting
        grid = fixed_margins(*size, left, gap_in=0.45, panels=len(units))
        axes = fig.subplots(len(units), 1, squeeze=False, height_ratios=[h + 1.5 for h in heights],
                            gridspec_kw=grid)[:, 0]
        for ax, unit in zip(axes, units):
            chosen = [r for r in rows if r["unit"] == unit]
            y = np.arange(len(chosen))
            change = np.array([r["change"] for r in chosen], dtype=float)
            spread = np.array([np.nan if r["std"] is None else 2.0 * r["std"] for r in chosen], dtype=float)
            ax.errorbar(change, y, xerr=np.where(np.isfinite(spread), spread, 0.0), fmt="o", ms=3.5,
                        color=CALIBRATED, ecolor="#93b4f5", elinewidth=2, capsize=0)
            ax.axvline(0.0, color="#52606d", lw=0.8)
            ax.set_yticks(y, [r["name"] for r in chosen], fontsize=7.5)
            ax.invert_yaxis()
            ax.set_xlabel(f"change from nominal [{unit}] (bars: ± 2 standard deviations)")
            ax.grid(axis="y", visible=False)
        return _svg_uri(fig)


#: The plan page: the plan's calibrated model in the calibrated colour, random choices grey.
PLAN_COLOURS = {"plan": CALIBRATED, "random": NOMINAL, "recorded_only": "#7b8794"}


def prediction_figure(rows: Sequence[dict[str, Any]]) -> str | None:
    """Predicted mean and max position error of the plan and of random choices (PLAN.json
    ``predicted``), as bars. ``rows``: ``{"key", "label", "mean_value", "max_value"}``."""
    rows = [r for r in rows if isinstance(r.get("mean_value"), (int, float))]
    if not rows:
        return None
    with rc_context(_STYLE):
        fig = Figure(figsize=(5.6, 0.9 + 0.55 * len(rows)))
        ax = fig.add_axes((0.2, 0.3, 0.76, 0.62))
        y = np.arange(len(rows), dtype=float)
        for stat, offset, alpha in (("mean_value", -0.18, 1.0), ("max_value", 0.18, 0.45)):
            values = [float(r[stat]) if isinstance(r.get(stat), (int, float)) else np.nan for r in rows]
            ax.barh(y + offset, values, height=0.34, alpha=alpha,
                    color=[PLAN_COLOURS.get(r["key"], CALIBRATED) for r in rows])
            for tick, value in zip(y + offset, values):
                if np.isfinite(value):
                    ax.text(value, tick, f" {value:#.3g} ({stat[:-6]})", va="center", fontsize=7.5, color="#33404d")
        short = {"plan": "this plan", "random": "random (median)", "recorded_only": "recorded rows"}
        ax.set_yticks(y, [short.get(r["key"], r["key"]) for r in rows], fontsize=8)
        ax.invert_yaxis()
        ax.set_xlim(0, 1.45 * max(float(r["max_value"] or r["mean_value"]) for r in rows))
        ax.set_xlabel("predicted position error [mm] (solid: mean, light: max)")
        ax.grid(axis="y", visible=False)
        return _svg_uri(fig)


def coverage_figure(coverage: Sequence[dict[str, Any]]) -> str | None:
    """Per joint: its URDF range (grey bar, scaled to 0 … 1) and the plan's poses in it (ticks).

    Args:
        coverage: ``{"joint", "values", "lower", "upper", "percent"}`` in display units.
    """
    if not coverage:
        return None
    with rc_context(_STYLE):
        fig = Figure(figsize=(7.2, 0.7 + 0.32 * len(coverage)))
        ax = fig.add_axes((0.2, 0.6 / (0.7 + 0.32 * len(coverage)), 0.66, 1 - 0.75 / (0.7 + 0.32 * len(coverage))))
        for row, entry in enumerate(coverage):
            lower, upper, values = entry["lower"], entry["upper"], np.asarray(entry["values"], dtype=float)
            if lower is None or upper is None or upper <= lower:  # no limits: the poses' own span
                lower, upper = (float(values.min()), float(values.max())) if values.size else (0.0, 1.0)
                upper = upper if upper > lower else lower + 1.0
            ax.barh(row, 1.0, left=0.0, height=0.6, color="#e4e8ec")
            scaled = (values - lower) / (upper - lower)
            if scaled.size:
                ax.barh(row, scaled.max() - scaled.min(), left=scaled.min(), height=0.6, color=CALIBRATED, alpha=0.35)
                ax.vlines(scaled, row - 0.3, row + 0.3, color=CALIBRATED, lw=1.2)
            ax.text(1.02, row, entry["percent"], va="center", fontsize=8, color="#33404d")
        ax.set_yticks(range(len(coverage)), [e["joint"] for e in coverage], fontsize=8)
        ax.set_ylim(len(coverage) - 0.5, -0.5)
        ax.set_xlim(0, 1)
        ax.set_xticks([0, 0.5, 1], ["lower limit", "middle", "upper limit"])
        ax.set_xlabel("each joint's range in the URDF (ticks: the plan's poses; right: share of the range spanned)")
        ax.grid(False)
        return _svg_uri(fig)
