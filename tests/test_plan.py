"""``pincal plan``: choosing the configurations worth measuring.

Simulated robots (KUKA, Panda, UR5, TIAGo; seeded): calibrating on the planned
configurations must give a held-out error within 15 % of the plan's prediction
(mean over noise seeds) and at most 0.7 × the error of as many random
candidates (medians over the same seeds, same noise) — both thresholds are
the planner's promise. Real data (TIAGo, data/tiago_mocap): 20 planned rows of 2021-11-30
against random 20-row subsets, held out on 2021-11-26. Plus the rank-m updates
of the search against a fresh inverse, the orders, the clearance and the CLI's
errors.
"""

from __future__ import annotations

import csv
import hashlib
import importlib.util
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from pincal.cli.commands import main
from pincal.errors import PincalError
from pincal.fit.chain_calibration import ChainFitOptions, calibrate_chain
from pincal.fit.prior import Prior
from pincal.measurements.csv_v1 import read_measurements
from pincal.model.chain import KinematicChain
from pincal.model.parameter_sets import PlacementErrors
from pincal.planning.candidates import sample_candidates
from pincal.planning.collisions import check_clearance
from pincal.planning.design import PRIOR, DesignProblem, _Search, _weight, select
from pincal.planning.information import (
    MeasurementModel,
    SensorModel,
    default_target_points,
)
from pincal.planning.ordering import approach_balance, move_times, short_tour
from pincal.planning.planner import PlanSettings, plan_measurements
from pincal.robots import KUKA_FLANGE_LINK, example_robot_data_urdf, kuka_lwr4plus_urdf
from pincal.simulation.chain import truth_error_mm
from pincal.simulation.sensor import DEFAULT_REGISTRATION, SimulatedSensor, measure, random_configurations

ROOT = Path(__file__).resolve().parent.parent
TIAGO_DATA = ROOT / "data" / "tiago_mocap"
TRAIN = TIAGO_DATA / "qualisys_2021-11-30_static_postures.csv"
HELD_OUT = TIAGO_DATA / "qualisys_2021-11-26_static_postures.csv"
ROBOTS = {
    "kuka": (None, KUKA_FLANGE_LINK),
    "panda": ("panda_description/urdf/panda.urdf", "panda_link8"),
    "ur5": ("ur_description/urdf/ur5_robot.urdf", "tool0"),
    "tiago": ("tiago_description/robots/tiago.urdf", "wrist_ft_tool_link"),
}
MARKERS = np.array([[0.05, 0.0, 0.07], [0.07, 0.0, -0.08], [0.16, 0.0, -0.05], [0.15, 0.01, 0.06]])
#: The planner's promise: planned held-out error within 15 % of the prediction, and at most 0.7 × random.
PREDICTION_TOLERANCE = 0.15
RANDOM_RATIO = 0.7


def _urdf(robot: str) -> Path:
    relative = ROBOTS[robot][0]
    return kuka_lwr4plus_urdf() if relative is None else example_robot_data_urdf(relative)


def _chain(robot: str) -> KinematicChain:
    return KinematicChain.from_urdf(_urdf(robot), ROBOTS[robot][1])


def _heldout_mm(chain, params, truth, result, points, q) -> float:
    """Mean truth-referenced position error of the calibration ``result``'s target points at ``q`` [mm]."""
    return truth_error_mm(params, truth, q, points, result.target.points, result.target.registration,
                          placements=result.chain_placements)


# robot, measure, target points, N: N about 1.1-1.2 x the fewest configurations that determine
# the parameters — the few-measurements regime where a plan matters (README: the ratio nears 1
# as N grows).
# The selection: AIC (the library's default), and calibrate's default prior, which the plan then
# counts in its information (eq P1).
#: Half the candidates keep both promises with the same margins at half the search's time: TIAGo (four
#: markers, 12 rows per candidate; measured: prediction within 4 %, planned / random 0.52; with 2000: 3 %,
#: 0.51) and the UR5 in 6D (+4.7 %, 0.650; with 2000: +6.5 %, 0.648). The UR5's 1000 failed (observed 1.64x
#: the prediction) while AIC weighed orientations at fixed scales: 2 of its 8 calibrations kept too few
#: parameters (pincal.fit.selection, the data's scales). The other one-marker robots keep 2000.
CANDIDATES = {"tiago": 1000, "ur5": 1000}
SIMULATED = [
    ("kuka", SensorModel("point", 1), MARKERS[:1], 12, "aic"),
    ("kuka", SensorModel("point", 1), MARKERS[:1], 12, "prior"),
    ("panda", SensorModel("point", 1), MARKERS[:1], 12, "aic"),
    ("ur5", SensorModel("pose", 1), MARKERS[:1], 12, "aic"),
    ("tiago", SensorModel("points", 4), MARKERS, 10, "aic"),
]


