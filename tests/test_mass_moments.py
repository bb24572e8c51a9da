"""Compliance without a mass model: the gravity loads per mass moment (eq M1–M3 of
:mod:`pincal.model.mass_moments`), the combinations the rows determine, and diagnose on a URDF without inertias.

Simulated KUKA LWR 4+ as in tests/test_diagnosis.py: the truth's compliances load on the URDF's inertias, the
diagnosed URDF has none, so diagnose must find them as mass-moment combinations.
"""

from __future__ import annotations

import re

import numpy as np
import pinocchio as pin
import pytest
from test_diagnosis import OFFSETS_ONLY

from pincal.diagnosis.diagnose import DiagnoseOptions, candidate_effects, diagnose
from pincal.diagnosis.moment_candidates import base_combinations, masses_unknown, moment_compliances
from pincal.fit.chain_calibration import ChainFitOptions, calibrate_chain
from pincal.model.chain import KinematicChain
from pincal.model.dh.table import KUKA_LWR4_DH
from pincal.model.effects import (
    Effect,
    EffectInputs,
    effect_from_dict,
    effect_to_dict,
    gravity_torques,
    joint_shifts,
    parse_effect,
    with_loads,
)
from pincal.model.mass_moments import LOAD_COMPONENTS, chain_mass_kg, gravity_loads, moment_names
from pincal.robots import KUKA_FLANGE_LINK
from pincal.simulation.paper import SimulationSettings, simulate_experiment

#: The truth's compliances [rad/(N·m)] on the URDF's inertias: J2 ~8 mrad and J4 ~4 mrad at most, moving the
#: tool 5–10 mm (measured below).
TRUE_EFFECTS = ("compliance:lwr_joint_2:2e-4", "compliance:lwr_joint_4:3e-4")
SIGMA_MM = 0.02


def _rows(n: int, seed: int = 1) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-2.0, 2.0, (n, 7))


def test_axis_loads_are_pinocchios_gravity_torques_and_the_bending_ones_its_wrench(kuka_chain):
    """Eq M2 with the URDF's inertias is computeGeneralizedGravity; eq M1 (all three moment components) the
    moment RNEA transmits through each joint."""
    q = _rows(5)
    loads = gravity_loads(kuka_chain, q)
    assert loads.shape == (5, 7, len(LOAD_COMPONENTS), 28)
    model = kuka_chain.model
    pi = np.concatenate([model.inertias[j].toDynamicParameters()[:4] for j in kuka_chain.joint_ids])
    g0 = np.linalg.norm(model.gravity.linear)
    np.testing.assert_allclose(loads[:, :, 0, :] @ pi * g0, gravity_torques(kuka_chain, q), atol=1e-10)
    data = model.createData()
    for k, row in enumerate(q):
        pin.forwardKinematics(model, data, row)
        pin.rnea(model, data, row, np.zeros(7), np.zeros(7))
        for i, jid in enumerate(kuka_chain.joint_ids):
            axis = np.asarray(kuka_chain.joints[i].axis)
            moment = data.f[jid].angular
            # (axis, u, v) is an orthonormal frame: the three loads give the whole moment back
            np.testing.assert_allclose(np.linalg.norm(loads[k, i, :, :] @ pi * g0), np.linalg.norm(moment),
                                       atol=1e-9)
            np.testing.assert_allclose(loads[k, i, 0, :] @ pi * g0, axis @ moment, atol=1e-9)


