"""``pincal plan``'s collision check by default and the joint ranges it says it sampled.

UR5 (collision meshes): the candidates in self-collision are refused by default — the same ones as
``--min-distance 0``, each with two links intersecting (checked pair by pair with coal through
Pinocchio), the kept ones with none —, ``--no-collision-check`` keeps them all, and it is refused
beside ``--min-distance``. KUKA (no ``<collision>``): a note says the candidates are not checked. TALOS: its SRDF's
pairs replace those in contact at zero, where its grippers sit inside its thighs.
PLAN.json and the console say each joint's range and where it comes from.
"""

from __future__ import annotations

import json
import shutil

import numpy as np
import pinocchio as pin
import pytest

from pincal.cli.commands import main
from pincal.errors import ModelError, PincalError
from pincal.model import packages
from pincal.model.chain import KinematicChain
from pincal.model.tree import KinematicTree, parse_targets
from pincal.planning.candidates import joint_ranges, sample_candidates
from pincal.planning.collisions import _disable_srdf_pairs, _geometry, check_clearance
from pincal.robots import KUKA_FLANGE_LINK, example_robot_data_dir, example_robot_data_urdf, kuka_lwr4plus_urdf
from pincal.workflows.preparation import PlanInputs

UR5 = example_robot_data_urdf("ur_description/urdf/ur5_robot.urdf")
UR5_SRDF = example_robot_data_dir() / "ur_description" / "srdf" / "ur5.srdf"
TALOS = example_robot_data_urdf("talos_data/robots/talos_full_v2.urdf")
TALOS_SRDF = example_robot_data_dir() / "talos_data" / "srdf" / "talos.srdf"
SAMPLE = 120


def _plan(tmp_path, name, urdf, tip, *flags):
    out = tmp_path / name
    code = main(["plan", str(urdf), "--tip-link", tip, "--count", "8", "--sample", str(SAMPLE), "--measure", "pose",
                 "--quiet", "--out", str(out / "PLAN.csv"), "--report", str(out / "PLAN.json"), *flags])
    return code, (json.loads((out / "PLAN.json").read_text()) if code == 0 else None)


@pytest.fixture(scope="module")
def ur5_runs(tmp_path_factory):
    """The UR5 planned by default, with --min-distance 0 and with --no-collision-check (same seed)."""
    tmp = tmp_path_factory.mktemp("ur5")
    return {name: _plan(tmp, name, UR5, "tool0", *flags)
            for name, flags in (("default", ()), ("zero", ("--min-distance", "0")),
                                ("off", ("--no-collision-check",)))}


def test_self_collision_is_refused_by_default_as_with_a_zero_clearance(ur5_runs):
    (code, default), (zero_code, zero), (off_code, off) = ur5_runs["default"], ur5_runs["zero"], ur5_runs["off"]
    assert (code, zero_code, off_code) == (0, 0, 0)
    checked = default["candidates"]
    assert checked["collision_check"] == "self-collision" and zero["candidates"]["collision_check"] == "min-distance"
    assert 0 < checked["clearance"]["refused"] == checked["clearance"]["refused_in_collision"] < SAMPLE
    assert checked["usable"] == SAMPLE - checked["clearance"]["refused"]
    assert {k: v for k, v in checked.items() if k != "collision_check"} == \
        {k: v for k, v in zero["candidates"].items() if k != "collision_check"}
    assert off["candidates"]["clearance"] is None and off["candidates"]["collision_check"] == "off"
    assert off["candidates"]["usable"] == SAMPLE
    # the pairs that touch at the zero configuration (adjacent links) are ignored, not counted as collisions
    assert checked["clearance"]["pairs_ignored_at_zero"] == [
        "upper_arm_link_0~forearm_link_0", "forearm_link_0~wrist_1_link_0", "wrist_2_link_0~wrist_3_link_0"]


def test_refused_candidates_have_two_links_intersecting_and_kept_ones_none():
    """Each pair of links checked alone (coal's collision test through Pinocchio, no margin): a refused
    candidate has an intersecting pair among those not in contact at zero, a kept one has none."""
    chain = KinematicChain.from_urdf(UR5, "tool0")
    q = sample_candidates(chain, 60, seed=4)
    clearance = check_clearance(UR5, chain, q, 0.0)
    model, geometry = _geometry(UR5, chain)
    geometry.addAllCollisionPairs()
    names = [o.name for o in geometry.geometryObjects]
    pairs = [i for i, p in enumerate(geometry.collisionPairs)
             if f"{names[p.first]}~{names[p.second]}" not in clearance.pairs_ignored]
    data, geometry_data = model.createData(), geometry.createData()
    intersecting = []
    for configuration in chain.configurations(q):
        pin.updateGeometryPlacements(model, data, geometry, geometry_data, configuration)
        intersecting.append(any(pin.computeCollision(geometry, geometry_data, i) for i in pairs))
    assert 0 < clearance.in_collision < len(q) and clearance.too_close == 0
    assert np.array_equal(~clearance.allowed, np.array(intersecting))


