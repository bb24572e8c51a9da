"""Which parameters the measurements determine, and which to keep.

From the measurement Jacobian J (columns scaled to unit norm so that metres and
radians compare), with the always-estimated block (registration, target)
projected out:

* QR with column pivoting (Businger & Golub 1965) orders the kinematic
  parameters from best to worst determined; the numerical rank (pivots above
  ``RANK_TOLERANCE`` of the largest) says how many combinations the data can
  determine at all. The others are not identifiable: each is reported with the
  kept parameters it is absorbed into (least-squares coefficients of its column).
* Among the identifiable ones, weakly determined combinations can still hurt
  prediction. :mod:`pincal.fit.chain_calibration` chooses how many to keep by an
  information criterion (AIC by default, BIC) or by linearised leave-one-row-out
  cross-validation (:func:`press`, Allen 1974: for a row block r_k with hat
  block H_kk, its left-out residual is (I − H_kk)⁻¹ r_k), always on the
  calibration rows; the validation data are never looked at.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np
import scipy.linalg

from pincal.errors import CalibrationError
from pincal.fit.solver import condition_number as matrix_condition
from pincal.fit.solver import triangular_factor

__all__ = [
    "RANK_TOLERANCE", "PIVOT_TIE", "CORRELATION_THRESHOLD", "LEVERAGE_FLOOR", "ABSORB_THRESHOLD", "Ordering",
    "order_parameters", "pivoted_order", "press", "press_of_blocks", "absorbed_into", "condition_number",
    "correlated_pairs", "Selection",
]

#: Pivots below this fraction of the largest mean "not identifiable".
RANK_TOLERANCE = 1e-8
#: Pivot candidates within this much of the longest tie (:func:`pivoted_order`), as a fraction
#: of the first pivot (1 for unit-scaled columns). Rounding separates exactly equivalent columns
#: by ~1e-15 of it (a few ε of the columns, whatever their projected length); columns that
#: differ by less than 1e-10 are equally well determined to far below RANK_TOLERANCE (1e-8),
#: so either choice is sound.
PIVOT_TIE = 1e-10
#: Pairs of kept parameters with |correlation| above this are reported.
CORRELATION_THRESHOLD = 0.9
#: Smallest eigenvalue of I − H_kk below which a row block counts as fitted exactly (leverage 1):
#: its leave-one-out prediction, and so PRESS, is undefined.
LEVERAGE_FLOOR = 1e-10
#: Absorbing coefficients below this (in scaled units) are not listed.
ABSORB_THRESHOLD = 0.1


@dataclass(frozen=True)
class Ordering:
    """Kinematic parameters ordered by how well the data determine them.

    Attributes:
        order: kinematic column indices, best determined first (all of them; the
            ``rank`` identifiable ones, then the others in their given order).
        rank: how many of them are identifiable.
        pivots: |R_ii| of the pivoted QR, scaled units, for the ``rank`` identifiable ones
            (each above ``RANK_TOLERANCE`` of the largest); then the others' in their listed
            order (the first at or below it, and any after it: the identifiable ones are the
            leading run above the threshold).
    """

    order: np.ndarray
    rank: int
    pivots: np.ndarray


def _scaled(jacobian: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    scale = np.linalg.norm(jacobian, axis=0)
    scale[scale == 0] = 1.0
    return jacobian / scale, scale


def order_parameters(jacobian: np.ndarray, kinematic: np.ndarray, always: np.ndarray) -> Ordering:
    """Pivoted QR of the kinematic columns after projecting out the ``always`` columns
    (:func:`pivoted_order`: exactly equivalent columns keep the first listed)."""
    scaled, _ = _scaled(jacobian)
    base = scaled[:, always]
    if base.shape[1]:
        q, _ = np.linalg.qr(base)
        projected = scaled[:, kinematic] - q @ (q.T @ scaled[:, kinematic])
    else:
        projected = scaled[:, kinematic]
    if projected.shape[1] == 0:
        return Ordering(np.array([], dtype=int), 0, np.array([]))
    piv, pivots = pivoted_order(projected)
    top = pivots[0] if pivots.size and pivots[0] > 0 else 1.0
    # the leading run above the threshold: a tie may take a column up to PIVOT_TIE shorter
    # first, so a later pivot can exceed an earlier one
    above = pivots > RANK_TOLERANCE * top
    rank = int(above.size if above.all() else np.argmin(above))
    tail = rank + np.argsort(piv[rank:], kind="stable")  # not identifiable: rounding orders them, list them as given
    piv, pivots = np.concatenate([piv[:rank], piv[tail]]), np.concatenate([pivots[:rank], pivots[tail]])
    return Ordering(order=np.asarray(kinematic)[piv], rank=rank, pivots=pivots)


def pivoted_order(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Column order and pivots |R_ii| of a QR with column pivoting (Businger & Golub 1965)
    of ``a`` (m, n), columns scaled to unit norm, with a reproducible choice among tied columns.

    Each step takes the column whose part orthogonal to the columns taken so far
    is longest. Exactly equivalent columns (two placement translations along one
    joint axis, a joint offset and the registration's turn about the same axis)
    tie in exact arithmetic, and LAPACK's pivoting (``dgeqp3``) keeps whichever
    rounding favours: a report's kept/dropped split then moved with the BLAS
    build or the order of a sum. Here a column within :data:`PIVOT_TIE` times the
    first pivot (the longest column) of the longest counts as tied, and the first
    listed of the tied ones is taken; pivots may then rise by up to that much.

    The pivoting runs on the triangular factor of an unpivoted LAPACK QR of ``a``
    (same column norms and inner products, n × n instead of m × n): each chosen
    direction is orthogonalised against the earlier ones a second time, and the
    remaining columns lose their component along it (one projection per step,
    modified Gram–Schmidt). Columns left after min(m, n) steps follow in their
    listed order with pivot 0.

    Returns:
        (n,) column indices in pivot order, and (n,) the pivots (zeros past min(m, n)).

    Raises:
        CalibrationError: ``a`` has NaN or infinite entries.
    """
    work = np.array(a, dtype=float)
    if not np.all(np.isfinite(work)):
        raise CalibrationError(
            "the measurement Jacobian has NaN or infinite entries; check the data for extreme values")
    m, n = work.shape
    if m > n:
        work = cast(np.ndarray, np.linalg.qr(work, mode="r"))  # R alone (NumPy's stubs say QRResult)
    basis = np.empty((work.shape[0], 0))
    order: list[int] = []
    pivots: list[float] = []
    left = np.arange(n)
    tie = None  # PIVOT_TIE times the first pivot
    for _ in range(min(m, n)):
        norms = np.sqrt(np.einsum("ij,ij->j", work[:, left], work[:, left]))
        longest = norms.max() if norms.size else 0.0
        if not longest > 0.0:
            break
        tie = PIVOT_TIE * longest if tie is None else tie
        position = int(np.flatnonzero(norms >= longest - tie)[0])
        column = left[position]
        direction = work[:, column].copy()
        direction -= basis @ (basis.T @ direction)  # second pass (the first is in ``work``)
        length = np.linalg.norm(direction)
        order.append(int(column))
        pivots.append(float(norms[position]))
        left = np.delete(left, position)
        if not length > 0.0:
            continue
        direction /= length
        basis = np.column_stack([basis, direction])
        work[:, left] -= np.outer(direction, direction @ work[:, left])
    order += [int(c) for c in left]
    pivots += [0.0] * len(left)
    return np.array(order, dtype=int), np.array(pivots)


