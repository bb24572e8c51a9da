"""URDF origin I/O, the DH <-> URDF adapter and the packaged KUKA LWR 4+ URDF."""

from __future__ import annotations

import collections
import importlib.metadata
import importlib.util
import tempfile
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from lxml import etree

from pincal.errors import ModelError
from pincal.model.dh.table import (
    KUKA_LWR4_DH,
    TABLE2_LARGE,
    TABLE2_SMALL,
    DHTable,
    random_deviations_like,
)
from pincal.model.dh.urdf import apply_dh_table, dh_table_from_urdf
from pincal.model.urdf import (
    read_joint_origins,
    rpy_from_matrix,
    rpy_matrix,
    write_urdf_with_origins,
)
from pincal.robots import (
    KUKA_BASE_LINK,
    KUKA_FLANGE_JOINT,
    KUKA_FLANGE_LINK,
    KUKA_JOINTS,
    KUKA_LINKS,
    example_robot_data_urdf,
    kuka_lwr4plus_urdf,
)

REPO_ROOT = Path(__file__).resolve().parents[1]
HYPOTHESIS = settings(
    max_examples=25,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow],
)
ERD_ROBOTS = {
    "tiago": "tiago_description/robots/tiago.urdf",
    "panda": "panda_description/urdf/panda.urdf",
    "ur5": "ur_description/urdf/ur5_robot.urdf",
}


# ------------------------------------------------------------------ helpers


def flange_pose(urdf: Path, theta: np.ndarray) -> np.ndarray:
    """Pinocchio pose of lwr_flange in the root link for encoder angles ``theta``."""
    model = pin.buildModelFromUrdf(str(urdf))
    data = model.createData()
    q = np.zeros(model.nq)
    for name, value in zip(KUKA_JOINTS, theta):
        q[model.joints[model.getJointId(name)].idx_q] = value
    pin.framesForwardKinematics(model, data, q)
    return data.oMf[model.getFrameId(KUKA_FLANGE_LINK)].homogeneous


def random_rigid(rng: np.random.Generator, gimbal: bool = False) -> np.ndarray:
    T = np.eye(4)
    if gimbal:
        pitch = rng.choice([-1.0, 1.0]) * np.pi / 2 + rng.normal() * 10.0 ** rng.uniform(-16, -3)
        T[:3, :3] = pin.rpy.rpyToMatrix(rng.uniform(-np.pi, np.pi), pitch, rng.uniform(-np.pi, np.pi))
    else:
        T[:3, :3] = pin.exp3(rng.normal(size=3) * 2.0)
    T[:3, 3] = rng.normal(size=3) * 0.3
    return T


def assert_same_table(a: DHTable, b: DHTable, tol: float = 1e-12) -> None:
    for field in ("alpha", "epsilon"):
        diff = np.angle(np.exp(1j * (getattr(a, field) - getattr(b, field))))
        assert np.max(np.abs(diff)) <= tol, field
    for field in ("r", "d"):
        assert np.max(np.abs(getattr(a, field) - getattr(b, field))) <= tol, field


def check_fk(table: DHTable, workdir: Path, seed: int) -> None:
    out = workdir / "dh.urdf"
    apply_dh_table(kuka_lwr4plus_urdf(), out, table, KUKA_JOINTS, KUKA_FLANGE_JOINT)
    rng = np.random.default_rng(seed)
    for theta in rng.uniform(-np.pi, np.pi, size=(5, 7)):
        err = np.max(np.abs(flange_pose(out, theta) - table.forward(theta)))
        assert err <= 1e-12, err
    assert_same_table(dh_table_from_urdf(out, KUKA_JOINTS, KUKA_FLANGE_JOINT), table)
    assert_same_table(dh_table_from_urdf(out, KUKA_JOINTS, KUKA_FLANGE_JOINT, reference=table), table)


