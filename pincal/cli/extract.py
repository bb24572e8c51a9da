"""``pincal extract BAG --joints TOPIC (--pose TOPIC | --point TOPIC ... | --image TOPIC) --out DATA.csv``.

Runs :mod:`pincal.workflows.extract` (rosbags loaded only by this command): reads the bag, cuts the
static postures and writes them as CSV v1, whole or not at all, never over an input. Prints what it
read, the clock offset and the rows; each refused stop is a line on stderr, and a bag that leaves no
row is an error (exit 2) after them.
"""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING

import numpy as np

from pincal.errors import PincalError

if TYPE_CHECKING:
    from pincal.measurements.plateaus import Extraction, PlateauSettings
    from pincal.workflows.extract import BagRead

__all__ = ["run_extract"]


def _rate(stamps: np.ndarray) -> str:
    return f"{1 / np.median(np.diff(stamps)):.0f} Hz" if len(stamps) > 1 else "one sample"


def run_extract(args: argparse.Namespace) -> int:
    """Run ``pincal extract``; returns the exit code (0), raises PincalError on bad input."""
    from pincal.measurements.plateaus import PlateauSettings
    from pincal.workflows.extract import CutFailed, NoPostures, extract_file

    settings = PlateauSettings(still_tol=args.still_tol, min_still=args.min_still, trim=args.trim,
                               min_samples=args.min_samples, max_spread_mm=args.max_spread,
                               max_offset=args.max_offset, clock_offset=args.clock_offset)
    if args.image is not None:
        return _run_extract_images(args, settings)
    if args.image_dir is not None:
        raise PincalError("--image-dir is the folder of --image's images; give --image TOPIC or drop --image-dir")
    topics = [args.pose] if args.pose is not None else list(args.point)
    try:
        read, extraction = extract_file(args.bag, args.joints, topics, args.out, settings, pose=args.pose is not None,
                                        joint_names=args.joint_names)
    except NoPostures as nothing:  # what was read and each stop refused, then the error
        _print_read(nothing.read)
        _print_cut(nothing.read, nothing.extraction, settings)
        raise
    except CutFailed as failed:  # what was read, then why no posture could be cut
        _print_read(failed.read)
        raise
    _print_read(read)
    _print_cut(read, extraction, settings)
    data = extraction.data
    assert data is not None  # extract_file raises NoPostures otherwise
    spread = data.extra["spread_mm"]
    print(f"averaged over {settings.trim:g} s-trimmed windows: spread_mm median {np.median(spread):.3f}, "
          f"max {np.max(spread):.3f}; fewest samples {int(np.min(data.extra['samples']))}")
    print(f"wrote {args.out} ({data.n_rows} rows; columns: {len(data.joint_names)} joints, "
          + ("x,y,z,qx,qy,qz,qw" if data.rotations is not None else "x,y,z" if data.n_points == 1
             else f"x1,y1,z1 ... x{data.n_points},y{data.n_points},z{data.n_points}")
          + f", role, {', '.join(data.extra)})")
    print(f"next: pincal calibrate ROBOT.urdf {args.out} --tip-link LINK --out CORRECTED.urdf --report REPORT.json")
    return 0


def _print_read(read: BagRead) -> None:
    """What the bag held, and the reader's notes."""
    joints, streams = read.joints, read.streams
    for note in read.notes:
        print(f"pincal: note: {note}", file=sys.stderr)
    print(f"read {read.bag}: {joints.topic}: {len(joints.stamps)} readings of {len(joints.names)} joints "
          f"({_rate(joints.stamps)}); " + "; ".join(
              f"{s.topic}: {len(s.stamps)} samples ({s.msgtype.rsplit('/', 1)[1]}, {_rate(s.stamps)}"
              + (f", frame '{s.frame}'" if s.frame else "") + ")" for s in streams))


def _print_cut(read: BagRead, extraction: Extraction, settings: PlateauSettings) -> None:
    """The clock offset, each stop refused and the count of rows."""
    from pincal.measurements.plateaus import REASONS

    joints, streams = read.joints, read.streams
    offset = extraction.offset
    text = (f"clock offset: {streams[0].topic} stamps - {joints.topic} stamps = {offset.seconds:+.4f} s")
    if offset.estimated:
        text += (f", from the motion: {offset.edges} starts and ends of stops (speeds alone: {offset.coarse:+.3f} s, "
                 f"correlation {offset.correlation:.2f}; receive times: {offset.prior:+.3f} s)")
    print(text + ("" if offset.estimated else " (--clock-offset)"))
    origin = joints.stamps[0]
    for refusal in extraction.refused:
        print(f"pincal: refused: stop at {refusal.start - origin:.2f}-{refusal.end - origin:.2f} s (joint clock, from "
              f"the first reading): {refusal.reason}: {refusal.detail}", file=sys.stderr)
    counts = ", ".join(f"{extraction.count(reason)} {reason}" for reason in REASONS)
    rows = 0 if extraction.data is None else extraction.data.n_rows
    print(f"{extraction.stretches} still stretches of >= {settings.min_still:g} s (every joint within "
          f"{settings.still_tol:g}): {rows} rows; refused: {counts}")


def _run_extract_images(args: argparse.Namespace, settings: PlateauSettings) -> int:
    """``pincal extract --image``: the images of the stops saved, JOINTS.csv written."""
    from pincal.workflows.extract import extract_images

    run = extract_images(args.bag, args.joints, args.image, args.out, args.image_dir, settings,
                         joint_names=args.joint_names)
    joints, images = run.read.joints, run.images
    for note in run.read.notes:
        print(f"pincal: note: {note}", file=sys.stderr)
    print(f"read {args.bag}: {joints.topic}: {len(joints.stamps)} readings of {len(joints.names)} joints "
          f"({_rate(joints.stamps)}); {images.topic}: {len(images.stamps)} images ({images.msgtype.rsplit('/', 1)[1]})")
    how = " (--clock-offset)" if settings.clock_offset is not None else ", from the receive times"
    print(f"clock offset: {images.topic} stamps - {joints.topic} stamps = {run.offset.seconds:+.4f} s{how}")
    origin = joints.stamps[0]
    for refusal in run.refused:
        print(f"pincal: refused: stop at {refusal.start - origin:.2f}-{refusal.end - origin:.2f} s (joint clock, from "
              f"the first reading): {refusal.reason}: {refusal.detail}", file=sys.stderr)
    folder = run.files[0].parent
    print(f"{len(run.postures)} stops with an image (the one nearest the middle of the {settings.trim:g} s-trimmed "
          f"window): wrote {len(run.files)} images to {folder} and {run.out} (columns: image, "
          f"{len(joints.names)} joints, t_image, t_start_robot, t_end_robot)")
    print(f"next: pincal detect {folder} --board charuco:COLSxROWS:SQUARE_M:MARKER_M:DICT --joints {run.out} "
          "--out DATA.csv")
    return 0