def press(jacobian: np.ndarray, residual: np.ndarray, block: int) -> float:
    """Linearised leave-one-row-out prediction error sum of squares.

    Args:
        jacobian: (m, n) at the fitted parameters; rows grouped by measurement row.
        residual: (m,) at the fitted parameters.
        block: residuals per measurement row (rows are contiguous blocks).
    """
    return press_of_blocks(jacobian, residual, np.arange(residual.size).reshape(-1, block))


def press_of_blocks(jacobian: np.ndarray, residual: np.ndarray, blocks: np.ndarray) -> float:
    """:func:`press` with each measurement row's residual entries given: ``blocks`` (K, b) indexes
    ``residual`` and ``jacobian``'s rows; ``jacobian`` may have more rows (a prior's, below the data's),
    which enter the hat matrix (Allen 1974). inf when a row has leverage 1."""
    u, s, _ = np.linalg.svd(jacobian, full_matrices=False)
    u = u[:, s > s[0] * 1e-12] if s.size else u[:, :0]
    ub = u[blocks]  # (K, b, r)
    complement = np.eye(blocks.shape[1]) - np.einsum("kin,kjn->kij", ub, ub)  # I − H_kk
    if np.min(np.linalg.eigvalsh(complement), initial=1.0) < LEVERAGE_FLOOR:
        return np.inf  # a row with leverage 1: the fit reproduces it whatever it measured
    loo = np.linalg.solve(complement, residual[blocks][..., None])
    return float(np.sum(loo**2))


