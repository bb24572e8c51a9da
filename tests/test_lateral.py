"""Lateral (bending) compliance: a joint that turns about the two axes orthogonal to its own under the gravity
moment it carries (eq L1–L3 of :mod:`pincal.model.lateral`): its moments, its exact Jacobian, its report entry."""

from __future__ import annotations

import re

import numpy as np
import pinocchio as pin
import pytest
from conftest import assert_close, numeric_jacobian

from pincal.diagnosis.diagnose import DiagnoseOptions, candidate_effects, diagnose
from pincal.diagnosis.moment_candidates import combination_words
from pincal.fit.chain_calibration import ChainFitOptions, calibrate_chain
from pincal.model.chain import KinematicChain
from pincal.model.effects import Effect, EffectInputs, effect_from_dict, effect_to_dict, parse_effect, with_loads
from pincal.model.lateral import bend_angles, bend_slots, bent_tool_poses, lateral_basis
from pincal.model.mass_moments import bending_moments, gravity_loads, lateral_axes
from pincal.model.parameter_sets import PlacementErrors
from pincal.model.sensor import Registration
from pincal.residuals.base import KinematicsCache
from pincal.residuals.sensor import SensorResidual, TargetEstimate
from pincal.residuals.sensor_values import ModelledEffects, RowWeights
from pincal.robots import KUKA_FLANGE_LINK
from pincal.simulation.sensor import (
    DEFAULT_REGISTRATION,
    SimulatedEffects,
    SimulatedSensor,
    measure,
    random_configurations,
)


def _rows(n: int, seed: int = 1) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-2.0, 2.0, (n, 7))


def _inputs(chain: KinematicChain, q: np.ndarray) -> EffectInputs:
    return with_loads(EffectInputs(q=q, gravity=np.zeros_like(q), time=None, order=np.arange(len(q)),
                                   bending=bending_moments(chain, q)), chain)


def test_bending_moments_are_the_loads_about_u_and_v_of_the_urdfs_inertias(kuka_urdf):
    """Eq M3 of the URDF's π (rnea's transmitted wrench) is the mass-moment loads' u, v components times π g₀."""
    chain = KinematicChain.from_urdf(kuka_urdf, KUKA_FLANGE_LINK)
    q = _rows(4)
    model = chain.model
    pi = np.concatenate([model.inertias[j].toDynamicParameters()[:4] for j in chain.joint_ids])
    loads = gravity_loads(chain, q)[:, :, 1:, :] @ pi * np.linalg.norm(model.gravity.linear)
    moments = bending_moments(chain, q)
    assert_close(moments, loads, 1e-9, "eq M3")
    assert np.abs(moments[:, 1:]).max() > 1.0  # N·m: J2..J7 carry links
    u, v = lateral_axes(np.array([0.0, 0.0, 1.0]))
    assert_close(np.vstack([u, v]), [[1, 0, 0], [0, 1, 0]], 0.0, "u, v of a z axis")


def test_a_lateral_compliance_turns_the_chain_at_its_joint(kuka_urdf):
    """Eq L1: the bent chain's tool is the joint's frame turned by exp(δ_u u) exp(δ_v v) and the rest after it."""
    chain = KinematicChain.from_urdf(kuka_urdf, KUKA_FLANGE_LINK)
    q = _rows(3)
    bends = np.zeros((3, 14))
    bends[:, 2:4] = [[0.01, -0.02], [0.0, 0.03], [-0.01, 0.0]]  # J2's u and v
    bent = bent_tool_poses(chain, q, bends)
    model, data = chain.model, chain.model.createData()
    jid = chain.joint_ids[1]
    u, v = lateral_axes(np.asarray(chain.joints[1].axis))
    for k, row in enumerate(chain.configurations(q)):
        pin.framesForwardKinematics(model, data, row)
        turn = pin.SE3(pin.exp3(bends[k, 2] * u) @ pin.exp3(bends[k, 3] * v), np.zeros(3))
        joint = data.oMi[jid]
        tool = joint * turn * joint.actInv(data.oMf[chain.tip_frame_id]) * pin.SE3(chain.tool)
        assert_close(bent.tool_positions[k], tool.translation, 1e-12, "bent tool position")
        assert_close(bent.tool_rotations[k], tool.rotation, 1e-12, "bent tool rotation")
    straight = bent_tool_poses(chain, q, np.zeros((3, 14)))
    assert_close(straight.tool_positions, chain.tool_poses(q)[1], 1e-12, "no bend: the chain")
    assert len(bend_slots(chain)) == 14


