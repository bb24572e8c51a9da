"""``pincal extract``'s job: a ROS bag's joint and measurement topics read
(:mod:`pincal.measurements.bags`), its static postures cut (:mod:`pincal.measurements.plateaus`) and
written as CSV v1, whole or not at all, never over an input.

In two steps, so a caller can say what was read before the cut (which may refuse the recording's
clocks): :func:`read_bag_file`, then :func:`write_postures`; :func:`extract_file` runs both.

A camera's images (``--image``): :func:`extract_images` saves the image of each static posture as a PNG
file and writes JOINTS.csv, the input of ``pincal detect`` (:mod:`pincal.measurements.image_bags`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pincal.errors import MeasurementError
from pincal.measurements.bags import JointStream, MeasurementStream, read_bag
from pincal.measurements.camera_csv import write_joint_readings
from pincal.measurements.csv_v1 import write_measurements
from pincal.measurements.image_bags import ImagePosture, ImageStream, image_postures, read_image_topic
from pincal.measurements.plateaus import ClockOffset, Extraction, PlateauSettings, Refusal, extract_postures
from pincal.outputs import write_bytes
from pincal.workflows.paths import ensure_directory, refuse_overwrite

__all__ = ["BagRead", "CutFailed", "NoPostures", "bag_files", "read_bag_file", "no_rows_error", "write_postures",
           "extract_file", "ImageExtraction", "extract_images"]


@dataclass(frozen=True)
class BagRead:
    """What :func:`read_bag_file` read: the bag, its joint stream, its measurement streams and a note
    for each thing left out or taken from the recorder (messages skipped, samples dropped, receive times)."""

    bag: Path
    joints: JointStream
    streams: list[MeasurementStream]
    notes: list[str]


def bag_files(bag: Path) -> list[Path]:
    """The bag and, for a rosbag2 folder, its files: the output must be none of them."""
    return [bag, *sorted(p for p in bag.rglob("*") if p.is_file())] if bag.is_dir() else [bag]


def read_bag_file(bag: str | Path, joints_topic: str, topics: Sequence[str], out: str | Path, *, pose: bool,
                  joint_names: Sequence[str] | None = None) -> BagRead:
    """Read ``joints_topic`` and the measurement ``topics`` (one pose topic with ``pose``, else point
    topics) of ``bag``, after refusing an ``out`` that is one of the bag's files."""
    bag = Path(bag)
    refuse_overwrite(out, *bag_files(bag))
    joints, streams = read_bag(bag, joints_topic, topics, pose=pose, joint_names=joint_names)
    notes = [f"{joints.topic}: {joints.skipped} message(s) left out (positions and names of different "
             "length, or before every joint was read)"] if joints.skipped else []
    notes += [f"{s.topic}: {s.dropped} sample(s) without a finite value left out" for s in streams if s.dropped]
    clocks = [(joints.topic, joints.clock), *((s.topic, s.clock) for s in streams)]
    notes += [f"{topic}: stamps are not set; the recorder's receive times are used"
              for topic, clock in clocks if clock == "receive"]
    return BagRead(bag, joints, streams, notes)


class CutFailed(MeasurementError):
    """The bag was read but its postures could not be cut (e.g. no clock offset found): nothing was
    written. ``read`` says what was read (the command prints it before this error)."""

    def __init__(self, read: BagRead, message: str) -> None:
        super().__init__(message)
        self.read = read


class NoPostures(CutFailed):
    """A recording that leaves no static posture: nothing was written. ``read`` and ``extraction`` say
    what was read and why each stop was refused (the command prints them before this error)."""

    def __init__(self, read: BagRead, extraction: Extraction) -> None:
        super().__init__(read, f"{read.bag}: no static posture left to write ({len(extraction.refused)} stop(s) "
                         "refused, listed above); nothing written")
        self.extraction = extraction


def no_rows_error(read: BagRead, extraction: Extraction) -> MeasurementError:
    """The error of a recording that leaves no static posture (nothing written): a :class:`NoPostures`."""
    return NoPostures(read, extraction)


def write_postures(read: BagRead, out: str | Path, settings: PlateauSettings) -> Extraction:
    """Cut the static postures of ``read`` as ``settings`` say and write them to ``out`` (CSV v1); a
    recording that leaves none writes nothing (``extraction.data`` is None: see :func:`no_rows_error`)."""
    extraction = extract_postures(read.joints, read.streams, settings, source=str(read.bag))
    if extraction.data is not None:
        write_measurements(out, extraction.data)
    return extraction


