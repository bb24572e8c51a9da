"""Methods 1–3 on simulated KUKA LWR 4+ data (Franaszek & Marvel 2022, Section 7).

Noise-free data must give the ground truth back exactly; noisy data must reach
the accuracy the paper reports for Method 2 (issue "Done when").
"""

from __future__ import annotations

import numpy as np
import pytest

from pincal.errors import CalibrationError
from pincal.fit.metrics import pose_errors
from pincal.fit.paper_methods import (
    ABSORBED,
    FROM_CPA,
    NOT_BY_CPA,
    calibrate_paper,
    cpa_groups,
)
from pincal.model.chain import KinematicChain
from pincal.model.dh import (
    KUKA_LWR4_DH,
    TABLE2_LARGE,
    TABLE2_SMALL,
    random_deviations_like,
)
from pincal.robots import KUKA_FLANGE_LINK
from pincal.simulation.paper import SimulationSettings, simulate_experiment

NOISE_FREE = SimulationSettings(seed=11)


def _calibrate(urdf, experiment, method, weight=1.0):
    chain = KinematicChain.from_urdf(urdf, KUKA_FLANGE_LINK, tool=experiment.tool)
    result = calibrate_paper(chain, experiment.calibration, method, weight=weight)
    errors = pose_errors(
        chain, experiment.validation, result.registration_position, result.registration_orientation
    )
    return result, errors


def _deviation_sets():
    rng = np.random.default_rng(2024)
    return [
        TABLE2_SMALL,
        TABLE2_LARGE,
        random_deviations_like(TABLE2_SMALL, rng, "random-small"),
        random_deviations_like(TABLE2_LARGE, rng, "random-large"),
    ]


@pytest.mark.parametrize("deviations", _deviation_sets(), ids=lambda d: d.name)
@pytest.mark.parametrize("method", [1, 2, 3])
def test_noise_free_data_recovers_ground_truth(kuka_urdf, kuka_chain, deviations, method):
    experiment = simulate_experiment(kuka_chain, KUKA_LWR4_DH, deviations, NOISE_FREE)
    result, errors = _calibrate(kuka_urdf, experiment, method)
    assert errors.position_m.max() < 1e-8
    assert errors.rotation_rad.max() < 1e-8
    determined = np.array([s not in (ABSORBED, NOT_BY_CPA) for s in result.status])
    diff = result.table.to_vector() - experiment.truth.to_vector()
    assert np.abs(diff[determined]).max() < 1e-8


def test_registration_absorbs_d1_and_eps1(kuka_urdf, kuka_chain):
    """d_1 and eps_1 keep nominal values; Registration 1 equals the truth composed with their change."""
    experiment = simulate_experiment(kuka_chain, KUKA_LWR4_DH, TABLE2_LARGE, NOISE_FREE)
    result, _ = _calibrate(kuka_urdf, experiment, 2)
    assert result.status[7] == ABSORBED and result.status[3 * 7] == ABSORBED  # eps_1, d_1
    assert result.table.epsilon[0] == KUKA_LWR4_DH.epsilon[0]
    # Table 2 has zero deviation for eps_1 and d_1, so the true registration is recovered
    assert np.abs(result.registration_position.rotation - experiment.registration.rotation).max() < 1e-9
    assert np.abs(result.registration_position.translation - experiment.registration.translation).max() < 1e-9


