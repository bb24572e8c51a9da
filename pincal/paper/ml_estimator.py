"""A fourth estimator: maximum likelihood over full poses with the registration.

The paper's Method 3 (eq 18) mixes millimetres and degrees with a hand-chosen
weight w; Method 2 avoids the weight by splitting the data (orientations for
eps, positions for r and d) and never uses the absolute poses. Here every
measured row — the ``cpa`` rows as well as the ``calibration`` rows — enters
one least-squares problem in which each residual is divided by the sensor's
noise (:func:`pincal.residuals.tool_pose.tool_pose_residual`, a
:class:`pincal.residuals.sensor.SensorResidual` of the known tool):

    r_k = [ (Ω t_k + τ − g_k) / σ_p ,  log(G_kᵀ Ω R_k) / σ_a ]

With the noise model of eq 20–22 (Gaussian ζ_k with σ_p per axis, small
rotations ξ_k with σ_a per component) the minimiser is the maximum-likelihood
estimate of the DH parameters and the registration sensor_T_base (Ω, τ)
together. Only the ratio σ_p/σ_a changes the estimate. If the σ's are not
given they are estimated from the data by alternating the fit with the
variance-component update σ² = ‖e‖² / (redundancy) per residual type
(Förstner 1979; the redundancy is the residual count minus that type's share
of the hat-matrix trace, a degrees-of-freedom correction), until the ratio
converges: the maximum-likelihood solution with unknown variances (REML-style
degrees of freedom).

Unknowns: alpha_1..N (alpha_N too: with the tool known and full poses measured
it is identifiable, unlike in CPA), eps_2..N, r_1..N, d_2..N, φ (3), τ (3),
with Ω = Ω_0 exp(φ) about Method 2's Registration 1 Ω_0.
eps_1 and d_1 are a gauge of the registration (rotation about and translation
along the first joint axis) and keep their nominal values. The fit starts from
Method 2's solution and its Registration 1 (computed, or given as ``start``).
``withhold_orientations`` names row roles that enter with their positions only
(orientation weight 0): the study's ablation gives the CPA rows no orientations,
as the paper's CPA measures positions only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from pincal.errors import CalibrationError
from pincal.fit.solver import Solution, solve
from pincal.measurements.data import MeasurementSet
from pincal.model.chain import KinematicChain
from pincal.model.dh.parameters import DHParameterSet
from pincal.model.dh.table import DHTable
from pincal.paper.methods import (
    ABSORBED,
    CALIBRATED,
    PaperCalibration,
    Stage,
    calibrate_paper,
)
from pincal.residuals.base import KinematicsCache
from pincal.residuals.sensor import REGISTRATION_NAMES, SensorResidual
from pincal.residuals.tool_pose import tool_pose_residual

__all__ = [
    "METHOD", "KEPT_NOMINAL", "SIGMA_FLOOR", "MAX_ITERATIONS", "RATIO_TOLERANCE", "MLSettings", "MLCalibration",
    "ml_parameter_indices", "variance_components", "calibrate_ml",
]

#: Value of :attr:`PaperCalibration.method` for this estimator.
METHOD = "ml"

#: Status of alpha_N when :attr:`MLSettings.fit_alpha_n` is False.
KEPT_NOMINAL = "not estimated: kept at its nominal value"

#: Smallest noise scale the variance estimate may return [m] or [rad]; noise-free
#: data give residuals at rounding level, which carry no weight information.
SIGMA_FLOOR = 1e-10

MAX_ITERATIONS = 30
RATIO_TOLERANCE = 1e-6  # relative change of sigma_p / sigma_a that ends the iteration


@dataclass(frozen=True)
class MLSettings:
    """What the ML estimator fits and of which rows (:func:`calibrate_ml`).

    Attributes:
        fit_alpha_n: estimate alpha_N too (identifiable with a known tool).
        withhold_orientations: roles (``cpa``, ``calibration``) whose rows enter
            with their positions only (orientation weight 0), e.g. ``("cpa",)``
            for the paper's position-only CPA.
    """

    fit_alpha_n: bool = True
    withhold_orientations: tuple[str, ...] = ()


@dataclass(frozen=True)
class MLCalibration(PaperCalibration):
    """:class:`PaperCalibration` of the ML estimator, with its noise scales.

    ``method`` is ``"ml"``; ``registration_position`` and
    ``registration_orientation`` are the same, jointly estimated registration.

    Attributes:
        sigma_pos_mm: σ_p used in the final fit [mm] (given or estimated).
        sigma_rot_deg: σ_a used in the final fit [deg] (given or estimated).
        sigma_estimated: whether (σ_p, σ_a) were estimated from the data.
        iterations: fits run (more than one when a σ was estimated).
    """

    sigma_pos_mm: float = float("nan")
    sigma_rot_deg: float = float("nan")
    sigma_estimated: tuple[bool, bool] = (False, False)
    iterations: int = 1


def ml_parameter_indices(params: DHParameterSet, fit_alpha_n: bool = True) -> np.ndarray:
    """Flat DH indices the ML estimator fits: all but eps_1 and d_1 (and alpha_N if not fitted)."""
    n = params.nominal.n_joints
    return np.concatenate(
        [
            params.indices("alpha", range(n if fit_alpha_n else n - 1)),
            params.indices("epsilon", range(1, n)),
            params.indices("r"),
            params.indices("d", range(1, n)),
        ]
    )


def variance_components(objective: SensorResidual, x: npt.ArrayLike) -> tuple[float, float]:
    """Estimates of σ_p² [m²] and σ_a² [rad²] from the residuals of ``objective`` at ``x``.

    σ² = ‖e‖² / (3K − tr H_type), with e the unscaled residuals of one type and
    H the hat matrix J (JᵀJ)⁻¹ Jᵀ of the scaled problem, whose diagonal over a
    type's rows is the number of unknowns that type absorbs (Förstner 1979).
    ``objective`` is a :func:`tool_pose_residual` (weights 1/σ_p and 1/σ_a);
    rows of orientation weight 0 (withheld orientations) count for σ_p only.
    """
    rows = objective.row_indices()  # (K, 6): position, orientation
    basis, _ = np.linalg.qr(objective.jacobian(x))
    leverage = (basis**2).sum(axis=1)[rows]
    residual = objective.residual(x)[rows]
    oriented = objective.v > 0  # (K,)
    k, k_a = len(residual), int(oriented.sum())
    ss_p = float(((residual[:, :3] / objective.w[:, None]) ** 2).sum())
    ss_a = float(((residual[oriented, 3:] / objective.v[oriented, None]) ** 2).sum())
    return ss_p / (3 * k - leverage[:, :3].sum()), ss_a / (3 * k_a - leverage[oriented, 3:].sum())


def calibrate_ml(
    chain: KinematicChain,
    data: MeasurementSet,
    sigma_pos_mm: float | None = None,
    sigma_rot_deg: float | None = None,
    nominal: DHTable | None = None,
    *,
    settings: MLSettings | None = None,
    start: PaperCalibration | None = None,
    models: dict | None = None,
) -> MLCalibration:
    """Maximum-likelihood calibration on the ``cpa`` and ``calibration`` rows of ``data``.

    Args:
        chain: the chain; its tool must be the measured target (the TCP). It is not
            changed: the calibrated table is the result's (``chain_placements`` in the chain's terms).
        data: full-pose measurements, one target point per row.
        sigma_pos_mm: σ_p, position noise per axis [mm]; estimated if None.
        sigma_rot_deg: σ_a, orientation noise per component [deg]; estimated if None.
        nominal: the default table (read from the chain's placements if None);
            eps_1 and d_1 (and alpha_N if not fitted) keep its values.
        settings: whether alpha_N is fitted, and rows whose orientations are withheld
            (:class:`MLSettings`; default: alpha_N fitted, no orientation withheld).
        start: Method 2's result on the same ``data`` (from
            :func:`pincal.paper.methods.calibrate_paper`), the fit's start;
            computed if None. Its nominal table is the nominal one.
        models: Pinocchio sensitivity models of ``chain`` by their slots, shared by
            many fits of one chain (:class:`pincal.residuals.base.KinematicsCache`);
            the fit adds those it builds. None: built for this fit only.

    Raises:
        CalibrationError: no orientations, several points per row, a σ that is
            not positive, too few rows, a start that is not Method 2's or whose
            nominal is not ``nominal``, or parameters the data cannot determine.
    """
    settings = MLSettings() if settings is None else settings
    fit_alpha_n, withhold_orientations = settings.fit_alpha_n, settings.withhold_orientations
    for value, name in ((sigma_pos_mm, "sigma_pos_mm"), (sigma_rot_deg, "sigma_rot_deg")):
        if value is not None and not value > 0:
            raise CalibrationError(f"ML estimator: {name} must be positive, got {value}")
    if not data.has_orientation:
        raise CalibrationError(
            f"{data.source}: the ML estimator needs orientations (columns qx,qy,qz,qw); "
            "use --method 1 for positions only"
        )
    if start is None:
        start = calibrate_paper(chain, data, method=2, nominal=nominal, models=models)
    elif start.method != 2 or (
        nominal is not None and not np.array_equal(start.nominal.to_vector(), nominal.to_vector())
    ):
        raise CalibrationError(
            f"ML estimator: the start must be Method 2's result from the same nominal table, "
            f"got Method {start.method}'s"
        )
    params = DHParameterSet(chain, start.nominal)
    rows = data.with_role("cpa", "calibration")
    withheld = np.isin(rows.roles, withhold_orientations)  # (K,) rows entering with positions only
    if withheld.all():
        raise CalibrationError(
            f"{data.source}: the ML estimator needs orientations; "
            f"every row's are withheld ({', '.join(withhold_orientations)})"
        )
    free = ml_parameter_indices(params, fit_alpha_n)
    cache = KinematicsCache(params, free, start.table.to_vector(), rows.q, models)
    points, rotations = rows.points[:, :1, :], rows.rotations
    assert rotations is not None  # has_orientation checked above
    reference = start.registration_position

    def pose_residual(*sigma: float) -> SensorResidual:
        """tool_pose_residual, with orientation weight 0 on the withheld rows."""
        objective = tool_pose_residual(cache, points, rotations, reference, *sigma)
        objective.v[withheld] = 0.0
        return objective

    estimated = (sigma_pos_mm is None, sigma_rot_deg is None)
    sigma = np.array(
        [1.0 if sigma_pos_mm is None else sigma_pos_mm / 1000.0,
         1.0 if sigma_rot_deg is None else np.radians(sigma_rot_deg)]
    )
    unscaled = pose_residual()  # σ = 1: residuals in m and rad
    x = unscaled.start_vector()  # Method 2's table and Registration 1
    if any(estimated):  # start from the spread of the residuals of Method 2's solution
        residual = unscaled.residual(x)[unscaled.row_indices()]
        first = np.sqrt([np.mean(residual[:, :3] ** 2), np.mean(residual[~withheld, 3:] ** 2)])
        sigma = np.where(estimated, np.maximum(first, SIGMA_FLOOR), sigma)

    def fit(sigma: np.ndarray, x: np.ndarray) -> tuple[SensorResidual, Solution]:
        objective = pose_residual(*sigma)
        return objective, solve(objective, x, what="ML estimator")

    objective, solution = fit(sigma, x)
    fits, converged = [solution], not any(estimated)
    while not converged and len(fits) < MAX_ITERATIONS:
        update = np.sqrt(np.maximum(variance_components(objective, solution.x), SIGMA_FLOOR**2))
        update = np.where(estimated, update, sigma)
        converged = abs(np.log((update[0] / update[1]) / (sigma[0] / sigma[1]))) < RATIO_TOLERANCE
        sigma = update
        if not converged:  # else the last fit's weights are within tolerance of these
            objective, solution = fit(sigma, solution.x)
            fits.append(solution)
    x, model = solution.x, objective.blocks["kinematic"]

    vector = cache.full_vector(x[model])
    registration = objective.estimate(x).registration
    std = np.full(params.size, np.nan)
    std[free] = solution.std[model]
    status = np.array([CALIBRATED] * params.size, dtype=object)
    status[params.indices("epsilon", [0])] = ABSORBED
    status[params.indices("d", [0])] = ABSORBED
    if not fit_alpha_n:
        status[params.indices("alpha", [params.nominal.n_joints - 1])] = KEPT_NOMINAL
    sigma_mm, sigma_deg = sigma[0] * 1000.0, float(np.degrees(sigma[1]))
    source = {True: "estimated from the residuals", False: "given"}
    notes = list(start.notes) + [
        (f"ML estimator on {rows.n_rows} rows (cpa and calibration), started from Method 2; "
         f"sensor noise sigma_p = {sigma_mm:.4g} mm ({source[estimated[0]]}), "
         f"sigma_a = {sigma_deg:.4g} deg ({source[estimated[1]]})")
    ]
    if withheld.any():
        notes.append(
            f"orientations of the {', '.join(withhold_orientations)} rows withheld ({int(withheld.sum())} rows "
            "enter with their positions only)"
        )
    if not converged:
        notes.append(f"noise estimate did not converge in {MAX_ITERATIONS} fits")
    stage = Stage(
        name="Err_ML",
        parameters=tuple(params.info[i].name for i in free) + REGISTRATION_NAMES,
        rms=solution.rms,
        unit="sigma",
        n_evaluations=sum(f.n_evaluations for f in fits),
        condition=solution.condition,
    )
    return MLCalibration(
        method=METHOD,
        weight=None,
        nominal=start.nominal,
        table=DHTable.from_vector(vector),
        std=std,
        status=tuple(status),
        registration_position=registration,
        registration_orientation=registration,
        stages=start.stages + (stage,),
        notes=tuple(notes),
        sigma_pos_mm=float(sigma_mm),
        sigma_rot_deg=sigma_deg,
        sigma_estimated=estimated,
        iterations=len(fits),
    )
