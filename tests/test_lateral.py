"""Lateral (bending) compliance: a joint that turns about the two axes orthogonal to its own under the gravity
moment it carries (eq L1–L3 of :mod:`pincal.model.lateral`): its moments, its exact Jacobian, its report entry."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from conftest import assert_close, numeric_jacobian

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
    massless = Effect("lateral", "lwr_joint_4", moments=("u/mx:lwr_link_5", "v/my:lwr_link_5"))
    back, read = effect_from_dict(effect_to_dict(massless, np.array([0.1, -0.2])))
    assert back == massless and back.label == "lateral:lwr_joint_4:moments"
    np.testing.assert_array_equal(read, [0.1, -0.2])