def test_method2_reaches_paper_accuracy_and_beats_method1_in_orientation(kuka_urdf, kuka_chain):
    """sigma_p = 0.055 mm, sigma_a = 0.055 deg, noise-free held-out poses, 16 seeds, both sets.

    Thresholds from the issue: Method 2 mean position error <= 0.20 mm, mean
    orientation error <= 0.05 deg, Method 1 orientation error above Method 2's.
    Over 40 seeds Method 2 averages 0.162 mm (seed-to-seed sd 0.056 mm) and
    0.032 deg, Method 1 0.050 deg; 16 seeds keep the test far from chance.
    """
    means = {1: [], 2: []}
    for seed in range(16):
        deviations = TABLE2_LARGE if seed % 2 else TABLE2_SMALL
        settings = SimulationSettings(0.055, 0.055, seed=seed, validation_noise=False)
        experiment = simulate_experiment(kuka_chain, KUKA_LWR4_DH, deviations, settings)
        for method in (1, 2):
            _, errors = _calibrate(kuka_urdf, experiment, method)
            means[method].append((errors.position.mean, errors.rotation.mean))
    m1, m2 = np.mean(means[1], axis=0), np.mean(means[2], axis=0)
    assert m2[0] <= 0.20, f"Method 2 mean position error {m2[0]:.3f} mm"
    assert m2[1] <= 0.05, f"Method 2 mean orientation error {m2[1]:.4f} deg"
    assert m1[1] > m2[1], f"Method 1 orientation {m1[1]:.4f} deg not above Method 2 {m2[1]:.4f} deg"


def test_twists_come_from_cpa_and_alpha_n_is_not_claimed(kuka_urdf, noisy_large_experiment):
    result, _ = _calibrate(kuka_urdf, noisy_large_experiment, 2)
    assert all(s == FROM_CPA for s in result.status[:6])
    assert result.status[6] == NOT_BY_CPA
    assert np.isnan(result.std[6])
    err = np.degrees(np.abs(result.table.alpha[:6] - noisy_large_experiment.truth.alpha[:6]))
    assert err.max() < 0.3  # the paper's largest twist deviation over all its runs


def test_without_cpa_rows_twists_stay_nominal(kuka_urdf, noisy_large_experiment):
    data = noisy_large_experiment.calibration.with_role("calibration")
    chain = KinematicChain.from_urdf(kuka_urdf, KUKA_FLANGE_LINK, tool=noisy_large_experiment.tool)
    result = calibrate_paper(chain, data, 2)
    assert np.array_equal(result.table.alpha, result.nominal.alpha)
    assert np.abs(result.table.alpha - KUKA_LWR4_DH.alpha).max() < 1e-12
    assert any("no CPA rows" in note for note in result.notes)


def test_method2_without_orientations_is_refused(kuka_urdf, noisy_large_experiment):
    data = noisy_large_experiment.calibration
    positions_only = type(data)(
        joint_names=data.joint_names, q=data.q, points=data.points, rotations=None,
        roles=data.roles, lines=data.lines, extra={}, source="x.csv",
    )
    chain = KinematicChain.from_urdf(kuka_urdf, KUKA_FLANGE_LINK, tool=noisy_large_experiment.tool)
    with pytest.raises(CalibrationError, match="needs orientations"):
        calibrate_paper(chain, positions_only, 2)
    calibrate_paper(chain, positions_only, 1)  # Method 1 works on positions alone


def test_method3_depends_on_weight(kuka_urdf, noisy_large_experiment):
    a, _ = _calibrate(kuka_urdf, noisy_large_experiment, 3, weight=1.0)
    b, _ = _calibrate(kuka_urdf, noisy_large_experiment, 3, weight=1000.0)
    assert np.abs(a.table.to_vector() - b.table.to_vector()).max() > 1e-7


def test_cpa_groups_split_runs_by_moving_joint():
    q = np.zeros((9, 3))
    q[0:3, 0] = [0.1, 0.2, 0.3]
    q[3:6, 1] = [0.1, 0.2, 0.3]
    q[6:9, 2] = [0.1, 0.2, 0.3]
    groups = cpa_groups(q)
    assert {k: v.tolist() for k, v in groups.items()} == {0: [0, 1, 2], 1: [3, 4, 5], 2: [6, 7, 8]}


def test_cpa_groups_reject_short_or_mixed_runs():
    q = np.zeros((5, 2))
    q[0:2, 0] = [0.1, 0.2]
    q[2:5, 1] = [0.1, 0.2, 0.3]
    with pytest.raises(CalibrationError, match="at least 3 rows"):
        cpa_groups(q)
