"""Which of exactly equivalent columns the identifiability analysis keeps does not depend on
rounding (:func:`pincal.fit.identifiability.pivoted_order`).

Two placement translations along one joint axis, or a joint offset and a registration turn about
the same axis, give Jacobian columns that are equal in exact arithmetic. LAPACK's pivoted QR keeps
whichever one rounding favours, so a report's kept/dropped split moved when a sum was reordered
(noticed when 6975758's einsum order was restored). Reordering the rows of the Jacobian changes
only the rounding, never which parameters the data determine, so it must not change the choice
(with LAPACK's ``dgeqp3`` alone, 40 row shuffles of the tied Jacobian below kept several sets).
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
from hypothesis import given, settings
from hypothesis import strategies as st

from pincal.errors import CalibrationError
from pincal.fit.identifiability import RANK_TOLERANCE, order_parameters, pivoted_order


def _tied_jacobian(seed: int, jitter: int | None = None) -> tuple[np.ndarray, list[tuple[int, ...]]]:
    """A (60, 9) Jacobian whose columns 1, 4 and 7 are one direction (scaled and signed), as are
    2 and 8: after the unit-norm scaling of order_parameters they tie exactly. With ``jitter``, each
    entry is moved by rounding-sized amounts (1e-15 relative, seeded by ``jitter``), as when two
    equivalent columns come out of Pinocchio through different joints."""
    rng = np.random.default_rng(seed)
    base = rng.normal(size=(60, 5))
    columns = [base[:, 0], base[:, 1], base[:, 2], base[:, 3], -3.0 * base[:, 1], base[:, 4],
               rng.normal(size=60), 0.25 * base[:, 1], -base[:, 2]]
    jacobian = np.column_stack(columns)
    if jitter is not None:
        jacobian *= 1.0 + 1e-15 * np.random.default_rng(jitter).standard_normal(jacobian.shape)
    return jacobian, [(1, 4, 7), (2, 8)]


def _kept(ordering) -> set[int]:
    return set(ordering.order[: ordering.rank].tolist())


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000), shuffle=st.integers(0, 10_000))
def test_tied_columns_keep_the_first_listed_whatever_the_rounding(seed, shuffle):
    jacobian, groups = _tied_jacobian(seed, jitter=shuffle)
    rows = np.random.default_rng(shuffle).permutation(len(jacobian))
    ordering = order_parameters(jacobian[rows], np.arange(9), np.array([], dtype=int))
    assert ordering.rank == 6  # 9 columns, 3 of them copies
    for group in groups:
        assert group[0] in _kept(ordering) and not set(group[1:]) & _kept(ordering)
    # the not identifiable ones are listed as given, not in rounding's order
    assert ordering.order[ordering.rank :].tolist() == [4, 7, 8]


def test_what_is_kept_is_above_the_rank_threshold_whatever_a_tie_picks():
    """A tie may take a column slightly shorter than the longest first (the first listed): the
    identifiable prefix must still hold only pivots above RANK_TOLERANCE, never a column below
    it while one above it is dropped. Columns 1 and 2 project (off the ``always`` column 3) to
    1e-8 -+ 4e-11 of the first pivot, a tie, on either side of the threshold."""
    jacobian = np.zeros((5, 4))
    jacobian[0, 0] = 1.0
    jacobian[[3, 1], 1] = 1.0, RANK_TOLERANCE - 4e-11
    jacobian[[3, 2], 2] = 1.0, RANK_TOLERANCE + 4e-11
    jacobian[3, 3] = 1.0
    ordering = order_parameters(jacobian, np.arange(3), np.array([3]))
    assert ordering.order[0] == 0
    assert (ordering.pivots[: ordering.rank] > RANK_TOLERANCE * ordering.pivots[0]).all(), ordering
    assert 1 not in _kept(ordering)


@pytest.mark.parametrize("shape", [(40, 7), (7, 7), (5, 9)])
def test_pivots_are_those_of_a_pivoted_qr(shape):
    """Without ties, the same order and |R_ii| as LAPACK's pivoted QR (to rounding), and zeros past
    min(m, n) columns."""
    a = np.random.default_rng(3).normal(size=shape) * np.logspace(0, -3, shape[1])
    order, pivots = pivoted_order(a)
    _, r, piv = scipy.linalg.qr(a, mode="economic", pivoting=True)
    k = min(shape)
    assert order[:k].tolist() == piv[:k].tolist()
    np.testing.assert_allclose(pivots[:k], np.abs(np.diag(r))[:k], rtol=1e-10)  # rounding of a 40 x 7 QR
    assert sorted(order.tolist()) == list(range(shape[1]))
    assert not pivots[k:].any()


def test_zero_and_empty_columns():
    order, pivots = pivoted_order(np.zeros((4, 3)))
    assert order.tolist() == [0, 1, 2] and not pivots.any()
    order, pivots = pivoted_order(np.zeros((4, 0)))
    assert order.size == 0 and pivots.size == 0


@pytest.mark.parametrize("weakness", [1e-3, 1e-7, 3e-8])
def test_weakly_determined_tied_columns_are_chosen_the_same_way(weakness):
    """Two equivalent columns that the ``always`` block (registration) nearly explains: their
    projected length is ``weakness`` of their own, still identifiable (RANK_TOLERANCE 1e-8),
    while rounding separates them by ~1e-15 absolute, i.e. ~1e-8 relative at 1e-7. A relative
    tie tolerance (1e-9) split 60 shuffles of the 1e-7 case 52 / 8."""
    rng = np.random.default_rng(1)
    always = rng.normal(size=(300, 6))
    other = rng.normal(size=(300, 4))
    along = always @ rng.normal(size=6)
    away = rng.normal(size=300)
    tied = along + weakness * np.linalg.norm(along) / np.linalg.norm(away) * away
    jacobian = np.column_stack([always, other[:, 0], tied, other[:, 1], other[:, 2], -2.0 * tied, other[:, 3]])
    kept = set()
    for shuffle in range(30):
        jittered = jacobian * (1.0 + 1e-15 * np.random.default_rng(shuffle).standard_normal(jacobian.shape))
        rows = np.random.default_rng(shuffle + 100).permutation(len(jacobian))
        ordering = order_parameters(jittered[rows], np.arange(6, 12), np.arange(6))
        kept.add((ordering.rank, tuple(sorted(ordering.order[: ordering.rank].tolist()))))
    assert kept == {(5, (6, 7, 8, 9, 11))}


def test_non_finite_jacobian_is_refused():
    with pytest.raises(CalibrationError, match="NaN or infinite"):
        pivoted_order(np.array([[1.0, np.nan], [0.0, 1.0]]))


def test_the_tie_is_relative_to_the_first_pivot():
    """When the ``always`` block explains all but 1e-3 of every kinematic column, the pivots are
    ~1e-3: two columns 5e-11 apart (5e-8 of their length, far more than rounding) are not tied,
    and the longer goes first, as in LAPACK's pivoted QR; an absolute 1e-10 tie took the first listed."""
    jacobian = np.zeros((4, 3))
    jacobian[[3, 0], 0] = 1.0, 1e-3
    jacobian[[3, 1], 1] = 1.0, 1e-3 * (1.0 + 5e-8)
    jacobian[3, 2] = 1.0
    ordering = order_parameters(jacobian, np.arange(2), np.array([2]))
    assert ordering.rank == 2
    assert ordering.order.tolist() == [1, 0]
