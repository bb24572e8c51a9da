"""ROS bags in and out: a ``sensor_msgs/JointState`` topic and measurement topics as arrays.

Read with `rosbags <https://gitlab.com/ternaris/rosbags>`_, which needs no ROS install: ROS 1
``.bag`` files, rosbag2 folders (``metadata.yaml`` with sqlite3 ``.db3`` or MCAP files) and a
single ``.db3`` or ``.mcap`` file. rosbags is imported inside the functions, so only ``pincal
extract`` pays for loading it.

A measurement is named by a topic or by ``tf:CHILD`` (the transforms to frame CHILD on every
``tf2_msgs/TFMessage`` topic but ``/tf_static``); its message type, read from the bag's connection
information, says how to read it: ``geometry_msgs/PoseStamped``, ``TransformStamped`` (position and
orientation) or ``PointStamped`` (position only).

Time: each message's ``header.stamp``, the time its source sampled it on the source's clock; a
stream whose stamps are not all set (zero) uses the times the recorder received its messages. The
receive times are kept too: they put the two clocks within a transport latency of each other
(:func:`pincal.measurements.plateaus.estimate_clock_offset`). Times are seconds (float64: 0.2 µs
resolution at Unix epoch values).

:func:`write_bag` writes such streams back (sqlite3, MCAP or ROS 1): the tests and
``scripts/make_example_bag.py`` make bags with it. Errors are one-line
:class:`~pincal.errors.MeasurementError`; this module never prints.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from pincal.errors import MeasurementError, did_you_mean

if TYPE_CHECKING:
    from rosbags.highlevel import AnyReader
    from rosbags.interfaces import Connection
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import Writer as Writer2
    from rosbags.typesys.store import Typestore

__all__ = [
    "JOINT_STATE", "POSE", "TRANSFORM", "POINT", "TF", "POSE_TYPES", "TF_PREFIX", "TF_STATIC", "STORAGES",
    "JointStream", "MeasurementStream", "read_bag", "write_bag",
]

JOINT_STATE = "sensor_msgs/msg/JointState"
POSE = "geometry_msgs/msg/PoseStamped"
TRANSFORM = "geometry_msgs/msg/TransformStamped"
POINT = "geometry_msgs/msg/PointStamped"
TF = "tf2_msgs/msg/TFMessage"
#: Topic types of a measurement that carry an orientation (``--pose``); ``--point`` also reads POINT.
#: A TF topic is read through ``tf:CHILD`` only (it carries many frames).
POSE_TYPES = (POSE, TRANSFORM)
#: ``--pose tf:CHILD`` / ``--point tf:CHILD``: a frame of the tf tree instead of a topic.
TF_PREFIX = "tf:"
#: tf topics not read for ``tf:CHILD``: static transforms do not move.
TF_STATIC = "/tf_static"
#: The storages :func:`write_bag` writes.
STORAGES = ("sqlite3", "mcap", "ros1")


@dataclass(frozen=True)
class JointStream:
    """Joint readings of one JointState topic, one row per message that completes a reading.

    Messages may name the joints in any order and each a subset (several publishers on one topic):
    every joint keeps its last value until its next message (zero-order hold); rows before every
    joint was seen once are dropped, of rows with one stamp only the last is kept, and a message
    whose ``position`` and ``name`` differ in length is skipped.

    Attributes:
        topic: the topic read.
        names: joint names (URDF joint names), in the order first seen, or as asked.
        stamps: (N,) time of each row [s], on the clock ``clock`` says.
        positions: (N, J) readings [rad; m for prismatic joints].
        received: (N,) the recorder's receive times [s].
        clock: ``"header"`` (header.stamp) or ``"receive"``.
        skipped: messages that gave no row (position and name of different length, before every
            joint was read, or stamped as the next message).
    """

    topic: str
    names: tuple[str, ...]
    stamps: np.ndarray
    positions: np.ndarray
    received: np.ndarray
    clock: str = "header"
    skipped: int = 0


@dataclass(frozen=True)
class MeasurementStream:
    """Samples of one measured frame or point, on the measuring system's clock.

    Attributes:
        topic: the topic read, or ``tf:CHILD``.
        msgtype: its message type (one of :data:`POSE_TYPES`, :data:`POINT`, or :data:`TF` for ``tf:CHILD``).
        stamps: (M,) sample times [s]; received: (M,) the recorder's receive times [s].
        positions: (M, 3) position in the frame ``frame`` [m].
        quaternions: (M, 4) orientation ``x, y, z, w``, or None (a point).
        frame: the header's ``frame_id`` (the sensor frame), of the first sample.
        clock: ``"header"`` or ``"receive"``.
        dropped: samples left out because a value was not finite (an occluded marker).
    """

    topic: str
    msgtype: str
    stamps: np.ndarray
    received: np.ndarray
    positions: np.ndarray
    quaternions: np.ndarray | None = None
    frame: str = ""
    clock: str = "header"
    dropped: int = 0


@dataclass
class _Samples:
    """Samples of one stream as they are read (lists, then arrays)."""

    stamps: list[float] = field(default_factory=list)
    received: list[float] = field(default_factory=list)
    values: list[Any] = field(default_factory=list)
    frame: str | None = None


def _seconds(stamp: Any) -> float:  # a builtin_interfaces/msg/Time, a class rosbags makes at run time
    return stamp.sec + stamp.nanosec * 1e-9


def _clock(samples: _Samples) -> tuple[np.ndarray, str]:
    """The stamps of a stream (header stamps if all are set, else receive times) and which they are."""
    stamps = np.asarray(samples.stamps, dtype=float)
    if stamps.size and np.all(stamps > 0):
        return stamps, "header"
    return np.asarray(samples.received, dtype=float), "receive"


def _reader(path: Path) -> tuple[AnyReader, tuple[type[Exception], ...]]:
    """A rosbags AnyReader on ``path`` (not yet open) and the errors rosbags raises on a bad bag."""
    from rosbags.highlevel import AnyReader, AnyReaderError
    from rosbags.serde import SerdeError
    from rosbags.typesys import Stores, TypesysError, get_typestore

    errors = (AnyReaderError, SerdeError, TypesysError, OSError, ValueError, EOFError)
    if not path.exists():
        raise MeasurementError(f"{path}: no such file or folder; give a ROS 1 .bag, a rosbag2 folder or a .mcap/.db3")
    try:  # bags without embedded definitions (sqlite3 before Iron) are read with the standard types
        return AnyReader([path], default_typestore=get_typestore(Stores.LATEST)), errors
    except errors as exc:
        raise MeasurementError(f"{path}: not a readable ROS bag ({' '.join(str(exc).split())})") from None


def _tf_child(spec: str) -> str | None:
    return spec[len(TF_PREFIX):].strip("/") if spec.startswith(TF_PREFIX) else None


def _connections(reader: AnyReader, path: Path, spec: str, flag: str, accepted: Sequence[str]) -> list[Connection]:
    """The connections of ``spec`` (a topic or tf:CHILD), their type checked against ``accepted``."""
    if _tf_child(spec) is not None:
        found = [c for c in reader.connections if c.msgtype == TF and c.topic != TF_STATIC]
        if not found:
            raise MeasurementError(f"{path}: {flag} {spec}: the bag has no tf topic (tf2_msgs/msg/TFMessage)")
        return found
    topics = {c.topic: c.msgtype for c in reader.connections}
    if spec not in topics:
        raise MeasurementError(f"{path}: {flag} {spec}: no such topic; {did_you_mean(spec, sorted(topics), 'topics')}")
    if topics[spec] not in accepted:
        names = ", ".join(t.rsplit("/", 1)[1] for t in accepted)
        hint = " (a tf topic: name a frame of it, tf:CHILD)" if topics[spec] == TF else ""
        raise MeasurementError(f"{path}: {flag} {spec}: message type {topics[spec]}; {flag} reads {names}"
                               + (" or tf:CHILD" if flag != "--joints" else "") + hint)
    return [c for c in reader.connections if c.topic == spec]


def _pose_of(message: Any, msgtype: str) -> tuple[Any, tuple[float, ...], tuple[float, ...] | None]:
    """(header, position, quaternion or None) of a PoseStamped, TransformStamped or PointStamped."""
    if msgtype == POINT:
        p = message.point
        return message.header, (p.x, p.y, p.z), None
    if msgtype == POSE:
        p, r = message.pose.position, message.pose.orientation
    else:
        p, r = message.transform.translation, message.transform.rotation
    return message.header, (p.x, p.y, p.z), (r.x, r.y, r.z, r.w)


def _joint_arrays(samples: _Samples, path: Path, topic: str,
                  wanted: Sequence[str] | None) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
    """Forward-filled (N, J) readings of the JointState samples ``(names, positions)``."""
    seen: dict[str, int] = {}
    for names, _ in samples.values:
        for name in names:
            seen.setdefault(name, len(seen))
    if wanted:
        twice = sorted({n for n in wanted if list(wanted).count(n) > 1})
        if twice:
            raise MeasurementError(f"{path}: --joint-names: '{twice[0]}' named twice; name each joint once")
        for name in wanted:
            if name not in seen:
                raise MeasurementError(f"{path}: --joint-names: no joint '{name}' on {topic}; "
                                       f"{did_you_mean(name, list(seen), 'joints')}")
    kept = list(wanted) if wanted else list(seen)
    column = {name: j for j, name in enumerate(kept)}
    table = np.full((len(samples.values), len(kept)), np.nan)
    last_names, index = None, (np.zeros(0, dtype=int), np.zeros(0, dtype=int))
    for k, (names, positions) in enumerate(samples.values):
        if names != last_names:
            pairs = [(i, column[n]) for i, n in enumerate(names) if n in column]
            index = (np.array([i for i, _ in pairs], dtype=int), np.array([j for _, j in pairs], dtype=int))
            last_names = names
        table[k, index[1]] = np.asarray(positions, dtype=float)[index[0]]
    rows = np.arange(len(table))[:, None]
    last = np.maximum.accumulate(np.where(np.isfinite(table), rows, -1), axis=0)  # zero-order hold
    filled = np.where(last >= 0, table[np.maximum(last, 0), np.arange(len(kept))], np.nan)
    complete = np.all(np.isfinite(filled), axis=1) if kept else np.zeros(len(table), dtype=bool)
    return tuple(kept), filled, complete


def read_bag(
    path: str | os.PathLike[str],
    joints_topic: str,
    measurements: Sequence[str],
    *,
    pose: bool,
    joint_names: Sequence[str] | None = None,
) -> tuple[JointStream, list[MeasurementStream]]:
    """Read a JointState topic and the measurement topics of a bag.

    Args:
        path: a ROS 1 ``.bag``, a rosbag2 folder, or a ``.mcap`` / ``.db3`` file.
        joints_topic: the ``sensor_msgs/JointState`` topic.
        measurements: topics or ``tf:CHILD`` frames, in column order.
        pose: ``True``: one pose (``--pose``, position and orientation); ``False``: points (``--point``).
        joint_names: the joints to keep (default: every joint the topic names).

    Raises:
        MeasurementError: an unreadable bag, a missing topic or frame (did you mean), a wrong message
            type, a joint never read, a stream with no usable sample.
    """
    path = Path(path)
    flag = "--pose" if pose else "--point"
    accepted = POSE_TYPES if pose else (*POSE_TYPES, POINT)
    repeated = sorted({spec for spec in measurements if list(measurements).count(spec) > 1})
    if repeated:
        raise MeasurementError(f"{flag} {repeated[0]}: given twice; name each topic once")
    if joints_topic in measurements:
        raise MeasurementError(f"{flag} {joints_topic}: is the --joints topic; name the measurement's topic")
    reader, errors = _reader(path)
    try:
        with reader:
            joints_samples, samples, tf_frames, joint_skips, msgtypes = _read_messages(
                reader, path, joints_topic, measurements, flag, accepted)
    except MeasurementError:
        raise
    except Exception as exc:  # rosbags' own errors, and a corrupt chunk's (zstd, struct, overflow) while decoding
        detail = " ".join(str(exc).split())  # one line
        raise MeasurementError(f"{path}: not a readable ROS bag ({type(exc).__name__}: {detail})") from None
    joints = _joint_stream(path, joints_topic, joints_samples, joint_names, joint_skips)
    out = []
    for spec in measurements:
        s = samples[spec]
        child = _tf_child(spec)
        if not s.values:
            if child is not None:
                raise MeasurementError(f"{path}: {flag} {spec}: no transform to frame '{child}' on the tf "
                                       f"topics; {did_you_mean(child, sorted(tf_frames), 'frames')}")
            raise MeasurementError(f"{path}: {flag} {spec}: the topic has no message")
        out.append(_measurement_stream(path, spec, msgtypes[spec], s, pose, flag))
    return joints, out


def _read_messages(reader: AnyReader, path: Path, joints_topic: str, measurements: Sequence[str], flag: str,
                   accepted: Sequence[str]) -> tuple[_Samples, dict[str, _Samples], set[str], int, dict[str, str]]:
    """The samples of the joint topic and of each measurement, read in one pass over the bag."""
    streams = {joints_topic: _connections(reader, path, joints_topic, "--joints", (JOINT_STATE,))}
    for spec in measurements:
        streams[spec] = _connections(reader, path, spec, flag, accepted)
    chosen = {c.id: c for conns in streams.values() for c in conns}
    samples: dict[str, _Samples] = {spec: _Samples() for spec in streams}
    children = {spec: _tf_child(spec) for spec in measurements}
    tf_frames: set[str] = set()
    joint_skips = 0
    for connection, received_ns, raw in reader.messages(connections=list(chosen.values())):
        message: Any = reader.deserialize(raw, connection.msgtype)  # of a class rosbags makes at run time
        received = received_ns * 1e-9
        if connection.msgtype == JOINT_STATE:
            if len(message.position) != len(message.name) or not message.name:
                joint_skips += 1
                continue
            s = samples[joints_topic]
            s.stamps.append(_seconds(message.header.stamp))
            s.received.append(received)
            s.values.append((tuple(message.name), message.position))
            continue
        for spec in measurements:
            child = children[spec]
            if child is None and connection.topic == spec:
                items = [(message, connection.msgtype)]
            elif child is not None and connection.msgtype == TF:
                tf_frames.update(t.child_frame_id.strip("/") for t in message.transforms)
                items = [(t, TRANSFORM) for t in message.transforms if t.child_frame_id.strip("/") == child]
            else:
                continue
            for item, kind in items:
                header, position, quaternion = _pose_of(item, kind)
                s = samples[spec]
                s.stamps.append(_seconds(header.stamp))
                s.received.append(received)
                s.values.append(position + (quaternion or ()))
                s.frame = header.frame_id if s.frame is None else s.frame
    msgtypes = {spec: streams[spec][0].msgtype for spec in measurements}
    return samples.pop(joints_topic), samples, tf_frames, joint_skips, msgtypes


def _joint_stream(path: Path, topic: str, s: _Samples, wanted: Sequence[str] | None, skips: int) -> JointStream:
    if not s.values:
        raise MeasurementError(f"{path}: --joints {topic}: no JointState message with positions")
    names, filled, complete = _joint_arrays(s, path, topic, wanted)
    if not np.any(complete):
        raise MeasurementError(f"{path}: --joints {topic}: no message gives a finite position of every joint kept")
    stamps, clock = _clock(s)
    received = np.asarray(s.received, dtype=float)
    order = np.flatnonzero(complete)[np.argsort(stamps[complete], kind="stable")]
    last = np.append(np.diff(stamps[order]) > 0, True)  # of messages with one stamp, the last (it holds the others)
    order = order[last]
    return JointStream(topic, names, stamps[order], filled[order], received[order], clock,
                       skips + len(stamps) - len(order))


def _measurement_stream(path: Path, spec: str, msgtype: str, s: _Samples, pose: bool, flag: str) -> MeasurementStream:
    values = np.asarray(s.values, dtype=float)
    stamps, clock = _clock(s)
    received = np.asarray(s.received, dtype=float)
    good = np.all(np.isfinite(values), axis=1)
    if pose:
        good &= np.linalg.norm(values[:, 3:7], axis=1) > 0.5  # a unit quaternion; zeros = no pose
    if not np.any(good):
        raise MeasurementError(f"{path}: {flag} {spec}: no sample with a finite position"
                               + (" and a unit quaternion" if pose else ""))
    order = np.argsort(stamps[good], kind="stable")
    values = values[good][order]
    quaternions = values[:, 3:7] / np.linalg.norm(values[:, 3:7], axis=1, keepdims=True) if pose else None
    return MeasurementStream(spec, TF if spec.startswith(TF_PREFIX) else msgtype, stamps[good][order],
                             received[good][order], values[:, :3], quaternions, s.frame or "", clock,
                             int(np.sum(~good)))


def _stamp(typestore: Typestore, seconds: float) -> Any:
    sec = int(np.floor(seconds))
    nanosec = min(int(round((seconds - sec) * 1e9)), 999_999_999)
    return typestore.types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec)


def write_bag(
    path: str | os.PathLike[str],
    joints: JointStream,
    measurements: Sequence[MeasurementStream],
    storage: str = "sqlite3",
    *,
    shuffle_seed: int | None = None,
    compress: bool = False,
) -> None:
    """Write streams as a bag :func:`read_bag` reads back: header stamps from ``stamps``, the bag's
    receive times from ``received`` (of each stream, to the nanosecond).

    Args:
        path: a new rosbag2 folder (``sqlite3``, ``mcap``) or ``.bag`` file (``ros1``); never
            overwritten. Written in a hidden sibling folder and renamed into place: whole or not at all.
        joints: written as JointState messages on ``joints.topic``.
        measurements: each as its ``msgtype`` on its topic; a ``tf:CHILD`` stream as ``/tf``
            TFMessages from its ``frame`` to CHILD. Non-finite values are written as they are.
        storage: one of :data:`STORAGES`.
        shuffle_seed: if given, each JointState message names its joints in a random order.
        compress: zstd chunks (MCAP) or lz4 chunks (ROS 1); sqlite3 is written uncompressed.

    Raises:
        MeasurementError: an unknown storage, or ``path`` exists.
        OSError: the folder of ``path`` does not exist or cannot be written.
    """
    from rosbags.typesys import Stores, get_typestore

    if storage not in STORAGES:
        raise MeasurementError(f"storage '{storage}': use one of {', '.join(STORAGES)}")
    path = Path(path)
    if path.exists():
        raise MeasurementError(f"{path}: exists; refusing to overwrite it")
    ros1 = storage == "ros1"
    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.LATEST)
    types = store.types
    serialize = store.serialize_ros1 if ros1 else store.serialize_cdr
    rng = np.random.default_rng(shuffle_seed)
    seq = {"seq": 0} if ros1 else {}

    def header(seconds: float, frame: str) -> Any:  # messages: classes the typestore makes at run time
        return types["std_msgs/msg/Header"](**seq, stamp=_stamp(store, seconds), frame_id=frame)

    def vector(name: str, values: Iterable[float]) -> Any:
        return types[name](*map(float, values))

    def measurement(stream: MeasurementStream, k: int) -> Any:
        head, p = header(stream.stamps[k], stream.frame), stream.positions[k]
        q = stream.quaternions[k] if stream.quaternions is not None else (0.0, 0.0, 0.0, 1.0)
        if stream.msgtype == POINT:
            return types[POINT](header=head, point=vector("geometry_msgs/msg/Point", p))
        if stream.msgtype == POSE:
            return types[POSE](header=head, pose=types["geometry_msgs/msg/Pose"](
                position=vector("geometry_msgs/msg/Point", p), orientation=vector("geometry_msgs/msg/Quaternion", q)))
        transform = types[TRANSFORM](header=head, child_frame_id=stream.topic.removeprefix(TF_PREFIX),
                                     transform=types["geometry_msgs/msg/Transform"](
                                         translation=vector("geometry_msgs/msg/Vector3", p),
                                         rotation=vector("geometry_msgs/msg/Quaternion", q)))
        return types[TF](transforms=[transform]) if stream.msgtype == TF else transform

    def joint_state(k: int) -> Any:
        order = rng.permutation(len(joints.names)) if shuffle_seed is not None else np.arange(len(joints.names))
        empty = np.zeros(0)
        return types[JOINT_STATE](header=header(joints.stamps[k], ""), name=[joints.names[i] for i in order],
                                  position=np.asarray(joints.positions[k], dtype=float)[order], velocity=empty,
                                  effort=empty)

    messages = [(joints.received[k], 0, joints.topic, JOINT_STATE, k) for k in range(len(joints.stamps))]
    for i, stream in enumerate(measurements):
        topic = "/tf" if stream.msgtype == TF else stream.topic
        messages += [(stream.received[k], i + 1, topic, stream.msgtype, k) for k in range(len(stream.stamps))]
    messages.sort(key=lambda m: (m[0], m[1]))
    staging = Path(tempfile.mkdtemp(prefix=f".{path.name}.", dir=path.parent))  # whole or not at all
    try:
        with _writer(staging / path.name, storage, compress) as writer:
            connections: dict[str, Any] = {}
            for received, source, topic, msgtype, k in messages:
                if topic not in connections:
                    connections[topic] = writer.add_connection(topic, msgtype, typestore=store)
                message = joint_state(k) if source == 0 else measurement(measurements[source - 1], k)
                writer.write(connections[topic], int(round(received * 1e9)), serialize(message, msgtype))
        os.rename(staging / path.name, path)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def _writer(path: Path, storage: str, compress: bool) -> Writer1 | Writer2:
    if storage == "ros1":
        from rosbags.rosbag1 import Writer as Writer1

        writer1 = Writer1(path)
        if compress:
            writer1.set_compression(Writer1.CompressionFormat.LZ4)
        return writer1
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.rosbag2.enums import CompressionFormat, CompressionMode

    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    writer = Writer(path, version=Writer.VERSION_LATEST, storage_plugin=plugin)
    if compress and storage == "mcap":
        writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    return writer
