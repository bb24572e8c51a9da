"""Rows whose residual is far outside the others.

Each row's error is the RMS distance of its target points from the model
[m]. With the median m and the MAD-based robust standard deviation
s = 1.4826 · median(|e − m|) (Hampel 1974), a row is an outlier when
(e − m) / s > :data:`OUTLIER_THRESHOLD` and its excess e − m is larger than
:data:`OUTLIER_FLOOR_M`: on noise-free data the residuals are rounding noise,
whose robust scores mean nothing.
"""

from __future__ import annotations

import numpy as np

__all__ = ["OUTLIER_THRESHOLD", "MAD_TO_SIGMA", "OUTLIER_FLOOR_M", "robust_scores", "find_outliers"]

#: Robust z-score above which a row is reported.
OUTLIER_THRESHOLD = 5.0
MAD_TO_SIGMA = 1.4826
#: Excess over the median below which no row is an outlier [m]: 1 µm, a tenth of a
#: laser tracker's resolution (~10 µm) and far above double-precision rounding.
OUTLIER_FLOOR_M = 1e-6


def robust_scores(errors: np.ndarray) -> np.ndarray:
    """(e − median) / (1.4826 · MAD) of per-row errors (K,); zeros if the MAD is 0."""
    errors = np.asarray(errors, dtype=float)
    center = np.median(errors)
    scale = MAD_TO_SIGMA * np.median(np.abs(errors - center))
    if scale <= 0:
        return np.zeros_like(errors)
    return (errors - center) / scale


def find_outliers(point_errors: np.ndarray, lines: np.ndarray) -> list[tuple[int, float]]:
    """(file line, robust score) of outlier rows, worst first.

    Args:
        point_errors: distance of each target point from the model [m], (K, P).
        lines: file line of each row, (K,).
    """
    per_row = np.sqrt(np.mean(np.asarray(point_errors, dtype=float) ** 2, axis=1))
    scores = robust_scores(per_row)
    excess = per_row - np.median(per_row)
    flagged = np.flatnonzero((scores > OUTLIER_THRESHOLD) & (excess > OUTLIER_FLOOR_M))
    flagged = flagged[np.argsort(-scores[flagged])]
    return [(int(lines[i]), float(scores[i])) for i in flagged]
