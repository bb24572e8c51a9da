"""Methods 1–3 on simulated KUKA LWR 4+ data (Franaszek & Marvel 2022, Section 7).

Noise-free data must give the ground truth back exactly; noisy data must reach
the accuracy the paper reports for Method 2 (issue "Done when").
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.stats import f as f_distribution

from pincal.errors import CalibrationError
from pincal.fit.metrics import pose_errors
from pincal.model.chain import KinematicChain
from pincal.model.dh.table import (
    KUKA_LWR4_DH,
    TABLE2_LARGE,
    TABLE2_SMALL,
    random_deviations_like,
)
from pincal.paper.methods import (
    ABSORBED,
    CALIBRATED,
    FROM_CPA,
    NOT_BY_CPA,
    calibrate_paper,
    cpa_groups,
)
from pincal.robots import KUKA_FLANGE_LINK
from pincal.simulation.paper import SimulationSettings, simulate_experiment

NOISE_FREE = SimulationSettings(seed=11)


def _calibrate(urdf, experiment, method, weight=1.0, also=None):
    """Calibrate; eq 24 errors on the experiment's validation rows (and on ``also``)."""
    chain = KinematicChain.from_urdf(urdf, KUKA_FLANGE_LINK, tool=experiment.tool)
    result = calibrate_paper(chain, experiment.calibration, method, weight=weight)

    def errors(rows):
        with chain.placed(result.chain_placements):
            return pose_errors(chain, rows, result.registration_position, result.registration_orientation)

    if also is not None:
        return result, errors(experiment.validation), errors(also)
    return result, errors(experiment.validation)


def _deviation_sets():
    rng = np.random.default_rng(2024)
    return [
        TABLE2_SMALL,
        TABLE2_LARGE,
        random_deviations_like(TABLE2_SMALL, rng, "random-small"),
        random_deviations_like(TABLE2_LARGE, rng, "random-large"),
    ]


# Noise-free data: the only error left is the solver's. Its tolerances
# (pincal.fit.solver, xtol = ftol = gtol = 1e-12 relative) put the solution
# within ~1e-12 of the truth for parameters of order 1 (rad, m), so a residual
# TCP error of 1e-8 m (10 nm) or 1e-8 rad is four orders above what the solver
# leaves and ten orders below the smallest deviation of Table 2 (0.02 deg,
# 0.06 mm): a missed parameter or a wrong sign cannot hide under it.
NUMERICAL = 1e-8


@pytest.mark.parametrize("deviations", _deviation_sets(), ids=lambda d: d.name)
@pytest.mark.parametrize("method", [1, 2, 3])
def test_noise_free_data_recovers_ground_truth(kuka_urdf, kuka_chain, deviations, method):
    experiment = simulate_experiment(kuka_chain, KUKA_LWR4_DH, deviations, NOISE_FREE)
    result, errors = _calibrate(kuka_urdf, experiment, method)
    assert errors.position_m.max() < NUMERICAL
    assert errors.rotation_rad.max() < NUMERICAL
    determined = np.array([s not in (ABSORBED, NOT_BY_CPA) for s in result.status])
    diff = result.table.to_vector() - experiment.truth.to_vector()
    assert np.abs(diff[determined]).max() < NUMERICAL


def test_registration_absorbs_d1_and_eps1(kuka_urdf, kuka_chain):
    """d_1 and eps_1 keep nominal values; Registration 1 equals the truth composed with their change."""
    experiment = simulate_experiment(kuka_chain, KUKA_LWR4_DH, TABLE2_LARGE, NOISE_FREE)
    result, _ = _calibrate(kuka_urdf, experiment, 2)
    assert result.status[7] == ABSORBED and result.status[3 * 7] == ABSORBED  # eps_1, d_1
    assert result.table.epsilon[0] == KUKA_LWR4_DH.epsilon[0]
    # Table 2 has zero deviation for eps_1 and d_1, so the true registration is
    # recovered; noise-free, Arun's closed form adds only rounding to the
    # solver's ~1e-12, hence 1e-9 (rad, m)
    assert np.abs(result.registration_position.rotation - experiment.registration.rotation).max() < 1e-9
    assert np.abs(result.registration_position.translation - experiment.registration.translation).max() < 1e-9