@pytest.mark.parametrize("robot, sensor, points, count, selection", SIMULATED,
                         ids=lambda v: getattr(v, "label", None))
def test_planned_configurations_calibrate_as_predicted_and_beat_random(robot, sensor, points, count, selection):
    """Full level, sigma 0.1 mm (and 0.1 deg), placement errors ~1 mm / 1 mrad, 8 noise seeds."""
    chain = _chain(robot)
    params = PlacementErrors(chain)
    truth = np.random.default_rng(1).normal(0.0, 1e-3, params.size)
    candidates = sample_candidates(chain, CANDIDATES.get(robot, 2000), seed=0)
    settings = PlanSettings(count=count, level="full", sensor=sensor, sigma_pos_mm=0.1, sigma_rot_deg=0.1,
                            target_points=points, selection=selection)
    plan = plan_measurements(chain, candidates, settings)
    heldout_q = random_configurations(chain, np.random.default_rng(123), 300)
    nominal = chain.placements()
    errors = {"planned": [], "random": []}
    for seed in range(8):
        rng = np.random.default_rng(1000 + seed)
        for kind in errors:
            q = plan.q if kind == "planned" else candidates[rng.choice(len(candidates), count, replace=False)]
            params.apply(truth)
            data = measure(chain, q, DEFAULT_REGISTRATION, rng,
                           SimulatedSensor(1e-4, np.radians(0.1), points=points, with_rotation=sensor.has_rotation),
                           "calibration")
            chain.set_placements(nominal)
            result = calibrate_chain(chain, data, "full", ChainFitOptions(selection=selection))
            errors[kind].append(_heldout_mm(chain, params, truth, result, points, heldout_q))
            chain.set_placements(nominal)
    predicted = plan.prediction.mean_position_mm
    observed = float(np.mean(errors["planned"]))
    assert abs(observed / predicted - 1.0) <= PREDICTION_TOLERANCE, f"observed {observed:.4f} vs {predicted:.4f} mm"
    ratio = np.median(errors["planned"]) / np.median(errors["random"])
    assert ratio <= RANDOM_RATIO, f"planned / random = {ratio:.3f}"
    assert plan.prediction.mean_position_mm < plan.random.mean_position_mm


def test_rank_m_updates_match_a_fresh_inverse():
    """The search's Woodbury updates (adds, removals) agree with recomputing P = M⁻¹ from scratch."""
    chain = _chain("ur5")
    model = MeasurementModel(chain, "full", SensorModel("pose", 1), MARKERS[:1], sigma_pos_m=1e-4, sigma_rot_rad=1e-3)
    q = sample_candidates(chain, 300, seed=4)
    problem = DesignProblem(model.jacobian(q), model.kinematic, model.jacobian(q[:2]), *model.error_jacobian(q[:50]))
    search = _Search(problem.blocks, problem.base, _weight(problem, "accuracy"), np.ones(300, bool))
    search.greedy(15, refresh_every=1000)
    search.update(int(np.flatnonzero(search.chosen)[3]), -1.0)
    state = {name: getattr(search, name).copy() for name in ("P", "G", "Q", "T")}
    search.refresh()
    for name, value in state.items():
        scale = np.abs(getattr(search, name)).max()
        assert np.abs(value - getattr(search, name)).max() <= 1e-8 * scale, name


def test_exchange_improves_on_greedy_and_criteria_are_consistent():
    chain = _chain("kuka")
    model = MeasurementModel(chain, "full", SensorModel("point", 1), default_target_points(1), sigma_pos_m=1e-4)
    q = sample_candidates(chain, 1000, seed=2)
    problem = DesignProblem(model.jacobian(q), model.kinematic, model.jacobian(q[:0]), *model.error_jacobian(q[:200]))
    for criterion in ("accuracy", "d", "a"):
        search = _Search(problem.blocks, problem.base, _weight(problem, criterion), np.ones(1000, bool))
        search.greedy(14)
        greedy = problem.criterion(np.flatnonzero(search.chosen), criterion)
        search.exchange()
        exchanged = problem.criterion(np.flatnonzero(search.chosen), criterion)
        assert (exchanged >= greedy) if criterion == "d" else (exchanged <= greedy), criterion


