"""What each robot configuration tells a calibration: the weighted measurement Jacobian.

A calibration (:func:`pincal.fit.chain_calibration.calibrate_chain`) estimates
the kinematic parameters of a level together with the registration
sensor_T_base and, unless the tool is known, the target. Linearised at the
model the plan assumes (the URDF as loaded, or a calibration of data already
recorded), row k's residual responds to a parameter step δθ as F_k δθ, with
F_k the analytic Jacobian of :class:`pincal.residuals.sensor.SensorResidual`
weighted by the sensor noise (1/σ_p [1/m] for points, 1/σ_a [1/rad] for
orientations). The information of a set S of configurations is
M(S) = Σ_{k∈S} F_kᵀ F_k, and the estimate's covariance is M⁻¹ (Cramér–Rao; the
least-squares estimate reaches it to first order).

The error of the calibrated model at a configuration e, against the truth, is
A_e δθ with A_e the unweighted position (and orientation) rows of the same
Jacobian [m or rad per parameter unit]; its covariance is A_e M⁻¹ A_eᵀ
(:mod:`pincal.paper.noise_limit` turns such covariances into expected norms).

The registration's rotation does not change these numbers (noise is isotropic),
so the model uses the identity registration.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from pincal.errors import PincalError
from pincal.fit.prior import prior_sigmas
from pincal.measurements.data import SENSOR_KINDS, SensorKind
from pincal.model.chain import KinematicChain, points_in_base
from pincal.model.dh.parameters import DHParameterSet
from pincal.model.parameter_sets import LEVELS, NoParameters
from pincal.model.sensor import Registration
from pincal.planning.defaults import PLAN_LEVELS
from pincal.residuals.base import KinematicsCache
from pincal.residuals.sensor import REGISTRATION_NAMES, SensorResidual, TargetEstimate
from pincal.residuals.sensor_values import FittedBlocks, RowWeights

__all__ = [
    "PLAN_LEVELS", "DEFAULT_TARGET_CENTRE_M", "DEFAULT_TARGET_RADIUS_M", "SensorModel", "default_target_points",
    "plan_parameters", "MeasurementModel",
]

#: Corners of a cube, the default directions of the target's points (unit vectors).
_CORNERS = np.array(
    [[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1], [-1, -1, -1], [-1, 1, 1], [1, -1, 1], [1, 1, -1]],
    dtype=float,
) / np.sqrt(3.0)
#: Default target when none is known: its centre 0.1 m along the tip link's z axis,
#: its points 0.05 m from the centre (a hand-sized marker body; TIAGo's markers are
#: 97–166 mm apart, data/tiago_mocap/README.md).
DEFAULT_TARGET_CENTRE_M = np.array([0.0, 0.0, 0.1])
DEFAULT_TARGET_RADIUS_M = 0.05


@dataclass(frozen=True)
class SensorModel:
    """What the sensor sees at each configuration.

    Attributes:
        kind: ``point`` (one point), ``points`` (a rigid target of several
            points) or ``pose`` (one point and the target's orientation).
        n_points: points per configuration.
    """

    kind: SensorKind
    n_points: int

    def __post_init__(self) -> None:
        if self.kind not in SENSOR_KINDS:
            raise PincalError(f"sensor kind '{self.kind}': use one of {', '.join(SENSOR_KINDS)}")

    @property
    def has_rotation(self) -> bool:
        return self.kind == "pose"

    @property
    def label(self) -> str:
        return f"points:{self.n_points}" if self.kind == "points" else self.kind

    @property
    def rows(self) -> int:
        """Scalar measurements per configuration: 3 per point, plus 3 for an orientation."""
        return 3 * self.n_points + (3 if self.has_rotation else 0)


def default_target_points(n_points: int) -> np.ndarray:
    """Assumed target points in the tool frame when none are known [m], (P, 3).

    One point: off the tool's axes (a point on a joint axis would hide that
    joint's rotation). Several: cube-corner directions about the centre.
    """
    if n_points > len(_CORNERS):
        raise PincalError(
            f"no default layout for {n_points} target points; give their positions with --target-points"
        )
    return DEFAULT_TARGET_CENTRE_M + DEFAULT_TARGET_RADIUS_M * _CORNERS[:n_points]


def plan_parameters(chain: KinematicChain, level: str):
    """The kinematic parameter set of ``level`` on ``chain`` (None at ``registration``)."""
    if level not in PLAN_LEVELS:
        raise PincalError(f"--level must be one of {', '.join(PLAN_LEVELS)}, got '{level}'")
    if level == "dh":
        return DHParameterSet(chain)
    return LEVELS[level](chain) if level in LEVELS else None


class MeasurementModel:
    """Weighted measurement Jacobians of a chain at its current placements.

    Args:
        chain: the chain (its tool is the measured frame's parent); placements
            as they are now are the linearisation point.
        level: ``registration``, ``offsets``, ``full`` or ``dh``.
        sensor: what is measured.
        points: target points in the tool frame [m], (P, 3).
        target_rotation: the measured frame in the tool frame (pose), (3, 3).
        tool_known: the target is known (not estimated).
        sigma_pos_m: σ_p, position noise per axis [m].
        sigma_rot_rad: σ_a, orientation noise per component [rad] (pose).
    """

    def __init__(
        self,
        chain: KinematicChain,
        level: str,
        sensor: SensorModel,
        points: npt.ArrayLike,
        target_rotation: npt.ArrayLike | None = None,
        tool_known: bool = False,
        sigma_pos_m: float = 1.0,
        sigma_rot_rad: float = 1.0,
    ) -> None:
        self.chain, self.level, self.sensor = chain, level, sensor
        self.params = plan_parameters(chain, level)
        self.points = np.atleast_2d(np.asarray(points, dtype=float))
        if self.points.shape != (sensor.n_points, 3):
            raise PincalError(
                f"--measure {sensor.label} needs {sensor.n_points} target point(s), got {len(self.points)}"
            )
        self.target_rotation = np.eye(3) if target_rotation is None else np.asarray(target_rotation, float)
        self.tool_known = tool_known
        self.sigma_pos_m, self.sigma_rot_rad = float(sigma_pos_m), float(sigma_rot_rad)
        self._size = self.params.size if self.params is not None else 0
        # the parameter vector of the model as it is: zero for offsets and placement errors, the table for DH
        self._base = (self.params.nominal.to_vector() if isinstance(self.params, DHParameterSet)
                      else np.zeros(self._size))
        self.names = self._names()

    @property
    def kinematic(self) -> np.ndarray:
        """Columns of the kinematic parameters (the first ones)."""
        return np.arange(self._size)

    def _names(self) -> tuple[str, ...]:
        names = [info.name for info in self.params.info] if self.params is not None else []
        names += [f"registration.{n}" for n in REGISTRATION_NAMES]
        if not self.tool_known:
            names += [f"target.point{p + 1}.{a}" for p in range(self.sensor.n_points) for a in "xyz"]
            if self.sensor.has_rotation:
                names += [f"target.r{a}" for a in "xyz"]
        return tuple(names)

    def prior_precision(self, prior) -> np.ndarray:
        """Λ's diagonal for a calibration with ``prior`` (a :class:`pincal.fit.prior.Prior`):
        1/σ_i² [1/m² or 1/rad²] for each kinematic column, zero for the registration and the target
        (eq P1 of :mod:`pincal.fit.prior` penalises neither), (n,)."""
        precision = np.zeros(len(self.names))
        if self.params is not None:
            precision[self.kinematic] = 1.0 / prior_sigmas(self.params, prior) ** 2
        return precision

    def jacobian(self, q: npt.ArrayLike, chunk: int = 2000) -> np.ndarray:
        """Noise-weighted Jacobian blocks F_k of configurations ``q`` (K, N), (K, m, n).

        Row k's m = 3P (+ 3) rows are its points' x, y, z, then its orientation
        (dimensionless: residual / σ); columns follow :attr:`names`.
        """
        q = np.atleast_2d(np.asarray(q, dtype=float))
        blocks = [self._jacobian(q[start : start + chunk]) for start in range(0, len(q), chunk)]
        return np.concatenate(blocks) if blocks else np.zeros((0, self.sensor.rows, len(self.names)))

    def _jacobian(self, q: np.ndarray) -> np.ndarray:
        params = self.params if self.params is not None else NoParameters(self.chain)
        cache = KinematicsCache(params, np.arange(self._size), self._base, q)
        poses, _ = cache.evaluate(self._base)
        world = points_in_base(poses.tool_positions, poses.tool_rotations, self.points)  # (K, P, 3)
        rotations = poses.tool_rotations @ self.target_rotation if self.sensor.has_rotation else None
        start = TargetEstimate(Registration(np.eye(3), np.zeros(3)), self.points, self.target_rotation)
        objective = SensorResidual(
            cache, world, rotations, start,
            RowWeights(1.0 / self.sigma_pos_m, 1.0 / self.sigma_rot_rad),
            FittedBlocks(points=not self.tool_known, rotation=not self.tool_known),
        )
        jac = objective.jacobian(objective.start_vector())
        return jac[objective.row_indices()]

    def error_jacobian(self, q: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray | None]:
        """Unweighted error rows A_e at configurations ``q``.

        Returns:
            Position rows [m per parameter unit], (E, P, 3, n), and orientation
            rows [rad per parameter unit], (E, 3, n) (None without orientations).
        """
        blocks = self.jacobian(q)
        n_pos = 3 * self.sensor.n_points
        position = blocks[:, :n_pos].reshape(len(blocks), self.sensor.n_points, 3, -1) * self.sigma_pos_m
        rotation = blocks[:, n_pos:] * self.sigma_rot_rad if self.sensor.has_rotation else None
        return position, rotation