def test_method2_reaches_paper_accuracy_and_beats_method1_in_orientation(kuka_urdf, kuka_chain):
    """sigma_p = 0.055 mm, sigma_a = 0.055 deg (the paper's Figure 2), 16 seeds, both sets.

    Each seed's held-out poses are simulated twice from the same calibration
    data: noise-free (the error against the truth) and noisy (eq 24 as the
    paper computes it, against noisy test measurements). Requirements:

    * the project's issue ("Done when"): Method 2's mean error against the
      truth <= 0.20 mm and <= 0.05 deg;
    * the paper (Section 9): Method 2's mean errors in its own metric are about
      4 sigma_p and 4 sigma_a (Figure 5a,b), so they must not exceed them;
    * the paper (Figure 5b and Section 9): orientations through Registration 2
      after Method 2 are more accurate than Method 1's, and vary much less
      from one noise realisation to the next. Both are judged against the
      seed-to-seed spread: the paired mean difference must exceed three of
      its standard errors, and the variance ratio the one-sided 1% point of
      the F distribution with (15, 15) degrees of freedom.
    """
    sigma_mm = sigma_deg = 0.055
    truth_referenced = {1: [], 2: []}
    paper_metric = {1: [], 2: []}
    for seed in range(16):
        deviations = TABLE2_LARGE if seed % 2 else TABLE2_SMALL
        exact = simulate_experiment(kuka_chain, KUKA_LWR4_DH, deviations,
                                    SimulationSettings(sigma_mm, sigma_deg, seed=seed, validation_noise=False))
        noisy = simulate_experiment(kuka_chain, KUKA_LWR4_DH, deviations,
                                    SimulationSettings(sigma_mm, sigma_deg, seed=seed))
        assert np.array_equal(exact.calibration.points, noisy.calibration.points)
        for method in (1, 2):
            _, errors, measured = _calibrate(kuka_urdf, exact, method, also=noisy.validation)
            truth_referenced[method].append((errors.position.mean, errors.rotation.mean))
            paper_metric[method].append((measured.position.mean, measured.rotation.mean))
    t1, t2 = np.array(truth_referenced[1]), np.array(truth_referenced[2])
    p2 = np.mean(paper_metric[2], axis=0)
    m2 = t2.mean(axis=0)
    assert m2[0] <= 0.20, f"Method 2 mean position error {m2[0]:.3f} mm (issue: <= 0.20 mm)"
    assert m2[1] <= 0.05, f"Method 2 mean orientation error {m2[1]:.4f} deg (issue: <= 0.05 deg)"
    assert p2[0] <= 4 * sigma_mm, f"Method 2 v = {p2[0]:.3f} mm above the paper's 4 sigma_p"
    assert p2[1] <= 4 * sigma_deg, f"Method 2 rho = {p2[1]:.4f} deg above the paper's 4 sigma_a"
    gain = t1[:, 1] - t2[:, 1]
    standard_error = gain.std(ddof=1) / np.sqrt(len(gain))
    assert gain.mean() > 3 * standard_error, (
        f"Method 1 orientation {t1[:, 1].mean():.4f} deg vs Method 2 {t2[:, 1].mean():.4f} deg: "
        f"difference {gain.mean():.4f} within 3 standard errors ({standard_error:.4f})"
    )
    ratio = t1[:, 1].var(ddof=1) / t2[:, 1].var(ddof=1)
    assert ratio > f_distribution.ppf(0.99, len(gain) - 1, len(gain) - 1), f"variance ratio {ratio:.2f}"


def test_twists_come_from_cpa_and_alpha_n_is_not_claimed(kuka_urdf, noisy_large_experiment):
    result, _ = _calibrate(kuka_urdf, noisy_large_experiment, 2)
    assert all(s == FROM_CPA for s in result.status[:6])
    assert result.status[6] == NOT_BY_CPA
    assert np.isnan(result.std[6])
    err = np.degrees(np.abs(result.table.alpha[:6] - noisy_large_experiment.truth.alpha[:6]))
    assert err.max() < 0.3  # the paper's largest twist deviation over all its runs (Section 8, 0.3 deg)


