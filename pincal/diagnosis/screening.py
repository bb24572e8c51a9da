"""The linearised test of adding an effect to a fit: which candidates deserve a full fit.

At a fit's solution x with residual r (m,) and Jacobian J (m, n), adding
columns B (m, e) (an effect's, at value zero) and taking the best Gauss–Newton
step along [J, B] lowers the residual sum of squares by ‖q_Bᵀ r‖², q_B an
orthonormal basis of B's part orthogonal to J — a score test (Rao 1948), here
expressed as a ΔBIC. On TIAGo and the simulated KUKA its error against the full
nonlinear refit stayed below 0.1 + 0.035 |ΔBIC|; :func:`may_reach` keeps a
margin above that. J is factored once per fit with :func:`pincal.fit.solver.thin_qr`
(no multithreaded BLAS call on the tall J), each candidate costs a QR of its own
few columns and an SVD of an (n + e)² triangle.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
import scipy.linalg

from pincal.fit.prior import PriorResidual, hat_diagonal
from pincal.fit.selection import information_criterion
from pincal.fit.solver import Solution, gram, thin_qr
from pincal.model.effects import Effect
from pincal.residuals.sensor import SensorResidual

__all__ = [
    "FitObjective", "SCREEN_MARGIN", "SCREEN_CONDITION", "SCREEN_INSEPARABLE", "Score", "Linearisation", "screen",
    "may_reach", "n_prior_rows", "GENERIC_NOT_RUN", "residual_freedom", "testable", "bic",
]

#: The objective of an effect fit: the sensor residual, with the prior rows of eq P1 appended under
#: ``--select prior`` (:class:`pincal.fit.prior.PriorResidual`, which answers for it otherwise).
FitObjective = SensorResidual | PriorResidual

#: A screened candidate may reach a cut unless its linearised ΔBIC is worse by more
#: than SCREEN_MARGIN[0] + SCREEN_MARGIN[1] · |ΔBIC| (the linearisation error, with room).
SCREEN_MARGIN = (1.5, 0.06)
#: Condition number of [J, B] above which the Gauss–Newton step is not trusted and a
#: candidate may be inseparable from the geometry (a full fit refuses above 1e12).
SCREEN_CONDITION = 1e10
#: Condition number of [J, B] from which a candidate is inseparable without a full
#: fit (a structural degeneracy: observed 1e15–1e17, separable candidates below 1e7).
SCREEN_INSEPARABLE = 1e14


class Score(NamedTuple):
    """The linearised test of adding columns B (m, e) to a fit with Jacobian J (m, n).

    Attributes:
        delta_bic: ΔBIC of the best linear step along J and B together, charged to
            B (the residual's part along B once J's columns are projected out).
        condition: condition number of [J, B].
        step: that Gauss–Newton step (n + e,): the fit's parameters, then B's
            (zero when the condition number exceeds :data:`SCREEN_CONDITION`).
    """

    delta_bic: float
    condition: float
    step: np.ndarray


class Linearisation:
    """A fit's Jacobian J (m, n) at its solution, factored once: J = Q R."""

    def __init__(self, solution: Solution, n_prior: int = 0) -> None:
        """``n_prior``: the last rows of the fit's residual that are a prior's (``--select prior``):
        not observations, so the BIC's m leaves them out."""
        self.n_prior = n_prior
        self.residual = solution.residual
        self.q, self.r = thin_qr(solution.jacobian)
        self.along_j = np.einsum("ki,k->i", self.q, self.residual)  # Qᵀ r

    def test(self, blocks: Sequence[np.ndarray], current_bic: float) -> list[Score]:
        """:class:`Score` of each block of columns (m, e), each added alone to the
        fit whose BIC is ``current_bic``."""
        if not blocks:
            return []
        m, n = self.q.shape
        m -= self.n_prior
        stacked = np.hstack(blocks)
        along_all = gram(self.q, stacked)  # Qᵀ B (n, Σe)
        projected_all = stacked - np.einsum("ki,ij->kj", self.q, along_all)  # B's part orthogonal to J
        total = float(self.residual @ self.residual)
        scores, start = [], 0
        for block in blocks:
            e = block.shape[1]
            along = along_all[:, start : start + e]
            q_new, r_new = np.linalg.qr(projected_all[:, start : start + e])
            start += e
            triangle = np.block([[self.r, along], [np.zeros((e, n)), r_new]])  # [J, B] = [Q, q_new] triangle
            singular = np.linalg.svd(triangle, compute_uv=False)
            condition = float(singular[0] / singular[-1]) if singular[-1] > 0 else np.inf
            gain = np.einsum("ki,k->i", q_new, self.residual)  # q_new ⟂ Q: the residual's part only B reaches
            rss = max(total - float(gain @ gain), 1e-300)
            step = np.zeros(n + e)
            if condition <= SCREEN_CONDITION:
                step = scipy.linalg.solve_triangular(triangle, -np.concatenate([self.along_j, gain]))
            scores.append(Score(float(information_criterion(rss, m, n + e, np.log(m)) - current_bic), condition, step))
        return scores


