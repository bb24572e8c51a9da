"""The files of a simulation study: study.csv, summary.csv, restarts.csv, findings.md, study.json.

:func:`write_study` writes them all, and the figures of
:mod:`pincal.study.figures` (matplotlib is imported only then), drawn by
other processes while this one writes the tables. CSV cells
hold floats at full precision and None as an empty cell; study.json is
strict JSON (NaN and infinities as null).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from pincal.outputs import write_text
from pincal.study.estimators import Estimator
from pincal.study.executors import default_workers
from pincal.study.findings import ML_COLUMNS, PAPER_MAX_DEVIATIONS
from pincal.study.protocol import (
    RESTART_SPREAD_DEG,
    RESTART_SPREAD_MM,
    SAME_SOLUTION_DEG,
    SAME_SOLUTION_MM,
)
from pincal.study.tables import (
    RESTART_COLUMNS,
    STUDY_COLUMNS,
    SUMMARY_COLUMNS,
    limit_table,
)
from pincal.study.tasks import ABLATION_REPEATS, ABLATION_SUFFIX, ablation_levels

if TYPE_CHECKING:
    from pincal.study.result import StudyResult

__all__ = ["write_csv", "study_json", "write_study", "findings_markdown"]


def _cell(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return repr(value)  # full precision; nan as nan
    return str(value)


def write_csv(path: Path, rows: Sequence[dict[str, Any]], columns: Sequence[str]) -> None:
    """Write ``rows`` with ``columns`` in order (None as an empty cell, floats at full precision)."""
    lines = [",".join(columns)] + [",".join(_cell(row[c]) for c in columns) for row in rows]
    write_text(path, "\n".join(lines) + "\n")


def _json_ready(value: Any) -> Any:
    """Strict JSON: NaN and infinities → None, numpy scalars → Python, recursively."""
    if isinstance(value, dict):
        return {str(k): _json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_ready(v) for v in value]
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    return bool(value) if isinstance(value, np.bool_) else value


def study_json(result: StudyResult) -> dict[str, Any]:
    """Everything of ``result``, ready for :func:`json.dumps`."""
    config = result.config
    return _json_ready({
        "protocol": {
            "paper": "Franaszek & Marvel 2022, Sections 7-9",
            "deviations": list(config.deviations),
            "sigmas_mm_deg": config.sigmas.tolist(),
            "repeats": config.repeats,
            "estimators": [{"method": str(e.method), "weight": e.weight, "label": e.label}
                           for e in config.estimators],
            "n_cpa": config.n_cpa,
            "n_calibration": config.n_calibration,
            "n_validation": config.n_validation,
            "restarts": config.restarts,
            "restart_cases": config.restart_cases,
            "restart_spread": {"epsilon_deg": RESTART_SPREAD_DEG, "r_d_mm": RESTART_SPREAD_MM},
            "same_solution_tolerance": {"epsilon_deg": SAME_SOLUTION_DEG, "r_d_mm": SAME_SOLUTION_MM},
            "limit_pose_sets": config.limit_pose_sets,
            "entropy": config.entropy,
            "seed_rule": "SeedSequence(entropy, spawn_key=(0, deviation index, level, repeat)) -> uint32",
            "columns": {
                "pos_mean_mm, rot_mean_deg": "eq 24 means against the noisy test measurements (the paper's)",
                "pos_truth_mean_mm, rot_truth_mean_deg": "eq 24 means against the noise-free test poses",
                "limit_pos_mm, limit_rot_deg": "linearised (Cramer-Rao) noise limit against the noise-free "
                                               "truth, positions through Registration 1, orientations through "
                                               "Registration 2 (Method 1: 1); sigma times its mean over the "
                                               "pose sets, _sd its spread over them",
                "*" + ABLATION_SUFFIX: "on the ML estimator's rows of the ablation trials only (not in study.csv): "
                                       "the same eq 24 means for the ML estimator with the CPA rows' "
                                       "orientations withheld (the paper's CPA measures positions only)",
            },
            "cpa_orientation_ablation": {
                "levels": list(ablation_levels(config)),
                "repeats": min(ABLATION_REPEATS, config.repeats),
            },
        },
        "executor": result.executor,
        "wall_s": result.wall_s,
        "findings": result.findings,
        "summary": result.summary,
        "noise_limit_table": limit_table(result.summary),
        "noise_limit_per_pose_set": result.limits,
        "restart_summary": result.restart_summary,
        "figure2": result.figure2,
        "rows": result.rows,
        "restarts": result.restarts,
    })


def write_study(result: StudyResult, out_dir: str | Path, figures: bool = True, workers: int | None = None,
                ) -> dict[str, Any]:
    """Write study.csv, summary.csv, restarts.csv, findings.md, study.json and the figures.

    Args:
        result, out_dir: the study and the folder of its files (created).
        figures: draw the figures.
        workers: processes drawing the figures while this one writes the tables
            (:func:`pincal.study.figures.start_figures`; default all cores, 1 = this process).

    Returns:
        {name: path} of the files written; ``figures`` is the list of PNG paths.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths: dict[str, Any] = {name: out / file for name, file in (
        ("study", "study.csv"), ("summary", "summary.csv"), ("restarts", "restarts.csv"),
        ("findings", "findings.md"), ("json", "study.json"))}
    drawn = None
    if figures:
        from pincal.study.figures import start_figures  # matplotlib only when drawing

        drawn = start_figures(result, out, default_workers() if workers is None else workers)
    try:
        write_csv(paths["study"], result.rows, STUDY_COLUMNS)
        write_csv(paths["summary"], result.summary, SUMMARY_COLUMNS)
        write_csv(paths["restarts"], result.restarts, RESTART_COLUMNS)
        write_text(paths["findings"], findings_markdown(result))
        write_text(paths["json"], json.dumps(study_json(result), indent=1, allow_nan=False) + "\n")
    finally:  # even when a table failed, the drawing processes are waited for (and their errors raised)
        if drawn is not None:
            paths["figures"] = drawn()
    return paths


