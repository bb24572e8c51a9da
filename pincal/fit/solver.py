"""Nonlinear least squares over an :class:`pincal.residuals.base.Objective`.

scipy.optimize.least_squares (Levenberg–Marquardt, MINPACK) with the
objective's analytic Jacobian. Parameter standard deviations come from the
linearised covariance at the solution, ``s² (JᵀJ)⁻¹`` with
``s² = ‖r‖² / (m − n)`` (the residual variance), or from a known noise scale.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.optimize import least_squares

from pincal.errors import CalibrationError
from pincal.residuals.base import Objective

#: Termination tolerances of least_squares: relative step, relative cost
#: change, and scaled gradient. Tight enough that noise-free data is fitted to
#: ~1e-13 relative, loose enough not to spend evaluations on rounding noise.
XTOL = 1e-12
FTOL = 1e-12
GTOL = 1e-12


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
    """

    x: np.ndarray
    std: np.ndarray
    residual: np.ndarray
    rms: float
    n_evaluations: int
    condition: float
    status: str


def solve(objective: Objective, x0: npt.ArrayLike, what: str = "fit") -> Solution:
    """Minimise ``‖objective.residual(x)‖²`` from ``x0``.

    Raises:
        CalibrationError: fewer residuals than unknowns, or the Jacobian is
            rank deficient at the solution (some parameters are not determined
            by the data; ``what`` names the fit in the message).
    """
    x0 = np.asarray(x0, dtype=float)
    m = objective.residual(x0).size
    n = x0.size
    if m < n:
        raise CalibrationError(
            f"{what}: {m} residuals cannot determine {n} parameters; add calibration rows"
        )
    try:
        result = least_squares(
            objective.residual,
            x0,
            jac=objective.jacobian,
            method="lm",
            x_scale="jac",
            xtol=XTOL,
            ftol=FTOL,
            gtol=GTOL,
        )
    except ValueError as exc:  # non-finite residuals or Jacobian
        raise CalibrationError(f"{what}: the fit failed ({exc}); check the data and the tool for extreme values") from None
    jac = objective.jacobian(result.x)
    singular = np.linalg.svd(jac, compute_uv=False)
    condition = float(singular[0] / singular[-1]) if singular[-1] > 0 else np.inf
    if not np.isfinite(condition) or condition > 1e12:
        raise CalibrationError(
            f"{what}: the data do not determine all {n} parameters "
            f"(Jacobian condition number {condition:.3g}); use more varied configurations"
        )
    residual = objective.residual(result.x)
    dof = max(m - n, 1)
    variance = float(residual @ residual) / dof
    covariance = variance * np.linalg.inv(jac.T @ jac)
    return Solution(
        x=result.x,
        std=np.sqrt(np.clip(np.diag(covariance), 0.0, None)),
        residual=residual,
        rms=float(np.sqrt(np.mean(residual**2))),
        n_evaluations=int(result.nfev),
        condition=condition,
        status=str(result.message),
    )
