"""Pinocchio's SO(3) log and its Jacobian, over a stack of rotations at once.

``pin.log3`` and ``pin.Jlog3`` take one matrix per call; the residuals need
them for every row, every evaluation. These evaluate the same formulas
(Pinocchio's ``log3`` and ``Jlog3``, pinocchio/spatial/log.hxx) on (K, 3, 3)
arrays with numpy:

    log R = theta / (2 sin theta) (R − Rᵀ)^∨,  theta = angle of R,
    Jlog3(R) = alpha r rᵀ + (theta / (2 tan(theta/2))) I + ½ [r]×,
    alpha = 1/theta² − 1 / (2 theta tan(theta/2)),  r = log R,

with Pinocchio's Taylor expansions for small angles (alpha = 1/12 + theta²/720,
diagonal term 1 − theta²/12). The angle comes from scipy's quaternion
extraction, accurate up to and including theta = pi. (sin θ / (1 − cos θ) is
written cot(θ/2), which loses no digits to cancellation at small angles.)
:func:`skew` is the hat map [v]× over stacks of vectors.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation

#: Below this angle [rad] Jlog3 uses its Taylor expansion (Pinocchio: eps^(1/3)).
TAYLOR_ANGLE = np.finfo(float).eps ** (1.0 / 3.0)


def log3(rotations: npt.ArrayLike) -> np.ndarray:
    """log of each rotation (K, 3, 3) → rotation vectors (K, 3) [rad], like ``pin.log3``."""
    rotations = np.asarray(rotations, dtype=float)
    if len(rotations) == 0:
        return np.zeros((0, 3))
    return Rotation.from_matrix(rotations).as_rotvec()


def jlog3(rotations: npt.ArrayLike, logs: np.ndarray | None = None) -> np.ndarray:
    """Jacobian of log3 for a right perturbation of each rotation, (K, 3, 3) → (K, 3, 3),
    like ``pin.Jlog3``; ``logs`` (K, 3) are the rotations' logs if already known."""
    r = log3(rotations) if logs is None else np.asarray(logs, dtype=float)
    theta2 = np.einsum("ki,ki->k", r, r)
    theta = np.sqrt(theta2)
    small = theta < TAYLOR_ANGLE
    big = ~small
    alpha = 1.0 / 12.0 + theta2 / 720.0
    diagonal = 1.0 - theta2 / 12.0
    if np.any(big):
        t = theta[big]
        cot_half = 1.0 / np.tan(0.5 * t)  # = sin t / (1 − cos t)
        alpha[big] = 1.0 / theta2[big] - cot_half / (2.0 * t)
        diagonal[big] = 0.5 * t * cot_half
    out = alpha[:, None, None] * r[:, :, None] * r[:, None, :]
    out[:, 0, 0] += diagonal
    out[:, 1, 1] += diagonal
    out[:, 2, 2] += diagonal
    half = 0.5 * r
    out[:, 0, 1] -= half[:, 2]
    out[:, 0, 2] += half[:, 1]
    out[:, 1, 0] += half[:, 2]
    out[:, 1, 2] -= half[:, 0]
    out[:, 2, 0] -= half[:, 1]
    out[:, 2, 1] += half[:, 0]
    return out


def skew(v: np.ndarray) -> np.ndarray:
    """[v]× for vectors (..., 3) → (..., 3, 3)."""
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out
