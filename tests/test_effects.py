"""Unmodelled effects: bases, gravity torques and their Jacobians."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from conftest import assert_close, numeric_jacobian

from pincal.errors import PincalError
from pincal.model.chain import pose_from_xyz_rpy
from pincal.model.effects import (
    FLANK_GAP_S,
    Effect,
    EffectInputs,
    RowContext,
    approach_flank,
    effect_inputs,
    gravity_torques,
    parse_effect,
)
from pincal.model.parameter_sets import PlacementErrors
from pincal.model.sensor import Registration
from pincal.residuals.base import KinematicsCache
from pincal.residuals.sensor import SensorResidual, TargetEstimate
from pincal.residuals.sensor_values import ModelledEffects, RowWeights

ALL_EFFECTS = [
    Effect("compliance", "lwr_joint_2"),
    Effect("encoder_scale", "lwr_joint_3"),
    Effect("cyclic", "lwr_joint_4", harmonic=2),
    Effect("backlash", "lwr_joint_5", source="gravity"),
    Effect("backlash", "lwr_joint_6", source="approach"),
    Effect("drift"),
    Effect("sensor_scale"),
]


def test_sensor_residual_jacobian_with_every_effect(kuka_chain):
    rng = np.random.default_rng(8)
    params = PlacementErrors(kuka_chain)
    q = rng.uniform(-1.5, 1.5, (9, 7))
    gravity = gravity_torques(kuka_chain, q)
    inputs = EffectInputs(q=q, gravity=gravity, time=np.linspace(-600, 600, 9), order=np.arange(9))
    free = rng.permutation(params.size)[:12]
    cache = KinematicsCache(params, free, rng.normal(0, 1e-2, params.size), q)
    start = TargetEstimate(Registration(pin.exp3(rng.normal(size=3)), rng.normal(size=3)),
                           rng.normal(0, 0.1, (2, 3)), pin.exp3(rng.normal(size=3)))
    rotations = np.stack([pin.exp3(rng.normal(size=3)) for _ in q])
    objective = SensorResidual(cache, rng.normal(size=(9, 2, 3)), rotations, start, RowWeights(rotation=2.0),
                               effects=ModelledEffects(ALL_EFFECTS, inputs))
    x = objective.start_vector() + rng.normal(0, 0.01, objective.n_free)
    x[objective.blocks["effects"]] = rng.normal(0, 1e-3, objective.blocks["effects"].stop - objective.blocks["effects"].start)
    # central differences, step 1e-6: truncation ~1e-12 × third derivatives, rounding
    # ~1e-16 × |r| / 1e-6 ≈ 1e-9 for residuals of O(10); a wrong term is O(1e-2) or more
    assert_close(objective.jacobian(x), numeric_jacobian(objective.residual, x), 1e-6, "effects")


def test_gravity_torques_match_pinocchio_and_payload_adds_torque(kuka_chain):
    q = np.array([[0.0, 0.3, 0.0, -0.5, 0.0, 0.4, 0.0]])
    base = gravity_torques(kuka_chain, q)
    direct = pin.computeGeneralizedGravity(kuka_chain.model, kuka_chain.model.createData(), q[0])
    assert_close(base[0], direct, 1e-12, "gravity")
    kuka_chain.set_tool(pose_from_xyz_rpy([0.045, -0.043, 0.118], [0.12, -0.25, 0.4]))  # the payload hangs on it
    point = np.array([0.0, 0.0, 0.1])
    loaded = gravity_torques(kuka_chain, q, payload_kg=2.0, payload_point=point)
    # A point mass m at p(q) adds the gradient of its potential energy −m gᵀ p(q):
    # −m J_pᵀ g, with J_p from central differences of Pinocchio FK (step 1e-6:
    # error ~1e-12 m per rad, times m |g| ≈ 20 N, far below the 1e-6 N·m tolerance)
    gravity = kuka_chain.model.gravity.linear

    def payload_position(joints):
        poses = kuka_chain.poses(joints[None])
        return poses.tool_positions[0] + poses.tool_rotations[0] @ point

    expected = -2.0 * numeric_jacobian(payload_position, q[0]).T @ gravity
    assert_close(loaded[0] - base[0], expected, 1e-6, "payload torque")
    assert np.abs(expected).max() > 1e3 * 1e-6  # the comparison is informative: far above its tolerance
    assert loaded[0, 0] == pytest.approx(base[0, 0], abs=1e-9)  # joint 1 turns about gravity's axis


def test_approach_flank_keeps_the_flank_on_small_moves():
    q = np.array([0.0, 0.1, 0.1005, 0.05, 0.05, 0.2])
    assert approach_flank(q, np.arange(6)).tolist() == [0, 1, 1, -1, -1, 1]
    # time order, not file order
    assert approach_flank(q[::-1], np.arange(6)[::-1]).tolist() == [1, -1, -1, 1, 1, 0]


def test_approach_flank_follows_interleaved_rows_of_another_set(kuka_chain):
    """A held-out row between calibration rows takes its flank from the row before it in time."""
    q = np.zeros((3, 7))
    q[:, 5] = [0.0, 0.2, 0.3]           # calibration rows at t = 0, 20, 40
    other = np.zeros((2, 7))
    other[:, 5] = [0.5, 0.1]            # held-out rows at t = 10, 30
    from pincal.measurements.data import MeasurementSet
    held = MeasurementSet(joint_names=kuka_chain.joint_names, q=other, points=np.zeros((2, 1, 3)), rotations=None,
                          roles=np.array(["validation"] * 2, dtype=object), lines=np.arange(2, 4))
    cal = MeasurementSet(joint_names=kuka_chain.joint_names, q=q, points=np.zeros((3, 1, 3)), rotations=None,
                         roles=np.array(["calibration"] * 3, dtype=object), lines=np.arange(2, 5))
    inputs = effect_inputs(kuka_chain, cal, time=np.array([0.0, 20.0, 40.0]),
                           context=RowContext(held.q, np.array([10.0, 30.0])))
    from pincal.model.effects import joint_basis
    flank = joint_basis(Effect("backlash", "lwr_joint_6", source="approach"), inputs, 5)[:, 0]
    assert flank.tolist() == [0.0, -1.0, 1.0]  # 0.5 -> 0.2 goes down, 0.1 -> 0.3 goes up
    # rows of another day (spans apart: 100 h before) set no flank: the first row's stays 0, the others
    # follow their own rows, as without them (the README's TIAGo split: diagnose's fit then does not
    # depend on the held-out file, and evaluate on the calibration rows says what diagnose said)
    days_before = effect_inputs(kuka_chain, cal, time=np.array([0.0, 20.0, 40.0]),
                                context=RowContext(held.q, np.array([10.0, 30.0]) - 3.6e5))
    assert days_before.context_q is None
    flank = joint_basis(Effect("backlash", "lwr_joint_6", source="approach"), days_before, 5)[:, 0]
    assert flank.tolist() == [0.0, 1.0, 1.0]
    # rows just before (10 s, not interleaved) are the same motion: 0.1 -> 0.0 reaches the first row from above
    just_before = effect_inputs(kuka_chain, cal, time=np.array([0.0, 20.0, 40.0]),
                                context=RowContext(held.q, np.array([-20.0, -10.0])))
    flank = joint_basis(Effect("backlash", "lwr_joint_6", source="approach"), just_before, 5)[:, 0]
    assert flank.tolist() == [-1.0, 1.0, 1.0]
    # and up to FLANK_GAP_S (half an hour) away; beyond it, unknown
    for gap, first in ((FLANK_GAP_S, -1.0), (FLANK_GAP_S + 1.0, 0.0)):
        apart = effect_inputs(kuka_chain, cal, time=np.array([0.0, 20.0, 40.0]),
                              context=RowContext(held.q, np.array([-10.0 - gap, -gap])))
        assert joint_basis(Effect("backlash", "lwr_joint_6", source="approach"), apart, 5)[0, 0] == first, gap


def test_parse_effect_forms():
    effect, value = parse_effect("compliance:lwr_joint_2:2e-4")
    assert effect == Effect("compliance", "lwr_joint_2") and value.tolist() == [2e-4]
    effect, value = parse_effect("cyclic:lwr_joint_4:2:1e-3:-5e-4")
    assert effect.harmonic == 2 and value.tolist() == [1e-3, -5e-4]
    effect, _ = parse_effect("backlash:arm_6_joint:0.04:approach")
    assert effect.source == "approach"
    with pytest.raises(PincalError, match="TYPE:JOINT:VALUE"):
        parse_effect("compliance:lwr_joint_2")
    with pytest.raises(PincalError, match="unknown effect"):
        parse_effect("wobble:lwr_joint_2:1")


def test_effect_columns_are_the_jacobian_columns_an_added_effect_brings(kuka_chain):
    """SensorResidual.effect_columns (the screening's candidate columns) equal the
    columns of the same objective with the effect added at value zero, on top of
    effects already in the fit (a nonzero sensor scale scales the new columns)."""
    rng = np.random.default_rng(12)
    params = PlacementErrors(kuka_chain)
    q = rng.uniform(-1.5, 1.5, (9, 7))
    inputs = EffectInputs(q=q, gravity=gravity_torques(kuka_chain, q), time=np.linspace(-600, 600, 9),
                          order=np.arange(9))
    free = rng.permutation(params.size)[:12]
    start = TargetEstimate(Registration(pin.exp3(rng.normal(size=3)), rng.normal(size=3)),
                           rng.normal(0, 0.1, (2, 3)), pin.exp3(rng.normal(size=3)))
    points, rotations = rng.normal(size=(9, 2, 3)), np.stack([pin.exp3(rng.normal(size=3)) for _ in q])
    base, weights = rng.normal(0, 1e-2, params.size), rng.uniform(0.5, 2, 9)
    present = [Effect("compliance", "lwr_joint_2"), Effect("sensor_scale")]
    added = [e for e in ALL_EFFECTS if e not in present]

    def objective(effects):
        cache = KinematicsCache(params, free, base, q)
        return SensorResidual(cache, points, rotations, start, RowWeights(position=weights, rotation=2.0),
                              effects=ModelledEffects(effects, inputs))

    fit = objective(present)
    x = fit.start_vector() + rng.normal(0, 0.01, fit.n_free)
    x[fit.blocks["effects"]] = [2e-4, 3e-3]
    columns = fit.effect_columns(x, added)
    for effect, block in zip(added, columns):
        extended = objective(present + [effect])
        full = extended.jacobian(np.concatenate([x, np.zeros(effect.n_values)]))
        assert_close(block, full[:, extended.effect_slices[-1]], 1e-12, effect.label)



def test_each_effect_states_its_unit():
    """The units of the module docstring of pincal.model.effects, for revolute and prismatic joints
    (pincal.model.effect_units.value_unit)."""
    from pincal.model.effect_units import value_unit

    assert value_unit("compliance") == "rad/(N·m)" and value_unit("compliance", True) == "m/N"
    assert value_unit("backlash") == "rad"
    assert value_unit("cyclic", prismatic=True) == "m"
    assert value_unit("encoder_scale") == value_unit("sensor_scale") == "(relative)"
    assert value_unit("drift") == "m/s"


def test_held_out_rows_judge_an_effect_by_a_paired_test_in_noise_units():
    """pincal.diagnosis.verdicts.held_out_verdict: the per-row change of held-out error over the noise,
    position and orientation together, must fall at the signed-rank test's one-sided level Φ(−2)."""
    from pincal.diagnosis.held_out import held_out_verdict
    from pincal.fit.metrics import PoseErrors

    rng = np.random.default_rng(4)
    sigma_pos, sigma_rot = 20e-6, 3e-4
    before = PoseErrors(np.abs(rng.normal(0.0, 3 * sigma_pos, (40, 1))), np.abs(rng.normal(0.0, sigma_rot, 40)))

    def after(position_scale, rotation_scale):
        return PoseErrors(before.position_m * position_scale, before.rotation_rad * rotation_scale)

    # the case: 0.370 -> 0.376 mm (+1.6 %) was adopted under a +2 % tolerance: worse, row by row
    assert held_out_verdict(before, after(1.016, 1.0), sigma_pos, sigma_rot).startswith("it makes the held-out rows worse")
    # much better in position for a little orientation: better in noise units
    assert held_out_verdict(before, after(0.2, 1.05), sigma_pos, sigma_rot) == "adopted"
    # the same errors dealt to other rows: each row changes by its noise, the mean by nothing
    shuffled = rng.permutation(40)
    dealt = PoseErrors(before.position_m[shuffled], before.rotation_rad[shuffled])
    assert "beyond their noise" in held_out_verdict(before, dealt, sigma_pos, sigma_rot)
    # orientation far worse, position a little better: worse
    assert "worse" in held_out_verdict(before, after(0.95, 3.0), sigma_pos, sigma_rot)
    # positions only: the orientation term is left out
    positions = PoseErrors(before.position_m, None)
    assert held_out_verdict(positions, PoseErrors(before.position_m * 0.5, None), sigma_pos, None) == "adopted"


def test_a_few_held_out_rows_veto_only_a_worse_total():
    """Below MIN_PAIRED_ROWS held-out rows the effect moves by a noise unit (TELLING_CHANGE) the signed-rank
    test cannot reach its level (2⁻ⁿ > 0.0228): only errors that grow in total refuse — by their distances, so
    a row a metre off counts by how far it moves, not by its square; rows it does not move cannot refute it."""
    from pincal.diagnosis.held_out import HELD_OUT_LEVEL, MIN_PAIRED_ROWS, held_out_verdict
    from pincal.fit.metrics import PoseErrors

    assert 2.0 ** -MIN_PAIRED_ROWS < HELD_OUT_LEVEL < 2.0 ** -(MIN_PAIRED_ROWS - 1)
    before = PoseErrors(np.full((MIN_PAIRED_ROWS - 4, 1), 0.6), None)
    assert held_out_verdict(before, PoseErrors(before.position_m / 6, None), 2e-5, None) == "adopted"
    assert "worse in total" in held_out_verdict(before, PoseErrors(before.position_m * 1.1, None), 2e-5, None)
    three = PoseErrors(np.array([[1e-4], [1e-4], [1.0]]), None)  # two rows improve by 4 σ, one a metre off
    assert held_out_verdict(three, PoseErrors(np.array([[2e-5], [2e-5], [1.0001]]), None), 2e-5, None) == "adopted"
    assert "worse in total" in held_out_verdict(three, PoseErrors(np.array([[2e-5], [2e-5], [1.0002]]), None),
                                                2e-5, None)  # it moves 10 σ the wrong way
    # twelve rows of which one sees the effect (circle point analysis: one joint moves in two held-out rows)
    twelve = PoseErrors(np.r_[np.full(11, 3e-5), 8e-4][:, None], None)
    moved = PoseErrors(np.r_[np.full(11, 3e-5) * np.r_[1.3, np.ones(10)], 3e-5][:, None], None)
    assert held_out_verdict(twelve, moved, 2e-5, None) == "adopted"


def test_two_wild_held_out_rows_cannot_decide():
    """18 held-out rows that an effect brings from its 0.3 mm to the noise (20 µm), and two rows a metre off (a
    bad measurement) whose error it moves 0.3 mm further: the mean change of squared error is the wild rows'
    (+1.5e6 noise² each against −225 for each good row), the signed-rank test of the distances is not."""
    from pincal.diagnosis.held_out import held_out_verdict
    from pincal.fit.metrics import PoseErrors

    rng = np.random.default_rng(29)
    sigma, shift = 20e-6, 3e-4
    noise = np.abs(rng.normal(0.0, sigma * np.sqrt(3), 20))
    before = PoseErrors(np.concatenate([shift + noise[:18], [1.0, 1.2]])[:, None], None)
    after = PoseErrors(np.concatenate([noise[:18], [1.0 + shift, 1.2 + shift]])[:, None], None)
    assert held_out_verdict(before, after, sigma, None) == "adopted"
    worse = PoseErrors(before.position_m * 1.02, None)  # every row 2 % worse, the wild ones too: still worse
    assert held_out_verdict(before, worse, sigma, None).startswith("it makes the held-out rows worse")


def test_a_report_effect_with_the_wrong_number_of_values_is_refused_in_one_line():
    """A thermal α given as two numbers, a pause step as two, a value null: refused, not run as α = 1."""
    from pincal.errors import PincalError
    from pincal.model.effects import effect_from_dict

    for entry in ({"type": "thermal", "joint": None, "value": [1.0, 2.0]},
                  {"type": "pause_step", "joint": None, "value": [1e-6, 2e-6], "pause": 1},
                  {"type": "compliance", "joint": "j", "value": None},
                  {"type": "drift", "joint": None, "value": [0.0, float("nan"), 0.0]}):
        with pytest.raises(PincalError, match="bad effect entry .* must be [13] finite number"):
            effect_from_dict(entry)
    assert effect_from_dict({"type": "pause_step", "joint": None, "value": [1e-6, 2e-6, 0.0], "pause": 1})[1].size == 3


def test_the_signed_rank_test_is_scipys():
    """pincal.diagnosis.held_out.signed_rank_p, written with numpy (importing scipy.stats costs 0.6 s of CPU),
    gives scipy.stats.wilcoxon's one-sided p to 1e-12: exact up to 50 rows, ties among them (up to 13 rows, where
    scipy enumerates every sign), the normal approximation with its tie correction beyond."""
    import scipy.stats

    from pincal.diagnosis.held_out import signed_rank_p

    rng = np.random.default_rng(45)
    for size, decimals in [(n, None) for n in (1, 6, 20, 50, 51, 120)] + [(n, 1) for n in (6, 9)] + [(120, 1)]:
        change = rng.normal(0.3, 1.0, size)
        change = change if decimals is None else np.round(change, decimals)
        change = change[change != 0]
        for alternative in ("less", "greater"):
            expected = scipy.stats.wilcoxon(change, alternative=alternative).pvalue
            assert abs(signed_rank_p(change, alternative) - expected) < 1e-12, (size, decimals, alternative)


def test_the_held_out_noise_is_the_sensors_or_the_fitting_models():
    """Judge.judged_noise: the stated σ_pos (--sigma-pos) when given; otherwise, per kind, the smallest of the
    current model's and the fitted models' — never the scale of a model a hundred times off — at least
    NOISE_FLOOR. With the misfit's scale no row would move by a noise unit, and the test could not refuse."""
    from pincal.diagnosis.held_out import held_out_verdict
    from pincal.diagnosis.verdicts import NOISE_FLOOR, Judge
    from pincal.fit.metrics import PoseErrors

    misfit = Judge(None, None, None, None, None, noise=(2e-3, 0.05))  # a geometry on the wrong readings
    assert misfit.judged_noise((2e-5, 3e-4)) == (2e-5, 3e-4)
    assert misfit.judged_noise((0.0, None)) == (NOISE_FLOOR, 0.05)
    stated = Judge(None, None, None, None, None, noise=(2e-3, None), stated_pos=1e-5)
    assert stated.judged_noise((2e-5, None)) == (1e-5, None)
    # four rows 5 σ better, eight 2 σ worse: not beyond the noise at the fitting scale, where every row tells;
    # at the misfit's none moves by a noise unit, and the total alone would let it through
    before = PoseErrors(np.r_[np.full(4, 1.2e-4), np.full(8, 3e-5)][:, None], None)
    after = PoseErrors(np.r_[np.full(4, 2e-5), np.full(8, 7e-5)][:, None], None)
    assert "beyond their noise" in held_out_verdict(before, after, *misfit.judged_noise((2e-5, None)))
    assert held_out_verdict(before, after, 2e-3, None) == "adopted"