def extract_file(bag: str | Path, joints_topic: str, topics: Sequence[str], out: str | Path,
                 settings: PlateauSettings | None = None, *, pose: bool,
                 joint_names: Sequence[str] | None = None) -> tuple[BagRead, Extraction]:
    """``pincal extract`` in one call: :func:`read_bag_file`, then :func:`write_postures` (``settings`` None:
    the defaults of :class:`~pincal.measurements.plateaus.PlateauSettings`, ``pincal extract``'s).

    Raises:
        NoPostures: the recording leaves no static posture (nothing written; what was read and refused in it).
        CutFailed: the postures cannot be cut, e.g. no clock offset found (nothing written; what was read).
        MeasurementError: a bad bag or topic.
    """
    read = read_bag_file(bag, joints_topic, topics, out, pose=pose, joint_names=joint_names)
    try:
        extraction = write_postures(read, out, settings or PlateauSettings())
    except CutFailed:
        raise
    except MeasurementError as error:  # the cut's own error, with what was read
        raise CutFailed(read, str(error)) from None
    if extraction.data is None:
        raise no_rows_error(read, extraction)
    return read, extraction


@dataclass(frozen=True)
class ImageExtraction:
    """What :func:`extract_images` read and wrote.

    Attributes:
        read: the bag, its joint stream and the notes of reading it (no measurement stream).
        images: the image topic's images.
        postures: the static postures with an image, in time order.
        refused: the stops without one (too short, no image in the window).
        offset: the clock offset used (given, or from the receive times).
        files: the image files written, one per posture.
        out: JOINTS.csv, written.
    """

    read: BagRead
    images: ImageStream
    postures: tuple[ImagePosture, ...]
    refused: tuple[Refusal, ...]
    offset: ClockOffset
    files: tuple[Path, ...]
    out: Path


def extract_images(bag: str | Path, joints_topic: str, image_topic: str, out: str | Path,
                   image_dir: str | Path | None = None, settings: PlateauSettings | None = None, *,
                   joint_names: Sequence[str] | None = None) -> ImageExtraction:
    """``pincal extract --image``: each static posture's image saved as ``image_NNN.png`` in ``image_dir``
    (default: ``OUT_images`` beside ``out``), then JOINTS.csv written to ``out`` (the image's name, the
    joint readings averaged over the window, ``t_image``, ``t_start_robot``, ``t_end_robot`` [s]).

    Raises:
        MeasurementError: no static posture with an image, an image that cannot be decoded, a folder holding
            an earlier run's images (nothing written then); a bad bag or topic.
    """
    out = Path(out)
    folder = Path(image_dir) if image_dir is not None else out.with_name(f"{out.stem}_images")
    read = read_bag_file(bag, joints_topic, [], out, pose=False, joint_names=joint_names)
    images = read_image_topic(read.bag, image_topic)
    postures, refused, offset = image_postures(read.joints, images, settings or PlateauSettings())
    if not postures:
        raise MeasurementError(f"{read.bag}: no static posture with an image of {image_topic} ({len(refused)} stop(s) "
                               "refused); nothing written")
    import cv2

    for path in bag_files(read.bag):
        if path.parent == folder:
            raise MeasurementError(f"{folder}: holds the bag's files; choose another folder for the images")
    encoded = []  # every image decoded and encoded before any file is written: whole or nothing
    for k, posture in enumerate(postures):
        ok, png = cv2.imencode(".png", images.image(posture.image, str(read.bag)))
        if not ok:
            raise MeasurementError(f"{folder}: OpenCV cannot encode image {k} as PNG")
        encoded.append(png.tobytes())
    files = [folder / f"image_{k:03d}.png" for k in range(len(encoded))]
    stale = sorted(set(folder.glob("image_*.png")) - set(files)) if folder.is_dir() else []
    if stale:  # an earlier run's images this one would not replace would pass for its own (detect reads the folder)
        raise MeasurementError(f"{folder}: holds image_*.png files of an earlier run that this one would not replace "
                               f"({stale[0].name} ...); choose another folder (--image-dir) or remove them")
    ensure_directory(folder)
    for path, png_bytes in zip(files, encoded):
        write_bytes(path, png_bytes)
    extra = {"t_image": np.array([images.stamps[p.image] for p in postures]),
             "t_start_robot": np.array([p.window[0] for p in postures]),
             "t_end_robot": np.array([p.window[1] for p in postures])}
    write_joint_readings(out, [f.name for f in files], read.joints.names, np.array([p.q for p in postures]), extra)
    return ImageExtraction(read, images, tuple(postures), tuple(refused), offset, tuple(files), out)
