"""``pincal detect IMAGES... --board charuco:COLSxROWS:SQUARE_M:MARKER_M:DICT --joints JOINTS.csv --out DATA.csv``.

Runs :func:`pincal.workflows.detection.detect_files` (OpenCV loaded by this command only) and prints what
it found: each image skipped (the board not in it) as a note on stderr, then the counts and the file.
"""

from __future__ import annotations

import argparse
import sys

__all__ = ["run_detect"]


def run_detect(args: argparse.Namespace) -> int:
    """Run ``pincal detect``; returns the exit code (0), raises PincalError on bad input (a ``--board`` that
    does not parse: one line with the form and an example, before OpenCV or numpy is loaded)."""
    from pincal.measurements.charuco import parse_board

    board = parse_board(args.board)
    import numpy as np

    from pincal.cli.progress import progress_bar
    from pincal.measurements.camera_csv import CORNER_COLUMNS, IMAGE_COLUMN
    from pincal.workflows.detection import DetectSettings, detect_files

    settings = DetectSettings(args.images, board, args.joints, args.out)
    with progress_bar("detect", unit="image") as progress:
        run = detect_files(settings, progress)
    for note in run.notes:
        print(f"pincal: note: {note}", file=sys.stderr)
    found = [image for image in run.images if image.found]
    counts = np.array([len(image.detection.ids) for image in found])
    sizes = sorted({image.detection.size for image in run.images})
    print(f"read {len(run.images)} image(s) ({', '.join(f'{w}x{h}' for w, h in sizes)} px) and {run.readings.source}"
          f" ({len(run.readings.columns)} joint column(s): {', '.join(run.readings.columns)})")
    print(f"board {board.text} ({board.n_corners} corners): found in {len(found)} image(s), {int(np.median(counts))} "
          f"corners median (fewest {counts.min()}); skipped {len(run.skipped)} (board not found)")
    extra = ", session" if run.readings.sessions is not None else ""
    print(f"wrote {run.out} ({run.rows} rows, one per corner; columns: {IMAGE_COLUMN}, {', '.join(CORNER_COLUMNS)}, "
          f"the joint columns, role{extra})")
    return 0
