"""Nonlinear least squares over an :class:`pincal.residuals.base.Objective`.

scipy.optimize.least_squares (Levenberg–Marquardt, MINPACK) with the
objective's analytic Jacobian. Parameter standard deviations come from the
linearised covariance at the solution, ``s² (JᵀJ)⁻¹`` with
``s² = ‖r‖² / (m − n)`` (the residual variance), or from a known noise scale.

The residual and Jacobian at the solution are the ones least_squares already
evaluated there (MINPACK's last residual, scipy's final Jacobian); the
residual at the start is evaluated once, for the size check and MINPACK's
first call.

The condition number and the covariance come from the n × n Gram matrix JᵀJ,
summed by numpy without BLAS (:func:`gram`), and from the singular values of
J's triangular factor when JᵀJ cannot resolve it (cond(J) ≥ :data:`GRAM_CONDITION`).
A LAPACK call on the tall J runs multithreaded level-2 BLAS; on a loaded
machine each such call can wait milliseconds for its threads, far longer than
the work itself.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
import numpy.typing as npt
from scipy.optimize import least_squares

from pincal.errors import CalibrationError

__all__ = [
    "XTOL", "FTOL", "GTOL", "GRAM_CONDITION", "MAX_CONDITION", "Fittable", "Solution", "solve", "gram",
    "condition_number", "thin_qr", "triangular_factor",
]

#: Termination tolerances of least_squares: relative step, relative cost
#: change, and scaled gradient. Tight enough that noise-free data is fitted to
#: ~1e-13 relative, loose enough not to spend evaluations on rounding noise.
XTOL = 1e-12
FTOL = 1e-12
GTOL = 1e-12
#: Largest condition number read from the eigenvalues of JᵀJ (their relative
#: accuracy is ~1e-16 · cond²); above it, the singular values of J's triangular factor.
GRAM_CONDITION = 1e5
#: Largest condition number of the Jacobian at a solution (beyond it a
#: parameter is not determined).
MAX_CONDITION = 1e12


class Fittable(Protocol):
    """What :func:`solve` fits: an :class:`pincal.residuals.base.Objective`, or a wrapper
    with its interface (:class:`pincal.fit.prior.PriorResidual`)."""

    def residual(self, x: np.ndarray) -> np.ndarray: ...

    def jacobian(self, x: np.ndarray) -> np.ndarray: ...


@dataclass(frozen=True)
class Solution:
    """Result of one least-squares fit.

    Attributes:
        x: fitted free parameters (n,).
        std: their standard deviations (n,) (:func:`solve` refuses undetermined parameters).
        residual: residual vector at ``x`` (m,).
        rms: root-mean-square residual (units of the objective).
        n_evaluations: number of residual evaluations.
        condition: condition number of the Jacobian at ``x``.
        status: scipy's termination message.
        jacobian: the Jacobian at ``x`` (m, n).
        converged: False when the fit stopped at ``max_evaluations``.
    """

    x: np.ndarray
    std: np.ndarray
    residual: np.ndarray
    rms: float
    n_evaluations: int
    condition: float
    status: str
    jacobian: np.ndarray
    converged: bool = True


def solve(objective: Fittable, x0: npt.ArrayLike, what: str = "fit", max_evaluations: int | None = None,
          tolerance: float | None = None) -> Solution:
    """Minimise ``‖objective.residual(x)‖²`` from ``x0``.

    ``max_evaluations`` bounds the residual evaluations (scipy's default,
    100 per unknown, when None); a fit stopped there has ``converged`` False.
    ``tolerance`` replaces :data:`XTOL`, :data:`FTOL` and :data:`GTOL`, for fits
    that only rank or score (at 1e-10 the cost is within ~1e-10 of its minimum
    and the parameters within ~1e-5 of their standard deviation).

    Raises:
        CalibrationError: fewer residuals than unknowns, or the Jacobian is
            rank deficient at the solution (some parameters are not determined
            by the data; ``what`` names the fit in the message).
    """
    x0 = np.asarray(x0, dtype=float)
    r0 = objective.residual(x0)
    m = r0.size
    n = x0.size
    if m < n:
        raise CalibrationError(
            f"{what}: {m} residuals cannot determine {n} parameters; add calibration rows"
        )
    known = [r0]  # the start's residual, for least_squares' first call
    jacobians: dict[bytes, np.ndarray] = {}  # the last two, by x: scipy asks again for the final x

    def residual_at(x: np.ndarray) -> np.ndarray:
        start = known.pop() if known else None
        return start if start is not None and np.array_equal(x, x0) else objective.residual(x)

    def jacobian(x: np.ndarray) -> np.ndarray:
        key = np.asarray(x, dtype=float).tobytes()
        if key not in jacobians:
            if len(jacobians) == 2:
                del jacobians[next(iter(jacobians))]
            jacobians[key] = objective.jacobian(x)
        return jacobians[key].copy()  # scipy and MINPACK may write into what they get

    try:
        result = least_squares(
            residual_at,
            x0,
            jac=jacobian,
            method="lm",
            x_scale="jac",
            xtol=XTOL if tolerance is None else tolerance,
            ftol=FTOL if tolerance is None else tolerance,
            gtol=GTOL if tolerance is None else tolerance,
            max_nfev=max_evaluations,
        )
    except ValueError as exc:  # non-finite residuals or Jacobian
        raise CalibrationError(
            f"{what}: the fit failed ({exc}); check the data and the tool for extreme values") from None
    jac = np.asarray(result.jac, dtype=float)  # scipy's Jacobian at result.x
    normal = gram(jac)
    condition = condition_number(jac, normal)
    if not np.isfinite(condition) or condition > MAX_CONDITION:
        raise CalibrationError(
            f"{what}: the data do not determine all {n} parameters "
            f"(Jacobian condition number {condition:.3g}); use more varied configurations"
        )
    residual = np.asarray(result.fun, dtype=float)  # MINPACK's residual at result.x
    dof = max(m - n, 1)
    variance = float(residual @ residual) / dof
    covariance = variance * np.linalg.inv(normal)
    return Solution(
        x=result.x,
        std=np.sqrt(np.clip(np.diag(covariance), 0.0, None)),
        residual=residual,
        rms=float(np.sqrt(np.mean(residual**2))),
        n_evaluations=int(result.nfev),
        condition=condition,
        status=str(result.message),
        jacobian=jac,
        converged=result.status != 0,
    )


def gram(a: np.ndarray, b: np.ndarray | None = None) -> np.ndarray:
    """aᵀb (aᵀa without ``b``) for tall a (m, n), b (m, e), summed by numpy (no BLAS threads)."""
    return np.einsum("ki,kj->ij", a, a if b is None else b)


def condition_number(matrix: np.ndarray, normal: np.ndarray | None = None) -> float:
    """σ_max / σ_min of ``matrix`` (m, n), m ≥ n, from its Gram matrix ``normal``
    (computed when None) when well conditioned, else from its SVD; inf when singular."""
    normal = gram(matrix) if normal is None else normal
    if normal.size:
        eigen = np.linalg.eigvalsh(normal)
        if eigen[0] > 0 and eigen[-1] < eigen[0] * GRAM_CONDITION**2:
            return float(np.sqrt(eigen[-1] / eigen[0]))
    if matrix.shape[0] < matrix.shape[1]:
        return float("inf")
    singular = np.linalg.svd(triangular_factor(matrix), compute_uv=False)  # = those of the matrix
    return float(singular[0] / singular[-1]) if singular.size and singular[-1] > 0 else float("inf")


def thin_qr(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Thin QR of a tall matrix a (m, n) of full column rank: Q (m, n), R (n, n), Q = a R⁻¹
    (no multithreaded BLAS call, :func:`triangular_factor`)."""
    r = triangular_factor(a)
    return np.einsum("ki,ij->kj", a, np.linalg.inv(r)), r


def triangular_factor(a: np.ndarray) -> np.ndarray:
    """R (n, n) of a thin QR of a tall matrix a (m, n): same singular values as a.

    Householder reflections (Golub & Van Loan, Algorithm 5.2.1) applied with
    numpy sums only, so no multithreaded BLAS call is made.
    """
    r = np.array(a, dtype=float)
    m, n = r.shape
    for k in range(n):
        column = r[k:, k]
        norm = np.sqrt(np.einsum("i,i->", column, column))
        if norm == 0.0:
            continue
        v = column.copy()
        v[0] += norm if column[0] >= 0 else -norm  # reflect onto ∓‖x‖ e_1, away from cancellation
        r[k:, k:] -= np.outer(v, np.einsum("i,ij->j", v, r[k:, k:]) * (2.0 / np.einsum("i,i->", v, v)))
    return np.triu(r[:n])