def absorbed_into(jacobian: np.ndarray, dropped: Sequence[int], kept: np.ndarray) -> list[list[tuple[int, float]]]:
    """For each dropped column, the kept columns that reproduce it, with scaled
    coefficients (largest first, at most three): one least-squares solve for all."""
    scaled, _ = _scaled(jacobian)
    dropped = list(dropped)
    if not dropped:
        return []
    # least squares through one triangular factor of [kept | dropped]: R11 C = R12
    r = triangular_factor(scaled[:, np.concatenate([np.asarray(kept, dtype=int), dropped])])
    n = len(kept)
    if n and np.abs(np.diag(r[:n, :n])).min() > 0:
        coefs = scipy.linalg.solve_triangular(r[:n, :n], r[:n, n:])  # (kept, dropped)
    else:  # an exactly dependent kept column: the minimum-norm solution copes
        coefs = np.linalg.lstsq(scaled[:, np.asarray(kept, dtype=int)], scaled[:, dropped], rcond=None)[0]
    out = []
    for coef in coefs.T:
        order = np.argsort(-np.abs(coef))
        out.append([(int(kept[i]), float(coef[i])) for i in order if abs(coef[i]) >= ABSORB_THRESHOLD][:3])
    return out


def condition_number(jacobian: np.ndarray) -> float:
    """Condition number of the column-scaled Jacobian."""
    scaled, _ = _scaled(jacobian)
    return matrix_condition(scaled)


def correlated_pairs(covariance: np.ndarray) -> list[tuple[int, int, float]]:
    """Index pairs whose correlation exceeds :data:`CORRELATION_THRESHOLD` in magnitude."""
    d = np.sqrt(np.clip(np.diag(covariance), 1e-300, None))
    corr = covariance / np.outer(d, d)
    i, j = np.nonzero(np.triu(np.abs(corr) > CORRELATION_THRESHOLD, k=1))
    return [(int(a), int(b), float(corr[a, b])) for a, b in zip(i, j)]


@dataclass(frozen=True)
class Selection:
    """Outcome of choosing how many ordered parameters to keep.

    Attributes:
        criterion: description of the criterion.
        sizes: candidate numbers of kinematic parameters.
        scores: criterion value of each candidate (same order): of its nonlinear
            fit for the sizes in ``refitted``, linearised for the others
            (:mod:`pincal.fit.selection`).
        chosen: the number kept.
        refitted: the sizes fitted nonlinearly (the chosen one among them).
        solution: the chosen subset's fitted unknowns (to start the final fit from).
        prior_scale: with ``--select prior``, the prior's ``translation_mm`` and ``rotation_deg``
            (``scores`` then holds the effective number of kinematic parameters).
    """

    criterion: str
    sizes: tuple[int, ...]
    scores: tuple[float, ...]
    chosen: int
    notes: tuple[str, ...] = field(default=())
    refitted: tuple[int, ...] = ()
    solution: np.ndarray | None = field(default=None, compare=False, repr=False)
    prior_scale: dict[str, Any] | None = None  # --select prior: its scales (pincal.fit.prior)