def test_a_bad_cpa_arc_is_named_by_joint_and_lines(kuka_urdf, noisy_large_experiment):
    """An arc CPA cannot use (joint 3's points, on a ~6 cm radius, pushed 5 cm off their plane,
    alternately up and down: another joint moved) is refused as off its plane, naming the joint
    and the file lines."""
    data = noisy_large_experiment.calibration
    cpa = np.flatnonzero(data.roles == "cpa")
    third = cpa[cpa_groups(data.q[cpa], data.lines[cpa])[2]]  # rows of joint 3's arc
    normal = np.linalg.svd(data.points[third, 0] - data.points[third, 0].mean(axis=0))[2][2]
    points = data.points.copy()
    points[third, 0, :] += 0.05 * np.where(np.arange(len(third)) % 2 == 0, 1.0, -1.0)[:, None] * normal
    chain = KinematicChain.from_urdf(kuka_urdf, KUKA_FLANGE_LINK, tool=noisy_large_experiment.tool)
    lines = data.lines[third]
    expected = (rf"<simulation>, CPA arc of joint 'lwr_joint_3' \(lines {lines.min()}-{lines.max()}\): "
                "the points do not lie on a plane arc")
    with pytest.raises(CalibrationError, match=expected):
        calibrate_paper(chain, dataclasses.replace(data, points=points), 2)


def test_without_cpa_rows_twists_stay_nominal(kuka_urdf, noisy_large_experiment):
    data = noisy_large_experiment.calibration.with_role("calibration")
    chain = KinematicChain.from_urdf(kuka_urdf, KUKA_FLANGE_LINK, tool=noisy_large_experiment.tool)
    result = calibrate_paper(chain, data, 2)
    assert np.array_equal(result.table.alpha, result.nominal.alpha)
    assert np.abs(result.table.alpha - KUKA_LWR4_DH.alpha).max() < 1e-12  # copied from the nominal table: equal to rounding
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


def test_method3_weight_moves_it_from_method1_to_method2(kuka_urdf, noisy_large_experiment):
    """Eq 18, Err_full = Err_pos + w Err_rot, between its limits.

    w -> 0 leaves Err_pos over the same eps, r, d: Method 1. w -> infinity
    fixes eps by Err_rot alone, and r, d (which Err_rot does not see) then
    minimise Err_pos: Method 2. To first order the distance from the limit is
    proportional to w (resp. 1/w); at the paper's w = 1 Method 3 lies about
    one standard deviation from each, so at w = 1e-6 and 1e6 mm²/deg² it must
    be within 1e-3 standard deviations of its limit (the solver's tolerance,
    1e-12 relative, is far below). Method 1 and Method 2 must differ by more
    than a thousand times that tolerance (1 sd), so the limits cannot be confused.
    """
    method1, _ = _calibrate(kuka_urdf, noisy_large_experiment, 1)
    method2, _ = _calibrate(kuka_urdf, noisy_large_experiment, 2)
    fitted = np.array([s == CALIBRATED for s in method1.status])  # eps_2..7, r_1..7, d_2..7
    assert fitted.sum() == 3 * 7 - 2
    spread = method1.std[fitted]
    assert np.all(np.isfinite(spread)) and np.all(spread > 0)

    def distance(a, b):
        """Largest parameter difference in units of Method 1's standard deviations."""
        return np.max(np.abs(a.table.to_vector() - b.table.to_vector())[fitted] / spread)

    assert distance(method1, method2) > 1e3 * 1e-3
    small, _ = _calibrate(kuka_urdf, noisy_large_experiment, 3, weight=1e-6)
    large, _ = _calibrate(kuka_urdf, noisy_large_experiment, 3, weight=1e6)
    assert distance(small, method1) < 1e-3, f"w = 1e-6: {distance(small, method1):.2g} sd from Method 1"
    assert distance(large, method2) < 1e-3, f"w = 1e6: {distance(large, method2):.2g} sd from Method 2"


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