def flatten_xml(path: Path) -> dict:
    """Every element of a URDF keyed by its position (names for links/joints), values parsed."""

    def norm(value: str):
        try:
            return tuple(float(x) for x in value.split())
        except ValueError:
            return value

    root = etree.parse(str(path), etree.XMLParser(remove_comments=True, remove_blank_text=True)).getroot()
    out = {}

    def walk(element, prefix):
        counts = collections.Counter()
        for child in element:
            if not isinstance(child.tag, str):
                continue
            key = child.get("name") if child.tag in ("link", "joint") else None
            if key is None:
                key = counts[child.tag]
                counts[child.tag] += 1
            path_key = prefix + ((child.tag, key),)
            out[path_key] = ({k: norm(v) for k, v in child.attrib.items()}, (child.text or "").strip())
            walk(child, path_key)

    walk(root, ())
    return out


def load_generator():
    spec = importlib.util.spec_from_file_location(
        "generate_kuka_urdf", REPO_ROOT / "scripts" / "generate_kuka_urdf.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


# ------------------------------------------------------------------ DH <-> URDF


@pytest.mark.parametrize(
    "table",
    [KUKA_LWR4_DH, TABLE2_SMALL.apply(KUKA_LWR4_DH), TABLE2_LARGE.apply(KUKA_LWR4_DH)],
    ids=["table1", "table2-small", "table2-large"],
)
def test_fk_of_adapter_urdf_matches_dh(table, tmp_path):
    check_fk(table, tmp_path, seed=11)


@HYPOTHESIS
@given(seed=st.integers(0, 2**32 - 1), large=st.booleans())
def test_fk_matches_dh_random_deviations_like_table2(seed, large):
    reference = TABLE2_LARGE if large else TABLE2_SMALL
    table = random_deviations_like(reference, np.random.default_rng(seed)).apply(KUKA_LWR4_DH)
    with tempfile.TemporaryDirectory() as tmp:
        check_fk(table, Path(tmp), seed=seed % 1000)


@HYPOTHESIS
@given(
    angles=st.lists(st.floats(-np.pi, np.pi), min_size=14, max_size=14),
    lengths=st.lists(st.floats(-0.5, 0.5), min_size=14, max_size=14),
)
def test_fk_matches_dh_arbitrary_tables(angles, lengths):
    """Any table, including exact and near gimbal-lock origins."""
    table = DHTable(alpha=angles[:7], epsilon=angles[7:], r=lengths[:7], d=lengths[7:])
    with tempfile.TemporaryDirectory() as tmp:
        check_fk(table, Path(tmp), seed=3)


def test_dh_table_from_urdf_rejects_non_dh_origin(tmp_path):
    bad = KUKA_LWR4_DH.joint_origins()[3].copy()
    bad[1, 3] = 0.01  # DH rows have no y translation
    out = tmp_path / "bad.urdf"
    write_urdf_with_origins(kuka_lwr4plus_urdf(), out, {"lwr_joint_4": bad})
    with pytest.raises(ModelError, match="lwr_joint_4"):
        dh_table_from_urdf(out, KUKA_JOINTS, KUKA_FLANGE_JOINT)


def test_dh_table_from_urdf_checks_chain_and_names(tmp_path):
    with pytest.raises(ModelError, match="lwr_joint_9"):
        dh_table_from_urdf(kuka_lwr4plus_urdf(), KUKA_JOINTS[:6] + ("lwr_joint_9",), KUKA_FLANGE_JOINT)
    with pytest.raises(ModelError, match="does not follow"):
        dh_table_from_urdf(kuka_lwr4plus_urdf(), tuple(reversed(KUKA_JOINTS)), KUKA_FLANGE_JOINT)


# ------------------------------------------------------------------ origins


def test_write_read_origins_exact(tmp_path):
    rng = np.random.default_rng(5)
    origins = {name: random_rigid(rng, gimbal=i % 2 == 1) for i, name in enumerate(KUKA_JOINTS)}
    origins[KUKA_FLANGE_JOINT] = random_rigid(rng, gimbal=True)
    out = tmp_path / "o.urdf"
    write_urdf_with_origins(kuka_lwr4plus_urdf(), out, origins)
    back = read_joint_origins(out)
    assert set(back) == set(KUKA_JOINTS) | {KUKA_FLANGE_JOINT}
    for name, matrix in origins.items():
        assert np.max(np.abs(back[name] - matrix)) <= 1e-14, name
    model = pin.buildModelFromUrdf(str(out))
    for name in KUKA_JOINTS:
        placement = model.jointPlacements[model.getJointId(name)].homogeneous
        assert np.max(np.abs(placement - origins[name])) <= 1e-14, name


@HYPOTHESIS
@given(seed=st.integers(0, 2**32 - 1))
def test_rpy_from_matrix_round_trip(seed):
    rng = np.random.default_rng(seed)
    for gimbal in (False, True):
        R = random_rigid(rng, gimbal=gimbal)[:3, :3]
        rpy = np.array([float(repr(float(v))) for v in rpy_from_matrix(R)])
        assert np.max(np.abs(rpy_matrix(rpy) - R)) <= 1e-14
        assert np.max(np.abs(pin.rpy.rpyToMatrix(*rpy) - R)) <= 1e-14


def test_refuses_to_overwrite_source(tmp_path):
    src = tmp_path / "robot.urdf"
    src.write_bytes(kuka_lwr4plus_urdf().read_bytes())
    before = src.read_bytes()
    for destination in (src, tmp_path / "sub" / ".." / "robot.urdf", str(src)):
        (tmp_path / "sub").mkdir(exist_ok=True)
        with pytest.raises(ModelError, match="never overwrite the input"):
            write_urdf_with_origins(src, destination, {})
    link = tmp_path / "link.urdf"
    link.symlink_to(src)
    with pytest.raises(ModelError, match="never overwrite the input"):
        write_urdf_with_origins(src, link, {})
    with pytest.raises(ModelError, match="never overwrite the input"):
        apply_dh_table(src, src, KUKA_LWR4_DH, KUKA_JOINTS, KUKA_FLANGE_JOINT)
    assert src.read_bytes() == before


def test_unknown_joint_lists_existing_joints(tmp_path):
    with pytest.raises(ModelError) as info:
        write_urdf_with_origins(kuka_lwr4plus_urdf(), tmp_path / "o.urdf", {"elbow": np.eye(4)})
    message = str(info.value)
    assert "'elbow'" in message and "\n" not in message
    for name in KUKA_JOINTS + (KUKA_FLANGE_JOINT,):
        assert name in message
    assert not (tmp_path / "o.urdf").exists()


@pytest.mark.parametrize(
    "matrix, reason",
    [
        (np.diag([1.0, 1.0, -1.0, 1.0]), "reflection"),
        (np.diag([1.1, 1.0, 1.0, 1.0]), "orthonormal"),
        (np.vstack([np.eye(4)[:3], [0.0, 0.0, 1.0, 1.0]]), "last row"),
        (np.full((4, 4), np.nan), "non-finite"),
        (np.eye(3), "4x4"),
    ],
)
def test_rejects_improper_origin(tmp_path, matrix, reason):
    with pytest.raises(ModelError, match=reason) as info:
        write_urdf_with_origins(kuka_lwr4plus_urdf(), tmp_path / "o.urdf", {"lwr_joint_2": matrix})
    assert "lwr_joint_2" in str(info.value) and "\n" not in str(info.value)


def test_comment_is_written_near_the_top(tmp_path):
    out = tmp_path / "o.urdf"
    write_urdf_with_origins(kuka_lwr4plus_urdf(), out, {}, comment="calibrated by pincal -- run 7")
    text = out.read_text()
    assert text.index("calibrated by pincal - - run 7") < text.index("<robot")
    etree.parse(str(out))  # still well-formed


# ------------------------------------------------------------------ example-robot-data


@pytest.mark.parametrize("robot", sorted(ERD_ROBOTS))
def test_example_robot_data_round_trip(robot, tmp_path):
    src = example_robot_data_urdf(ERD_ROBOTS[robot])
    before = pin.buildModelFromUrdf(str(src))
    rng = np.random.default_rng(len(robot))
    movable = [before.names[j] for j in range(1, before.njoints) if before.joints[j].nq == 1]
    chosen = [movable[i] for i in sorted(rng.choice(len(movable), size=3, replace=False))]
    old = read_joint_origins(src)
    new = {}
    for name in chosen:
        delta = np.eye(4)
        delta[:3, :3] = pin.exp3(rng.normal(size=3) * 0.05)
        delta[:3, 3] = rng.normal(size=3) * 0.01
        new[name] = old[name] @ delta
    out = tmp_path / f"{robot}.urdf"
    write_urdf_with_origins(src, out, new, comment=f"test of {robot}")
    after = pin.buildModelFromUrdf(str(out))

    assert (after.njoints, after.nq, after.nv, after.nframes) == (
        before.njoints,
        before.nq,
        before.nv,
        before.nframes,
    )
    assert list(after.names) == list(before.names)
    for j in range(1, before.njoints):
        name = before.names[j]
        expected = new[name] if name in new else before.jointPlacements[j].homogeneous
        assert np.max(np.abs(after.jointPlacements[j].homogeneous - expected)) <= 1e-14, name
        assert np.array_equal(after.inertias[j].toDynamicParameters(), before.inertias[j].toDynamicParameters())
    for attribute in (
        "lowerPositionLimit",
        "upperPositionLimit",
        "velocityLimit",
        "effortLimit",
        "damping",
        "friction",
    ):
        assert np.array_equal(getattr(after, attribute), getattr(before, attribute)), attribute
    for fa, fb in zip(after.frames, before.frames):
        assert (fa.name, fa.parentJoint, fa.type) == (fb.name, fb.parentJoint, fb.type)
        assert np.array_equal(fa.placement.homogeneous, fb.placement.homogeneous), fa.name

    # Text level: everything but the replaced origins is identical, including
    # mesh file names, transmissions, gazebo tags, mimic and safety controllers.
    a, b = flatten_xml(src), flatten_xml(out)
    assert set(a) == set(b)
    changed = {key for key in a if a[key] != b[key]}
    assert changed == {(("joint", name), ("origin", 0)) for name in chosen}
    meshes_a = [e.get("filename") for e in etree.parse(str(src)).iter("mesh")]
    meshes_b = [e.get("filename") for e in etree.parse(str(out)).iter("mesh")]
    assert sorted(meshes_a) == sorted(meshes_b) and meshes_a


def test_example_robot_data_errors(monkeypatch):
    with pytest.raises(ModelError, match="not found"):
        example_robot_data_urdf("no_such_robot/robot.urdf")
    with pytest.raises(ModelError, match="relative"):
        example_robot_data_urdf("../../../etc/passwd")

    def missing(name):
        raise importlib.metadata.PackageNotFoundError(name)

    monkeypatch.setattr(importlib.metadata, "distribution", missing)
    with pytest.raises(ModelError, match="pip install example-robot-data"):
        example_robot_data_urdf(ERD_ROBOTS["ur5"])


# ------------------------------------------------------------------ packaged KUKA URDF


def test_committed_kuka_urdfs_are_generated_and_identical():
    generator = load_generator()
    content = generator.generate_urdf_bytes()
    user_facing = REPO_ROOT / "urdf" / "kuka_lwr4plus.urdf"
    packaged = REPO_ROOT / "pincal" / "robots" / "kuka_lwr4plus.urdf"
    assert user_facing.read_bytes() == packaged.read_bytes()
    assert packaged.read_bytes() == content
    assert kuka_lwr4plus_urdf().read_bytes() == content
    assert generator.main(["--check"]) == 0


def test_kuka_urdf_names_limits_and_provenance():
    path = kuka_lwr4plus_urdf()
    model = pin.buildModelFromUrdf(str(path))
    assert tuple(model.names[1:]) == KUKA_JOINTS
    for link in (KUKA_BASE_LINK, KUKA_FLANGE_LINK) + KUKA_LINKS:
        assert model.existFrame(link), link
    assert model.existFrame(KUKA_FLANGE_JOINT)
    limit = np.radians([170, 120, 170, 120, 170, 120, 170])
    np.testing.assert_allclose(model.upperPositionLimit, limit, rtol=0, atol=1e-15)
    np.testing.assert_allclose(model.lowerPositionLimit, -limit, rtol=0, atol=1e-15)
    assert np.all(np.isfinite(model.effortLimit)) and np.all(model.effortLimit > 0)
    assert np.all(np.isfinite(model.velocityLimit)) and np.all(model.velocityLimit > 0)

    root = etree.parse(str(path)).getroot()
    joint_axes = {j.get("name"): j.find("axis").get("xyz") for j in root.findall("joint[@type='revolute']")}
    assert set(joint_axes) == set(KUKA_JOINTS)
    assert all(np.allclose(np.array(v.split(), float), [0, 0, 1]) for v in joint_axes.values())
    comment = root.getprevious()
    assert isinstance(comment, etree._Comment)
    for phrase in ("scripts/generate_kuka_urdf.py", "Table 1", "Franaszek & Marvel", "DO NOT EDIT",
                   "Rz(theta_n + eps_n) Tz(d_n) Tx(r_n) Rx(alpha_n)", "eps_2 = 90 deg",
                   "not upright", "Gaz"):
        assert phrase in comment.text, phrase

    assert_same_table(dh_table_from_urdf(path, KUKA_JOINTS, KUKA_FLANGE_JOINT), KUKA_LWR4_DH)
    theta = np.zeros(7)
    assert np.max(np.abs(flange_pose(path, theta) - KUKA_LWR4_DH.forward(theta))) <= 1e-12
    upright = flange_pose(path, np.radians([0, 90, 0, 0, 0, 0, 0]))
    np.testing.assert_allclose(upright[:3, 3], [0, 0, 0.3105 + 0.4 + 0.39 + 0.078], atol=1e-12)


def test_kuka_urdf_inertias_are_physical():
    model = pin.buildModelFromUrdf(str(kuka_lwr4plus_urdf()))
    total = 0.0
    source = load_generator().GAZ_MASS  # the masses the generator cites (Gaz, Flacco & De Luca 2016)
    for name, mass in zip(KUKA_JOINTS, source):
        inertia = model.inertias[model.getJointId(name)]
        assert inertia.mass == pytest.approx(mass, rel=1e-12), name  # written with full precision
        total += inertia.mass
        assert np.linalg.norm(inertia.lever) < 0.5, name  # inside its link: the longest (d_3) is 0.4 m
        moments = np.linalg.eigvalsh(inertia.inertia)  # about the centre of mass
        assert np.all(moments > 0), name
        a, b, c = np.sort(moments)
        assert a + b >= c * (1 - 1e-12), name  # triangle inequality
        assert np.allclose(inertia.inertia, inertia.inertia.T)
    assert 10.0 < total < 25.0  # KUKA's datasheet gives 16 kg for the LWR 4+ arm


def test_kuka_gravity_torques_finite_and_non_zero():
    model = pin.buildModelFromUrdf(str(kuka_lwr4plus_urdf()))
    data = model.createData()
    rng = np.random.default_rng(2)
    for q in rng.uniform(model.lowerPositionLimit, model.upperPositionLimit, size=(10, 7)):
        tau = pin.computeGeneralizedGravity(model, data, q)
        assert np.all(np.isfinite(tau))
        assert np.linalg.norm(tau) > 1.0  # 17 kg of links: only COMs on vertical axes would give ~0
    # Upright, gravity is along the joint-1/3/5/7 axes: only the COM offsets load 2, 4, 6.
    tau = pin.computeGeneralizedGravity(model, data, np.radians([0, 90, 0, 0, 0, 0, 0]))
    assert abs(tau[0]) < 1e-9
    # Upper arm horizontal at q = 0: joint 2 carries the whole arm; links 4-7 alone
    # (5.1 kg, Gaz et al.) sit at least d_3 = 0.4 m out, about 20 N m: half of it as a floor.
    tau = pin.computeGeneralizedGravity(model, data, np.zeros(7))
    assert abs(tau[1]) > 10.0
