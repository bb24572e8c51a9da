"""Jacobian columns of the lateral compliances of :mod:`pincal.model.lateral` in the sensor residual.

A lateral compliance of joint j turns the chain at j by (δ_u, δ_v)_k = B_k · values (eq L3); the sensed
point's derivative by its values is the ``bend`` slots' point columns Ω (v_b + w_b × o) times B_k, the
orientation residual's Jlog3(E) Eᵀ G_kᵀ Ω w_b times B_k (:mod:`pincal.residuals.sensor`), both at the deflected
pose (Pinocchio's Jacobian of the bent chain).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from pincal.model.effects import BEND_EFFECTS, Effect, EffectInputs
from pincal.model.lateral import lateral_basis
from pincal.model.sensitivity import Sensitivity
from pincal.residuals.conditions import point_columns

__all__ = ["bend_bases", "row_bends", "bend_columns", "lateral_columns"]


def bend_bases(effects: Sequence[Effect], inputs: EffectInputs | None, joints: Sequence[int]
               ) -> list[np.ndarray | None]:
    """B_k of each lateral effect among ``effects`` (eq L3, (K, 2, n_values)), None for the others."""
    return [lateral_basis(e, inputs, j) if e.type in BEND_EFFECTS and inputs is not None else None
            for e, j in zip(effects, joints)]


def row_bends(bases: Sequence[np.ndarray | None], joints: Sequence[int], values: Sequence[np.ndarray],
              fixed: np.ndarray | None, n_joints: int) -> np.ndarray | None:
    """Every joint's deflections (K, 2N) [rad]: ``fixed`` (a report's, or None) plus each lateral effect's
    B_k @ values; None without either."""
    if fixed is None and all(b is None for b in bases):
        return None
    k = next(len(b) for b in bases if b is not None) if fixed is None else len(fixed)
    out = np.zeros((k, 2 * n_joints)) if fixed is None else np.array(fixed, dtype=float)
    for basis, j, value in zip(bases, joints, values):
        if basis is not None:
            out[:, 2 * j : 2 * j + 2] += basis @ value
    return out


def bend_columns(sens: Sensitivity, omega_t: np.ndarray, offsets: np.ndarray, left: np.ndarray | None,
                 factor: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None]:
    """The bend slots' columns of the sensed points (K, P, 3, 2N) (times a thermal factor f_k, eq T1) and, with
    orientations (``left`` = Jlog3(E) Eᵀ G_kᵀ Ω, (K, 3, 3)), of the orientation residual (K, 3, 2N)."""
    assert sens.bend_angular is not None and sens.bend_linear is not None  # evaluated with bends
    points = point_columns(sens.bend_linear @ omega_t, sens.bend_angular @ omega_t, offsets)
    if factor is not None:
        points *= factor[:, None, None, None]
    turns = None if left is None else left @ sens.bend_angular.transpose(0, 2, 1)
    return points, turns


def lateral_columns(columns: np.ndarray, j: int, basis: np.ndarray) -> np.ndarray:
    """Joint ``j``'s lateral effect's columns from the bend slots' ``columns`` (..., 2N) and its B_k
    (K, 2, n_values): (..., n_values), the rows first."""
    block = columns[..., 2 * j : 2 * j + 2]  # (K, ..., 2)
    return np.einsum("k...c,kcn->k...n", block, basis)
