"""``pincal detect``: a ChArUco board's corners found in images and written with the joint readings.

The images are rendered here (pincal.simulation.board_images): a 7x5 board of 40 mm squares and 30 mm
DICT_5X5_100 markers, seen 0.45-0.55 m away by a 640x480 camera (f = 600 px) with mild distortion
(k1 = -0.1, k2 = 0.05, p1 = 0.001, p2 = -0.001), Gaussian noise of sigma 2 grey levels, seeded.
"""

from __future__ import annotations

import csv
import re
from types import SimpleNamespace

import cv2
import numpy as np
import pytest

from pincal.cli.commands import main
from pincal.errors import MeasurementError
from pincal.measurements.camera_csv import read_corners
from pincal.measurements.charuco import DICTIONARY_SIZES, parse_board
from pincal.measurements.data import JointSpec
from pincal.measurements.image_bags import IMAGE, ImageStream
from pincal.simulation.board_images import BoardView, render_board
from pincal.workflows.detection import DetectSettings, detect_files

SPEC = parse_board("charuco:7x5:0.04:0.03:DICT_5X5_100")
K = np.array([[600.0, 0.0, 320.0], [0.0, 600.0, 240.0], [0.0, 0.0, 1.0]])
DISTORTION = np.array([-0.1, 0.05, 0.001, -0.001, 0.0])
POSES = [((0.2, -0.3, 0.05), (-0.14, -0.09, 0.5)), ((-0.3, 0.2, 0.3), (-0.1, -0.12, 0.45)),
         ((0.1, 0.4, -0.2), (-0.16, -0.08, 0.55))]
VIEWS = [BoardView(K, DISTORTION, (640, 480), np.array(r), np.array(t)) for r, t in POSES]
#: Largest distance of a detected corner from its projection [px]. Measured on these images: 0.20 px
#: (RMS 0.07 px) -- OpenCV's cornerSubPix under sigma 2 grey-level noise plus the rendering's
#: interpolation. 0.3 px leaves room for other seeds and OpenCV versions and still fails a half-pixel
#: slip of the pixel convention (0.5 px).
TOLERANCE_PX = 0.3
JOINTS = ("shoulder", "elbow")


def _write_joints(path, names, extra_header=(), extra=()):
    with open(path, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["image", *JOINTS, "role", *extra_header])
        for k, name in enumerate(names):
            writer.writerow([name, f"{0.1 * k:.3f}", f"{0.5 - 0.2 * k:.3f}", "validation" if k == 1 else "", *extra])


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """A folder of three board images and a blank one, their JOINTS.csv, and detect's run on them."""
    root = tmp_path_factory.mktemp("detect")
    folder = root / "images"
    folder.mkdir()
    rng = np.random.default_rng(3)
    names = [f"view_{k}.png" for k in range(len(VIEWS))] + ["blank.png"]
    for name, view in zip(names, VIEWS):
        cv2.imwrite(str(folder / name), render_board(SPEC, view, 2.0, rng))
    cv2.imwrite(str(folder / "blank.png"), np.clip(rng.normal(200, 2.0, (480, 640)), 0, 255).astype(np.uint8))
    _write_joints(root / "joints.csv", names)
    run = detect_files(DetectSettings((folder,), SPEC, root / "joints.csv", root / "data.csv"))
    return root, folder, names, run


def _rows(path):
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))


def test_corners_are_found_where_the_camera_projects_them(scene):
    root, _, names, run = scene
    rows = _rows(root / "data.csv")
    assert len(rows) == run.rows
    errors = []
    for name, view in zip(names, VIEWS):
        mine = [r for r in rows if r["image"] == name]
        ids = np.array([int(r["corner"]) for r in mine])
        assert len(ids) == SPEC.n_corners  # every corner of these full views
        board = np.array([[float(r["board_x"]), float(r["board_y"]), 0.0] for r in mine])
        opencv = cv2.aruco.CharucoBoard((7, 5), 0.04, 0.03, cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_5X5_100))
        np.testing.assert_allclose(board, opencv.getChessboardCorners()[ids], atol=1e-7)  # float32 there
        found = np.array([[float(r["u"]), float(r["v"])] for r in mine])
        errors.append(np.linalg.norm(found - view.project(board), axis=1))
        assert {(r["width"], r["height"]) for r in mine} == {("640", "480")}
    errors = np.concatenate(errors)
    assert errors.max() < TOLERANCE_PX, errors.max()


