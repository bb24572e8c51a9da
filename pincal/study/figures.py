"""Figures of the simulation study, equivalent to Figures 2–6 of Franaszek & Marvel (2022).

Each figure plots eq 25: the mean over repeats of the eq 24 mean errors
(v̄ position [mm], ρ̄ orientation [deg]) against the noise level, with error
bars of one standard deviation; curves of one panel are shifted slightly
along the noise axis, as in the paper. Two more figures compare the
estimators with their linearised noise limit and the maximum-likelihood
estimator with Method 2. Drawn with matplotlib's Agg backend into PNG files,
by forked worker processes where that is safe (:func:`start_figures`; as many
as the study's workers, at most seven): the seven figures take ~2.5 s of one core,
about half of that on two. Their margins are sized from their labels
(:mod:`pincal.figure_margins`), not by a tight layout, which measures each
figure by drawing it once more (30-40 % of the drawing).
"""

from __future__ import annotations

import dataclasses
import multiprocessing
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Any

import matplotlib
import matplotlib.pyplot as plt  # noqa: E402  (after choosing the backend)
import numpy as np  # noqa: E402

from pincal.figure_margins import (  # noqa: E402
    BOTTOM_10PT_IN,
    RIGHT_IN,
    grid_margins,
    label_width_in,
    y_label_room_in,
)
from pincal.outputs import replacing  # noqa: E402
from pincal.study.estimators import Estimator  # noqa: E402
from pincal.study.executors import fork_is_safe  # noqa: E402
from pincal.study.result import StudyResult  # noqa: E402

__all__ = [
    "figure2", "figure3", "figure4", "figure5", "figure6", "figure_noise_limit", "figure_ml", "FIGURES",
    "start_figures", "write_figures",
]

matplotlib.use("Agg")


_POS_X = "sensor position noise σ_p [mm]"
_ROT_X = "sensor orientation noise σ_a [deg]"
_POS_Y = "mean position error v̄ [mm]"
_ROT_Y = "mean orientation error ρ̄ [deg]"
_REGISTRATION_COLOURS = {1: "tab:blue", 2: "tab:red"}
_DPI = 110
_TITLE_PT = 9
#: Padding [in] above the titles and beyond a title wider than its panel: a tight layout pads 1.08 × 10 pt =
#: 0.15 in, and the labels' rooms of :mod:`pincal.figure_margins` hold some padding already.
_PAD_IN = 0.1


def _points(summary, deviations: str, method: str, weight, registration: int, column: str):
    """(sigma, mean, sd) over the levels of one summary curve."""
    rows = sorted(
        (s for s in summary if s["deviations"] == deviations and s["method"] == method
         and s["weight"] == weight and s["registration"] == registration),
        key=lambda s: s["level"],
    )
    sigma = np.array([s["sigma_pos_mm"] for s in rows])
    mean = np.array([s[column] for s in rows])
    sd = np.array([s[column + "_sd"] for s in rows]) if rows and column + "_sd" in rows[0] else None
    return sigma, mean, sd


def _curve(ax, summary, deviations, estimator: Estimator, registration, column, shift, **style) -> None:
    sigma, mean, sd = _points(summary, deviations, str(estimator.method), estimator.weight, registration, column)
    if sigma.size:
        ax.errorbar(sigma + shift, mean, yerr=sd, capsize=2, markersize=4, linewidth=1.2, **style)


def _axes(ax, title: str, position: bool) -> None:
    ax.set_title(title, fontsize=_TITLE_PT)
    ax.set_xlabel(_POS_X if position else _ROT_X)
    ax.set_ylabel(_POS_Y if position else _ROT_Y)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7)


def _shift(result: StudyResult) -> float:
    """Horizontal offset between curves of one panel [mm or deg]."""
    return 0.08 * result.config.max_sigma / max(result.config.levels - 1, 1)


def _main_set(result: StudyResult) -> str:
    return "large" if "large" in result.config.deviations else result.config.deviations[0]


def _has(result: StudyResult, *estimators: Estimator) -> bool:
    return all(e in result.config.estimators for e in estimators)


def _overhang_in(ax, width_in: float) -> float:
    """How far [in] the title of ``ax`` (centred on it) reaches past each side of the panel."""
    # Agg's hinting rounds each glyph's advance to whole pixels: a 9 pt title drawn measured up to 3.5 % wider
    # than the font's metrics at 100 dpi (the figure's), 1.3 % at 110 (the PNG's)
    title = 1.05 * label_width_in(ax.get_title().split("\n"), _TITLE_PT)
    return 0.5 * (title - ax.get_position().width * width_in)


