"""Simulated measurements of any chain at random configurations, with the truth behind them."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from pincal.measurements.data import MeasurementSet
from pincal.model.chain import points_in_base
from pincal.model.sensor import Registration
from pincal.simulation.paper import SimulationSettings
from pincal.simulation.sensor import (
    DEFAULT_REGISTRATION,
    SimulatedSensor,
    measure,
    random_configurations,
)

__all__ = ["DEFAULT_SIMULATION_SETTINGS", "ChainExperiment", "simulate_chain", "truth_error_mm"]

#: The default settings of :func:`simulate_chain` (frozen, so one shared instance is safe).
DEFAULT_SIMULATION_SETTINGS = SimulationSettings()


@dataclass(frozen=True)
class ChainExperiment:
    """Simulated measurements of any chain and the truth behind them.

    Attributes:
        calibration / validation: the simulated rows.
        truth: the true parameter vector of the parameter set used.
        registration: the true sensor_T_base.
        points: the true target points in the tool frame [m], (P, 3).
        target_rotation: the measured frame's rotation in the tool frame.
    """

    calibration: MeasurementSet
    validation: MeasurementSet
    truth: np.ndarray
    registration: Registration
    points: np.ndarray
    target_rotation: np.ndarray


def simulate_chain(
    params,
    truth: np.ndarray,
    points: np.ndarray,
    settings: SimulationSettings = DEFAULT_SIMULATION_SETTINGS,
    with_rotation: bool = False,
    target_rotation: np.ndarray | None = None,
    registration: Registration = DEFAULT_REGISTRATION,
) -> ChainExperiment:
    """Simulate random-configuration measurements of ``params.chain`` with the
    true parameters ``truth`` (a vector of the parameter set ``params``); the
    chain's placements are restored afterwards."""
    chain = params.chain
    rng = np.random.default_rng(settings.seed)
    target_rotation = np.eye(3) if target_rotation is None else target_rotation
    sigma_p = settings.sigma_pos_mm / 1000.0
    sigma_a = np.radians(settings.sigma_rot_deg)
    with chain.placed(params.placements(truth)):
        q_cal = random_configurations(chain, rng, settings.n_calibration)
        q_val = random_configurations(chain, rng, settings.n_validation)
        sensor = SimulatedSensor(sigma_p, sigma_a, points, target_rotation, with_rotation)
        cal = measure(chain, q_cal, registration, rng, sensor, "calibration")
        scale = 1.0 if settings.validation_noise else 0.0
        val = measure(chain, q_val, registration, rng, replace(sensor, sigma_pos_m=sigma_p * scale,
                                                               sigma_rot_rad=sigma_a * scale), "validation")
    return ChainExperiment(cal, val, np.asarray(truth, dtype=float), registration, np.asarray(points), target_rotation)


def truth_error_mm(params, truth: np.ndarray, q: np.ndarray, true_points: np.ndarray, points: np.ndarray,
                   registration: Registration, true_registration: Registration = DEFAULT_REGISTRATION,
                   placements=None) -> float:
    """Mean distance [mm] at configurations ``q`` between where the target truly is — the chain with the
    true parameters ``truth`` (of ``params``), its points ``true_points`` (P, 3) [m], seen through
    ``true_registration`` — and where a calibrated model puts it: the chain with ``placements`` (a
    calibration's ``chain_placements``; None: the chain as it is), the estimated ``points`` and
    ``registration``. The chain is not changed."""
    chain = params.chain
    with chain.placed(params.placements(truth)):
        poses = chain.poses(q)
        true = true_registration.apply_points(points_in_base(poses.tool_positions, poses.tool_rotations, true_points))
    with chain.placed(chain.placements() if placements is None else placements):
        poses = chain.poses(q)
    predicted = registration.apply_points(points_in_base(poses.tool_positions, poses.tool_rotations, points))
    return float(np.linalg.norm(predicted - true, axis=2).mean() * 1000.0)