def test_links_touching_at_zero_are_ignored_even_a_few_nanometres_apart():
    """Kinova: coal puts its base and link 1 6e-9 m apart at zero, yet in collision at every configuration;
    the pair is in contact at zero by the collision test, so it is ignored and not every candidate refused."""
    urdf = example_robot_data_urdf("kinova_description/robots/kinova.urdf")
    chain = KinematicChain.from_urdf(urdf, "j2s6s200_end_effector")
    clearance = check_clearance(urdf, chain, sample_candidates(chain, 40, seed=1), 0.0)
    assert "j2s6s200_link_base_0~j2s6s200_link_1_0" in clearance.pairs_ignored
    assert 0 <= clearance.in_collision < 20


def test_a_urdf_without_collision_geometry_is_planned_with_a_note(tmp_path, capsys):
    code, doc = _plan(tmp_path, "kuka", kuka_lwr4plus_urdf(), KUKA_FLANGE_LINK)
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert doc["candidates"]["collision_check"] == "no collision geometry" and doc["candidates"]["clearance"] is None
    notes = [line for line in captured.err.splitlines() if "no <collision> geometry" in line]
    assert len(notes) == 1 and "not checked for self-collision" in notes[0]
    # an SRDF has nothing to serve: said, not silently dropped
    code, _ = _plan(tmp_path, "kuka-srdf", kuka_lwr4plus_urdf(), KUKA_FLANGE_LINK, "--srdf", str(UR5_SRDF))
    assert code == 0 and f"--srdf {UR5_SRDF} is not used" in capsys.readouterr().err
    # asked for explicitly, the clearance cannot be checked: an error, as before
    code, _ = _plan(tmp_path, "kuka-clearance", kuka_lwr4plus_urdf(), KUKA_FLANGE_LINK, "--min-distance", "0.01")
    assert code == 2 and "no <collision> geometry" in capsys.readouterr().err


