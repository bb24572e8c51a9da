"""Calibrations return their model as a value; the chain they are given is left as it was.

A calibration's result carries ``chain_placements`` (the calibrated joint and tip placements);
code evaluates that model with ``chain.placed(...)``, which puts the chain back on leaving the
block, also on an error. Here: every chain calibration, the level choice, ``diagnose`` and the
planner leave ``chain.placements()`` bit for bit as they found it, their ``chain_placements`` are
the model they describe. That no module outside ``pincal/model/`` sets placements, a tool or a
parameter vector on a chain itself is read from the source in tests/test_architecture.py.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from test_select_prior import _fixture_data

from pincal.diagnosis.diagnose import DiagnoseOptions, diagnose
from pincal.errors import CalibrationError
from pincal.fit.chain_calibration import ChainFitOptions, calibrate_chain
from pincal.fit.fixture_calibration import calibrate_fixture
from pincal.fit.level_choice import choose_level
from pincal.fit.metrics import pose_errors
from pincal.fit.prior import Prior
from pincal.model.chain import KinematicChain
from pincal.model.dh.table import DEVIATION_SETS, KUKA_LWR4_DH
from pincal.model.effects import Effect
from pincal.model.parameter_sets import PlacementErrors
from pincal.paper.methods import calibrate_paper
from pincal.paper.ml_estimator import calibrate_ml
from pincal.paper.noise_limit import predicted_errors
from pincal.planning.candidates import sample_candidates
from pincal.planning.planner import PlanSettings, plan_measurements
from pincal.robots import KUKA_FLANGE_LINK, example_robot_data_urdf, kuka_lwr4plus_urdf
from pincal.simulation.cells import measure_truth
from pincal.simulation.chain import SimulationSettings, simulate_chain
from pincal.simulation.paper import SimulationSettings as PaperSettings
from pincal.simulation.paper import simulate_experiment
from pincal.simulation.sensor import DEFAULT_REGISTRATION, SimulatedEffects, SimulatedSensor, random_configurations

UR5 = example_robot_data_urdf("ur_description/urdf/ur5_robot.urdf")
PANDA = example_robot_data_urdf("panda_description/urdf/panda.urdf")
POINTS = np.array([[0.03, -0.02, 0.08], [-0.04, 0.05, 0.06]])


@pytest.fixture(scope="module")
def experiment():
    chain = KinematicChain.from_urdf(UR5, "tool0")
    params = PlacementErrors(chain)
    truth = np.random.default_rng(3).normal(0.0, 1e-3, params.size)
    settings = SimulationSettings(sigma_pos_mm=0.02, sigma_rot_deg=0.02, n_calibration=40, n_validation=20, seed=4)
    return simulate_chain(params, truth, POINTS, settings)


@pytest.fixture(scope="module")
def with_outliers(experiment):
    """The calibration rows with two rows 10 mm off: ``reject_outliers`` fits twice."""
    points = experiment.calibration.points.copy()
    points[[5, 17]] += 0.01
    return replace(experiment.calibration, points=points)


def _same(a, b) -> bool:
    return len(a) == len(b) and all(np.array_equal(x, y) for x, y in zip(a, b))


@pytest.mark.parametrize("level, selection", [("registration", "aic"), ("offsets", "aic"), ("full", "aic"),
                                              ("full", Prior()), ("full", "all")])
def test_a_calibration_leaves_the_chain_and_returns_its_model(experiment, with_outliers, level, selection):
    chain = KinematicChain.from_urdf(UR5, "tool0")
    before = chain.placements()
    refit = calibrate_chain(chain, with_outliers, level, ChainFitOptions(selection=selection, reject_outliers=True))
    assert len(refit.removed_lines) == 2 and _same(chain.placements(), before)  # the second fit starts at nominal
    result = calibrate_chain(chain, experiment.calibration, level, ChainFitOptions(selection=selection))
    assert _same(chain.placements(), before)
    expected = before if result.params is None else result.params.placements(result.vector)
    assert _same(result.chain_placements, expected)
    # the model as a value: its errors on the calibration rows are the fit's (eq 24, rms_m); 1e-6: under a
    # prior rms_m is rescaled with eq P2's last noise scale, settled to 1e-3 (seen 7e-8), else rounding
    with chain.placed(result.chain_placements):
        errors = pose_errors(chain, experiment.calibration, result.target.registration, result.target.registration,
                             points=result.target.points)
    assert np.sqrt(np.mean(errors.position_m**2)) == pytest.approx(result.rms_m, rel=1e-6)
    assert _same(chain.placements(), before)


def test_the_level_choice_and_diagnose_leave_the_chain(experiment):
    chain = KinematicChain.from_urdf(UR5, "tool0")
    before = chain.placements()
    choose_level(chain, experiment.calibration, folds=4)
    assert _same(chain.placements(), before)
    # a hidden encoder scale on the elbow: diagnose adopts it and refits the geometry with it
    params = PlacementErrors(chain)
    truth = np.random.default_rng(3).normal(0.0, 1e-3, params.size)
    rng = np.random.default_rng(6)
    scale = [(Effect("encoder_scale", "elbow_joint"), np.array([2e-3]))]
    rows = measure_truth(params, truth, random_configurations(chain, rng, 40), DEFAULT_REGISTRATION, rng,
                         SimulatedSensor(2e-5, 0.0, points=POINTS, with_rotation=False),
                         effects=SimulatedEffects(effects=scale))
    calibration = calibrate_chain(chain, rows, "full")
    diagnosis = diagnose(chain, calibration, rows, options=DiagnoseOptions(candidates=[
        Effect("encoder_scale", "elbow_joint"), Effect("compliance", "shoulder_lift_joint")]))
    assert _same(chain.placements(), before)
    assert [e.label for e, _, _ in diagnosis.effects] == [Effect("encoder_scale", "elbow_joint").label]
    assert not _same(diagnosis.chain_placements, calibration.chain_placements)  # the refitted geometry
    refit = calibration.vector.copy()
    refit[calibration.kept] = diagnosis.solution_x[diagnosis.objective.blocks["kinematic"]]
    assert _same(diagnosis.chain_placements, calibration.params.placements(refit))
    # an error inside diagnose (held-out rows measuring another target: one point) leaves the chain too
    calibration = calibrate_chain(chain, experiment.calibration, "full")
    one_point = simulate_chain(PlacementErrors(chain), np.zeros(PlacementErrors(chain).size), POINTS[:1],
                               SimulationSettings(n_calibration=5, n_validation=5, seed=5))
    with pytest.raises(CalibrationError, match="same target"):
        diagnose(chain, calibration, experiment.calibration, heldout=one_point.validation)
    assert _same(chain.placements(), before)


def test_placed_restores_on_an_error():
    chain = KinematicChain.from_urdf(UR5, "tool0")
    before = chain.placements()
    moved = [p.copy() for p in before]
    moved[2][:3, 3] += 0.01
    with pytest.raises(RuntimeError):
        with chain.placed(moved):
            assert _same(chain.placements(), moved)
            raise RuntimeError("inside the block")
    assert _same(chain.placements(), before)
    # a malformed entry fails after the joints before it were set: they are put back too
    broken = [p.copy() for p in moved]
    broken[3] = np.eye(3)
    with pytest.raises(TypeError):  # Pinocchio's SE3 refuses a 3x3 (Boost.Python.ArgumentError)
        with chain.placed(broken):
            pass
    assert _same(chain.placements(), before)


def test_placed_sets_and_restores_the_tool():
    chain = KinematicChain.from_urdf(UR5, "tool0")
    before, tool = chain.placements(), chain.tool
    tcp = np.eye(4)
    tcp[:3, 3] = [0.01, 0.02, 0.1]
    q = np.zeros((1, chain.n_joints))
    with chain.placed(tool=tcp):
        assert np.array_equal(chain.tool, tcp) and _same(chain.placements(), before)
        moved = chain.tool_poses(q)[1][0]
    assert np.array_equal(chain.tool, tool) and not np.allclose(chain.tool_poses(q)[1][0], moved)
    with pytest.raises(RuntimeError):
        with chain.placed(before, tool=tcp):
            raise RuntimeError("inside the block")
    assert np.array_equal(chain.tool, tool) and _same(chain.placements(), before)


def test_the_paper_simulator_and_noise_limit_leave_the_chain():
    chain = KinematicChain.from_urdf(kuka_lwr4plus_urdf(), KUKA_FLANGE_LINK)
    before, tool = chain.placements(), chain.tool
    experiment = simulate_experiment(chain, KUKA_LWR4_DH, DEVIATION_SETS["small"],
                                     PaperSettings(n_cpa=16, n_calibration=30, n_validation=10, seed=2))
    assert _same(chain.placements(), before) and np.array_equal(chain.tool, tool)
    predicted_errors(chain, experiment, 2, 0.05, 0.05)
    assert _same(chain.placements(), before) and np.array_equal(chain.tool, tool)


def test_a_fixture_calibration_leaves_the_chain():
    chain, data = _fixture_data()  # a Panda ~1 mm / 1 mrad off, on a socket fixture
    before = chain.placements()
    result = calibrate_fixture(chain, data, "full", selection="prior")
    assert _same(chain.placements(), before)
    assert _same(result.chain_placements, result.params.placements(result.vector))


def test_the_paper_methods_leave_the_chain():
    chain = KinematicChain.from_urdf(kuka_lwr4plus_urdf(), KUKA_FLANGE_LINK)
    experiment = simulate_experiment(chain, KUKA_LWR4_DH, DEVIATION_SETS["small"], PaperSettings(seed=2))
    chain.set_tool(experiment.tool)
    before = chain.placements()
    for result in (calibrate_paper(chain, experiment.calibration, 2), calibrate_ml(chain, experiment.calibration)):
        assert _same(chain.placements(), before)
        assert _same(result.chain_placements, result.table.joint_origins())


def test_a_plan_on_recorded_rows_leaves_the_chain(experiment):
    """The plan linearises at the recorded rows' calibration without putting it in the chain."""
    chain = KinematicChain.from_urdf(UR5, "tool0")
    before = chain.placements()
    candidates = sample_candidates(chain, 200, seed=1)
    plan_measurements(chain, candidates, PlanSettings(count=4, level="full"), existing=experiment.calibration)
    assert _same(chain.placements(), before)