def test_joint_readings_role_and_columns_travel_with_each_corner(scene):
    root, _, names, _ = scene
    rows = _rows(root / "data.csv")
    assert list(rows[0]) == ["image", "corner", "u", "v", "board_x", "board_y", "width", "height", *JOINTS, "role"]
    one = [r for r in rows if r["image"] == names[1]]
    assert {(r["shoulder"], r["elbow"], r["role"]) for r in one} == {("0.100", "0.300", "validation")}
    assert {r["role"] for r in rows if r["image"] == names[0]} == {"calibration"}


def test_a_blank_image_is_listed_and_skipped(scene):
    root, folder, _, run = scene
    assert [image.path for image in run.skipped] == [folder / "blank.png"]
    assert len(run.notes) == 1 and "blank.png: board not found" in run.notes[0]
    assert "blank.png" not in {r["image"] for r in _rows(root / "data.csv")}


def test_the_command_writes_the_csv_and_lists_the_skipped_image(scene, tmp_path, capsys):
    root, folder, names, _ = scene
    out = tmp_path / "out.csv"
    code = main(["detect", str(folder), "--board", SPEC.text, "--joints", str(root / "joints.csv"), "--out", str(out)])
    captured = capsys.readouterr()
    assert code == 0
    assert out.read_text() == (root / "data.csv").read_text()
    assert "blank.png: board not found" in captured.err
    assert "found in 3 image(s)" in captured.out and f"wrote {out}" in captured.out


def _refused(capsys, argv, out):
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2 and not out.exists()
    assert "Traceback" not in err and err.count("\n") == 1, err
    return err


def test_bad_inputs_are_one_line_and_write_nothing(scene, tmp_path, capsys):
    root, folder, names, _ = scene
    out = tmp_path / "out.csv"
    one = ["detect", str(folder / names[0])]
    joints = tmp_path / "joints.csv"
    _write_joints(joints, names[:1])
    base = ["--joints", str(joints), "--out", str(out)]
    err = _refused(capsys, [*one, str(folder / names[1]), "--board", SPEC.text, *base], out)
    assert f"{folder / names[1]}: no row of {joints} names this image" in err
    err = _refused(capsys, [*one, "--board", SPEC.text, "--joints", str(root / "joints.csv"), "--out", str(out)], out)
    assert "line 3, column 'image': 'view_1.png' is none of the 1 image(s) given" in err
    err = _refused(capsys, [*one, "--board", "charuco:7x5:0.04:DICT_5X5_100", *base], out)
    assert "expected charuco:COLSxROWS:SQUARE_M:MARKER_M:DICT" in err and "e.g. charuco:7x5:0.04:0.03" in err
    err = _refused(capsys, [*one, "--board", "charuco:7x5:0.04:0.03:DICT_4X4_50", *base], out)
    assert "the board is found in none of the 1 image(s)" in err and "7x5 is not 5x7" in err
    err = _refused(capsys, [*one, "--board", "charuco:5x7:0.04:0.03:DICT_5X5_100", *base], out)  # counted wrongly
    assert "found in none of the 1 image(s) (markers found: 17 at most)" in err and "5x7 is not 7x5" in err
    broken = tmp_path / "view_0.png"
    broken.write_text("not a picture")
    err = _refused(capsys, ["detect", str(broken), "--board", SPEC.text, *base], out)
    assert f"{broken}: not an image OpenCV can decode" in err


def test_main_refusals_are_the_whole_line(capsys, tmp_path):
    """The argument list's own refusals: each a one-line error naming the spec."""
    for argv in (["detect", "x.png"], ["detect"]):
        with pytest.raises(SystemExit):
            main(argv)
    capsys.readouterr()
    for text, message in [("charuco:7x5:0.04:0.05:DICT_5X5_100", "marker side must be positive and smaller"),
                          ("charuco:7x5:0.04:0.03:DICT_5X5_10", "unknown dictionary 'DICT_5X5_10'"),
                          ("charuco:15x15:0.04:0.03:DICT_4X4_50", "needs 112 markers but DICT_4X4_50 holds 50"),
                          ("charuco:7x5:40:30:DICT_5X5_100", "looks like millimetres")]:
        with pytest.raises(MeasurementError, match=message):
            parse_board(text)


def test_dictionary_sizes_are_opencvs():
    for name, size in DICTIONARY_SIZES.items():
        assert cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name)).bytesList.shape[0] == size


def test_corner_positions_are_opencvs():
    spec = parse_board("charuco:5x8:0.03:0.022:dict_4x4_50")
    opencv = cv2.aruco.CharucoBoard((5, 8), 0.03, 0.022, cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50))
    mine = np.array([[*spec.corner_position(k), 0.0] for k in range(spec.n_corners)])
    np.testing.assert_allclose(mine, opencv.getChessboardCorners(), atol=1e-7)