def test_the_prior_is_the_calibrations_posterior_precision():
    """With a prior the information is JᵀJ + Λ on the kinematic columns only (eq P1), in the scaled
    parameters; a prior 1e6 times wider than the default predicts what no prior does (to 1e-6)."""
    chain = _chain("kuka")
    model = MeasurementModel(chain, "full", SensorModel("point", 1), MARKERS[:1], sigma_pos_m=1e-4)
    q = sample_candidates(chain, 300, seed=5)
    args = (model.jacobian(q), model.kinematic, model.jacobian(q[:0]), *model.error_jacobian(q[:50]))
    plain = DesignProblem(*args)
    prior = Prior(1.0, 0.5)
    precision = model.prior_precision(prior)
    assert np.all(precision[model.kinematic] > 0) and not precision[len(model.kinematic):].any()
    assert precision[0] == pytest.approx(1e6)  # lwr_joint_1.tx: 1 / (1 mm)^2 [1/m^2]
    with_prior = DesignProblem(*args, prior_precision=precision)
    chosen = np.arange(14)
    added = with_prior.information(chosen) - plain.information(chosen)
    expected = np.diag(precision[with_prior.columns] / with_prior.scale**2)
    assert np.abs(added - expected).max() <= 1e-12 * np.abs(expected).max()
    assert with_prior.predict(chosen).mean_position_mm < plain.predict(chosen).mean_position_mm
    wide = DesignProblem(*args, prior_precision=model.prior_precision(Prior(1e6, 5e5)))
    assert wide.predict(chosen).mean_position_mm == pytest.approx(plain.predict(chosen).mean_position_mm, rel=1e-6)
    # the planner passes the selection's prior on: a prior of 1 um / 1e-4 deg leaves only what the
    # registration and the target add (the kinematics are known), far below the data alone
    settings = PlanSettings(count=12, level="full", sensor=SensorModel("point", 1), target_points=MARKERS[:1],
                            sigma_pos_mm=0.1)
    free = plan_measurements(chain, q, settings).prediction.mean_position_mm
    held = plan_measurements(chain, q, replace(settings, selection=Prior(1e-3, 1e-4))).prediction.mean_position_mm
    assert held < 0.5 * free


def test_the_best_of_several_exchange_starts_is_kept():
    """select() keeps the best end of the greedy start and the random ones: never worse than the
    greedy start alone, for every criterion and seed."""
    chain = _chain("kuka")
    model = MeasurementModel(chain, "full", SensorModel("point", 1), MARKERS[:1], sigma_pos_m=1e-4)
    q = sample_candidates(chain, 600, seed=6)
    problem = DesignProblem(model.jacobian(q), model.kinematic, model.jacobian(q[:0]), *model.error_jacobian(q[:100]))
    def minimised(chosen, criterion) -> float:  # what the search minimises: tr(P B), tr P or -ln det M
        info = problem.information(chosen) + PRIOR * np.eye(problem.n)
        if criterion == "d":
            return -np.linalg.slogdet(info)[1]
        return float(np.trace(np.linalg.solve(info, _weight(problem, criterion))))

    better = 0
    for criterion in ("accuracy", "d", "a"):
        for seed in range(3):
            alone = minimised(select(problem, 12, criterion, starts=1).chosen, criterion)
            best = minimised(select(problem, 12, criterion, starts=4, seed=seed).chosen, criterion)
            assert best <= alone + 1e-9 * abs(alone), (criterion, seed)
            better += best < alone - 1e-3 * abs(alone)
    assert better >= 1  # the random starts find a better end somewhere (6 % on the README's 12-point plan)


