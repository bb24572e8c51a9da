"""`pincal urdf-from-dh`: DH tables (standard and modified) to URDF, exactly, and its bad inputs.

Reference matrices are the textbook ones, written out here independently of
pincal: Spong, Hutchinson & Vidyasagar, *Robot Modeling and Control* (2006),
eq 3.10 (standard, distal) and Craig, *Introduction to Robotics* (3rd ed.),
eq 3.6 (modified). The tolerance 1e-12 is the issue's (FK of the written URDF
equals the DH product); URDF origins are written with 17 significant digits, so
the only error is rounding (~1e-15 per joint).
"""

from __future__ import annotations

import hashlib
import tempfile
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pincal.cli.commands import main
from pincal.model.dh.files import read_dh_csv
from pincal.model.dh.robot import DEFAULT_LIMITS, DHRobot
from pincal.model.dh.table import (
    KUKA_LWR4_DH,
    dh_chain_origins,
    dh_origin_rows,
    rot_x,
    rot_z,
    trans,
)
from pincal.model.dh.urdf import (
    DH_FLANGE_JOINT,
    DH_FLANGE_LINK,
    dh_robot_from_urdf,
    urdf_from_dh,
)
from pincal.model.urdf import read_joint_origins
from pincal.robots import KUKA_FLANGE_JOINT, KUKA_JOINTS, kuka_lwr4plus_urdf

TOL = 1e-12
HYPOTHESIS = settings(max_examples=25, deadline=None, derandomize=True,
                      suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])


# ------------------------------------------------------------------ references and helpers


def spong_standard(theta, d, a, alpha):
    """Standard DH link transform, Spong et al. eq 3.10."""
    ct, st_, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
    return np.array([[ct, -st_ * ca, st_ * sa, a * ct],
                     [st_, ct * ca, -ct * sa, a * st_],
                     [0.0, sa, ca, d],
                     [0.0, 0.0, 0.0, 1.0]])


def craig_modified(alpha_prev, a_prev, theta, d):
    """Modified DH link transform, Craig eq 3.6."""
    ct, st_, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha_prev), np.sin(alpha_prev)
    return np.array([[ct, -st_, 0.0, a_prev],
                     [st_ * ca, ct * ca, -sa, -sa * d],
                     [st_ * sa, ct * sa, ca, ca * d],
                     [0.0, 0.0, 0.0, 1.0]])


def textbook_forward(robot: DHRobot, q) -> np.ndarray:
    pose = np.eye(4)
    for n in range(robot.n_joints):
        revolute = robot.types[n] == "revolute"
        theta = robot.theta[n] + (q[n] if revolute else 0.0)
        d = robot.d[n] + (0.0 if revolute else q[n])
        if robot.convention == "standard":
            pose = pose @ spong_standard(theta, d, robot.a[n], robot.alpha[n])
        else:
            pose = pose @ craig_modified(robot.alpha[n], robot.a[n], theta, d)
    return pose


def pinocchio_flange(urdf: Path, q) -> np.ndarray:
    """Pose of link 'flange' in the root link, straight from Pinocchio (q in chain order = URDF order)."""
    model = pin.buildModelFromUrdf(str(urdf))
    data = model.createData()
    pin.framesForwardKinematics(model, data, np.asarray(q, dtype=float))
    return data.oMf[model.getFrameId(DH_FLANGE_LINK, pin.BODY)].homogeneous


