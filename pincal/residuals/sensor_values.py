"""The values a sensor residual (:mod:`pincal.residuals.sensor`) is made of and gives: the weights of its rows,
which of its blocks are fitted, the effects it models, the registration and target geometry at a parameter
vector, and the state of one evaluation."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from pincal.model.effects import Effect, EffectInputs
from pincal.model.sensitivity import Sensitivity, ToolPoses
from pincal.model.sensor import Registration
from pincal.model.thermal import RowConditions

__all__ = ["RowWeights", "FittedBlocks", "ModelledEffects", "TargetEstimate", "SensorState", "Linearisation"]


@dataclass(frozen=True)
class RowWeights:
    """The weight of each row's residuals: its measurement noise's inverse, so position and orientation need
    no ad-hoc scale.

    Attributes:
        position: w_k = 1/sigma_pos,k [1/m], a scalar or (K,).
        rotation: v_k = 1/sigma_rot,k [1/rad], a scalar or (K,).
    """

    position: npt.ArrayLike = 1.0
    rotation: npt.ArrayLike = 1.0


@dataclass(frozen=True)
class FittedBlocks:
    """Which blocks of a sensor residual's unknowns are fitted, and in which directions.

    Attributes:
        registration / points / rotation: whether the registrations, the target points and the target
            rotation are unknown (else held at the start's).
        point_basis: (3P, b) orthonormal columns: the points' unknowns are b values z with
            m = start.points + basis z (the directions outside the basis held at the start's
            values, :mod:`pincal.fit.target_hold`); default: the 3P coordinates themselves.
        registration_basis: (6S, b) orthonormal columns: the registrations' unknowns (phi_s, tau_s of
            each session) are b values z, (phi, tau) = (0, start's tau) + basis z (the rotations outside
            it held at the start's, :mod:`pincal.fit.registration_hold`); default: the 6S themselves.
    """

    registration: bool = True
    points: bool = True
    rotation: bool = True
    point_basis: npt.ArrayLike | None = None
    registration_basis: npt.ArrayLike | None = None


@dataclass(frozen=True)
class ModelledEffects:
    """The unmodelled effects a sensor residual fits (:mod:`pincal.model.effects`), what they act on, and the
    fixed per-row changes they add to.

    Attributes:
        effects: the effects, their values unknowns of the fit.
        inputs: their inputs (gravity torques, time ...); needed when there are effects.
        conditions: fixed per-row thermal expansion and pause steps (a report's, :mod:`pincal.model.thermal`).
    """

    effects: Sequence[Effect] = ()
    inputs: EffectInputs | None = None
    conditions: RowConditions | None = None


@dataclass(frozen=True)
class TargetEstimate:
    """Registration and target geometry at a parameter vector.

    Attributes:
        registration: sensor_T_base (of the first session when there are several).
        points: target points in the tool frame [m], (P, 3).
        rotation: target rotation R_T in the tool frame, (3, 3).
        registrations: sensor_T_base of each session (default: ``(registration,)``);
            when given, ``registration`` is set to its first.
        conditions: each row's thermal expansion and pause step at these values, or None.
    """

    registration: Registration
    points: np.ndarray
    rotation: np.ndarray
    registrations: tuple[Registration, ...] = ()
    conditions: RowConditions | None = None

    def __post_init__(self) -> None:
        if self.registrations:
            object.__setattr__(self, "registrations", tuple(self.registrations))
            object.__setattr__(self, "registration", self.registrations[0])
        else:
            object.__setattr__(self, "registrations", (self.registration,))


#: What :meth:`SensorResidual.state` gives: tool poses, sensitivities, target, target points in the base
#: frame (K, P, 3) [m].
SensorState = tuple[ToolPoses, Sensitivity, TargetEstimate, np.ndarray]


@dataclass
class Linearisation:
    """What the Jacobian blocks of a sensor residual share at one x
    (:meth:`pincal.residuals.sensor.SensorResidual._linearisation`)."""

    state: SensorState
    omega: np.ndarray  # each row's Omega, (3, 3) or (K, 3, 3)
    offsets: np.ndarray  # the target points' offsets from the tool origin in the sensor frame (K, P, 3) [m]
    scale: float  # sensor scale s
    sensed: np.ndarray  # sensed points, (1 + s) excluded (K, P, 3) [m]
    jlog: np.ndarray | None = None  # with orientations: Jlog3(E_k) (K, 3, 3)
    left: np.ndarray | None = None  # with orientations: Jlog3(E_k) E_kᵀ G_kᵀ Omega (K, 3, 3)
    joint_points: np.ndarray | None = None  # with joints: d(point)/d(q_j) (K, P, 3, N)
    joint_turns: np.ndarray | None = None  # with joints and orientations: (K, 3, N)
    bend_points: np.ndarray | None = None  # with lateral effects: d(point)/d(bend) (K, P, 3, 2N)
    bend_turns: np.ndarray | None = None  # with lateral effects and orientations: (K, 3, 2N)
