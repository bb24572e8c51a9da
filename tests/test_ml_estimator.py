"""The ML estimator (pincal.paper.ml_estimator) and its residual (pincal.residuals.tool_pose.tool_pose_residual).

Jacobians against central finite differences (step 1e-6, tolerance 1e-7
relative to the column scale, as in test_jacobians.py); noise-free data must
give the truth back (1e-8, the solver's tolerance with margin, as in
test_paper_methods.py); noisy data must beat Method 2 by more than the
seed-to-seed spread; the noise estimate must recover the simulated sigmas
within its chi-square spread.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest
from conftest import assert_close, numeric_jacobian

from pincal.errors import CalibrationError
from pincal.fit.metrics import pose_errors
from pincal.model.chain import KinematicChain
from pincal.model.dh.parameters import DHParameterSet
from pincal.model.dh.table import (
    KUKA_LWR4_DH,
    TABLE2_LARGE,
    TABLE2_SMALL,
    DHDeviations,
    DHTable,
)
from pincal.model.effects import Effect, EffectInputs
from pincal.model.sensor import Registration
from pincal.paper.methods import ABSORBED, CALIBRATED, calibrate_paper
from pincal.paper.ml_estimator import KEPT_NOMINAL, MLCalibration, MLSettings, calibrate_ml
from pincal.residuals.base import KinematicsCache
from pincal.residuals.sensor import SensorResidual, TargetEstimate
from pincal.residuals.sensor_values import ModelledEffects, RowWeights
from pincal.residuals.tool_pose import tool_pose_residual
from pincal.robots import KUKA_FLANGE_LINK
from pincal.simulation.paper import SimulationSettings, simulate_experiment
from pincal.simulation.sensor import DEFAULT_REGISTRATION

STEP = 1e-6
TOL = 1e-7


def _pose_residual(chain, rng, k=10):
    """A tool pose residual over all 28 DH parameters away from the truth and the reference."""
    chain.set_tool(pin.SE3.Random().homogeneous)
    params = DHParameterSet(chain)
    truth = TABLE2_LARGE.apply(KUKA_LWR4_DH)
    lower = np.array([j.lower for j in chain.joints])
    upper = np.array([j.upper for j in chain.joints])
    q = rng.uniform(lower, upper, (k, chain.n_joints))
    params.apply(truth.to_vector())
    poses = chain.poses(q)
    points = DEFAULT_REGISTRATION.apply_points(poses.tool_positions) + rng.normal(0, 1e-3, (k, 3))
    rotations = np.stack(
        [pin.exp3(rng.normal(0, 0.01, 3)) @ DEFAULT_REGISTRATION.rotation @ r for r in poses.tool_rotations]
    )
    reference = Registration(
        pin.exp3(rng.normal(0, 0.05, 3)) @ DEFAULT_REGISTRATION.rotation, DEFAULT_REGISTRATION.translation + 0.01
    )
    cache = KinematicsCache(params, np.arange(params.size), KUKA_LWR4_DH.to_vector(), q)
    objective = tool_pose_residual(cache, points, rotations, reference, 2e-3, 0.03)
    x = objective.start_vector()
    x[objective.blocks["kinematic"]] += rng.normal(0, 0.01, params.size)
    x[objective.blocks["registration"].start + np.arange(3)] = rng.normal(0, 0.05, 3)  # away from phi = 0

    def moved(g, rot):
        return tool_pose_residual(cache, g, rot, reference, 2e-3, 0.03)

    return objective, x, moved


def _target_residual(chain, rng, k=5):
    """A SensorResidual with two fitted target points, a fitted target rotation, per-row
    weights and the sensor effects (scale, drift), away from its start."""
    params = DHParameterSet(chain)
    q = rng.uniform(-1.5, 1.5, (k, chain.n_joints))
    inputs = EffectInputs(q=q, gravity=np.zeros_like(q), time=np.linspace(-600, 600, k), order=np.arange(k))
    cache = KinematicsCache(params, np.arange(params.size), KUKA_LWR4_DH.to_vector(), q)
    start = TargetEstimate(Registration(pin.exp3(rng.normal(size=3)), rng.normal(size=3)),
                           rng.normal(0, 0.1, (2, 3)), pin.exp3(rng.normal(size=3)))
    weights = rng.uniform(0.5, 2.0, k), rng.uniform(0.5, 2.0, k)

    def moved(g, rot):
        return SensorResidual(cache, g, rot, start, RowWeights(*weights),
                              effects=ModelledEffects([Effect("drift"), Effect("sensor_scale")], inputs))

    objective = moved(rng.normal(size=(k, 2, 3)), np.stack([pin.exp3(rng.normal(size=3)) for _ in q]))
    x = objective.start_vector() + rng.normal(0, 0.01, objective.n_free)
    return objective, x, moved


@pytest.mark.parametrize("seed", [0, 1])
def test_pose_residual_jacobian_matches_finite_differences(kuka_chain, seed):
    objective, x, _ = _pose_residual(kuka_chain, np.random.default_rng(seed))
    analytic, numeric = objective.jacobian(x), numeric_jacobian(objective.residual, x)
    n = objective.blocks["kinematic"].stop
    for name, block in (("DH", slice(0, n)), ("phi", slice(n, n + 3)), ("tau", slice(n + 3, n + 6))):
        scale = max(1.0, np.abs(numeric[:, block]).max())
        assert_close(analytic[:, block] / scale, numeric[:, block] / scale, TOL, name)


@pytest.mark.parametrize("case", [_pose_residual, _target_residual], ids=["tool", "target"])
def test_noise_jacobian_matches_finite_differences(kuka_chain, case):
    """g_kp → g_kp + zeta, G_k → exp(xi) G_k moves only row k's residuals, by the returned block."""
    objective, x, moved = case(kuka_chain, np.random.default_rng(5), k=4)
    blocks, rows = objective.noise_jacobian(x), objective.row_indices()
    points, rotations = objective.g, objective.G
    n_position = 3 * points.shape[1]
    assert blocks.shape == (len(points), n_position + 3, n_position + 3) == rows.shape + (n_position + 3,)
    for k in range(len(points)):
        for c in range(blocks.shape[2]):

            def residual(h):
                g, rot = points.copy(), rotations.copy()
                if c < n_position:
                    g[k, c // 3, c % 3] += h
                else:
                    rot[k] = pin.exp3(h * np.eye(3)[c - n_position]) @ rot[k]
                return moved(g, rot).residual(x)

            numeric = (residual(STEP) - residual(-STEP)) / (2 * STEP)
            expected = np.zeros_like(numeric)
            expected[rows[k]] = blocks[k][:, c]
            scale = max(1.0, np.abs(numeric).max())
            assert_close(numeric / scale, expected / scale, TOL, f"row {k} noise {c}")


def test_tool_pose_residual_is_row_by_row_pose_error(kuka_chain):
    """Row k's residuals are [(Omega t_k + tau − g_k) / sigma_p, log(G_kᵀ Omega R_k) / sigma_a]."""
    objective, x, _ = _pose_residual(kuka_chain, np.random.default_rng(2), k=3)
    registration = objective.estimate(x).registration
    poses, _ = objective.cache.evaluate(x[objective.blocks["kinematic"]])
    position = (registration.apply_points(poses.tool_positions) - objective.g[:, 0]) / 2e-3
    rotation = np.stack(
        [pin.log3(g.T @ registration.rotation @ r) for g, r in zip(objective.G, poses.tool_rotations)]
    ) / 0.03
    assert_close(objective.residual(x)[objective.row_indices()], np.hstack([position, rotation]), 1e-12, "residual")
    with pytest.raises(CalibrationError, match="must be positive"):
        tool_pose_residual(objective.cache, objective.g, objective.G, registration, 0.0, 0.03)


def _run(urdf, experiment, **kwargs):
    chain = KinematicChain.from_urdf(urdf, KUKA_FLANGE_LINK, tool=experiment.tool)
    result = calibrate_ml(chain, experiment.calibration, nominal=KUKA_LWR4_DH, **kwargs)
    with chain.placed(result.chain_placements):
        errors = pose_errors(chain, experiment.validation, result.registration_position,
                             result.registration_orientation)
    return result, errors, chain


@pytest.mark.parametrize("deviations", [TABLE2_SMALL, TABLE2_LARGE], ids=lambda d: d.name)
def test_noise_free_data_recovers_ground_truth(kuka_urdf, kuka_chain, deviations):
    experiment = simulate_experiment(kuka_chain, KUKA_LWR4_DH, deviations, SimulationSettings(seed=11))
    result, errors, _ = _run(kuka_urdf, experiment)  # sigmas estimated from rounding-level residuals
    assert isinstance(result, MLCalibration) and result.method == "ml"
    assert errors.position_m.max() < 1e-8
    assert errors.rotation_rad.max() < 1e-8
    determined = np.array([s == CALIBRATED for s in result.status])
    assert determined.sum() == 26  # all but eps_1 and d_1, alpha_7 included
    diff = result.table.to_vector() - experiment.truth.to_vector()
    assert np.abs(diff[determined]).max() < 1e-8
    assert result.registration_position is result.registration_orientation
    assert np.abs(result.registration_position.rotation - experiment.registration.rotation).max() < 1e-9
    assert np.abs(result.registration_position.translation - experiment.registration.translation).max() < 1e-9


def test_alpha_n_is_identified_with_the_tool_known(kuka_urdf, kuka_chain):
    """CPA cannot see alpha_N; with full poses and a known tool the ML fit recovers it."""
    delta = TABLE2_LARGE.delta.to_vector()
    delta[6] = np.radians(0.4)  # alpha_7
    deviations = DHDeviations("large+alpha7", DHTable.from_vector(delta))
    experiment = simulate_experiment(kuka_chain, KUKA_LWR4_DH, deviations, SimulationSettings(seed=2))
    result, errors, _ = _run(kuka_urdf, experiment)
    assert abs(result.table.alpha[6] - experiment.truth.alpha[6]) < 1e-9
    assert errors.position_m.max() < 1e-8 and errors.rotation_rad.max() < 1e-8
    kept, kept_errors, _ = _run(kuka_urdf, experiment, settings=MLSettings(fit_alpha_n=False))
    assert kept.status[6] == KEPT_NOMINAL and kept.table.alpha[6] == KUKA_LWR4_DH.alpha[6]
    # noise-free: a model that can fit gives 1e-8 (above); keeping alpha_7 0.4 deg off
    # must leave a misfit, here required at a quarter of that, 0.1 deg, far above 1e-8
    assert kept_errors.rotation_rad.max() > np.radians(0.1)
    assert kept.status[7] == ABSORBED and kept.status[21] == ABSORBED  # eps_1, d_1


#: sigma_p [mm], sigma_a [deg] of the paper's Figure 2.
PAPER_NOISE = (0.055, 0.055)


@pytest.fixture(scope="module")
def paper_noise_experiments(kuka_urdf):
    """Six seeded experiments at the paper's noise, both deviation sets, noise-free held-out poses."""
    kuka_chain = KinematicChain.from_urdf(kuka_urdf, KUKA_FLANGE_LINK)
    return [
        simulate_experiment(kuka_chain, KUKA_LWR4_DH, TABLE2_LARGE if seed % 2 else TABLE2_SMALL,
                            SimulationSettings(*PAPER_NOISE, seed=seed, validation_noise=False))
        for seed in range(6)
    ]


def _paired_gain(worse, better):
    """Mean of the paired differences and its standard error over the seeds."""
    gain = np.asarray(worse) - np.asarray(better)
    return gain.mean(), gain.std(ddof=1) / np.sqrt(len(gain))


def test_ml_beats_method2_at_the_paper_noise(kuka_urdf, paper_noise_experiments):
    """The ML estimator uses every row's absolute pose with the right weights, so
    on the same data it must be more accurate against the truth than Method 2,
    on every seed and on average by more than three standard errors of the
    seed-to-seed spread of the paired differences (a significant gain, not a
    fluctuation)."""
    means = {2: [], "ml": []}
    for seed, experiment in enumerate(paper_noise_experiments):
        result, errors, chain = _run(kuka_urdf, experiment)
        method2 = calibrate_paper(chain, experiment.calibration, 2, nominal=KUKA_LWR4_DH)
        with chain.placed(method2.chain_placements):
            errors2 = pose_errors(
                chain, experiment.validation, method2.registration_position, method2.registration_orientation
            )
        means["ml"].append((errors.position.mean, errors.rotation.mean))
        means[2].append((errors2.position.mean, errors2.rotation.mean))
        assert errors.position.mean < errors2.position.mean, f"seed {seed}: position"
        assert errors.rotation.mean < errors2.rotation.mean, f"seed {seed}: orientation"
    ml, m2 = np.array(means["ml"]), np.array(means[2])
    for column, what in ((0, "position [mm]"), (1, "orientation [deg]")):
        gain, standard_error = _paired_gain(m2[:, column], ml[:, column])
        assert gain > 3 * standard_error, f"{what}: gain {gain:.4g} ± {standard_error:.2g} over Method 2"


@pytest.mark.parametrize("sigma_pos_mm, sigma_rot_deg", [(0.055, 0.055), (0.02, 0.15)])
def test_noise_estimate_recovers_the_simulated_sigmas(kuka_urdf, kuka_chain, sigma_pos_mm, sigma_rot_deg):
    """sigma² = ||e||² / r with r the redundancy of that residual type: for
    Gaussian noise r sigma_hat² / sigma² is chi-square with r degrees of freedom,
    so sigma_hat / sigma − 1 has standard deviation 1 / sqrt(2 r). Four of them
    bound it, with r at least 3 components × the rows minus every unknown (26 DH
    parameters and 6 of the registration)."""
    settings = SimulationSettings(sigma_pos_mm, sigma_rot_deg, seed=21)
    experiment = simulate_experiment(kuka_chain, KUKA_LWR4_DH, TABLE2_LARGE, settings)
    result, _, _ = _run(kuka_urdf, experiment)
    assert result.sigma_estimated == (True, True)
    redundancy = 3 * experiment.calibration.with_role("cpa", "calibration").n_rows - (26 + 6)
    tolerance = 4 / np.sqrt(2 * redundancy)  # 0.085 for the 380 rows here
    assert abs(result.sigma_pos_mm / sigma_pos_mm - 1) < tolerance, result.sigma_pos_mm
    assert abs(result.sigma_rot_deg / sigma_rot_deg - 1) < tolerance, result.sigma_rot_deg
    assert any("estimated from the residuals" in note for note in result.notes)
    assert result.iterations > 1


def test_only_the_sigma_ratio_changes_the_estimate(kuka_urdf, noisy_large_experiment, paper_noise_experiments):
    """Scaling both sigmas scales the cost: the minimiser is the same to the
    solver's tolerance (1e-12 relative; 1e-10 allows the rounding of the
    scaled residuals). Changing their ratio changes the weights, and in the
    direction ML theory says: telling the fit that positions are 100 times
    noisier than they are (sigma_p = 5.5 mm against the true 0.055 mm) throws
    away the position information, so the held-out position error must grow,
    on average by more than three standard errors of the paired differences."""
    a, _, _ = _run(kuka_urdf, noisy_large_experiment, sigma_pos_mm=0.05, sigma_rot_deg=0.05)
    b, _, _ = _run(kuka_urdf, noisy_large_experiment, sigma_pos_mm=5.0, sigma_rot_deg=5.0)
    assert a.sigma_estimated == (False, False) and a.iterations == 1
    assert np.abs(a.table.to_vector() - b.table.to_vector()).max() < 1e-10
    right, wrong = [], []
    for experiment in paper_noise_experiments:
        for sigmas, out in ((PAPER_NOISE, right), ((100 * PAPER_NOISE[0], PAPER_NOISE[1]), wrong)):
            _, errors, _ = _run(kuka_urdf, experiment, sigma_pos_mm=sigmas[0], sigma_rot_deg=sigmas[1])
            out.append(errors.position.mean)
    gain, standard_error = _paired_gain(wrong, right)
    assert gain > 3 * standard_error, f"position error grows by {gain:.4g} ± {standard_error:.2g} mm"


def test_positions_only_and_bad_sigmas_are_refused(kuka_urdf, noisy_large_experiment):
    chain = KinematicChain.from_urdf(kuka_urdf, KUKA_FLANGE_LINK, tool=noisy_large_experiment.tool)
    data = noisy_large_experiment.calibration
    with pytest.raises(CalibrationError, match="needs orientations"):
        calibrate_ml(chain, replace(data, rotations=None))
    with pytest.raises(CalibrationError, match="must be positive"):
        calibrate_ml(chain, data, sigma_pos_mm=0.0)


def test_withheld_orientations_do_not_enter_the_fit(kuka_urdf, noisy_large_experiment):
    """MLSettings(withhold_orientations=("cpa",)) gives the CPA rows orientation weight 0: turning their measured
    orientations at random changes nothing, bit for bit, with the sigmas given or estimated (sigma_a from
    the calibration rows alone), while the same turn changes the ML estimate that uses them. Passing
    Method 2's result as the start reproduces the estimator's own start exactly."""
    data = noisy_large_experiment.calibration
    chain = KinematicChain.from_urdf(kuka_urdf, KUKA_FLANGE_LINK, tool=noisy_large_experiment.tool)
    method2 = calibrate_paper(chain, data, method=2, nominal=KUKA_LWR4_DH)
    rng = np.random.default_rng(4)
    turned = np.stack([pin.exp3(rng.normal(0, 0.3, 3)) @ r if role == "cpa" else r
                       for role, r in zip(data.roles, data.rotations)])
    scrambled = replace(data, rotations=turned)
    given, own = (calibrate_ml(chain, data, 0.05, 0.05, nominal=KUKA_LWR4_DH, start=s) for s in (method2, None))
    assert np.array_equal(given.table.to_vector(), own.table.to_vector())
    for sigmas in ((0.05, 0.05), (None, None)):
        kept, withheld = (
            calibrate_ml(chain, d, *sigmas, start=method2, settings=MLSettings(withhold_orientations=("cpa",)))
            for d in (data, scrambled)
        )
        assert np.array_equal(kept.table.to_vector(), withheld.table.to_vector())
        assert kept.sigma_rot_deg == withheld.sigma_rot_deg and np.isfinite(kept.sigma_rot_deg)
        assert any("orientations of the cpa rows withheld" in note for note in kept.notes)
    used = calibrate_ml(chain, scrambled, 0.05, 0.05, start=method2)
    assert not np.array_equal(used.table.to_vector(), kept.table.to_vector())
    with pytest.raises(CalibrationError, match="every row's are withheld"):
        calibrate_ml(chain, data, 0.05, 0.05, start=method2,
                     settings=MLSettings(withhold_orientations=("cpa", "calibration")))
    with pytest.raises(CalibrationError, match="must be Method 2's"):
        calibrate_ml(chain, data, 0.05, 0.05, start=calibrate_paper(chain, data, method=1, nominal=KUKA_LWR4_DH))