def _fix_margins(fig) -> None:
    """Margins and panel spacing of a grid of panels sized from their labels, without a draw
    (:mod:`pincal.figure_margins`): left of a column, its y tick labels and axis label, or the
    part of a title wider than its panel; right of a column, half a last x tick label or that
    part of a title; between rows, the upper row's x labels and the lower row's title. The y
    ticks follow the panels' size (matplotlib's locator fits their number to it) and the
    titles' overhang too, so the margins are set until they settle (within 0.01 in; twice or thrice)."""
    specs = {ax: spec for ax in fig.axes if (spec := ax.get_subplotspec()) is not None}
    if not specs:  # no grid of panels: nothing to lay out
        return
    width, height = fig.get_size_inches()
    rows, cols = next(iter(specs.values())).get_gridspec().get_geometry()
    lines = max(ax.get_title().count("\n") + 1 for ax in specs)
    # above the panels: the title's pad and lines (matplotlib's line spacing, 1.2 × the font size)
    top = (plt.rcParams["axes.titlepad"] + lines * 1.2 * _TITLE_PT) / 72.0 + _PAD_IN
    margins: dict[str, float] = {}
    for _ in range(4):
        lefts, rights = [0.0] * cols, [RIGHT_IN] * cols
        for ax, spec in specs.items():
            overhang = _overhang_in(ax, width) + _PAD_IN
            c = spec.colspan.start
            lefts[c] = max(lefts[c], y_label_room_in(ax), overhang)
            rights[c] = max(rights[c], overhang)
        gap = max((rights[c - 1] + lefts[c] for c in range(1, cols)), default=0.0)
        # between rows: the upper row's x labels and the lower row's title, the edges' padding once, not twice
        settled = grid_margins((width, height), (rows, cols), left_in=lefts[0], right_in=rights[-1], top_in=top,
                               bottom_in=BOTTOM_10PT_IN, gaps_in=(gap, BOTTOM_10PT_IN + top - _PAD_IN))
        if margins and all(abs(settled[key] - margins[key]) < 1e-3 for key in settled):  # within 0.01 in
            return
        margins = settled
        fig.subplots_adjust(**margins)


def _save(fig, path: Path) -> Path:
    _fix_margins(fig)
    with replacing(path, "wb") as handle:
        fig.savefig(handle, format="png", dpi=_DPI)
    plt.close(fig)
    return path


def figure2(result: StudyResult, path: Path) -> Path | None:
    """Figure 2: per-pose errors q_j [mm] and eta_j [deg] of Methods 1 and 2, one noise realisation."""
    if not result.figure2:
        return None
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 3.8))
    colours = {"1": "black", "2": "tab:blue"}
    for entry in result.figure2:
        j = np.arange(1, len(entry["q_mm"]) + 1)
        label = f"Method {entry['method']}"
        a.plot(j, entry["q_mm"], "o-", color=colours[entry["method"]], markersize=3, label=label)
        rotation = "Reg 1" if entry["method"] == "1" else "Reg 2"
        b.plot(j, entry["eta_deg"], "o-", color=colours[entry["method"]], markersize=3, label=f"{label} ({rotation})")
    entry = result.figure2[0]
    where = (f"{entry['deviations']} deviations, σ_p = {entry['sigma_pos_mm']} mm, "
             f"σ_a = {entry['sigma_rot_deg']}°, realisation {entry['repeat']}")
    for ax, title, ylabel in ((a, "(a) position errors q_j (Registration 1)", "q_j [mm]"),
                              (b, "(b) orientation errors η_j", "η_j [deg]")):
        ax.set_title(f"{title}\n{where}", fontsize=_TITLE_PT)
        ax.set_xlabel("test pose j")
        ax.set_ylabel(ylabel)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
    return _save(fig, path)


def _registration_panels(result, axes, deviations: str, estimator: Estimator, letters: Sequence[str]) -> None:
    """Position (a) and orientation (b) panels, Registration 1 vs 2, for one estimator."""
    shift = _shift(result)
    for ax, column, position, letter in zip(axes, ("pos_mean_mm", "rot_mean_deg"), (True, False), letters):
        for registration in (1, 2):
            _curve(ax, result.summary, deviations, estimator, registration, column,
                   (registration - 1.5) * shift, color=_REGISTRATION_COLOURS[registration], marker="o",
                   label=f"Registration {registration}")
        _axes(ax, f"({letter}) {estimator.label}, {deviations} deviations", position)


def figure3(result: StudyResult, path: Path) -> Path | None:
    """Figure 3: Registration 1 vs 2 for Method 2, each deviation set."""
    if not _has(result, Estimator(2)):
        return None
    sets = result.config.deviations
    fig, axes = plt.subplots(len(sets), 2, figsize=(10, 3.8 * len(sets)), squeeze=False)
    letters = "abcdefgh"
    for row, deviations in enumerate(sets):
        _registration_panels(result, axes[row], deviations, Estimator(2), letters[2 * row: 2 * row + 2])
    return _save(fig, path)


