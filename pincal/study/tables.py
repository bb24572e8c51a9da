"""The tables of a simulation study: their columns, eq 25 over the repeats, the noise-limit table.

Rows come from :mod:`pincal.study.tasks`: one per (deviations, level, repeat,
method, weight, registration) for the trials, one per random start for the
restart test. :func:`summarize` averages the trials over the repeats (eq 25)
beside the noise limit, :func:`limit_table` sets estimator and limit side by
side, :func:`summarize_restarts` counts the restarts reaching the solution.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from pincal.study.estimators import Estimator
from pincal.study.findings import PAPER_MAX_DEVIATIONS

__all__ = ["STUDY_COLUMNS", "SUMMARY_COLUMNS", "RESTART_COLUMNS", "summarize", "limit_table", "summarize_restarts"]

# The key of an eq 25 group (a summary row), and the eq 24 means averaged over its repeats.
_GROUP = ("deviations", "level", "sigma_pos_mm", "sigma_rot_deg", "method", "weight", "registration")
_AVERAGED = ("pos_mean_mm", "rot_mean_deg", "pos_truth_mean_mm", "rot_truth_mean_deg")

#: Columns of study.csv, one row per (deviations, level, repeat, method, weight, registration).
STUDY_COLUMNS = (
    *_GROUP[:4], "repeat", "seed", *_GROUP[4:], *_AVERAGED, "fit_ms", *PAPER_MAX_DEVIATIONS,
)
#: Columns of summary.csv: eq 25 and the noise limit.
SUMMARY_COLUMNS = (
    *_GROUP, "n_repeats", *(c for column in _AVERAGED for c in (column, column + "_sd")),
    "limit_pos_mm", "limit_pos_mm_sd", "pos_truth_over_limit",
    "limit_rot_deg", "limit_rot_deg_sd", "rot_truth_over_limit", "fit_ms_median", *PAPER_MAX_DEVIATIONS,
)
#: Columns of restarts.csv, one row per restart.
RESTART_COLUMNS = (
    "case", "deviations", "level", "sigma_pos_mm", "sigma_rot_deg", "repeat", "seed", "method", "weight",
    "start", "same_solution", "max_deps_deg", "max_dlength_mm", "error",
)


def _grouped(rows: Sequence[dict[str, Any]], fields: Sequence[str]) -> dict[tuple, list[dict[str, Any]]]:
    """``rows`` by their values of ``fields``, groups and members in first-seen order."""
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for row in rows:
        groups.setdefault(tuple(row[k] for k in fields), []).append(row)
    return groups


def _ratio(a: float, b: float) -> float:
    return float(a / b) if b > 0 else math.nan


def summarize(rows: Sequence[dict[str, Any]], limits: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Eq 25 over repeats, per (deviations, level, method, weight, registration).

    For each error column c: ``c`` (mean) and ``c_sd`` (standard deviation with
    1/N_rep). ``limit_pos_mm`` (on Registration 1 rows) and ``limit_rot_deg``
    (on Registration 2 rows; Method 1: Registration 1) are the noise limit,
    sigma times its mean over the pose sets, ``limit_*_sd`` its spread over
    them (1/L), and ``*_truth_over_limit`` how far the estimator is from it
    (1 = at the limit); NaN where the limit does not apply.
    """
    unit: dict[tuple, list] = {}
    for entry in limits:
        key = (entry["deviations"], entry["method"], entry["weight"])
        unit.setdefault(key, []).append((entry["pos_mm_per_unit_sigma"], entry["rot_deg_per_unit_sigma"]))
    summary = []
    for key, members in _grouped(rows, _GROUP).items():
        out = dict(zip(_GROUP, key))
        out["n_repeats"] = len(members)
        for column in _AVERAGED:
            values = np.array([m[column] for m in members])
            out[column], out[column + "_sd"] = float(values.mean()), float(values.std())
        per_set = np.array(unit.get((out["deviations"], out["method"], out["weight"]), [(math.nan, math.nan)]))
        sigma = out["sigma_pos_mm"]
        orientation = Estimator.of(out["method"], out["weight"]).orientation_registration
        for i, limit, measured, ratio, applies in (
            (0, "limit_pos_mm", "pos_truth_mean_mm", "pos_truth_over_limit", out["registration"] == 1),
            (1, "limit_rot_deg", "rot_truth_mean_deg", "rot_truth_over_limit", out["registration"] == orientation),
        ):
            out[limit] = float(sigma * per_set[:, i].mean()) if applies else math.nan
            out[limit + "_sd"] = float(sigma * per_set[:, i].std()) if applies else math.nan
            out[ratio] = _ratio(out[measured], out[limit])
        out["fit_ms_median"] = float(np.median([m["fit_ms"] for m in members]))
        for column in PAPER_MAX_DEVIATIONS:
            out[column] = float(max(m[column] for m in members))
        summary.append(out)
    return summary


def limit_table(summary: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """The estimator-vs-limit table: Monte Carlo (against the noise-free truth) beside the prediction.

    One row per (deviations, level, estimator): position through Registration 1,
    orientation through Registration 2 (Method 1: Registration 1).
    """
    index = {tuple(s[k] for k in _GROUP): s for s in summary}
    table = []
    for key, position in index.items():
        if position["registration"] != 1:
            continue
        estimator = Estimator.of(position["method"], position["weight"])
        orientation = index[key[:-1] + (estimator.orientation_registration,)]
        table.append({
            **{k: position[k] for k in _GROUP[:-1]},
            **{c: position[c] for c in ("pos_truth_mean_mm", "pos_truth_mean_mm_sd", "limit_pos_mm",
                                        "limit_pos_mm_sd", "pos_truth_over_limit")},
            **{c: orientation[c] for c in ("rot_truth_mean_deg", "rot_truth_mean_deg_sd", "limit_rot_deg",
                                           "limit_rot_deg_sd", "rot_truth_over_limit")},
        })
    return table


def summarize_restarts(restarts: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per restart case and estimator: how many starts reached the nominal start's solution."""
    fields = ("case", "deviations", "level", "sigma_pos_mm", "repeat", "seed", "method", "weight")
    table = []
    for key, members in _grouped(restarts, fields).items():
        converged = [m for m in members if not m["error"]]
        table.append({
            **dict(zip(fields, key)),
            "starts": len(members),
            "same_solution": sum(m["same_solution"] for m in members),
            "failed": len(members) - len(converged),
            "max_deps_deg": max((m["max_deps_deg"] for m in converged), default=math.nan),
            "max_dlength_mm": max((m["max_dlength_mm"] for m in converged), default=math.nan),
        })
    return table
