"""``pincal plan --camera-link``: the images to take of a ChArUco board (pincal.planning.camera_views,
pincal.planning.camera_plan, pincal.workflows.camera_plan).

A UR5 of example-robot-data with a camera (eye in hand) or a board (eye to hand) on tool0 by a fixed joint;
the board (or camera) placed so that the posture Q0 sees the board straight on 0.5 m away
(pincal.simulation.camera_scene.facing_scene). Small seeded candidate sets keep each test well under 2 s.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from pincal.cli.commands import main
from pincal.measurements.camera_csv import CornerSet, read_joint_readings
from pincal.measurements.charuco import parse_board
from pincal.model.camera_info import write_camera_info
from pincal.model.camera_view import camera_points, pose
from pincal.model.chain import KinematicChain, xyz_rpy_from_pose
from pincal.model.parameter_sets import PlacementErrors
from pincal.model.pinhole import CameraIntrinsics, project
from pincal.planning.camera_plan import CameraPlanSettings, plan_camera_views
from pincal.planning.camera_views import MAX_VIEW_ANGLE_DEG, ViewLimits, aimed_configurations
from pincal.residuals.base import KinematicsCache
from pincal.residuals.camera import CameraEstimate, CameraResidual
from pincal.robots import example_robot_data_dir, example_robot_data_urdf
from pincal.simulation.camera_scene import (
    CameraScene,
    board_corners,
    facing_scene,
    view_configurations,
    view_corners,
    with_fixed_link,
)
from pincal.simulation.sensor import random_configurations

INTRINSICS = CameraIntrinsics(1000.0, 1000.0, 640.0, 480.0, (-0.1, 0.05, 1e-3, -5e-4, 0.0), 1280, 960)
BOARD = parse_board("charuco:7x5:0.04:0.03:DICT_5X5_100")
Q0 = np.array([0.3, -1.2, 1.4, -1.6, -1.57, 0.2])
COUNT = 8


def _urdf(arrangement: str, camera_T_base: np.ndarray | None = None) -> str:
    text = example_robot_data_urdf("ur_description/urdf/ur5_robot.urdf").read_text()
    if arrangement == "eye_in_hand":
        return with_fixed_link(text, "tool0", "camera_link")
    text = with_fixed_link(text, "tool0", "board_link")
    if camera_T_base is None:
        return text
    xyz, rpy = xyz_rpy_from_pose(np.linalg.inv(camera_T_base))
    added = (f'<link name="camera_link"/><joint name="camera_joint" type="fixed"><parent link="world"/>'
             f'<child link="camera_link"/><origin xyz="{" ".join(map(repr, xyz.tolist()))}" '
             f'rpy="{" ".join(map(repr, rpy.tolist()))}"/></joint></robot>')
    head, _ = text.rsplit("</robot>", 1)
    return head + added


class _Case:
    def __init__(self, arrangement: str) -> None:
        link = "camera_link" if arrangement == "eye_in_hand" else "board_link"
        self.arrangement = arrangement
        self.chain = KinematicChain(pin.buildModelFromXML(_urdf(arrangement)), link, source="<ur5>")
        scene = facing_scene(self.chain, arrangement, Q0, np.eye(4), INTRINSICS, BOARD)
        self.camera = CameraEstimate(arrangement, scene.worlds, np.eye(4), INTRINSICS)
        rng = np.random.default_rng(3)
        self.candidates = aimed_configurations(self.chain, self.camera, BOARD, Q0[None], 60, rng)
        self.plan = plan_camera_views(self.chain, self.camera, BOARD, self.candidates,
                                      CameraPlanSettings(COUNT, criterion="d", random_draws=10))


@pytest.fixture(scope="module", params=("eye_in_hand", "eye_to_hand"))
def case(request: pytest.FixtureRequest) -> _Case:
    return _Case(request.param)


def _seen(case: _Case, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each image's corners' pixels (K, P, 2), its board outline's pixels (K, 4, 2) and the angle between the
    board's normal and the optical axis (K,) [deg], projected here from eqs C1/C2 and P1-P3."""
    w, h = BOARD.cols * BOARD.square, BOARD.rows * BOARD.square
    points = np.concatenate([board_corners(BOARD), [[0, 0, 0], [w, 0, 0], [w, h, 0], [0, h, 0]]])
    rotations, positions = case.chain.tool_poses(q)
    k, n = len(q), len(points)
    rows = np.repeat(np.arange(k), n)
    _, p = camera_points(case.arrangement, (rotations[rows], positions[rows]),
                         np.repeat(case.camera.worlds, k * n, axis=0), case.camera.mount, np.tile(points, (k, 1)))
    p = p.reshape(k, n, 3)
    assert np.all(p[:, :, 2] > 0.0)  # ahead of the camera
    pixels = project(INTRINSICS, p.reshape(-1, 3)).reshape(k, n, 2)
    normal = np.cross(p[:, -3] - p[:, -4], p[:, -1] - p[:, -4])
    angle = np.degrees(np.arccos(normal[:, 2] / np.linalg.norm(normal, axis=1)))
    return pixels[:, :-4], pixels[:, -4:], angle


