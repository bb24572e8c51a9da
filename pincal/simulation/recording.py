"""A simulated recording: a robot visiting postures, its joint stream and a tracker on its own clock.

What a ROS bag of a calibration session holds (:mod:`pincal.measurements.bags` writes it): the
robot holds each posture for a while and moves to the next along a cosine-blended joint path; the
joint driver stamps its readings (encoder noise) on the robot's clock, the tracker samples the
target at its own rate (sensor noise, :func:`pincal.simulation.sensor.measure`) and stamps it on
a clock ``clock_offset_s`` ahead; the recorder receives each message after a transport delay with
a random jitter. A stop can be made short, the target can be shaken while the joints hold
(a bumped tracker or a loose target: the measurement moves, the joints do not), and the tracker
can drop out. Everything is drawn from one seeded generator.

The chain is measured as it is: place it in the true geometry first (``with chain.placed(...)``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from pincal.measurements.bags import POINT, POSE, JointStream, MeasurementStream
from pincal.model.chain import KinematicChain
from pincal.model.sensor import Registration
from pincal.simulation.sensor import SimulatedSensor, measure

__all__ = ["RecordingSettings", "SessionEvents", "RecordingTopics", "Recording", "simulate_recording"]


@dataclass(frozen=True)
class RecordingSettings:
    """Rates, noise, clocks and timing of a simulated recording.

    Attributes:
        hold_s: time at each posture [s]; move_s: time of each move between postures [s].
        joint_rate_hz / tracker_rate_hz: sampling rates.
        joint_noise: std of each joint reading [rad, or m for prismatic joints].
        tracker_noise_m: std of each measured coordinate [m]; tracker_noise_rad: of each ZYX angle [rad].
        clock_offset_s: tracker stamp − joint stamp of one instant [s].
        joint_delay_s / tracker_delay_s: transport delay to the recorder [s], plus an exponential
            jitter of mean ``jitter_s``.
        start_s: the joint clock at the first sample (Unix seconds).
        seed: seed of the generator.
    """

    hold_s: float = 3.0
    move_s: float = 1.5
    joint_rate_hz: float = 100.0
    tracker_rate_hz: float = 100.0
    joint_noise: float = 1e-5
    tracker_noise_m: float = 5e-5
    tracker_noise_rad: float = 1e-4
    clock_offset_s: float = 0.25
    joint_delay_s: float = 0.002
    tracker_delay_s: float = 0.012
    jitter_s: float = 0.002
    start_s: float = 1.7e9
    seed: int = 0


@dataclass(frozen=True)
class SessionEvents:
    """What disturbs a simulated session, by posture index or time.

    Attributes:
        holds: hold time [s] of the postures named (others: ``RecordingSettings.hold_s``): a short stop.
        shaken: amplitude [m] of a 2 Hz shake of the measured target during the hold of the
            postures named; the joints hold still.
        dropouts: stretches of time since the start [s] in which the tracker sends nothing.
    """

    holds: Mapping[int, float] | None = None
    shaken: Mapping[int, float] | None = None
    dropouts: Sequence[tuple[float, float]] = ()


@dataclass(frozen=True)
class RecordingTopics:
    """The topics a simulated recording is written on.

    Attributes:
        measurements: the measurement topics (default ``/tracker/pose`` or ``/tracker/marker1``, …).
        joints: the JointState topic.
    """

    measurements: Sequence[str] | None = None
    joints: str = "/joint_states"


@dataclass(frozen=True)
class Recording:
    """The streams of a simulated recording and the truth behind them.

    Attributes:
        joints: the joint stream; measurements: one pose stream or one point stream per point.
        postures: (K, N) the joint values held [rad or m]; holds: (K, 2) each hold's start and
            end on the joint clock [s].
        truth: (K, P, 3) the noise-free measured points at each posture [m]; rotations: (K, 3, 3)
            the noise-free measured orientation, or None.
    """

    joints: JointStream
    measurements: list[MeasurementStream]
    postures: np.ndarray
    holds: np.ndarray
    truth: np.ndarray
    rotations: np.ndarray | None


def _path(postures: np.ndarray, holds: np.ndarray, move_s: float):
    """The joint path as a function of time since the start [s]: hold, cosine-blended move, hold…"""
    starts = np.concatenate([[0.0], np.cumsum(holds[:-1] + move_s)])

    def q(t: np.ndarray) -> np.ndarray:
        k = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(postures) - 1)
        u = np.clip((t - starts[k] - holds[k]) / move_s, 0.0, 1.0)
        blend = 0.5 * (1 - np.cos(np.pi * u))
        after = postures[np.minimum(k + 1, len(postures) - 1)]
        return postures[k] + blend[:, None] * (after - postures[k])

    return q, np.column_stack([starts, starts + holds]), float(starts[-1] + holds[-1])


def simulate_recording(
    chain: KinematicChain,
    postures: np.ndarray,
    registration: Registration,
    settings: RecordingSettings = RecordingSettings(),
    *,
    points: np.ndarray | None = None,
    pose: bool = False,
    events: SessionEvents | None = None,
    topics: RecordingTopics | None = None,
) -> Recording:
    """Simulate the recording of a session visiting ``postures`` (K, N) in order.

    Args:
        chain: the robot, placed in its true geometry.
        registration: the true sensor_T_base.
        points: target points in the tool frame (P, 3) [m] (default the tool origin); with ``pose``
            the one point's frame is measured (position and orientation).
        events: short stops, shakes of the target and tracker dropouts (:class:`SessionEvents`; default none).
        topics: the topics written on (:class:`RecordingTopics`; default ``/joint_states`` and
            ``/tracker/pose`` or ``/tracker/marker1``, …).
    """
    events = SessionEvents() if events is None else events
    holds, shaken, dropouts = events.holds, events.shaken, events.dropouts
    topics = RecordingTopics() if topics is None else topics
    rng = np.random.default_rng(settings.seed)
    postures = np.asarray(postures, dtype=float)
    points = np.zeros((1, 3)) if points is None else np.asarray(points, dtype=float)
    hold = np.full(len(postures), settings.hold_s)
    for k, seconds in (holds or {}).items():
        hold[k] = seconds
    path, windows, duration = _path(postures, hold, settings.move_s)
    t_joint = np.arange(0.0, duration, 1.0 / settings.joint_rate_hz)
    readings = path(t_joint) + rng.normal(0.0, settings.joint_noise, (len(t_joint), postures.shape[1]))
    t_tracker = np.arange(rng.uniform(0, 1.0 / settings.tracker_rate_hz), duration, 1.0 / settings.tracker_rate_hz)
    for start, end in dropouts:
        t_tracker = t_tracker[(t_tracker < start) | (t_tracker > end)]
    seen = measure(chain, path(t_tracker), registration, rng,
                   SimulatedSensor(settings.tracker_noise_m, settings.tracker_noise_rad, points, with_rotation=pose),
                   "calibration")
    sensed = np.array(seen.points)
    for k, amplitude in (shaken or {}).items():
        inside = (t_tracker >= windows[k, 0]) & (t_tracker <= windows[k, 1])
        sensed[inside, :, 0] += amplitude * np.sin(2 * np.pi * 2.0 * t_tracker[inside])[:, None]
    truth = measure(chain, postures, registration, rng, SimulatedSensor(0.0, 0.0, points, with_rotation=pose),
                    "calibration")

    def delays(mean: float, count: int) -> np.ndarray:
        return mean + rng.exponential(settings.jitter_s, count)

    start = settings.start_s
    joints = JointStream(topics.joints, chain.joint_names, start + t_joint, readings,
                         start + t_joint + delays(settings.joint_delay_s, len(t_joint)))
    stamps = start + t_tracker + settings.clock_offset_s
    received = start + t_tracker + delays(settings.tracker_delay_s, len(t_tracker))
    if pose:
        assert seen.rotations is not None  # measured with orientations
        names = list(topics.measurements or ["/tracker/pose"])
        streams = [MeasurementStream(names[0], POSE, stamps, received, sensed[:, 0],
                                     Rotation.from_matrix(seen.rotations).as_quat(), "tracker")]
    else:
        names = list(topics.measurements or [f"/tracker/marker{p + 1}" for p in range(len(points))])
        streams = [MeasurementStream(names[p], POINT, stamps, received, sensed[:, p], None, "tracker")
                   for p in range(len(points))]
    return Recording(joints, streams, postures, start + windows, np.array(truth.points), truth.rotations)
