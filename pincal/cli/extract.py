"""``pincal extract BAG --joints TOPIC (--pose TOPIC | --point TOPIC ...) --out DATA.csv``.

Reads the bag (:mod:`pincal.measurements.bags`, rosbags loaded only here), cuts the static
postures (:mod:`pincal.measurements.plateaus`) and writes them as CSV v1, whole or not at all,
never over an input. Prints what it read, the clock offset and the rows; each refused stop is a
line on stderr, and a bag that leaves no row is an error (exit 2) after them.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from pincal.errors import MeasurementError

__all__ = ["run_extract"]


def _rate(stamps: np.ndarray) -> str:
    return f"{1 / np.median(np.diff(stamps)):.0f} Hz" if len(stamps) > 1 else "one sample"


def _bag_files(bag: Path) -> list[Path]:
    """The bag and, for a rosbag2 folder, its files: the output must be none of them."""
    return [bag, *sorted(p for p in bag.rglob("*") if p.is_file())] if bag.is_dir() else [bag]


def run_extract(args: argparse.Namespace) -> int:
    """Run ``pincal extract``; returns the exit code (0), raises PincalError on bad input."""
    from pincal.cli.paths import refuse_overwrite
    from pincal.measurements.bags import read_bag
    from pincal.measurements.csv_v1 import write_measurements
    from pincal.measurements.plateaus import REASONS, PlateauSettings, extract_postures

    settings = PlateauSettings(still_tol=args.still_tol, min_still=args.min_still, trim=args.trim,
                               min_samples=args.min_samples, max_spread_mm=args.max_spread,
                               max_offset=args.max_offset, clock_offset=args.clock_offset)
    topics = [args.pose] if args.pose is not None else list(args.point)
    refuse_overwrite(args.out, *_bag_files(args.bag))
    joints, streams = read_bag(args.bag, args.joints, topics, pose=args.pose is not None,
                               joint_names=args.joint_names)
    notes = [f"{joints.topic}: {joints.skipped} message(s) left out (positions and names of different "
             "length, or before every joint was read)"] if joints.skipped else []
    notes += [f"{s.topic}: {s.dropped} sample(s) without a finite value left out" for s in streams if s.dropped]
    clocks = [(joints.topic, joints.clock), *((s.topic, s.clock) for s in streams)]
    notes += [f"{topic}: stamps are not set; the recorder's receive times are used"
              for topic, clock in clocks if clock == "receive"]
    for note in notes:
        print(f"pincal: note: {note}", file=sys.stderr)
    print(f"read {args.bag}: {joints.topic}: {len(joints.stamps)} readings of {len(joints.names)} joints "
          f"({_rate(joints.stamps)}); " + "; ".join(
              f"{s.topic}: {len(s.stamps)} samples ({s.msgtype.rsplit('/', 1)[1]}, {_rate(s.stamps)}"
              + (f", frame '{s.frame}'" if s.frame else "") + ")" for s in streams))
    extraction = extract_postures(joints, streams, settings, source=str(args.bag))
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
    if extraction.data is None:
        raise MeasurementError(f"{args.bag}: no static posture left to write ({len(extraction.refused)} stop(s) "
                               "refused, listed above); nothing written")
    data = extraction.data
    spread = data.extra["spread_mm"]
    print(f"averaged over {settings.trim:g} s-trimmed windows: spread_mm median {np.median(spread):.3f}, "
          f"max {np.max(spread):.3f}; fewest samples {int(np.min(data.extra['samples']))}")
    write_measurements(args.out, data)
    print(f"wrote {args.out} ({data.n_rows} rows; columns: {len(data.joint_names)} joints, "
          + ("x,y,z,qx,qy,qz,qw" if data.rotations is not None else "x,y,z" if data.n_points == 1
             else f"x1,y1,z1 ... x{data.n_points},y{data.n_points},z{data.n_points}")
          + f", role, {', '.join(data.extra)})")
    print(f"next: pincal calibrate ROBOT.urdf {args.out} --tip-link LINK --out CORRECTED.urdf --report REPORT.json")
    return 0