def random_robot(rng: np.random.Generator, convention: str, n: int = 6, prismatic: bool = True) -> DHRobot:
    """A random table; angles are often the exact multiples of pi/2 real tables have."""

    def angles():
        nice = rng.choice([-np.pi, -np.pi / 2, 0.0, np.pi / 2, np.pi], size=n)
        return np.where(rng.random(n) < 0.5, nice, rng.uniform(-np.pi, np.pi, n))

    types = tuple(rng.choice(["revolute", "prismatic"]) if prismatic else "revolute" for _ in range(n))
    lower = np.array([-np.pi if t == "revolute" else -0.5 for t in types])
    return DHRobot(convention=convention, names=tuple(f"j{i}" for i in range(1, n + 1)),
                   alpha=angles(), a=rng.uniform(-0.8, 0.8, n), theta=angles(), d=rng.uniform(-0.8, 0.8, n),
                   types=types, lower=lower, upper=-lower, velocity=np.ones(n), effort=np.ones(n))


def random_q(robot: DHRobot, rng: np.random.Generator, count: int) -> np.ndarray:
    return rng.uniform(robot.lower, robot.upper, (count, robot.n_joints))


def write_csv(path: Path, text: str) -> Path:
    path.write_text(text.strip() + "\n", encoding="utf-8")
    return path


def angle_diff(a, b) -> np.ndarray:
    return np.abs(np.angle(np.exp(1j * (np.asarray(a) - np.asarray(b)))))


# ------------------------------------------------------------------ the DH row core


def test_origin_core_is_the_elementary_product():
    rng = np.random.default_rng(1)
    for alpha, a, theta, d0, d1 in rng.uniform(-4, 4, (200, 5)):
        expected = trans(z=d0) @ trans(x=a) @ rot_x(alpha) @ rot_z(theta) @ trans(z=d1)
        np.testing.assert_allclose(dh_origin_rows(alpha, a, theta, d0, d1)[0], expected, rtol=0, atol=1e-15)


@pytest.mark.parametrize("convention", ["standard", "modified"])
@pytest.mark.parametrize("prismatic", [False, True], ids=["revolute", "mixed"])
def test_dh_product_is_the_textbook_one(convention, prismatic):
    rng = np.random.default_rng(2)
    for _ in range(10):
        robot = random_robot(rng, convention, prismatic=prismatic)
        for q in random_q(robot, rng, 5):
            np.testing.assert_allclose(robot.forward(q), textbook_forward(robot, q), rtol=0, atol=TOL)


def test_standard_product_is_the_papers_table():
    """With the KUKA table, DHRobot's standard product is DHTable's (eq 4-5) and the origins are bit-identical."""
    t = KUKA_LWR4_DH
    robot = DHRobot("standard", KUKA_JOINTS, t.alpha, t.r, t.epsilon, t.d, ("revolute",) * 7,
                    -np.ones(7), np.ones(7), np.ones(7), np.ones(7))
    for q in np.random.default_rng(3).uniform(-1, 1, (5, 7)):
        np.testing.assert_allclose(robot.forward(q), t.forward(q), rtol=0, atol=TOL)
    for mine, kuka in zip(robot.joint_origins(), t.joint_origins()):
        assert np.array_equal(mine, kuka)


# ------------------------------------------------------------------ FK of the written URDF


@HYPOTHESIS
@given(seed=st.integers(0, 2**32 - 1), convention=st.sampled_from(["standard", "modified"]),
       prismatic=st.booleans(), flange=st.booleans(), n=st.integers(1, 7))
def test_fk_of_written_urdf_equals_dh_product(seed, convention, prismatic, flange, n):
    rng = np.random.default_rng(seed)
    robot = random_robot(rng, convention, n=n, prismatic=prismatic)
    flange_T = None
    if flange:
        flange_T = np.eye(4)
        flange_T[:3, :3] = pin.exp3(rng.normal(size=3))
        flange_T[:3, 3] = rng.uniform(-0.2, 0.2, 3)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "robot.urdf"
        urdf_from_dh(robot, out, flange=flange_T)
        for q in random_q(robot, rng, 5):
            expected = textbook_forward(robot, q) @ (np.eye(4) if flange_T is None else flange_T)
            err = np.abs(pinocchio_flange(out, q) - expected).max()
            assert err <= TOL, err