def test_recorded_data_choose_additions_with_decreasing_predicted_error():
    chain = _chain("tiago")
    existing, _ = read_measurements(TRAIN, chain.joint_specs)
    candidates = sample_candidates(chain, 500, seed=3)
    plan = plan_measurements(chain, candidates, PlanSettings(count=6, level="full"), existing=existing)
    assert plan.settings.sensor.label == "points:4"  # what the recorded rows hold
    assert plan.sigma_source.startswith("estimated from")
    predicted = [a.predicted_mean_mm for a in plan.additions]
    assert predicted[0] < plan.recorded.mean_position_mm
    assert all(b < a for a, b in zip(predicted, predicted[1:]))
    assert all(a.gain_mm > 0 for a in plan.additions)
    assert plan.prediction.mean_position_mm == pytest.approx(predicted[-1])
    assert plan.prediction.mean_position_mm < plan.random.mean_position_mm


def test_alternate_order_balances_the_approach_directions():
    chain = _chain("tiago")
    # 300 candidates, not 800: the choice is made twice and its cost grows with the candidates; of 300, arm_6's
    # correlation with its approach is 0.45 in the short order and 0.02 balanced (0.47 and 0.01 of 800)
    candidates = sample_candidates(chain, 300, seed=5)
    settings = PlanSettings(count=30, level="offsets", sensor=SensorModel("points", 4), target_points=MARKERS)
    short = plan_measurements(chain, candidates, settings)
    balanced = plan_measurements(chain, candidates, replace(settings, alternate=("arm_6_joint",)))
    assert set(short.candidates) == set(balanced.candidates)  # same choice, another order

    def arm6(plan):
        return next(b for b in plan.balance if b.joint == "arm_6_joint")

    b = arm6(balanced)
    assert abs(b.from_below - b.from_above) <= 2 and abs(b.correlation) < 0.2
    assert abs(b.correlation) < abs(arm6(short).correlation) or abs(arm6(short).balance - 0.5) > 0.1
    assert short.travel_s < balanced.travel_s


def test_short_tour_is_shorter_than_the_chosen_order():
    chain = _chain("panda")
    q = sample_candidates(chain, 40, seed=6)
    velocity = np.ones(chain.n_joints)
    order = short_tour(q, velocity, np.zeros(chain.n_joints))
    assert sorted(order) == list(range(40))
    travel = move_times(q[order], velocity).sum()
    assert travel < 0.7 * move_times(q, velocity).sum()
    for i in range(1, 39):  # 2-opt optimal: no segment reversal shortens it
        for j in range(i + 1, 40):
            trial = order.copy()
            trial[i : j + 1] = trial[i : j + 1][::-1]
            assert move_times(q[trial], velocity).sum() >= travel - 1e-9
    ups = approach_balance(np.array([[0.0], [1.0], [0.5], [0.5], [2.0]]), ["j"])[0]
    assert (ups.from_below, ups.from_above, ups.kept) == (2, 1, 1)


def test_min_distance_refuses_configurations_closer_than_the_clearance():
    """Panda: refused candidates are counted; every kept one has all checked pairs >= 2 cm apart
    (checked independently with Pinocchio's distances)."""
    chain = _chain("panda")
    q = sample_candidates(chain, 150, seed=7)
    clearance = check_clearance(_urdf("panda"), chain, q, 0.02)
    assert clearance.in_collision > 0 and clearance.too_close > 0
    assert clearance.allowed.sum() == 150 - clearance.in_collision - clearance.too_close
    model = pin.buildModelFromUrdf(str(_urdf("panda")))
    geometry = pin.buildGeomFromUrdf(model, str(_urdf("panda")), pin.GeometryType.COLLISION,
                                     package_dirs=[str(p) for p in _urdf("panda").parents])
    geometry.addAllCollisionPairs()
    data, geometry_data = model.createData(), geometry.createData()
    full_q = np.zeros((len(q) + 1, model.nq))  # the fingers stay at zero, as locked in the chain
    full_q[1:, : chain.n_joints] = q
    full_q[0, : chain.n_joints] = np.clip(0.0, [j.lower for j in chain.joints], [j.upper for j in chain.joints])
    pin.computeDistances(model, data, geometry, geometry_data, full_q[0])  # the rule: pairs apart at zero
    checked = [i for i, r in enumerate(geometry_data.distanceResults) if r.min_distance >= 0.02]
    full_q = full_q[1:]
    closest = []
    for configuration in full_q:
        pin.computeDistances(model, data, geometry, geometry_data, configuration)
        closest.append(min(geometry_data.distanceResults[i].min_distance for i in checked))
    closest = np.array(closest)
    assert np.all(closest[clearance.allowed] >= 0.02 - 1e-9)
    assert np.all(closest[~clearance.allowed] < 0.02)


