"""Jacobian columns of the per-row changes of :mod:`pincal.model.thermal` in the sensor residual.

With f_k = 1 + α ΔT_k (eq T1) and the step d_k of row k (eq T2) the modelled point is
s_k = Ω f_k y_k + τ + d_k (+ drift, times the sensor scale, as in :mod:`pincal.residuals.sensor`);
orientations do not change. Hence

    d s/d α   = ΔT_k Ω y_k,        d s/d d_p = a_kp I,        d o/d α = d o/d d_p = 0,

and every other column of y_k (the kinematic parameters, the target points, the joint effects,
the registration's rotation) is f_k times its column without the expansion.
"""

from __future__ import annotations

import numpy as np

from pincal.model.effects import Effect, EffectInputs

__all__ = ["condition_columns", "point_columns"]


def condition_columns(effect: Effect, inputs: EffectInputs, world: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """d s/d values of a ``thermal`` or ``pause_step`` effect (module docstring), (K, P, 3, n_values),
    before the sensor scale and weights: ``world`` y_k (K, P, 3) [m], ``omega`` each row's Ω ((3, 3) or (K, 3, 3))."""
    k, n_points = world.shape[:2]
    if effect.type == "thermal":
        assert inputs.temperature is not None  # offered only with a temperature column
        return (inputs.temperature[:, None, None] * (world @ np.swapaxes(omega, -1, -2)))[..., None]
    assert inputs.pauses is not None and effect.pause is not None  # offered only for a pause of these rows
    applies = inputs.pauses[:, effect.pause - 1]
    return np.broadcast_to(applies[:, None, None, None] * np.eye(3), (k, n_points, 3, 3))


def point_columns(linear: np.ndarray, angular: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Velocities of points rigidly attached to the tool, per unit of each column:
    v + w × o for column velocities (K, n, 3) and angular velocities (K, n, 3) at
    the tool origin and point offsets o (K, P, 3) from it, all in one frame → (K, P, 3, n)."""
    k, n_points = offsets.shape[:2]
    out = np.empty((k, n_points, 3, linear.shape[1]))
    a0, a1, a2 = (angular[:, None, :, i] for i in range(3))  # (K, 1, n)
    o0, o1, o2 = (offsets[:, :, i, None] for i in range(3))  # (K, P, 1)
    out[:, :, 0, :] = linear[:, None, :, 0] + (a1 * o2 - a2 * o1)
    out[:, :, 1, :] = linear[:, None, :, 1] + (a2 * o0 - a0 * o2)
    out[:, :, 2, :] = linear[:, None, :, 2] + (a0 * o1 - a1 * o0)
    return out
