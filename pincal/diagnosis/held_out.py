"""Whether an effect makes held-out rows better beyond their noise: a signed-rank test over the rows.

``diagnose --validation`` adopts an effect only when the held-out rows fit better with it
(:func:`held_out_verdict`); :mod:`pincal.diagnosis.verdicts` applies it as the last of its checks.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.special

from pincal.fit.metrics import PoseErrors

__all__ = ["HELD_OUT_Z", "HELD_OUT_LEVEL", "MIN_PAIRED_ROWS", "TELLING_CHANGE", "EXACT_ROWS", "fitted_scales",
           "row_changes", "held_out_verdict", "signed_rank_p"]

#: The held-out test's level in standard normal units: an effect is adopted when its rows are better at the
#: one-sided level Φ(−2) = 2.3 % (:data:`HELD_OUT_LEVEL`), the level of the two standard errors of the mean
#: paired test this signed-rank test replaced (:func:`held_out_verdict`).
HELD_OUT_Z = 2.0
#: One-sided level of the held-out signed-rank test: Φ(−:data:`HELD_OUT_Z`) = 0.0228.
HELD_OUT_LEVEL = 0.5 * math.erfc(HELD_OUT_Z / math.sqrt(2.0))
#: Held-out rows below which the signed-rank test cannot reach :data:`HELD_OUT_LEVEL` — its smallest
#: one-sided p is 2⁻ⁿ, 1/64 = 0.016 at six rows, 1/32 = 0.031 at five: the veto is then a worse total.
MIN_PAIRED_ROWS = int(np.ceil(-np.log2(HELD_OUT_LEVEL)))
#: Rows up to which the signed-rank test takes the exact distribution of its statistic, as scipy.stats.wilcoxon
#: does (:func:`signed_rank_p`); its normal approximation beyond.
EXACT_ROWS = 50
#: Change of a held-out row's error [noise units: σ of one coordinate] below which the row cannot tell the two
#: models apart: one σ, the resolution of a single measurement of it.
TELLING_CHANGE = 1.0


def fitted_scales(errors: PoseErrors) -> tuple[float, float | None]:
    """The noise scales per axis a fit's own errors give (maximum likelihood): σ_pos = √(mean |e|² / 3) [m],
    σ_rot = √(mean η² / 3) [rad] (None without orientations)."""
    rotation = None if errors.rotation_rad is None else float(np.sqrt(np.mean(errors.rotation_rad**2) / 3.0))
    return float(np.sqrt(np.mean(errors.position_m**2) / 3.0)), rotation


def row_changes(before: PoseErrors, after: PoseErrors, sigma_pos_m: float, sigma_rot_rad: float | None) -> np.ndarray:
    """The change of each held-out row's error from ``before`` to ``after`` in units of the noise (K,):
    d_k = Σ_p (|e'_kp| − |e_kp|) / σ_pos + (η'_k − η_k) / σ_rot (the orientation term with 6D rows). The
    distance, not its square: |e'|² − |e|² = (|e'| − |e|)(|e'| + |e|) grows with the row's own error, so a row
    a metre off (a bad measurement) would change ten thousand times more than a row at the noise for the same
    change of the model; the change of distance is the model's own change along the row's error."""
    change = (np.sum(after.position_m, axis=1) - np.sum(before.position_m, axis=1)) / sigma_pos_m
    if before.rotation_rad is not None and after.rotation_rad is not None and sigma_rot_rad:
        change = change + (_per_row(after.rotation_rad) - _per_row(before.rotation_rad)) / sigma_rot_rad
    return change


def _per_row(angles: np.ndarray) -> np.ndarray:
    """η_k of each row (K,): the row's angle, or with several targets (K, T) the sum of its seen ones' (a target
    not seen, NaN, changes nothing), as the points' distances are summed."""
    return angles if angles.ndim == 1 else np.nansum(angles, axis=1)


def _rms_mrad(angles: np.ndarray) -> float:
    """The RMS of the seen angles [mrad]: per row, or per (row, target) with several targets."""
    return 1e3 * float(np.sqrt(np.nanmean(angles**2)))


def held_out_verdict(before: PoseErrors, after: PoseErrors, sigma_pos_m: float, sigma_rot_rad: float | None) -> str:
    """``adopted`` when the held-out rows fit better beyond their noise, else why not (judged on
    held-out poses in position and orientation).

    The per-row changes d_k of :func:`row_changes` (position and orientation together in noise units, so a trade
    of a little orientation for much position counts as what it is) are tested by Wilcoxon's signed-rank test
    (Wilcoxon 1945; :func:`signed_rank_p`, rows without a change left out) at the
    one-sided level :data:`HELD_OUT_LEVEL`:

    * worse, when all rows' changes lie above zero, or those of the rows it moves by at least
      :data:`TELLING_CHANGE` noise units (the rows that can tell the two models apart);
    * adopted, when those rows' changes lie below zero;
    * with fewer than :data:`MIN_PAIRED_ROWS` such rows the test cannot reach its level: adopted unless the
      rows' errors grow in total (Σ d_k > 0) — rows the effect barely moves cannot refute it, and the calibration
      rows' evidence stands (circle point analysis moves one joint at a time: two held-out rows of twelve see an
      effect of one joint);
    * not beyond the noise otherwise.

    A rank test, not the mean of the d_k: each row weighs by the rank of its change, so two rows with errors of a
    metre cannot outweigh ten that improve (the mean of the squared changes they dominated refused a coupling that
    brought ten of twelve rows from 300 mm to 0.1 mm). Its noise scales decide which rows can tell: a model a
    hundred times off the data would make none of them (:meth:`pincal.diagnosis.verdicts.Judge.judged_noise`)."""
    change = row_changes(before, after, sigma_pos_m, sigma_rot_rad)
    shown = [f"position {before.position.rms:.3f} → {after.position.rms:.3f} mm RMS"]
    if before.rotation_rad is not None and after.rotation_rad is not None and sigma_rot_rad:
        shown.append(f"orientation {_rms_mrad(before.rotation_rad):.3g} → {_rms_mrad(after.rotation_rad):.3g} mrad RMS")
    nonzero, telling = change[change != 0.0], change[np.abs(change) >= TELLING_CHANGE]
    if nonzero.size >= MIN_PAIRED_ROWS and _p(nonzero, "greater") < HELD_OUT_LEVEL:
        return (f"it makes the held-out rows worse ({', '.join(shown)}; signed-rank over {nonzero.size} rows, "
                f"{np.sum(nonzero > 0)} worse: one-sided p {_p(nonzero, 'greater'):.2g})")
    text = f"{', '.join(shown)}; {telling.size} of {change.size} rows moved by {TELLING_CHANGE:g} noise unit or more"
    if telling.size < MIN_PAIRED_ROWS:  # too few rows for the test to reach its level: only a worse total vetoes
        total = float(np.sum(change))
        return "adopted" if total <= 0 else (f"it makes the held-out rows worse in total ({text}, too few for a "
                                             f"signed-rank test; their errors grow by {total:.3g} noise units)")
    better, worse = _p(telling, "less"), _p(telling, "greater")
    text += f", {np.sum(telling < 0)} better: signed-rank one-sided p {min(better, worse):.2g}"
    if worse < HELD_OUT_LEVEL:
        return f"it makes the held-out rows worse ({text})"
    if better >= HELD_OUT_LEVEL:
        return f"it does not improve the held-out rows beyond their noise ({text})"
    return "adopted"


def _p(change: np.ndarray, alternative: str) -> float:
    """One-sided p of Wilcoxon's signed-rank test that the changes lie below (``less``) or above zero."""
    return signed_rank_p(change, alternative)


def signed_rank_p(change: np.ndarray, alternative: str) -> float:
    """One-sided p of Wilcoxon's signed-rank test (Wilcoxon 1945) that non-zero ``change`` (n,) lies below zero
    (``alternative`` ``less``) or above it (``greater``): the sum R⁺ of the ranks of |change| (ties: their mean
    rank) of the positive changes, against its exact distribution under symmetry — each of the 2ⁿ signs of the
    ranks equally likely, counted over the sums of the doubled ranks (integers) — up to :data:`EXACT_ROWS` rows,
    else its normal approximation, mean n(n+1)/4, variance n(n+1)(2n+1)/24 − Σ(t³ − t)/48 over groups of t tied
    ranks. The p ``scipy.stats.wilcoxon(change, alternative=...)`` gives where it is exact (tests/test_effects.py
    checks it to 1e-12; with ties between 14 and 50 rows scipy samples sign flips at random), written with
    numpy because importing scipy.stats costs 0.6 s of CPU, a sixth of the README's diagnose."""
    change = np.asarray(change, dtype=float)
    _, inverse, counts = np.unique(np.abs(change), return_inverse=True, return_counts=True)
    ranks = (np.cumsum(counts) - (counts - 1) / 2.0)[inverse]  # mean rank of each group of equal |change|
    r_plus, n = float(np.sum(ranks[change > 0])), change.size
    if n <= EXACT_ROWS:  # the exact distribution of 2 R⁺: number of sign choices giving each sum
        doubled = np.rint(2.0 * ranks).astype(int)
        ways = np.zeros(int(doubled.sum()) + 1)
        ways[0] = 1.0
        for rank in doubled:
            ways[rank:] = ways[rank:] + ways[:-rank]  # the sums without this rank, and with it
        observed = int(round(2.0 * r_plus))
        tail = ways[: observed + 1].sum() if alternative == "less" else ways[observed:].sum()
        return float(tail / 2.0**n)
    variance = n * (n + 1) * (2 * n + 1) / 24.0 - float(np.sum(counts**3 - counts)) / 48.0
    z = (r_plus - n * (n + 1) / 4.0) / math.sqrt(variance)
    return float(scipy.special.ndtr(z if alternative == "less" else -z))
