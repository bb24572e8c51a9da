"""A camera's images in a ROS bag, matched to the robot's static postures: ``pincal extract --image``.

The images of a ``sensor_msgs/Image`` or ``sensor_msgs/CompressedImage`` topic are read with rosbags
(the messages kept as they are, decoded only when chosen); the joint stream and its still stretches are
those of the other sensors (:mod:`pincal.measurements.bags`, :func:`pincal.measurements.plateaus.stops_of`
with the same :class:`~pincal.measurements.plateaus.PlateauSettings`). For each still
stretch, trimmed by ``trim`` seconds at both ends, the image stamped nearest the window's middle is
taken, and the joint readings averaged over the window. The clock offset (image stamp − joint stamp of
one instant) is ``--clock-offset`` when given, else what the receive times say: the median of stamp −
receive time of the images minus that of the joints (exact when both streams are stamped on the
recorder's clock; otherwise within the difference of the transport delays). Images cannot give the
motion-based estimate of point and pose streams before their board is detected.

Images are returned in grey levels (H, W) uint8: ``mono8``, ``mono16`` (its high byte), ``rgb8``,
``bgr8``, ``rgba8``, ``bgra8`` and their ``8UC1``/``16UC1`` forms; a compressed image as OpenCV decodes it.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pincal.errors import MeasurementError
from pincal.measurements.bags import JointStream, _clock, _connections, _reader, _Samples, _seconds
from pincal.measurements.plateaus import ClockOffset, PlateauSettings, Refusal, stops_of

__all__ = ["IMAGE", "COMPRESSED_IMAGE", "ImageStream", "ImagePosture", "read_image_topic", "image_postures"]

IMAGE = "sensor_msgs/msg/Image"
COMPRESSED_IMAGE = "sensor_msgs/msg/CompressedImage"
#: Raw encodings read, with OpenCV's conversion to grey (None: already grey).
_ENCODINGS: dict[str, str | None] = {"mono8": None, "8UC1": None, "mono16": None, "16UC1": None,
                                     "rgb8": "COLOR_RGB2GRAY", "bgr8": "COLOR_BGR2GRAY",
                                     "rgba8": "COLOR_RGBA2GRAY", "bgra8": "COLOR_BGRA2GRAY"}


@dataclass(frozen=True)
class ImageStream:
    """The images of one topic, as recorded (decoded by :meth:`image`).

    Attributes:
        topic: the topic.
        msgtype: :data:`IMAGE` or :data:`COMPRESSED_IMAGE`.
        stamps: (M,) each image's time [s] on the clock ``clock`` says; received: (M,) the recorder's.
        messages: the messages, in the order of ``stamps``.
        clock: ``"header"`` or ``"receive"``.
    """

    topic: str
    msgtype: str
    stamps: np.ndarray
    received: np.ndarray
    messages: tuple[Any, ...]
    clock: str = "header"

    def image(self, k: int, source: str = "<bag>") -> np.ndarray:
        """Image ``k`` in grey levels (H, W) uint8.

        Raises:
            MeasurementError: an encoding not read, or data OpenCV cannot decode (naming the image's time).
        """
        import cv2

        message = self.messages[k]
        where = f"{source}: --image {self.topic}: the image at {self.stamps[k]:.3f} s"
        data = np.frombuffer(bytes(message.data), dtype=np.uint8)
        if self.msgtype == COMPRESSED_IMAGE:
            decoded = cv2.imdecode(data, cv2.IMREAD_GRAYSCALE) if data.size else None
            if decoded is None:
                raise MeasurementError(f"{where}: OpenCV cannot decode its data ({message.format!r})")
            return np.asarray(decoded)
        if message.encoding not in _ENCODINGS:
            raise MeasurementError(f"{where}: encoding '{message.encoding}' is not read ({', '.join(_ENCODINGS)})")
        wide = message.encoding in ("mono16", "16UC1")
        channels = {"rgb8": 3, "bgr8": 3, "rgba8": 4, "bgra8": 4}.get(message.encoding, 1)
        depth = 2 if wide else 1
        if data.size < message.height * message.step or message.step < message.width * channels * depth:
            raise MeasurementError(f"{where}: {data.size} bytes for {message.width}x{message.height} "
                                   f"{message.encoding} (step {message.step})")
        rows = data[: message.height * message.step].reshape(message.height, message.step)
        pixels = rows[:, : message.width * channels * depth]
        if wide:
            values = pixels.view(">u2" if message.is_bigendian else "<u2")
            return (values >> 8).astype(np.uint8)
        image = pixels.reshape(message.height, message.width, channels)
        conversion = _ENCODINGS[message.encoding]
        return image[:, :, 0].copy() if conversion is None else cv2.cvtColor(image, getattr(cv2, conversion))


@dataclass(frozen=True)
class ImagePosture:
    """A still stretch and the image taken in it.

    Attributes:
        image: the index of the image in its :class:`ImageStream`.
        q: the joint readings averaged over the window (N,) [rad; m for prismatic joints].
        window: the trimmed window on the joint clock [s].
    """

    image: int
    q: np.ndarray
    window: tuple[float, float]


def read_image_topic(path: str | os.PathLike[str], topic: str) -> ImageStream:
    """The images of ``topic`` in the bag at ``path``.

    Raises:
        MeasurementError: an unreadable bag, no such topic (did you mean), another message type, no image.
    """
    path = Path(path)
    reader, errors = _reader(path)
    samples = _Samples()
    try:
        with reader:
            connections = _connections(reader, path, topic, "--image", (IMAGE, COMPRESSED_IMAGE))
            for connection, received_ns, raw in reader.messages(connections=connections):
                message: Any = reader.deserialize(raw, connection.msgtype)  # a class rosbags makes at run time
                samples.stamps.append(_seconds(message.header.stamp))
                samples.received.append(received_ns * 1e-9)
                samples.values.append(message)
    except MeasurementError:
        raise
    except Exception as exc:  # rosbags' own errors and a corrupt chunk's, as for the other topics
        raise MeasurementError(f"{path}: not a readable ROS bag ({type(exc).__name__}: "
                               f"{' '.join(str(exc).split())})") from None
    if not samples.values:
        raise MeasurementError(f"{path}: --image {topic}: the topic has no message")
    stamps, clock = _clock(samples)
    order = np.argsort(stamps, kind="stable")
    return ImageStream(topic, connections[0].msgtype, stamps[order], np.asarray(samples.received)[order],
                       tuple(samples.values[k] for k in order), clock)


def _receive_offset(joints: JointStream, images: ImageStream) -> float:
    """Image stamp − joint stamp of one instant, as the receive times say it [s]."""
    return float(np.median(images.stamps - images.received) - np.median(joints.stamps - joints.received))


def image_postures(joints: JointStream, images: ImageStream, settings: PlateauSettings
                   ) -> tuple[list[ImagePosture], list[Refusal], ClockOffset]:
    """Each still stretch of ``joints`` with the image nearest the middle of its trimmed window.

    Returns:
        The postures with an image, the stops refused (too short, no image in the window) in time order,
        and the clock offset used (``estimated`` False: given, or from the receive times, ``prior``).
    """
    prior = _receive_offset(joints, images)
    given = settings.clock_offset
    offset = ClockOffset(prior if given is None else given, False, prior=prior)
    t, q = joints.stamps, joints.positions
    stops, refused = stops_of(joints, settings)
    postures = []
    for a, b in stops:
        start, end = float(t[a]), float(t[b])
        window = (start + settings.trim, end - settings.trim)
        shifted = images.stamps - offset.seconds
        inside = np.flatnonzero((shifted >= window[0]) & (shifted <= window[1]))
        if end - start < settings.min_still or inside.size == 0:
            detail = (f"still for {end - start:.2f} s < --min-still {settings.min_still:g} s" if inside.size
                      else f"no image of {images.topic} in the {window[1] - window[0]:.2f} s window")
            refused.append(Refusal(start, end, "too short" if inside.size else "too few samples", detail))
            continue
        middle = inside[np.argmin(np.abs(shifted[inside] - (window[0] + window[1]) / 2))]
        in_window = (t >= window[0]) & (t <= window[1])
        postures.append(ImagePosture(int(middle), q[in_window].mean(axis=0), window))
    refused.sort(key=lambda r: r.start)
    return postures, refused, offset