def test_conventions_agree_on_the_same_arm(tmp_path):
    """A standard table regrouped into Craig's rows (Tz(d1) first, Tx(a_N) Rx(alpha_N) as the
    flange transform) is the same arm: both URDFs put the flange at the same pose."""
    rng = np.random.default_rng(4)
    std = random_robot(rng, "standard", prismatic=True)
    zero = np.zeros(1)
    mod = DHRobot("modified", std.names, np.concatenate([zero, std.alpha[:-1]]),
                  np.concatenate([zero, std.a[:-1]]), std.theta, std.d, std.types,
                  std.lower, std.upper, std.velocity, std.effort)
    flange = trans(x=std.a[-1]) @ rot_x(std.alpha[-1])
    urdf_from_dh(std, tmp_path / "std.urdf")
    urdf_from_dh(mod, tmp_path / "mod.urdf", flange=flange)
    for q in random_q(std, rng, 5):
        a, b = pinocchio_flange(tmp_path / "std.urdf", q), pinocchio_flange(tmp_path / "mod.urdf", q)
        assert np.abs(a - b).max() <= TOL


def test_kuka_generator_and_urdf_from_dh_write_the_same_origins(tmp_path):
    """One code path: the packaged KUKA URDF (scripts/generate_kuka_urdf.py, apply_dh_table) and
    urdf_from_dh of the same table write the same origin text for every joint."""
    t = KUKA_LWR4_DH
    robot = DHRobot("standard", KUKA_JOINTS, t.alpha, t.r, t.epsilon, t.d, ("revolute",) * 7,
                    -np.ones(7), np.ones(7), np.ones(7), np.ones(7))
    urdf_from_dh(robot, tmp_path / "kuka.urdf")
    from lxml import etree

    def origin_text(path, joint):
        return dict(etree.parse(str(path)).getroot().find(f"joint[@name='{joint}']/origin").attrib)

    for ours, theirs in zip(KUKA_JOINTS + (DH_FLANGE_JOINT,), KUKA_JOINTS + (KUKA_FLANGE_JOINT,)):
        assert origin_text(tmp_path / "kuka.urdf", ours) == origin_text(kuka_lwr4plus_urdf(), theirs)


def test_fk_check_measures_a_wrong_urdf(tmp_path):
    """The command's bug guard (urdf_from_dh.fk_error) sees a URDF that is not the table's."""
    from pincal.model.dh.conversion import fk_error

    rng = np.random.default_rng(8)
    robot, other = random_robot(rng, "modified"), random_robot(rng, "modified")
    other = DHRobot(**{**other.__dict__, "types": robot.types})
    urdf_from_dh(robot, tmp_path / "right.urdf")
    urdf_from_dh(other, tmp_path / "wrong.urdf")
    assert fk_error(robot, tmp_path / "right.urdf", np.eye(4)) <= TOL
    assert fk_error(robot, tmp_path / "wrong.urdf", np.eye(4)) > 1e-3


# ------------------------------------------------------------------ round trip


ROUND_TRIP_TABLE = """
joint,type,a,alpha,d,theta,lower,upper,velocity,effort
shoulder,revolute,0.0,-90,0.4865,0,-170,170,3.1,200
upper_arm,,0.15,0,0,-90,-95,155,3.1,200
elbow,revolute,0.7,-90,0,0,-180,75,3.1,150
slide,prismatic,0.0,90,0.1,180,-0.2,0.25,0.5,1000
wrist_2,revolute,-0.02,-90,0.64,0,-120,120,6.2,30
wrist_3,Revolute,0,90,0.1,45.5,-350,350,6.2,30
"""