def test_base_combinations_keep_what_the_rows_determine(kuka_chain):
    """J1 (vertical axis) has no load; the last joint's load determines its link's two moments across its
    axis; the kept columns are independent and reproduce the others."""
    q = _rows(60)
    inputs = with_loads(EffectInputs(q=q, gravity=np.zeros_like(q), time=None, order=np.arange(60)), kuka_chain)
    names = moment_names(kuka_chain)
    assert base_combinations(inputs.loads[:, 0, 0, :], names).kept == ()
    last = base_combinations(inputs.loads[:, 6, 0, :], names)
    assert sorted(last.kept) == ["mx:lwr_link_7", "my:lwr_link_7"]
    j2 = base_combinations(inputs.loads[:, 1, 0, :], names)
    kept = inputs.loads[:, 1, 0, [names.index(n) for n in j2.kept]]
    assert np.linalg.matrix_rank(kept) == len(j2.kept) == 12  # two per link it carries (2 to 7): across their axes
    pool, untestable = moment_compliances([Effect("compliance", n) for n in kuka_chain.joint_names]
                                          + [Effect("backlash", "lwr_joint_2", source="gravity")], inputs, kuka_chain)
    assert [e.n_values for e in pool] == [12, 10, 8, 6, 4, 2]
    assert [e.label for e in untestable] == ["compliance:lwr_joint_1", "backlash:lwr_joint_2:gravity"]


def test_a_moment_compliance_round_trips_through_the_report(kuka_chain):
    effect = Effect("compliance", "lwr_joint_7", moments=("mx:lwr_link_7", "my:lwr_link_7"))
    entry = effect_to_dict(effect, np.array([1e-3, -2e-3]), np.array([1e-5, 1e-5]))
    assert entry["moments"] == ["mx:lwr_link_7", "my:lwr_link_7"] and entry["value"] == [1e-3, -2e-3]
    back, values = effect_from_dict(entry)
    assert back == effect and back.n_values == 2 and back.label == "compliance:lwr_joint_7:moments"
    np.testing.assert_array_equal(values, [1e-3, -2e-3])
    from pincal.report.sections import _effect_value

    led = effect_to_dict(Effect("compliance", "lwr_joint_7", moments=("mx:lwr_link_7", "m:lwr_link_7")),
                         np.array([1e-3, 2e-3]), np.array([1e-5, 1e-5]))
    shown, _ = _effect_value(led, dict.fromkeys(kuka_chain.joint_names, "revolute"))  # the HTML report's
    assert shown.count("mrad") == 2 and shown.count("mrad/m") == 1, shown  # a mass-led one: its basis a lever arm
    assert masses_unknown(kuka_chain, "unknown", 0.0) and not masses_unknown(kuka_chain, "urdf", 0.0)
    assert chain_mass_kg(kuka_chain) > 0