def screen(objective: FitObjective, solution: Solution, effects: Sequence[Effect],
           current_bic: float) -> list[tuple[Effect, Score]]:
    """The linearised test of adding each effect to the fit (``objective`` at
    ``solution``), best first; equal scores keep the order of ``effects``."""
    scores = Linearisation(solution, n_prior_rows(objective)).test(
        objective.effect_columns(solution.x, effects), current_bic)
    return sorted(zip(effects, scores), key=lambda item: item[1].delta_bic)


def may_reach(linear_delta: float, cut: float) -> bool:
    """Could a candidate screened at ``linear_delta`` have a full-fit ΔBIC at or below ``cut``?"""
    return linear_delta - (SCREEN_MARGIN[0] + SCREEN_MARGIN[1] * abs(linear_delta)) <= cut


def n_prior_rows(objective: FitObjective) -> int:
    """Rows of the prior in ``objective``'s residual (0 without ``--select prior``)."""
    return int(getattr(objective, "n_prior", 0))


#: Note when too few residual degrees of freedom are left to test a generic correction
#: (:func:`testable`; ``pincal diagnose``).
GENERIC_NOT_RUN = ("the generic joint-angle check (linear + harmonics per joint) was not run: the fit leaves too few "
                   "residual degrees of freedom to test it; add rows")


def residual_freedom(objective: FitObjective, solution: Solution) -> tuple[int, float]:
    """(m, d) of a fit: its data rows m and residual degrees of freedom d = m − tr H (m − n without
    a prior; under ``--select prior`` the hat matrix's trace, eq P2 of :mod:`pincal.fit.prior`)."""
    n_prior = n_prior_rows(objective)
    m = solution.residual.size - n_prior
    used = float(hat_diagonal(solution.jacobian, n_prior).sum()) if n_prior else float(solution.x.size)
    return m, m - used


def testable(freedom: tuple[int, float], n_values: int, evidence: float) -> bool:
    """Whether a fit of :func:`residual_freedom` ``(m, d)`` can test ``n_values`` more values.

    Fitting e values to pure noise shrinks the RSS by e/d on average, a ΔBIC of
    m ln(1 − e/d) + e ln m: a candidate is testable only when that is above the evidence cut
    ``evidence`` (:data:`pincal.diagnosis.verdicts.EVIDENCE`), i.e. when noise alone would not pass it.
    """
    m, d = freedom
    return bool(d > n_values and m * np.log1p(-n_values / d) + n_values * np.log(m) > evidence)


def bic(residual: np.ndarray, n_params: int, n_prior: int = 0) -> float:
    """BIC m ln(RSS/m) + n ln m with m the data rows: under ``--select prior`` the last ``n_prior``
    rows of the residual are the prior's (their squares stay in the penalised RSS), not observations."""
    m = residual.size - n_prior
    return float(information_criterion(residual @ residual, m, n_params, np.log(m)))