def figure4(result: StudyResult, path: Path) -> Path | None:
    """Figure 4: Registration 1 vs 2 for Method 3 (w = 1), large deviations."""
    if not _has(result, Estimator(3, 1.0)):
        return None
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    _registration_panels(result, axes, _main_set(result), Estimator(3, 1.0), "ab")
    return _save(fig, path)


def _compare(ax, result, deviations, curves, column, position, title) -> None:
    """Curves = [(estimator, registration, colour, marker)] of one panel."""
    shift = _shift(result)
    for i, (estimator, registration, colour, marker) in enumerate(curves):
        _curve(ax, result.summary, deviations, estimator, registration, column,
               (i - (len(curves) - 1) / 2) * shift, color=colour, marker=marker,
               label=f"{estimator.label}, Registration {registration}")
    _axes(ax, title, position)


def figure5(result: StudyResult, path: Path) -> Path | None:
    """Figure 5: Methods 1, 2, 3 (w = 1) compared, large deviations.

    (a, b) Method 1 vs Method 2 (positions via Registration 1, orientations via
    Registration 2); (c, d) Method 2 vs Method 3 with the same registrations.
    """
    m1, m2, m3 = Estimator(1), Estimator(2), Estimator(3, 1.0)
    if not _has(result, m1, m2, m3):
        return None
    d = _main_set(result)
    fig, axes = plt.subplots(2, 2, figsize=(10, 7.6))
    _compare(axes[0, 0], result, d, [(m1, 1, "black", "s"), (m2, 1, "tab:blue", "o")], "pos_mean_mm", True,
             f"(a) Methods 1 and 2, {d} deviations")
    _compare(axes[0, 1], result, d, [(m1, 1, "black", "s"), (m2, 2, "tab:red", "o")], "rot_mean_deg", False,
             "(b) Methods 1 and 2 (σ = σ_p for Method 1)")
    _compare(axes[1, 0], result, d, [(m2, 1, "tab:blue", "o"), (m3, 1, "tab:blue", "^")], "pos_mean_mm", True,
             "(c) Methods 2 and 3, Registration 1")
    _compare(axes[1, 1], result, d, [(m2, 2, "tab:red", "o"), (m3, 2, "tab:red", "^")], "rot_mean_deg", False,
             "(d) Methods 2 and 3, Registration 2")
    return _save(fig, path)


def figure6(result: StudyResult, path: Path) -> Path | None:
    """Figure 6: Method 3 with two weights w, large deviations."""
    weights = [e for e in result.config.estimators if e.method == 3]
    if len(weights) < 2:
        return None
    d = _main_set(result)
    colours = ("tab:green", "tab:purple", "tab:orange", "tab:brown")
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 3.8))
    _compare(a, result, d, [(e, 1, c, "o") for e, c in zip(weights, colours)], "pos_mean_mm", True,
             f"(a) Method 3, two weights w [mm²/deg²], Registration 1, {d} deviations")
    _compare(b, result, d, [(e, 2, c, "o") for e, c in zip(weights, colours)], "rot_mean_deg", False,
             "(b) Method 3, two weights w [mm²/deg²], Registration 2")
    return _save(fig, path)


def figure_noise_limit(result: StudyResult, path: Path) -> Path | None:
    """Each estimator's error against the noise-free truth vs its linearised noise limit (dashed)."""
    sets = result.config.deviations
    fig, axes = plt.subplots(len(sets), 2, figsize=(11, 4.2 * len(sets)), squeeze=False)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    shift = _shift(result)
    for row, deviations in enumerate(sets):
        for col, (column, limit, position) in enumerate(
            (("pos_truth_mean_mm", "limit_pos_mm", True), ("rot_truth_mean_deg", "limit_rot_deg", False))
        ):
            ax = axes[row, col]
            for i, estimator in enumerate(result.config.estimators):
                registration = 1 if position or estimator.method == 1 else 2
                colour = colours[i % len(colours)]
                _curve(ax, result.summary, deviations, estimator, registration, column,
                       (i - 2) * shift / 2, color=colour, marker="o", linestyle="none",
                       label=f"{estimator.label} (Monte Carlo)")
                sigma, predicted, _ = _points(result.summary, deviations, str(estimator.method),
                                              estimator.weight, registration, limit)
                ax.plot(sigma, predicted, "--", color=colour, linewidth=1, label=f"{estimator.label} (limit)")
            kind = "position, Registration 1" if position else "orientation, Registration 2 (Method 1: 1)"
            _axes(ax, f"{deviations} deviations, {kind}", position)
            ax.set_ylabel((_POS_Y if position else _ROT_Y).replace("error", "error vs truth"))
    return _save(fig, path)


