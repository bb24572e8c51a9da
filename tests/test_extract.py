"""``pincal extract``: ROS bags in, the static postures out as CSV v1 (pincal.measurements.bags, .plateaus).

Every bag here is written with rosbags from a simulated session (pincal.simulation.recording): a
KUKA LWR 4+ in its true geometry (Table 1 + Table 2's large deviations) visits random postures,
joints at 100 Hz (1e-5 rad noise), a tracker at 100 Hz (0.05 mm, 0.1 mrad noise) on a clock
0.3456 s behind, received 2 and 12 ms late with jitter. Bounds are stated where they are used;
n ~ 200 samples per averaging window (2 s at 100 Hz).
"""

from __future__ import annotations

import csv
import json
from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pincal.cli.commands import main
from pincal.errors import MeasurementError
from pincal.measurements.bags import POINT, TF, TRANSFORM, read_bag, write_bag
from pincal.measurements.csv_v1 import write_measurements
from pincal.measurements.plateaus import PlateauSettings, extract_postures, still_stretches
from pincal.model.chain import KinematicChain
from pincal.model.dh.table import KUKA_LWR4_DH, TABLE2_LARGE
from pincal.robots import KUKA_FLANGE_LINK, kuka_lwr4plus_urdf
from pincal.simulation.recording import RecordingSettings, SessionEvents, simulate_recording
from pincal.simulation.sensor import DEFAULT_REGISTRATION, SimulatedSensor, measure, random_configurations

OFFSET = -0.3456  # tracker stamp - joint stamp [s]: more than the 0.5 s trim away from its opposite
SETTINGS = RecordingSettings(clock_offset_s=OFFSET, seed=5)
PERIOD = 1 / SETTINGS.tracker_rate_hz
SHORT, SHAKEN, DROPPED = 3, 5, 7  # postures: held 1 s, target shaken by 3 mm, tracker silent
#: Recovered values are within this many standard errors (sigma / sqrt(n)) of the truth.
FACTOR = 5.0
DATA = kuka_lwr4plus_urdf().parents[2] / "data"


@pytest.fixture(scope="module")
def chain():
    return KinematicChain.from_urdf(kuka_lwr4plus_urdf(), KUKA_FLANGE_LINK)


def _record(chain, postures, settings=SETTINGS, **options):
    with chain.placed(TABLE2_LARGE.apply(KUKA_LWR4_DH).joint_origins()):
        return simulate_recording(chain, postures, DEFAULT_REGISTRATION, settings, **options)


@pytest.fixture(scope="module")
def awkward(chain):
    """12 postures, a pose stream; a short stop, a shaken target, a dropout that leaves 4 samples
    in a window, and every other quaternion sign-flipped (q and -q: the same rotation)."""
    start = DROPPED * (SETTINGS.hold_s + SETTINGS.move_s) - (SETTINGS.hold_s - 1.0)  # after the short stop
    dropout = (start, start + SETTINGS.hold_s - 0.54)  # the averaging window ends 0.49 s before the hold does
    recording = _record(chain, random_configurations(chain, np.random.default_rng(11), 12), pose=True,
                        events=SessionEvents(holds={SHORT: 1.0}, shaken={SHAKEN: 0.003}, dropouts=[dropout]))
    pose = recording.measurements[0]
    signs = np.where(np.arange(len(pose.stamps)) % 2, -1.0, 1.0)[:, None]
    return replace(recording, measurements=[replace(pose, quaternions=pose.quaternions * signs)])


def _bag(tmp_path, recording, storage="ros1", measurements=None, **options):
    path = tmp_path / ("session.bag" if storage == "ros1" else "session")
    write_bag(path, recording.joints, recording.measurements if measurements is None else measurements, storage,
              **options)
    return path