def _fmt(value: float | None, digits: int = 4) -> str:
    return "–" if value is None or not math.isfinite(value) else f"{value:.{digits}g}"


def _ml_section(result: StudyResult) -> list[str]:
    """findings.md: the ML estimator against Method 2 on both metrics, and the CPA-orientation ablation."""
    finding = next((f for f in result.findings if f["finding"] == "ml_vs_method2"), None)
    if finding is None:
        return [""]
    change, ablation = finding["values"]["percent_change"], finding["values"]["cpa_orientation_ablation"]
    lines = [
        "", "## ML estimator vs Method 2", "",
        "Change of the eq 25 mean error, ML estimator vs Method 2 (negative = ML better), averaged over the "
        "non-zero levels and the deviation sets: on the paper's metric (against the noisy test measurements, "
        "`pos_mean_mm`, `rot_mean_deg`) and against the noise-free truth (`pos_truth_mean_mm`, "
        "`rot_truth_mean_deg`). The noisy test measurements add the same sensor noise to every estimator's "
        "error, so the gain on the paper's metric is smaller.",
        "",
    ]
    if not ablation["trials"]:
        return lines + ["| metric | ML vs Method 2 |", "|---|---|",
                        *(f"| {name} | {change[column]:+.1f} % |" for column, _, name in ML_COLUMNS), ""]
    sigmas = ", ".join(f"{s:g}" for s in ablation["sigmas"])
    lines += [
        "The simulator gives the CPA rows orientations too; the paper's CPA (Section 3) measures positions "
        f"only, so Method 2 never sees them while the ML estimator does. The ablation reruns the ML estimator "
        f"with the CPA rows' orientations withheld, on the same data, on {ablation['trials']} trials (sigma "
        f"{sigmas}, repeats {ablation['repeats'][0]}–{ablation['repeats'][-1]}; its one registration for "
        "positions and orientations, as the ML estimator's). Share = (r_without − r_ML) / (1 − r_ML) of the "
        "ratios r to Method 2 on these trials, ± its standard error from the paired per-trial differences.",
        "",
        "| metric | ML vs Method 2, all levels | on the ablation trials | without the CPA orientations | "
        "share of the gain due to the CPA orientations |",
        "|---|---|---|---|---|",
        *(f"| {name} | {change[column]:+.1f} % | {-ablation['gain'][column]:+.1f} % | "
          f"{-ablation['gain_without'][column]:+.1f} % | {_fmt(ablation['share'][column], 2)} ± "
          f"{_fmt(ablation['share_se'][column], 2)} % |" for column, _, name in ML_COLUMNS),
        "",
    ]
    return lines