# --- real data ------------------------------------------------------------------------


def test_tiago_planned_subset_is_in_the_best_quarter_of_random_subsets():
    """Choose 20 of the 37 postures of 2021-11-30 (full level, four markers, the default criterion),
    calibrate on them and hold out 2021-11-26: marker-1 RMS (the README's TIAGo metric) in the best
    quarter of 1000 seeded random 20-row subsets. Every calibration estimates all identifiable
    parameters (``selection="all"``): the estimator whose error the plan predicts.

    The 1000 random calibrations (85 s) are read from ``tests/data/tiago_random_subsets.csv``
    (``scripts/tiago_random_subsets.py``); 20 of them are recomputed here to 1e-6 mm — the 10 nearest
    the planned value, which decide the rank, and 10 seeded others — so a reference that no longer
    matches the calibrator fails rather than ranks."""
    script = _script("tiago_random_subsets")
    chain, train, held_out = script.tiago()
    subsets, random = script.read_reference()
    assert len(random) == 1000 and [list(s) for s in subsets] == [list(s) for s in script.random_subsets(1000)]
    plan = plan_measurements(chain, train.q, PlanSettings(count=20, level="full", sensor=SensorModel("points", 4)))
    planned = script.heldout_rms(chain, train, held_out, plan.candidates)
    nearest = np.argsort(np.abs(random - planned))[:10]
    others = np.random.default_rng(2).choice(np.setdiff1d(np.arange(1000), nearest), 10, replace=False)
    for index in np.concatenate([nearest, others]):
        again = script.heldout_rms(chain, train, held_out, subsets[index])
        assert again == pytest.approx(random[index], abs=1e-6), (
            f"subset {index}: {again!r} mm now, {random[index]!r} mm in the reference: "
            "rerun python scripts/tiago_random_subsets.py")
    rank = np.mean(random < planned)
    assert rank <= 0.25, f"planned {planned:.2f} mm, rank {rank:.3f}"