def test_the_csv_reads_back_one_configuration_per_image(scene):
    root, _, names, run = scene
    joints = [JointSpec("shoulder", "revolute"), JointSpec("elbow", "revolute")]
    data, notes = read_corners(root / "data.csv", joints)
    assert notes == [] and data.images == tuple(names[:3])
    np.testing.assert_array_equal(data.q, [[0.0, 0.5], [0.1, 0.3], [0.2, 0.1]])
    assert list(data.roles) == ["calibration", "validation", "calibration"] and set(data.sessions) == {"data"}
    for k, image in enumerate(run.images[1:]):  # blank.png first, by name, and skipped
        mine = data.image_of == k
        np.testing.assert_array_equal(data.corners[mine], image.detection.ids)
        np.testing.assert_allclose(data.pixels[mine], image.detection.pixels, atol=5e-5)  # written to 1e-4 px
    np.testing.assert_array_equal(data.sizes, [[640, 480]] * 3)


@pytest.mark.parametrize(("line", "column", "value", "message"), [
    (3, "elbow", "0.4", "image 'view_0.png' has 0.4 here but 0.500 at line 2; the rows of one image share its elbow"),
    (3, "corner", "0", "corner 0 of image 'view_0.png' given again (first at line 2)"),
    (2, "u", "700", "corner at (700, "),
    (2, "shoulder", "45", "looks like degrees"),
])
def test_a_csv_whose_rows_disagree_is_refused(scene, tmp_path, line, column, value, message):
    root = scene[0]
    with open(root / "data.csv", newline="") as handle:
        rows = list(csv.reader(handle))
    rows[line - 1][rows[0].index(column)] = value
    edited = tmp_path / "edited.csv"
    with open(edited, "w", newline="") as handle:
        csv.writer(handle).writerows(rows)
    joints = [JointSpec("shoulder", "revolute"), JointSpec("elbow", "revolute")]
    with pytest.raises(MeasurementError, match=re.escape(f"{edited}: line {line}")) as caught:
        read_corners(edited, joints)
    assert message in str(caught.value)


def _image_bag(path, scene_images, offset):
    """A rosbag2 (sqlite3) of a JointState topic at 25 Hz and a camera at 1 Hz, mono8 on /camera/image_raw and
    PNG on /camera/compressed: three stops of 3 s (each showing one of ``scene_images``) with 1 s moves
    between them (encoder noise 1e-5 rad), a grey image while moving; camera stamps ``offset`` s ahead of the joints' clock, both
    received 10 ms after their stamp on the joints' clock."""
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.LATEST)
    types = store.types
    stops = [(4.0 * k + 1.0, 4.0 * k + 4.0) for k in range(3)]  # on the joint clock [s]
    targets = np.array([[0.1, 0.5], [0.3, 0.2], [-0.2, 0.4]])

    def posture(t):
        for k, (start, end) in enumerate(stops):
            if start <= t <= end:
                return targets[k], k
            if k + 1 < len(stops) and end < t < stops[k + 1][0]:
                a = (t - end) / (stops[k + 1][0] - end)
                return targets[k] + a * (targets[k + 1] - targets[k]), None
        return (targets[0], None) if t < stops[0][0] else (targets[-1], None)

    def header(t):
        sec = int(np.floor(t))
        return types["std_msgs/msg/Header"](stamp=types["builtin_interfaces/msg/Time"](
            sec=sec, nanosec=int(round((t - sec) * 1e9))), frame_id="camera")

    grey = np.full((480, 640), 128, np.uint8)
    messages = []
    rng = np.random.default_rng(7)
    for t in np.arange(0.04, 13.0, 0.04):  # a zero stamp would be read as unset
        q = posture(t)[0] + rng.normal(0.0, 1e-5, 2)  # encoder noise [rad]
        messages.append((t + 0.01, "/joint_states", "sensor_msgs/msg/JointState", types["sensor_msgs/msg/JointState"](
            header=header(t), name=list(JOINTS), position=q, velocity=np.zeros(0), effort=np.zeros(0))))
    for t in np.arange(0.1, 13.0, 1.0):
        _, k = posture(t)
        image = grey if k is None else scene_images[k]
        padded = np.pad(image, ((0, 0), (0, 8)))  # rows of 648 bytes: a step beyond the width
        messages.append((t + 0.01, "/camera/image_raw", "sensor_msgs/msg/Image", types["sensor_msgs/msg/Image"](
            header=header(t + offset), height=480, width=640, encoding="mono8", is_bigendian=0, step=648,
            data=padded.ravel())))
        png = cv2.imencode(".png", image)[1].ravel()
        messages.append((t + 0.01, "/camera/compressed", "sensor_msgs/msg/CompressedImage",
                         types["sensor_msgs/msg/CompressedImage"](header=header(t + offset), format="png", data=png)))
    messages.sort(key=lambda m: m[0])
    with Writer(path, version=Writer.VERSION_LATEST) as writer:
        connections = {}
        for received, topic, msgtype, message in messages:
            if topic not in connections:
                connections[topic] = writer.add_connection(topic, msgtype, typestore=store)
            writer.write(connections[topic], int(round(received * 1e9)), store.serialize_cdr(message, msgtype))
    return targets


