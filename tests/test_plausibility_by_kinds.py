"""A compliance or a coupling is judged plausible in its own unit, which follows the kinds of the shifted joint
and of its driver (pincal.diagnosis.verdicts.PLAUSIBLE, pincal.model.effect_units), and the HTML page states a
coupling between a revolute and a prismatic joint in rad/m or m/rad, as the console and effects.yaml do.

TIAGo's chain (example-robot-data): a prismatic torso lift carrying ~19 kg of upper body (up to 188 N of gravity
force in its URDF) under seven revolute arm joints, the shoulder's (arm_2) gravity torque up to 30 N·m; the
lift travels 0.35 m. Each value
below is judged by what it would do on this arm, not by the bound it is tested against:

* rad/(N·m), arm_1 under arm_2's torque: 2e-3 is 0.06 rad at 30 N·m, a joint of 500 N·m/rad
  (harmonic drives: 1e4–1e5); 1e-4 is 3 mrad, a joint of 1e4 N·m/rad.
* m/N, the lift under its own load: 3e-4 m/N is 57 mm at 190 N; 1e-5 m/N is 1.9 mm.
* rad/N, arm_1 under the lift's force: 5e-4 rad/N is 0.095 rad (5.4°) at 190 N; 1e-5 rad/N is 1.9 mrad.
* m/(N·m), the lift under arm_2's torque: 5e-3 m/(N·m) is 150 mm at 30 N·m; 3e-4 m/(N·m) is 9 mm.
* rad/m, arm_1's reading following the lift's: 50 rad/m is 17 rad over the lift's 0.35 m, nearly three turns;
  5 rad/m at the wrist's ~0.1 m lever moves the tool 0.5 m per m of lift, half the lift's own motion.
* m/rad, the lift's reading following arm_1's: 3 m/rad is 3 m of lift per radian; 0.05 m/rad is a 50 mm
  pulley's radius.
* a coupling of like joints stays a ratio: 3 is twice a parallelogram's reading convention (1), 1 is it.
"""

from __future__ import annotations

import html

import numpy as np
import pytest

from pincal.diagnosis.verdicts import Judge
from pincal.model.chain import KinematicChain
from pincal.model.effects import Effect, EffectInputs, gravity_torques
from pincal.report.html import render_html
from pincal.robots import example_robot_data_urdf
from pincal.simulation.sensor import random_configurations

TIAGO = example_robot_data_urdf("tiago_description/robots/tiago.urdf")
TIP = "wrist_ft_tool_link"
OUTSIDE = "outside the physical range"

CASES = [  # (effect, its unit, an implausible value, a plausible value)
    (Effect("compliance", "arm_1_joint", driver="arm_2_joint"), "rad/(N·m)", 2e-3, 1e-4),
    (Effect("compliance", "torso_lift_joint"), "m/N", 3e-4, 1e-5),
    (Effect("compliance", "arm_1_joint", driver="torso_lift_joint"), "rad/N", 5e-4, 1e-5),
    (Effect("compliance", "torso_lift_joint", driver="arm_2_joint"), "m/(N·m)", 5e-3, 3e-4),
    (Effect("coupling", "arm_1_joint", driver="torso_lift_joint"), "rad/m", 50.0, 5.0),
    (Effect("coupling", "torso_lift_joint", driver="arm_1_joint"), "m/rad", 3.0, 0.05),
    (Effect("coupling", "arm_1_joint", driver="arm_2_joint"), "(relative)", 3.0, 1.0),
]


@pytest.fixture(scope="module")
def judge() -> Judge:
    chain = KinematicChain.from_urdf(TIAGO, TIP)
    q = random_configurations(chain, np.random.default_rng(3), 40)
    inputs = EffectInputs(q=q, gravity=gravity_torques(chain, q), time=None, order=np.arange(len(q)),
                          joint_names=chain.joint_names)
    return Judge(inputs, chain, None, None, np.zeros(0))  # type: ignore[arg-type]  # no held-out rows, no fit


@pytest.mark.parametrize(("effect", "unit", "implausible", "plausible"), CASES, ids=[c[1] for c in CASES])
def test_a_value_is_judged_in_the_unit_its_joints_kinds_give(judge, effect, unit, implausible, plausible):
    from pincal.model.effect_units import effect_unit

    assert effect_unit(effect, judge.chain.joint_kinds) == unit

    def verdict(value: float) -> str:
        return judge.judged(effect, np.array([value]), -50.0, [(-50.0, effect, None, None)], [])[0]

    assert OUTSIDE in verdict(implausible)
    assert OUTSIDE not in verdict(plausible), verdict(plausible)


def test_the_page_states_a_coupling_between_kinds_in_its_unit():
    """A revolute joint following the lift's reading: rad/m on the page, as on the console; like joints: × a reading."""
    kinds = {"torso_lift_joint": "prismatic", "arm_1_joint": "revolute", "arm_2_joint": "revolute"}
    across = {"type": "coupling", "joint": "arm_1_joint", "driver": "torso_lift_joint", "value": 0.3, "std": 0.01}
    like = {"type": "coupling", "joint": "arm_1_joint", "driver": "arm_2_joint", "value": 0.02, "std": 0.001}
    for entry, shown, not_shown in ((across, "0.3 ± 0.01 rad/m", "× torso_lift_joint's reading"),
                                    (like, "0.02 ± 0.001 × arm_2_joint's reading", "rad/")):
        report = {"chain": {"joints": list(kinds), "joint_kinds": list(kinds.values())}, "effects": [entry],
                  "diagnosis": {"steps": [{"effect": entry}], "last_candidates": [{**entry, "delta_bic": -50.0}]}}
        page = html.unescape(render_html(report))
        assert page.count(shown) == 3 and not_shown not in page  # the final model, the step, the candidate
