"""Joint effects seen through a camera (eq C4 of pincal.residuals.camera) and diagnose on a camera's images
(pincal.diagnosis.camera_diagnose).

A UR5 of example-robot-data, eye in hand (pincal.workflows.camera_simulation's scene: the joint placements off by
0.5 mm / 0.5 mrad, the mount 10 cm and 30 degrees off); the corners are projected at the true joint angles, the
readings being those minus the true effect.
"""

from __future__ import annotations

import numpy as np
import pytest

from pincal.fit.camera_calibration import CameraProblem
from pincal.fit.camera_start import hand_eye_start
from pincal.model.effects import Effect, effect_inputs
from pincal.model.parameter_sets import PlacementErrors
from pincal.model.pinhole import INTRINSIC_NAMES
from pincal.residuals.base import KinematicsCache
from pincal.residuals.camera import CameraResidual
from pincal.residuals.sensor_values import ModelledEffects
from pincal.workflows.camera_simulation import INTRINSICS, CameraSimulationSettings, simulate_camera

EFFECTS = (Effect("backlash", "elbow_joint", source="approach"), Effect("cyclic", "wrist_1_joint", harmonic=2),
           Effect("compliance", "shoulder_lift_joint"), Effect("encoder_scale", "wrist_2_joint"))


@pytest.mark.parametrize("arrangement", ["eye_in_hand", "eye_to_hand"])
def test_effect_columns_match_central_differences(arrangement: str):
    rng = np.random.default_rng(4)
    simulated = simulate_camera(CameraSimulationSettings(arrangement, images=4, held_out=0, seed=2))
    chain, corners = simulated.chain, simulated.corners
    params = PlacementErrors(chain)
    start, _ = hand_eye_start(chain, corners, arrangement, INTRINSICS)
    problem = CameraProblem(chain, params, corners, start, np.zeros(len(corners.images), dtype=np.intp))
    inputs = effect_inputs(chain, problem.rows_view())
    cache = KinematicsCache(params, np.arange(params.size), rng.normal(0.0, 1e-3, params.size), corners.q)
    objective = CameraResidual(cache, corners, start, tuple(range(len(INTRINSIC_NAMES))),
                               effects=ModelledEffects(EFFECTS, inputs))
    x = objective.start_vector() + rng.normal(0.0, 1e-3, objective.n_params)
    x[objective.blocks["effects"]] = rng.normal(0.0, 3e-3, objective.blocks["effects"].stop
                                                 - objective.blocks["effects"].start)
    analytic = objective.jacobian(x)
    step = 1e-6  # central differences: truncation ~1e-12 relative, rounding ~1e-10 px / 1e-6
    numeric = np.array([(objective.residual(x + step * e) - objective.residual(x - step * e)) / (2 * step)
                        for e in np.eye(objective.n_params)]).T
    scale = np.abs(numeric).max(axis=0)
    assert np.all(scale[objective.blocks["effects"]] > 1.0)  # every effect moves some corner by a pixel per unit
    assert np.max(np.abs(analytic - numeric).max(axis=0) / scale) < 1e-5
    # a candidate's columns (its values zero) are the Jacobian's of the residual with it, at zero
    plain = CameraResidual(cache, corners, start, tuple(range(len(INTRINSIC_NAMES))),
                           effects=ModelledEffects((), inputs))
    x0 = x[: plain.n_params]
    with_zero = np.r_[x0, np.zeros(objective.n_params - plain.n_params)]
    columns = np.hstack(plain.effect_columns(x0, EFFECTS))
    assert np.allclose(columns, objective.jacobian(with_zero)[:, objective.blocks["effects"]], rtol=1e-12, atol=1e-9)
