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

import numpy as np
import scipy.linalg

from pincal.fit.solver import condition_number as matrix_condition
from pincal.fit.solver import triangular_factor

#: Pivots below this fraction of the largest mean "not identifiable".
RANK_TOLERANCE = 1e-8
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
        order: kinematic column indices, best determined first (all of them).
        rank: how many of them are identifiable.
        pivots: |R_ii| of the pivoted QR, scaled units, same order.
    """

    order: np.ndarray
    rank: int
    pivots: np.ndarray


def _scaled(jacobian: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    scale = np.linalg.norm(jacobian, axis=0)
    scale[scale == 0] = 1.0
    return jacobian / scale, scale


def order_parameters(jacobian: np.ndarray, kinematic: np.ndarray, always: np.ndarray) -> Ordering:
    """Pivoted QR of the kinematic columns after projecting out the ``always`` columns.

    Exactly equivalent columns (e.g. two placement translations along one joint
    axis) tie; LAPACK's pivoting then keeps whichever rounding favours, so this
    runs on the projected Jacobian itself, as it always has, to keep that choice.
    """
    scaled, _ = _scaled(jacobian)
    base = scaled[:, always]
    if base.shape[1]:
        q, _ = np.linalg.qr(base)
        projected = scaled[:, kinematic] - q @ (q.T @ scaled[:, kinematic])
    else:
        projected = scaled[:, kinematic]
    if projected.shape[1] == 0:
        return Ordering(np.array([], dtype=int), 0, np.array([]))
    _, r, piv = scipy.linalg.qr(projected, mode="economic", pivoting=True)
    pivots = np.abs(np.diag(r))
    pivots = np.concatenate([pivots, np.zeros(len(piv) - len(pivots))])
    top = pivots[0] if pivots.size and pivots[0] > 0 else 1.0
    rank = int(np.sum(pivots > RANK_TOLERANCE * top))
    return Ordering(order=np.asarray(kinematic)[piv], rank=rank, pivots=pivots)


def press(jacobian: np.ndarray, residual: np.ndarray, block: int) -> float:
    """Linearised leave-one-row-out prediction error sum of squares.

    Args:
        jacobian: (m, n) at the fitted parameters; rows grouped by measurement row.
        residual: (m,) at the fitted parameters.
        block: residuals per measurement row (rows are contiguous blocks).
    """
    u, s, _ = np.linalg.svd(jacobian, full_matrices=False)
    u = u[:, s > s[0] * 1e-12] if s.size else u[:, :0]
    k = residual.size // block
    ub = u.reshape(k, block, -1)
    hat = np.einsum("kin,kjn->kij", ub, ub)  # H_kk blocks
    complement = np.eye(block) - hat
    if np.min(np.linalg.eigvalsh(complement), initial=1.0) < LEVERAGE_FLOOR:
        return np.inf  # a row with leverage 1: the fit reproduces it whatever it measured
    loo = np.linalg.solve(complement, residual.reshape(k, block, 1))
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
    prior_scale: dict[str, float] | None = None  # --select prior: its scales (pincal.fit.prior)