def test_planned_images_see_the_whole_board_at_a_good_angle_and_size(case: _Case) -> None:
    plan = case.plan
    assert len(plan.q) == COUNT and len(set(plan.candidates.tolist())) == COUNT
    corners, outline, angle = _seen(case, plan.q)
    both = np.concatenate([corners, outline], axis=1)
    assert np.all((both >= 0.0) & (both <= [INTRINSICS.width - 1, INTRINSICS.height - 1]))
    assert np.all(angle <= MAX_VIEW_ANGLE_DEG)
    grid = corners.reshape(COUNT, BOARD.rows - 1, BOARD.cols - 1, 2)
    spacing = min(np.linalg.norm(np.diff(grid, axis=axis), axis=3).min() for axis in (1, 2))
    floor = ViewLimits().min_spacing_px(BOARD, INTRINSICS.width, INTRINSICS.height)
    assert spacing >= floor == pytest.approx(0.03 * 1280 / 4 * 0.04 / 0.03)  # OpenCV's 3 % perimeter rate
    np.testing.assert_allclose(plan.views.angle_deg, angle, atol=1e-9)


def test_some_candidates_are_refused_and_never_chosen(case: _Case) -> None:
    """Random configurations rarely see the board; those that do not are never planned."""
    q = np.concatenate([case.candidates, random_configurations(case.chain, np.random.default_rng(4), 40)])
    plan = plan_camera_views(case.chain, case.camera, BOARD, q, CameraPlanSettings(COUNT, criterion="d",
                                                                                   random_draws=2))
    assert (~plan.usable).sum() >= 30
    assert np.all(plan.usable[plan.candidates])


