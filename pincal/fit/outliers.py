"""Rows whose residual is far outside the others.

Each row's position error is the RMS distance of its target points from the
model [m], its orientation error (6D rows) the angle of its orientation
residual [rad]. For each kind of error, with the median m and the MAD-based
robust standard deviation s = 1.4826 · median(|e − m|) (Hampel 1974), a row is
an outlier when (e − m) / s > :data:`OUTLIER_THRESHOLD` and its excess e − m is
larger than the kind's floor (:data:`OUTLIER_FLOOR_M`, :data:`OUTLIER_FLOOR_RAD`):
on noise-free data the residuals are rounding noise, whose robust scores mean
nothing. The two kinds are scored apart — a row whose orientation alone is
wrong (a rigid body's markers matched the wrong way round) keeps a position
error like the others', and the orientation noise scale it inflates would
hide it in a joint score.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

__all__ = [
    "OUTLIER_THRESHOLD", "MAD_TO_SIGMA", "OUTLIER_FLOOR_M", "OUTLIER_FLOOR_RAD", "OutlierError", "RowOutlier",
    "robust_scores", "find_outliers", "find_row_outliers",
]

#: Robust z-score above which a row is reported.
OUTLIER_THRESHOLD = 5.0
MAD_TO_SIGMA = 1.4826
#: Excess over the median below which no row is an outlier [m]: 1 µm, a tenth of a
#: laser tracker's resolution (~10 µm) and far above double-precision rounding.
OUTLIER_FLOOR_M = 1e-6
#: Excess over the median below which no row is an orientation outlier [rad]: 10 µrad (0.0006°), a
#: seventeenth of a 6-DoF laser-tracker probe's orientation accuracy (±0.01°, Leica's T-Mac) and far above rounding.
OUTLIER_FLOOR_RAD = 1e-5

#: Which of a row's errors flags it: the RMS distance of its points or the angle of its orientation.
OutlierError = Literal["position", "orientation"]


@dataclass(frozen=True)
class RowOutlier:
    """A row far outside the others.

    Attributes:
        row: the row's label, as the caller gave it (a file line, or an index into the data).
        score: the robust score (e − m) / s of the error that flags it.
        by: that error: ``position`` or ``orientation``; a row both flag names the higher score's.
    """

    row: int
    score: float
    by: OutlierError


def robust_scores(errors: np.ndarray) -> np.ndarray:
    """(e − median) / (1.4826 · MAD) of per-row errors (K,); zeros if the MAD is 0."""
    errors = np.asarray(errors, dtype=float)
    center = np.median(errors)
    scale = MAD_TO_SIGMA * np.median(np.abs(errors - center))
    if scale <= 0:
        return np.zeros_like(errors)
    return (errors - center) / scale


def _scores(per_row: np.ndarray, floor: float) -> np.ndarray:
    """Each row's robust score where it is an outlier by the rule (module docstring), else −inf, (K,);
    a NaN error (a row without this kind of measurement) is no outlier and no part of the median."""
    out = np.full(per_row.shape, -np.inf)
    known = np.isfinite(per_row)
    if not known.any():
        return out
    values = per_row[known]
    scores = robust_scores(values)
    out[np.flatnonzero(known)] = np.where((scores > OUTLIER_THRESHOLD) & (values - np.median(values) > floor),
                                          scores, -np.inf)
    return out


def find_row_outliers(point_errors: np.ndarray, rows: np.ndarray,
                      rotation_errors: np.ndarray | None = None) -> list[RowOutlier]:
    """The outlier rows, worst first, by their position or their orientation error.

    Args:
        point_errors: distance of each target point from the model [m], (K, P).
        rows: each row's label (its file line, or its index), (K,).
        rotation_errors: each row's orientation error, an angle [rad], (K,); NaN where a row has none;
            None without orientation data.
    """
    per_row = np.sqrt(np.mean(np.asarray(point_errors, dtype=float) ** 2, axis=1))
    position = _scores(per_row, OUTLIER_FLOOR_M)
    orientation = (np.full(per_row.shape, -np.inf) if rotation_errors is None else
                   _scores(np.asarray(rotation_errors, dtype=float).reshape(-1), OUTLIER_FLOOR_RAD))
    best = np.maximum(position, orientation)
    flagged = np.flatnonzero(np.isfinite(best))
    flagged = flagged[np.argsort(-best[flagged])]
    return [RowOutlier(int(rows[i]), float(best[i]), "position" if position[i] >= orientation[i] else "orientation")
            for i in flagged]


def find_outliers(point_errors: np.ndarray, lines: np.ndarray) -> list[tuple[int, float]]:
    """(file line, robust score) of the rows whose position error flags them, worst first
    (:func:`find_row_outliers` without orientations).

    Args:
        point_errors: distance of each target point from the model [m], (K, P).
        lines: file line of each row, (K,).
    """
    return [(o.row, o.score) for o in find_row_outliers(point_errors, lines)]
