"""Convert MUKCa socket recordings (upstream layout) into pincal's socket-fixture CSV form.

Upstream (platonics-delft/kinematics_calibration, ``data/``) keeps one folder
per robot and fixture placement, each with ``hole_0.csv`` and ``hole_1.csv``:
one row per configuration with the ball in that socket, one column per arm
joint in chain order, radians, no header. pincal reads one CSV per placement
with the URDF's joint names as header, a ``point`` column naming the socket
and a ``placement`` column (README, "Without an external sensor"), plus a
fixture file giving the sockets' centres: ``hole_0`` at the origin, ``hole_1``
50 mm along x (the tool's sockets are 50 mm apart). Values are copied exactly
(shortest round-trip text of each float).

Run:  python examples/mukca_convert.py SOURCE_DATA_DIR [--out data/mukca]

SOURCE_DATA_DIR holds ``kuka_14/`` and/or ``panda_1/``; derived files
(``hole_*_pose.csv``: poses upstream computed with its nominal model) are not
converted.
"""

from __future__ import annotations

import argparse
import csv
import io
import sys
from pathlib import Path

import numpy as np

from pincal.outputs import write_text

# data/ beside examples/: a clone's, or `pincal example NAME` (absolute: a clone's examples/ is a link)
ROOT = Path(__file__).absolute().parent.parent

#: Upstream robot folder → the chain's joint names, in upstream's column order.
JOINTS = {
    "kuka_14": tuple(f"joint_a{n}" for n in range(1, 8)),  # data/mukca/urdf/iiwa14.urdf
    "panda_1": tuple(f"panda_joint{n}" for n in range(1, 8)),  # example-robot-data panda.urdf
}
#: Socket centres in the fixture frame [m]: the tool's two sockets, 50 mm apart.
SOCKETS = {"hole_0": (0.0, 0.0, 0.0), "hole_1": (0.05, 0.0, 0.0)}


def _csv(rows: list[list[str]]) -> str:
    text = io.StringIO()
    csv.writer(text, lineterminator="\n").writerows(rows)
    return text.getvalue()


def convert_placement(folder: Path, joints: tuple[str, ...]) -> str:
    """The pincal CSV text of one upstream placement folder (hole_0.csv, hole_1.csv, ...)."""
    rows = [[*joints, "point", "placement"]]
    for socket in SOCKETS:
        path = folder / f"{socket}.csv"
        if not path.is_file():
            raise SystemExit(f"{path}: missing; a placement folder holds {', '.join(SOCKETS)}.csv")
        q = np.loadtxt(path, delimiter=",", ndmin=2)
        if q.shape[1] != len(joints):
            raise SystemExit(f"{path}: {q.shape[1]} columns, expected {len(joints)} joints")
        rows += [[repr(float(v)) for v in row] + [socket, folder.name] for row in q]
    return _csv(rows)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("source", type=Path, help="upstream data folder (holding kuka_14/, panda_1/)")
    parser.add_argument("--out", type=Path, default=ROOT / "data" / "mukca", help="output folder")
    args = parser.parse_args(argv)
    robots = [r for r in JOINTS if (args.source / r).is_dir()]
    if not robots:
        raise SystemExit(f"{args.source}: no {' or '.join(JOINTS)} folder")
    args.out.mkdir(parents=True, exist_ok=True)
    fixture = [["point", "x", "y", "z"]] + [[name, *map(repr, xyz)] for name, xyz in SOCKETS.items()]
    write_text(args.out / "fixture.csv", _csv(fixture))
    for robot in robots:
        for folder in sorted(p for p in (args.source / robot).iterdir() if p.is_dir()):
            out = args.out / robot / f"{folder.name}.csv"
            out.parent.mkdir(parents=True, exist_ok=True)
            write_text(out, convert_placement(folder, JOINTS[robot]))
            print(f"wrote {out}")
    print(f"wrote {args.out / 'fixture.csv'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