def _without_inertias(urdf, tmp_path):
    text = re.sub(r"<inertial>.*?</inertial>", "", urdf.read_text(encoding="utf-8"), flags=re.S)
    path = tmp_path / "no_inertias.urdf"
    path.write_text(text, encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def massless_runs(kuka_urdf, tmp_path_factory):
    """Simulated rows with and without the true compliances, diagnosed on the URDF without inertias."""
    bare = _without_inertias(kuka_urdf, tmp_path_factory.mktemp("massless"))
    chain = KinematicChain.from_urdf(kuka_urdf, KUKA_FLANGE_LINK)
    settings = SimulationSettings(seed=5, sigma_pos_mm=SIGMA_MM, sigma_rot_deg=SIGMA_MM, n_cpa=8, n_calibration=80,
                                  n_validation=30, validation_noise=True)
    runs = {}
    for name, texts in (("with", TRUE_EFFECTS), ("without", ())):
        effects = [parse_effect(t) for t in texts]
        experiment = simulate_experiment(chain, KUKA_LWR4_DH, OFFSETS_ONLY, settings, effects=effects)
        massless = KinematicChain.from_urdf(bare, KUKA_FLANGE_LINK, tool=experiment.tool)
        assert chain_mass_kg(massless) == 0.0
        calibration = calibrate_chain(massless, experiment.calibration, "offsets", ChainFitOptions(tool_known=True))
        runs[name] = diagnose(massless, calibration, experiment.calibration, heldout=experiment.validation,
                              options=DiagnoseOptions(candidates=candidate_effects(massless, False, lateral=True)))
    return runs


def test_without_the_effect_nothing_is_claimed(massless_runs):
    """Nothing, lateral compliances offered too (their mass-moment combinations about u and v)."""
    assert massless_runs["without"].effects == ()


def test_true_compliances_are_named_and_the_heldout_error_reaches_the_noise(massless_runs):
    """The noise floor: the simulated sensor's σ = 0.02 mm per axis, √3 σ = 0.035 mm RMS of a 3D point."""
    diagnosis = massless_runs["with"]
    # lateral compliances offered too: J3's, whose many load patterns a forward step takes for both compliances
    # at once, is dropped once they are adopted (pincal.diagnosis.steps.drop_superseded)
    assert sorted(e.label for e, _, _ in diagnosis.effects) == ["compliance:lwr_joint_2:moments",
                                                                "compliance:lwr_joint_4:moments"]
    before = diagnosis.steps[0].heldout_before.position.rms
    after = diagnosis.heldout_errors.position.rms
    floor = np.sqrt(3) * SIGMA_MM
    print(f"held-out RMS {before:.3f} -> {after:.4f} mm, floor {floor:.4f} mm")
    assert before > 2.0 and after < 1.2 * floor, (before, after, floor)


def test_effects_yaml_carries_what_evaluate_applies(massless_runs, kuka_chain, tmp_path):
    """The adopted effects written to effects.yaml and read back give evaluate's shifts: Σ value × load
    (eq M2) of the moments each names, on any rows."""
    from pincal.report.effects_file import read_effects_file, write_effects_file

    diagnosis = massless_runs["with"]
    entries = [effect_to_dict(e, v, s) for e, v, s in diagnosis.effects]
    report = {"chain": {"joints": list(kuka_chain.joint_names), "joint_kinds": ["revolute"] * 7},
              "tool": {"parent_link": KUKA_FLANGE_LINK, "points_m": [[0.0, 0.0, 0.0]]}, "effects": entries}
    path = write_effects_file(tmp_path / "corrected.urdf", tmp_path / "REPORT.json", report)
    read = read_effects_file(path)
    assert [e for e, _ in read.effects] == [e for e, _, _ in diagnosis.effects]
    q = _rows(4, seed=7)
    inputs = with_loads(EffectInputs(q=q, gravity=np.zeros_like(q), time=None, order=np.arange(4)), kuka_chain)
    shifts = joint_shifts([e for e, _ in read.effects], [v for _, v in read.effects], inputs, kuka_chain.joint_names)
    names = moment_names(kuka_chain)
    expected = np.zeros_like(q)
    for effect, values, _ in diagnosis.effects:
        j = kuka_chain.joint_names.index(effect.joint)
        expected[:, j] += gravity_loads(kuka_chain, q)[:, j, 0, [names.index(n) for n in effect.moments]] @ values
    np.testing.assert_allclose(shifts, expected, atol=1e-15)
    assert np.abs(shifts).max() > 1e-3  # mrad: the shifts are there
    from pincal.measurements.data import MeasurementSet
    from pincal.workflows.evaluation import _effect_corrections

    rows = MeasurementSet(joint_names=tuple(kuka_chain.joint_names), q=q, points=np.zeros((4, 1, 3)), rotations=None,
                          roles=np.array(["validation"] * 4, dtype=object), lines=np.arange(2, 6))
    corrections, _ = _effect_corrections(kuka_chain, rows, {"effects": entries}, np.zeros((1, 3)),
                                         (np.zeros(4), np.zeros(4)), "REPORT.json")
    np.testing.assert_allclose(corrections.q, q + expected, atol=1e-15)  # what evaluate gives the chain
    from pincal.report.sections import _effect_value

    shown, _ = _effect_value(entries[0], dict.fromkeys(kuka_chain.joint_names, "revolute"))  # the HTML report's
    assert shown.count("mrad") == len(entries[0]["moments"]) and "N·m" not in shown


def test_masses_is_checked_once():
    from pincal.errors import PincalError
    from pincal.workflows.settings import DiagnoseSettings

    assert DiagnoseSettings(tip_link="lwr_flange", masses="unknown").masses == "unknown"
    with pytest.raises(PincalError, match="--masses must be one of urdf, unknown"):
        DiagnoseSettings(tip_link="lwr_flange", masses="none")
