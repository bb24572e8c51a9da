"""``--select prior``: the MAP fit with physical priors (pincal.fit.prior)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from pincal.cli.commands import main
from pincal.errors import CalibrationError
from pincal.fit.chain_calibration import ChainFitOptions, FitProblem, calibrate_chain
from pincal.fit.fixture_calibration import calibrate_fixture
from pincal.fit.level_choice import RULE, RULE_PRIOR, choose_level, one_standard_error
from pincal.fit.metrics import pose_errors
from pincal.fit.pipeline import KEPT
from pincal.fit.prior import PRIOR_STATUS, Prior, PriorResidual, prior_sigmas
from pincal.fit.sessions import initial_target
from pincal.fit.socket_metrics import fixture_metrics
from pincal.measurements.csv_v1 import write_measurements
from pincal.measurements.fixture import Fixture
from pincal.model.chain import KinematicChain, pose_from_xyz_rpy
from pincal.model.parameter_sets import JointOffsets, PlacementErrors
from pincal.robots import example_robot_data_urdf
from pincal.simulation.fixture import simulate_fixture
from pincal.simulation.sensor import (
    DEFAULT_REGISTRATION,
    SimulatedEffects,
    SimulatedSensor,
    measure,
    random_configurations,
)

UR5 = example_robot_data_urdf("ur_description/urdf/ur5_robot.urdf")
POINT = np.array([[0.02, 0.01, 0.05]])
SIGMA_M = 0.05e-3  # a laser tracker's noise per axis (as examples/level_auto.py)


def _rows(rows: int, seed: int, sigma_m: float, kind=PlacementErrors, error=1e-4, with_rotation=False, effects=()):
    """UR5 rows whose ``kind`` parameters are off by N(0, error) [m or rad] (the training rows with
    ``effects`` too: (Effect, values) pairs); the chain back at nominal."""
    chain = KinematicChain.from_urdf(UR5, "tool0")
    nominal = chain.placements()
    rng = np.random.default_rng(seed)
    params = kind(chain)
    params.apply(rng.normal(0.0, error, params.size))
    train = measure(chain, random_configurations(chain, rng, rows), DEFAULT_REGISTRATION, rng,
                    SimulatedSensor(sigma_m, 1e-4 if with_rotation else 0.0, points=POINT, with_rotation=with_rotation),
                    "calibration", effects=SimulatedEffects(effects=effects))
    test = measure(chain, random_configurations(chain, rng, 50), DEFAULT_REGISTRATION, rng,
                   SimulatedSensor(0.0, 0.0, points=POINT, with_rotation=False), "calibration")
    chain.set_placements(nominal)
    return chain, train, test


def _heldout_m(chain, result, test) -> float:
    registration = result.target.registration
    with chain.placed(result.chain_placements):
        errors = pose_errors(chain, test, registration, registration, points=result.target.points)
    return float(np.sqrt(np.mean(errors.position_m**2)))


def test_prior_rows_jacobian_matches_finite_differences():
    chain, data, _ = _rows(10, seed=1, sigma_m=SIGMA_M, with_rotation=True)
    params = PlacementErrors(chain)
    problem = FitProblem(chain, params, data, initial_target(chain, data, fit_points=True), fit_target=True,
                         row_weight=np.ones(data.n_rows), prior=prior_sigmas(params, Prior(2.0, 0.3)))
    free = np.arange(0, params.size, 3)
    objective = problem.objective(free, np.zeros(params.size))
    assert isinstance(objective, PriorResidual) and objective.n_prior == free.size
    x = objective.start_vector() + np.random.default_rng(2).normal(0.0, 1e-3, objective.n_params)
    analytic = objective.jacobian(x)
    step = 1e-7
    numeric = np.column_stack([(objective.residual(x + step * e) - objective.residual(x - step * e)) / (2 * step)
                               for e in np.eye(x.size)])
    # central differences: truncation ~step² × curvature, rounding ~1e-16 |r| / step; 1e-6 of the
    # largest entry is far above both and far below any wrong column (entries of order 1 or more)
    assert analytic.shape == (objective.residual(x).size, x.size)
    assert np.allclose(analytic, numeric, atol=1e-6 * np.abs(analytic).max())
    # the prior rows: θ_i / σ_i of the free kinematic parameters, nothing else
    kin = objective.blocks["kinematic"]
    assert np.allclose(objective.residual(x)[-free.size:], x[kin] / problem.prior[free])


def test_prior_scales_are_in_each_parameters_unit():
    chain = KinematicChain.from_urdf(UR5, "tool0")
    sigma = prior_sigmas(PlacementErrors(chain), Prior(1.0, 0.5))
    units = [info.unit for info in PlacementErrors(chain).info]
    assert set(sigma[[u == "m" for u in units]]) == {1e-3}
    assert np.allclose(sigma[[u == "rad" for u in units]], np.radians(0.5))
    assert np.allclose(prior_sigmas(JointOffsets(chain), Prior()), np.radians(0.5))  # revolute joints


def test_noise_free_data_recovers_the_truth_under_the_default_prior():
    """Noise-free rows: σ_pos shrinks towards rounding, so the prior's weight vanishes against the data."""
    chain, train, test = _rows(20, seed=3, sigma_m=0.0, error=1e-3)
    result = calibrate_chain(chain, train, "full", ChainFitOptions(selection="prior"))
    # rounding and solver tolerance leave ~1e-12 m; 1e-9 m is far above that, far below the 1 mm errors
    assert _heldout_m(chain, result, test) < 1e-9
    scale = result.selection.prior_scale  # the scales used: estimated from the rows, or the defaults kept
    assert scale["estimated"] or (scale["translation_mm"], scale["rotation_deg"], scale["joint_zero_deg"]) == (
        1.0, 0.5, 0.5)