@pytest.mark.parametrize("storage", ["sqlite3", "mcap", "ros1"])
def test_a_bag_reads_back_what_was_written(storage, awkward, tmp_path):
    """Joints named in a shuffled order per message come back by name; stamps to the nanosecond."""
    path = _bag(tmp_path, awkward, storage, shuffle_seed=1, compress=storage != "sqlite3")
    assert [p.name for p in tmp_path.iterdir()] == [path.name]  # written in a staging folder, renamed into place
    paths = [path, path / "session.mcap"] if storage == "mcap" else [path]  # a lone .mcap file reads too
    for given in paths:
        joints, (pose,) = read_bag(given, "/joint_states", ["/tracker/pose"], pose=True)
        written, written_pose = awkward.joints, awkward.measurements[0]
        order = [joints.names.index(name) for name in written.names]
        assert joints.clock == pose.clock == "header" and joints.skipped == pose.dropped == 0
        assert np.array_equal(joints.positions[:, order], written.positions)
        assert np.abs(joints.stamps - written.stamps).max() < 1e-6  # 1 ns, in float64 at 1.7e9 s
        assert np.abs(pose.stamps - written_pose.stamps).max() < 1e-6
        assert np.abs(pose.received - written_pose.received).max() < 1e-6
        assert np.array_equal(pose.positions, written_pose.positions) and pose.frame == "tracker"
        assert np.allclose(pose.quaternions, written_pose.quaternions, rtol=0, atol=1e-15)


