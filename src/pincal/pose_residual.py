"""Absolute pose residual: measured tool poses against the model, through an unknown registration.

Unlike the paper's pairwise objectives (eq 10–11, 14) this residual compares
each measured pose with the model pose mapped into the sensor frame, so the
registration sensor_T_base (Ω, τ) is estimated together with the model
parameters. With g_k, G_k the measured position and orientation of row k and
t_k, R_k the model's (robot base frame), the residual of row k is

    r_k = [ (Ω t_k + τ − g_k) / σ_p ,  log(G_kᵀ Ω R_k) / σ_a ]      (6,)

(Pinocchio's SO(3) log), dimensionless: the noise scales σ_p [m] and σ_a [rad]
make the position and orientation parts commensurable, which is what the paper's
Method 3 weight w (eq 18) tries to do by hand. With σ_p, σ_a the sensor's noise
(eq 20–22) the least-squares solution is the maximum-likelihood estimate.

Unknowns: x = [model parameters (the cache's free set), φ (3) [rad], τ (3) [m]],
with the rotation perturbed on the left, Ω = exp(φ) Ω_0, about a fixed
reference Ω_0. The model part goes through :class:`pincal.objective.KinematicsCache`
only, so the residual is not tied to DH parameters.

Jacobians (world perturbation ω of R_k, E_k = G_kᵀ Ω R_k, Pinocchio's right
Jlog3): d(Ω t)/dφ = −[Ω t]×, d/dτ = I, d(Ω t)/dθ = Ω · (point velocity);
d log E/dω = Jlog3(E) Eᵀ G_kᵀ Ω = Jlog3(E) R_kᵀ, d log E/dφ = Jlog3(E) R_kᵀ Ωᵀ.
Away from φ = 0 the φ columns carry the left Jacobian of exp, Jl(φ), since
exp(φ + δ) = exp(Jl(φ) δ) exp(φ).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pinocchio as pin

from .errors import CalibrationError
from .objective import KinematicsCache, Objective
from .registration import Registration
from .sensor_residual import skew

#: Names of the six registration unknowns appended to the model parameters.
REGISTRATION_NAMES = ("phi_x", "phi_y", "phi_z", "tau_x", "tau_y", "tau_z")


class PoseResidual(Objective):
    """Noise-scaled absolute pose residual with the registration as unknowns.

    Residuals are ordered per row: ``residual(x).reshape(K, 6)`` gives, for each
    row, the three position components then the three orientation components.

    Args:
        cache: kinematics of the K measured rows; its free set is the model part of x.
        sensor_points: measured tool positions g_k in the sensor frame (K, 3) [m].
        sensor_rotations: measured tool orientations G_k in the sensor frame (K, 3, 3).
        reference: registration whose rotation is Ω_0 (φ = 0); its translation is
            the starting τ of :meth:`initial_vector`.
        sigma_position_m: σ_p, the position noise per axis [m].
        sigma_rotation_rad: σ_a, the orientation noise per component [rad].

    Raises:
        CalibrationError: mismatched shapes or a non-positive σ.
    """

    def __init__(
        self,
        cache: KinematicsCache,
        sensor_points: npt.ArrayLike,
        sensor_rotations: npt.ArrayLike,
        reference: Registration,
        sigma_position_m: float = 1.0,
        sigma_rotation_rad: float = 1.0,
    ) -> None:
        super().__init__(cache)
        k = len(cache.q)
        self.points = np.asarray(sensor_points, dtype=float)  # (K, 3) g_k
        self.rotations = np.asarray(sensor_rotations, dtype=float)  # (K, 3, 3) G_k
        if self.points.shape != (k, 3) or self.rotations.shape != (k, 3, 3):
            raise CalibrationError(
                f"pose residual: expected points ({k}, 3) and rotations ({k}, 3, 3), "
                f"got {self.points.shape} and {self.rotations.shape}"
            )
        if not (sigma_position_m > 0 and sigma_rotation_rad > 0):
            raise CalibrationError(
                f"noise scales must be positive, got sigma_p={sigma_position_m} m, "
                f"sigma_a={sigma_rotation_rad} rad"
            )
        self.reference = reference
        self.sigma_position = float(sigma_position_m)
        self.sigma_rotation = float(sigma_rotation_rad)

    @property
    def n_model(self) -> int:
        """Number of model parameters (the cache's free set)."""
        return len(self.cache.free)

    @property
    def n_free(self) -> int:
        return self.n_model + 6

    def initial_vector(self, model_x: npt.ArrayLike) -> np.ndarray:
        """x for model parameters ``model_x`` and the reference registration (φ = 0)."""
        return np.concatenate([np.asarray(model_x, dtype=float), np.zeros(3), self.reference.translation])

    def registration(self, x: npt.ArrayLike) -> Registration:
        """sensor_T_base at x: Ω = exp(φ) Ω_0, τ."""
        omega, tau = self._registration(np.asarray(x, dtype=float))
        return Registration(omega, tau)

    def _registration(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        phi, tau = x[self.n_model : self.n_model + 3], x[self.n_model + 3 :]
        return pin.exp3(phi) @ self.reference.rotation, tau

    def _state(self, x: npt.ArrayLike):
        x = np.asarray(x, dtype=float)
        poses, sens = self.cache.evaluate(x[: self.n_model])
        omega, tau = self._registration(x)
        relative = self.rotations.transpose(0, 2, 1) @ omega @ poses.tool_rotations  # E_k
        return x, poses, sens, omega, tau, relative

    def residual(self, x: npt.ArrayLike) -> np.ndarray:
        _, poses, _, omega, tau, relative = self._state(x)
        position = (poses.tool_positions @ omega.T + tau - self.points) / self.sigma_position
        rotation = np.stack([pin.log3(e) for e in relative]) / self.sigma_rotation
        return np.hstack([position, rotation]).reshape(-1)

    def _left(self, poses, relative) -> np.ndarray:
        """Jlog3(E_k) R_kᵀ (K, 3, 3): d log E_k per world rotation ω of the tool."""
        return np.stack([pin.Jlog3(e) for e in relative]) @ poses.tool_rotations.transpose(0, 2, 1)

    def jacobian(self, x: npt.ArrayLike) -> np.ndarray:
        x, poses, sens, omega, _, relative = self._state(x)
        k, n = len(self.points), self.n_model
        # exp(φ + δ) = exp(Jl(φ) δ) exp(φ), Jl(φ) = Jexp3(−φ): δ moves Ω by the world rotation Jl δ
        world = pin.Jexp3(-x[n : n + 3])
        jac = np.zeros((k, 6, n + 6))
        velocity = sens.point_velocity(poses.tool_positions)  # (K, n, 3)
        jac[:, :3, :n] = np.einsum("ij,knj->kin", omega, velocity) / self.sigma_position
        jac[:, :3, n : n + 3] = -skew(poses.tool_positions @ omega.T) @ world / self.sigma_position
        jac[:, :3, n + 3 :] = np.eye(3) / self.sigma_position
        left = self._left(poses, relative)
        jac[:, 3:, :n] = np.einsum("kij,knj->kin", left, sens.angular) / self.sigma_rotation
        jac[:, 3:, n : n + 3] = left @ omega.T @ world / self.sigma_rotation
        return jac.reshape(6 * k, n + 6)

    def noise_jacobian(self, x: npt.ArrayLike) -> np.ndarray:
        """Derivative of each row's residual with respect to that row's sensor noise.

        The noise of row k is (ζ_k [m], ξ_k [rad]): g_k → g_k + ζ_k and
        G_k → exp(ξ_k) G_k, the linearised sensor model of eq 20–22 (R_ZYX(ξ) and
        exp(ξ) agree to first order up to the order of ξ's components, which have
        equal variances). The residual is block-diagonal in the rows.

        Returns:
            (K, 6, 6): block k = d r_k / d (ζ_k, ξ_k).
        """
        _, poses, _, omega, _, relative = self._state(x)
        blocks = np.zeros((len(self.points), 6, 6))
        blocks[:, :3, :3] = -np.eye(3) / self.sigma_position
        blocks[:, 3:, 3:] = -self._left(poses, relative) @ omega.T / self.sigma_rotation
        return blocks