def test_a_huge_prior_scale_is_the_select_all_fit():
    chain, train, _ = _rows(30, seed=4, sigma_m=SIGMA_M)
    nominal = chain.placements()
    every = calibrate_chain(chain, train, "full", ChainFitOptions(selection="all"))
    chain.set_placements(nominal)
    wide = calibrate_chain(chain, train, "full", ChainFitOptions(selection=Prior(1e6, 1e6)))  # km and 10^6 degrees
    assert np.array_equal(every.kept, wide.kept) and every.status == wide.status
    assert all(s == KEPT or s.startswith("not determined") for s in wide.status)
    determined = np.isfinite(every.std)
    # a prior ~1e9 times wider than the data's std changes the estimate by ~1e-18 of it
    # (relative weight σ_data² / σ_prior²); 1e-4 std allows for the solvers' tolerance (seen: 3e-6)
    assert np.all(np.abs(wide.vector - every.vector)[determined] < 1e-4 * every.std[determined])
    assert np.allclose(wide.std[determined], every.std[determined], rtol=1e-4)


def test_prior_dominated_parameters_are_flagged_and_not_reported_as_measured():
    chain, train, _ = _rows(12, seed=5, sigma_m=SIGMA_M)
    # 1 µm, 0.001°: the prior decides
    result = calibrate_chain(chain, train, "full", ChainFitOptions(selection=Prior(1e-3, 1e-3)))
    weak = [i for i, s in enumerate(result.status) if s == PRIOR_STATUS]
    assert weak and len(weak) == len(result.kept)
    assert any("determined mainly by the prior" in note for note in result.notes)
    sigma = prior_sigmas(result.params, Prior(1e-3, 1e-3))
    assert np.all(result.std[weak] > 0.7 * sigma[weak])


def test_noise_scale_counts_the_effective_parameters_on_sparse_data():
    """12 rows, 36 coordinates, ~27 unknowns: the mean square residual would give σ ≈ 0.5 σ_true
    (sqrt(9/36)); eq P2 is unbiased to first order. Mean over 4 seeds of σ̂/σ: its spread is
    ~sqrt(1/(2·9))/2 ≈ 0.12, so [0.7, 1.4] holds it at ~3 standard deviations and excludes 0.5."""
    ratios = []
    for seed in range(4):
        chain, train, _ = _rows(12, seed=10 + seed, sigma_m=SIGMA_M)
        ratios.append(calibrate_chain(chain, train, "full", ChainFitOptions(selection="prior")).sigma_pos_m / SIGMA_M)
    assert 0.7 < np.mean(ratios) < 1.4


def test_prior_refuses_bad_scales():
    for bad in ((-1.0, 0.5), (1.0, 0.0), (float("nan"), 0.5)):
        with pytest.raises(CalibrationError, match="must be a positive number"):
            Prior(*bad)


# --- socket fixture and --level auto --------------------------------------------------------------


def _fixture_data():
    """Noise-free socket-fixture rows of a Panda ~1 mm / 1 mrad off its URDF (two sockets, two
    placements, 8 rows per socket), and a chain of the nominal Panda to calibrate."""
    panda = example_robot_data_urdf("panda_description/urdf/panda.urdf")
    truth = KinematicChain.from_urdf(panda, "panda_link8")
    rng = np.random.default_rng(7)
    PlacementErrors(truth).apply(rng.normal(0.0, 1e-3, PlacementErrors(truth).size))
    fixture = Fixture(("hole_0", "hole_1"), np.array([[0.0, 0.0, 0.0], [0.05, 0.0, 0.0]]))
    poses = (pose_from_xyz_rpy([0.5, 0.1, 0.05], [0.0, 0.0, 0.3]),
             pose_from_xyz_rpy([0.4, -0.3, 0.2], [0.1, 0.0, -0.5]))
    data = simulate_fixture(truth, fixture, poses, np.array([0.01, -0.005, 0.12]), 8, rng)
    return KinematicChain.from_urdf(panda, "panda_link8"), data