@pytest.mark.parametrize("convention", ["standard", "modified"])
def test_round_trip_table_urdf_table(convention, tmp_path):
    table = write_csv(tmp_path / "arm.csv", ROUND_TRIP_TABLE)
    robot, _ = read_dh_csv(table, convention, degrees=True)
    assert robot.types == ("revolute", "revolute", "revolute", "prismatic", "revolute", "revolute")
    assert robot.lower[3] == -0.2 and robot.upper[3] == 0.25  # prismatic limits stay metres
    assert robot.alpha[0] == np.radians(-90.0) and robot.theta[5] == np.radians(45.5)  # --degrees converts
    assert robot.lower[0] == np.radians(-170.0) and robot.upper[5] == np.radians(350.0)
    urdf_from_dh(robot, tmp_path / "arm.urdf")
    back = dh_robot_from_urdf(tmp_path / "arm.urdf", convention)
    assert back.names == robot.names and back.types == robot.types and back.convention == convention
    for field in ("alpha", "theta"):
        assert angle_diff(getattr(back, field), getattr(robot, field)).max() <= TOL, field
    for field in ("a", "d"):
        assert np.abs(getattr(back, field) - getattr(robot, field)).max() <= TOL, field
    for field in ("lower", "upper", "velocity", "effort"):
        assert np.array_equal(getattr(back, field), getattr(robot, field)), field


def test_round_trip_with_flange(tmp_path):
    robot = random_robot(np.random.default_rng(5), "modified")
    flange = trans(0.01, -0.02, 0.15) @ rot_z(0.3) @ rot_x(-1.0)
    urdf_from_dh(robot, tmp_path / "r.urdf", flange=flange)
    back = dh_robot_from_urdf(tmp_path / "r.urdf", "modified", flange=flange)
    assert angle_diff(back.theta, robot.theta).max() <= TOL
    assert np.abs(back.d - robot.d).max() <= TOL


def test_modified_read_back_rejects_non_dh_origin(tmp_path):
    origins = dh_chain_origins("modified", [0.1, 0.3, -0.7], [0.2, 0.0, 0.4], [0.0, 0.4, 1.1], [0.3, 0.1, 0.0])
    origins[2] = origins[2] @ trans(y=0.01)  # Craig's rows have no y translation in the child frame
    from pincal.errors import PincalError
    from pincal.model.dh.table import dh_chain_from_origins

    with pytest.raises(PincalError, match="origin 2: not of the modified DH shape"):
        dh_chain_from_origins("modified", origins)


# ------------------------------------------------------------------ the command


GOOD_TABLE = """
joint,a,alpha,d,theta,lower,upper
A1,0,0,0.45,0,-185,185
A2,0.15,-90,0,-90,-140,-5
A3,0.61,0,0,0,-120,168
A4,0.02,-90,0.66,0,-350,350
A5,0,90,0,0,-125,125
A6,0,-90,0.08,180,-350,350
"""