def figure_ml(result: StudyResult, path: Path) -> Path | None:
    """The ML estimator vs Method 2: noisy test measurements (solid) and noise-free truth (dashed)."""
    ml, m2 = Estimator("ml"), Estimator(2)
    if not _has(result, ml, m2):
        return None
    d = _main_set(result)
    shift = _shift(result)
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 3.8))
    for ax, registration, position, columns in (
        (a, 1, True, ("pos_mean_mm", "pos_truth_mean_mm")),
        (b, 2, False, ("rot_mean_deg", "rot_truth_mean_deg")),
    ):
        for i, (estimator, colour) in enumerate(((m2, "tab:blue"), (ml, "tab:orange"))):
            for column, style, what in ((columns[0], "-", "noisy test data"), (columns[1], "--", "vs truth")):
                _curve(ax, result.summary, d, estimator, registration, column, (i - 0.5) * shift,
                       color=colour, marker="o", linestyle=style, label=f"{estimator.label}, {what}")
        _axes(ax, f"({'a' if position else 'b'}) ML estimator vs Method 2, Registration {registration}, "
                  f"{d} deviations", position)
    return _save(fig, path)


#: File name → figure function.
FIGURES: dict[str, Any] = {
    "fig2_per_pose_errors.png": figure2,
    "fig3_registrations_method2.png": figure3,
    "fig4_registrations_method3.png": figure4,
    "fig5_methods.png": figure5,
    "fig6_method3_weights.png": figure6,
    "fig_noise_limit.png": figure_noise_limit,
    "fig_ml_vs_method2.png": figure_ml,
}


#: The figures, the longest to draw first (measured: fig_noise_limit ~27 % of the drawing time,
#: fig3 and fig5 ~18 % each, the others ~9 % each), so that the processes finish close together.
_LONGEST_FIRST = ("fig_noise_limit.png", "fig3_registrations_method2.png", "fig5_methods.png",
                  "fig_ml_vs_method2.png", "fig2_per_pose_errors.png", "fig4_registrations_method3.png",
                  "fig6_method3_weights.png")


def _draw(name: str, result: StudyResult, out: Path) -> Path | None:
    """Draw the figure ``name`` of :data:`FIGURES` into ``out`` (module level: a worker process runs it)."""
    return FIGURES[name](result, out / name)


def _forked_pool(workers: int) -> ProcessPoolExecutor | None:
    """``workers`` processes forked from this one (they start with matplotlib imported), or None
    where a fork is not safe (:func:`pincal.study.executors.fork_is_safe`) or not asked for."""
    if workers < 2 or not fork_is_safe():
        return None
    return ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("fork"))


def start_figures(result: StudyResult, out_dir: str | Path, workers: int = 1) -> Callable[[], list[Path]]:
    """Start drawing every figure the study's estimators allow into ``out_dir``.

    Args:
        result: the study.
        out_dir: the folder of the PNG files (created).
        workers: processes drawing the figures; with more than one (and a safe fork:
            :func:`_forked_pool`) they draw while this process goes on, else the
            returned function draws them here.

    Returns:
        A function that waits for the figures and returns the PNG paths, in :data:`FIGURES` order.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)

    def here() -> list[Path]:
        return [path for name in FIGURES if (path := _draw(name, result, out)) is not None]

    pool = _forked_pool(min(workers, len(FIGURES)))
    if pool is None:
        return here
    figures_only = dataclasses.replace(result, rows=[], limits=[], restarts=[])  # what the figures read
    try:
        futures = {name: pool.submit(_draw, name, figures_only, out) for name in _LONGEST_FIRST}
    except (OSError, BrokenProcessPool):  # the fork itself failed (process or memory limits): draw here
        pool.shutdown(cancel_futures=True)
        return here

    def wait() -> list[Path]:
        try:
            drawn = {name: future.result() for name, future in futures.items()}
        except BrokenProcessPool:  # a drawing process died (out of memory?): draw them all here
            return here()
        finally:
            pool.shutdown(cancel_futures=True)
        return [path for name in FIGURES if (path := drawn[name]) is not None]

    return wait


def write_figures(result: StudyResult, out_dir: str | Path, workers: int = 1) -> list[Path]:
    """Draw every figure the study's estimators allow into ``out_dir``; returns the PNG paths
    (``workers``: see :func:`start_figures`)."""
    return start_figures(result, out_dir, workers)()
