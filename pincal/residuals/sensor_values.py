"""The values a sensor residual (:mod:`pincal.residuals.sensor`) starts from and gives: the registration and
target geometry at a parameter vector, and the state of one evaluation."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pincal.model.sensitivity import Sensitivity, ToolPoses
from pincal.model.sensor import Registration
from pincal.model.thermal import RowConditions

__all__ = ["TargetEstimate", "SensorState"]


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