def _information(case: _Case, q: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """JᵀJ of eqs C1-C3 at the images of ``q`` (every corner: the plan's candidates see the whole board), and
    the names of its columns."""
    params = PlacementErrors(case.chain)
    cache = KinematicsCache(params, np.arange(params.size), np.zeros(params.size), q)
    corners = plan_corners(case, q)
    residual = CameraResidual(cache, corners, case.camera)
    jacobian = residual.jacobian(residual.start_vector())
    return jacobian.T @ jacobian, residual.column_names([p.name for p in params.info])


def plan_corners(case: _Case, q: np.ndarray) -> CornerSet:
    scene = CameraScene(case.arrangement, case.camera.worlds, case.camera.mount, INTRINSICS, BOARD)
    corners = view_corners(case.chain, scene, q, 0.0, np.random.default_rng(0))
    assert len(corners.image_of) == len(q) * BOARD.n_corners
    return corners


def test_planned_images_determine_the_calibration_better_than_random_usable_ones(case: _Case) -> None:
    """ln det of the information of the parameters the plan estimates: the plan's above every seeded random
    choice of as many usable candidates (and the planner's own comparison says so too)."""
    plan = case.plan
    assert plan.log_det > plan.random_log_det
    info, names = _information(case, plan.q)
    columns = [names.index(n) for n in plan.estimated]
    scale = np.sqrt(np.diag(info)[columns])  # the same unit-free scaling for both

    def log_det(m: np.ndarray) -> float:
        sign, value = np.linalg.slogdet(m[np.ix_(columns, columns)] / np.outer(scale, scale))
        return float(value) if sign > 0 else -np.inf

    planned = log_det(info)
    rng = np.random.default_rng(11)
    usable = np.flatnonzero(plan.usable)
    for _ in range(5):
        draw = case.candidates[rng.choice(usable, COUNT, replace=False)]
        assert planned > log_det(_information(case, draw)[0])


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    root = tmp_path_factory.mktemp("camera_plan")
    chain = KinematicChain(pin.buildModelFromXML(_urdf("eye_to_hand")), "board_link")
    world = facing_scene(chain, "eye_to_hand", Q0, np.eye(4), INTRINSICS, BOARD).worlds[0]
    (root / "eye_to_hand.urdf").write_text(_urdf("eye_to_hand", world))
    chain = KinematicChain(pin.buildModelFromXML(_urdf("eye_in_hand")), "camera_link")
    board_pose = facing_scene(chain, "eye_in_hand", Q0, np.eye(4), INTRINSICS, BOARD).worlds[0]
    (root / "eye_in_hand.urdf").write_text(_urdf("eye_in_hand"))
    write_camera_info(root / "camera.yaml", INTRINSICS)
    xyz, rpy = xyz_rpy_from_pose(board_pose)
    return {"root": str(root), "board_pose": ",".join(f"{v:.6f}" for v in (*xyz, *rpy))}


def _plan(files: dict[str, str], arrangement: str, *extra: str) -> list[str]:
    root = files["root"]
    link = ["--camera-link", "camera_link"] + (["--board-link", "board_link"] if arrangement == "eye_to_hand" else [])
    return ["plan", f"{root}/{arrangement}.urdf", *link, "--intrinsics", f"{root}/camera.yaml", "--board",
            BOARD.text, "--count", "6", "--sample", "40", "--no-collision-check", "--quiet", *extra]


@pytest.mark.parametrize("arrangement", ("eye_to_hand", "eye_in_hand"))
def test_cli_writes_a_plan_csv_that_detect_reads_as_joints(files: dict[str, str], arrangement: str,
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    out = f"{files['root']}/{arrangement}_PLAN.csv"
    extra = ["--board-pose", files["board_pose"]] if arrangement == "eye_in_hand" else []
    assert main([*_plan(files, arrangement, *extra), "--out", out]) == 0
    printed = capsys.readouterr().out
    assert "chose 6 of" in printed and "ln det of the information: plan" in printed
    with open(out, newline="") as handle:
        rows = list(csv.reader(handle))
    joints = ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint",
              "wrist_3_joint"]
    assert rows[0] == [*joints, "priority", "candidate"] and len(rows) == 7
    assert sorted(int(r[-2]) for r in rows[1:]) == list(range(1, 7))
    with open(f"{files['root']}/joints.csv", "w", newline="") as handle:  # the user's images of the plan's rows
        writer = csv.writer(handle)
        writer.writerow(["image", *rows[0]])
        writer.writerows([f"image_{i}.png", *row] for i, row in enumerate(rows[1:]))
    readings = read_joint_readings(f"{files['root']}/joints.csv")
    assert readings.columns[:6] == tuple(joints)


@pytest.mark.parametrize(("arrangement", "extra", "message"), [
    ("eye_in_hand", [], "rides on the chain (eye in hand): say where the board is, --board-pose"),
    ("eye_to_hand", ["--board-pose", "0,0,1,0,0,0"], "leave out --board-pose"),
    ("eye_to_hand", ["--tool", "0,0,0.1,0,0,0"], "--tool is a point sensor's"),
    ("eye_to_hand", ["--count", "500"], "candidates that see the whole board at most 60 degrees"),
    ("eye_to_hand", ["--srdf", "ur5.srdf"], "--srdf says which link pairs the collision check skips"),
])
def test_cli_bad_input_is_one_line(files: dict[str, str], arrangement: str, extra: list[str], message: str,
                                   capsys: pytest.CaptureFixture[str]) -> None:
    code = main([*_plan(files, arrangement, *extra), "--out", f"{files['root']}/bad.csv"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and message in err and len(err.splitlines()) == 1, err


def test_cli_camera_flags_without_a_camera_and_a_camera_link_not_in_the_urdf(
        files: dict[str, str], capsys: pytest.CaptureFixture[str]) -> None:
    root = files["root"]
    assert main(["plan", f"{root}/eye_to_hand.urdf", "--tip-link", "tool0", "--count", "6", "--out",
                 f"{root}/p.csv", "--report", f"{root}/p.json", "--board", BOARD.text]) == 2
    assert "give --camera-link" in capsys.readouterr().err
    assert main(["plan", f"{root}/eye_to_hand.urdf", "--count", "6", "--out", f"{root}/p.csv"]) == 2
    assert "give --tip-link LINK" in capsys.readouterr().err
    camera_data = Path(root) / "camera_DATA.csv"  # detect's columns: a point sensor's plan cannot continue it
    joints = "shoulder_pan_joint,shoulder_lift_joint,elbow_joint,wrist_1_joint,wrist_2_joint,wrist_3_joint"
    camera_data.write_text(f"image,corner,u,v,board_x,board_y,width,height,{joints}\na.png,0,1,2,0.04,0.04,1280,960,"
                           + ",".join(str(v) for v in Q0) + "\n")
    assert main(["plan", f"{root}/eye_to_hand.urdf", "--tip-link", "tool0", "--count", "6", "--out", f"{root}/p.csv",
                 "--report", f"{root}/p.json", "--existing", str(camera_data)]) == 2
    err = capsys.readouterr().err.strip()
    assert f"{camera_data}: a camera's DATA.csv" in err and "give --camera-link" in err and len(err.splitlines()) == 1
    assert main(_plan(files, "eye_to_hand")[:2] + ["--camera-link", "camera", "--board-link", "board_link",
                                                   *_plan(files, "eye_to_hand")[6:], "--out", f"{root}/p.csv"]) == 2
    err = capsys.readouterr().err.strip()
    assert "no link named 'camera'" in err and len(err.splitlines()) == 1
    assert not Path(f"{root}/p.csv").exists()


def test_cli_plans_from_a_first_run_s_images(files: dict[str, str], capsys: pytest.CaptureFixture[str]) -> None:
    """Eye in hand without --board-pose: a first run's DATA.csv (8 images, the camera's true mount 10 cm and
    30 degrees off the URDF's, 0.2 px noise) says where the board and the camera are; the planned images see
    the board as the truth projects it."""
    root = files["root"]
    chain = KinematicChain(pin.buildModelFromXML(_urdf("eye_in_hand")), "camera_link")
    mount = pose(pin.exp3(np.radians(30.0) * np.array([0.6, 0.0, 0.8])), np.array([0.06, 0.0, 0.08]))
    scene = facing_scene(chain, "eye_in_hand", Q0, mount, INTRINSICS, BOARD)
    rng = np.random.default_rng(8)
    corners = view_corners(chain, scene, view_configurations(chain, scene, Q0, 8, rng), 0.2, rng)
    with open(f"{root}/data.csv", "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["image", "corner", "u", "v", "board_x", "board_y", "width", "height",
                         *chain.joint_names, "role"])
        for c in range(len(corners.image_of)):
            k = corners.image_of[c]
            writer.writerow([corners.images[k], corners.corners[c], *corners.pixels[c], *corners.board_points[c, :2],
                             *corners.sizes[k], *corners.q[k], "calibration"])
    out = f"{root}/PLAN_existing.csv"
    assert main([*_plan(files, "eye_in_hand", "--existing", f"{root}/data.csv"), "--out", out]) == 0
    captured = capsys.readouterr()
    assert "8 image(s) recorded, reprojection RMS" in captured.err
    with open(out, newline="") as handle:
        q = np.array([[float(v) for v in row[:6]] for row in list(csv.reader(handle))[1:]])
    case = _Case.__new__(_Case)  # the truth's view of the plan
    case.arrangement, case.chain = "eye_in_hand", chain
    case.camera = CameraEstimate("eye_in_hand", scene.worlds, mount, INTRINSICS)
    pixels, outline, angle = _seen(case, q)
    both = np.concatenate([pixels, outline], axis=1)
    assert len(q) == 6 and np.all(angle <= MAX_VIEW_ANGLE_DEG + 0.5)  # the fitted mount and board: ~0.1 deg
    assert np.all((both >= -2.0) & (both <= [INTRINSICS.width + 1, INTRINSICS.height + 1]))


def test_an_image_s_information_keeps_its_rank_when_compressed(case: _Case) -> None:
    """An image moves its corners through the camera's pose relative to the board and the intrinsics only:
    its block keeps 6 + (intrinsics estimated) rows and the same information JᵀJ."""
    from pincal.model.pinhole import INTRINSIC_NAMES
    from pincal.planning.camera_plan import _compressed, _image_blocks

    q = case.plan.q[:3]
    corners = plan_corners(case, q)
    params = PlacementErrors(case.chain)
    cache = KinematicsCache(params, np.arange(params.size), np.zeros(params.size), q)
    residual = CameraResidual(cache, corners, case.camera, tuple(range(len(INTRINSIC_NAMES))))
    blocks = _image_blocks(residual, len(q), 2 * BOARD.n_corners, 0.2)
    small = _compressed(blocks, 6 + len(INTRINSIC_NAMES))
    assert small.shape == (3, 15, blocks.shape[2])
    full = np.einsum("kim,kin->kmn", blocks, blocks)
    np.testing.assert_allclose(np.einsum("kim,kin->kmn", small, small), full, rtol=0, atol=1e-9 * np.abs(full).max())


def test_cli_refuses_a_first_run_of_the_other_arrangement(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Eight eye-to-hand images as the first run of an eye-in-hand camera: the nominal kinematics with a mount and
    world frame fitted miss them by ~63 px, 58 mm at the board against 5 % of a 0.77 m reach (calibrate would
    withhold such a model): refused in one line, not planned with 63 px as the pixel noise."""
    from pincal.workflows.camera_simulation import CameraSimulationSettings, simulate_camera_files

    hand = simulate_camera_files(tmp_path / "hand", CameraSimulationSettings("eye_in_hand", images=3, held_out=0))
    fixed = simulate_camera_files(tmp_path / "fixed", CameraSimulationSettings("eye_to_hand", images=8, held_out=0,
                                                                               noise_px=0.0))
    out = tmp_path / "PLAN.csv"
    code = main(["plan", str(hand.urdf), "--camera-link", "camera_link", "--intrinsics", str(hand.intrinsics),
                 "--board", BOARD.text, "--existing", str(fixed.data), "--count", "3", "--sample", "20",
                 "--no-collision-check", "--quiet", "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1, err
    assert str(fixed.data) in err and "not images of this arrangement (eye in hand" in err and not out.exists()


def test_the_view_angle_bound_is_one_constant() -> None:
    """The plan's view-angle bound is the simulated images' (one constant, its source beside it), not a copy."""
    import pincal.simulation.camera_scene as scene
    from pincal.planning import camera_views

    assert camera_views.MAX_VIEW_ANGLE_DEG is scene.MAX_VIEW_ANGLE_DEG


def test_cli_camera_plan_takes_the_robots_srdf(files: dict[str, str], capsys: pytest.CaptureFixture[str]) -> None:
    """The UR5's SRDF (example-robot-data's ur5.srdf) serves the camera's plan as the points' plan: a note says
    how many pairs it disabled."""
    srdf = example_robot_data_dir() / "ur_description" / "srdf" / "ur5.srdf"
    args = [a for a in _plan(files, "eye_to_hand") if a != "--no-collision-check"]
    assert main([*args, "--srdf", str(srdf), "--out", f"{files['root']}/srdf_PLAN.csv"]) == 0
    err = capsys.readouterr().err
    assert "link pairs checked, 10 disabled by ur5.srdf" in err, err  # ur5.srdf: 10 pairs, none 'Never'