def _script(name: str):
    """A module of ``scripts/`` (not a package), loaded from its file."""
    spec = importlib.util.spec_from_file_location(name, ROOT / "scripts" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


# --- command line ---------------------------------------------------------------------


def _plan(tmp_path, *args):
    return main(["plan", *map(str, args), "--out", str(tmp_path / "PLAN.csv"), "--report", str(tmp_path / "PLAN.json")])


def test_cli_plans_writes_the_plan_and_its_prediction(tmp_path, capsys):
    code = _plan(tmp_path, kuka_lwr4plus_urdf(), "--tip-link", KUKA_FLANGE_LINK, "--count", 14, "--sample", 500,
                 "--seed", 3, "--alternate", "lwr_joint_2")
    assert code == 0, capsys.readouterr().err
    out = capsys.readouterr().out
    assert "plan / random" in out and "lwr_joint_2" in out
    with open(tmp_path / "PLAN.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 14 and list(rows[0])[:7] == [f"lwr_joint_{n}" for n in range(1, 8)]
    assert sorted(int(r["priority"]) for r in rows) == list(range(1, 15))
    doc = json.loads((tmp_path / "PLAN.json").read_text())
    predicted = doc["predicted"]
    assert predicted["plan"]["mean_position_mm"] < predicted["random"]["mean_position_mm"]
    # the prediction after the last addition is the plan's, and it is what the command printed
    assert doc["additions"][-1]["predicted_mean_mm"] == pytest.approx(predicted["plan"]["mean_position_mm"])
    assert f"predicted error, plan:   mean {predicted['plan']['mean_position_mm']:.4g} mm" in out
    assert doc["identifiability"]["condition_number"] > 1 and doc["identifiability"]["identifiable"]
    assert doc["order"]["alternate"] == ["lwr_joint_2"] and len(doc["order"]["approach_balance"]) == 7
    assert doc["criterion"]["name"] == "accuracy" and doc["candidates"]["count"] == 500
    # calibrate's default at level full is the prior: the plan is for it, and says so
    assert doc["settings"]["select"] == "prior"
    assert doc["settings"]["prior_scale"] == {"translation_mm": 1.0, "rotation_deg": 0.5, "joint_zero_deg": 0.5}


def test_cli_candidates_file_plan_feeds_calibrate(tmp_path, capsys):
    """TIAGo: choose 12 of the recorded postures; the plan's rows, measured (here: taken from the
    session), calibrate through the CLI."""
    urdf = _urdf("tiago")
    code = _plan(tmp_path, urdf, "--tip-link", "wrist_ft_tool_link", "--count", 12, "--candidates", TRAIN,
                 "--measure", "points:4", "--level", "offsets")
    assert code == 0, capsys.readouterr().err
    with open(tmp_path / "PLAN.csv", newline="") as handle:
        lines = [int(r["candidate"]) for r in csv.DictReader(handle)]
    with open(TRAIN, newline="") as handle:
        records = list(csv.reader(handle))
    measured = tmp_path / "measured.csv"
    with open(measured, "w", newline="") as handle:
        csv.writer(handle).writerows([records[0]] + [records[line - 1] for line in lines])
    assert main(["calibrate", str(urdf), str(measured), "--tip-link", "wrist_ft_tool_link", "--level", "offsets",
                 "--out", str(tmp_path / "c.urdf"), "--report", str(tmp_path / "r.json")]) == 0


@pytest.mark.parametrize(
    "args, message",
    [
        (["--alternate", "lwr_joint_9"], "no joint 'lwr_joint_9'"),
        (["--count", "600"], "more than the 500 usable candidates"),
        (["--count", "3"], "plan at least"),
        (["--measure", "points:2", "--tool", "0,0,0.1,0,0,0"], "a known tool is one point"),
        (["--min-distance", "0.01"], "no <collision> geometry"),
        (["--level", "dh"], "--level dh plans for the paper's DH parameters with the target known: give --tool"),
        (["--level", "registration", "--select", "prior"], "--select prior does not apply to --level registration"),
        (["--select", "aic", "--prior-scale", "1,0.5"], "--prior-scale applies to --select prior only"),
    ],
)
def test_cli_errors_are_one_line_and_exit_2(tmp_path, capsys, args, message):
    candidates = tmp_path / "candidates.csv"
    candidates.write_text("lwr_joint_1,lwr_joint_2,lwr_joint_3,lwr_joint_4,lwr_joint_5,lwr_joint_6,lwr_joint_7\n"
                          + "0,0,0,0,0,0,0\n" * 3)
    args = [str(candidates) if a == "CANDIDATES" else a for a in args]
    base = ["--tip-link", KUKA_FLANGE_LINK, "--sample", "500"] if "--sample" not in args else ["--tip-link",
                                                                                               KUKA_FLANGE_LINK]
    count = [] if "--count" in args else ["--count", "12"]
    code = _plan(tmp_path, kuka_lwr4plus_urdf(), *base, *count, *args)
    err = capsys.readouterr().err
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1, err


@pytest.mark.parametrize(
    "content, message",
    [
        ("lwr_joint_1,lwr_joint_2\n0,0\n", "missing joint column(s) lwr_joint_3"),
        ("{header}\n0,0,0,3.5,0,0,0\n", "line 2, column 'lwr_joint_4': 3.5 rad is outside the joint limits"),
        ("{header}\n0,0,0,90,0,0,0\n", "looks like degrees"),
        ("{header}\n0,0,x,0,0,0,0\n", "line 2, column 'lwr_joint_3'"),
        ("{header},lwr_joint_1\n0,0,0,0,0,0,0,0.5\n", "line 1: duplicate column(s) lwr_joint_1"),
        ("{header}\n0,0,0,0,0,0\n", "line 2: 6 fields but the header has 7"),
        ("{header}\n0,0,0,0,0,0,0,0\n", "line 2: 8 fields but the header has 7"),
    ],
)
def test_cli_rejects_bad_candidate_files(tmp_path, capsys, content, message):
    header = ",".join(f"lwr_joint_{n}" for n in range(1, 8))
    candidates = tmp_path / "candidates.csv"
    candidates.write_text(content.format(header=header))
    code = _plan(tmp_path, kuka_lwr4plus_urdf(), "--tip-link", KUKA_FLANGE_LINK, "--count", 12,
                 "--candidates", candidates)
    err = capsys.readouterr().err
    assert code == 2 and message in err, err


@pytest.mark.parametrize(
    "args, message",
    [
        (["--measure", "points:1"], "argument --measure: 'points:1': use point, points:M"),
        (["--target-points", "0.1,0.2"], "argument --target-points: '0.1,0.2': give X,Y,Z"),
        (["--alternate", ","], "argument --alternate: ',': give JOINT[,JOINT...]"),
        (["--tool", "0,0,0.1,0,0,90"], "roll/pitch/yaw beyond one turn look like degrees; give radians"),
        (["--candidates", "c.csv", "--sample", "100"], "argument --sample: not allowed with argument --candidates"),
    ],
)
def test_cli_argument_errors_are_usage_errors(tmp_path, capsys, args, message):
    """Values argparse checks (its types and groups): exit 2, the message on the usage error's line."""
    with pytest.raises(SystemExit) as exit_info:
        _plan(tmp_path, kuka_lwr4plus_urdf(), "--tip-link", KUKA_FLANGE_LINK, "--count", 12, *args)
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert message in err.strip().splitlines()[-1], err


def test_plan_settings_take_typed_values():
    assert PlanSettings(count=3, target_points=[0.0, 0.0, 0.1]).target_points.shape == (1, 3)
    with pytest.raises(PincalError, match="target points"):
        PlanSettings(count=3, target_points=np.zeros((2, 2)))


def test_cli_refuses_a_tip_link_without_a_chain_and_an_input_as_output(tmp_path, capsys):
    assert _plan(tmp_path, kuka_lwr4plus_urdf(), "--tip-link", "lwr_base_link", "--count", 12) == 2
    assert "no joint between the root" in capsys.readouterr().err
    code = main(["plan", str(kuka_lwr4plus_urdf()), "--tip-link", KUKA_FLANGE_LINK, "--count", "12",
                 "--out", str(kuka_lwr4plus_urdf()), "--report", str(tmp_path / "PLAN.json")])
    assert code == 2 and "refusing to overwrite an input" in capsys.readouterr().err
    same = tmp_path / "PLAN.csv"
    code = main(["plan", str(kuka_lwr4plus_urdf()), "--tip-link", KUKA_FLANGE_LINK, "--count", "12",
                 "--out", str(same), "--report", str(same)])
    err = capsys.readouterr().err
    assert code == 2 and "is also the path of another output of this run" in err
    assert "refusing to overwrite an input" not in err, err  # the message of the case above
    assert not same.exists()


def test_cli_creates_a_missing_output_folder_and_records_the_plan_it_describes(tmp_path, capsys):
    """One folder policy for every command: a missing output folder is created. PLAN.json names the
    PLAN.csv written beside it by the SHA-256 of its bytes."""
    out = tmp_path / "new" / "deeper"
    code = main(["plan", str(kuka_lwr4plus_urdf()), "--tip-link", KUKA_FLANGE_LINK, "--count", "12",
                 "--sample", "300", "--out", str(out / "PLAN.csv"), "--report", str(out / "PLAN.json")])
    assert code == 0, capsys.readouterr().err
    doc = json.loads((out / "PLAN.json").read_text())
    assert doc["plan_csv_sha256"] == hashlib.sha256((out / "PLAN.csv").read_bytes()).hexdigest()


def test_cli_existing_data_must_match_the_measure(tmp_path, capsys):
    code = _plan(tmp_path, _urdf("tiago"), "--tip-link", "wrist_ft_tool_link", "--count", 4, "--sample", 200,
                 "--existing", TRAIN, "--measure", "point")
    err = capsys.readouterr().err
    assert code == 2 and "measure 4 point(s)" in err, err


def test_sensor_kinds_of_measure_and_their_refusal():
    """``--measure``'s forms give the sensor kinds of ``SENSOR_KINDS``, each; a kind outside them is refused."""
    from pincal.cli.arguments import measure
    from pincal.measurements.data import SENSOR_KINDS

    models = [measure(text) for text in ("point", "points:3", "pose")]
    assert tuple(m.kind for m in models) == SENSOR_KINDS
    assert [m.n_points for m in models] == [1, 3, 1]
    with pytest.raises(PincalError, match="sensor kind 'marker'"):
        SensorModel("marker", 1)  # type: ignore[arg-type]  # what the Literal forbids, at run time