def test_fixture_prior_fit_recovers_noise_free_data_and_flags_what_the_prior_decides():
    chain, data = _fixture_data()
    result = calibrate_fixture(chain, data, "full", selection="prior")
    with chain.placed(result.chain_placements):
        after = fixture_metrics(chain, data, result.ball)
    # noise-free: the noise scale falls to rounding and the prior's weight with it (as for sensor data);
    # 1e-6 mm is far above rounding (~1e-12 m) and far below the ~1 mm placement errors
    assert after.consistency_mm < 1e-6 and after.distortion_mm < 1e-6
    scale = result.selection.prior_scale  # the scales used: estimated from the rows, or the defaults kept
    assert scale["estimated"] or (scale["translation_mm"], scale["rotation_deg"], scale["joint_zero_deg"]) == (
        1.0, 0.5, 0.5)
    tight = calibrate_fixture(chain, data, "full", selection=Prior(1e-6, 1e-6))  # 1 nm, 1e-6 °: the prior decides
    assert tight.status.count(PRIOR_STATUS) == len(tight.kept) > 0


def test_richest_level_within_one_standard_error_under_priors():
    # the same numbers as tests/test_level_choice.py's rule test: simplest within 0.31 is index 1
    assert one_standard_error([1.0, 0.30, 0.25], [0.1, 0.05, 0.06]) == (2, 1, pytest.approx(0.31))
    assert one_standard_error([1.0, 0.30, 0.25], [0.1, 0.05, 0.06], richest=True)[:2] == (2, 2)
    assert one_standard_error([0.28, 0.25, 0.31], [0.1, 0.05, 0.06], richest=True)[:2] == (1, 1)  # 0.31 > 0.30
    assert one_standard_error([0.5, 0.25, np.inf], [0.0, 0.125, np.nan], richest=True)[:2] == (1, 1)


def test_level_auto_uses_the_prior_in_its_fits_and_says_its_rule():
    chain, train, _ = _rows(15, seed=8, sigma_m=SIGMA_M)
    choice = choose_level(chain, train, ChainFitOptions(selection=Prior(2.0, 0.25)), folds=5)
    assert choice.selection == "prior" and choice.as_dict()["rule"] == RULE_PRIOR != RULE
    # every fold of the full level kept every identifiable parameter (no subset selection)
    assert len(set(choice.scores[-1].kept)) == 1


# --- command line --------------------------------------------------------------------------------


def _cli(tmp_path, *extra):
    data = tmp_path / "cal.csv"
    if not data.exists():
        write_measurements(data, _rows(15, seed=6, sigma_m=SIGMA_M)[1])
    out, report = tmp_path / "ur5.urdf", tmp_path / "REPORT.json"
    code = main(["calibrate", str(UR5), str(data), "--tip-link", "tool0", "--level", "full", "--quiet",
                 "--out", str(out), "--report", str(report), *extra])
    return code, report


def test_cli_select_prior_records_its_scales(tmp_path, capsys):
    code, report = _cli(tmp_path, "--select", "prior", "--prior-scale", "2,0.25")
    assert code == 0
    document = json.loads(report.read_text())
    selection = document["identifiability"]["selection"]
    assert selection["prior_scale"] == {"translation_mm": 2.0, "rotation_deg": 0.25, "joint_zero_deg": 0.25,
                                        "estimated": False, "reason": "given"}
    assert "prior" in selection["criterion"]
    # 1 µm / 0.001°: the prior decides some parameters (none at 2 mm / 0.25° on these rows)
    code, report = _cli(tmp_path, "--select", "prior", "--prior-scale", "0.001,0.001")
    assert code == 0
    parameters = json.loads(report.read_text())["parameters"]
    weak = [entry for entry in parameters if entry["status"] == PRIOR_STATUS]
    assert weak  # prior-dominated ones carry no number, as undetermined ones
    for entry in parameters:
        if entry["status"] != KEPT:
            assert entry["calibrated"] is None and entry["std"] is None
    code, report = _cli(tmp_path, "--select", "aic")
    assert code == 0 and "prior_scale" not in json.loads(report.read_text())["identifiability"]["selection"]


@pytest.mark.parametrize("scale", ["-1,0.5", "0,0.5", "1,0", "a,b", "1", "1,2,3,4", "1,2,0", "inf,1"])
def test_cli_bad_prior_scale_is_one_line(tmp_path, capsys, scale):
    with pytest.raises(SystemExit) as exit_info:
        _cli(tmp_path, "--select", "prior", f"--prior-scale={scale}")
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    errors = [line for line in err.splitlines() if "error" in line]
    assert len(errors) == 1 and "--prior-scale" in errors[0] and "MM,DEG" in errors[0] and "Traceback" not in err


def test_cli_prior_scale_with_another_select_is_one_line(tmp_path, capsys):
    code, _ = _cli(tmp_path, "--select", "aic", "--prior-scale", "1,0.5")
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "--select prior" in err