def findings_markdown(result: StudyResult) -> str:
    """findings.md: the paper's findings on this run, the estimator-vs-limit and restart tables."""
    config = result.config
    lines = [
        "# Simulation study of Franaszek & Marvel (2022), Sections 7-9",
        "",
        f"KUKA LWR 4+ (Table 1), deviation sets {', '.join(config.deviations)} (Table 2); {config.levels} noise "
        f"levels sigma_p [mm] = sigma_a [deg] from 0 to {config.max_sigma:g}; {config.repeats} repeats; "
        f"K_alpha = {config.n_cpa}, K = {config.n_calibration}, J = {config.n_validation}; "
        f"{len(result.rows)} result rows; {result.executor}, {result.wall_s:.1f} s.",
        "",
        "Estimators: " + ", ".join(e.label for e in config.estimators) + " (w in mm²/deg², eq 18). Errors "
        "are eq 24 means over the J test poses, averaged over the repeats (eq 25). *Noisy*: against the noisy "
        "test measurements (`pos_mean_mm`, `rot_mean_deg`; the paper's metric). *Truth*: against the "
        "noise-free test poses (`pos_truth_mean_mm`, `rot_truth_mean_deg`; what the noise limit predicts). "
        "The findings compare the noisy means at the non-zero levels.",
        "",
        "## Findings",
        "",
        "| finding | paper | holds here | evidence |",
        "|---|---|---|---|",
        *(f"| `{f['finding']}` | {f['paper']} | {'yes' if f['holds'] else '**no**'} | {f['evidence']} |"
          for f in result.findings),
        *_ml_section(result),
        "## Estimators vs the noise limit",
        "",
        "Error against the noise-free truth (mean ± sd over the repeats, eq 25) beside the linearised "
        "(Cramér–Rao) prediction; positions through Registration 1, orientations through Registration 2 "
        "(Method 1: Registration 1). Ratio 1 = at the limit.",
        "",
        "| deviations | sigma | estimator | pos [mm] | limit [mm] | ratio | rot [deg] | limit [deg] | ratio |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    table = limit_table(result.summary)
    nonzero = [level for level in range(config.levels) if config.sigmas[level] > 0]
    shown = {nonzero[0], nonzero[len(nonzero) // 2], nonzero[-1]} if nonzero else set()
    for row in table:
        if row["level"] in shown:
            label = Estimator.of(row["method"], row["weight"]).label
            lines.append(
                f"| {row['deviations']} | {row['sigma_pos_mm']:.3g} | {label} "
                f"| {_fmt(row['pos_truth_mean_mm'])} ± {_fmt(row['pos_truth_mean_mm_sd'], 2)} "
                f"| {_fmt(row['limit_pos_mm'])} | {_fmt(row['pos_truth_over_limit'], 3)} "
                f"| {_fmt(row['rot_truth_mean_deg'])} ± {_fmt(row['rot_truth_mean_deg_sd'], 2)} "
                f"| {_fmt(row['limit_rot_deg'])} | {_fmt(row['rot_truth_over_limit'], 3)} |"
            )
    lines += ["", "Mean ratio to the limit over the non-zero levels:", "",
              "| deviations | estimator | position | orientation |", "|---|---|---|---|"]
    for deviations in config.deviations:
        for estimator in config.estimators:
            picked = [r for r in table if r["deviations"] == deviations and r["sigma_pos_mm"] > 0
                      and Estimator.of(r["method"], r["weight"]) == estimator]
            pos = np.mean([r["pos_truth_over_limit"] for r in picked]) if picked else math.nan
            rot = np.mean([r["rot_truth_over_limit"] for r in picked]) if picked else math.nan
            lines.append(f"| {deviations} | {estimator.label} | {_fmt(pos, 3)} | {_fmt(rot, 3)} |")
    if result.restart_summary:
        lines += [
            "", "## Restart test", "",
            f"Starts uniform ±{RESTART_SPREAD_DEG:g} deg (eps) and ±{RESTART_SPREAD_MM:g} mm (r, d) around "
            f"Table 1, seeded; same solution = eps within {SAME_SOLUTION_DEG:g} deg and r, d within "
            f"{SAME_SOLUTION_MM:g} mm of the fit from Table 1.", "",
            "| case | deviations | sigma | repeat | seed | estimator | same / starts | failed | "
            "largest eps diff [deg] | largest r,d diff [mm] |",
            "|---|---|---|---|---|---|---|---|---|---|",
            *(f"| {r['case']} | {r['deviations']} | {r['sigma_pos_mm']:.3g} | {r['repeat']} | {r['seed']} | "
              f"{Estimator.of(r['method'], r['weight']).label} | {r['same_solution']} / {r['starts']} | "
              f"{r['failed']} | {_fmt(r['max_deps_deg'], 2)} | {_fmt(r['max_dlength_mm'], 2)} |"
              for r in result.restart_summary),
        ]
    largest = next(f for f in result.findings if f["finding"] == "largest_parameter_deviations")
    lines += [
        "", "## Largest parameter deviations from the ground truth", "",
        "| estimator | δα [deg] | δε [deg] | δr [mm] | δd [mm] |", "|---|---|---|---|---|",
        "| paper (Section 8) | " + " | ".join(f"{v:g}" for v in PAPER_MAX_DEVIATIONS.values()) + " |",
        *(f"| {label} | " + " | ".join(_fmt(values[c], 3) for c in PAPER_MAX_DEVIATIONS) + " |"
          for label, values in largest["values"]["by_estimator"].items()),
        "",
    ]
    return "\n".join(lines)
