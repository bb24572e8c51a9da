"""The expected norm of a zero-mean Gaussian error in 3D, E‖e‖ for e ~ N(0, C).

Computed exactly: writing e = C^½ u, u ~ N(0, I₃) = ρ n with ρ ~ χ₃ independent of the
direction n, E‖e‖ = E[ρ] · mean over the unit sphere of √(nᵀ C n), E[ρ] = 2√(2/π); the sphere
mean is a fixed Gauss–Legendre × trapezoid quadrature (spectrally accurate). The paper's noise
limit (:mod:`pincal.paper.noise_limit`) and the planner's predicted errors
(:mod:`pincal.planning.design`) turn their covariances into expected norms with it.
"""

from __future__ import annotations

import functools

import numpy as np

__all__ = ["mean_norm"]

_CHI3_MEAN = 2.0 * np.sqrt(2.0 / np.pi)  # E‖u‖ for u ~ N(0, I₃)


@functools.lru_cache(maxsize=8)
def _sphere_quadrature(n_polar: int, n_azimuth: int) -> tuple[np.ndarray, np.ndarray]:
    """Nodes and weights of :func:`mean_norm`'s sphere rule, built once per size.

    Returns:
        n_i n_j of the M = n_polar · n_azimuth unit directions, (M, 9), and the
        weights, (M,), summing to 1; both read-only.
    """
    cos, weight = np.polynomial.legendre.leggauss(n_polar)
    azimuth = 2.0 * np.pi * np.arange(n_azimuth) / n_azimuth
    sin = np.sqrt(1.0 - cos**2)
    directions = np.stack(
        [np.outer(sin, np.cos(azimuth)), np.outer(sin, np.sin(azimuth)), np.repeat(cos[:, None], n_azimuth, 1)],
        axis=-1,
    ).reshape(-1, 3)
    weights = np.repeat(weight / 2.0, n_azimuth) / n_azimuth  # sums to 1
    outer = (directions[:, :, None] * directions[:, None, :]).reshape(-1, 9)
    outer.flags.writeable = weights.flags.writeable = False
    return outer, weights


def mean_norm(covariances: np.ndarray, n_polar: int = 24, n_azimuth: int = 48) -> np.ndarray:
    """E‖e‖ for zero-mean Gaussians e ~ N(0, C) in 3D, C of shape (..., 3, 3).

    E‖e‖ = 2√(2/π) · (1/4π) ∮ √(nᵀ C n) dn, the sphere integral by Gauss–Legendre
    in cos θ (``n_polar`` nodes) times the trapezoid rule in the azimuth.
    """
    outer, weights = _sphere_quadrature(n_polar, n_azimuth)
    covariances = np.asarray(covariances, dtype=float)
    quadratic = covariances.reshape(*covariances.shape[:-2], 9) @ outer.T  # nᵀ C n = Σ_ij C_ij n_i n_j
    return _CHI3_MEAN * np.sqrt(np.clip(quadratic, 0.0, None)) @ weights