def test_cli_end_to_end(tmp_path, capsys):
    table = write_csv(tmp_path / "kr.csv", GOOD_TABLE)
    before = hashlib.sha256(table.read_bytes()).hexdigest()
    out = tmp_path / "kr.urdf"
    code = main(["urdf-from-dh", str(table), "--convention", "modified", "--degrees", "--out", str(out),
                 "--name", "kr_test", "--flange", "0,0,0.1,0,0,1.5707963267948966"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert hashlib.sha256(table.read_bytes()).hexdigest() == before
    assert "6 joints (6 revolute), modified DH convention" in captured.out
    assert "tip link flange" in captured.out and "--tip-link flange" in captured.out
    assert "no velocity or effort limit for joint(s) A1, A2, A3, A4, A5, A6" in captured.err
    text = out.read_text()
    assert '<robot name="kr_test">' in text
    for needle in (str(table), before, "convention modified", "degrees", "Craig", "Rx(alpha_{i-1})"):
        assert needle in text.split("<robot")[0], needle
    robot, _ = read_dh_csv(table, "modified", degrees=True)
    flange = trans(z=0.1) @ rot_z(np.pi / 2)
    for q in random_q(robot, np.random.default_rng(7), 5):
        assert np.abs(pinocchio_flange(out, q) - textbook_forward(robot, q) @ flange).max() <= TOL
    origins = read_joint_origins(out)
    assert list(origins) == ["A1", "A2", "A3", "A4", "A5", "A6", DH_FLANGE_JOINT]


def test_cli_defaults_limits_and_states_them(tmp_path, capsys):
    table = write_csv(tmp_path / "t.csv", "joint,a,alpha,d,theta,type\nj1,0,0,0.3,0,\nj2,0.2,1.5,0,0,prismatic")
    out = tmp_path / "t.urdf"
    assert main(["urdf-from-dh", str(table), "--convention", "standard", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert "no lower/upper limit for joint(s) j1, j2" in err
    back = dh_robot_from_urdf(out, "standard")
    assert (back.lower[0], back.upper[0]) == DEFAULT_LIMITS["revolute"]
    assert (back.lower[1], back.upper[1]) == DEFAULT_LIMITS["prismatic"]
    assert '<robot name="t">' in out.read_text()


HEADER = "joint,a,alpha,d,theta,lower,upper\n"

BAD_TABLES = {
    "missing column": ("joint,a,alpha,d\nj1,0,0,0.3", [], "line 1: missing column(s) theta"),
    "non-numeric cell": (HEADER + "j1,0,0,0.3,0,-1,1\nj2,0.2m,0,0,0,-1,1", [],
                         "line 3 (joint 'j2'), column 'a': '0.2m' is not a finite number"),
    "empty cell": (HEADER + "j1,0,,0.3,0,-1,1", [], "line 2 (joint 'j1'), column 'alpha': empty cell"),
    "duplicate joint": (HEADER + "j1,0,0,0.3,0,-1,1\nj1,0,0,0.3,0,-1,1", [],
                        "line 3, column 'joint': joint name 'j1' already used on line 2"),
    "lower > upper": (HEADER + "j1,0,0,0.3,0,1,-1", [], "line 2 (joint 'j1'), column 'lower': lower limit 1 > upper"),
    "lower > default upper": ("joint,a,alpha,d,theta,lower\nj1,0,0,0.3,0,3.5", [],
                              "lower limit 3.5 > upper limit 3.14159 (default)"),
    "alpha in degrees": (HEADER + "j1,0,-90,0.3,0,-1,1", [], "line 2 (joint 'j1'), column 'alpha': -90 looks like degrees"),
    "theta in degrees": (HEADER + "j1,0,0,0.3,180,-1,1", [], "column 'theta': 180 looks like degrees"),
    "limit in degrees": (HEADER + "j1,0,0,0.3,0,-170,170", [], "column 'lower': -170 looks like degrees"),
    # --degrees on a table in radians (a twist of -1.5708° is no design angle; conventions.RIGHT_ANGLE_TOL)
    "radians with --degrees": (HEADER + "j1,0,-1.5707963267948966,0.3,0,-1,1", ["--degrees"],
                               "line 2 (joint 'j1'), column 'alpha': -1.5708 looks like radians"),
    "π to two decimals with --degrees": (HEADER + "j1,0,0,0.3,3.14,-1,1", ["--degrees"],
                                         "column 'theta': 3.14 looks like radians"),
    "3π/2 to two decimals with --degrees": (HEADER + "j1,0,0,0.3,-4.71,-1,1", ["--degrees"],
                                            "column 'theta': -4.71 looks like radians"),
    "length in mm": (HEADER + "j1,0,0,450,0,-1,1", [], "column 'd': 450 looks like millimetres"),
    "unknown type": ("joint,a,alpha,d,theta,type\nj1,0,0,0.3,0,rotary", [],
                     "line 2 (joint 'j1'), column 'type': unknown joint type 'rotary'; use revolute, prismatic or continuous"),
    "reserved name": (HEADER + "flange_joint,0,0,0.3,0,-1,1", [], "'flange_joint' is the name of the fixed joint"),
    "ragged row": (HEADER + "j1,0,0,0.3,0,-1", [], "line 2: 6 fields but the header has 7"),
    "header only": (HEADER, [], "header only, no data rows; add one row per joint"),
    "negative velocity": ("joint,a,alpha,d,theta,velocity\nj1,0,0,0.3,0,-2", [], "column 'velocity': -2 is negative"),
}


@pytest.mark.parametrize("case", sorted(BAD_TABLES))
def test_bad_table_one_line_exit_2(case, tmp_path, capsys):
    text, extra, expected = BAD_TABLES[case]
    table = tmp_path / "bad.csv"
    table.write_text(text, encoding="utf-8")
    before = table.read_bytes()
    out = tmp_path / "bad.urdf"
    code = main(["urdf-from-dh", str(table), "--convention", "standard", "--out", str(out), *extra])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and err.startswith(f"pincal: error: {table}: "), err
    assert expected in err, err
    assert "Traceback" not in err
    assert not out.exists() and table.read_bytes() == before


def _good(tmp_path: Path) -> Path:
    return write_csv(tmp_path / "good.csv", GOOD_TABLE)


BAD_OPTIONS = {
    "output is the input": (lambda t, d: ["--convention", "modified", "--degrees", "--out", str(t)],
                            "refusing to overwrite an input file"),
    "output is the input by another path": (
        lambda t, d: ["--convention", "modified", "--degrees", "--out", str(d / "." / "good.csv")],
        "refusing to overwrite an input file"),
    "output is a folder": (lambda t, d: ["--convention", "modified", "--degrees", "--out", str(d)], "is a directory"),
    "table not found": (lambda t, d: ["--convention", "modified", "--out", str(d / "r.urdf")], "file not found"),
}

USAGE_ERRORS = {
    "unknown convention": (["--convention", "craig"], "argument --convention: invalid choice: 'craig'"),
    "no convention": ([], "the following arguments are required: --convention"),
    "bad flange": (["--convention", "modified", "--flange", "0,0,1"],
                   "argument --flange: '0,0,1' is not X,Y,Z,ROLL,PITCH,YAW"),
    "flange in degrees": (["--convention", "modified", "--degrees", "--flange", "0,0,0.1,0,0,90"],
                          "argument --flange: '0,0,0.1,0,0,90': roll/pitch/yaw beyond one turn look like degrees"),
}


@pytest.mark.parametrize("case", sorted(USAGE_ERRORS))
def test_bad_arguments_are_usage_errors(case, tmp_path, capsys):
    args, expected = USAGE_ERRORS[case]
    table = _good(tmp_path)
    with pytest.raises(SystemExit) as exit_info:
        main(["urdf-from-dh", str(table), *args, "--out", str(tmp_path / "r.urdf")])
    assert exit_info.value.code == 2
    assert expected in capsys.readouterr().err.strip().splitlines()[-1]
    assert not (tmp_path / "r.urdf").exists()


def test_missing_output_folder_is_created(tmp_path, capsys):
    """The folder policy of every pincal command: a missing output folder is created."""
    out = tmp_path / "no" / "r.urdf"
    assert main(["urdf-from-dh", str(_good(tmp_path)), "--convention", "modified", "--degrees",
                 "--out", str(out)]) == 0, capsys.readouterr().err
    assert out.is_file()


@pytest.mark.parametrize("case", sorted(BAD_OPTIONS))
def test_bad_options_one_line_exit_2(case, tmp_path, capsys):
    make_args, expected = BAD_OPTIONS[case]
    table = _good(tmp_path)
    before = table.read_bytes()
    source = tmp_path / "missing.csv" if case == "table not found" else table
    code = main(["urdf-from-dh", str(source), *make_args(table, tmp_path)])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("pincal: error: "), err
    assert expected in err, err
    assert table.read_bytes() == before
    assert not (tmp_path / "r.urdf").exists()
