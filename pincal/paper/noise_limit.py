"""Linearised (Cramér–Rao) prediction of the held-out errors each method should reach.

For small sensor noise every estimator is, to first order, linear in the noise.
Let z be the noise of all measured rows — per row k the position noise ζ_k [m]
(σ_p per axis, eq 21) and the orientation noise ξ_k [rad] (G_k = exp(ξ_k) Ω R_k,
σ_a per component: eq 20, 22 to first order). Each least-squares stage with
residual r(θ, z), linearised at its noise-free solution (where r = 0), gives

    dθ̂/dz = −(JᵀJ)⁻¹ Jᵀ (∂r/∂z + ∂r/∂θ_prev · dθ̂_prev/dz)

with θ_prev the outputs of the earlier stages it depends on. The stages are
chained as the methods run them: CPA (eq 9; the plane normals' derivatives are
the first-order perturbation of the plane fit's SVD,
:func:`pincal.paper.cpa.circle_axis_derivative`, the twists' are
:func:`pincal.paper.cpa.twist_gradients`; the central differences with a 1e-6 m
step they replaced differ by their truncation, ~(h · |∂b/∂p|)² relative, and
rounding, ~1e-9: the study's limits moved by < 1e-10 relative) → Err_rot (eq 14–17)
→ Err_pos (eq 10–12), or Err_full (eq 18) → Registration 1 (Arun: the
least-squares fit of Ω t + τ to g) and Registration 2 (the mean rotation, which
minimises Σ ‖log(G_kᵀ Ω R_k)‖², then τ by eq 19). For the ML estimator
(:mod:`pincal.paper.ml_estimator`) there is one stage and the result is its Cramér–Rao
bound (JᵀΣ⁻¹J)⁻¹.

The error of validation pose j against the noise-free truth — position
Ω̂₁ t̂_j + τ̂₁ − g_j and orientation log(G_jᵀ Ω̂₂ R̂_j) — is then A_j z with
covariance C_j = A_j Σ_z A_jᵀ. Its predicted mean norm is E‖e‖ for e ~ N(0, C_j),
computed exactly (no approximation beyond the linearisation): writing e = C^½ u,
u ~ N(0, I₃) = ρ n with ρ ~ χ₃ independent of the direction n,
E‖e‖ = E[ρ] · mean over the unit sphere of √(nᵀ C n), E[ρ] = 2√(2/π); the sphere
mean is a fixed Gauss–Legendre × trapezoid quadrature (spectrally accurate).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import cast

import numpy as np
import pinocchio as pin
from scipy import sparse

from pincal.errors import CalibrationError
from pincal.fit.gaussian_norm import mean_norm
from pincal.measurements.data import MeasurementSet
from pincal.model.chain import KinematicChain
from pincal.model.dh.parameters import DHParameterSet
from pincal.model.dh.table import DHTable
from pincal.model.sensor import Registration
from pincal.paper.cpa import circle_axis_derivative, twist_gradients
from pincal.paper.methods import (
    FROM_CPA,
    PaperCalibration,
    calibrate_paper,
    cpa_groups,
)
from pincal.paper.ml_estimator import METHOD as ML
from pincal.paper.ml_estimator import calibrate_ml
from pincal.residuals.base import KinematicsCache, Objective
from pincal.residuals.distance import DistanceResidual
from pincal.residuals.full_pose import DEG_PER_RAD, MM_PER_M, FullPoseResidual
from pincal.residuals.rotation import RotationResidual
from pincal.residuals.sensor import REGISTRATION_NAMES
from pincal.residuals.tool_pose import tool_pose_residual
from pincal.simulation.paper import SimulatedExperiment
from pincal.simulation.sensor import perfect_measurements

__all__ = ["METHODS", "PredictedErrors", "predicted_errors"]

METHODS = (1, 2, 3, ML)

@dataclass(frozen=True)
class PredictedErrors:
    """Linearised prediction of one method's held-out errors at one noise level.

    Errors are truth-referenced: the calibrated model and registration against
    the noise-free validation poses.

    Attributes:
        method: 1, 2, 3 or ``"ml"``.
        sigma_pos_mm: σ_p [mm].
        sigma_rot_deg: σ_a [deg].
        position_mm: predicted mean over the J poses of E‖position error‖ [mm].
        rotation_deg: predicted mean over the J poses of E[orientation error angle] [deg].
        position_per_pose_mm: E‖position error‖ per validation pose [mm], (J,).
        rotation_per_pose_deg: E[orientation error] per validation pose [deg], (J,).
        covariance: covariance of the estimated parameters, (4N + 12, 4N + 12),
            in SI units (rad, m) in the order of ``parameter_names``: the flat DH
            vector, Registration 1 (φ, τ), Registration 2 (φ, τ); φ is a left
            rotation of the noise-free registration. Parameters a method does not
            estimate have zero rows.
        parameter_names: names of the covariance's rows.
        sensitivity: d(parameters)/d(sensor noise), (4N + 12, 6 K), the
            linearised estimator: column 6k + c is the noise of row k of
            ``experiment.calibration``, ζ_k[c] [m] for c < 3 and ξ_k[c − 3] [rad]
            (G_k → exp(ξ_k) G_k) otherwise; covariance = S Σ_z Sᵀ.
    """

    method: int | str
    sigma_pos_mm: float
    sigma_rot_deg: float
    position_mm: float
    rotation_deg: float
    position_per_pose_mm: np.ndarray
    rotation_per_pose_deg: np.ndarray
    covariance: np.ndarray
    parameter_names: tuple[str, ...]
    sensitivity: np.ndarray


def _noise_free(
    chain: KinematicChain, truth: DHTable, registration: Registration, data: MeasurementSet
) -> MeasurementSet:
    """``data`` with the sensor readings the truth would give (eq 20–21 without noise)."""
    with chain.placed(DHParameterSet(chain, truth).placements(truth.to_vector())):
        return perfect_measurements(chain, data, registration)


class _Propagation:
    """dp/dz of an estimator, built stage by stage.

    The estimate is p = [DH vector (4N), Registration 1 (φ, τ), Registration 2 (φ, τ)]
    with φ a left rotation of the noise-free registration; z is the sensor
    noise, 6 components per row of ``data`` (ζ [m] then ξ [rad]). :attr:`d`
    holds dp/dz, shape (4N + 12, 6 K). ``models``: Pinocchio sensitivity models
    of the chain by their slots, shared by every stage's kinematics (see
    :class:`pincal.residuals.base.KinematicsCache`).
    """

    def __init__(self, params: DHParameterSet, result: PaperCalibration, data: MeasurementSet, models: dict):
        self.params, self.result, self.data, self.models = params, result, data, models
        self.vector = result.table.to_vector()
        self.n_dh = params.size
        self.n_noise = 6 * data.n_rows
        self.d = np.zeros((self.n_dh + 12, self.n_noise))
        self.rows = {role: np.flatnonzero(data.roles == role) for role in ("cpa", "calibration")}
        self.registration_columns = {
            "position": np.arange(self.n_dh, self.n_dh + 6),
            "orientation": np.arange(self.n_dh + 6, self.n_dh + 12),
        }

    # --- helpers -------------------------------------------------------

    def dh_indices(self, names: tuple[str, ...]) -> np.ndarray:
        """Flat DH indices of the DH parameters among ``names`` (a stage's parameters)."""
        index = {info.name: i for i, info in enumerate(self.params.info)}
        return np.array([index[n] for n in names if n in index], dtype=int)

    def cache(self, rows: np.ndarray) -> KinematicsCache:
        """Kinematics of ``rows`` of the data with every DH parameter free."""
        return KinematicsCache(self.params, np.arange(self.n_dh), self.vector, self.data.q[rows], self.models)

    def embed(self, blocks: np.ndarray, rows: np.ndarray) -> sparse.csr_matrix:
        """Per-row noise blocks (R, m, 6) of data ``rows`` → dr/dz, sparse (R·m, 6 K)."""
        r, m, _ = blocks.shape
        row_index = np.broadcast_to(np.arange(r * m).reshape(r, m, 1), blocks.shape)
        column = np.broadcast_to((6 * np.asarray(rows)).reshape(r, 1, 1) + np.arange(6), blocks.shape)
        return sparse.csr_matrix(
            (blocks.ravel(), (row_index.ravel(), column.ravel())), shape=(r * m, self.n_noise)
        )

    def stage(self, jac: np.ndarray, columns: np.ndarray, free: np.ndarray, noise: sparse.spmatrix) -> None:
        """One linearised least-squares stage.

        Args:
            jac: dr/dp over ``columns`` of p, (m, len(columns)).
            columns: the p indices the residual depends on.
            free: the p indices this stage estimates (a subset of ``columns``).
            noise: dr/dz, sparse (m, 6 K).
        """
        is_free = np.isin(columns, free)
        solve = -np.linalg.pinv(jac[:, is_free])  # −(JᵀJ)⁻¹Jᵀ
        # (solve · J_prev) · dθ_prev/dz: the small product first (free × prev, not free × 6K)
        self.d[columns[is_free]] = (solve @ jac[:, ~is_free]) @ self.d[columns[~is_free]] + (noise.T @ solve.T).T

    def pose_jacobians(
        self, data: MeasurementSet, which: str, sigma: tuple[float, float] | np.ndarray = (1.0, 1.0)
    ) -> tuple[np.ndarray, np.ndarray]:
        """dr/dp and per-row dr/dz of the tool pose residual of ``data`` at the noise-free solution.

        The residual is :func:`pincal.residuals.tool_pose.tool_pose_residual` about
        the registration ``which`` with every DH parameter free; ``sigma`` =
        (σ_p [m], σ_a [rad]) scales it (the ML weights), single-type stages use 1.

        Returns:
            dr/dp over [DH vector, φ, τ], (6 R, 4N + 6), row by row (three
            position then three orientation residuals), with φ converted to p's
            left rotation: the residual's Ω₀ exp(φ_r) is exp(φ) Ω₀ for φ = Ω₀ φ_r,
            so dr/dφ = dr/dφ_r Ω₀ᵀ at φ = 0. And dr/dz per row, (R, 6, 6).
        """
        registration = getattr(self.result, f"registration_{which}")
        assert data.rotations is not None  # noise-free simulated rows: they have orientations
        cache = KinematicsCache(self.params, np.arange(self.n_dh), self.vector, data.q, self.models)
        objective = tool_pose_residual(cache, data.points[:, :1], data.rotations, registration, *sigma)
        x = objective.start_vector()
        jac = objective.jacobian(x)[objective.row_indices().ravel()]
        phi = objective.blocks["registration"].start + np.arange(3)
        jac[:, phi] = jac[:, phi] @ registration.rotation.T
        return jac, objective.noise_jacobian(x)

    # --- stages --------------------------------------------------------

    def twists(self) -> None:
        """CPA (Section 3, eq 9): alpha from the plane normals of the joints' arcs."""
        alpha = self.params.indices("alpha")
        estimated = [i for i, j in enumerate(alpha) if self.result.status[j] == FROM_CPA]
        if not estimated:
            return
        cpa = self.rows["cpa"]
        q, points = self.data.q[cpa], self.data.points[cpa, 0]
        axes, d_axes = {}, {}
        for joint, rows in cpa_groups(q).items():
            axes[joint], d_arc = circle_axis_derivative(points[rows], q[rows, joint])  # d_arc (3, K, 3)
            d_axes[joint] = np.zeros((3, self.n_noise))  # d axis / dz
            columns = 6 * cpa[rows][:, None] + np.arange(3)  # ζ_k[c] of the arc's rows, (K, 3)
            d_axes[joint][:, columns.ravel()] = d_arc.reshape(3, -1)
        nominal = self.result.nominal.alpha
        for i in estimated:
            grad = twist_gradients(np.stack([axes[i], axes[i + 1]]), nominal[i : i + 2])[0]  # (2, 3)
            self.d[alpha[i]] = grad[0] @ d_axes[i] + grad[1] @ d_axes[i + 1]

    def pairs(self, name: str, free_names: tuple[str, ...], weight: float) -> None:
        """Err_pos (eq 10–11), Err_rot (eq 14–17) or Err_full (eq 18) on the calibration rows."""
        rows = self.rows["calibration"]
        cache = self.cache(rows)
        assert self.data.rotations is not None  # noise-free simulated rows: they have orientations
        points, rotations = self.data.points[rows, 0], self.data.rotations[rows]
        objective: Objective
        if name == "Err_pos":
            objective = DistanceResidual(cache, points)
            noise = self._distance_noise(objective, rows)
        elif name == "Err_rot":
            objective = RotationResidual(cache, rotations)
            noise = self._rotation_noise(objective, rows)
        elif name == "Err_full":  # the scaling of FullPoseResidual: mm and sqrt(w) deg
            objective = FullPoseResidual(cache, points, rotations, weight)
            noise = sparse.vstack(
                [
                    MM_PER_M * self._distance_noise(objective.position, rows),
                    np.sqrt(weight) * DEG_PER_RAD * self._rotation_noise(objective.rotation, rows),
                ]
            )
        else:
            raise CalibrationError(f"no linearisation for the stage '{name}'")
        self.stage(objective.jacobian(self.vector), np.arange(self.n_dh), self.dh_indices(free_names), noise)

    def _distance_noise(self, objective: DistanceResidual, rows: np.ndarray) -> sparse.csr_matrix:
        """dr/dz of eq 10–11: r_k = L_k − ‖g_k − g_k'‖, so dr_k = −u_kᵀ (ζ_k − ζ_k')."""
        first, second = objective.first, objective.second
        g = self.data.points[rows, 0]
        unit = g[first] - g[second]
        unit /= np.linalg.norm(unit, axis=1, keepdims=True)
        block = np.zeros((len(first), 1, 6))
        block[:, 0, :3] = -unit
        return self.embed(block, rows[first]) - self.embed(block, rows[second])

    def _rotation_noise(self, objective: RotationResidual, rows: np.ndarray) -> sparse.csr_matrix:
        """dr/dz of eq 14: D_k = G_k R_kᵀ R_k' G_k'ᵀ and G → exp(ξ) G give
        d log D_k = Jlog3(D_k) (D_kᵀ ξ_k − ξ_k')."""
        first, second = objective.first, objective.second
        assert self.data.rotations is not None  # noise-free simulated rows: they have orientations
        g = self.data.rotations[rows]
        r = objective.cache.evaluate(self.vector)[0].tool_rotations
        relative = g[first] @ r[first].transpose(0, 2, 1) @ r[second] @ g[second].transpose(0, 2, 1)
        jlog = np.stack([pin.Jlog3(d) for d in relative])
        block_first = np.zeros((len(first), 3, 6))
        block_first[:, :, 3:] = jlog @ relative.transpose(0, 2, 1)
        block_second = np.zeros_like(block_first)
        block_second[:, :, 3:] = -jlog
        return self.embed(block_first, rows[first]) + self.embed(block_second, rows[second])

    def registration_position(self) -> None:
        """Registration 1 (Arun et al. 1987 + eq 19): min Σ ‖Ω t_k + τ − g_k‖² on the calibration rows."""
        rows = self.rows["calibration"]
        jac, noise = self.pose_jacobians(self.data.select(rows), "position")
        position = (np.arange(6 * len(rows)) % 6) < 3
        columns = np.concatenate([np.arange(self.n_dh), self.registration_columns["position"]])
        self.stage(jac[position], columns, self.registration_columns["position"], self.embed(noise[:, :3, :], rows))

    def registration_orientation(self) -> None:
        """Registration 2: Ω = mean rotation of G_k R_kᵀ (Moakher 2002), then τ by eq 19."""
        rows = self.rows["calibration"]
        jac, noise = self.pose_jacobians(self.data.select(rows), "orientation")
        position = (np.arange(6 * len(rows)) % 6) < 3
        columns = np.concatenate([np.arange(self.n_dh), self.registration_columns["orientation"]])
        phi, tau = columns[self.n_dh : self.n_dh + 3], columns[self.n_dh + 3 :]
        self.stage(jac[~position], columns, phi, self.embed(noise[:, 3:, :], rows))
        self.stage(jac[position], columns, tau, self.embed(noise[:, :3, :], rows))

    def maximum_likelihood(self, free_names: tuple[str, ...], sigma: np.ndarray) -> None:
        """The ML estimator's single stage; equals the Cramér–Rao bound at the truth."""
        rows = np.concatenate([self.rows["cpa"], self.rows["calibration"]])
        jac, noise = self.pose_jacobians(self.data.select(rows), "position", sigma)
        registration = self.registration_columns["position"]
        free = np.concatenate([self.dh_indices(free_names), registration])
        columns = np.concatenate([np.arange(self.n_dh), registration])
        self.stage(jac, columns, free, self.embed(noise, rows))
        self.d[self.registration_columns["orientation"]] = self.d[registration]

    # --- validation ----------------------------------------------------

    def pose_errors(self, validation: MeasurementSet) -> tuple[np.ndarray, np.ndarray]:
        """de/dz of the truth-referenced errors at the validation poses (eq 24 against the truth).

        Position e = Ω̂₁ t̂_j + τ̂₁ − g_j [m] and orientation log(G_jᵀ Ω̂₂ R̂_j) [rad]
        are the residuals of the tool pose residual on noise-free ``validation``.

        Returns:
            Position and orientation derivatives, (J, 3, 6 K) each.
        """
        out = []
        for which, part in (("position", slice(0, 3)), ("orientation", slice(3, 6))):
            jac = self.pose_jacobians(validation, which)[0].reshape(validation.n_rows, 6, -1)
            columns = np.concatenate([np.arange(self.n_dh), self.registration_columns[which]])
            out.append(jac[:, part, :] @ self.d[columns])
        return out[0], out[1]


def _sensitivity(
    chain: KinematicChain, experiment: SimulatedExperiment, method: int | str, ml_sigma: np.ndarray, weight: float
) -> tuple[_Propagation, np.ndarray, np.ndarray]:
    """Run ``method`` on the experiment's noise-free rows and linearise it there.

    Returns:
        The propagation (dp/dz and parameter names) and de/dz of the validation
        position and orientation errors, (J, 3, 6 K) each.
    """
    data = _noise_free(chain, experiment.truth, experiment.registration, experiment.calibration)
    validation = _noise_free(chain, experiment.truth, experiment.registration, experiment.validation)
    models: dict = {}  # Pinocchio sensitivity models by their slots, built once for the fit and the stages
    result: PaperCalibration
    if method == ML:
        result = calibrate_ml(
            chain, data, ml_sigma[0] * 1000.0, np.degrees(ml_sigma[1]), nominal=experiment.truth, models=models
        )
    else:
        # a paper method's number here (ML is the only name)
        result = calibrate_paper(chain, data, cast(int, method), weight=weight, nominal=experiment.truth,
                                 models=models)
    propagation = _Propagation(DHParameterSet(chain, result.nominal), result, data, models)
    if method == ML:
        propagation.maximum_likelihood(result.stages[-1].parameters, ml_sigma)
    else:
        propagation.twists()
        for stage in result.stages:
            propagation.pairs(stage.name, stage.parameters, weight)
        propagation.registration_position()
        if method == 1:  # one registration for positions and orientations (Section 6)
            columns = propagation.registration_columns
            propagation.d[columns["orientation"]] = propagation.d[columns["position"]]
        else:
            propagation.registration_orientation()
    return (propagation, *propagation.pose_errors(validation))


def predicted_errors(
    chain: KinematicChain,
    experiment: SimulatedExperiment,
    method: int | str,
    sigma_pos_mm: float,
    sigma_rot_deg: float,
    weight: float = 1.0,
) -> PredictedErrors:
    """Linearised prediction of a method's truth-referenced held-out errors.

    The estimator is linearised at its noise-free solution on the experiment's
    rows (run with the truth as the nominal table, so parameters a method does
    not estimate are at their true values) and its sensitivity to the noise of
    every ``cpa`` and ``calibration`` row is propagated to the validation poses.
    The paper methods' predictions are exactly proportional to σ when σ_p and
    σ_a scale together; the ML estimator's depend on σ_p/σ_a through its weights.

    Args:
        chain: a chain of the experiment's robot, left as it was (the experiment's tool is
            used inside ``chain.placed``).
        experiment: the simulated experiment (rows, truth, registration, tool);
            its noise realisation is not used.
        method: 1, 2, 3 or ``"ml"``.
        sigma_pos_mm: σ_p, position noise per axis [mm].
        sigma_rot_deg: σ_a, orientation noise per component [deg].
        weight: w of Method 3 [mm²/deg²].

    Raises:
        CalibrationError: unknown method, negative σ, or (ML) exactly one σ zero.
    """
    if method not in METHODS:
        raise CalibrationError(f"method must be one of {METHODS}, got {method!r}")
    if not (sigma_pos_mm >= 0 and sigma_rot_deg >= 0):
        raise CalibrationError(f"noise must be non-negative, got {sigma_pos_mm} mm, {sigma_rot_deg} deg")
    if method == ML and (sigma_pos_mm == 0) != (sigma_rot_deg == 0):
        raise CalibrationError("the ML estimator's prediction needs both sigmas positive (or both 0)")
    sigma = np.array([sigma_pos_mm / 1000.0, np.radians(sigma_rot_deg)])
    ml_sigma = sigma if sigma[0] > 0 else np.ones(2)  # only the ratio shapes the ML estimate
    with chain.placed(tool=experiment.tool):
        propagation, d_position, d_rotation = _sensitivity(chain, experiment, method, ml_sigma, weight)
    std = np.tile(np.repeat(sigma, 3), propagation.data.n_rows)  # of z, eq 20–22
    d_position, d_rotation = d_position * std, d_rotation * std
    position = mean_norm(d_position @ d_position.transpose(0, 2, 1)) * 1000.0
    rotation = np.degrees(mean_norm(d_rotation @ d_rotation.transpose(0, 2, 1)))
    scaled = propagation.d * std
    names = tuple(info.name for info in propagation.params.info) + tuple(
        f"registration_{which}_{name}" for which in ("position", "orientation") for name in REGISTRATION_NAMES
    )
    return PredictedErrors(
        method=method,
        sigma_pos_mm=float(sigma_pos_mm),
        sigma_rot_deg=float(sigma_rot_deg),
        position_mm=float(position.mean()),
        rotation_deg=float(rotation.mean()),
        position_per_pose_mm=position,
        rotation_per_pose_deg=rotation,
        covariance=scaled @ scaled.T,
        parameter_names=names,
        sensitivity=propagation.d,
    )