def test_meshes_not_found_for_the_default_check_say_how_to_plan_without_it(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    monkeypatch.delenv("AMENT_PREFIX_PATH", raising=False)
    monkeypatch.setattr(packages, "installed_prefixes", list)  # nor where pip installed example-robot-data
    urdf = tmp_path / "ur5.urdf"  # away from its package: its package:// meshes are found nowhere
    shutil.copy(UR5, urdf)
    code, _ = _plan(tmp_path, "lost", urdf, "tool0")
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1
    assert "collision mesh" in err and "--package-dir" in err and "or plan --no-collision-check" in err
    code, doc = _plan(tmp_path, "unchecked", urdf, "tool0", "--no-collision-check")
    assert code == 0 and doc["candidates"]["collision_check"] == "off"


def test_no_collision_check_and_min_distance_are_refused_together(tmp_path, capsys):
    with pytest.raises(SystemExit) as caught:
        _plan(tmp_path, "both", UR5, "tool0", "--no-collision-check", "--min-distance", "0.01")
    assert caught.value.code == 2
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert "--min-distance" in last and "--no-collision-check" in last
    with pytest.raises(PincalError, match="give one of them"):
        PlanInputs(min_distance_m=0.01, collision_check=False)
    assert PlanInputs(min_distance_m=0.01).check == "min-distance" and PlanInputs().check == "self-collision"


def test_the_sampled_ranges_are_said_and_recorded(ur5_runs, tmp_path, capsys):
    """UR5: ±360° from the URDF (a note says more than one turn); a candidate file: the span of its rows."""
    ranges = ur5_runs["off"][1]["candidates"]["joint_ranges"]
    assert [r["joint"] for r in ranges][:2] == ["shoulder_pan_joint", "shoulder_lift_joint"]
    assert ranges[0] == {"joint": "shoulder_pan_joint", "kind": "revolute", "unit": "deg",
                         "lower": pytest.approx(-360.0), "upper": pytest.approx(360.0), "source": "URDF limits"}
    assert ranges[2]["lower"] == pytest.approx(-180.0) and ranges[2]["upper"] == pytest.approx(180.0)
    candidates = tmp_path / "candidates.csv"
    rows = np.array([[0.1, -1.0, 0.5, 0.0, 0.2, 0.0], [0.3, -1.5, 1.0, -0.5, 0.2, 0.1]] * 4)
    header = "shoulder_pan_joint,shoulder_lift_joint,elbow_joint,wrist_1_joint,wrist_2_joint,wrist_3_joint"
    candidates.write_text(header + "\n" + "\n".join(",".join(map(str, r)) for r in rows) + "\n")
    out = tmp_path / "file"
    code = main(["plan", str(UR5), "--tip-link", "tool0", "--count", "8", "--measure", "pose", "--level", "offsets",
                 "--candidates", str(candidates), "--no-collision-check", "--out", str(out / "PLAN.csv"),
                 "--report", str(out / "PLAN.json")])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    spans = json.loads((out / "PLAN.json").read_text())["candidates"]["joint_ranges"]
    assert {r["source"] for r in spans} == {"candidate file"}
    assert spans[1]["lower"] == pytest.approx(-np.degrees(1.5)) and spans[1]["upper"] == pytest.approx(-np.degrees(1.0))
    assert "read from the file, spanning:" in captured.out and "wider than one turn" not in captured.err
    # the elbow read against the shoulder: the span is still the file's (the readings, as PLAN.csv holds them)
    code = main(["plan", str(UR5), "--tip-link", "tool0", "--count", "8", "--measure", "pose", "--level", "offsets",
                 "--candidates", str(candidates), "--no-collision-check", "--coupling",
                 "elbow_joint=-1*shoulder_lift_joint", "--out", str(out / "c.csv"), "--report", str(out / "c.json")])
    assert code == 0, capsys.readouterr().err
    coupled = json.loads((out / "c.json").read_text())["candidates"]["joint_ranges"]
    assert coupled[2]["lower"] == pytest.approx(np.degrees(0.5)) and coupled[2]["upper"] == pytest.approx(np.degrees(1.0))
    out = tmp_path / "drawn"
    code = main(["plan", str(UR5), "--tip-link", "tool0", "--count", "8", "--measure", "pose", "--level", "offsets",
                 "--sample", "60", "--no-collision-check", "--out", str(out / "PLAN.csv"),
                 "--report", str(out / "PLAN.json")])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "drawn uniformly (seed 0) within:" in captured.out and "(URDF limits)" in captured.out
    assert "not checked for self-collision (--no-collision-check)" in captured.out
    note = [line for line in captured.err.splitlines() if "wider than one turn" in line]
    assert len(note) == 1 and "shoulder_pan_joint, shoulder_lift_joint, wrist_1_joint" in note[0], captured.err
    assert "elbow_joint" not in note[0] and "up to 720 deg" in note[0]


def test_the_plan_page_says_how_the_candidates_were_checked_and_drawn(ur5_runs, tmp_path):
    """``pincal report PLAN.json``: its facts name the collision check and each joint's range."""
    document = tmp_path / "PLAN.json"
    document.write_text(json.dumps(ur5_runs["default"][1]))
    assert main(["report", str(document), "--out", str(tmp_path / "PLAN.html")]) == 0
    page = (tmp_path / "PLAN.html").read_text()
    assert "<dt>collision check</dt><dd>self-collision</dd>" in page
    assert "shoulder_pan_joint -360 to 360 deg" in page and "(URDF limits)" in page


def test_continuous_joints_are_drawn_over_one_turn():
    chain = KinematicChain.from_urdf(example_robot_data_urdf("kinova_description/robots/kinova.urdf"),
                                     "j2s6s200_end_effector")
    ranges = joint_ranges(chain)
    assert [r.source for r in ranges if r.kind == "continuous"] == ["continuous: one turn"] * 3
    assert all((r.lower, r.upper) == (-180.0, 180.0) for r in ranges if r.kind == "continuous")
    assert {r.source for r in ranges if r.kind == "revolute"} == {"URDF limits"}


def test_geometry_on_one_link_only_is_said_to_check_nothing(tmp_path, capsys):
    """A URDF whose only <collision> is on the base: the check runs on no pair, and a note says so rather
    than reporting a self-collision check that could refuse nothing."""
    from lxml import etree

    root = etree.parse(str(UR5)).getroot()
    for element in list(root.iter("collision")):
        element.getparent().remove(element)
    base = root.find("link[@name='base_link']")
    etree.SubElement(etree.SubElement(etree.SubElement(base, "collision"), "geometry"), "box", size="0.1 0.1 0.1")
    urdf = tmp_path / "ur5_base_only.urdf"
    urdf.write_bytes(etree.tostring(root))
    code, doc = _plan(tmp_path, "base-only", urdf, "tool0")
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert doc["candidates"]["collision_check"] == "self-collision"
    assert doc["candidates"]["clearance"]["pairs_checked"] == 0
    notes = [line for line in captured.err.splitlines() if "in effect not checked for collision" in line]
    assert len(notes) == 1 and "ur5_base_only.urdf" in notes[0]
    assert notes[0].removeprefix("pincal: note: ") in doc["notes"]  # PLAN.json keeps what the console said
    # with geometry on the moving links (the UR5 itself) no such note
    code, _ = _plan(tmp_path, "ur5", UR5, "tool0")
    assert code == 0 and "in effect not checked" not in capsys.readouterr().err


def _talos_arms():
    return KinematicTree.from_urdf(TALOS, parse_targets(["gripper_left_fingertip_1_link:1",
                                                         "gripper_right_fingertip_1_link:2"]))


def test_talos_srdf_checks_the_grippers_against_the_thighs_that_touch_at_zero():
    """At TALOS's zero configuration (arms down) its grippers' meshes intersect its thighs: the zero rule ignores
    those pairs — and so would let a gripper into a thigh in any posture — and names them as not adjacent. With
    the robot's SRDF (example-robot-data's talos.srdf), its disabled pairs are the ones skipped, and the zero
    configuration is refused; the arms abducted by 0.6 rad (34°) away from the legs are free either way."""
    tree = _talos_arms()
    zero = np.clip(np.zeros(tree.n_joints), [j.lower for j in tree.joints], [j.upper for j in tree.joints])
    abducted = zero.copy()
    abducted[[tree.joint_names.index("arm_left_2_joint"), tree.joint_names.index("arm_right_2_joint")]] = 0.6, -0.6
    q = np.stack([zero, abducted])
    default = check_clearance(TALOS, tree, q, 0.0)
    assert default.allowed.tolist() == [True, True] and default.srdf is None
    assert {"leg_left_3_link_0~gripper_left_base_link_0", "leg_right_3_link_0~gripper_right_base_link_0"} <= \
        set(default.unrelated_ignored) <= set(default.pairs_ignored)
    srdf = check_clearance(TALOS, tree, q, 0.0, srdf=TALOS_SRDF)
    assert srdf.allowed.tolist() == [False, True] and srdf.in_collision == 1
    assert srdf.pairs_ignored == () and srdf.unrelated_ignored == () and srdf.pairs_disabled > 0
    assert default.unrelated_note().startswith(f"{len(default.unrelated_ignored)} pair(s) of links more than 3 joints")
    assert default.unrelated_note().endswith("give the robot's SRDF with --srdf to check them")
    assert srdf.unrelated_note() == ""
    # which pairs: an adjacent pair of the SRDF is not checked, a thigh and a gripper are, and so is a pair the
    # SRDF disables as "Never" in collision (its forearm and wrist sensor, which intersect in some postures)
    model, geometry = _geometry(TALOS, tree)
    geometry.addAllCollisionPairs()
    assert _disable_srdf_pairs(model, geometry, TALOS_SRDF) == srdf.srdf_never_checked > 0
    names = [o.name for o in geometry.geometryObjects]
    checked = {frozenset((names[p.first], names[p.second])) for p in geometry.collisionPairs}
    assert frozenset(("arm_left_1_link_0", "arm_left_2_link_0")) not in checked
    assert frozenset(("leg_left_3_link_0", "gripper_left_base_link_0")) in checked
    assert frozenset(("arm_left_5_link_0", "wrist_left_ft_link_0")) in checked
    assert srdf.as_dict()["srdf"] == {"file": str(TALOS_SRDF), "pairs_disabled": srdf.pairs_disabled,
                                      "never_pairs_checked": srdf.srdf_never_checked}
    assert "srdf" not in default.as_dict()


@pytest.mark.parametrize("text, message", [
    (None, "cannot read the SRDF"),
    ("DIR", "cannot read the SRDF"),
    ("<robot name='ur5'><group name='arm'/>", "cannot read the SRDF"),
    ("<robot name='ur5'><group name='arm'/></robot>", "no <disable_collisions> pair"),
    ("TALOS", "disables no pair of this URDF's moving links .* not in the URDF"),
    ("<robot name='ur5'><disable_collisions link1='base_link' link2='shoulder_link' reason='Never'/></robot>",
     "disables no pair of this URDF's moving links .its 1 pairs are all 'Never'"),
])
def test_an_srdf_that_cannot_serve_is_one_line_naming_it(tmp_path, text, message):
    """A missing or malformed file, one without pairs, another robot's (TALOS's for a UR5): a ModelError
    naming the file, never a check that silently skips nothing."""
    chain = KinematicChain.from_urdf(UR5, "tool0")
    path = TALOS_SRDF if text == "TALOS" else tmp_path if text == "DIR" else tmp_path / "robot.srdf"
    if text not in (None, "TALOS", "DIR"):
        path.write_text(text, encoding="utf-8")
    with pytest.raises(ModelError, match=message) as caught:
        check_clearance(UR5, chain, sample_candidates(chain, 2, seed=1), 0.0, srdf=path)
    assert str(path) in str(caught.value) and "\n" not in str(caught.value)


def test_plan_srdf_is_printed_recorded_and_refused_beside_no_collision_check(tmp_path, capsys):
    """UR5 with its SRDF (example-robot-data's ur5.srdf): the console says how many pairs it disabled and
    PLAN.json records the file; with --no-collision-check it is one line and exit 2; without the SRDF the UR5's
    pairs in contact at zero are all adjacent, so no note."""
    code, doc = _plan(tmp_path, "srdf", UR5, "tool0", "--srdf", str(UR5_SRDF))
    captured = capsys.readouterr()
    assert code == 0, captured.err
    clearance = doc["candidates"]["clearance"]
    assert clearance["srdf"]["file"] == str(UR5_SRDF) and clearance["srdf"]["pairs_disabled"] > 0
    assert clearance["pairs_ignored_at_zero"] == []
    assert f"{clearance['srdf']['pairs_disabled']} disabled by ur5.srdf)" in captured.out  # no 'Never' pair in it
    code, _ = _plan(tmp_path, "both", UR5, "tool0", "--srdf", str(UR5_SRDF), "--no-collision-check")
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "--srdf" in err and "--no-collision-check" in err
    code, _ = _plan(tmp_path, "clearance", UR5, "tool0", "--srdf", str(UR5_SRDF), "--min-distance", "0.02")
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "--srdf" in err and "--min-distance" in err
    code, _ = _plan(tmp_path, "plain", UR5, "tool0")
    assert code == 0 and "--srdf" not in capsys.readouterr().err


@pytest.mark.parametrize("relative, tip", [("panda_description/urdf/panda.urdf", "panda_link8"),
                                           ("kinova_description/robots/kinova.urdf", "j2s6s200_end_effector")])
def test_one_arms_wrist_links_touching_at_zero_are_not_named(relative, tip):
    """A Panda's links 5 and 7 (two joints apart) and a Kinova's links 3 and 6 (three) touch at zero by design:
    one wrist, not separate limbs, so no pair is named for the SRDF note (TALOS's thigh and gripper are, above)."""
    urdf = example_robot_data_urdf(relative)
    chain = KinematicChain.from_urdf(urdf, tip)
    clearance = check_clearance(urdf, chain, sample_candidates(chain, 2, seed=1), 0.0)
    assert clearance.pairs_ignored and clearance.unrelated_ignored == ()


def test_a_pair_listed_never_and_adjacent_is_disabled_and_not_counted_as_checked(tmp_path):
    """An SRDF listing one pair twice, "Adjacent" and "Never": disabled (a reason pincal honours), and not among the
    "Never" pairs counted as checked; a "Never" pair of its own is checked and counted."""
    chain = KinematicChain.from_urdf(UR5, "tool0")
    srdf = tmp_path / "ur5.srdf"
    srdf.write_text("<robot name='ur5'>"
                    "<disable_collisions link1='base_link' link2='shoulder_link' reason='Adjacent'/>"
                    "<disable_collisions link1='shoulder_link' link2='base_link' reason='Never'/>"
                    "<disable_collisions link1='upper_arm_link' link2='wrist_3_link' reason='Never'/></robot>",
                    encoding="utf-8")
    model, geometry = _geometry(UR5, chain)
    geometry.addAllCollisionPairs()
    assert _disable_srdf_pairs(model, geometry, srdf) == 1
    names = [o.name for o in geometry.geometryObjects]
    checked = {frozenset((names[p.first], names[p.second])) for p in geometry.collisionPairs}
    assert frozenset(("base_link_0", "shoulder_link_0")) not in checked
    assert frozenset(("upper_arm_link_0", "wrist_3_link_0")) in checked