def test_the_residual_and_its_jacobian_with_lateral_compliances(kuka_urdf):
    """The sensor residual with lateral compliances (URDF masses and mass moments) and a joint compliance is the
    plain residual of the bent chain, and its Jacobian matches central differences (every block: the geometry's
    columns are taken at the bent pose)."""
    chain = KinematicChain.from_urdf(kuka_urdf, KUKA_FLANGE_LINK)
    rng = np.random.default_rng(8)
    params = PlacementErrors(chain)
    q = _rows(6, seed=3)
    inputs = _inputs(chain, q)
    moments = ("u/mx:lwr_link_5", "v/my:lwr_link_5", "v/m:lwr_link_6")
    effects = [Effect("lateral", "lwr_joint_2"), Effect("lateral", "lwr_joint_4", moments=moments),
               Effect("encoder_scale", "lwr_joint_3")]
    free = np.arange(params.size)[::4]
    start = TargetEstimate(Registration(pin.exp3(rng.normal(size=3)), rng.normal(size=3)),
                           rng.normal(0, 0.1, (2, 3)), pin.exp3(rng.normal(size=3)))
    rotations = np.stack([pin.exp3(rng.normal(size=3)) for _ in q])
    sensed = rng.normal(size=(6, 2, 3))
    nominal = rng.normal(0, 1e-3, params.size)

    def objective(effects, at, bends=None):
        cache = KinematicsCache(params, free, nominal, at, bends=bends)
        return SensorResidual(cache, sensed, rotations, start, RowWeights(rotation=2.0),
                              effects=ModelledEffects(effects, inputs) if effects else None)

    with_effects = objective(effects, q)
    x = with_effects.start_vector()
    values = [np.array([2e-4, -3e-4]), np.array([0.01, -0.02, 0.005]), np.array([0.01])]
    x[with_effects.blocks["effects"]] = np.concatenate(values)
    bends = bend_angles(effects, values, inputs, chain.joint_names)
    assert np.abs(bends[:, 2:4]).max() > 1e-3 and np.abs(bends[:, 6:8]).max() > 1e-3  # mrad: both bend
    moved = q.copy()
    moved[:, 2] *= 1.01
    plain = objective([], moved, bends)
    assert_close(with_effects.residual(x), plain.residual(x[: plain.n_free]), 1e-12, "bent residual")
    assert_close(with_effects.jacobian(x), numeric_jacobian(with_effects.residual, x), 1e-6, "lateral columns")
    # a candidate's columns (screening), the objective without it: its values' columns at zero bends
    without = objective(effects[2:], q)
    y = x[: without.n_params]
    columns = without.effect_columns(y, effects[:2])
    full = objective(effects[2:] + effects[:2], q).jacobian(np.concatenate([y, np.zeros(5)]))
    assert_close(np.hstack(columns), full[:, without.n_params:], 1e-12, "candidate columns")
    basis = lateral_basis(effects[1], inputs, 3)
    loads = inputs.loads[:, 3]
    assert_close(basis[:, 0, 0], loads[:, 1, inputs.load_names.index("mx:lwr_link_5")], 0.0, "eq L2 about u")
    assert_close(basis[:, 1, 1], loads[:, 2, inputs.load_names.index("my:lwr_link_5")], 0.0, "eq L2 about v")
    assert not basis[:, 1, 0].any() and not basis[:, 0, 1:].any()  # each value loads its own axis


def test_a_lateral_compliance_round_trips_through_the_report():
    effect, values = parse_effect("lateral:lwr_joint_2:2e-4:-3e-4")
    assert effect == Effect("lateral", "lwr_joint_2") and effect.n_values == 2 and effect.label == "lateral:lwr_joint_2"
    entry = effect_to_dict(effect, values, np.array([1e-6, 2e-6]))
    assert entry["value"] == [2e-4, -3e-4] and entry["std"] == [1e-6, 2e-6]
    back, read = effect_from_dict(entry)
    assert back == effect
    np.testing.assert_array_equal(read, values)
    from pincal.report.sections import _effect_value, effect_label

    kinds = {"lwr_joint_2": "revolute"}
    assert _effect_value(entry, kinds)[0] == "u 0.2 ± 0.001 mrad/(N·m), v -0.3 ± 0.002 mrad/(N·m)"  # the HTML's
    assert effect_label(entry).startswith("lateral (bending) compliance of lwr_joint_2")
    massless = Effect("lateral", "lwr_joint_4", moments=("u/mx:lwr_link_5", "v/my:lwr_link_5"))
    back, read = effect_from_dict(effect_to_dict(massless, np.array([0.1, -0.2])))
    assert back == massless and back.label == "lateral:lwr_joint_4:moments"
    np.testing.assert_array_equal(read, [0.1, -0.2])