def test_joints_from_several_publishers_on_one_topic_are_held_until_their_next_message(tmp_path):
    """An arm (two joints) and a gripper publish on /joint_states in turn, the gripper with the arm's
    last stamp; a message whose names and positions differ in length is skipped; a PointStamped
    topic beside them loses its NaN samples."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    types = store.types

    def header(k: int):  # the gripper stamps as the arm's message before it
        stamp = types["builtin_interfaces/msg/Time"](sec=100, nanosec=(k - k % 2) * 10**7)
        return types["std_msgs/msg/Header"](seq=k, stamp=stamp, frame_id="tracker")

    with Writer(tmp_path / "split.bag") as writer:
        joints = writer.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=store)
        point = writer.add_connection("/marker", POINT, typestore=store)
        for k in range(6):
            names, values = (["arm_2", "arm_1"], [0.2 + k, 0.1 + k]) if k % 2 == 0 else (["finger"], [0.01 * k])
            if k == 3:
                values = []  # an effort-only message
            message = types["sensor_msgs/msg/JointState"](header=header(k), name=names, position=np.array(values),
                                                          velocity=np.zeros(0), effort=np.zeros(0))
            writer.write(joints, 10**11 + k * 10**7, store.serialize_ros1(message, "sensor_msgs/msg/JointState"))
            marker = types[POINT](header=header(k), point=types["geometry_msgs/msg/Point"](
                x=k, y=0.0, z=np.nan if k % 2 else 0.0))
            writer.write(point, 10**11 + k * 10**7, store.serialize_ros1(marker, POINT))
    joints, (marker,) = read_bag(tmp_path / "split.bag", "/joint_states", ["/marker"], pose=False)
    # skipped: k = 0 (before the finger was read), 3 (no positions), 4 (the finger's k = 5 has its stamp)
    assert joints.names == ("arm_2", "arm_1", "finger") and joints.skipped == 3
    assert np.allclose(joints.positions, [[0.2, 0.1, 0.01], [2.2, 2.1, 0.01], [4.2, 4.1, 0.05]])
    assert np.allclose(joints.stamps, 100 + np.array([0, 2, 4]) * 0.01)
    assert marker.dropped == 3 and np.array_equal(marker.positions[:, 0], [0, 2, 4]) and marker.frame == "tracker"


def test_static_postures_offset_and_refusals_are_recovered(awkward, tmp_path):
    joints, streams = read_bag(_bag(tmp_path, awkward, shuffle_seed=2), "/joint_states", ["/tracker/pose"], pose=True)
    extraction = extract_postures(joints, streams)
    # the offset: within a tenth of the tracker's 10 ms sample period (measured: 0.17 ms)
    assert abs(extraction.offset.seconds - OFFSET) < PERIOD / 10
    assert extraction.offset.estimated and extraction.offset.edges >= 18
    holds = awkward.holds
    reasons = {}
    for refusal in extraction.refused:
        posture = int(np.argmin(np.abs(holds[:, 0] - refusal.start)))
        assert abs(refusal.start - holds[posture, 0]) < 0.2 and abs(refusal.end - holds[posture, 1]) < 0.2
        reasons[posture] = refusal.reason
    assert reasons == {SHORT: "too short", SHAKEN: "moving", DROPPED: "too few samples"}
    kept = [k for k in range(len(holds)) if k not in reasons]
    data = extraction.data
    assert data is not None and data.n_rows == len(kept) and extraction.stretches == len(kept) + 2
    order = [joints.names.index(name) for name in awkward.joints.names]
    n = data.extra["samples"]
    assert np.all(n >= 190)  # 2 s windows at 100 Hz
    # joints and positions: within FACTOR standard errors of the truth, rotations likewise (3 angles)
    assert np.all(np.abs(data.q[:, order] - awkward.postures[kept]) < FACTOR * SETTINGS.joint_noise / np.sqrt(190))
    error = np.abs(data.points[:, 0] - awkward.truth[kept, 0])
    assert np.all(error < FACTOR * SETTINGS.tracker_noise_m / np.sqrt(n)[:, None])
    assert awkward.rotations is not None and data.rotations is not None
    angle = Rotation.from_matrix(data.rotations.transpose(0, 2, 1) @ awkward.rotations[kept]).magnitude()
    assert np.all(angle < FACTOR * np.sqrt(3) * SETTINGS.tracker_noise_rad / np.sqrt(n))
    # the spread column: sqrt(3) sigma [mm] for a point held still (to 15 %)
    assert np.allclose(data.extra["spread_mm"], np.sqrt(3) * SETTINGS.tracker_noise_m * 1000, rtol=0.15)
    windows = np.column_stack([data.extra["t_start_robot"], data.extra["t_end_robot"]])
    assert np.all(windows[:, 0] >= holds[kept, 0] + 0.4) and np.all(windows[:, 1] <= holds[kept, 1] - 0.4)


def test_still_stretches_and_short_stops():
    """Still 0-3 s, a 1 s ramp, still 4-4.5 s, a ramp, still 5.5-8 s (100 Hz, noise 1e-5)."""
    t = np.arange(0, 8, 0.01)
    q = np.interp(t, [0, 3, 4, 4.5, 5.5, 8], [0, 0, 0.5, 0.5, 1.0, 1.0])
    q = np.column_stack([q, -q]) + np.random.default_rng(0).normal(0, 1e-5, (len(t), 2))
    long = [(t[a], t[b]) for a, b in still_stretches(t, q, 1e-3, 2.0)]
    short = [(t[a], t[b]) for a, b in still_stretches(t, q, 1e-3, 0.4)]
    assert np.allclose(long, [(0, 3), (5.5, 7.99)], atol=0.011)
    assert np.allclose(short, [(0, 3), (4, 4.5), (5.5, 7.99)], atol=0.011)


def test_markers_as_points_topics_and_tf_frames_in_the_order_given(chain, tmp_path, capsys):
    """Three markers: a PointStamped topic, a tf frame, a TransformStamped topic -> x1..z3 in that order;
    --joint-names keeps a subset in its order; --clock-offset is used as given."""
    markers = np.array([[0.05, 0.0, 0.07], [0.07, 0.0, -0.08], [0.16, 0.0, -0.05]])
    recording = _record(chain, random_configurations(chain, np.random.default_rng(3), 5), points=markers)
    first, second, third = recording.measurements
    streams = [replace(second, topic="tf:marker2", msgtype=TF), first, replace(third, msgtype=TRANSFORM)]
    bag = _bag(tmp_path, recording, "sqlite3", streams)
    out = tmp_path / "markers.csv"
    names = "lwr_joint_7,lwr_joint_1,lwr_joint_2,lwr_joint_3,lwr_joint_4,lwr_joint_5,lwr_joint_6"
    assert main(["extract", str(bag), "--joints", "/joint_states", "--point", "/tracker/marker1", "--point",
                 "tf:marker2", "--point", "/tracker/marker3", "--joint-names", names, "--clock-offset", str(OFFSET),
                 "--out", str(out)]) == 0
    assert f"= {OFFSET:+.4f} s (--clock-offset)" in capsys.readouterr().out
    with out.open(encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle))
    assert list(rows[0])[:16] == names.split(",") + [f"{a}{p}" for p in (1, 2, 3) for a in "xyz"]
    assert len(rows) == 5 and POINT == first.msgtype
    found = np.array([[[float(row[f"{a}{p}"]) for a in "xyz"] for p in (1, 2, 3)] for row in rows])
    assert np.all(np.abs(found - recording.truth) < FACTOR * SETTINGS.tracker_noise_m / np.sqrt(190))


def test_unset_header_stamps_fall_back_to_receive_times(chain, tmp_path, capsys):
    recording = _record(chain, random_configurations(chain, np.random.default_rng(4), 4))
    marker = recording.measurements[0]
    bag = _bag(tmp_path, recording, "mcap", [replace(marker, stamps=np.zeros_like(marker.stamps))])
    assert main(["extract", str(bag), "--joints", "/joint_states", "--point", marker.topic,
                 "--out", str(tmp_path / "d.csv")]) == 0
    out, err = capsys.readouterr()
    assert f"{marker.topic}: stamps are not set; the recorder's receive times are used" in err
    # receive time - joint stamp: the tracker's 12 ms delay and its jitter (mean 2 ms)
    offset = float(out.split(" stamps = ")[1].split(" s")[0])
    assert abs(offset - (SETTINGS.tracker_delay_s + SETTINGS.jitter_s)) < 0.003


def test_bag_to_calibrate_to_evaluate_matches_the_csv_it_was_made_from(chain, tmp_path, capsys):
    """The done-when of the issue: 30 postures of a pose tracker as a bag (MCAP) and as the CSV of
    their noise-free measurements; both calibrated (level full) and evaluated on 20 held-out rows.
    The CSV fits to 0; the bag to its averaging noise, sigma / sqrt(n) = 0.05 mm / sqrt(150) =
    0.004 mm per axis: its held-out RMS position error must stay under 0.02 mm (measured 0.004),
    its rotation error under 0.005 deg (measured 0.0005)."""
    rng = np.random.default_rng(7)
    postures, held_out = random_configurations(chain, rng, 30), random_configurations(chain, rng, 20)
    settings = replace(SETTINGS, hold_s=2.5, move_s=1.0)
    recording = _record(chain, postures, settings, pose=True)
    with chain.placed(TABLE2_LARGE.apply(KUKA_LWR4_DH).joint_origins()):
        write_measurements(tmp_path / "source.csv", measure(chain, postures, DEFAULT_REGISTRATION, rng,
                                                            SimulatedSensor(0, 0), "calibration"))
        write_measurements(tmp_path / "held_out.csv", measure(chain, held_out, DEFAULT_REGISTRATION, rng,
                                                              SimulatedSensor(0, 0), "validation"))
    bag = _bag(tmp_path, recording, "mcap")
    assert main(["extract", str(bag), "--joints", "/joint_states", "--pose", "/tracker/pose",
                 "--out", str(tmp_path / "bag.csv")]) == 0
    errors = {}
    for name in ("source", "bag"):
        urdf, report, metrics = (tmp_path / f"{name}{suffix}" for suffix in (".urdf", ".json", "_eval.json"))
        assert main(["calibrate", str(kuka_lwr4plus_urdf()), str(tmp_path / f"{name}.csv"), "--tip-link",
                     KUKA_FLANGE_LINK, "--out", str(urdf), "--report", str(report), "--quiet"]) == 0
        assert main(["evaluate", str(urdf), str(report), str(tmp_path / "held_out.csv"), "--json", str(metrics)]) == 0
        errors[name] = json.loads(metrics.read_text(encoding="utf-8"))
    capsys.readouterr()
    assert errors["source"]["position"]["rms_mm"] < 1e-5
    assert abs(errors["bag"]["position"]["rms_mm"] - errors["source"]["position"]["rms_mm"]) < 0.02
    assert abs(errors["bag"]["orientation"]["rms_deg"] - errors["source"]["orientation"]["rms_deg"]) < 0.005


def _only_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("pincal: error: "), err
    return err[0]


@pytest.fixture(scope="module")
def small_bag(chain, tmp_path_factory):
    """4 postures: /joint_states, a pose topic, a point topic and a tf frame 'tool'."""
    recording = _record(chain, random_configurations(chain, np.random.default_rng(6), 4), pose=True)
    pose = recording.measurements[0]
    streams = [pose, replace(pose, topic="/tracker/point", msgtype=POINT), replace(pose, topic="tf:tool", msgtype=TF)]
    return _bag(tmp_path_factory.mktemp("small"), recording, "sqlite3", streams)


@pytest.mark.parametrize("arguments, message", [
    (["--joints", "/joint_state", "--pose", "/tracker/pose"], "--joints /joint_state: no such topic; did you mean "
                                                               "'/joint_states'?"),
    (["--joints", "/joint_states", "--pose", "/tracker/point"], "--pose /tracker/point: message type "
                                                                "geometry_msgs/msg/PointStamped; --pose reads "
                                                                "PoseStamped, TransformStamped"),
    (["--joints", "/tracker/pose", "--point", "/tracker/point"], "message type geometry_msgs/msg/PoseStamped"),
    (["--joints", "/joint_states", "--pose", "tf:tol"], "no transform to frame 'tol' on the tf topics; did you "
                                                        "mean 'tool'?"),
    (["--joints", "/joint_states", "--pose", "/tracker/pose", "--joint-names", "lwr_joint_1,lwr_jont_2"],
     "no joint 'lwr_jont_2' on /joint_states; did you mean 'lwr_joint_2'?"),
    (["--joints", "/joint_states", "--pose", "/tracker/pose", "--trim", "1"], "--trim 1 s leaves nothing"),
    (["--joints", "/joint_states", "--pose", "/tracker/pose", "--min-still", "10"], "no static posture left"),
    (["--joints", "/joint_states", "--pose", "/tracker/pose", "--max-offset", "0.001"], "edge of the search range"),
    (["--joints", "/joint_states", "--point", "/tracker/point", "--point", "/tracker/point"], "given twice"),
    (["--joints", "/joint_states", "--pose", "/tracker/pose", "--joint-names", "lwr_joint_1,lwr_joint_1"],
     "'lwr_joint_1' named twice"),
    (["--joints", "/joint_states", "--pose", "/tracker/pose", "--max-offset", "1e9"], "longer than the recording"),
    (["--joints", "/joint_states", "--pose", "/tf"], "message type tf2_msgs/msg/TFMessage; --pose reads PoseStamped, "
                                                     "TransformStamped or tf:CHILD (a tf topic: name a frame of it"),
])
def test_bad_input_is_one_line_and_writes_nothing(small_bag, tmp_path, capsys, arguments, message):
    out = tmp_path / "d.csv"
    assert main(["extract", str(small_bag), *arguments, "--out", str(out)]) == 2
    captured = capsys.readouterr()
    error = [line for line in captured.err.splitlines() if line.startswith("pincal: error: ")]
    assert len(error) == 1 and message in error[0], captured.err
    assert not out.exists()


def test_a_missing_bag_a_csv_and_an_output_over_the_bag_are_refused(small_bag, tmp_path, capsys):
    args = ["--joints", "/joint_states", "--pose", "/tracker/pose", "--out"]
    assert main(["extract", str(tmp_path / "nope"), *args, str(tmp_path / "d.csv")]) == 2
    assert "no such file or folder" in _only_line(capsys)
    (tmp_path / "rows.csv").write_text("a,b\n1,2\n", encoding="utf-8")
    assert main(["extract", str(tmp_path / "rows.csv"), *args, str(tmp_path / "d.csv")]) == 2
    assert "not a readable ROS bag" in _only_line(capsys)
    metadata = small_bag / "metadata.yaml"
    before = metadata.read_bytes()
    assert main(["extract", str(small_bag), *args, str(metadata)]) == 2
    assert "is an input of this run" in _only_line(capsys) and metadata.read_bytes() == before


def test_the_shipped_bag_gives_what_its_readme_states(tmp_path, capsys):
    """data/lwr_bag: the offset, rows and refusals of its README, and calibrate -> evaluate at the noise."""
    out = tmp_path / "lwr.csv"
    assert main(["extract", str(DATA / "lwr_bag" / "session"), "--joints", "/joint_states", "--pose",
                 "/mocap/tool/pose", "--out", str(out)]) == 0
    printed, refused = capsys.readouterr()
    assert "= +0.1800 s, from the motion" in printed and "11 still stretches of >= 2 s" in printed
    assert "10 rows; refused: 1 too short, 0 too few samples, 1 moving" in printed
    assert "too short: still for 1.00 s" in refused and "moving: measured positions spread 1.79" in refused
    urdf, report = tmp_path / "lwr.urdf", tmp_path / "REPORT.json"
    assert main(["calibrate", str(kuka_lwr4plus_urdf()), str(out), "--tip-link", KUKA_FLANGE_LINK, "--out",
                 str(urdf), "--report", str(report), "--quiet"]) == 0
    assert main(["evaluate", str(urdf), str(report), str(DATA / "lwr_bag" / "validation.csv"), "--json",
                 str(tmp_path / "e.json")]) == 0
    assert json.loads((tmp_path / "e.json").read_text(encoding="utf-8"))["position"]["rms_mm"] < 0.02


@pytest.mark.parametrize("where", [0.4, 0.6])  # seen: ZstdError at 0.4, OverflowError at 0.6
def test_a_corrupt_bag_is_one_line(tmp_path, capsys, where):
    """Two bytes of the shipped MCAP flipped part-way: decoding fails inside rosbags or zstd (ZstdError,
    struct.error, OverflowError), reported as an unreadable bag, not a traceback."""
    import shutil

    folder = tmp_path / "session"
    shutil.copytree(DATA / "lwr_bag" / "session", folder)
    mcap = folder / "session.mcap"
    raw = bytearray(mcap.read_bytes())
    at = int(where * len(raw))
    raw[at] ^= 0xFF
    raw[at + 1] ^= 0xFF
    mcap.write_bytes(bytes(raw))
    code = main(["extract", str(folder), "--joints", "/joint_states", "--pose", "/mocap/tool/pose",
                 "--out", str(tmp_path / "d.csv")])
    captured = capsys.readouterr()
    errors = [line for line in captured.err.splitlines() if line.startswith("pincal: error: ")]
    assert code == 2 and "Traceback" not in captured.err
    assert len(errors) == 1 and "not a readable ROS bag" in errors[0], captured.err


@pytest.mark.parametrize("name", ["x", "role", "spread_mm"])
def test_a_joint_named_as_a_column_is_refused(chain, tmp_path, capsys, name):
    """A JointState joint called like a column the rows are written with would write a CSV with two
    columns of that name (seen: exit 0): refused, naming the joint and --joint-names."""
    recording = _record(chain, random_configurations(chain, np.random.default_rng(6), 4), pose=True)
    names = (name, *recording.joints.names[1:])
    bag = _bag(tmp_path, replace(recording, joints=replace(recording.joints, names=names)), "sqlite3")
    out = tmp_path / "d.csv"
    assert main(["extract", str(bag), "--joints", "/joint_states", "--pose", recording.measurements[0].topic,
                 "--out", str(out)]) == 2
    assert f"joint '{name}' has the name of a column" in _only_line(capsys) and not out.exists()


def test_the_python_workflow_writes_what_the_command_writes(small_bag, tmp_path, capsys):
    """``pincal.extract_file`` (the job behind ``pincal extract``) writes the command's file byte for byte,
    prints nothing, and a recording that leaves no posture raises with nothing written."""
    from pincal import extract_file

    by_command, by_call = tmp_path / "command.csv", tmp_path / "call.csv"
    assert main(["extract", str(small_bag), "--joints", "/joint_states", "--pose", "/tracker/pose",
                 "--out", str(by_command)]) == 0
    capsys.readouterr()
    read, extraction = extract_file(small_bag, "/joint_states", ["/tracker/pose"], by_call, pose=True)
    assert capsys.readouterr() == ("", "")
    assert by_call.read_bytes() == by_command.read_bytes()
    assert extraction.data is not None and extraction.data.n_rows == 4 and read.joints.topic == "/joint_states"
    none = tmp_path / "none.csv"
    with pytest.raises(MeasurementError, match="no static posture left to write") as raised:
        extract_file(small_bag, "/joint_states", ["/tracker/pose"], none, PlateauSettings(min_still=10.0), pose=True)
    assert not none.exists()
    # what was read and each stop refused travel with the error: the command prints them before it
    assert raised.value.extraction.data is None and len(raised.value.extraction.refused) == 4  # type: ignore[attr-defined]
    assert raised.value.read.joints.topic == "/joint_states"  # type: ignore[attr-defined]


def test_a_cut_that_fails_says_what_was_read_first(small_bag, tmp_path, capsys):
    """A clock offset the motion cannot give stops the cut: the streams read are printed before the error,
    as for a recording with no posture (the error names the cause; nothing is written)."""
    from pincal.workflows.extract import CutFailed, extract_file

    out = tmp_path / "d.csv"
    assert main(["extract", str(small_bag), "--joints", "/joint_states", "--pose", "/tracker/pose",
                 "--max-offset", "0.001", "--out", str(out)]) == 2
    captured = capsys.readouterr()
    assert captured.out.startswith(f"read {small_bag}: /joint_states: ") and not out.exists()
    with pytest.raises(CutFailed, match="edge of the search range") as raised:
        extract_file(small_bag, "/joint_states", ["/tracker/pose"], out,
                     PlateauSettings(max_offset=0.001), pose=True)
    assert raised.value.read.joints.topic == "/joint_states"
