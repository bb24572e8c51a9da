"""Pinocchio's SO(3) log and its Jacobian over a stack of rotations, and [v]× over stacks.

:func:`log3` and :func:`jlog3` call Pinocchio's own ``pin.log3`` and
``pin.Jlog3`` (pinocchio/spatial/log.hxx) on each (3, 3) matrix of a
(K, 3, 3) stack, so every residual gets Pinocchio's numbers bit for bit:

    log R = theta / (2 sin theta) (R − Rᵀ)^∨,  theta = angle of R,
    Jlog3(R) = alpha r rᵀ + (theta / (2 tan(theta/2))) I + ½ [r]×,
    alpha = 1/theta² − 1 / (2 theta tan(theta/2)),  r = log R.

A numpy evaluation of the same formulas over the whole stack (scipy's
rotation vector, tried) was no faster for the study's 100-row stacks
(about 2 µs per matrix either way) but rounded differently, and the
Levenberg–Marquardt fits, which stop at a relative cost change of 1e-12,
turn such rounding into differences of ~1e-7 relative in fitted values (the
last step taken or not): the study's numbers are reproducible from run to run
and version to version only with the same arithmetic. Pinocchio's Jlog3 is
within ~1e-8 of the exact derivative between 1e-4 and 1e-2 rad, which moves
the solver's path, not its solution (the residual defines that).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pinocchio as pin

__all__ = ["log3", "jlog3", "skew"]


def log3(rotations: npt.ArrayLike) -> np.ndarray:
    """``pin.log3`` of each rotation (K, 3, 3) → rotation vectors (K, 3) [rad]."""
    rotations = np.asarray(rotations, dtype=float)
    return np.array([pin.log3(r) for r in rotations]).reshape(len(rotations), 3)


def jlog3(rotations: npt.ArrayLike) -> np.ndarray:
    """``pin.Jlog3`` of each rotation (K, 3, 3) → (K, 3, 3): the Jacobian of log3 for a right
    perturbation R exp(δ)."""
    rotations = np.asarray(rotations, dtype=float)
    return np.array([pin.Jlog3(r) for r in rotations]).reshape(len(rotations), 3, 3)


def skew(v: np.ndarray) -> np.ndarray:
    """[v]× for vectors (..., 3) → (..., 3, 3)."""
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out