def _lwr_link_2_massless(urdf, directory):
    """The KUKA with lwr_link_2 (between J2 and J3, which share their origin) massless: at J3 = 0 the moment J3
    carries about its lateral axis v is then minus J2's torque, and a lateral compliance of J3 about v turns the
    chain as a compliance of J2 does."""
    text = re.sub(r'(<link name="lwr_link_2">\s*)<inertial>.*?</inertial>', r"\1", urdf.read_text(encoding="utf-8"),
                  flags=re.S)
    path = directory / "kuka_link_2_massless.urdf"
    path.write_text(text, encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def alike_runs(kuka_urdf, tmp_path_factory):
    """Diagnoses of position rows with J3 held at 0 on :func:`_lwr_link_2_massless`: a true compliance of J2, and
    a true lateral compliance of J3 about v (the same correction on these rows)."""
    chain = KinematicChain.from_urdf(_lwr_link_2_massless(kuka_urdf, tmp_path_factory.mktemp("alike")),
                                     KUKA_FLANGE_LINK)
    sensor = SimulatedSensor(0.02e-3, np.deg2rad(0.02), with_rotation=False)
    runs = {}
    for text in ("compliance:lwr_joint_2:2e-4", "lateral:lwr_joint_3:0:2e-4"):
        rng = np.random.default_rng(4)
        rows = []
        for role, n in (("calibration", 80), ("validation", 30)):
            q = random_configurations(chain, rng, n)
            q[:, 2] = 0.0
            rows.append(measure(chain, q, DEFAULT_REGISTRATION, rng, sensor, role,
                                SimulatedEffects([parse_effect(text)])))
        calibration = calibrate_chain(chain, rows[0], "offsets", ChainFitOptions(tool_known=True))
        runs[text] = diagnose(chain, calibration, rows[0], heldout=rows[1],
                              options=DiagnoseOptions(candidates=candidate_effects(chain, False, lateral=True)))
    return runs


@pytest.mark.parametrize("truth", ["compliance:lwr_joint_2:2e-4", "lateral:lwr_joint_3:0:2e-4"])
def test_a_lateral_and_a_joint_compliance_that_correct_alike_are_both_named(alike_runs, truth):
    """Where the rows cannot tell the two apart, one is taken (the one that predicts the held-out rows best) and
    the other named beside it; either brings the held-out rows to the noise (√3 × 0.02 mm)."""
    diagnosis = alike_runs[truth]
    adopted = [e.label for e, _, _ in diagnosis.effects]
    assert len(adopted) == 1 and adopted[0] in ("compliance:lwr_joint_2", "lateral:lwr_joint_3")
    named = [n for n in diagnosis.notes if "— these poses cannot tell;" in n]  # the alternatives, in words
    assert len(named) == 1 and "lwr_joint_2's error: a compliance" in named[0], diagnosis.notes
    assert "lwr_joint_3's error: a lateral (bending) compliance" in named[0]
    assert diagnosis.heldout_errors.position.rms < 1.2 * np.sqrt(3) * 0.02


@pytest.fixture(scope="module")
def massless_lateral(kuka_urdf, tmp_path_factory):
    """A true lateral compliance of J3 on the URDF's inertias (~7 mm at the tool), diagnosed on the URDF without
    inertias, lateral compliances offered."""
    from test_diagnosis import OFFSETS_ONLY
    from test_mass_moments import SIGMA_MM, _without_inertias

    from pincal.model.dh.table import KUKA_LWR4_DH
    from pincal.simulation.paper import SimulationSettings, simulate_experiment

    bare = _without_inertias(kuka_urdf, tmp_path_factory.mktemp("massless_lateral"))
    chain = KinematicChain.from_urdf(kuka_urdf, KUKA_FLANGE_LINK)
    settings = SimulationSettings(seed=5, sigma_pos_mm=SIGMA_MM, sigma_rot_deg=SIGMA_MM, n_cpa=8, n_calibration=80,
                                  n_validation=30, validation_noise=True)
    experiment = simulate_experiment(chain, KUKA_LWR4_DH, OFFSETS_ONLY, settings,
                                     effects=[parse_effect("lateral:lwr_joint_3:3e-4:2.5e-4")])
    massless = KinematicChain.from_urdf(bare, KUKA_FLANGE_LINK, tool=experiment.tool)
    calibration = calibrate_chain(massless, experiment.calibration, "offsets", ChainFitOptions(tool_known=True))
    return massless, diagnose(massless, calibration, experiment.calibration, heldout=experiment.validation,
                              options=DiagnoseOptions(candidates=candidate_effects(massless, False, lateral=True)))


def test_a_lateral_compliance_without_masses_is_named_and_the_heldout_error_reaches_the_noise(massless_lateral):
    """Its combinations of mass moments about u and v (eq L2), named in words; the floor √3 × 0.02 mm."""
    _, diagnosis = massless_lateral
    (effect, values, _), = diagnosis.effects
    assert effect.label == "lateral:lwr_joint_3:moments" and values.size == effect.n_values > 2
    assert {name[:2] for name in effect.moments} == {"u/", "v/"}
    change = diagnosis.target_changes[0]
    assert 0.005 < change.rms_m < 0.015, change  # the truth moves the tool 5-15 mm
    before, after = diagnosis.steps[0].heldout_before.position.rms, diagnosis.heldout_errors.position.rms
    print(f"held-out RMS {before:.3f} -> {after:.4f} mm, floor {np.sqrt(3) * 0.02:.4f} mm")
    assert before > 2.0 and after < 1.2 * np.sqrt(3) * 0.02, (before, after)
    words = combination_words(effect, diagnosis.inputs, False)
    assert len(words) == effect.n_values and all("/k_u[lwr_joint_3]" in w or "/k_v[lwr_joint_3]" in w for w in words)


def test_effects_yaml_carries_the_lateral_compliances_evaluate_applies(massless_lateral, kuka_urdf, tmp_path):
    """Written to effects.yaml and read back exactly; evaluate's corrections bend the joints as eq L1–L3 say."""
    from pincal.measurements.data import MeasurementSet
    from pincal.report.effects_file import read_effects_file, write_effects_file
    from pincal.workflows.evaluation import _effect_corrections

    chain, diagnosis = massless_lateral
    entries = [effect_to_dict(e, v, s) for e, v, s in diagnosis.effects]
    entries.append(effect_to_dict(Effect("lateral", "lwr_joint_2"), np.array([2e-4, -1e-4]), np.array([1e-6, 1e-6])))
    report = {"chain": {"joints": list(chain.joint_names), "joint_kinds": ["revolute"] * 7},
              "tool": {"parent_link": KUKA_FLANGE_LINK, "points_m": [[0.0, 0.0, 0.0]]}, "effects": entries}
    path = write_effects_file(tmp_path / "corrected.urdf", tmp_path / "REPORT.json", report)
    text = path.read_text(encoding="utf-8")
    assert "side: bend" in text and "lateral axis u" in text
    read = read_effects_file(path)
    assert [e for e, _ in read.effects] == [effect_from_dict(entry)[0] for entry in entries]
    for (_, value), entry in zip(read.effects, entries):
        np.testing.assert_array_equal(value, entry["value"])  # exact
    q = _rows(4, seed=7)
    rows = MeasurementSet(joint_names=tuple(chain.joint_names), q=q, points=np.zeros((4, 1, 3)), rotations=None,
                          roles=np.array(["validation"] * 4, dtype=object), lines=np.arange(2, 6))
    corrections, _ = _effect_corrections(chain, rows, {"effects": entries}, np.zeros((1, 3)),
                                         (np.zeros(4), np.zeros(4)), "REPORT.json")
    inputs = _inputs(chain, q)
    expected = bend_angles([e for e, _ in read.effects], [v for _, v in read.effects], inputs, chain.joint_names)
    assert_close(corrections.bends, expected, 1e-15, "evaluate's bends")
    assert np.abs(corrections.bends[:, 4:6]).max() > 1e-3 and not corrections.bends[:, 2:4].any()  # J3's; J2: no masses
    np.testing.assert_array_equal(corrections.q, q)  # no joint shifts
    massive = KinematicChain.from_urdf(kuka_urdf, KUKA_FLANGE_LINK)  # on the URDF's inertias: c × M (eq L1)
    corrections, _ = _effect_corrections(massive, rows, {"effects": entries[-1:]}, np.zeros((1, 3)),
                                         (np.zeros(4), np.zeros(4)), "REPORT.json")
    assert_close(corrections.bends[:, 2:4], bending_moments(massive, q)[:, 1] * [2e-4, -1e-4], 1e-15, "c × M")