@pytest.fixture(scope="module")
def image_bag(scene, tmp_path_factory):
    """The bag of :func:`_image_bag` showing the scene's three views, the joints' stops and the views."""
    _, folder, names, _ = scene
    shown = [cv2.imread(str(folder / name), cv2.IMREAD_GRAYSCALE) for name in names[:3]]
    bag = tmp_path_factory.mktemp("bag") / "session"
    return bag, _image_bag(bag, shown, offset=1.5), shown  # a sign slip would take images of the moves


@pytest.mark.parametrize("topic", ["/camera/image_raw", "/camera/compressed"])
def test_extract_saves_each_stops_image_for_detect(image_bag, tmp_path, capsys, topic):
    bag, targets, shown = image_bag
    out = tmp_path / "joints.csv"
    assert main(["extract", str(bag), "--joints", "/joint_states", "--image", topic, "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "clock offset: " + topic + " stamps - /joint_states stamps = +1.5000 s" in printed
    readings = _rows(out)
    assert [r["image"] for r in readings] == ["image_000.png", "image_001.png", "image_002.png"]
    # averaged over the 2 s window (50 readings of sigma 1e-5 rad): within 4 sigma / sqrt(50) = 5.7e-6 rad
    np.testing.assert_allclose([[float(r[j]) for j in JOINTS] for r in readings], targets, atol=5.7e-6)
    for r, image in zip(readings, shown):  # the image of the stop, as it was recorded
        np.testing.assert_array_equal(cv2.imread(str(tmp_path / "joints_images" / r["image"]), 0), image)
    data = tmp_path / "data.csv"
    assert main(["detect", str(tmp_path / "joints_images"), "--board", SPEC.text, "--joints", str(out),
                 "--out", str(data)]) == 0
    assert len(_rows(data)) == 3 * SPEC.n_corners


@pytest.mark.parametrize(("encoding", "channels", "convert"), [
    ("rgb8", 3, cv2.COLOR_RGB2GRAY), ("bgra8", 4, cv2.COLOR_BGRA2GRAY), ("mono16", 1, None)])
def test_raw_images_are_read_in_grey(encoding, channels, convert):
    rng = np.random.default_rng(1)
    depth = 2 if encoding == "mono16" else 1
    pixels = rng.integers(0, 256 ** depth, (4, 5, channels)).astype(np.uint16 if depth == 2 else np.uint8)
    data = np.pad(pixels.reshape(4, -1).view(np.uint8), ((0, 0), (0, 3)))  # little-endian rows, 3 bytes of padding
    message = SimpleNamespace(encoding=encoding, height=4, width=5, step=data.shape[1], is_bigendian=0,
                              data=data.ravel())
    stream = ImageStream("/camera", IMAGE, np.zeros(1), np.zeros(1), (message,))
    expected = (pixels[:, :, 0] >> 8).astype(np.uint8) if depth == 2 else cv2.cvtColor(pixels, convert)
    np.testing.assert_array_equal(stream.image(0), expected)


def test_extract_refuses_a_folder_with_images_it_would_not_replace(image_bag, tmp_path, capsys):
    """A rerun into the same folder replaces its images; a folder holding more of an earlier run's, which
    detect would take for this one's, is refused with nothing written."""
    bag, _, _ = image_bag
    out, folder = tmp_path / "joints.csv", tmp_path / "joints_images"
    args = ["extract", str(bag), "--joints", "/joint_states", "--image", "/camera/image_raw", "--out", str(out)]
    assert main(args) == 0 and main(args) == 0  # the same names again
    (folder / "image_007.png").write_bytes((folder / "image_000.png").read_bytes())
    out.unlink()
    capsys.readouterr()
    assert main(args) == 2
    assert "image_007.png" in capsys.readouterr().err and not out.exists()
